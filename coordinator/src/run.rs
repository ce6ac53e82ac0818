//! A run: start the nodes, initialise them, drive the schedule window by window over zenoh,
//! watch stability and liveliness, stop cleanly and write `summary.json` (Ullrich Algorithm 3).

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context};
use proto::participant::{CoordinatorLink, Event, Monitor};
use proto::{CommandBody, Init, LinkConfig, LinkMode, NodeKind, StatusBody};
use serde::{Deserialize, Serialize};

use crate::launch::NodeProcess;
use crate::scene::{Scene, ScheduleKind};
use crate::schedule::implicit::{Estimate, Outputs};
use crate::schedule::{substeps, Action, Scheduler, SchedulerConfig, Topology};
use crate::stability::StabilityMonitor;

/// A run's one-line progress note, shared with whoever shows it.
pub type ProgressNote = std::sync::Arc<std::sync::Mutex<String>>;

/// How to run.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// Validate only: start the nodes, let them read their tables, report limits, stop.
    pub check_only: bool,
    /// A zenoh configuration file for the coordinator (client to a router, TLS, ...). Nodes
    /// are then expected to be started with a matching configuration (or are external).
    pub zenoh_config: Option<PathBuf>,
    /// Override the output folder.
    pub out_dir: Option<PathBuf>,
    /// Longest wait for nodes to say hello and to initialise.
    pub startup_timeout: Duration,
    /// Show a progress bar.
    pub progress: bool,
    /// Where the run keeps a one-line note of its progress (the window, or a DEM programme's
    /// stage): `cosim study` shows its runs' notes on its own bar.
    pub progress_note: Option<ProgressNote>,
    /// Override the run id (default: scene name + a random suffix).
    pub run_id: Option<String>,
    /// Local runs: the coordinator's own endpoint (default: a free loopback port).
    pub listen: Option<String>,
    /// Nodes started by someone else (other machines, your own solver): not launched.
    pub external: Vec<String>,
    /// Continue from this checkpoint (its folder and the coordinator's state there).
    pub resume: Option<(PathBuf, crate::checkpoint::CheckpointState)>,
    /// A new run into a folder that holds an earlier run's files clears it first (else it
    /// is refused).
    pub overwrite: bool,
    /// Threads of each launched node's pool (`RAYON_NUM_THREADS` in its environment, unless
    /// the user's shell sets it; a DEM scene's `dem.threads` still wins): `cosim study --jobs`
    /// shares the cores between its runs instead of starting every pool on all of them.
    pub node_threads: Option<usize>,
}

impl Default for RunOptions {
    fn default() -> Self {
        RunOptions {
            check_only: false,
            zenoh_config: None,
            out_dir: None,
            startup_timeout: Duration::from_secs(120),
            progress: true,
            progress_note: None,
            run_id: None,
            listen: None,
            external: Vec::new(),
            resume: None,
            overwrite: false,
            node_threads: None,
        }
    }
}

/// Per-node figures in the summary.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct NodeSummary {
    pub limits: BTreeMap<String, f64>,
    pub warnings: Vec<String>,
    pub results: BTreeMap<String, f64>,
    pub compute_s: f64,
    pub wait_s: f64,
    /// Of `compute_s`, the time after the node's interface data left in each window (its
    /// outputs and monitor values: off the critical path, PROTOCOL.md `window_done`).
    #[serde(default)]
    pub after_output_s: f64,
    pub software: String,
    /// The features its `hello` named (e.g. `queued_commands`: it accepts windows announced
    /// ahead).
    #[serde(default)]
    pub capabilities: Vec<String>,
}

/// Wall time split like Ullrich's tables 5.3/6.2.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Timing {
    pub total_wall_s: f64,
    pub startup_s: f64,
    pub windows_wall_s: f64,
    pub shutdown_s: f64,
    pub dem_compute_s: f64,
    /// Sum over the FEM nodes.
    pub fem_compute_s: f64,
    /// The windows' compute on the critical path, summed per window: DEM + the slowest FEM
    /// node (the FEM nodes of several structures compute at the same time), or the larger of
    /// the two when the schedule runs them concurrently). In serial schedules the nodes'
    /// bookkeeping after their data (`after_output_s` of PROTOCOL.md) overlaps the partner's
    /// compute: with windows announced ahead both tails are off the path (never below either
    /// node's whole compute), in lockstep only the smaller of the two.
    #[serde(default)]
    pub critical_path_s: f64,
    /// Windows wall time − the critical path: transport, waiting, coordinator.
    pub coupling_overhead_s: f64,
    pub coupling_overhead_fraction: f64,
}

/// `summary.json`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Summary {
    pub scene: String,
    pub scene_file: String,
    pub run_id: String,
    /// `running` (while it runs, or a run that died without a word), `completed`, `checked`,
    /// `unstable`, `interrupted` or `failed`.
    pub status: String,
    pub error: Option<String>,
    pub schedule: String,
    pub coupling_window_s: f64,
    pub dem_substeps: u32,
    pub windows_planned: u64,
    pub windows_done: u64,
    pub simulated_time_s: f64,
    pub timing: Timing,
    pub nodes: BTreeMap<String, NodeSummary>,
    /// The scene's result quantities, `<node>.<name>`.
    pub results: BTreeMap<String, f64>,
    pub warnings: Vec<String>,
    /// The scene compared with the known stability limits before the first window.
    #[serde(default)]
    pub checks: Vec<crate::limits::Finding>,
    /// The run continued from the checkpoint after this window (`cosim resume`).
    pub resumed_after_window: Option<u64>,
    /// How many times the run was resumed; the timing adds up every part's time that
    /// counts (up to the checkpoint each part was resumed from).
    #[serde(default)]
    pub resumes: u32,
    /// The interface energy audit, per interface (docs/coupling.md, "Energy audit").
    #[serde(default)]
    pub interface_work: BTreeMap<String, InterfaceWork>,
    /// Implicit schedule: coupling iterations over the run, the most in one window, and the
    /// windows that ended unconverged (`continue_unconverged`).
    #[serde(default)]
    pub coupling_iterations: u64,
    #[serde(default)]
    pub max_window_iterations: u32,
    #[serde(default)]
    pub unconverged_windows: Vec<u64>,
    /// Adaptive windows: the shortest and longest window used and how often the length
    /// changed (each change is in the log; windows.csv has every window's `window_s`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub adaptive_windows: Option<AdaptiveWindows>,
    /// Windows the coordinator announced beyond the running one (`coupling.lookahead`, or 0
    /// where the schedule, a node or the DEM's programme needs lockstep).
    #[serde(default)]
    pub lookahead: u64,
    /// Windows whose commands went out before the window before them was complete.
    #[serde(default)]
    pub windows_announced_ahead: u64,
    /// The coordinator asked for zenoh's low-latency links (one host, shared memory:
    /// proto/PROTOCOL.md §1); the nodes it starts decide the same way.
    #[serde(default)]
    pub lowlatency_links: bool,
}

#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct AdaptiveWindows {
    pub shortest_s: f64,
    pub longest_s: f64,
    pub changes: u64,
}

/// The work of one interface's forces on its structure, summed over the windows, as each side
/// computed it: the DEM Σ_steps Δt Σ_nodes f·v on the mesh motion it was given, the FEM f·Δx
/// over its step with the forces it holds. `dem_j − fem_j` is the energy the coupling
/// created (> 0) or lost (< 0) at the interface.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct InterfaceWork {
    pub dem_j: f64,
    pub fem_j: f64,
    /// Σ (dem − fem) over the windows: the coupling's energy error.
    pub energy_error_j: f64,
    /// The largest |dem − fem| of one window.
    pub max_window_error_j: f64,
    /// Windows where both sides reported.
    pub windows: u64,
    /// The window where the mismatch's growth raised the early warning, if it did.
    #[serde(default)]
    pub growth_warning_window: Option<u64>,
}

impl InterfaceWork {
    /// One window's work as the DEM (`dem`) and the FEM (`fem`) computed it.
    fn add(&mut self, dem: f64, fem: f64) {
        self.dem_j += dem;
        self.fem_j += fem;
        self.energy_error_j += dem - fem;
        self.max_window_error_j = self.max_window_error_j.max((dem - fem).abs());
        self.windows += 1;
    }
}

