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
}

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
        }
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
                        "the largest interface nodal force on `{}` grew from {last:.3e} N to {f:.3e} N in one window (more than {}×): the coupling diverges; reduce the coupling window or use the predictive schedule",
                        d.interface, self.max_growth
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
                        return fail(format!(
                            "a node of interface `{}` moves at {:.3e} m/s: {step:.3e} m in one window of {window:.3e} s, more than half the smallest particle radius ({radius:.3e} m); the coupling diverges — reduce the coupling window or use the predictive schedule",
                            d.interface, d.max_norm
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
            total: [0.0; 3],
            non_finite: None,
        };
        assert!(m.observe(&k(49.0)).is_none());
        let e = m.observe(&k(51.0)).unwrap();
        assert!(e.cause.contains("half the smallest particle radius"), "{e}");
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
            total: [0.1, 0.1, z],
            non_finite: None,
        };
        assert!(m.observe(&kin(0, 0.0)).is_none());
        assert!(m.observe(&kin(1, -0.4)).is_none());
        let e = m.observe(&kin(2, -0.6)).unwrap();
        assert!(e.cause.contains("drifted"), "{e}");
    }
}
