//! Scene files (TOML): what exists in a run. The coordinator reads `[scene]`, `[coupling]`,
//! `[output]` and `[nodes]`; every other top-level table belongs to a solver node of that id —
//! `[dem]` and `[fem]`, and further structures declared in `[nodes.<id>]` with a `kind` —
//! which parses and validates it (the nodes get the whole file in their `init` command and
//! report errors with line numbers of this file). Every error names the file, line and field.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use proto::{InterfaceDecl, InterfaceKind, NodeKind};
use serde::Deserialize;
use toml::Spanned;

use crate::units::{format_seconds, Joules, Seconds};

/// Most coupling windows a scene may have: each is a row of windows.csv and a round of
/// messages; beyond this the scene is almost certainly a typo (a window in s meant as ms).
pub const MAX_WINDOWS: f64 = 1e8;

pub use scenefile::line_col;
/// A scene error with its place in the file (line 0: the file as a whole, e.g. unreadable):
/// the one scene error type of every crate.
pub use scenefile::SceneError;

/// The coupling schedule (Ullrich ch. 3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ScheduleKind {
    /// A single solver, no coupling.
    None,
    /// DEM to a steady state, then a static FEM solve with its interface forces.
    OneWay,
    /// Just-in-time: DEM first with the last FEM kinematics, then FEM.
    Jit,
    /// Predictive: FEM first with the last DEM forces, DEM follows the predicted motion.
    Predictive,
    /// Implicit: each window iterated until the interface forces are a fixed point
    /// (`[coupling.implicit]`; docs/coupling.md).
    Implicit,
    /// Concurrent (explicit Jacobi): both solvers compute a window at once, each from the
    /// other's data of the window before.
    Concurrent,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneSection {
    /// Name of the scene (default: the file name without extension).
    pub name: Option<Spanned<String>>,
    pub description: Option<String>,
    /// Simulated time (s). For one-way coupling: the longest the DEM may take to settle.
    pub end_time: Spanned<Seconds>,
}

