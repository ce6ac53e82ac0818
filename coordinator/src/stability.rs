//! The stability monitor: watches interface data digests window by window and names the
//! cause when the coupling diverges (runaway force growth, mesh drift), so that a run
//! stops with "unstable at window k (t = …)" instead of writing NaNs.

use proto::participant::Digest;

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct StabilityMonitor {
    max_growth: f64,
    /// Largest force norm seen so far, per interface.
    peak_force: std::collections::BTreeMap<String, f64>,
    last_force: std::collections::BTreeMap<String, f64>,
    /// A length scale of the interface (its bounding-box diagonal), for the drift check.
    pub mesh_size: Option<f64>,
    /// `(window length, smallest particle radius)`: an interface moving more than half a
    /// particle radius in one window no longer resolves its contacts (the coupled system has
    /// diverged even when no force has run away yet).
    #[serde(default)]
    pub step_limit: Option<(f64, f64)>,
    reference_centre: std::collections::BTreeMap<String, [f64; 3]>,
    /// The energy audit's early warning, per interface.
    #[serde(default)]
    energy: std::collections::BTreeMap<String, EnergyWatch>,
    /// The window over the schedule's estimated stability limit (limits.rs), when known:
    /// the remedy a divergence message proposes depends on it.
    #[serde(default)]
    pub window_over_limit: Option<f64>,
}

/// Windows below this fraction of the schedule's estimated limit are far inside it: a
/// divergence there is more likely the model's than the coupling's.
const FAR_INSIDE_LIMIT: f64 = 0.1;

/// Per interface: the last windows' energy mismatches |W_DEM − W_FEM| and the largest work of
/// one window so far, for [`StabilityMonitor::observe_work`].
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
struct EnergyWatch {
    mismatch: std::collections::VecDeque<f64>,
    largest_work: f64,
    growing: bool,
    warned: bool,
}

/// Windows of mismatch history the early warning looks at.
const ENERGY_HISTORY: usize = 8;

/// Why a run was stopped.
#[derive(Debug, Clone, PartialEq)]
pub struct Instability {
    pub window: u64,
    pub time: f64,
    pub cause: String,
}

impl std::fmt::Display for Instability {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "unstable at window {} (t = {:.6e} s): {}",
            self.window, self.time, self.cause
        )
    }
}

/// Diagonal of the bounding box of flat xyz positions (m).
pub fn bounding_diagonal(xyz: &[f64]) -> f64 {
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for p in xyz.chunks_exact(3) {
        for i in 0..3 {
            lo[i] = lo[i].min(p[i]);
            hi[i] = hi[i].max(p[i]);
        }
    }
    if xyz.len() < 3 {
        return 0.0;
    }
    (0..3).map(|i| (hi[i] - lo[i]).powi(2)).sum::<f64>().sqrt()
}

impl StabilityMonitor {
    pub fn new(max_growth: f64) -> Self {
        StabilityMonitor {
            max_growth,
            peak_force: Default::default(),
            last_force: Default::default(),
            mesh_size: None,
            step_limit: None,
            reference_centre: Default::default(),
            energy: Default::default(),
            window_over_limit: None,
        }
    }

    /// What to do about a divergence: shorten the window or change the schedule — unless the
    /// window is far inside the schedule's estimated limit, where the coupling is rarely the
    /// cause (a triaxial membrane at 400 kPa folded in with 2 % and with 1 % of its limit
    /// alike: its grains passed through a too-soft contact partner).
    fn remedy(&self) -> String {
        match self.window_over_limit {
            Some(r) if r < FAR_INSIDE_LIMIT => format!(
                "the window is only {r:.3} of this schedule's estimated stability limit, so the \
                 coupling is an unlikely cause: look for a part of the structure without support, \
                 particles passing through the interface (contact partner too soft for the load: \
                 overlaps near the particle radius) or a load the mesh cannot carry, in the last \
                 snapshots; a shorter window tells the two apart"
            ),
            _ => "reduce the coupling window or use the predictive schedule".into(),
        }
    }

