//! The coupling schedules as pure state machines (Ullrich ch. 3, Algorithm 3).
//!
//! A [`Scheduler`] is told what happened (a node finished a window) and answers with the
//! commands to send. It never touches the network, so every schedule is unit-tested here.
//!
//! Data dependencies do the sequencing: both nodes get their window command at once; the
//! one that needs the other's data waits for it (matched by window index). Window indices of
//! interface data:
//! - just-in-time: FEM publishes kinematics `0` (its initial state) before window 0; in window
//!   k the DEM reads kinematics k, moves the mesh by x = P + Vτ + ½Aτ², publishes forces k; the
//!   FEM reads forces k, steps, publishes kinematics k + 1.
//! - predictive: in window k the FEM reads forces k − 1 (none in window 0), steps from P_k to
//!   P_{k+1}, publishes kinematics k = (P_k, V = (P_{k+1} − P_k)/Δt^F, A = 0) (3.4–3.7); the DEM
//!   reads them, so its mesh lands exactly on P_{k+1}, and publishes forces k.
//! - one-way: the DEM runs windows against the fixed mesh until its kinetic energy is below
//!   the threshold, publishes its forces once, and the FEM solves statically with them.

use std::collections::BTreeSet;

use proto::{AdvanceWindow, CommandBody, MotionRule, Role};

use crate::scene::ScheduleKind;
use crate::units::format_seconds;

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

/// What the coordinator must do next.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    Send(Role, CommandBody),
    /// The schedule is complete.
    Finish {
        reason: String,
    },
}

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct SchedulerConfig {
    pub kind: ScheduleKind,
    pub window: f64,
    pub windows: u64,
    /// n^D (1 when there is no DEM).
    pub substeps: u32,
    pub force_averaging: bool,
    pub has_dem: bool,
    pub has_fem: bool,
    /// One-way: kinetic energy (J) below which the DEM is steady ...
    pub steady_kinetic_energy: Option<f64>,
    /// ... for this many consecutive windows.
    pub steady_windows: u32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
enum Phase {
    Idle,
    Window,
    OneWaySolve,
    Done,
}

/// The state machine of one run (serialisable: checkpoints store it).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Scheduler {
    cfg: SchedulerConfig,
    phase: Phase,
    window: u64,
    pending: BTreeSet<Role>,
    /// Consecutive windows with the DEM below the steady kinetic energy.
    calm_windows: u32,
    /// One-way: the DEM was still moving when the end time forced the static solve (its
    /// kinetic energy then, J): the run says so instead of passing the forces off as settled.
    #[serde(default)]
    pub unsettled_kinetic_energy: Option<f64>,
}

