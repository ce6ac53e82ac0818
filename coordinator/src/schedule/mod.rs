//! The coupling schedules as pure state machines over node ids (Ullrich ch. 3, Algorithm 3).
//!
//! A [`Scheduler`] is told what happened (a node finished a window) and answers with the
//! commands to send. It never touches the network, so every schedule is unit-tested here.
//! Each schedule is a [`Scheme`] in its own module (`alone`, `one_way`, `jit`, `predictive`,
//! `concurrent`, `implicit`):
//! the commands before window 0, the commands of window k, the data to publish again after a
//! restore, and what follows a completed window. Adding a schedule adds a module and a
//! variant of [`SchemeState`].
//!
//! Data dependencies do the sequencing: every node gets its window command at once; the one
//! that needs another's data waits for it (matched by label). With several FEM nodes (one
//! structure each) every FEM node gets the same commands for its own interface.

use std::collections::BTreeSet;

use proto::{AdvanceWindow, CommandBody, Label, MotionRule};

use crate::scene::ScheduleKind;
use crate::units::format_seconds;

pub mod adaptive;
mod alone;
mod concurrent;
pub mod implicit;
mod jit;
mod one_way;
mod predictive;

/// Integer number of DEM substeps in a coupling window: Δt^C = n^D Δt^D (Ullrich ch. 3.3).
pub fn substeps(window: f64, dem_time_step: f64) -> Result<u32, String> {
    if !(dem_time_step > 0.0 && dem_time_step.is_finite()) {
        return Err(format!(
            "the DEM time step must be positive, got {}",
            format_seconds(dem_time_step)
        ));
    }
    proto::motion::whole_substeps(window, dem_time_step).map_err(|ratio| {
        let n = ratio.round();
        if n > u32::MAX as f64 {
            return format!("{n:.3e} substeps per window is too many");
        }
        format!(
            "the coupling window Δt^C = {} is not a whole multiple of the DEM time step Δt^D = {} (ratio {ratio:.4}); choose Δt^C = n·Δt^D, e.g. {} or {}",
            format_seconds(window),
            format_seconds(dem_time_step),
            format_seconds(n.max(1.0) * dem_time_step),
            format_seconds((n + 1.0) * dem_time_step)
        )
    })
}

/// The nodes of a run by kind: at most one DEM node (the interfaces' user), any number of
/// FEM nodes (each the provider of one interface).
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Topology {
    pub dem: Option<String>,
    pub fems: Vec<String>,
}

impl Topology {
    /// Every node, the DEM first.
    pub fn all(&self) -> impl Iterator<Item = &str> + '_ {
        self.dem.iter().chain(&self.fems).map(String::as_str)
    }
}

/// Commands for nodes.
pub type Sends = Vec<(String, CommandBody)>;

/// Estimates for interfaces' nodes (implicit schemes): (interface, label, estimate).
pub type Publications = Vec<(String, Label, implicit::Estimate)>;

/// The windows of a run.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Windows {
    /// Δt^C (s) of the current window.
    pub length: f64,
    /// Fixed windows: how many.
    pub count: u64,
    /// Adaptive windows: the clock and the controller.
    #[serde(default)]
    pub adaptive: Option<Box<Clock>>,
}

/// Adaptive windows' time, counted in ladder bases (adaptive.rs), and the controller.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Clock {
    pub controller: adaptive::Adaptive,
    /// The current window's start and length, and the end time, in bases.
    start: u64,
    steps: u64,
    total: u64,
    /// What the nodes reported of the current window, and its iterations (implicit).
    observation: adaptive::Observation,
    iterations: u32,
    /// Changes of the window length not yet taken by the run loop.
    changes: Vec<WindowChange>,
}

/// A change of the adaptive window's length, for the log.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct WindowChange {
    /// The first window with the new length.
    pub window: u64,
    pub from: f64,
    pub to: f64,
    pub reason: String,
}

impl Windows {
    /// Window k is the last (k: the current window).
    pub fn is_last(&self, k: u64) -> bool {
        match &self.adaptive {
            Some(c) => c.start + c.steps >= c.total,
            None => k + 1 == self.count,
        }
    }

    /// The start time of window k (k: the current window).
    pub fn t_start(&self, k: u64) -> f64 {
        match &self.adaptive {
            Some(c) => c.start as f64 * c.controller.settings.min_window,
            None => k as f64 * self.length,
        }
    }

    /// `advance_window` of window k, iteration 0, with input and output labelled by window.
    pub fn advance(
        &self,
        k: u64,
        motion: MotionRule,
        input: Option<u64>,
        output: Option<u64>,
        static_solve: bool,
    ) -> CommandBody {
        CommandBody::AdvanceWindow(AdvanceWindow {
            window: k,
            iteration: 0,
            t_start: self.t_start(k),
            dt: self.length,
            motion,
            input: input.map(Label::window),
            output: output.map(Label::window),
            static_solve,
        })
    }
}

/// What follows a window every node has finished.
#[derive(Debug, Clone, PartialEq)]
pub enum Next {
    /// The next window (or the end after the last).
    Continue,
    /// A last step (e.g. one-way's static solve): send these; when the nodes that got an
    /// `advance_window` among them are done, the run finishes with `reason`.
    Final { sends: Sends, reason: String },
}

/// One coupling schedule. Only [`Scheme::window`] is required; the rest has the defaults of an
/// explicit schedule without a prologue.
pub trait Scheme {
    /// Commands of window k (each node's `advance_window`).
    fn window(&self, t: &Topology, w: &Windows, k: u64) -> Sends;
    /// Estimates the coordinator publishes with window k's commands (an implicit scheme's
    /// first).
    fn window_publications(&mut self, _w: &Windows, _k: u64) -> Publications {
        Vec::new()
    }
    /// Commands before window 0.
    fn prologue(&self, _t: &Topology) -> Sends {
        Vec::new()
    }
    /// After a restore from a checkpoint taken between window k − 1 and k: the interface data
    /// that was in flight then, published again from the restored states.
    fn replay(&self, _t: &Topology, _k: u64) -> Sends {
        Vec::new()
    }
    /// Every node finished window k (`kinetic_energy`: the DEM's, if reported).
    fn after_window(
        &mut self,
        _t: &Topology,
        _w: &Windows,
        _k: u64,
        _kinetic_energy: Option<f64>,
    ) -> Next {
        Next::Continue
    }
    /// An iterating scheme's iteration now running: once every node has finished it, the
    /// users' forces (and, if [`Scheme::needs_positions`], the providers' end positions) are
    /// read and given to [`Scheme::on_outputs`].
    fn iteration(&self) -> Option<u32> {
        None
    }
    /// The iteration's outputs include the providers' end positions.
    fn needs_positions(&self) -> bool {
        false
    }
    /// The outputs of window k's iteration just finished, per interface.
    fn on_outputs(
        &mut self,
        _t: &Topology,
        _w: &Windows,
        k: u64,
        _outputs: &implicit::Outputs,
    ) -> Result<implicit::Iterate, String> {
        Err(format!(
            "outputs of window {k} given to a schedule that does not iterate"
        ))
    }
    /// Window k's commands depend on nothing the nodes report, so the coordinator may send
    /// them before earlier windows are done (lookahead): explicit schemes with a fixed end.
    fn pipelines(&self) -> bool {
        false
    }
    /// The iterations since the last call.
    fn take_iterations(&mut self) -> Vec<implicit::IterationRecord> {
        Vec::new()
    }
    /// Windows that ended unconverged (`continue_unconverged`).
    fn unconverged_windows(&self) -> &[u64] {
        &[]
    }
    /// One-way: the DEM's kinetic energy when the end time forced the solve on a moving bed.
    fn unsettled_kinetic_energy(&self) -> Option<f64> {
        None
    }
}

/// The schedule of a run with its state (serialisable: checkpoints store it).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
#[serde(tag = "scheme", rename_all = "kebab-case")]
pub enum SchemeState {
    None(alone::Alone),
    OneWay(one_way::OneWay),
    Jit(jit::Jit),
    Predictive(predictive::Predictive),
    Implicit(Box<implicit::Implicit>),
    Concurrent(concurrent::Concurrent),
}