/// An entry of `coupling.interfaces`: a name (its provider is the scene's only FEM node) or a
/// table naming the provider.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
pub enum InterfaceEntry {
    Name(String),
    Table(InterfaceTable),
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InterfaceTable {
    pub name: String,
    /// The FEM node that owns the surface (default: the only FEM node).
    pub provider: Option<String>,
    /// `surface` (default), or `volume`: an Arlequin overlap of the provider's mesh with the
    /// particles (`[fem.overlap]`, Wellmann ch. 6).
    #[serde(default)]
    pub kind: InterfaceKind,
}

/// How long the coordinator waits for a window's replies: long enough for a full-size
/// window on a busy machine (a slow node is still reported every minute in the log), short
/// enough that a hung node ends the run the same hour.
fn default_timeout() -> Seconds {
    Seconds(600.0)
}

fn default_steady_windows() -> u32 {
    5
}

fn default_growth() -> f64 {
    1e3
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CouplingSection {
    /// `none` (one solver), `one-way`, `jit`, `predictive`.
    pub schedule: Option<Spanned<ScheduleKind>>,
    /// Coupling window Δt^C = Δt^F (s). For a single solver: the reporting interval.
    pub window: Option<Spanned<Seconds>>,
    /// FEM gets the mean of the DEM forces over the window's substeps (Ullrich (3.8)).
    #[serde(default)]
    pub force_averaging: bool,
    /// The coupled interfaces: names, or `{ name = "...", provider = "<fem node>" }` tables
    /// (default: one interface per FEM node, named `interface` when there is one FEM node and
    /// after the node otherwise).
    #[serde(default)]
    pub interfaces: Vec<Spanned<InterfaceEntry>>,
    /// Longest wait for one window's messages before the run is stopped (s).
    #[serde(default = "default_timeout")]
    pub window_timeout: Seconds,
    /// Explicit schedules with fixed windows: how many windows the coordinator announces
    /// beyond the one running, so that its round trip leaves the window's critical path
    /// (0: lockstep, one window at a time). Results do not depend on it.
    #[serde(default = "default_lookahead")]
    pub lookahead: u64,
    /// One-way: the DEM is steady when its kinetic energy falls below this (J).
    pub steady_kinetic_energy: Option<Spanned<Joules>>,
    /// One-way: ... for this many consecutive windows.
    #[serde(default = "default_steady_windows")]
    pub steady_windows: u32,
    /// Stability monitor: stop when the interface force grows by more than this factor
    /// between consecutive windows while exceeding 10 × its running maximum.
    #[serde(default = "default_growth")]
    pub max_force_growth: f64,
    /// Run even when the scene is beyond a known stability limit (the refusal becomes a
    /// warning; the stability monitor still stops a diverging run).
    #[serde(default)]
    pub allow_beyond_limits: bool,
    /// The implicit schedule's settings.
    pub implicit: Option<Spanned<crate::schedule::implicit::ImplicitSettings>>,
    /// Adaptive windows (`window` is then the first one).
    pub adaptive: Option<Spanned<AdaptiveSection>>,
}

/// The most windows `coupling.lookahead` may announce ahead (zenoh's subscriber queue holds
/// 256 samples; the nodes' command queues stay far below it).
pub const MAX_LOOKAHEAD: u64 = 64;

fn default_lookahead() -> u64 {
    2
}

fn default_adaptive_tolerance() -> f64 {
    0.05
}
fn default_adaptive_iterations() -> u32 {
    4
}

/// `[coupling.adaptive]`: the window chosen after each window (schedule/adaptive.rs).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AdaptiveSection {
    /// Shortest window: the ladder's base (windows are min_window × 2^i), a whole number of
    /// DEM steps, and end_time a whole number of it.
    pub min_window: Seconds,
    /// Longest window.
    pub max_window: Seconds,
    /// Explicit schedules: the relative energy mismatch per window aimed at (default 0.05).
    #[serde(default = "default_adaptive_tolerance")]
    pub tolerance: f64,
    /// Implicit: the iterations per window aimed at (default 4).
    #[serde(default = "default_adaptive_iterations")]
    pub iterations: u32,
}

impl Default for CouplingSection {
    fn default() -> Self {
        CouplingSection {
            schedule: None,
            window: None,
            force_averaging: false,
            interfaces: Vec::new(),
            window_timeout: default_timeout(),
            lookahead: default_lookahead(),
            steady_kinetic_energy: None,
            steady_windows: default_steady_windows(),
            max_force_growth: default_growth(),
            allow_beyond_limits: false,
            implicit: None,
            adaptive: None,
        }
    }
}

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputSection {
    /// Output folder (default `out/<scene name>`), relative to the working directory.
    pub dir: Option<String>,
    /// Nodes write per-window interface traces (verification; large for big interfaces).
    #[serde(default)]
    pub trace_interfaces: bool,
    /// Checkpoint every this many windows (0: never); `cosim resume <out>` continues a run
    /// from the newest checkpoint.
    #[serde(default)]
    pub checkpoint_every: u64,
    /// Also checkpoint once this much wall time has passed since the run (or its resume) began
    /// or since the last checkpoint, e.g. `"20 min"`: long runs whose windows take seconds
    /// lose at most this much work when the machine goes away (alone or with
    /// `checkpoint_every`; either makes a run resumable).
    #[serde(default)]
    pub checkpoint_wall: Option<Spanned<Seconds>>,
    /// At the end, every node writes its full final state to `<out>/final/<node>.state`.
    #[serde(default)]
    pub final_state: bool,
}

/// A solver node of the scene (`[nodes.<id>]`): its kind and how it is started.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NodeLaunch {
    /// `dem` or `fem`; default from the id for `dem` and `fem`, required for other ids (the
    /// node reads the scene's top-level table of its id, e.g. `[sleeper_left]`).
    pub kind: Option<Spanned<NodeKind>>,
    /// Command line that starts the node instead of the built-in binary; the coordinator
    /// appends `--run-id`, `--node`, `--listen`, `--connect`.
    pub command: Option<Vec<String>>,
    /// The node is started by someone else (another machine): the coordinator waits for it.
    #[serde(default)]
    pub external: bool,
}

/// A solver node of a run.
#[derive(Debug, Clone)]
pub struct SceneNode {
    /// Its id: node name on the wire, its table in the scene, its output folder.
    pub id: String,
    pub kind: NodeKind,
    pub launch: NodeLaunch,
}

/// The coordinator's tables; every other top-level key is checked to be a node's table.
#[derive(Debug, Clone, Deserialize)]
struct SceneFile {
    scene: SceneSection,
    #[serde(default)]
    coupling: CouplingSection,
    #[serde(default)]
    output: OutputSection,
    #[serde(default)]
    nodes: BTreeMap<String, NodeLaunch>,
}

/// Top-level keys the coordinator reads itself.
const COORDINATOR_TABLES: [&str; 4] = ["scene", "coupling", "output", "nodes"];

