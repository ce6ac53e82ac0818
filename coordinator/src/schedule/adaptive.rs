//! Adaptive coupling windows: the next window's length chosen after each window from the
//! nodes' live numbers and an error estimate the schedule already has.
//!
//! The lengths form a ladder Δt_min · 2^i within [min_window, max_window], so every window is a
//! whole number of DEM steps, the end time stays reachable, and a FEM node with a factorised
//! effective matrix meets only a few step sizes. After window k the next length is the
//! smallest of:
//!
//! - **the error estimate's proposal.** For the explicit schedules it comes from the energy audit:
//!   e = |Σ (W_DEM − W_FEM)| / max(Σ|W_DEM|, Σ|W_FEM|, 1e-3 × the largest window's work so
//!   far). This is the relative energy the explicit lag created in the window. It is first order
//!   in Δt^C (the mismatch is (f̄_k − f̄_{k−1})·Δx_k ∝ Δt², the work ∝ Δt; docs/coupling.md), so
//!   the proposal is Δt · 0.9 · tol / e. For the implicit schedule it comes from the iterations
//!   the window needed: half the length above `iterations`, twice at most half of it.
//! - **the stiffness limit while the interface is loaded** (some interface node carries a force
//!   in the DEM's report): the schedule's fraction of T_c = 2π √(M/k_c) (limits.rs), with the
//!   interface mass and contact stiffness the nodes reported when they started. An unloaded
//!   interface has no contact spring, and the window may grow beyond it,
//! - **but only to half the time in which the nearest approaching particle could reach the
//!   unloaded interface's bounding box** (the DEM's `interface_approach_time`): the window
//!   halves as a particle approaches, so an impact starts in a short window.
//! - **the speed limit**: the fastest interface node (the FEM's report) may move at most a tenth
//!   of the smallest particle radius in one window.
//!
//! The result is rounded down to the ladder. It may grow by at most 2× per window, and is cut to
//! the time left. Time is counted in ladder bases (integers), so windows end exactly on the end
//! time. Every change is logged, and windows.csv has each window's length.

use std::collections::BTreeMap;

/// `[coupling.adaptive]`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AdaptiveSettings {
    /// Shortest window (s): the ladder's base, a whole number of DEM steps.
    pub min_window: f64,
    /// Longest window (s).
    pub max_window: f64,
    /// Explicit schedules: the relative energy mismatch per window aimed at.
    pub tolerance: f64,
    /// Implicit: the iterations per window aimed at.
    pub iterations: u32,
}

/// What the controller knows of the run when it starts (from the nodes' `ready` numbers).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Limits {
    /// The schedule's stiffness limit (s) while the interface is loaded, if known.
    pub loaded: Option<f64>,
    /// The smallest particle radius (m), if known.
    pub radius_min: Option<f64>,
}

/// What the nodes reported of the window just finished (their last iteration's, for an
/// implicit window).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Observation {
    /// Per interface: the DEM's work, the FEM's work (J).
    pub work: BTreeMap<String, (Option<f64>, Option<f64>)>,
    /// Per interface: the largest nodal force in the DEM's forces (N).
    pub force: BTreeMap<String, f64>,
    /// Per FEM node: its fastest interface node (m/s).
    pub speed: BTreeMap<String, f64>,
    /// Per interface: the shortest time in which a particle could reach it (s; absent: none
    /// approaches).
    #[serde(default)]
    pub approach: BTreeMap<String, f64>,
}

impl Observation {
    /// A node's `window_done` numbers: `interface_work.<if>` (DEM or FEM by `dem`),
    /// `interface_force_max.<if>` (DEM), `max_interface_speed` (FEM).
    pub fn record(&mut self, node: &str, dem: bool, values: &BTreeMap<String, f64>) {
        for (key, &v) in values {
            match key.split_once('.') {
                Some(("interface_work", i)) => {
                    let e = self.work.entry(i.to_string()).or_default();
                    if dem {
                        e.0 = Some(v);
                    } else {
                        e.1 = Some(v);
                    }
                }
                Some(("interface_force_max", i)) => {
                    self.force.insert(i.to_string(), v);
                }
                Some(("interface_approach_time", i)) => {
                    self.approach.insert(i.to_string(), v);
                }
                _ if key == "max_interface_speed" => {
                    self.speed.insert(node.to_string(), v);
                }
                _ => {}
            }
        }
    }
}