impl SchemeState {
    fn scheme(&mut self) -> &mut dyn Scheme {
        match self {
            SchemeState::None(s) => s,
            SchemeState::OneWay(s) => s,
            SchemeState::Jit(s) => s,
            SchemeState::Predictive(s) => s,
            SchemeState::Implicit(s) => s.as_mut(),
            SchemeState::Concurrent(s) => s,
        }
    }

    fn scheme_ref(&self) -> &dyn Scheme {
        match self {
            SchemeState::None(s) => s,
            SchemeState::OneWay(s) => s,
            SchemeState::Jit(s) => s,
            SchemeState::Predictive(s) => s,
            SchemeState::Implicit(s) => s.as_ref(),
            SchemeState::Concurrent(s) => s,
        }
    }
}

/// What the coordinator must do next.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    Send(String, CommandBody),
    /// Publish an estimate for an interface's nodes (implicit schemes: the accelerated
    /// forces for the provider; concurrent, the estimated kinematics for the users).
    Publish {
        interface: String,
        label: Label,
        estimate: implicit::Estimate,
    },
    /// Read the users' forces of this label on every interface (and, with `positions`, the
    /// providers' kinematics) and give them to [`Scheduler::on_outputs`] (implicit schemes,
    /// after every node finished an iteration).
    NeedOutputs {
        label: Label,
        positions: bool,
    },
    /// The schedule is complete (every window announced ahead has been reported done).
    Finish {
        reason: String,
    },
}

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct SchedulerConfig {
    pub kind: ScheduleKind,
    pub window: f64,
    pub windows: u64,
    pub topology: Topology,
    /// One-way: kinetic energy (J) below which the DEM is steady ...
    pub steady_kinetic_energy: Option<f64>,
    /// ... for this many consecutive windows.
    pub steady_windows: u32,
    /// Implicit: the settings.
    pub implicit: Option<implicit::ImplicitSettings>,
    /// The interfaces (name, nodes), in the scene's order ...
    pub interfaces: Vec<(String, usize)>,
    /// ... and their reference positions, concatenated.
    pub positions: Vec<f64>,
    /// Adaptive windows: the settings, the limits the nodes reported, and the end time (s);
    /// `window` is then the first window's length.
    pub adaptive: Option<(adaptive::AdaptiveSettings, adaptive::Limits, f64)>,
    /// Windows the coordinator may announce beyond the one running (0: lockstep). Used only
    /// by schemes that [`Scheme::pipelines`], with fixed windows.
    pub lookahead: u64,
    /// The run loop checkpoints after every window w with (w + 1) % checkpoint_every == 0
    /// (0: never): no command of a later window may be sent before that checkpoint.
    pub checkpoint_every: u64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
enum Phase {
    Idle,
    Window,
    /// Implicit: every node finished an iteration; its outputs are awaited.
    #[serde(alias = "Forces")]
    Outputs,
    Final,
    Done,
}

/// The state machine of one run (serialisable: checkpoints store it).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Scheduler {
    topology: Topology,
    windows: Windows,
    scheme: SchemeState,
    phase: Phase,
    window: u64,
    pending: BTreeSet<String>,
    /// The DEM's kinetic energy at the end of the current window, once reported.
    #[serde(default)]
    window_kinetic_energy: Option<f64>,
    /// Why the run finishes after the final step.
    final_reason: String,
    /// The DEM reported that its programme (a periodic cell's stages) is finished: the run
    /// ends after the current window.
    #[serde(default)]
    programme_finished: bool,
    /// Lookahead: windows beyond the running one whose commands may be out (see
    /// [`SchedulerConfig::lookahead`]), the checkpoint period, and the first window whose
    /// commands have not been issued yet.
    #[serde(default)]
    lookahead: u64,
    #[serde(default)]
    checkpoint_every: u64,
    #[serde(default)]
    issued: u64,
    /// `issued` when the running window began (its commands went out ahead if greater).
    #[serde(default)]
    issued_before: u64,
    /// Windows whose commands went out before the window before them was complete.
    #[serde(default)]
    announced: u64,
    /// No more windows announced ahead in this process (an interrupt); not kept in
    /// checkpoints: a resumed run announces ahead again.
    #[serde(skip)]
    held: bool,
}

impl Scheduler {
    pub fn new(cfg: SchedulerConfig) -> Result<Scheduler, String> {
        let t = &cfg.topology;
        let both = t.dem.is_some() && !t.fems.is_empty();
        match cfg.kind {
            ScheduleKind::None if both => return Err("two solvers need a coupling schedule".into()),
            ScheduleKind::None if t.all().count() == 0 => return Err("no solver to run".into()),
            ScheduleKind::None if t.all().count() > 1 => {
                return Err("schedule `none` runs a single solver".into())
            }
            ScheduleKind::OneWay
            | ScheduleKind::Jit
            | ScheduleKind::Predictive
            | ScheduleKind::Implicit
            | ScheduleKind::Concurrent
                if !both =>
            {
                return Err(format!(
                    "schedule {:?} needs a DEM node and at least one FEM node",
                    cfg.kind
                ))
            }
            _ => {}
        }
        if cfg.windows == 0 {
            return Err("the run has no coupling window".into());
        }
        let scheme = match cfg.kind {
            ScheduleKind::None => SchemeState::None(alone::Alone),
            ScheduleKind::OneWay => SchemeState::OneWay(one_way::OneWay::new(
                cfg.steady_kinetic_energy,
                cfg.steady_windows,
            )),
            ScheduleKind::Jit => SchemeState::Jit(jit::Jit),
            ScheduleKind::Predictive => SchemeState::Predictive(predictive::Predictive),
            ScheduleKind::Concurrent => SchemeState::Concurrent(concurrent::Concurrent),
            ScheduleKind::Implicit => {
                let settings = cfg
                    .implicit
                    .clone()
                    .ok_or("the implicit schedule needs its settings")?;
                SchemeState::Implicit(Box::new(implicit::Implicit::new(
                    settings,
                    cfg.interfaces.clone(),
                    cfg.positions.clone(),
                )))
            }
        };
        let clock = match cfg.adaptive {
            None => None,
            Some(_) if !matches!(
                cfg.kind,
                ScheduleKind::Jit
                    | ScheduleKind::Predictive
                    | ScheduleKind::Concurrent
                    | ScheduleKind::Implicit
            ) =>
            {
                return Err(format!(
                    "adaptive windows need a two-way schedule (jit, predictive, concurrent or implicit), not {:?}",
                    cfg.kind
                ))
            }
            Some((settings, limits, end_time)) => {
                let base = settings.min_window;
                let whole = |t: f64, what: &str| -> Result<u64, String> {
                    let n = (t / base).round();
                    if n < 1.0 || (t / base - n).abs() > 1e-6 * n {
                        return Err(format!(
                            "{what} = {} is not a whole number of min_window = {}",
                            format_seconds(t),
                            format_seconds(base)
                        ));
                    }
                    Ok(n as u64)
                };
                let steps = whole(cfg.window, "the first window")?;
                if !steps.is_power_of_two() {
                    return Err(format!(
                        "the first window {} must be min_window × 2^i (min_window = {})",
                        format_seconds(cfg.window),
                        format_seconds(base)
                    ));
                }
                Some(Box::new(Clock {
                    controller: adaptive::Adaptive::new(settings, limits),
                    start: 0,
                    steps,
                    total: whole(end_time, "end_time")?,
                    observation: Default::default(),
                    iterations: 0,
                    changes: Vec::new(),
                }))
            }
        };
        Ok(Scheduler {
            topology: cfg.topology,
            windows: Windows {
                length: cfg.window,
                count: cfg.windows,
                adaptive: clock,
            },
            scheme,
            phase: Phase::Idle,
            window: 0,
            pending: BTreeSet::new(),
            window_kinetic_energy: None,
            final_reason: String::new(),
            programme_finished: false,
            lookahead: cfg.lookahead,
            checkpoint_every: cfg.checkpoint_every,
            issued: 0,
            issued_before: 0,
            announced: 0,
            held: false,
        })
    }