fn make_run_id(name: &str) -> String {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.subsec_nanos())
        .unwrap_or(0);
    let tag = (nanos ^ (std::process::id() << 8)) & 0xff_ffff;
    let base: String = name.chars().take(40).collect();
    format!("{base}-{tag:06x}")
}

struct Run<'a> {
    scene: &'a Scene,
    link: CoordinatorLink,
    nodes: Vec<NodeProcess>,
    summary: Summary,
    out_dir: PathBuf,
    /// Nodes that have left or whose process exited, with when and how.
    gone: BTreeMap<String, (Instant, String)>,
    /// Nodes that reported `stopped` (they may leave).
    stopped: std::collections::BTreeSet<String>,
    /// Nodes whose `hello` was accepted: a status of another protocol version from one of
    /// them afterwards is not theirs (a stray or hostile sender) and is only logged.
    greeted: std::collections::BTreeSet<String>,
    /// When the windows (of this process) began, and the windows' wall time of the run
    /// before a resume.
    windows_started: Instant,
    windows_wall_base: f64,
    /// When this process began the run, and the total and start-up wall time of the parts
    /// before a resume.
    started: Instant,
    total_wall_base: f64,
    startup_base: f64,
    /// SIGINT / SIGTERM (crate::interrupt).
    signals: crate::interrupt::Watch,
    /// Implicit schedules: the reliable tap on the users' forces.
    tap: Option<proto::participant::DataTap<proto::InterfaceForces>>,
    /// The concurrent implicit scheme's tap on the providers' kinematics.
    kinematics_tap: Option<proto::participant::DataTap<proto::InterfaceKinematics>>,
    /// While windows run, the first signal is kept here and acted on at the window's end.
    defer_interrupt: bool,
    pending_interrupt: Option<i32>,
    /// When the coordinator last heard from a node or said it was still waiting (a long wait
    /// is reported every [`WAITING_NOTICE`], or every quarter of `coupling.window_timeout`
    /// if that is shorter).
    last_heard: Instant,
    /// A resumed run's folder holds another text of its scene (a settings-neutral edit):
    /// the next checkpoint writes this one there.
    stale_scene_text: bool,
}

/// How often a long wait for the nodes is reported in the log.
const WAITING_NOTICE: Duration = Duration::from_secs(60);