impl Scheduler {
    pub fn new(cfg: SchedulerConfig) -> Result<Scheduler, String> {
        let both = cfg.has_dem && cfg.has_fem;
        match cfg.kind {
            ScheduleKind::None if both => return Err("two solvers need a coupling schedule".into()),
            ScheduleKind::None if !cfg.has_dem && !cfg.has_fem => {
                return Err("no solver to run".into())
            }
            ScheduleKind::OneWay | ScheduleKind::Jit | ScheduleKind::Predictive if !both => {
                return Err(format!(
                    "schedule {:?} needs both a DEM and a FEM node",
                    cfg.kind
                ))
            }
            _ => {}
        }
        if cfg.windows == 0 {
            return Err("the run has no coupling window".into());
        }
        Ok(Scheduler {
            cfg,
            phase: Phase::Idle,
            window: 0,
            pending: BTreeSet::new(),
            calm_windows: 0,
            unsettled_kinetic_energy: None,
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
    pub fn pending(&self) -> impl Iterator<Item = Role> + '_ {
        self.pending.iter().copied()
    }

    fn t_start(&self, k: u64) -> f64 {
        k as f64 * self.cfg.window
    }

    fn advance(
        &self,
        k: u64,
        motion: MotionRule,
        input: Option<u64>,
        output: Option<u64>,
        static_solve: bool,
    ) -> AdvanceWindow {
        AdvanceWindow {
            window: k,
            t_start: self.t_start(k),
            dt: self.cfg.window,
            substeps: self.cfg.substeps,
            motion,
            force_averaging: self.cfg.force_averaging,
            input_window: input,
            output_window: output,
            static_solve,
        }
    }

    /// Commands of window k.
    fn window_actions(&mut self, k: u64) -> Vec<Action> {
        let last = k + 1 == self.cfg.windows;
        let mut out = Vec::new();
        match self.cfg.kind {
            ScheduleKind::None => {
                let role = if self.cfg.has_dem {
                    Role::Dem
                } else {
                    Role::Fem
                };
                out.push((role, self.advance(k, MotionRule::Fixed, None, None, false)));
            }
            ScheduleKind::OneWay => out.push((
                Role::Dem,
                self.advance(k, MotionRule::Fixed, None, None, false),
            )),
            ScheduleKind::Jit => {
                out.push((
                    Role::Dem,
                    self.advance(k, MotionRule::Quadratic, Some(k), Some(k), false),
                ));
                out.push((
                    Role::Fem,
                    self.advance(
                        k,
                        MotionRule::Quadratic,
                        Some(k),
                        (!last).then_some(k + 1),
                        false,
                    ),
                ));
            }
            ScheduleKind::Predictive => {
                out.push((
                    Role::Fem,
                    self.advance(k, MotionRule::Linear, k.checked_sub(1), Some(k), false),
                ));
                out.push((
                    Role::Dem,
                    self.advance(k, MotionRule::Linear, Some(k), (!last).then_some(k), false),
                ));
            }
        }
        self.phase = Phase::Window;
        self.window = k;
        self.pending = out.iter().map(|(r, _)| *r).collect();
        out.into_iter()
            .map(|(r, a)| Action::Send(r, CommandBody::AdvanceWindow(a)))
            .collect()
    }

    /// The first commands of the run.
    pub fn start(&mut self) -> Vec<Action> {
        assert_eq!(self.phase, Phase::Idle, "start() called twice");
        let mut out = Vec::new();
        if self.cfg.kind == ScheduleKind::Jit {
            // The DEM's first window needs the FEM's initial kinematics.
            out.push(Action::Send(
                Role::Fem,
                CommandBody::Publish {
                    window: 0,
                    force_averaging: false,
                },
            ));
        }
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
        let mut out = Vec::new();
        match self.cfg.kind {
            // the FEM's state at the end of window k − 1 is kinematics k
            ScheduleKind::Jit => out.push(Action::Send(
                Role::Fem,
                CommandBody::Publish {
                    window: k,
                    force_averaging: false,
                },
            )),
            // the DEM's forces of window k − 1 load the FEM in window k
            ScheduleKind::Predictive => out.push(Action::Send(
                Role::Dem,
                CommandBody::Publish {
                    window: k - 1,
                    force_averaging: self.cfg.force_averaging,
                },
            )),
            ScheduleKind::OneWay | ScheduleKind::None => {}
        }
        out.extend(self.window_actions(k));
        Ok(out)
    }

    /// A node finished window `window`; `kinetic_energy` is the DEM's, if it reported one.
    pub fn on_window_done(
        &mut self,
        role: Role,
        window: u64,
        kinetic_energy: Option<f64>,
    ) -> Result<Vec<Action>, String> {
        if !matches!(self.phase, Phase::Window | Phase::OneWaySolve)
            || window != self.window
            || !self.pending.contains(&role)
        {
            return Err(format!(
                "unexpected `window_done` from the {role} node for window {window} (the run is at window {}, waiting for {:?})",
                self.window, self.pending
            ));
        }
        self.pending.remove(&role);
        if !self.pending.is_empty() {
            return Ok(Vec::new());
        }
        if self.phase == Phase::OneWaySolve {
            self.phase = Phase::Done;
            return Ok(vec![Action::Finish {
                reason: format!("static FEM solve with the DEM forces of window {window} done"),
            }]);
        }
        let last = window + 1 == self.cfg.windows;
        if self.cfg.kind == ScheduleKind::OneWay {
            let calm = match (kinetic_energy, self.cfg.steady_kinetic_energy) {
                (Some(e), Some(limit)) => e < limit,
                _ => false,
            };
            self.calm_windows = if calm { self.calm_windows + 1 } else { 0 };
            let steady = self.calm_windows >= self.cfg.steady_windows;
            if steady || last {
                if !steady && self.cfg.steady_kinetic_energy.is_some() {
                    self.unsettled_kinetic_energy = Some(kinetic_energy.unwrap_or(f64::NAN));
                }
                // Ullrich ch. 4: the settled DEM forces load a static FEM solve.
                self.phase = Phase::OneWaySolve;
                self.pending = [Role::Fem].into();
                let solve = self.advance(window, MotionRule::Fixed, Some(window), None, true);
                return Ok(vec![
                    Action::Send(
                        Role::Dem,
                        CommandBody::Publish {
                            window,
                            force_averaging: self.cfg.force_averaging,
                        },
                    ),
                    Action::Send(Role::Fem, CommandBody::AdvanceWindow(solve)),
                ]);
            }
        }
        if last {
            self.phase = Phase::Done;
            return Ok(vec![Action::Finish {
                reason: format!("end time reached after {} windows", window + 1),
            }]);
        }
        Ok(self.window_actions(window + 1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg(kind: ScheduleKind, windows: u64) -> SchedulerConfig {
        SchedulerConfig {
            kind,
            window: 1e-4,
            windows,
            substeps: 10,
            force_averaging: false,
            has_dem: true,
            has_fem: kind != ScheduleKind::None,
            steady_kinetic_energy: Some(1e-6),
            steady_windows: 2,
        }
    }

    fn advance(a: &Action) -> (Role, AdvanceWindow) {
        match a {
            Action::Send(r, CommandBody::AdvanceWindow(w)) => (*r, w.clone()),
            other => panic!("not an advance: {other:?}"),
        }
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
        assert_eq!(
            a[0],
            Action::Send(
                Role::Fem,
                CommandBody::Publish {
                    window: 0,
                    force_averaging: false
                }
            )
        );
        let (r, d) = advance(&a[1]);
        assert_eq!(
            (r, d.input_window, d.output_window, d.motion),
            (Role::Dem, Some(0), Some(0), MotionRule::Quadratic)
        );
        let (r, f) = advance(&a[2]);
        assert_eq!(
            (r, f.input_window, f.output_window),
            (Role::Fem, Some(0), Some(1))
        );
        assert!(s.on_window_done(Role::Dem, 0, None).unwrap().is_empty());
        let a = s.on_window_done(Role::Fem, 0, None).unwrap();
        assert_eq!(advance(&a[0]).1.window, 1);
        s.on_window_done(Role::Fem, 1, None).unwrap();
        let a = s.on_window_done(Role::Dem, 1, None).unwrap();
        let (_, f) = advance(&a[1]);
        assert_eq!(
            (f.window, f.output_window),
            (2, None),
            "no kinematics after the last window"
        );
        s.on_window_done(Role::Dem, 2, None).unwrap();
        let a = s.on_window_done(Role::Fem, 2, None).unwrap();
        assert!(matches!(a[0], Action::Finish { .. }));
        assert!(s.is_done());
    }

    #[test]
    fn predictive_runs_fem_first_with_the_previous_dem_forces() {
        let mut s = Scheduler::new(cfg(ScheduleKind::Predictive, 2)).unwrap();
        let a = s.start();
        let (r, f) = advance(&a[0]);
        assert_eq!(
            (r, f.input_window, f.output_window, f.motion),
            (Role::Fem, None, Some(0), MotionRule::Linear)
        );
        let (r, d) = advance(&a[1]);
        assert_eq!(
            (r, d.input_window, d.output_window),
            (Role::Dem, Some(0), Some(0))
        );
        s.on_window_done(Role::Fem, 0, None).unwrap();
        let a = s.on_window_done(Role::Dem, 0, None).unwrap();
        let (_, f) = advance(&a[0]);
        assert_eq!(
            (f.window, f.input_window, f.output_window),
            (1, Some(0), Some(1))
        );
        let (_, d) = advance(&a[1]);
        assert_eq!((d.window, d.output_window), (1, None));
    }

    #[test]
    fn one_way_solves_statically_once_the_dem_is_steady() {
        let mut s = Scheduler::new(cfg(ScheduleKind::OneWay, 100)).unwrap();
        let a = s.start();
        assert_eq!(a.len(), 1);
        let a = s.on_window_done(Role::Dem, 0, Some(1.0)).unwrap();
        assert_eq!(advance(&a[0]).1.window, 1);
        let a = s.on_window_done(Role::Dem, 1, Some(1e-7)).unwrap();
        assert_eq!(advance(&a[0]).1.window, 2, "calm for one window only");
        let a = s.on_window_done(Role::Dem, 2, Some(1e-5)).unwrap();
        assert_eq!(advance(&a[0]).1.window, 3, "a kick resets the count");
        s.on_window_done(Role::Dem, 3, Some(1e-7)).unwrap();
        let a = s.on_window_done(Role::Dem, 4, Some(1e-7)).unwrap();
        assert_eq!(
            a[0],
            Action::Send(
                Role::Dem,
                CommandBody::Publish {
                    window: 4,
                    force_averaging: false
                }
            )
        );
        let (r, f) = advance(&a[1]);
        assert_eq!(
            (r, f.static_solve, f.input_window),
            (Role::Fem, true, Some(4))
        );
        assert!(
            s.on_window_done(Role::Dem, 4, None).is_err(),
            "the DEM is not pending any more"
        );
        let a = s.on_window_done(Role::Fem, 4, None).unwrap();
        assert!(matches!(a[0], Action::Finish { .. }));
    }

    #[test]
    fn one_way_says_when_the_end_time_forced_the_solve_on_a_moving_bed() {
        let mut s = Scheduler::new(cfg(ScheduleKind::OneWay, 3)).unwrap();
        s.start();
        s.on_window_done(Role::Dem, 0, Some(1.0)).unwrap();
        s.on_window_done(Role::Dem, 1, Some(1e-7)).unwrap();
        let a = s.on_window_done(Role::Dem, 2, Some(1e-3)).unwrap();
        assert!(advance(&a[1]).1.static_solve);
        assert_eq!(s.unsettled_kinetic_energy, Some(1e-3));
        // settled in time: nothing to say
        let mut s = Scheduler::new(cfg(ScheduleKind::OneWay, 100)).unwrap();
        s.start();
        s.on_window_done(Role::Dem, 0, Some(1e-7)).unwrap();
        s.on_window_done(Role::Dem, 1, Some(1e-7)).unwrap();
        assert_eq!(s.unsettled_kinetic_energy, None);
    }

    #[test]
    fn a_restored_scheduler_republishes_the_data_in_flight_then_continues() {
        for (kind, role, window) in [
            (ScheduleKind::Jit, Role::Fem, 2),
            (ScheduleKind::Predictive, Role::Dem, 1),
        ] {
            let mut s = Scheduler::new(cfg(kind, 5)).unwrap();
            s.start();
            s.on_window_done(Role::Dem, 0, None).unwrap();
            s.on_window_done(Role::Fem, 0, None).unwrap();
            s.on_window_done(Role::Dem, 1, None).unwrap();
            let expected = s.on_window_done(Role::Fem, 1, None).unwrap();
            // a checkpoint here, then a restore from its JSON
            let mut restored: Scheduler =
                serde_json::from_str(&serde_json::to_string(&s).unwrap()).unwrap();
            let a = restored.replay_actions().unwrap();
            assert_eq!(
                a[0],
                Action::Send(
                    role,
                    CommandBody::Publish {
                        window,
                        force_averaging: false
                    }
                ),
                "{kind:?}"
            );
            assert_eq!(&a[1..], &expected[..], "{kind:?}");
        }
    }

    #[test]
    fn out_of_order_window_done_is_refused() {
        let mut s = Scheduler::new(cfg(ScheduleKind::None, 5)).unwrap();
        s.start();
        let e = s.on_window_done(Role::Dem, 3, None).unwrap_err();
        assert!(e.contains("window 3") && e.contains("window 0"), "{e}");
        assert!(s.on_window_done(Role::Fem, 0, None).is_err());
    }

    #[test]
    fn schedules_refuse_the_wrong_solver_set() {
        let mut c = cfg(ScheduleKind::Jit, 2);
        c.has_fem = false;
        assert!(Scheduler::new(c).is_err());
    }
}