/// A validated scene, as far as the coordinator is concerned.
#[derive(Debug, Clone)]
pub struct Scene {
    pub path: PathBuf,
    /// The whole file, sent to the nodes.
    pub text: String,
    pub name: String,
    pub description: Option<String>,
    pub end_time: f64,
    pub schedule: ScheduleKind,
    /// Δt^C (s).
    pub window: f64,
    pub windows: u64,
    pub force_averaging: bool,
    /// The coupled interfaces with provider and users (empty for a single solver).
    pub interfaces: Vec<InterfaceDecl>,
    pub window_timeout: f64,
    /// Windows announced ahead (`coupling.lookahead`).
    pub lookahead: u64,
    pub steady_kinetic_energy: Option<f64>,
    pub steady_windows: u32,
    pub max_force_growth: f64,
    pub allow_beyond_limits: bool,
    /// The implicit schedule's settings (`schedule = "implicit"`).
    pub implicit: Option<crate::schedule::implicit::ImplicitSettings>,
    /// Adaptive windows (`[coupling.adaptive]`).
    pub adaptive: Option<crate::schedule::adaptive::AdaptiveSettings>,
    pub out_dir: PathBuf,
    pub trace_interfaces: bool,
    pub checkpoint_every: u64,
    /// `[output] checkpoint_wall` in seconds.
    pub checkpoint_wall: Option<f64>,
    pub final_state: bool,
    pub has_dem: bool,
    pub has_fem: bool,
    /// The solver nodes: the DEM first, then the FEM nodes by id.
    pub nodes: Vec<SceneNode>,
}

impl Scene {
    /// The run writes checkpoints (`[output] checkpoint_every` or `checkpoint_wall`), so it
    /// can be resumed and an interrupt saves one.
    pub fn checkpoints(&self) -> bool {
        self.checkpoint_every > 0 || self.checkpoint_wall.is_some()
    }

    /// The DEM node's id, if the scene has one.
    pub fn dem_node(&self) -> Option<&str> {
        self.nodes
            .iter()
            .find(|n| n.kind == NodeKind::Dem)
            .map(|n| n.id.as_str())
    }

    /// The schedule runs the DEM and the FEM at the same time (a window's critical path is the
    /// slower of the two, not their sum).
    pub fn concurrent(&self) -> bool {
        self.schedule == ScheduleKind::Concurrent
            || self.implicit.as_ref().is_some_and(|i| i.concurrent)
    }

    /// The FEM nodes' ids.
    pub fn fem_nodes(&self) -> impl Iterator<Item = &str> + '_ {
        self.nodes
            .iter()
            .filter(|n| n.kind == NodeKind::Fem)
            .map(|n| n.id.as_str())
    }

    /// The node that provides interface `name`.
    pub fn provider_of(&self, name: &str) -> Option<&str> {
        self.interfaces
            .iter()
            .find(|i| i.name == name)
            .map(|i| i.provider.as_str())
    }
}

impl Scene {
    /// Reads and validates a scene file.
    pub fn load(path: &Path) -> Result<Scene, SceneError> {
        let text = std::fs::read_to_string(path).map_err(|e| SceneError {
            file: path.display().to_string(),
            line: 0,
            column: 0,
            field: String::new(),
            message: format!("cannot read the scene file: {e}"),
        })?;
        Scene::parse(path, text)
    }