impl Run<'_> {
    /// The kind the scene gives node `name`.
    fn kind_of(&self, name: &str) -> Option<NodeKind> {
        self.scene
            .nodes
            .iter()
            .find(|n| n.id == name)
            .map(|n| n.kind)
    }

    fn node_mut(&mut self, name: &str) -> Option<&mut NodeProcess> {
        self.nodes.iter_mut().find(|n| n.name == name)
    }

    /// Next event; dead processes and departed nodes are errors naming the node (after a
    /// short grace, so that a node's own `error` or `stopped` message sent just before it
    /// left is read first).
    async fn next(
        &mut self,
        deadline: Instant,
        what: &str,
        window: Option<u64>,
    ) -> anyhow::Result<Event> {
        const GRACE: Duration = Duration::from_millis(300);
        loop {
            if let Some(sig) = self.signals.poll() {
                if self.defer_interrupt && self.pending_interrupt.is_none() {
                    eprintln!(
                        "\n{}: stopping after the windows already announced{} (again to stop at once)",
                        crate::interrupt::signal_name(sig),
                        if self.scene.checkpoints() {
                            ", after a checkpoint"
                        } else {
                            ""
                        }
                    );
                    self.pending_interrupt = Some(sig);
                } else {
                    return Err(crate::interrupt::Interrupted { signal: sig }.into());
                }
            }
            for n in &mut self.nodes {
                if !self.stopped.contains(&n.name) && !self.gone.contains_key(&n.name) {
                    if let Some(msg) = n.exited() {
                        self.gone.insert(n.name.clone(), (Instant::now(), msg));
                    }
                }
            }
            let overdue = self
                .gone
                .iter()
                .find(|(node, (t, _))| !self.stopped.contains(*node) && t.elapsed() > GRACE)
                .map(|(node, (_, msg))| (node.clone(), msg.clone()));
            if let Some((node, msg)) = overdue {
                let detail = if msg.is_empty() {
                    self.node_mut(&node)
                        .map(
                            |n| match (n.exited(), n.child.as_ref().and_then(|c| c.id())) {
                                (Some(exit), _) => exit,
                                (None, Some(pid)) => format!(
                                "its liveliness token disappeared but its process ({pid}) still \
                                 runs: its link closed (silent for longer than the links' lease, \
                                 or the connection failed){}",
                                n.log_tail()
                            ),
                                (None, None) => String::new(),
                            },
                        )
                        .unwrap_or_default()
                } else {
                    msg
                };
                bail!(
                    "node `{node}` left the run{} while the coordinator waited for {what}{}",
                    window
                        .map(|w| format!(" at window {w}"))
                        .unwrap_or_default(),
                    if detail.is_empty() {
                        String::new()
                    } else {
                        format!(": {detail}")
                    }
                );
            }
            let left = deadline.saturating_duration_since(Instant::now());
            let notice =
                WAITING_NOTICE.min(Duration::from_secs_f64(0.25 * self.scene.window_timeout));
            if self.last_heard.elapsed() >= notice && !left.is_zero() {
                tracing::info!(
                    "still waiting for {what}: no message for {:.1} s, the run stops if none \
                     comes within {:.1} s",
                    self.last_heard.elapsed().as_secs_f64(),
                    left.as_secs_f64()
                );
                self.last_heard = Instant::now();
            }
            if left.is_zero() {
                bail!(
                    "timed out waiting for {what} (a window may take coupling.window_timeout \
                     = {} s: raise it if the nodes need longer on this machine)",
                    self.scene.window_timeout
                );
            }
            match self
                .link
                .next_event(left.min(Duration::from_millis(100)), what)
                .await
            {
                Ok(Event::Left(node)) if self.nodes.iter().any(|n| n.name == node) => {
                    if !self.stopped.contains(&node) {
                        self.gone
                            .entry(node)
                            .or_insert((Instant::now(), String::new()));
                    }
                }
                Ok(Event::Status(st)) if matches!(st.body, StatusBody::Stopped { .. }) => {
                    self.last_heard = Instant::now();
                    self.stopped.insert(st.node.clone());
                    return Ok(Event::Status(st));
                }
                Ok(Event::Status(st)) => {
                    self.last_heard = Instant::now();
                    if let StatusBody::Error {
                        code,
                        message,
                        window: w,
                    } = &st.body
                    {
                        let at = w
                            .or(window)
                            .map(|w| format!(" at window {w}"))
                            .unwrap_or_default();
                        if *code == proto::ErrorCode::Unstable {
                            self.summary.status = "unstable".into();
                        }
                        bail!(
                            "node `{}` reported a {code:?} error{at}: {message}",
                            st.node
                        );
                    }
                    return Ok(Event::Status(st));
                }
                Ok(Event::WrongVersion {
                    node: Some(node),
                    got,
                    expected,
                }) if self.nodes.iter().any(|n| n.name == node)
                    && !self.greeted.contains(&node) =>
                {
                    bail!(
                        "node `{node}` speaks protocol version {got}; this coordinator speaks version {expected} (proto/PROTOCOL.md §9 lists the changes): update the node"
                    );
                }
                Ok(Event::WrongVersion {
                    node,
                    got,
                    expected,
                }) => {
                    tracing::warn!(
                        "refused a status message of node `{}`: it speaks protocol version {got}, this coordinator speaks version {expected}",
                        node.unwrap_or_default()
                    );
                }
                Ok(Event::Rejected { key, error }) => {
                    tracing::warn!("refused a message on `{key}`: {error}");
                }
                Ok(ev) => {
                    self.last_heard = Instant::now();
                    return Ok(ev);
                }
                Err(proto::ProtoError::Timeout { .. }) => continue,
                Err(e) => return Err(e.into()),
            }
        }
    }

    async fn broadcast(&mut self, body: CommandBody) -> anyhow::Result<()> {
        let names: Vec<String> = self.nodes.iter().map(|n| n.name.clone()).collect();
        for n in names {
            self.link.send(&n, body.clone()).await?;
        }
        Ok(())
    }

    /// Hello from every node, then `init`, then `ready` (or the node's scene error).
    async fn start(&mut self, check_only: bool, timeout: Duration) -> anyhow::Result<()> {
        let deadline = Instant::now() + timeout;
        let mut waiting: Vec<String> = self.nodes.iter().map(|n| n.name.clone()).collect();
        while !waiting.is_empty() {
            let what = format!("hello from {}", waiting.join(", "));
            if let Event::Status(st) = self.next(deadline, &what, None).await? {
                if let StatusBody::Hello(h) = &st.body {
                    match self.kind_of(&st.node) {
                        Some(k) if k == h.kind => {}
                        Some(k) => bail!(
                            "node `{}` says it is a {} node; the scene makes it a {k} node",
                            st.node,
                            h.kind
                        ),
                        None => bail!(
                            "node `{}` ({} node) is not a node of the scene",
                            st.node,
                            h.kind
                        ),
                    }
                    tracing::info!(node = %st.node, "hello from {} (pid {})", h.software, h.pid);
                    self.greeted.insert(st.node.clone());
                    let ns = self.summary.nodes.entry(st.node.clone()).or_default();
                    ns.software = h.software.clone();
                    ns.capabilities = h.capabilities.clone();
                    waiting.retain(|n| n != &st.node);
                }
            }
        }
        let names: Vec<String> = self.nodes.iter().map(|n| n.name.clone()).collect();
        for name in names {
            // every node reads the scene's table of its id
            let init = Init {
                scene_path: self.scene.path.display().to_string(),
                scene_toml: self.scene.text.clone(),
                table: name.clone(),
                out_dir: self.out_dir.display().to_string(),
                interfaces: self.scene.interfaces.clone(),
                check_only,
                trace: self.scene.trace_interfaces,
            };
            self.link.send(&name, CommandBody::Init(init)).await?;
        }
        let mut waiting: Vec<String> = self.nodes.iter().map(|n| n.name.clone()).collect();
        while !waiting.is_empty() {
            let what = format!("`ready` from {}", waiting.join(", "));
            if let Event::Status(st) = self.next(deadline, &what, None).await? {
                if let StatusBody::Ready { limits, warnings } = st.body {
                    for w in &warnings {
                        tracing::warn!(node = %st.node, "{w}");
                        self.summary.warnings.push(format!("{}: {w}", st.node));
                    }
                    let s = self.summary.nodes.entry(st.node.clone()).or_default();
                    s.limits = limits;
                    s.warnings = warnings;
                    waiting.retain(|n| n != &st.node);
                }
            }
        }
        Ok(())
    }

    /// Compares the scene with the known limits (crate::limits); a refusal stops the nodes and
    /// fails the run before its first window, unless `coupling.allow_beyond_limits`.
    async fn check_limits(&mut self, check_only: bool) -> anyhow::Result<()> {
        let facts = crate::limits::SceneFacts::from(self.scene);
        let dem = self
            .scene
            .dem_node()
            .and_then(|d| self.summary.nodes.get(d))
            .map(|n| &n.limits);
        let fems: Vec<&str> = self.scene.fem_nodes().collect();
        let mut findings = Vec::new();
        if fems.is_empty() {
            findings = crate::limits::assess(&facts, dem, None);
        }
        for (i, fem) in fems.iter().enumerate() {
            let limits = self.summary.nodes.get(*fem).map(|n| &n.limits);
            for mut f in crate::limits::assess(&facts, dem, limits) {
                // the DEM's own limits once; the rest per structure when there are several
                let dem_only = f.limit.starts_with("DEM ");
                if dem_only && i > 0 {
                    continue;
                }
                if !dem_only && fems.len() > 1 {
                    f.limit = format!("{} (node `{fem}`)", f.limit);
                }
                findings.push(f);
            }
        }
        let mut refusals = Vec::new();
        for f in &findings {
            match f.level {
                crate::limits::Level::Info => tracing::info!("limit check: {f}"),
                crate::limits::Level::Warn => {
                    tracing::warn!("{f}");
                    self.summary.warnings.push(f.to_string());
                }
                crate::limits::Level::Refuse if self.scene.allow_beyond_limits => {
                    tracing::warn!("{f} (run anyway: coupling.allow_beyond_limits = true)");
                    self.summary.warnings.push(f.to_string());
                }
                crate::limits::Level::Refuse => refusals.push(f.to_string()),
            }
        }
        self.summary.checks = findings;
        if refusals.is_empty() {
            return Ok(());
        }
        if !check_only {
            let _ = self
                .stop("the scene is beyond a stability limit", false)
                .await;
        }
        bail!(
            "{}: the scene is beyond a stability limit (set coupling.allow_beyond_limits = true to run anyway):\n  {}",
            self.scene.path.display(),
            refusals.join("\n  ")
        )
    }

    fn windows_wall(&self) -> f64 {
        self.windows_wall_base + self.windows_started.elapsed().as_secs_f64()
    }

    /// The run's wall time so far, the parts before a resume included.
    fn total_wall(&self) -> f64 {
        self.total_wall_base + self.started.elapsed().as_secs_f64()
    }

    /// n^D = Δt^C / Δt^D from the DEM node's `time_step` (1 without a DEM).
    fn dem_substeps(&self) -> anyhow::Result<u32> {
        let Some(dem) = self.scene.dem_node() else {
            return Ok(1);
        };
        let dt = self.limit(dem, "time_step").ok_or_else(|| {
            anyhow!("the DEM node `{dem}` did not report its `time_step` in `ready`")
        })?;
        substeps(self.scene.window, dt)
            .map_err(|e| anyhow!("{}: coupling.window: {e}", self.scene.path.display()))
    }

    /// The node that publishes `kind` (`forces` or `kinematics`) data of `interface`: forces
    /// come from its users (the DEM), kinematics from its provider.
    fn sender_of(&self, interface: &str, kind: &str) -> String {
        let decl = self.scene.interfaces.iter().find(|i| i.name == interface);
        match (decl, kind) {
            (Some(d), "kinematics") => d.provider.clone(),
            (Some(d), _) => d.users.join(", "),
            (None, _) => "unknown".into(),
        }
    }

    /// [`Self::sender_of`] from a data key `cosim/<run>/iface/<name>/<kind>`.
    fn sender_of_key(&self, key: &str) -> String {
        let mut parts = key.rsplit('/');
        let kind = parts.next().unwrap_or_default();
        let interface = parts.next().unwrap_or_default();
        self.sender_of(interface, kind)
    }

    /// The tightest estimated window limit of the scene's schedule over its structures
    /// (limits.rs, from the nodes' `ready` numbers), when known.
    fn tightest_window_limit(&self, scene: &Scene) -> Option<f64> {
        let dem_limits = scene
            .dem_node()
            .and_then(|d| self.summary.nodes.get(d))
            .map(|n| n.limits.clone())
            .unwrap_or_default();
        scene
            .fem_nodes()
            .filter_map(|f| self.summary.nodes.get(f))
            .filter_map(|n| crate::limits::window_limit(scene.schedule, &dem_limits, &n.limits))
            .fold(None, |a: Option<f64>, b| Some(a.map_or(b, |a| a.min(b))))
    }

    fn limit(&self, node: &str, key: &str) -> Option<f64> {
        self.summary
            .nodes
            .get(node)
            .and_then(|n| n.limits.get(key))
            .copied()
    }

    /// Windows to announce ahead: the scene's `coupling.lookahead`, unless a node does not
    /// queue commands (its `hello` lacks `queued_commands`: e.g. an older external solver) or
    /// the DEM runs a programme that ends the run by itself (the nodes would run past its
    /// end). The scheduler further allows it only for explicit schedules with fixed windows.
    fn lookahead(&self) -> u64 {
        let wanted = self.scene.lookahead;
        if wanted == 0 {
            return 0;
        }
        let lacking: Vec<&str> = self
            .nodes
            .iter()
            .map(|n| n.name.as_str())
            .filter(|n| {
                self.summary.nodes.get(*n).is_none_or(|s| {
                    !s.capabilities
                        .iter()
                        .any(|c| c == proto::CAPABILITY_QUEUED_COMMANDS)
                })
            })
            .collect();
        if !lacking.is_empty() {
            tracing::info!(
                "windows one at a time: node(s) {} do not accept commands ahead (no `{}` in their hello)",
                lacking.join(", "),
                proto::CAPABILITY_QUEUED_COMMANDS
            );
            return 0;
        }
        let programme = self
            .scene
            .dem_node()
            .and_then(|d| self.limit(d, "programme_stages"))
            .is_some_and(|n| n > 0.0);
        if programme {
            tracing::info!(
                "windows one at a time: the DEM's programme ends the run after the window it finishes in"
            );
            return 0;
        }
        wanted
    }

    async fn windows(
        &mut self,
        monitor: &Monitor,
        progress: bool,
        note: Option<&ProgressNote>,
        resume: Option<(PathBuf, crate::checkpoint::CheckpointState)>,
    ) -> anyhow::Result<()> {
        let scene = self.scene;
        self.summary.dem_substeps = self.dem_substeps()?;
        let topology = Topology {
            dem: scene.dem_node().map(String::from),
            fems: scene.fem_nodes().map(String::from).collect(),
        };
        let timeout = Duration::from_secs_f64(scene.window_timeout);
        // every interface's node count (the implicit scheme's vectors, its forces' sizes) and
        // size (the drift check: the bounding-box diagonal)
        let mut meshes: Vec<(String, usize, f64)> = Vec::new();
        let mut positions = Vec::new();
        for iface in &scene.interfaces {
            let mesh = self.link.read_mesh(&iface.name, timeout).await?;
            let size = crate::stability::bounding_diagonal(mesh.positions.as_slice());
            meshes.push((iface.name.clone(), mesh.num_nodes(), size));
            positions.extend_from_slice(mesh.positions.as_slice());
        }
        // adaptive windows: the limits the controller keeps, from the nodes' `ready` numbers
        // (the tightest structure's stiffness limit)
        let adaptive = scene.adaptive.clone().map(|settings| {
            let limits = crate::schedule::adaptive::Limits {
                loaded: self.tightest_window_limit(scene),
                radius_min: scene
                    .dem_node()
                    .and_then(|d| self.limit(d, "particle_radius_min")),
            };
            (settings, limits, scene.end_time)
        });
        let lookahead = self.lookahead();
        let scheduler = Scheduler::new(SchedulerConfig {
            kind: scene.schedule,
            window: scene.window,
            windows: scene.windows,
            topology,
            steady_kinetic_energy: scene.steady_kinetic_energy,
            steady_windows: scene.steady_windows,
            implicit: scene.implicit.clone(),
            interfaces: meshes
                .iter()
                .map(|(name, nodes, _)| (name.clone(), *nodes))
                .collect(),
            positions,
            adaptive,
            lookahead,
            checkpoint_every: scene.checkpoint_every,
        })
        .map_err(|e| anyhow!(e))?;
        let implicit = scene.implicit.is_some();
        let csv_path = self.out_dir.join("windows.csv");
        // `dem_compute_s` (the DEM node's), `fem_compute_s` (the sum over the FEM nodes), and
        // with several structures one `<node>_compute_s` column per FEM node
        let fem_ids: Vec<String> = scene.fem_nodes().map(String::from).collect();
        let per_structure: Vec<String> = if fem_ids.iter().any(|f| f != "fem") {
            fem_ids.clone()
        } else {
            Vec::new()
        };
        // the interface energy audit: per interface the work of its forces on the structure
        // in the window as the DEM and the FEM computed it, and the FEM's work of the forces it
        // received over the displacement they were computed on
        let iface_names: Vec<String> = scene.interfaces.iter().map(|i| i.name.clone()).collect();
        let header = format!(
            "window,t_end_s,wall_s,dem_compute_s,fem_compute_s,{}overhead_s,dem_kinetic_energy_j{}{}",
            per_structure
                .iter()
                .map(|n| format!("{n}_compute_s,"))
                .collect::<String>(),
            iface_names
                .iter()
                .map(|n| format!(
                    ",interface_work_dem.{n}_j,interface_work_fem.{n}_j,interface_work_received.{n}_j"
                ))
                .collect::<String>(),
            match (implicit, scene.adaptive.is_some()) {
                (true, true) => ",iterations,residual,window_s",
                (true, false) => ",iterations,residual",
                (false, true) => ",window_s",
                (false, false) => "",
            }
        );
        let (mut scheduler, mut stability, mut actions, done_rows) = match resume {
            None => {
                let mut scheduler = scheduler;
                let actions = scheduler.start();
                let mut stability = StabilityMonitor::new(scene.max_force_growth);
                // adaptive: the longest window the controller may choose
                let longest = scene
                    .adaptive
                    .as_ref()
                    .map_or(scene.window, |a| a.max_window);
                for (_, _, size) in &meshes {
                    stability.mesh_size =
                        Some(stability.mesh_size.map_or(*size, |s: f64| s.min(*size)));
                }
                if matches!(
                    scene.schedule,
                    ScheduleKind::Jit
                        | ScheduleKind::Predictive
                        | ScheduleKind::Concurrent
                        | ScheduleKind::Implicit
                ) {
                    if let Some(r) = scene
                        .dem_node()
                        .and_then(|d| self.limit(d, "particle_radius_min"))
                    {
                        stability.step_limit = Some((longest, r));
                    }
                }
                // how far inside the schedule's estimated limit the (longest) window is
                stability.window_over_limit = self
                    .tightest_window_limit(scene)
                    .filter(|&l| l > 0.0)
                    .map(|l| longest / l);
                (scheduler, stability, actions, String::new())
            }
            Some((dir, state)) => {
                // every node takes its state from the checkpoint ...
                let names: Vec<String> = self.nodes.iter().map(|n| n.name.clone()).collect();
                for n in &names {
                    let path = crate::checkpoint::node_state_path(&dir, n);
                    self.link
                        .send(
                            n,
                            CommandBody::Restore {
                                window: state.window,
                                path: path.display().to_string(),
                            },
                        )
                        .await?;
                }
                self.await_all("`restored`", timeout, |b| {
                    matches!(b, StatusBody::Restored { .. })
                })
                .await?;
                // ... the coordinator too; the data that was in flight is published again
                let mut scheduler = state.scheduler;
                // this run's nodes and scene decide how far ahead it goes
                scheduler.set_lookahead(lookahead, scene.checkpoint_every);
                let actions = scheduler.replay_actions().map_err(|e| anyhow!(e))?;
                let kept: String = std::fs::read_to_string(&csv_path)
                    .unwrap_or_default()
                    .lines()
                    .skip(1)
                    .filter(|l| {
                        l.split(',')
                            .next()
                            .and_then(|w| w.parse::<u64>().ok())
                            .is_some_and(|w| w <= state.window)
                    })
                    .map(|l| format!("{l}\n"))
                    .collect();
                (scheduler, state.stability, actions, kept)
            }
        };
        // what the scheduler allows for this schedule (0 where its windows depend on the reports)
        self.summary.lookahead = scheduler.effective_lookahead();
        self.defer_interrupt = true;
        // a DEM programme ends the run by itself: the bar counts its stages, not the windows
        let mut programme = scene
            .dem_node()
            .and_then(|d| self.limit(d, "programme_stages"))
            .filter(|&n| n >= 1.0)
            .map(|n| crate::programme::ProgrammeProgress::new(&scene.text, n as usize));
        let bar = match &programme {
            Some(p) => programme_bar(progress, p.length()),
            None => {
                let bar = progress_bar(progress, scene.windows, scene.adaptive.is_some());
                bar.set_position(self.summary.windows_done);
                bar
            }
        };
        let mut programme_line: Option<crate::programme::ProgressLine> = None;
        // asked for progress but no terminal to draw it on: a log line every few minutes
        let log_progress = progress && bar.is_hidden();
        let mut last_progress_log = Instant::now();
        let mut csv = std::io::BufWriter::new(
            std::fs::File::create(&csv_path)
                .with_context(|| format!("creating {}", csv_path.display()))?,
        );
        write!(csv, "{header}\n{done_rows}")?;
        csv.flush()?;
        let mut window_start = Instant::now();
        let mut last_checkpoint = Instant::now();
        // this window's compute time per node, end time and DEM kinetic energy
        let mut computed: BTreeMap<String, f64> = BTreeMap::new();
        let mut on_path: BTreeMap<String, f64> = BTreeMap::new();
        let mut row_t_end: Option<f64> = None;
        let mut row_ke: Option<f64> = None;
        // the audit's values of this window: (`dem` | `fem` | `received`, interface) → J
        let mut work: BTreeMap<(&'static str, String), f64> = BTreeMap::new();
        // implicit: this window's iterations and its last residual
        let (mut row_iterations, mut row_residual) = (0u32, 0.0f64);
        // adaptive: this window's length
        let mut row_length = scheduler.window_span().1;
        // `window_done` of windows announced ahead that arrived before the running window
        // was complete: taken in window order
        let mut early: std::collections::VecDeque<proto::Status> = Default::default();
        loop {
            for a in std::mem::take(&mut actions) {
                match a {
                    Action::Send(node, body) => self.link.send(&node, body).await?,
                    Action::Publish {
                        interface,
                        label,
                        estimate: Estimate::Forces(forces),
                    } => {
                        let msg = proto::InterfaceForces {
                            version: proto::PROTOCOL_VERSION,
                            run_id: self.link.keys().run_id().to_string(),
                            interface,
                            window: label.window,
                            iteration: label.iteration,
                            time: scheduler.window_span().0,
                            forces: forces.into(),
                            averaged: true,
                            samples: 1,
                        };
                        self.link.publish_relaxed(&msg, timeout).await?;
                    }
                    Action::Publish {
                        interface,
                        label,
                        estimate:
                            Estimate::Kinematics {
                                positions,
                                velocities,
                            },
                    } => {
                        let msg = proto::InterfaceKinematics {
                            version: proto::PROTOCOL_VERSION,
                            run_id: self.link.keys().run_id().to_string(),
                            interface,
                            window: label.window,
                            iteration: label.iteration,
                            // the estimated end state of the window
                            time: {
                                let (start, length) = scheduler.window_span();
                                start + length
                            },
                            accelerations: vec![0.0; positions.len()].into(),
                            positions: positions.into(),
                            velocities: velocities.into(),
                        };
                        self.link.publish_relaxed_kinematics(&msg, timeout).await?;
                    }
                    Action::NeedOutputs { .. } => {
                        bail!("internal: outputs asked for outside a window's end")
                    }
                    Action::Finish { reason } => {
                        tracing::info!("{reason}");
                        let unconverged = scheduler.unconverged_windows().to_vec();
                        if !unconverged.is_empty() {
                            let w = format!(
                                "implicit coupling: {} window(s) ended unconverged (continue_unconverged = true): {:?}",
                                unconverged.len(),
                                unconverged
                            );
                            tracing::warn!("{w}");
                            self.summary.warnings.push(w);
                        }
                        self.summary.unconverged_windows = unconverged;
                        if let (Some(e), Some(limit)) = (
                            scheduler.unsettled_kinetic_energy(),
                            scene.steady_kinetic_energy,
                        ) {
                            let w = format!(
                                "one-way: the DEM had not settled by end_time = {} (kinetic energy {e:.3e} J, steady below {limit:.3e} J for {} windows): the static FEM solve used the forces of a moving bed; give it a longer end_time",
                                crate::units::format_seconds(scene.end_time),
                                scene.steady_windows
                            );
                            tracing::warn!("{w}");
                            self.summary.warnings.push(w);
                        }
                        bar.finish_and_clear();
                        csv.flush()?;
                        return Ok(());
                    }
                }
            }
            let k = scheduler.window();
            let what = format!(
                "window {k} from {}{}",
                scheduler.pending().collect::<Vec<_>>().join(", "),
                match scheduler.last_issued() {
                    Some(last) if last > k => format!(" (windows up to {last} announced)"),
                    _ => String::new(),
                }
            );
            let buffered = early.iter().position(
                |s| matches!(&s.body, StatusBody::WindowDone { window, .. } if *window == k),
            );
            let ev = match buffered.and_then(|i| early.remove(i)) {
                Some(st) => Event::Status(st),
                None => self.next(Instant::now() + timeout, &what, Some(k)).await?,
            };
            for d in monitor.drain() {
                match d {
                    Ok(d) => {
                        // data from outside a solver is checked at the boundary: a NaN that
                        // arrives is the sender's invalid data, not an instability of the run
                        // (the Rust nodes refuse to publish their own NaNs: proto::participant)
                        if let Some((field, index)) = d.non_finite {
                            bail!(
                                "invalid interface data from the {} node: the {} of interface `{}` for window {} carry a non-finite value ({field}, value {index})",
                                self.sender_of(&d.interface, d.kind),
                                d.kind,
                                d.interface,
                                d.window
                            );
                        }
                        if let Some(bad) = stability.observe(&d) {
                            self.summary.status = "unstable".into();
                            bail!("{bad}");
                        }
                    }
                    // not this run's: refused and logged (PROTOCOL.md §8)
                    Err((key, e @ proto::ProtoError::WrongRun { .. })) => {
                        tracing::warn!("refused a message on `{key}`: {e}")
                    }
                    Err((key, e)) => bail!(
                        "invalid interface data from the {} node on `{key}` (the coordinator at window {k}): {e}",
                        self.sender_of_key(&key)
                    ),
                }
            }
            let Event::Status(st) = ev else { continue };
            if matches!(&st.body, StatusBody::WindowDone { window, .. } if *window > k) {
                early.push_back(st);
                continue;
            }
            let StatusBody::WindowDone {
                window,
                t_end,
                compute_s,
                wait_s,
                monitor: values,
                after_output_s,
            } = st.body
            else {
                tracing::debug!(node = %st.node, "ignoring {:?}", st.body);
                continue;
            };
            let kind = self
                .kind_of(&st.node)
                .ok_or_else(|| anyhow!("unknown node `{}`", st.node))?;
            if let Some((name, v)) = values.iter().find(|(_, v)| !v.is_finite()) {
                self.summary.status = "unstable".into();
                bail!("unstable at window {window} (t = {t_end:.6e} s): node `{}` reports {name} = {v}", st.node);
            }
            let ns = self.summary.nodes.entry(st.node.clone()).or_default();
            ns.compute_s += compute_s;
            ns.wait_s += wait_s;
            // an external node's numbers: negative or not finite counts as none
            let compute_ok = if compute_s.is_finite() {
                compute_s.max(0.0)
            } else {
                0.0
            };
            let after = if after_output_s.is_finite() {
                after_output_s.clamp(0.0, compute_ok)
            } else {
                0.0
            };
            ns.after_output_s += after;
            *computed.entry(st.node.clone()).or_default() += compute_s;
            // the compute up to the node's data message (the bookkeeping after it can overlap
            // the partner's compute)
            *on_path.entry(st.node.clone()).or_default() += compute_ok - after;
            // a static solve does not advance the FEM clock: the window ends at the latest time
            let t_end = row_t_end.unwrap_or(t_end).max(t_end);
            row_t_end = Some(t_end);
            let ke = (kind == NodeKind::Dem)
                .then(|| values.get("kinetic_energy").copied())
                .flatten();
            if ke.is_some() {
                row_ke = ke;
            }
            if kind == NodeKind::Dem {
                if let Some(p) = programme.as_mut() {
                    programme_line = p.update(&values, Instant::now()).or(programme_line);
                }
            }
            for (key, v) in &values {
                let side = match (kind, key.split_once('.')) {
                    (NodeKind::Dem, Some(("interface_work", i))) => Some(("dem", i)),
                    (NodeKind::Fem, Some(("interface_work", i))) => Some(("fem", i)),
                    (NodeKind::Fem, Some(("interface_work_received", i))) => Some(("received", i)),
                    _ => None,
                };
                if let Some((side, iface)) = side {
                    work.insert((side, iface.to_string()), *v);
                }
            }
            scheduler.observe(&st.node, kind == NodeKind::Dem, &values);
            actions = scheduler
                .on_window_done(&st.node, window, ke)
                .map_err(|e| anyhow!(e))?;
            // implicit: every node finished an iteration; its outputs decide what follows
            while let [Action::NeedOutputs { label, positions }] = actions.as_slice() {
                let (label, positions) = (*label, *positions);
                let mut outputs = Outputs::default();
                let tap = self
                    .tap
                    .as_mut()
                    .ok_or_else(|| anyhow!("internal: no forces tap for the implicit schedule"))?;
                for (name, nodes, _) in &meshes {
                    let f = tap.read(name, label, *nodes, timeout).await.map_err(|e| {
                        anyhow!("implicit coupling, interface `{name}`, {label}: {e}")
                    })?;
                    outputs.forces.insert(name.clone(), f.forces.0);
                }
                if positions {
                    let tap = self.kinematics_tap.as_mut().ok_or_else(|| {
                        anyhow!("internal: no kinematics tap for the concurrent implicit schedule")
                    })?;
                    for (name, nodes, _) in &meshes {
                        let k = tap.read(name, label, *nodes, timeout).await.map_err(|e| {
                            anyhow!("implicit coupling, interface `{name}`, {label}: {e}")
                        })?;
                        outputs.positions.insert(name.clone(), k.positions.0);
                    }
                }
                actions = scheduler.on_outputs(&outputs).map_err(|e| anyhow!(e))?;
                for r in scheduler.take_iterations() {
                    tracing::debug!(
                        "window {} iteration {}: residual {:.3e}, ω {:.3}",
                        r.window,
                        r.iteration,
                        r.residual,
                        r.relaxation
                    );
                    row_iterations += 1;
                    row_residual = r.residual;
                    self.summary.coupling_iterations += 1;
                }
            }
            if scheduler.window() != window
                || scheduler.is_done()
                || actions.iter().any(|a| matches!(a, Action::Finish { .. }))
            {
                // the window is complete
                let wall = window_start.elapsed().as_secs_f64();
                let of = |n: &str| computed.get(n).copied().unwrap_or(0.0);
                let dem = scene.dem_node().map(of).unwrap_or(0.0);
                let fem: f64 = fem_ids.iter().map(|f| of(f)).sum();
                let mut line = format!("{window},{t_end:.9e},{wall:.6e},{dem:.6e},{fem:.6e}");
                for n in &per_structure {
                    line.push_str(&format!(",{:.6e}", of(n)));
                }
                // the FEM nodes compute at the same time: the critical path is the DEM's time
                // plus the slowest structure's (concurrent schedules: the larger of the two,
                // each node's next window waiting for its own outputs). In a serial schedule
                // with windows announced ahead both nodes' bookkeeping after their data
                // overlaps the partner's compute (but not their own next window); in lockstep
                // only the first solver's does, and which went first is not known here, so
                // only the smaller of the two tails is taken off (an upper bound of the path)
                let slowest = fem_ids.iter().map(|f| of(f)).fold(0.0f64, f64::max);
                let critical = if scene.concurrent() {
                    dem.max(slowest)
                } else if scheduler.effective_lookahead() > 0 {
                    let path = |n: &str| on_path.get(n).copied().unwrap_or(0.0);
                    let dem_path = scene.dem_node().map(path).unwrap_or(0.0);
                    let fem_path = fem_ids.iter().map(|f| path(f)).fold(0.0f64, f64::max);
                    (dem_path + fem_path).max(dem).max(slowest)
                } else {
                    let tail = |n: &str| (of(n) - on_path.get(n).copied().unwrap_or(0.0)).max(0.0);
                    let dem_tail = scene.dem_node().map(tail).unwrap_or(0.0);
                    let fem_tail = fem_ids
                        .iter()
                        .filter(|f| of(f) == slowest)
                        .map(|f| tail(f))
                        .fold(f64::INFINITY, f64::min);
                    let hidden = dem_tail.min(if fem_tail.is_finite() { fem_tail } else { 0.0 });
                    (dem + slowest - hidden).max(dem).max(slowest)
                };
                self.summary.timing.critical_path_s += critical;
                let mut audit = String::new();
                for name in &iface_names {
                    let get = |side: &'static str| work.get(&(side, name.clone())).copied();
                    for v in [get("dem"), get("fem"), get("received")] {
                        audit.push(',');
                        if let Some(v) = v {
                            audit.push_str(&format!("{v:.9e}"));
                        }
                    }
                    if let (Some(d), Some(f)) = (get("dem"), get("fem")) {
                        if let Some(w) = stability.observe_work(name, window, d, f) {
                            tracing::warn!("{w}");
                            self.summary.warnings.push(w);
                            self.summary
                                .interface_work
                                .entry(name.clone())
                                .or_default()
                                .growth_warning_window = Some(window);
                        }
                        self.summary
                            .interface_work
                            .entry(name.clone())
                            .or_default()
                            .add(d, f);
                    }
                }
                work.clear();
                if implicit {
                    audit.push_str(&format!(",{row_iterations},{row_residual:.3e}"));
                    self.summary.max_window_iterations =
                        self.summary.max_window_iterations.max(row_iterations);
                    row_iterations = 0;
                }
                if scene.adaptive.is_some() {
                    audit.push_str(&format!(",{row_length:.6e}"));
                    let a = self
                        .summary
                        .adaptive_windows
                        .get_or_insert(AdaptiveWindows {
                            shortest_s: row_length,
                            longest_s: row_length,
                            changes: 0,
                        });
                    a.shortest_s = a.shortest_s.min(row_length);
                    a.longest_s = a.longest_s.max(row_length);
                    for c in scheduler.take_window_changes() {
                        tracing::info!(
                            "adaptive window: Δt^C {} → {} from window {} ({})",
                            crate::units::format_seconds(c.from),
                            crate::units::format_seconds(c.to),
                            c.window,
                            c.reason
                        );
                        a.changes += 1;
                    }
                    row_length = scheduler.window_span().1;
                }
                writeln!(
                    csv,
                    "{line},{:.6e},{}{audit}",
                    (wall - critical).max(0.0),
                    row_ke
                        .take()
                        .map(|e| format!("{e:.6e}"))
                        .unwrap_or_default()
                )?;
                computed.clear();
                on_path.clear();
                row_t_end = None;
                csv.flush()?;
                self.summary.windows_done = window + 1;
                self.summary.windows_announced_ahead = scheduler.windows_announced_ahead();
                self.summary.simulated_time_s = t_end;
                // one status line for the study's note and the log: the programme's stage, or
                // the window among all
                let status = match (&programme, &programme_line) {
                    (Some(_), Some(l)) => format!("window {}; {}", window + 1, l.message),
                    (Some(_), None) => format!("window {}", window + 1),
                    (None, _) => format!("window {}/{}", window + 1, scene.windows),
                };
                if let Some(note) = note {
                    *note.lock().unwrap_or_else(|e| e.into_inner()) = status.clone();
                }
                if programme.is_some() {
                    bar.set_position(programme_line.as_ref().map_or(0, |l| l.position));
                    bar.set_message(format!("{status}, t = {t_end:.4e} s"));
                } else {
                    bar.set_position(if scene.adaptive.is_some() {
                        (t_end / scene.end_time * scene.windows as f64).round() as u64
                    } else {
                        window + 1
                    });
                    bar.set_message(format!("t = {t_end:.4e} s"));
                }
                if log_progress && last_progress_log.elapsed() >= crate::study::PROGRESS_LOG_EVERY {
                    tracing::info!("{status}, t = {t_end:.4e} s");
                    last_progress_log = Instant::now();
                }
                let finishing = actions.iter().any(|a| matches!(a, Action::Finish { .. }));
                let due = scene.checkpoint_every > 0 && (window + 1) % scene.checkpoint_every == 0;
                // `checkpoint_wall`: once that much wall time has passed, the windows already
                // announced finish (held), then the checkpoint is written, as for an interrupt
                let wall_due = scene
                    .checkpoint_wall
                    .is_some_and(|w| last_checkpoint.elapsed().as_secs_f64() >= w);
                // a checkpoint is of this window's end only if no node has a later command
                // (the scheduler does not announce past a due checkpoint; an interrupt first
                // lets the windows already announced finish)
                let ahead = scheduler.announced_ahead();
                if (self.pending_interrupt.is_some() || wall_due) && ahead && !finishing {
                    scheduler.hold();
                    window_start = Instant::now();
                    continue;
                }
                if due && ahead && !finishing {
                    bail!("internal: window {window}'s checkpoint is due, but later windows were announced");
                }
                if let Some(sig) = self.pending_interrupt.filter(|_| !finishing) {
                    // a second signal now stops at once, without the checkpoint
                    self.defer_interrupt = false;
                    bar.finish_and_clear();
                    if scene.checkpoints() {
                        self.checkpoint(window, &scheduler, &stability, timeout)
                            .await?;
                        eprintln!(
                            "checkpoint after window {window}: `cosim resume {}` continues the run",
                            self.out_dir.display()
                        );
                    }
                    return Err(crate::interrupt::Interrupted { signal: sig }.into());
                }
                if (due || wall_due) && !finishing {
                    scheduler.release();
                    self.checkpoint(window, &scheduler, &stability, timeout)
                        .await?;
                    last_checkpoint = Instant::now();
                }
                window_start = Instant::now();
            }
        }
    }

    /// Every node writes its state into `dir`; waits until all have.
    async fn snapshot_all(
        &mut self,
        window: u64,
        dir: &Path,
        timeout: Duration,
    ) -> anyhow::Result<()> {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let names: Vec<String> = self.nodes.iter().map(|n| n.name.clone()).collect();
        for n in &names {
            let path = crate::checkpoint::node_state_path(dir, n)
                .display()
                .to_string();
            self.link
                .send(n, CommandBody::Snapshot { window, path })
                .await?;
        }
        self.await_all("`snapshot_done`", timeout, |b| {
            matches!(b, StatusBody::SnapshotDone { .. })
        })
        .await
    }

    /// A consistent checkpoint after `window`: the nodes' states, then the coordinator's.
    async fn checkpoint(
        &mut self,
        window: u64,
        scheduler: &Scheduler,
        stability: &StabilityMonitor,
        timeout: Duration,
    ) -> anyhow::Result<()> {
        let dir = crate::checkpoint::checkpoint_dir(&self.out_dir, window);
        self.snapshot_all(window, &dir, timeout).await?;
        self.summary.timing.windows_wall_s = self.windows_wall();
        self.summary.timing.total_wall_s = self.total_wall();
        let state = crate::checkpoint::CheckpointState {
            window,
            scheduler: scheduler.clone(),
            stability: stability.clone(),
            summary: self.summary.clone(),
            scene_fingerprint: Some(crate::checkpoint::scene_fingerprint(&self.scene.text)),
            settings_fingerprint: crate::checkpoint::settings_fingerprint(&self.scene.text),
        };
        crate::checkpoint::commit(&self.out_dir, &state)?;
        // a run resumed from a scene whose text differs in settings-neutral parts (comments,
        // the checkpoint period): its folder's scene.toml becomes this text once a checkpoint
        // of it exists (before, the older checkpoint still matches the older text)
        if std::mem::take(&mut self.stale_scene_text) {
            let text_path = self.out_dir.join("scene.toml");
            proto::node::write_atomically(&text_path, self.scene.text.as_bytes())
                .with_context(|| format!("writing {}", text_path.display()))?;
        }
        tracing::debug!("checkpoint after window {window}");
        Ok(())
    }

    /// Waits until every node has sent a status matching `is`.
    async fn await_all(
        &mut self,
        what: &str,
        timeout: Duration,
        is: impl Fn(&StatusBody) -> bool,
    ) -> anyhow::Result<()> {
        let deadline = Instant::now() + timeout;
        let mut waiting: Vec<String> = self.nodes.iter().map(|n| n.name.clone()).collect();
        while !waiting.is_empty() {
            let w = format!("{what} from {}", waiting.join(", "));
            if let Event::Status(st) = self.next(deadline, &w, None).await? {
                if is(&st.body) {
                    waiting.retain(|n| n != &st.node);
                }
            }
        }
        Ok(())
    }

    /// `stop` to every node, collect results, wait for the processes.
    async fn stop(&mut self, reason: &str, collect: bool) -> anyhow::Result<()> {
        self.broadcast(CommandBody::Stop {
            reason: reason.to_string(),
        })
        .await?;
        if collect {
            let deadline = Instant::now() + Duration::from_secs(60);
            let mut waiting: Vec<String> = self.nodes.iter().map(|n| n.name.clone()).collect();
            while !waiting.is_empty() {
                let what = format!("`stopped` from {}", waiting.join(", "));
                if let Event::Status(st) = self.next(deadline, &what, None).await? {
                    if let StatusBody::Stopped { results, .. } = st.body {
                        for (k, v) in &results {
                            self.summary.results.insert(format!("{}.{k}", st.node), *v);
                        }
                        self.summary
                            .nodes
                            .entry(st.node.clone())
                            .or_default()
                            .results = results;
                        waiting.retain(|n| n != &st.node);
                    }
                }
            }
        }
        let mut clean = true;
        for n in &mut self.nodes {
            clean &= n.reap(Duration::from_secs(10)).await;
        }
        if !clean && collect {
            bail!("a node did not exit cleanly after `stop`");
        }
        Ok(())
    }
}