    /// The energy audit's early warning: the interface's energy mismatch of window `window`,
    /// |W_DEM − W_FEM|, looked at over the last windows. Its envelope over pairs of windows
    /// (explicit schemes diverge with an odd–even oscillation) growing monotonically, by 8× or
    /// more over six windows, beyond the largest work any single window exchanged so far, in
    /// two windows running, says the coupling is diverging — measured on sleeper-ci with a
    /// too-long just-in-time window, 87 windows before the motion check stopped it, and on
    /// none of the stable scenes (docs/coupling.md). Returns the warning once.
    pub fn observe_work(
        &mut self,
        interface: &str,
        window: u64,
        dem: f64,
        fem: f64,
    ) -> Option<String> {
        let w = self.energy.entry(interface.to_string()).or_default();
        w.mismatch.push_back((dem - fem).abs());
        if w.mismatch.len() > ENERGY_HISTORY {
            w.mismatch.pop_front();
        }
        let m = &w.mismatch;
        let growing = m.len() == ENERGY_HISTORY && {
            // envelope e_j = max(m_j, m_{j−1}) at the last window and 2, 4, 6 windows before
            let e = |back: usize| {
                let i = m.len() - 1 - back;
                m[i].max(m[i - 1])
            };
            let (e0, e2, e4, e6) = (e(0), e(2), e(4), e(6));
            e0 > e2 && e2 > e4 && e4 > e6 && e0 >= 8.0 * e6 && e0 > w.largest_work
        };
        let fire = growing && w.growing && !w.warned;
        w.growing = growing;
        w.largest_work = w.largest_work.max(dem.abs()).max(fem.abs());
        if fire {
            w.warned = true;
            let e = w.mismatch.back().copied().unwrap_or(0.0);
            let remedy = self.remedy();
            return Some(format!(
                "energy audit: the work mismatch at interface `{interface}` grows window after window (|W_DEM − W_FEM| = {e:.3e} J at window {window}, more than any window's work so far): the coupling may be diverging; {remedy}"
            ));
        }
        None
    }