    /// Validates scene text that came from `path`.
    pub fn parse(path: &Path, text: String) -> Result<Scene, SceneError> {
        let file = path.display().to_string();
        let err_at = |offset: usize, field: &str, message: String| {
            let (line, column) = line_col(&text, offset);
            SceneError {
                file: file.clone(),
                line,
                column,
                field: field.to_string(),
                message,
            }
        };
        let raw: SceneFile = toml::from_str(&text).map_err(|e| {
            let offset = e.span().map(|s| s.start).unwrap_or(0);
            err_at(offset, "", e.message().trim().to_string())
        })?;
        let nodes = solver_nodes(&text, &raw.nodes)
            .map_err(|(offset, field, message)| err_at(offset, &field, message))?;
        let has_dem = nodes.iter().any(|n| n.kind == NodeKind::Dem);
        let has_fem = nodes.iter().any(|n| n.kind == NodeKind::Fem);
        if !has_dem && !has_fem {
            return Err(err_at(
                0,
                "",
                "the scene has neither a [dem] nor a [fem] table: nothing to run".into(),
            ));
        }
        let name = match &raw.scene.name {
            Some(n) => {
                proto::keys::validate_name("scene name", n.get_ref())
                    .map_err(|e| err_at(n.span().start, "scene.name", e.to_string()))?;
                n.get_ref().clone()
            }
            None => {
                let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("scene");
                stem.chars()
                    .map(|c| {
                        if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                            c
                        } else {
                            '_'
                        }
                    })
                    .take(48)
                    .collect()
            }
        };
        let end_time = raw.scene.end_time.get_ref().0;
        if end_time <= 0.0 {
            return Err(err_at(
                raw.scene.end_time.span().start,
                "scene.end_time",
                format!("must be positive, got {}", format_seconds(end_time)),
            ));
        }
        let c = &raw.coupling;
        let both = has_dem && has_fem;
        let schedule = match &c.schedule {
            Some(s) => {
                let k = *s.get_ref();
                if both && k == ScheduleKind::None {
                    return Err(err_at(s.span().start, "coupling.schedule", "the scene has both [dem] and [fem]: choose `one-way`, `jit`, `predictive`, `concurrent` or `implicit`".into()));
                }
                if !both && k != ScheduleKind::None {
                    return Err(err_at(
                        s.span().start,
                        "coupling.schedule",
                        format!(
                            "`{}` couples two solvers, but the scene has only a [{}] table",
                            serde_json::to_value(k)
                                .ok()
                                .and_then(|v| v.as_str().map(String::from))
                                .unwrap_or_default(),
                            if has_dem { "dem" } else { "fem" }
                        ),
                    ));
                }
                k
            }
            None if both => {
                return Err(err_at(text.find("[coupling]").unwrap_or(0), "coupling.schedule", "the scene couples [dem] and [fem]: set `schedule` to `one-way`, `jit`, `predictive`, `concurrent` or `implicit`".into()));
            }
            None => ScheduleKind::None,
        };
        let window = match &c.window {
            Some(w) => {
                let v = w.get_ref().0;
                if v <= 0.0 || v > end_time * (1.0 + 1e-12) {
                    return Err(err_at(
                        w.span().start,
                        "coupling.window",
                        format!(
                            "must lie in (0, end_time = {}], got {}",
                            format_seconds(end_time),
                            format_seconds(v)
                        ),
                    ));
                }
                v
            }
            None => {
                return Err(err_at(text.find("[coupling]").unwrap_or(0), "coupling.window", "missing: the coupling window Δt^C in s (for a single solver: the reporting interval)".into()));
            }
        };
        let adaptive = match &c.adaptive {
            None => None,
            Some(a) => {
                let at = a.span().start;
                let v = a.get_ref();
                let (min, max) = (v.min_window.0, v.max_window.0);
                if !matches!(
                    schedule,
                    ScheduleKind::Jit
                        | ScheduleKind::Predictive
                        | ScheduleKind::Concurrent
                        | ScheduleKind::Implicit
                ) {
                    return Err(err_at(
                        at,
                        "coupling.adaptive",
                        "adaptive windows need a two-way schedule: jit, predictive, concurrent or implicit".into(),
                    ));
                }
                if !(min > 0.0 && min <= max) {
                    return Err(err_at(
                        at,
                        "coupling.adaptive.min_window",
                        format!(
                            "must be positive and at most max_window = {}, got {}",
                            format_seconds(max),
                            format_seconds(min)
                        ),
                    ));
                }
                let steps = window / min;
                let n = steps.round();
                if n < 1.0
                    || (steps - n).abs() > 1e-6 * n
                    || !(n as u64).is_power_of_two()
                    || window > max * (1.0 + 1e-9)
                {
                    return Err(err_at(
                        c.window.as_ref().map_or(at, |w| w.span().start),
                        "coupling.window",
                        format!(
                            "with adaptive windows the first window must be min_window × 2^i and at most max_window = {}: got {} (min_window = {})",
                            format_seconds(max),
                            format_seconds(window),
                            format_seconds(min)
                        ),
                    ));
                }
                let whole = end_time / min;
                if (whole - whole.round()).abs() > 1e-6 * whole.max(1.0) {
                    return Err(err_at(
                        at,
                        "coupling.adaptive.min_window",
                        format!(
                            "end_time / min_window = {} / {} = {whole:.6} is not a whole number",
                            format_seconds(end_time),
                            format_seconds(min)
                        ),
                    ));
                }
                if !(v.tolerance > 0.0 && v.tolerance < 1.0) {
                    return Err(err_at(
                        at,
                        "coupling.adaptive.tolerance",
                        format!("must lie in (0, 1), got {}", v.tolerance),
                    ));
                }
                if v.iterations == 0 {
                    return Err(err_at(
                        at,
                        "coupling.adaptive.iterations",
                        "must be at least 1".into(),
                    ));
                }
                Some(crate::schedule::adaptive::AdaptiveSettings {
                    min_window: min,
                    max_window: max,
                    tolerance: v.tolerance,
                    iterations: v.iterations,
                })
            }
        };
        let ratio = end_time / window;
        let windows = ratio.round();
        if adaptive.is_none() && (ratio - windows).abs() > 1e-9 * ratio.max(1.0) {
            let w = c.window.as_ref().expect("checked above");
            return Err(err_at(
                w.span().start,
                "coupling.window",
                format!(
                    "end_time / window = {} / {} = {ratio:.6} is not a whole number of windows",
                    format_seconds(end_time),
                    format_seconds(window)
                ),
            ));
        }
        if windows > MAX_WINDOWS {
            let w = c.window.as_ref().expect("checked above");
            return Err(err_at(
                w.span().start,
                "coupling.window",
                format!(
                    "end_time / window = {} / {} = {windows:.3e} windows, more than the {MAX_WINDOWS:.0e} a scene may have (each is a row of windows.csv and a round of messages): is the window's unit right?",
                    format_seconds(end_time),
                    format_seconds(window)
                ),
            ));
        }
        let interfaces = if both {
            declare_interfaces(&text, c, &nodes)
                .map_err(|(offset, field, message)| err_at(offset, &field, message))?
        } else {
            Vec::new()
        };
        if !both && nodes.len() > 1 {
            return Err(err_at(
                0,
                "nodes",
                format!(
                    "the scene has {} FEM nodes ({}) and no DEM node: structures are coupled through a [dem] bed",
                    nodes.len(),
                    nodes.iter().map(|n| format!("`{}`", n.id)).collect::<Vec<_>>().join(", ")
                ),
            ));
        }
        let steady = match &c.steady_kinetic_energy {
            Some(s) if s.get_ref().0 <= 0.0 => {
                return Err(err_at(
                    s.span().start,
                    "coupling.steady_kinetic_energy",
                    "must be positive (J)".into(),
                ));
            }
            Some(s) => Some(s.get_ref().0),
            None => None,
        };
        if !(c.max_force_growth.is_finite() && c.max_force_growth > 1.0) {
            return Err(err_at(
                text.find("max_force_growth").unwrap_or(0),
                "coupling.max_force_growth",
                format!(
                    "must be a finite factor above 1 (the growth of the interface force in one window that stops the run; default 1e3), got {}",
                    c.max_force_growth
                ),
            ));
        }
        if c.steady_windows == 0 {
            return Err(err_at(
                text.find("steady_windows").unwrap_or(0),
                "coupling.steady_windows",
                "must be at least 1 (consecutive windows below steady_kinetic_energy)".into(),
            ));
        }
        if c.lookahead > MAX_LOOKAHEAD {
            return Err(err_at(
                text.find("lookahead").unwrap_or(0),
                "coupling.lookahead",
                format!(
                    "at most {MAX_LOOKAHEAD} windows ahead (got {}): a node holds the commands announced to it in a bounded queue; 2 hides the coordinator's round trip",
                    c.lookahead
                ),
            ));
        }
        let checkpoint_wall = match &raw.output.checkpoint_wall {
            Some(w) if w.get_ref().0 <= 0.0 => {
                return Err(err_at(
                    w.span().start,
                    "output.checkpoint_wall",
                    format!(
                        "must be a positive wall time (e.g. \"20 min\"), got {} s",
                        w.get_ref().0
                    ),
                ))
            }
            Some(w) => Some(w.get_ref().0),
            None => None,
        };
        if c.window_timeout.0 <= 0.0 {
            return Err(err_at(
                text.find("window_timeout").unwrap_or(0),
                "coupling.window_timeout",
                "must be positive (s)".into(),
            ));
        }
        let implicit = match (&c.implicit, schedule) {
            (Some(i), ScheduleKind::Implicit) => {
                let v = i.get_ref();
                let at = i.span().start;
                if !(v.tolerance > 0.0 && v.tolerance < 1.0) {
                    return Err(err_at(
                        at,
                        "coupling.implicit.tolerance",
                        format!(
                            "must lie in (0, 1) (a relative force residual), got {}",
                            v.tolerance
                        ),
                    ));
                }
                if v.max_iterations == 0 {
                    return Err(err_at(
                        at,
                        "coupling.implicit.max_iterations",
                        "must be at least 1".into(),
                    ));
                }
                if !(v.relaxation > 0.0 && v.relaxation <= 1.0) {
                    return Err(err_at(
                        at,
                        "coupling.implicit.relaxation",
                        format!("must lie in (0, 1], got {}", v.relaxation),
                    ));
                }
                if !(v.filter > 0.0 && v.filter < 1.0) {
                    return Err(err_at(
                        at,
                        "coupling.implicit.filter",
                        format!("must lie in (0, 1), got {}", v.filter),
                    ));
                }
                Some(v.clone())
            }
            (None, ScheduleKind::Implicit) => Some(Default::default()),
            (Some(i), _) => {
                return Err(err_at(
                    i.span().start,
                    "coupling.implicit",
                    "settings of the implicit schedule, but `schedule` is not \"implicit\"".into(),
                ));
            }
            (None, _) => None,
        };
        if let Some(v) = interfaces.iter().find(|i| i.kind == InterfaceKind::Volume) {
            // a volume interface sends the pull of the window's end (the FE's implicit
            // penalty balance is an end-of-step one): no window means to average or iterate on
            let (field, what) = if implicit.is_some() {
                (
                    "coupling.schedule",
                    "the implicit schedule iterates on window means",
                )
            } else if c.force_averaging {
                (
                    "coupling.force_averaging",
                    "force_averaging sends window means",
                )
            } else {
                ("", "")
            };
            if !field.is_empty() {
                return Err(err_at(
                    text.find(field.rsplit('.').next().unwrap_or(field))
                        .unwrap_or(0),
                    field,
                    format!(
                        "{what}, but the volume interface `{}` sends the penalty pull of the \
                         window's end: use jit, predictive or concurrent without force_averaging",
                        v.name
                    ),
                ));
            }
        }
        let mut interfaces = interfaces;
        if let Some(settings) = &implicit {
            // the iteration works on the mean forces of the window; the provider gets the
            // coordinator's estimates (concurrent: the users get its estimated kinematics)
            for i in &mut interfaces {
                i.force_averaging = true;
                i.relaxed_forces = true;
                i.relaxed_kinematics = settings.concurrent;
            }
        }
        let out_dir = raw
            .output
            .dir
            .clone()
            .map(PathBuf::from)
            .unwrap_or_else(|| PathBuf::from("out").join(&name));
        Ok(Scene {
            path: path.to_path_buf(),
            name,
            description: raw.scene.description.clone(),
            end_time,
            schedule,
            window,
            windows: windows as u64,
            force_averaging: c.force_averaging,
            interfaces,
            window_timeout: c.window_timeout.0,
            lookahead: c.lookahead,
            steady_kinetic_energy: steady,
            steady_windows: c.steady_windows,
            max_force_growth: c.max_force_growth,
            allow_beyond_limits: c.allow_beyond_limits,
            implicit,
            adaptive,
            out_dir,
            trace_interfaces: raw.output.trace_interfaces,
            checkpoint_every: raw.output.checkpoint_every,
            checkpoint_wall,
            final_state: raw.output.final_state,
            has_dem,
            has_fem,
            nodes,
            text,
        })
    }
}