/// The run's progress: by window, or (adaptive windows, whose number is not known ahead) by
/// simulated time in steps of the first window.
fn progress_bar(show: bool, windows: u64, adaptive: bool) -> indicatif::ProgressBar {
    if !show {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(windows);
    bar.set_style(
        indicatif::ProgressStyle::with_template(if adaptive {
            "{elapsed_precise} [{bar:40}] {percent}% {msg} (ETA {eta})"
        } else {
            "{elapsed_precise} [{bar:40}] window {pos}/{len} {msg} (ETA {eta})"
        })
        .expect("valid template")
        .progress_chars("=> "),
    );
    bar
}

/// The progress of a run that a DEM programme ends: its stages, each filled by its progress
/// (crate::programme), with the window and time in the message.
fn programme_bar(show: bool, length: u64) -> indicatif::ProgressBar {
    if !show {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(length);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{elapsed_precise} [{bar:40}] {msg}")
            .expect("valid template")
            .progress_chars("=> "),
    );
    bar
}

fn write_summary(out_dir: &Path, summary: &Summary) -> anyhow::Result<PathBuf> {
    let path = out_dir.join("summary.json");
    let text = serde_json::to_string_pretty(summary)? + "\n";
    // temporary file, fsync, rename: a reader (or a crash) never sees half a summary
    proto::node::write_atomically(&path, text.as_bytes())
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(path)
}

/// Runs (or checks) a scene. The summary is written in every case; the error, if any, is
/// both in the summary and returned.
pub async fn run_scene(scene: &Scene, opts: &RunOptions) -> anyhow::Result<Summary> {
    let t0 = Instant::now();
    let out_dir = opts
        .out_dir
        .clone()
        .unwrap_or_else(|| scene.out_dir.clone());
    let what = if opts.check_only {
        "check"
    } else if opts.resume.is_some() {
        "resume"
    } else {
        "run"
    };
    // held until this function returns: no other run writes into the folder meanwhile
    let lock = crate::outdir::lock(&out_dir, &format!("{what} of scene `{}`", scene.name))?;
    if opts.check_only {
        // a check's scratch folder: never another run's (cosim check has no --overwrite)
        crate::outdir::prepare_new(&lock, false).map_err(|e| {
            anyhow!(
                "{e:#}\n(cosim check writes the nodes' scratch output into its --out folder: give an empty or new one, or none)"
            )
        })?;
    } else if opts.resume.is_none() {
        crate::outdir::prepare_new(&lock, opts.overwrite)?;
    }
    let run_id = opts
        .run_id
        .clone()
        .unwrap_or_else(|| make_run_id(&scene.name));
    proto::keys::validate_name("run id", &run_id)?;

    // Local peers: every process listens on its own loopback port and connects explicitly
    // to those started before it (a full mesh without any scouting), with the long local lease
    // the nodes it starts are given too.
    let (coord_link, ports, local_lease) = match (&opts.zenoh_config, &opts.listen) {
        // the file decides the mode (client of a router, or a router itself)
        (Some(cfg), _) => (
            LinkConfig {
                mode: LinkMode::Peer,
                zenoh_config: Some(cfg.clone()),
                ..Default::default()
            },
            None,
            None,
        ),
        (None, Some(endpoint)) => {
            proto::link::validate_endpoint(endpoint)?;
            (
                LinkConfig {
                    listen: vec![endpoint.clone()],
                    ..Default::default()
                },
                Some(endpoint.clone()),
                None,
            )
        }
        (None, None) => {
            let p0 = proto::link::free_loopback_port()?;
            (
                LinkConfig {
                    lease: proto::link::LOCAL_LEASE,
                    ..LinkConfig::loopback_peer(Some(p0), &[])
                },
                Some(format!("tcp/127.0.0.1:{p0}")),
                Some(proto::link::LOCAL_LEASE),
            )
        }
    };
    let link = CoordinatorLink::open(&coord_link, &run_id)
        .await
        .context("opening the coordinator's zenoh session")?;
    // implicit schedules read every iteration's forces: the tap is in place before the nodes
    // (a check too: the DEM's forces have no other subscriber, and a node reports `ready` only
    // once its publishers are matched)
    let tap = match scene.schedule {
        ScheduleKind::Implicit => Some(link.forces_tap().await?),
        _ => None,
    };
    // ... and the concurrent one every iteration's kinematics (their only subscriber)
    let kinematics_tap = match &scene.implicit {
        Some(i) if i.concurrent => Some(link.kinematics_tap().await?),
        _ => None,
    };
    let mut summary = Summary {
        scene: scene.name.clone(),
        scene_file: scene.path.display().to_string(),
        run_id: run_id.clone(),
        status: "running".into(),
        schedule: schedule_name(scene.schedule),
        coupling_window_s: scene.window,
        windows_planned: scene.windows,
        lowlatency_links: link.lowlatency(),
        ..Default::default()
    };
    tracing::debug!(
        "links: {}",
        match summary.lowlatency_links {
            true => "zenoh low-latency, large messages in shared memory",
            false => "zenoh ordinary (COSIM_LOWLATENCY=0, a config file, endpoints off this host, or no room to lock shared memory)",
        }
    );
    let mut nodes = Vec::new();
    let scene_dir = scene
        .path
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_default();
    if let Some(bad) = opts
        .external
        .iter()
        .find(|e| !scene.nodes.iter().any(|n| &n.id == *e))
    {
        let ids: Vec<&str> = scene.nodes.iter().map(|n| n.id.as_str()).collect();
        let e = anyhow!(
            "--external {bad}: the scene has no node `{bad}` (its nodes: {})",
            ids.join(", ")
        );
        summary.status = "failed".into();
        summary.error = Some(format!("{e:#}"));
        write_summary(&out_dir, &summary)?;
        return Err(e);
    }
    let mut started: Vec<String> = ports.iter().cloned().collect();
    for scene_node in &scene.nodes {
        let (kind, id) = (scene_node.kind, scene_node.id.as_str());
        let launch = Some(&scene_node.launch);
        let (listen, connect) = if ports.is_some() {
            let p = proto::link::free_loopback_port()?;
            (vec![format!("tcp/127.0.0.1:{p}")], started.clone())
        } else {
            (Vec::new(), Vec::new())
        };
        let external = crate::scene::NodeLaunch {
            kind: None,
            command: None,
            external: true,
        };
        let launch = if opts.external.iter().any(|n| n == id) {
            Some(&external)
        } else {
            launch
        };
        let node = match NodeProcess::spawn(
            kind,
            id,
            launch,
            &run_id,
            listen.clone(),
            connect,
            &out_dir.join("logs"),
            &scene_dir,
            local_lease,
            opts.node_threads,
        ) {
            Ok(n) => n,
            Err(e) => {
                summary.status = "failed".into();
                summary.error = Some(format!("{e:#}"));
                write_summary(&out_dir, &summary)?;
                return Err(e);
            }
        };
        if node.child.is_none() {
            eprintln!(
                "waiting for the external {kind} node `{id}`: start it with --run-id {run_id} --node {id}{}{}",
                node.connect.iter().map(|c| format!(" --connect {c}")).collect::<String>(),
                match local_lease {
                    Some(l) => format!(
                        " and {}={} in its environment (this run's links have a {} s lease)",
                        proto::link::LEASE_ENV,
                        l.as_millis(),
                        l.as_secs()
                    ),
                    None => String::new(),
                }
            );
        }
        started.extend(listen);
        nodes.push(node);
    }
    let mut run = Run {
        scene,
        link,
        nodes,
        summary,
        out_dir: out_dir.clone(),
        gone: BTreeMap::new(),
        stopped: Default::default(),
        greeted: Default::default(),
        windows_started: Instant::now(),
        windows_wall_base: 0.0,
        started: t0,
        total_wall_base: 0.0,
        startup_base: 0.0,
        signals: crate::interrupt::Watch::new(),
        tap,
        kinematics_tap,
        defer_interrupt: false,
        pending_interrupt: None,
        last_heard: Instant::now(),
        stale_scene_text: opts.resume.is_some()
            && std::fs::read_to_string(out_dir.join("scene.toml")).is_ok_and(|t| t != scene.text),
    };
    if let Some((_, state)) = &opts.resume {
        // the run continues: its summary so far comes from the checkpoint
        let mut restored = state.summary.clone();
        restored.run_id = run_id.clone();
        restored.status = "running".into();
        restored.error = None;
        restored.resumed_after_window = Some(state.window);
        restored.resumes += 1;
        run.windows_wall_base = restored.timing.windows_wall_s;
        // checkpoints written before the total was recorded there: at least the windows
        run.total_wall_base = restored
            .timing
            .total_wall_s
            .max(restored.timing.startup_s + restored.timing.windows_wall_s);
        run.startup_base = restored.timing.startup_s;
        for (name, n) in &run.summary.nodes {
            restored.nodes.entry(name.clone()).or_default().software = n.software.clone();
        }
        run.summary = restored;
    } else if !opts.check_only {
        // what `cosim resume` needs
        std::fs::write(out_dir.join("scene.toml"), &scene.text)
            .with_context(|| format!("writing {}", out_dir.join("scene.toml").display()))?;
        crate::checkpoint::write_json(
            &out_dir.join("run.json"),
            &crate::checkpoint::RunRecord {
                scene_file: scene.path.clone(),
                run_id: run_id.clone(),
                zenoh_config: opts.zenoh_config.clone(),
            },
        )?;
    }
    if !opts.check_only {
        // `running` until the run ends: a folder never shows an earlier run's status
        write_summary(&out_dir, &run.summary)?;
    }
    let result: anyhow::Result<()> = async {
        run.start(opts.check_only, opts.startup_timeout).await?;
        run.summary.timing.startup_s = run.startup_base + t0.elapsed().as_secs_f64();
        run.check_limits(opts.check_only).await?;
        if opts.check_only {
            if scene.has_dem {
                run.summary.dem_substeps = run.dem_substeps()?;
            }
            run.stop("check done", true).await?;
            run.summary.status = "checked".into();
            return Ok(());
        }
        let monitor = run.link.monitor().await?;
        run.windows_started = Instant::now();
        run.windows(
            &monitor,
            opts.progress,
            opts.progress_note.as_ref(),
            opts.resume.clone(),
        )
        .await?;
        run.summary.timing.windows_wall_s = run.windows_wall();
        if scene.final_state {
            let last = run.summary.windows_done.saturating_sub(1);
            let dir = run.out_dir.join("final");
            run.snapshot_all(last, &dir, Duration::from_secs_f64(scene.window_timeout))
                .await?;
        }
        let ts = Instant::now();
        run.stop("end of the schedule", true).await?;
        run.summary.timing.shutdown_s = ts.elapsed().as_secs_f64();
        run.summary.status = "completed".into();
        Ok(())
    }
    .await;
    if let Err(e) = &result {
        let interrupted = e.downcast_ref::<crate::interrupt::Interrupted>().is_some();
        if interrupted {
            run.summary.status = "interrupted".into();
        } else if run.summary.status != "unstable" {
            run.summary.status = "failed".into();
        }
        run.summary.error = Some(format!("{e:#}"));
        // Best effort: tell the others to stop, then make sure no process is left behind.
        let reason = if interrupted {
            "the run was interrupted"
        } else {
            "the run failed"
        };
        let _ = tokio::time::timeout(Duration::from_secs(5), run.stop(reason, false)).await;
        for n in &mut run.nodes {
            if let Some(c) = n.child.as_mut() {
                let _ = c.kill().await;
            }
        }
    }
    let total_wall = run.total_wall();
    let mut summary = run.summary;
    let compute = |id: &str| summary.nodes.get(id).map(|n| n.compute_s).unwrap_or(0.0);
    let dem = scene.dem_node().map(compute).unwrap_or(0.0);
    let fem: f64 = scene.fem_nodes().map(compute).sum();
    let t = &mut summary.timing;
    t.total_wall_s = total_wall;
    t.dem_compute_s = dem;
    t.fem_compute_s = fem;
    t.coupling_overhead_s = (t.windows_wall_s - t.critical_path_s).max(0.0);
    t.coupling_overhead_fraction = if t.windows_wall_s > 0.0 {
        t.coupling_overhead_s / t.windows_wall_s
    } else {
        0.0
    };
    let _ = run.link.close().await;
    write_summary(&out_dir, &summary)?;
    drop(lock);
    result.map(|_| summary)
}

/// The schedule's name as written in scene files.
pub fn schedule_name(k: ScheduleKind) -> String {
    serde_json::to_value(k)
        .ok()
        .and_then(|v| v.as_str().map(String::from))
        .unwrap_or_default()
}