    /// Looks at one digest; `Some` when the run must stop.
    pub fn observe(&mut self, d: &Digest) -> Option<Instability> {
        let fail = |cause: String| {
            Some(Instability {
                window: d.window,
                time: d.time,
                cause,
            })
        };
        // non-finite data is not looked at here: it is the sender's invalid data (run.rs)
        match d.kind {
            "forces" => {
                let f = d.max_norm;
                let last = self.last_force.get(&d.interface).copied().unwrap_or(0.0);
                let peak = self.peak_force.get(&d.interface).copied().unwrap_or(0.0);
                if last > 0.0 && f > self.max_growth * last && f > 10.0 * peak {
                    return fail(format!(
                        "the largest interface nodal force on `{}` grew from {last:.3e} N to {f:.3e} N in one window (more than {}×; now on its node {}): the coupling diverges; {}",
                        d.interface, self.max_growth, d.max_node, self.remedy()
                    ));
                }
                self.last_force.insert(d.interface.clone(), f);
                self.peak_force.insert(d.interface.clone(), peak.max(f));
            }
            "kinematics" => {
                let centre = *self
                    .reference_centre
                    .entry(d.interface.clone())
                    .or_insert(d.total);
                if let Some((window, radius)) = self.step_limit {
                    let step = d.max_norm * window;
                    if step > 0.5 * radius {
                        let at = d.max_position.map_or(String::new(), |x| {
                            format!(" at ({:.4}, {:.4}, {:.4}) m", x[0], x[1], x[2])
                        });
                        return fail(format!(
                            "node {} of interface `{}`{at} moves at {:.3e} m/s: {step:.3e} m in one window of {window:.3e} s, more than half the smallest particle contact radius ({radius:.3e} m: a sphere's radius, a stone's dilation); the coupling diverges — {}",
                            d.max_node, d.interface, d.max_norm, self.remedy()
                        ));
                    }
                }
                if let Some(size) = self.mesh_size {
                    let drift = ((0..3)
                        .map(|i| (d.total[i] - centre[i]).powi(2))
                        .sum::<f64>())
                    .sqrt();
                    if drift > size {
                        return fail(format!(
                            "the interface `{}` drifted {drift:.3e} m from its start, more than its own size {size:.3e} m",
                            d.interface
                        ));
                    }
                }
            }
            _ => {}
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn forces(window: u64, f: f64) -> Digest {
        Digest {
            interface: "top".into(),
            window,
            time: window as f64 * 1e-4,
            kind: "forces",
            max_norm: f,
            max_node: 3,
            max_position: None,
            total: [0.0, 0.0, f],
            non_finite: None,
        }
    }

    #[test]
    fn an_interface_outrunning_the_particles_stops_the_run() {
        let mut m = StabilityMonitor::new(1e3);
        m.step_limit = Some((1e-4, 0.01));
        let k = |speed: f64| Digest {
            interface: "bottom".into(),
            window: 7,
            time: 7e-4,
            kind: "kinematics",
            max_norm: speed,
            max_node: 5,
            max_position: Some([0.1, 0.2, 0.3]),
            total: [0.0; 3],
            non_finite: None,
        };
        assert!(m.observe(&k(49.0)).is_none());
        let e = m.observe(&k(51.0)).unwrap();
        assert!(
            e.cause
                .contains("half the smallest particle contact radius"),
            "{e}"
        );
        // the node is named, with where it is
        assert!(
            e.cause
                .contains("node 5 of interface `bottom` at (0.1000, 0.2000, 0.3000) m"),
            "{e}"
        );
    }

    /// The remedy the messages propose: a shorter window or another schedule, unless the
    /// window is far inside the schedule's estimated limit — then the model is named first.
    #[test]
    fn a_divergence_far_inside_the_limit_points_at_the_model() {
        let k = Digest {
            interface: "membrane".into(),
            window: 1390,
            time: 2.78e-2,
            kind: "kinematics",
            max_norm: 41.5,
            max_node: 194,
            max_position: Some([0.0252, 0.0252, 0.1671]),
            total: [0.0; 3],
            non_finite: None,
        };
        let stop = |ratio: Option<f64>| {
            let mut m = StabilityMonitor::new(1e3);
            m.step_limit = Some((2e-5, 1.65e-3));
            m.window_over_limit = ratio;
            m.observe(&k).expect("stops").cause
        };
        for near in [None, Some(0.5), Some(1.3)] {
            let c = stop(near);
            assert!(c.contains("reduce the coupling window"), "{c}");
            assert!(!c.contains("unlikely cause"), "{c}");
        }
        let c = stop(Some(0.008));
        assert!(
            c.contains("only 0.008 of this schedule's estimated stability limit"),
            "{c}"
        );
        assert!(c.contains("particles passing through the interface"), "{c}");
        assert!(!c.contains("use the predictive schedule"), "{c}");
        // the same remedy in the energy audit's warning
        let mut m = StabilityMonitor::new(1e3);
        m.window_over_limit = Some(0.008);
        let mut warned = None;
        for w in 0..40u64 {
            let mismatch = 1e-3 * 2f64.powi(w as i32);
            warned = warned.or(m.observe_work("membrane", w, mismatch, 0.0));
        }
        let w = warned.expect("a growing mismatch warns");
        assert!(w.contains("unlikely cause"), "{w}");
    }

    #[test]
    fn steady_and_growing_loads_pass_runaway_growth_stops() {
        let mut m = StabilityMonitor::new(1e3);
        // a particle landing: from 0 to a finite force is fine
        assert!(m.observe(&forces(0, 0.0)).is_none());
        assert!(m.observe(&forces(1, 1.0)).is_none());
        assert!(m.observe(&forces(2, 50.0)).is_none());
        let e = m.observe(&forces(3, 1e6)).unwrap();
        assert_eq!(e.window, 3);
        assert!(
            e.to_string().starts_with("unstable at window 3 (t = 3.0"),
            "{e}"
        );
        // the node of the largest force is named (`forces` puts it at node 3)
        assert!(e.cause.contains("now on its node 3"), "{e}");
    }

    #[test]
    fn a_growing_work_mismatch_warns_once_and_a_single_spike_does_not() {
        // sleeper-ci, just-in-time at 10 µs, windows 349–366 (W_DEM, W_FEM in J): an odd–even
        // oscillation whose envelope doubles every two windows
        let diverging = [
            (-0.2217, -0.5018),
            (-0.3646, -0.5301),
            (-0.5092, -0.4474),
            (-0.2841, -0.1640),
            (-0.2457, -0.1049),
            (-0.1542, -0.05844),
            (-0.2453, -0.05658),
            (-0.2154, -0.1109),
            (-0.6924, -0.2033),
            (-0.9813, -0.5406),
            (-2.541, -0.3452),
            (-2.804, -0.7933),
            (-7.652, 0.7621),
            (-5.558, -0.05758),
            (-17.50, 4.138),
            (-9.113, 1.588),
            (-25.71, 8.715),
            (-12.15, 3.822),
        ];
        let mut m = StabilityMonitor::new(1e3);
        let warned: Vec<u64> = diverging
            .iter()
            .enumerate()
            .filter_map(|(i, (d, f))| {
                m.observe_work("bottom", 349 + i as u64, *d, *f)
                    .map(|_| 349 + i as u64)
            })
            .collect();
        assert_eq!(
            warned,
            vec![362],
            "once, 11 windows before the run was stopped"
        );
        // steady work with a one-window spike (sheet-ci, predictive, window 5464)
        let mut m = StabilityMonitor::new(1e3);
        let mut warnings = 0;
        for k in 0..40u64 {
            let spike = if k == 30 { 6e-5 } else { 0.0 };
            let d = 5e-6 + 1e-6 * (k % 3) as f64 + spike;
            warnings += m.observe_work("sheet", k, d, 4e-6).is_some() as usize;
        }
        assert_eq!(warnings, 0);
    }

    #[test]
    fn an_interface_drifting_more_than_its_size_stops() {
        let mut m = StabilityMonitor::new(1e3);
        m.mesh_size = Some(bounding_diagonal(&[0.0, 0.0, 0.0, 0.3, 0.4, 0.0]));
        assert_eq!(m.mesh_size, Some(0.5));
        let kin = |window: u64, z: f64| Digest {
            interface: "top".into(),
            window,
            time: 0.0,
            kind: "kinematics",
            max_norm: 0.0,
            max_node: 0,
            max_position: None,
            total: [0.1, 0.1, z],
            non_finite: None,
        };
        assert!(m.observe(&kin(0, 0.0)).is_none());
        assert!(m.observe(&kin(1, -0.4)).is_none());
        let e = m.observe(&kin(2, -0.6)).unwrap();
        assert!(e.cause.contains("drifted"), "{e}");
    }
}