/// An error at a byte offset of the scene text, with its field.
type Located = (usize, String, String);

/// The solver nodes of a scene: every top-level table that is not the coordinator's is a
/// node's (`[dem]`, `[fem]`, or an id declared in `[nodes.<id>]` with its `kind`).
fn solver_nodes(
    text: &str,
    decls: &BTreeMap<String, NodeLaunch>,
) -> Result<Vec<SceneNode>, Located> {
    let root = toml::de::DeTable::parse(text).map_err(|e| {
        (
            e.span().map(|s| s.start).unwrap_or(0),
            String::new(),
            e.message().to_string(),
        )
    })?;
    let mut nodes = Vec::new();
    for (key, value) in root.get_ref().iter() {
        let id = key.get_ref().to_string();
        if COORDINATOR_TABLES.contains(&id.as_str()) {
            continue;
        }
        let at = key.span().start;
        if !matches!(value.get_ref(), toml::de::DeValue::Table(_)) {
            return Err((at, id.clone(), format!("unknown top-level key `{id}`: a scene has the tables [scene], [coupling], [output], [nodes] and one table per solver node")));
        }
        let decl = decls.get(&id);
        let declared = decl.and_then(|d| d.kind.as_ref()).map(|k| *k.get_ref());
        let kind = match (id.as_str(), declared) {
            (_, Some(k)) => k,
            ("dem", None) => NodeKind::Dem,
            ("fem", None) => NodeKind::Fem,
            (_, None) => {
                return Err((at, id.clone(), format!(
                    "unknown table [{id}]: a further solver node needs `[nodes.{id}]` with `kind = \"fem\"` (or \"dem\"); the coordinator's tables are [scene], [coupling], [output], [nodes]"
                )))
            }
        };
        proto::keys::validate_name("node", &id).map_err(|e| (at, id.clone(), e.to_string()))?;
        if id == proto::participant::COORDINATOR {
            return Err((
                at,
                id.clone(),
                "`coordinator` is reserved; give the node another id".into(),
            ));
        }
        nodes.push(SceneNode {
            id,
            kind,
            launch: decl.cloned().unwrap_or_default(),
        });
    }
    // a declared node needs its table (the built-in names without a table are simply absent)
    for (id, d) in decls {
        if d.kind.is_some() && !nodes.iter().any(|n| &n.id == id) {
            let at = d.kind.as_ref().map(|k| k.span().start).unwrap_or(0);
            return Err((
                at,
                format!("nodes.{id}"),
                format!("node `{id}` has no [{id}] table in the scene"),
            ));
        }
    }
    let dems: Vec<&str> = nodes
        .iter()
        .filter(|n| n.kind == NodeKind::Dem)
        .map(|n| n.id.as_str())
        .collect();
    if dems.len() > 1 {
        return Err((
            text.find(&format!("[{}]", dems[1])).unwrap_or(0),
            dems[1].to_string(),
            format!(
                "the scene has {} DEM nodes ({}); one DEM node holds the granular bed",
                dems.len(),
                dems.join(", ")
            ),
        ));
    }
    nodes.sort_by(|a, b| (a.kind, &a.id).cmp(&(b.kind, &b.id)));
    Ok(nodes)
}