    /// The window now running (or next to run).
    pub fn window(&self) -> u64 {
        self.window
    }

    pub fn is_done(&self) -> bool {
        self.phase == Phase::Done
    }

    /// Nodes whose reply the scheduler waits for.
    pub fn pending(&self) -> impl Iterator<Item = &str> + '_ {
        self.pending.iter().map(String::as_str)
    }

    /// One-way: the DEM's kinetic energy when the end time forced the solve on a moving bed.
    pub fn unsettled_kinetic_energy(&mut self) -> Option<f64> {
        self.scheme.scheme().unsettled_kinetic_energy()
    }

    /// Implicit: the iterations since the last call (window, iteration, residual, ω).
    pub fn take_iterations(&mut self) -> Vec<implicit::IterationRecord> {
        self.scheme.scheme().take_iterations()
    }

    /// Implicit: the windows that ended unconverged (`continue_unconverged`).
    pub fn unconverged_windows(&self) -> &[u64] {
        self.scheme.scheme_ref().unconverged_windows()
    }

    /// The current window's start time and length (s).
    pub fn window_span(&self) -> (f64, f64) {
        (self.windows.t_start(self.window), self.windows.length)
    }

    /// Adaptive windows: a node's `window_done` numbers of the current window (the last
    /// iteration's count).
    pub fn observe(
        &mut self,
        node: &str,
        dem: bool,
        values: &std::collections::BTreeMap<String, f64>,
    ) {
        if dem && values.get("programme_finished").is_some_and(|v| *v >= 1.0) {
            self.programme_finished = true;
        }
        if let Some(c) = self.windows.adaptive.as_mut() {
            c.observation.record(node, dem, values);
        }
    }

    /// Adaptive windows: the changes of the window length since the last call.
    pub fn take_window_changes(&mut self) -> Vec<WindowChange> {
        self.windows
            .adaptive
            .as_mut()
            .map(|c| std::mem::take(&mut c.changes))
            .unwrap_or_default()
    }

    /// Adaptive windows: the next window's length, chosen after window k.
    fn choose_next_window(&mut self, k: u64) {
        let iterates = self.scheme.scheme_ref().iteration().is_some();
        let Some(c) = self.windows.adaptive.as_mut() else {
            return;
        };
        c.start += c.steps;
        let observation = std::mem::take(&mut c.observation);
        let iterations = std::mem::take(&mut c.iterations);
        let choice = c.controller.next(
            c.steps,
            c.total - c.start,
            &observation,
            iterates.then_some(iterations),
        );
        let base = c.controller.settings.min_window;
        if choice.steps != c.steps {
            c.changes.push(WindowChange {
                window: k + 1,
                from: c.steps as f64 * base,
                to: choice.steps as f64 * base,
                reason: choice.reason,
            });
        }
        c.steps = choice.steps;
        self.windows.length = c.steps as f64 * base;
    }

    /// Forces to publish as actions.
    fn publish(relaxed: Publications) -> Vec<Action> {
        relaxed
            .into_iter()
            .map(|(interface, label, estimate)| Action::Publish {
                interface,
                label,
                estimate,
            })
            .collect()
    }

    /// Sends as actions; the nodes that got an `advance_window` become pending.
    fn issue(&mut self, sends: Sends) -> Vec<Action> {
        for (node, body) in &sends {
            if matches!(body, CommandBody::AdvanceWindow(_)) {
                self.pending.insert(node.clone());
            }
        }
        sends.into_iter().map(|(n, b)| Action::Send(n, b)).collect()
    }

    /// Commands of window k (unless they went out ahead), then those of the windows that may
    /// be announced ahead of it.
    fn window_actions(&mut self, k: u64) -> Vec<Action> {
        self.phase = Phase::Window;
        self.window = k;
        self.window_kinetic_energy = None;
        // e.g. an implicit scheme's first force estimate goes out with the window's commands
        let mut out = Self::publish(self.scheme.scheme().window_publications(&self.windows, k));
        let sends = self
            .scheme
            .scheme()
            .window(&self.topology, &self.windows, k);
        self.issued_before = self.issued;
        if k < self.issued {
            // sent ahead: only the replies are awaited now
            for (node, body) in &sends {
                if matches!(body, CommandBody::AdvanceWindow(_)) {
                    self.pending.insert(node.clone());
                }
            }
        } else {
            out.extend(self.issue(sends));
            self.issued = k + 1;
        }
        out.extend(self.ahead());
        out
    }

    /// How many windows beyond the running one may be announced: the configured lookahead
    /// for a scheme whose commands do not depend on the nodes' reports and fixed windows
    /// (none once held, or once the DEM's programme has finished).
    pub fn effective_lookahead(&self) -> u64 {
        if self.windows.adaptive.is_some()
            || !self.scheme.scheme_ref().pipelines()
            || self.held
            || self.programme_finished
        {
            0
        } else {
            self.lookahead
        }
    }

    /// A resumed run's lookahead and checkpoint period (those of the scene and nodes now,
    /// not of the run that wrote the checkpoint).
    pub fn set_lookahead(&mut self, lookahead: u64, checkpoint_every: u64) {
        self.lookahead = lookahead;
        self.checkpoint_every = checkpoint_every;
    }

    /// How many windows went out before the window before them was complete.
    pub fn windows_announced_ahead(&self) -> u64 {
        self.announced
    }

    /// The last window whose commands have gone out.
    pub fn last_issued(&self) -> Option<u64> {
        self.issued.checked_sub(1)
    }

    /// Commands of the windows after the running one, up to the lookahead, the last window,
    /// and the next checkpoint (its snapshot must be taken before any later command).
    fn ahead(&mut self) -> Vec<Action> {
        let limit = (self.window + 1 + self.effective_lookahead()).min(self.windows.count);
        let mut out = Vec::new();
        while self.issued < limit {
            let j = self.issued;
            if self.checkpoint_every > 0 && j % self.checkpoint_every == 0 {
                break;
            }
            let sends = self
                .scheme
                .scheme()
                .window(&self.topology, &self.windows, j);
            out.extend(sends.into_iter().map(|(n, b)| Action::Send(n, b)));
            self.issued = j + 1;
            self.announced += 1;
        }
        out
    }

    /// No more windows announced ahead (e.g. an interrupt: the run stops, after a
    /// checkpoint, once the windows already announced are done).
    pub fn hold(&mut self) {
        self.held = true;
    }

    /// Windows may be announced ahead again after a [`Scheduler::hold`] (a wall-time
    /// checkpoint is written).
    pub fn release(&mut self) {
        self.held = false;
    }

    /// The running window's commands went out before the window before it was complete:
    /// the nodes may be computing it already, so a checkpoint now would not be of its start.
    pub fn announced_ahead(&self) -> bool {
        self.issued_before > self.window
    }

    /// The first commands of the run.
    pub fn start(&mut self) -> Vec<Action> {
        assert_eq!(self.phase, Phase::Idle, "start() called twice");
        let prologue = self.scheme.scheme().prologue(&self.topology);
        let mut out = self.issue(prologue);
        out.extend(self.window_actions(0));
        out
    }

    /// After a restore from a checkpoint taken between window k − 1 and window k (this
    /// scheduler's state at that moment): the interface data that was in flight at the
    /// checkpoint, published again from the restored states, then window k's commands.
    pub fn replay_actions(&mut self) -> Result<Vec<Action>, String> {
        if self.phase != Phase::Window || self.window == 0 {
            return Err(format!(
                "cannot resume a schedule in phase {:?} at window {}",
                self.phase, self.window
            ));
        }
        let k = self.window;
        self.pending.clear();
        // the restored nodes have received nothing of window k yet
        self.issued = k;
        let replay = self.scheme.scheme().replay(&self.topology, k);
        let mut out = self.issue(replay);
        out.extend(self.window_actions(k));
        Ok(out)
    }

    /// Node `node` finished window `window`; `kinetic_energy` is the DEM's, if it reported one.
    pub fn on_window_done(
        &mut self,
        node: &str,
        window: u64,
        kinetic_energy: Option<f64>,
    ) -> Result<Vec<Action>, String> {
        if !matches!(self.phase, Phase::Window | Phase::Final)
            || window != self.window
            || !self.pending.contains(node)
        {
            return Err(format!(
                "unexpected `window_done` from node `{node}` for window {window} (the run is at window {}, waiting for {:?})",
                self.window, self.pending
            ));
        }
        self.pending.remove(node);
        if kinetic_energy.is_some() {
            self.window_kinetic_energy = kinetic_energy;
        }
        if !self.pending.is_empty() {
            return Ok(Vec::new());
        }
        if self.phase == Phase::Final {
            self.phase = Phase::Done;
            return Ok(vec![Action::Finish {
                reason: std::mem::take(&mut self.final_reason),
            }]);
        }
        let scheme = self.scheme.scheme_ref();
        if let Some(iteration) = scheme.iteration() {
            self.phase = Phase::Outputs;
            return Ok(vec![Action::NeedOutputs {
                label: Label { window, iteration },
                positions: scheme.needs_positions(),
            }]);
        }
        self.next_after(window)
    }

    /// Implicit: the outputs of the iteration just finished, per interface.
    pub fn on_outputs(&mut self, outputs: &implicit::Outputs) -> Result<Vec<Action>, String> {
        let k = self.window;
        if self.phase != Phase::Outputs {
            return Err(format!("outputs of window {k} given out of turn"));
        }
        if let Some(c) = self.windows.adaptive.as_mut() {
            c.iterations += 1;
        }
        let next = self
            .scheme
            .scheme()
            .on_outputs(&self.topology, &self.windows, k, outputs)?;
        match next {
            implicit::Iterate::Converged => self.next_after(k),
            implicit::Iterate::Repeat { sends, relaxed } => {
                self.phase = Phase::Window;
                let mut out = Self::publish(relaxed);
                out.extend(self.issue(sends));
                Ok(out)
            }
        }
    }

    /// Window `window` is complete: what the scheme says follows.
    fn next_after(&mut self, window: u64) -> Result<Vec<Action>, String> {
        let next = self.scheme.scheme().after_window(
            &self.topology,
            &self.windows,
            window,
            self.window_kinetic_energy,
        );
        match next {
            Next::Final { sends, reason } => {
                self.phase = Phase::Final;
                self.final_reason = reason;
                Ok(self.issue(sends))
            }
            Next::Continue if self.windows.is_last(window) => {
                self.phase = Phase::Done;
                Ok(vec![Action::Finish {
                    reason: format!("end time reached after {} windows", window + 1),
                }])
            }
            // windows already announced run first (the run loop keeps a DEM programme in
            // lockstep; this is the guard if one reports its end without saying it has one)
            Next::Continue if self.programme_finished && self.issued <= window + 1 => {
                self.phase = Phase::Done;
                Ok(vec![Action::Finish {
                    reason: format!(
                        "the DEM's programme finished after {} windows (before end_time)",
                        window + 1
                    ),
                }])
            }
            Next::Continue => {
                self.choose_next_window(window);
                Ok(self.window_actions(window + 1))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DEM: &str = "dem";
    const FEM: &str = "fem";

    /// Adaptive settings from `min` to `max` with the default tolerance.
    fn ladder(min_window: f64, max_window: f64, iterations: u32) -> adaptive::AdaptiveSettings {
        adaptive::AdaptiveSettings {
            min_window,
            max_window,
            tolerance: 0.05,
            iterations,
        }
    }

    fn cfg(kind: ScheduleKind, windows: u64) -> SchedulerConfig {
        SchedulerConfig {
            kind,
            window: 1e-4,
            windows,
            topology: Topology {
                dem: Some(DEM.into()),
                fems: if kind == ScheduleKind::None {
                    vec![]
                } else {
                    vec![FEM.into()]
                },
            },
            steady_kinetic_energy: Some(1e-6),
            steady_windows: 2,
            implicit: None,
            interfaces: Vec::new(),
            positions: Vec::new(),
            adaptive: None,
            lookahead: 0,
            checkpoint_every: 0,
        }
    }

    fn advance(a: &Action) -> (&str, AdvanceWindow) {
        match a {
            Action::Send(r, CommandBody::AdvanceWindow(w)) => (r.as_str(), w.clone()),
            other => panic!("not an advance: {other:?}"),
        }
    }

    fn publish(node: &str, window: u64) -> Action {
        Action::Send(
            node.into(),
            CommandBody::Publish {
                label: Label::window(window),
            },
        )
    }

    fn l(window: u64) -> Option<Label> {
        Some(Label::window(window))
    }

    #[test]
    fn substeps_must_be_whole() {
        assert_eq!(substeps(1e-4, 1e-6).unwrap(), 100);
        assert_eq!(substeps(1e-5, 1e-6).unwrap(), 10);
        let e = substeps(1e-4, 3e-6).unwrap_err();
        assert!(
            e.contains("Δt^C = 100 µs") && e.contains("Δt^D = 3 µs (ratio 33.3333)"),
            "{e}"
        );
        assert!(e.contains("not a whole multiple"), "{e}");
    }

    #[test]
    fn jit_moves_dem_by_the_last_fem_kinematics_and_fem_by_this_windows_forces() {
        let mut s = Scheduler::new(cfg(ScheduleKind::Jit, 3)).unwrap();
        let a = s.start();
        assert_eq!(a[0], publish(FEM, 0));
        let (r, d) = advance(&a[1]);
        assert_eq!(
            (r, d.input, d.output, d.motion),
            (DEM, l(0), l(0), MotionRule::Quadratic)
        );
        let (r, f) = advance(&a[2]);
        assert_eq!((r, f.input, f.output), (FEM, l(0), l(1)));
        assert!(s.on_window_done(DEM, 0, None).unwrap().is_empty());
        let a = s.on_window_done(FEM, 0, None).unwrap();
        assert_eq!(advance(&a[0]).1.window, 1);
        s.on_window_done(FEM, 1, None).unwrap();
        let a = s.on_window_done(DEM, 1, None).unwrap();
        let (_, f) = advance(&a[1]);
        assert_eq!(
            (f.window, f.output),
            (2, None),
            "no kinematics after the last window"
        );
        s.on_window_done(DEM, 2, None).unwrap();
        let a = s.on_window_done(FEM, 2, None).unwrap();
        assert!(matches!(a[0], Action::Finish { .. }));
        assert!(s.is_done());
    }

    #[test]
    fn predictive_runs_fem_first_with_the_previous_dem_forces() {
        let mut s = Scheduler::new(cfg(ScheduleKind::Predictive, 2)).unwrap();
        let a = s.start();
        let (r, f) = advance(&a[0]);
        assert_eq!(
            (r, f.input, f.output, f.motion),
            (FEM, None, l(0), MotionRule::Linear)
        );
        let (r, d) = advance(&a[1]);
        assert_eq!((r, d.input, d.output), (DEM, l(0), l(0)));
        s.on_window_done(FEM, 0, None).unwrap();
        let a = s.on_window_done(DEM, 0, None).unwrap();
        let (_, f) = advance(&a[0]);
        assert_eq!((f.window, f.input, f.output), (1, l(0), l(1)));
        let (_, d) = advance(&a[1]);
        assert_eq!((d.window, d.output), (1, None));
    }

    #[test]
    fn concurrent_gives_both_their_window_at_once_each_with_the_others_previous_data() {
        let mut s = Scheduler::new(cfg(ScheduleKind::Concurrent, 3)).unwrap();
        let a = s.start();
        assert_eq!(
            a[0],
            publish(FEM, 0),
            "the FEM's initial state is kinematics 0"
        );
        let (r, d) = advance(&a[1]);
        assert_eq!(
            (r, d.input, d.output, d.motion),
            (DEM, l(0), l(0), MotionRule::Quadratic)
        );
        let (r, f) = advance(&a[2]);
        assert_eq!((r, f.input, f.output), (FEM, None, l(1)));
        // either may finish first; the next window waits for both
        assert!(s.on_window_done(FEM, 0, None).unwrap().is_empty());
        let a = s.on_window_done(DEM, 0, None).unwrap();
        let (_, d) = advance(&a[0]);
        let (_, f) = advance(&a[1]);
        assert_eq!((d.window, d.input, d.output), (1, l(1), l(1)));
        assert_eq!((f.window, f.input, f.output), (1, l(0), l(2)));
        s.on_window_done(DEM, 1, None).unwrap();
        let a = s.on_window_done(FEM, 1, None).unwrap();
        let (_, d) = advance(&a[0]);
        let (_, f) = advance(&a[1]);
        assert_eq!(
            (d.output, f.input, f.output),
            (None, l(1), None),
            "nothing is published in the last window"
        );
        s.on_window_done(FEM, 2, None).unwrap();
        let a = s.on_window_done(DEM, 2, None).unwrap();
        assert!(matches!(a[0], Action::Finish { .. }));
    }

    #[test]
    fn one_way_solves_statically_once_the_dem_is_steady() {
        let mut s = Scheduler::new(cfg(ScheduleKind::OneWay, 100)).unwrap();
        let a = s.start();
        assert_eq!(a.len(), 1);
        let a = s.on_window_done(DEM, 0, Some(1.0)).unwrap();
        assert_eq!(advance(&a[0]).1.window, 1);
        let a = s.on_window_done(DEM, 1, Some(1e-7)).unwrap();
        assert_eq!(advance(&a[0]).1.window, 2, "calm for one window only");
        let a = s.on_window_done(DEM, 2, Some(1e-5)).unwrap();
        assert_eq!(advance(&a[0]).1.window, 3, "a kick resets the count");
        s.on_window_done(DEM, 3, Some(1e-7)).unwrap();
        let a = s.on_window_done(DEM, 4, Some(1e-7)).unwrap();
        assert_eq!(a[0], publish(DEM, 4));
        let (r, f) = advance(&a[1]);
        assert_eq!((r, f.static_solve, f.input), (FEM, true, l(4)));
        assert!(
            s.on_window_done(DEM, 4, None).is_err(),
            "the DEM is not pending any more"
        );
        let a = s.on_window_done(FEM, 4, None).unwrap();
        assert!(matches!(a[0], Action::Finish { .. }));
    }

    #[test]
    fn one_way_says_when_the_end_time_forced_the_solve_on_a_moving_bed() {
        let mut s = Scheduler::new(cfg(ScheduleKind::OneWay, 3)).unwrap();
        s.start();
        s.on_window_done(DEM, 0, Some(1.0)).unwrap();
        s.on_window_done(DEM, 1, Some(1e-7)).unwrap();
        let a = s.on_window_done(DEM, 2, Some(1e-3)).unwrap();
        assert!(advance(&a[1]).1.static_solve);
        assert_eq!(s.unsettled_kinetic_energy(), Some(1e-3));
        // settled in time: nothing to say
        let mut s = Scheduler::new(cfg(ScheduleKind::OneWay, 100)).unwrap();
        s.start();
        s.on_window_done(DEM, 0, Some(1e-7)).unwrap();
        s.on_window_done(DEM, 1, Some(1e-7)).unwrap();
        assert_eq!(s.unsettled_kinetic_energy(), None);
    }

    #[test]
    fn a_restored_scheduler_republishes_the_data_in_flight_then_continues() {
        for (kind, replayed) in [
            (ScheduleKind::Jit, vec![publish(FEM, 2)]),
            (ScheduleKind::Predictive, vec![publish(DEM, 1)]),
            (
                ScheduleKind::Concurrent,
                vec![publish(FEM, 2), publish(DEM, 1)],
            ),
        ] {
            let mut s = Scheduler::new(cfg(kind, 5)).unwrap();
            s.start();
            s.on_window_done(DEM, 0, None).unwrap();
            s.on_window_done(FEM, 0, None).unwrap();
            s.on_window_done(DEM, 1, None).unwrap();
            let expected = s.on_window_done(FEM, 1, None).unwrap();
            // a checkpoint here, then a restore from its JSON
            let mut restored: Scheduler =
                serde_json::from_str(&serde_json::to_string(&s).unwrap()).unwrap();
            let a = restored.replay_actions().unwrap();
            let n = replayed.len();
            assert_eq!(&a[..n], &replayed[..], "{kind:?}");
            assert_eq!(&a[n..], &expected[..], "{kind:?}");
        }
    }

    #[test]
    fn out_of_order_window_done_is_refused() {
        let mut s = Scheduler::new(cfg(ScheduleKind::None, 5)).unwrap();
        s.start();
        let e = s.on_window_done(DEM, 3, None).unwrap_err();
        assert!(e.contains("window 3") && e.contains("window 0"), "{e}");
        assert!(s.on_window_done(FEM, 0, None).is_err());
    }

    #[test]
    fn schedules_refuse_the_wrong_solver_set() {
        let mut c = cfg(ScheduleKind::Jit, 2);
        c.topology.fems.clear();
        assert!(Scheduler::new(c).is_err());
    }

    #[test]
    fn several_structures_each_get_their_own_commands_and_the_window_waits_for_all() {
        for kind in [
            ScheduleKind::Jit,
            ScheduleKind::Predictive,
            ScheduleKind::Concurrent,
            ScheduleKind::OneWay,
        ] {
            let mut c = cfg(kind, 3);
            c.topology.fems = vec!["left".into(), "right".into()];
            let mut s = Scheduler::new(c).unwrap();
            let a = s.start();
            let advanced: Vec<&str> = a
                .iter()
                .filter_map(|a| match a {
                    Action::Send(n, CommandBody::AdvanceWindow(_)) => Some(n.as_str()),
                    _ => None,
                })
                .collect();
            let expected: Vec<&str> = match kind {
                ScheduleKind::Jit | ScheduleKind::Concurrent => vec![DEM, "left", "right"],
                ScheduleKind::Predictive => vec!["left", "right", DEM],
                _ => vec![DEM],
            };
            assert_eq!(advanced, expected, "{kind:?}");
            if matches!(kind, ScheduleKind::Jit | ScheduleKind::Concurrent) {
                assert_eq!(&a[..2], &[publish("left", 0), publish("right", 0)]);
            }
            if kind == ScheduleKind::OneWay {
                s.on_window_done(DEM, 0, Some(1e-9)).unwrap();
                let a = s.on_window_done(DEM, 1, Some(1e-9)).unwrap();
                assert_eq!(a[0], publish(DEM, 1));
                assert_eq!(
                    a[1..].iter().map(|x| advance(x).0).collect::<Vec<_>>(),
                    vec!["left", "right"]
                );
                assert!(s.on_window_done("left", 1, None).unwrap().is_empty());
                let a = s.on_window_done("right", 1, None).unwrap();
                assert!(matches!(a[0], Action::Finish { .. }));
                continue;
            }
            for n in [DEM, "left"] {
                assert!(s.on_window_done(n, 0, None).unwrap().is_empty());
            }
            let e = s.on_window_done("middle", 0, None).unwrap_err();
            assert!(e.contains("`middle`"), "{e}");
            let a = s.on_window_done("right", 0, None).unwrap();
            assert_eq!(advance(&a[0]).1.window, 1, "{kind:?}");
        }
    }

    fn implicit_cfg(
        acceleration: implicit::Acceleration,
        max_iterations: u32,
        continue_unconverged: bool,
    ) -> SchedulerConfig {
        let mut c = cfg(ScheduleKind::Implicit, 3);
        c.interfaces = vec![("top".into(), 2)];
        c.implicit = Some(implicit::ImplicitSettings {
            tolerance: 1e-6,
            max_iterations,
            acceleration: Some(acceleration),
            continue_unconverged,
            ..Default::default()
        });
        c
    }

    /// The users' response to a force estimate F: H(F) = −0.8 F + (1, 2, …) per component
    /// (a contracting fixed point that plain substitution (ω = 1) would approach slowly and
    /// oscillating).
    fn respond(estimate: &[f64]) -> implicit::Outputs {
        let h = estimate
            .iter()
            .enumerate()
            .map(|(i, f)| -0.8 * f + (i + 1) as f64)
            .collect();
        implicit::Outputs {
            forces: BTreeMap::from([("top".to_string(), h)]),
            positions: BTreeMap::new(),
        }
    }

    fn published(a: &[Action]) -> Vec<(Label, Vec<f64>)> {
        a.iter()
            .filter_map(|a| match a {
                Action::Publish {
                    label,
                    estimate: implicit::Estimate::Forces(forces),
                    ..
                } => Some((*label, forces.clone())),
                _ => None,
            })
            .collect()
    }

    use std::collections::BTreeMap;

    /// Runs window 0 to convergence; returns the iterations taken and the next window's actions.
    fn iterate_window(s: &mut Scheduler, first: Vec<Action>) -> (u32, Vec<Action>) {
        let mut actions = first;
        for j in 0..100u32 {
            let (estimate_label, estimate) = published(&actions).pop().expect("an estimate");
            assert_eq!(estimate_label.iteration, j);
            // both nodes were told to compute iteration j (after a rollback for j > 0)
            let advances: Vec<(String, AdvanceWindow)> = actions
                .iter()
                .filter_map(|a| match a {
                    Action::Send(n, CommandBody::AdvanceWindow(w)) => Some((n.clone(), w.clone())),
                    _ => None,
                })
                .collect();
            assert_eq!(advances.len(), 2);
            for (_, w) in &advances {
                assert_eq!(
                    (w.iteration, w.input, w.output),
                    (j, Some(estimate_label), Some(estimate_label))
                );
            }
            let rollbacks = actions
                .iter()
                .filter(|a| matches!(a, Action::Send(_, CommandBody::Rollback { window: 0 })))
                .count();
            let checkpoints = actions
                .iter()
                .filter(|a| matches!(a, Action::Send(_, CommandBody::Checkpoint { window: 0 })))
                .count();
            assert_eq!(
                (rollbacks, checkpoints),
                if j == 0 { (0, 2) } else { (2, 0) }
            );
            assert!(s.on_window_done(DEM, 0, None).unwrap().is_empty());
            let a = s.on_window_done(FEM, 0, None).unwrap();
            assert_eq!(
                a,
                vec![Action::NeedOutputs {
                    label: estimate_label,
                    positions: false
                }]
            );
            let next = s.on_outputs(&respond(&estimate)).unwrap();
            if s.window() == 1 {
                return (j + 1, next);
            }
            actions = next;
        }
        panic!("no convergence")
    }

    #[test]
    fn implicit_iterates_a_window_with_rollbacks_until_the_forces_are_a_fixed_point() {
        // the fixed point of H(F) = −0.8 F + c is F = c / 1.8
        let mut counts = Vec::new();
        for acc in [
            implicit::Acceleration::Aitken,
            implicit::Acceleration::Constant,
            implicit::Acceleration::IqnIls,
        ] {
            let mut s = Scheduler::new(implicit_cfg(acc, 100, false)).unwrap();
            let first = s.start();
            // window 0 starts from zero forces
            assert_eq!(published(&first), vec![(Label::window(0), vec![0.0; 6])]);
            let (iterations, next) = iterate_window(&mut s, first);
            // window 1 starts from window 0's converged forces, after a checkpoint
            let (label, f) = published(&next).pop().unwrap();
            assert_eq!(label, Label::window(1));
            for (i, v) in f.iter().enumerate() {
                assert!(
                    (v - (i + 1) as f64 / 1.8).abs() < 1e-5 * (i + 1) as f64,
                    "{f:?}"
                );
            }
            assert!(next
                .iter()
                .any(|a| matches!(a, Action::Send(_, CommandBody::Checkpoint { window: 1 }))));
            let records = s.take_iterations();
            assert_eq!(records.len() as u32, iterations);
            assert!(records.last().unwrap().residual <= 1e-6);
            counts.push(iterations);
        }
        // Aitken finds the linear fixed point in a couple of steps; ω = 0.5 contracts by 0.1
        // per iteration; IQN-ILS needs a secant per direction (6 here, fewer as they align)
        eprintln!(
            "iterations: Aitken {}, constant {}, IQN-ILS {}",
            counts[0], counts[1], counts[2]
        );
        assert!(counts[0] <= 4, "{counts:?}");
        assert!(counts[1] > counts[0], "{counts:?}");
        assert!(counts[2] <= 8, "{counts:?}");
    }

    #[test]
    fn implicit_stops_at_max_iterations_with_the_residuals_or_goes_on_when_allowed() {
        let mut s =
            Scheduler::new(implicit_cfg(implicit::Acceleration::Constant, 3, false)).unwrap();
        let mut actions = s.start();
        let mut err = None;
        for _ in 0..3 {
            let (_, estimate) = published(&actions).pop().unwrap();
            s.on_window_done(DEM, 0, None).unwrap();
            s.on_window_done(FEM, 0, None).unwrap();
            match s.on_outputs(&respond(&estimate)) {
                Ok(a) => actions = a,
                Err(e) => {
                    err = Some(e);
                    break;
                }
            }
        }
        let e = err.expect("not converged in 3 iterations");
        assert!(
            e.contains("window 0 did not converge in 3 iterations"),
            "{e}"
        );
        assert!(
            e.matches("e").count() > 3 && e.contains("tolerance 1.0e-6"),
            "{e}"
        );

        let mut s =
            Scheduler::new(implicit_cfg(implicit::Acceleration::Constant, 3, true)).unwrap();
        let mut actions = s.start();
        for _ in 0..3 {
            let (_, estimate) = published(&actions).pop().unwrap();
            s.on_window_done(DEM, 0, None).unwrap();
            s.on_window_done(FEM, 0, None).unwrap();
            actions = s.on_outputs(&respond(&estimate)).unwrap();
        }
        assert_eq!(s.window(), 1);
        assert_eq!(s.unconverged_windows(), &[0]);
        // a restored scheduler publishes the window's first estimate again and continues
        let mut restored: Scheduler =
            serde_json::from_str(&serde_json::to_string(&s).unwrap()).unwrap();
        assert_eq!(restored.replay_actions().unwrap(), actions);
    }

    /// The estimates of `a` by kind: (forces, positions) of interface `top`.
    fn estimates(a: &[Action]) -> (Vec<f64>, Option<Vec<f64>>) {
        let mut forces = None;
        let mut positions = None;
        for a in a {
            match a {
                Action::Publish {
                    estimate: implicit::Estimate::Forces(f),
                    ..
                } => forces = Some(f.clone()),
                Action::Publish {
                    estimate: implicit::Estimate::Kinematics { positions: p, .. },
                    ..
                } => positions = Some(p.clone()),
                _ => {}
            }
        }
        (forces.expect("a force estimate"), positions)
    }

    #[test]
    fn concurrent_implicit_estimates_forces_and_positions_and_converges_both() {
        // a linear Jacobi pair: the structure moves u = c F from P_k under the force estimate,
        // the particles push back f = g − κ (X − P_k) against the position estimate X; the
        // fixed point is F = g / (1 + κ c), u = c F
        // κc = 1.6: the plain Jacobi iteration's eigenvalues ±i√(κc) lie outside the unit
        // circle. (Aitken's single ω barely helps a Jacobi pair: at κc = 0.2 it needs 28
        // iterations for 1e-6, more than plain substitution; IQN-ILS is the concurrent
        // default.)
        let g = [10.0, -20.0, 30.0, 5.0, 0.0, -15.0];
        let reference = vec![0.0, 0.0, 1.0, 1.0, 0.0, 1.0];
        let (c, kappa) = (2e-6, 8e5);
        {
            let acc = implicit::Acceleration::IqnIls;
            let mut cfg = implicit_cfg(acc, 50, false);
            cfg.positions = reference.clone();
            if let Some(i) = cfg.implicit.as_mut() {
                i.concurrent = true;
            }
            let mut s = Scheduler::new(cfg).unwrap();
            let mut actions = s.start();
            let mut start = reference.clone();
            for k in 0..2u64 {
                let mut iterations = 0;
                loop {
                    let (f, x) = estimates(&actions);
                    let x = x.expect("a position estimate for the DEM");
                    if iterations == 0 && k == 0 {
                        assert_eq!((f.clone(), x.clone()), (vec![0.0; 6], reference.clone()));
                    }
                    for a in &actions {
                        if let Action::Send(_, CommandBody::AdvanceWindow(w)) = a {
                            assert_eq!(w.input, w.output);
                            assert_eq!(w.input.unwrap().iteration, iterations);
                        }
                    }
                    s.on_window_done(FEM, k, None).unwrap();
                    let a = s.on_window_done(DEM, k, None).unwrap();
                    assert!(matches!(
                        a.as_slice(),
                        [Action::NeedOutputs {
                            positions: true,
                            ..
                        }]
                    ));
                    let p: Vec<f64> = (0..6).map(|i| start[i] + c * f[i]).collect();
                    let h: Vec<f64> = (0..6).map(|i| g[i] - kappa * (x[i] - start[i])).collect();
                    let out = implicit::Outputs {
                        forces: BTreeMap::from([("top".to_string(), h)]),
                        positions: BTreeMap::from([("top".to_string(), p)]),
                    };
                    actions = s.on_outputs(&out).unwrap();
                    iterations += 1;
                    if s.window() != k {
                        // the next window starts where the DEM ended, from the converged forces
                        let (f, x) = estimates(&actions);
                        let x = x.unwrap();
                        for i in 0..6 {
                            let exact = g[i] / (1.0 + kappa * c);
                            assert!((f[i] - exact).abs() < 1e-5 * g[0], "{f:?}");
                            // the first position estimate extrapolates the FEM's displacement
                            let moved = c * exact;
                            assert!((x[i] - (start[i] + 2.0 * moved)).abs() < 1e-9, "{x:?}");
                        }
                        for i in 0..6 {
                            start[i] += c * g[i] / (1.0 + kappa * c);
                        }
                        break;
                    }
                    assert!(iterations < 50, "{acc:?}: no convergence");
                }
                // a linear pair of rank 6: at most one relaxation and six secant steps
                assert!(iterations <= 8, "{iterations} iterations");
            }
            // resume: a restored scheduler republishes the same estimates
            let mut restored: Scheduler =
                serde_json::from_str(&serde_json::to_string(&s).unwrap()).unwrap();
            assert_eq!(restored.replay_actions().unwrap(), actions);
        }
    }

    #[test]
    fn adaptive_windows_grow_in_free_flight_shrink_under_load_and_end_on_the_end_time() {
        let mut c = cfg(ScheduleKind::Predictive, 32);
        c.window = 1e-5;
        c.adaptive = Some((
            ladder(1e-5, 8e-5, 4),
            adaptive::Limits {
                loaded: Some(2.5e-5),
                radius_min: Some(1e-3),
            },
            // 32 bases: the last windows are cut to the time left
            3.2e-4,
        ));
        let mut s = Scheduler::new(c).unwrap();
        let mut actions = s.start();
        let mut spans = Vec::new();
        let mut changes = Vec::new();
        for k in 0.. {
            let (_, f) = advance(&actions[0]);
            assert_eq!(f.window, k);
            spans.push((f.t_start, f.dt));
            // windows 3–5 carry contact forces: the stiffness limit holds them at 20 µs
            let loaded = (3..6).contains(&k);
            let dem_values = BTreeMap::from([
                ("interface_work.top".to_string(), 1.0),
                (
                    "interface_force_max.top".to_string(),
                    if loaded { 2.0 } else { 0.0 },
                ),
            ]);
            let fem_values = BTreeMap::from([("interface_work.top".to_string(), 1.0)]);
            s.observe(FEM, false, &fem_values);
            s.on_window_done(FEM, k, None).unwrap();
            s.observe(DEM, true, &dem_values);
            actions = s.on_window_done(DEM, k, None).unwrap();
            changes.extend(s.take_window_changes());
            if matches!(actions[0], Action::Finish { .. }) {
                break;
            }
        }
        let dts: Vec<f64> = spans.iter().map(|x| x.1).collect();
        let base = 1e-5;
        let expected: Vec<f64> = [1, 2, 4, 8, 2, 2, 2, 4, 4, 2, 1]
            .iter()
            .map(|&n| n as f64 * base)
            .collect();
        assert_eq!(dts, expected, "{spans:?}");
        // contiguous, exactly on the ladder, ending on the end time
        for w in spans.windows(2) {
            assert_eq!(w[1].0, w[0].0 + w[0].1);
        }
        let (t, dt) = *spans.last().unwrap();
        assert!((t + dt - 3.2e-4).abs() < 1e-15);
        assert!(changes
            .iter()
            .any(|c| c.window == 4 && c.reason.contains("stiffness")));
        assert!(changes.iter().any(|c| c.reason == "the time left"));
        // the clock and the controller are in the checkpoint
        let restored: Scheduler =
            serde_json::from_str(&serde_json::to_string(&s).unwrap()).unwrap();
        assert_eq!(restored.window_span(), s.window_span());
    }

    #[test]
    fn concurrent_implicit_converges_when_a_contact_closes_within_the_window() {
        // the structure sags by u_free under its own weight plus c F; the particle pushes only
        // once the estimated surface has come within reach (u < −gap): the forces appear from
        // nothing in a later iteration, and the acceleration must not explain them away
        let (c, kappa, gap, u_free) = (2e-6, 1e5, 7e-5, -1e-4);
        let mut cfg = implicit_cfg(implicit::Acceleration::IqnIls, 30, false);
        cfg.positions = vec![0.0; 6];
        if let Some(i) = cfg.implicit.as_mut() {
            i.concurrent = true;
        }
        let mut s = Scheduler::new(cfg).unwrap();
        let mut actions = s.start();
        let mut contact_at = None;
        for j in 0..30u32 {
            let (f, x) = estimates(&actions);
            let x = x.unwrap();
            let h: Vec<f64> = x
                .iter()
                .map(|&u| if u < -gap { kappa * (-gap - u) } else { 0.0 })
                .collect();
            if contact_at.is_none() && h.iter().any(|&v| v > 0.0) {
                contact_at = Some(j);
            }
            let p: Vec<f64> = f.iter().map(|&f| u_free + c * f).collect();
            s.on_window_done(FEM, 0, None).unwrap();
            s.on_window_done(DEM, 0, None).unwrap();
            actions = s
                .on_outputs(&implicit::Outputs {
                    forces: BTreeMap::from([("top".to_string(), h)]),
                    positions: BTreeMap::from([("top".to_string(), p)]),
                })
                .unwrap_or_else(|e| panic!("{e}"));
            if s.window() == 1 {
                let (f, _) = estimates(&actions);
                let exact = kappa * (-gap - (-c * kappa * gap + u_free) / (1.0 + c * kappa));
                assert!(
                    contact_at.unwrap() > 0,
                    "the contact closes in a later iteration"
                );
                for v in f {
                    assert!((v - exact).abs() < 1e-5 * exact, "{v} vs {exact}");
                }
                return;
            }
        }
        panic!("no convergence in 30 iterations");
    }

    #[test]
    fn concurrent_implicit_scales_its_first_position_estimate_to_an_adaptive_window() {
        // window 0 (10 µs) converges on the linear pair with the interface unloaded by the
        // controller's reading (no interface_force_max): window 1 is twice as long, and its
        // first position estimate moves twice the FEM's displacement of window 0
        let (c, kappa) = (2e-6, 1e5);
        let g = [10.0, -20.0, 30.0, 5.0, 0.0, -15.0];
        let mut cfg = implicit_cfg(implicit::Acceleration::IqnIls, 30, false);
        cfg.positions = vec![0.0; 6];
        cfg.window = 1e-5;
        cfg.adaptive = Some((ladder(1e-5, 8e-5, 30), adaptive::Limits::default(), 3e-5));
        if let Some(i) = cfg.implicit.as_mut() {
            i.concurrent = true;
        }
        let mut s = Scheduler::new(cfg).unwrap();
        let mut actions = s.start();
        let mut p = Vec::new();
        while s.window() == 0 {
            let (f, x) = estimates(&actions);
            let x = x.unwrap();
            p = f.iter().map(|&f| c * f).collect();
            let h: Vec<f64> = (0..6).map(|i| g[i] - kappa * x[i]).collect();
            s.on_window_done(FEM, 0, None).unwrap();
            s.on_window_done(DEM, 0, None).unwrap();
            actions = s
                .on_outputs(&implicit::Outputs {
                    forces: BTreeMap::from([("top".to_string(), h)]),
                    positions: BTreeMap::from([("top".to_string(), p.clone())]),
                })
                .unwrap();
        }
        assert_eq!(s.window_span().1, 2e-5);
        let (_, x) = estimates(&actions);
        let x = x.unwrap();
        for i in 0..6 {
            // start of window 1 ≈ p (converged), plus twice window 0's displacement p
            assert!(
                (x[i] - 3.0 * p[i]).abs() < 1e-5 * p[i].abs().max(1e-12),
                "{x:?} {p:?}"
            );
        }
    }

    /// The (node, window) of every `advance_window` among the actions, in order.
    fn advances(a: &[Action]) -> Vec<(String, u64)> {
        a.iter()
            .filter_map(|a| match a {
                Action::Send(n, CommandBody::AdvanceWindow(w)) => Some((n.clone(), w.window)),
                _ => None,
            })
            .collect()
    }

    /// Every node reports window k; the actions that follow.
    fn finish_window(s: &mut Scheduler, k: u64) -> Vec<Action> {
        let mut out = s.on_window_done(DEM, k, None).unwrap();
        out.extend(s.on_window_done(FEM, k, None).unwrap());
        out
    }

    fn sends(a: &[Action]) -> Vec<(String, CommandBody)> {
        a.iter()
            .filter_map(|a| match a {
                Action::Send(n, b) => Some((n.clone(), b.clone())),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn lookahead_announces_windows_ahead_but_not_past_a_checkpoint_or_the_last_window() {
        for kind in [
            ScheduleKind::Jit,
            ScheduleKind::Predictive,
            ScheduleKind::Concurrent,
        ] {
            let mut c = cfg(kind, 6);
            c.lookahead = 2;
            c.checkpoint_every = 4;
            let mut s = Scheduler::new(c).unwrap();
            let mut all = s.start();
            let w = |a: &[Action]| -> Vec<u64> {
                let mut v: Vec<u64> = advances(a).into_iter().map(|(_, k)| k).collect();
                v.dedup();
                v
            };
            assert_eq!(w(&all), [0, 1, 2], "{kind:?}");
            assert!(!s.announced_ahead());
            // window 1 went out with window 0; now window 3 goes, window 4 waits for the
            // checkpoint after window 3
            let a = finish_window(&mut s, 0);
            assert_eq!(w(&a), [3], "{kind:?}");
            assert!(s.announced_ahead());
            assert_eq!(s.window(), 1);
            assert_eq!(
                s.pending().count(),
                2,
                "the replies of window 1 are awaited"
            );
            all.extend(a.clone());
            for k in [1, 2] {
                let a = finish_window(&mut s, k);
                assert!(advances(&a).is_empty(), "{kind:?} after window {k}: {a:?}");
                assert!(s.announced_ahead());
            }
            // the checkpoint after window 3 sees window 4's commands still unsent
            let a = finish_window(&mut s, 3);
            assert_eq!(w(&a), [4, 5], "{kind:?}");
            assert!(
                !s.announced_ahead(),
                "{kind:?}: a checkpoint now is of window 4's start"
            );
            all.extend(a);
            let a = finish_window(&mut s, 4);
            assert!(advances(&a).is_empty());
            let a = finish_window(&mut s, 5);
            assert!(matches!(a.as_slice(), [Action::Finish { .. }]), "{a:?}");

            // the same commands, in the same order per node, as windows one at a time
            let mut lockstep = Scheduler::new(cfg(kind, 6)).unwrap();
            let mut one = lockstep.start();
            for k in 0..6 {
                one.extend(finish_window(&mut lockstep, k));
            }
            for node in [DEM, FEM] {
                let of = |a: &[Action]| -> Vec<CommandBody> {
                    sends(a)
                        .into_iter()
                        .filter(|(n, _)| n == node)
                        .map(|(_, b)| b)
                        .collect()
                };
                assert_eq!(of(&all), of(&one), "{kind:?}, node {node}");
            }
        }
    }

    #[test]
    fn held_lookahead_lets_the_announced_windows_finish_then_runs_one_at_a_time() {
        let mut c = cfg(ScheduleKind::Jit, 8);
        c.lookahead = 2;
        let mut s = Scheduler::new(c).unwrap();
        s.start();
        assert_eq!(advances(&finish_window(&mut s, 0)).len(), 2);
        s.hold();
        for k in [1, 2] {
            assert!(advances(&finish_window(&mut s, k)).is_empty());
            assert!(s.announced_ahead(), "window {} went out earlier", k + 1);
        }
        let a = finish_window(&mut s, 3);
        let expected: Vec<(String, u64)> = vec![(DEM.into(), 4), (FEM.into(), 4)];
        assert_eq!(advances(&a), expected);
        assert!(!s.announced_ahead());
        // a checkpoint here restores to window 4 with nothing announced; the resumed run
        // announces ahead again
        let mut restored: Scheduler =
            serde_json::from_str(&serde_json::to_string(&s).unwrap()).unwrap();
        let a = restored.replay_actions().unwrap();
        let resumed: Vec<(String, u64)> = [4, 5, 6]
            .into_iter()
            .flat_map(|k| [(DEM.to_string(), k), (FEM.to_string(), k)])
            .collect();
        assert_eq!(advances(&a), resumed);
        assert!(!restored.announced_ahead());
        assert_eq!(restored.effective_lookahead(), 2);
        // a wall-time checkpoint releases the hold in the same process
        s.hold();
        assert_eq!(s.effective_lookahead(), 0);
        s.release();
        assert_eq!(s.effective_lookahead(), 2);
    }

    #[test]
    fn a_finished_programme_ends_the_run_after_the_windows_already_announced() {
        let mut c = cfg(ScheduleKind::None, 10);
        c.lookahead = 2;
        let mut s = Scheduler::new(c).unwrap();
        assert_eq!(advances(&s.start()).len(), 3);
        let finished = BTreeMap::from([("programme_finished".to_string(), 1.0)]);
        s.observe(DEM, true, &finished);
        assert_eq!(s.effective_lookahead(), 0);
        // windows 1 and 2 went out with window 0: they run, nothing more goes out
        for k in [0, 1] {
            let a = s.on_window_done(DEM, k, None).unwrap();
            assert!(a.is_empty(), "after window {k}: {a:?}");
        }
        let a = s.on_window_done(DEM, 2, None).unwrap();
        assert!(matches!(a.as_slice(), [Action::Finish { .. }]), "{a:?}");
    }

    #[test]
    fn lookahead_is_lockstep_where_the_next_window_depends_on_the_reports() {
        let mut c = cfg(ScheduleKind::OneWay, 6);
        c.lookahead = 3;
        let mut s = Scheduler::new(c).unwrap();
        let a = s.start();
        assert_eq!(
            advances(&a),
            [(DEM.to_string(), 0)],
            "one-way waits for the kinetic energy: {a:?}"
        );
        let mut c = implicit_cfg(implicit::Acceleration::Aitken, 5, false);
        c.lookahead = 3;
        let mut s = Scheduler::new(c).unwrap();
        let a = advances(&s.start());
        assert!(
            a.len() == 2 && a.iter().all(|(_, k)| *k == 0),
            "implicit: {a:?}"
        );
        let mut c = cfg(ScheduleKind::Predictive, 32);
        c.lookahead = 3;
        c.window = 1e-5;
        c.adaptive = Some((
            ladder(1e-5, 8e-5, 4),
            adaptive::Limits {
                loaded: None,
                radius_min: None,
            },
            3.2e-4,
        ));
        let mut s = Scheduler::new(c).unwrap();
        let a = advances(&s.start());
        assert!(
            a.len() == 2 && a.iter().all(|(_, k)| *k == 0),
            "adaptive: {a:?}"
        );
        // a single solver's windows need nothing from each other
        let mut c = cfg(ScheduleKind::None, 6);
        c.lookahead = 3;
        let mut s = Scheduler::new(c).unwrap();
        assert_eq!(advances(&s.start()).len(), 4);
    }
}