/// The controller's state (in the scheduler, so checkpoints hold it).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Adaptive {
    pub settings: AdaptiveSettings,
    pub limits: Limits,
    /// The largest |work| of one window so far (the error estimate's floor).
    largest_work: f64,
}

/// The controller's choice and why.
#[derive(Debug, Clone, PartialEq)]
pub struct Choice {
    /// The length in ladder bases (a power of two).
    pub steps: u64,
    pub reason: String,
}

impl Adaptive {
    pub fn new(settings: AdaptiveSettings, limits: Limits) -> Self {
        Adaptive {
            settings,
            limits,
            largest_work: 0.0,
        }
    }

    /// The longest ladder length (in bases: a power of two) not above `t` s nor `max_window`
    /// nor `remaining` bases, and at least one base.
    fn ladder_floor(&self, t: f64, remaining: u64) -> u64 {
        let base = self.settings.min_window;
        let mut n = 1u64;
        while (2 * n) as f64 * base <= t * (1.0 + 1e-9)
            && (2 * n) as f64 * base <= self.settings.max_window * (1.0 + 1e-9)
            && 2 * n <= remaining
        {
            n *= 2;
        }
        n
    }

    /// The next window's length after a window of `current` bases, with `remaining` bases
    /// left. `iterations`: the implicit window's iterations (None for explicit schedules).
    pub fn next(
        &mut self,
        current: u64,
        remaining: u64,
        obs: &Observation,
        iterations: Option<u32>,
    ) -> Choice {
        let current = current as f64 * self.settings.min_window;
        let mut candidates: Vec<(f64, String)> = Vec::new();
        match iterations {
            Some(n) => {
                let target = self.settings.iterations;
                let proposal = if n > target {
                    0.5 * current
                } else if 2 * n <= target {
                    2.0 * current
                } else {
                    current
                };
                candidates.push((proposal, format!("{n} iterations (aim {target})")));
            }
            None => {
                let (mut dem, mut fem, mut mismatch, mut any) = (0.0f64, 0.0f64, 0.0, false);
                for (d, f) in obs.work.values() {
                    if let (Some(d), Some(f)) = (d, f) {
                        dem += d.abs();
                        fem += f.abs();
                        mismatch += d - f;
                        any = true;
                    }
                }
                self.largest_work = self.largest_work.max(dem).max(fem);
                let scale = dem.max(fem).max(1e-3 * self.largest_work);
                if any && scale > 0.0 {
                    let e = mismatch.abs() / scale;
                    let proposal = if e > 0.0 {
                        current * (0.9 * self.settings.tolerance / e).clamp(0.25, 2.0)
                    } else {
                        2.0 * current
                    };
                    candidates.push((proposal, format!("energy mismatch {e:.2e}")));
                } else {
                    candidates.push((2.0 * current, "no interface work".into()));
                }
            }
        }
        let loaded = obs.force.values().any(|&f| f > 0.0);
        let approach = obs.approach.values().fold(f64::INFINITY, |a, &b| a.min(b));
        match (loaded, self.limits.loaded) {
            (true, Some(limit)) => {
                candidates.push((limit, "the stiffness limit of a loaded interface".into()))
            }
            // no particle may reach an unloaded interface within two windows: the window
            // halves as one approaches, so an impact starts in a short window
            (false, _) if approach.is_finite() => candidates.push((
                0.5 * approach,
                format!("a particle {approach:.3e} s from the interface"),
            )),
            _ => {}
        }
        let speed = obs.speed.values().fold(0.0f64, |a, &b| a.max(b));
        if let (Some(r), true) = (self.limits.radius_min, speed > 0.0) {
            candidates.push((0.1 * r / speed, format!("interface speed {speed:.3e} m/s")));
        }
        candidates.push((2.0 * current, "at most twice the last window".into()));
        let (t, mut reason) =
            candidates
                .into_iter()
                .fold((f64::INFINITY, String::new()), |a, b| {
                    if b.0 < a.0 {
                        b
                    } else {
                        a
                    }
                });
        let steps = self.ladder_floor(t, remaining);
        if (steps as f64 * self.settings.min_window) < t * (1.0 - 1e-9) && steps * 2 > remaining {
            reason = "the time left".into();
        }
        Choice { steps, reason }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn controller() -> Adaptive {
        Adaptive::new(
            AdaptiveSettings {
                min_window: 1e-5,
                max_window: 1.6e-4,
                tolerance: 0.05,
                iterations: 4,
            },
            Limits {
                loaded: Some(5e-5),
                radius_min: Some(1e-3),
            },
        )
    }

    fn obs(work: Option<(f64, f64)>, force: f64, speed: f64) -> Observation {
        let mut o = Observation::default();
        if let Some((d, f)) = work {
            o.work.insert("top".into(), (Some(d), Some(f)));
        }
        o.force.insert("top".into(), force);
        o.speed.insert("fem".into(), speed);
        o
    }

    #[test]
    fn free_flight_grows_to_the_longest_window_by_doubling() {
        let mut a = controller();
        let mut l = 1;
        let mut seen = vec![l];
        for _ in 0..6 {
            l = a.next(l, 1000, &obs(None, 0.0, 0.0), None).steps;
            seen.push(l);
        }
        assert_eq!(seen, vec![1, 2, 4, 8, 16, 16, 16]);
    }

    #[test]
    fn a_loaded_interface_keeps_the_stiffness_limit_and_a_mismatch_shrinks_the_window() {
        let mut a = controller();
        // loaded, no mismatch: the ladder length below the 50 µs limit
        let c = a.next(16, 1000, &obs(Some((1.0, 1.0)), 3.0, 0.0), None);
        assert_eq!(c.steps, 4);
        assert!(c.reason.contains("stiffness"), "{}", c.reason);
        // a 20 % mismatch against a 5 % aim: a quarter of the window
        let c = a.next(4, 1000, &obs(Some((1.0, 0.8)), 3.0, 0.0), None);
        assert_eq!(c.steps, 1);
        assert!(c.reason.contains("energy mismatch 2.00e-1"), "{}", c.reason);
        // fast interface nodes: 0.1 r / v = 2e-5 s
        let c = a.next(4, 1000, &obs(Some((1.0, 1.0)), 0.0, 5.0), None);
        assert_eq!(c.steps, 2);
        // unloaded, a particle 1e-4 s away: half of it on the ladder, 4 bases = 40 µs; one
        // about to touch: the shortest window
        let mut o = obs(None, 0.0, 0.0);
        o.approach.insert("top".into(), 1e-4);
        let c = a.next(16, 1000, &o, None);
        assert_eq!(c.steps, 4);
        o.approach.insert("top".into(), 0.0);
        assert_eq!(a.next(4, 1000, &o, None).steps, 1);
        assert!(c.reason.contains("from the interface"), "{}", c.reason);
        // ... far away: free growth
        o.approach.insert("top".into(), 1.0);
        assert_eq!(a.next(4, 1000, &o, None).steps, 8);
        // the last windows end on the end time
        let c = a.next(4, 3, &obs(None, 0.0, 0.0), None);
        assert_eq!((c.steps, c.reason.as_str()), (2, "the time left"));
    }

    #[test]
    fn implicit_windows_follow_their_iterations() {
        let mut a = controller();
        let o = obs(None, 0.0, 0.0);
        assert_eq!(a.next(4, 1000, &o, Some(2)).steps, 8);
        assert_eq!(a.next(4, 1000, &o, Some(3)).steps, 4);
        assert_eq!(a.next(4, 1000, &o, Some(7)).steps, 2);
    }
}