/// The interfaces of a coupled scene: each FEM node provides one surface, the DEM uses all.
fn declare_interfaces(
    text: &str,
    c: &CouplingSection,
    nodes: &[SceneNode],
) -> Result<Vec<InterfaceDecl>, Located> {
    const F: &str = "coupling.interfaces";
    let fems: Vec<&str> = nodes
        .iter()
        .filter(|n| n.kind == NodeKind::Fem)
        .map(|n| n.id.as_str())
        .collect();
    let users: Vec<String> = nodes
        .iter()
        .filter(|n| n.kind == NodeKind::Dem)
        .map(|n| n.id.clone())
        .collect();
    let decl = |name: String, provider: String, kind| InterfaceDecl {
        name,
        kind,
        provider,
        users: users.clone(),
        force_averaging: c.force_averaging,
        relaxed_forces: false,
        relaxed_kinematics: false,
    };
    let mut out: Vec<InterfaceDecl> = Vec::new();
    if c.interfaces.is_empty() {
        for f in &fems {
            let name = if fems.len() == 1 {
                "interface".to_string()
            } else {
                f.to_string()
            };
            out.push(decl(name, f.to_string(), InterfaceKind::Surface));
        }
        return Ok(out);
    }
    for entry in &c.interfaces {
        let at = entry.span().start;
        let (name, provider, kind) = match entry.get_ref() {
            InterfaceEntry::Name(n) => (n.clone(), None, InterfaceKind::Surface),
            InterfaceEntry::Table(t) => (t.name.clone(), t.provider.clone(), t.kind),
        };
        proto::keys::validate_name("interface", &name)
            .map_err(|e| (at, F.to_string(), e.to_string()))?;
        if out.iter().any(|i| i.name == name) {
            return Err((
                at,
                F.to_string(),
                format!("interface `{name}` is listed twice"),
            ));
        }
        let provider = match provider {
            Some(p) if fems.contains(&p.as_str()) => p,
            Some(p) => {
                return Err((at, F.to_string(), format!(
                    "interface `{name}`: provider `{p}` is not a FEM node of the scene (FEM nodes: {})",
                    fems.join(", ")
                )))
            }
            None if fems.len() == 1 => fems[0].to_string(),
            None => {
                return Err((at, F.to_string(), format!(
                    "interface `{name}`: the scene has {} FEM nodes ({}); name the one that provides it: {{ name = \"{name}\", provider = \"{}\" }}",
                    fems.len(),
                    fems.join(", "),
                    fems[0]
                )))
            }
        };
        if let Some(other) = out.iter().find(|i| i.provider == provider) {
            return Err((at, F.to_string(), format!(
                "interfaces `{}` and `{name}` are both provided by node `{provider}`; a FEM node provides one surface (give each structure its own node)",
                other.name
            )));
        }
        out.push(decl(name, provider, kind));
    }
    if let Some(idle) = fems.iter().find(|f| !out.iter().any(|i| &i.provider == *f)) {
        return Err((text.find("interfaces").unwrap_or(0), F.to_string(), format!(
            "FEM node `{idle}` provides no interface: add {{ name = \"...\", provider = \"{idle}\" }}"
        )));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Scene, SceneError> {
        Scene::parse(Path::new("s.toml"), text.to_string())
    }

    const OK: &str =
        "[scene]\nend_time = \"1 ms\"\n[coupling]\nwindow = 1e-4\n[dem]\ntime_step = 1e-6\n";

    #[test]
    fn a_minimal_dem_scene_is_valid() {
        let s = parse(OK).unwrap();
        assert_eq!(s.schedule, ScheduleKind::None);
        assert_eq!(s.windows, 10);
        assert_eq!(s.name, "s");
        assert!(s.has_dem && !s.has_fem);
    }

    /// A volume interface sends the pull of the window's end: window means (force_averaging,
    /// the implicit schedule) are refused with it, naming the field and the interface.
    #[test]
    fn volume_interfaces_refuse_window_means() {
        let scene = |coupling: &str| {
            format!(
                "[scene]\nend_time = 1\n[coupling]\nwindow = 0.1\n{coupling}\n\
                 interfaces = [{{ name = \"soil\", kind = \"volume\" }}]\n[dem]\n[fem]\n"
            )
        };
        assert!(parse(&scene("schedule = \"jit\"")).is_ok());
        let e = parse(&scene("schedule = \"jit\"\nforce_averaging = true")).unwrap_err();
        assert_eq!(e.field, "coupling.force_averaging");
        assert!(e.message.contains("`soil`"), "{e}");
        let e = parse(&scene("schedule = \"implicit\"")).unwrap_err();
        assert_eq!(e.field, "coupling.schedule");
    }

    #[test]
    fn unknown_key_names_line_and_field() {
        let e = parse("[scene]\nend_time = 1\n[coupling]\nwindow = 0.1\nwindoww = 3\n[dem]\n")
            .unwrap_err();
        assert_eq!((e.line, e.file.as_str()), (5, "s.toml"));
        assert!(e.message.contains("unknown field `windoww`"), "{e}");
        assert!(e.to_string().starts_with("s.toml:5:"), "{e}");
    }

    #[test]
    fn wrong_unit_names_line_and_field() {
        let e = parse("[scene]\nend_time = 1\n[coupling]\nwindow = \"3 kg\"\n[dem]\n").unwrap_err();
        assert_eq!(e.line, 4);
        assert!(e.message.contains("expected a time"), "{e}");
    }

    #[test]
    fn coupled_scene_needs_a_schedule_and_whole_windows() {
        let e =
            parse("[scene]\nend_time = 1\n[coupling]\nwindow = 0.1\n[dem]\n[fem]\n").unwrap_err();
        assert_eq!(e.field, "coupling.schedule");
        let e = parse(
            "[scene]\nend_time = 1\n[coupling]\nschedule = \"jit\"\nwindow = 0.3\n[dem]\n[fem]\n",
        )
        .unwrap_err();
        assert_eq!((e.field.as_str(), e.line), ("coupling.window", 5));
        assert!(e.message.contains("not a whole number"), "{e}");
        let e =
            parse("[scene]\nend_time = 1\n[coupling]\nschedule = \"jit\"\nwindow = 0.1\n[dem]\n")
                .unwrap_err();
        assert!(e.message.contains("only a [dem]"), "{e}");
    }

    #[test]
    fn monitor_thresholds_must_be_meaningful() {
        for (line, what) in [
            ("max_force_growth = 0", "got 0"),
            ("max_force_growth = -5.0", "got -5"),
            ("max_force_growth = nan", "got NaN"),
            ("max_force_growth = inf", "got inf"),
            ("steady_windows = 0", "at least 1"),
            ("steady_kinetic_energy = 0", "must be positive"),
            ("steady_kinetic_energy = nan", "not a finite"),
            ("window_timeout = -1", "must be positive"),
            ("window_timeout = inf", "not a finite"),
            ("lookahead = 65", "at most 64"),
        ] {
            let e = parse(&format!(
                "[scene]\nend_time = 1\n[coupling]\nwindow = 0.1\n{line}\n[dem]\n"
            ))
            .unwrap_err();
            assert_eq!(e.line, 5, "{line}: {e}");
            assert!(e.to_string().contains(what), "{line}: {e}");
        }
    }

    #[test]
    fn a_wall_time_checkpoint_period_is_read_with_its_unit_and_must_be_positive() {
        let scene = |line: &str| {
            parse(&format!(
                "[scene]\nend_time = 1\n[coupling]\nwindow = 0.1\n[dem]\n[output]\n{line}\n"
            ))
        };
        let s = scene("checkpoint_wall = \"20 min\"").unwrap();
        assert_eq!((s.checkpoint_wall, s.checkpoint_every), (Some(1200.0), 0));
        assert!(s.checkpoints());
        assert_eq!(
            scene("checkpoint_wall = \"1.5 h\"")
                .unwrap()
                .checkpoint_wall,
            Some(5400.0)
        );
        assert!(!scene("final_state = true").unwrap().checkpoints());
        for (line, what) in [
            ("checkpoint_wall = 0", "must be a positive wall time"),
            ("checkpoint_wall = \"-5 min\"", "got -300 s"),
            ("checkpoint_wall = \"20 m\"", "expected a time"),
        ] {
            let e = scene(line).unwrap_err();
            assert_eq!(e.line, 7, "{line}: {e}");
            assert!(e.to_string().contains(what), "{line}: {e}");
        }
    }

    #[test]
    fn numbers_in_messages_are_readable_and_absurd_window_counts_are_refused() {
        let e = parse("[scene]\nend_time = 1\n[coupling]\nwindow = 0.000099\n[dem]\n").unwrap_err();
        assert!(e.message.contains("1 s / 99 µs = 10101.010101"), "{e}");
        let e = parse("[scene]\nend_time = 100\n[coupling]\nwindow = 1e-9\n[dem]\n").unwrap_err();
        assert!(e.message.contains("1.000e11 windows"), "{e}");
        let e = parse("[scene]\nend_time = -2e-5\n[coupling]\nwindow = 1\n[dem]\n").unwrap_err();
        assert!(e.message.contains("got -20 µs"), "{e}");
    }

    #[test]
    fn an_unreadable_file_is_named_without_a_line() {
        let e = Scene::load(Path::new("/nonexistent/s.toml")).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("/nonexistent/s.toml: cannot read"),
            "{e}"
        );
    }

    #[test]
    fn nothing_to_run_is_an_error() {
        let e = parse("[scene]\nend_time = 1\n[coupling]\nwindow = 0.1\n").unwrap_err();
        assert!(e.message.contains("neither"), "{e}");
    }
}
