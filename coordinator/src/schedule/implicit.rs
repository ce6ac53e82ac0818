//! Implicit coupling (serial, FEM first): each window is iterated until the interface forces
//! are a fixed point (preCICE's serial-implicit scheme; Küttler & Wall 2008 for Aitken).
//!
//! Window k, iteration j (both nodes `checkpoint` at the window's start, `rollback` before each
//! repeat):
//! 1. every FEM node reads the force estimate F⁽ʲ⁾ the coordinator publishes (labelled (k, j) on
//!    the interface's `forces_relaxed` key), steps, and publishes its end state P⁽ʲ⁾ as
//!    kinematics (k, j);
//! 2. the DEM moves each mesh linearly from P_k to P⁽ʲ⁾ (the predictive motion) and publishes its
//!    mean forces f̄⁽ʲ⁾ = H(F⁽ʲ⁾) as (k, j);
//! 3. the coordinator: r = f̄⁽ʲ⁾ − F⁽ʲ⁾; converged when ‖r‖ ≤ tol ‖f̄⁽ʲ⁾‖ (all interfaces
//!    together); else F⁽ʲ⁺¹⁾ = F⁽ʲ⁾ + ω_j r with ω constant or by Aitken's Δ² rule.
//! The first estimate of window k is the converged f̄ of window k − 1 (zero in window 0). The
//! acceleration's state is part of the scheduler, so checkpoints hold it and resume is bitwise.

use std::collections::BTreeMap;

use proto::{CommandBody, Label, MotionRule};

use super::{Next, Scheme, Sends, Topology, Windows};

/// How the next force estimate is formed from the residual.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Acceleration {
    /// F⁽ʲ⁺¹⁾ = F⁽ʲ⁾ + ω r⁽ʲ⁾ with a fixed ω.
    Constant,
    /// Aitken's dynamic relaxation: ω_j = −ω_{j−1} r⁽ʲ⁻¹⁾·(r⁽ʲ⁾ − r⁽ʲ⁻¹⁾) / ‖r⁽ʲ⁾ − r⁽ʲ⁻¹⁾‖²,
    /// ω_0 the scene's relaxation in every window.
    Aitken,
}

/// The scene's settings of the implicit scheme.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct ImplicitSettings {
    /// Relative force residual ‖f̄ − F‖ / ‖f̄‖ below which a window is converged.
    pub tolerance: f64,
    pub max_iterations: u32,
    pub acceleration: Acceleration,
    /// ω of `constant`, ω_0 of `aitken`.
    pub relaxation: f64,
    /// At `max_iterations` without convergence: go on with the last estimate (a warning)
    /// instead of stopping the run.
    pub continue_unconverged: bool,
}

/// An iteration's outcome, for windows.csv and the summary.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct IterationRecord {
    pub window: u64,
    pub iteration: u32,
    /// ‖f̄ − F‖ / ‖f̄‖ (0 when both are zero).
    pub residual: f64,
    pub relaxation: f64,
}

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Implicit {
    pub settings: ImplicitSettings,
    /// Interfaces (name, nodes) and the FEM node that provides each.
    pub interfaces: Vec<(String, usize, String)>,
    /// The current estimate F⁽ʲ⁾, all interfaces concatenated in `interfaces` order.
    estimate: Vec<f64>,
    /// Aitken's memory: the last residual of this window and its ω.
    last_residual: Option<Vec<f64>>,
    omega: f64,
    iteration: u32,
    /// The iterations of the window now running (the run loop logs and clears them).
    #[serde(default)]
    pub records: Vec<IterationRecord>,
    /// Windows that ended unconverged (with `continue_unconverged`).
    #[serde(default)]
    pub unconverged: Vec<u64>,
}

impl Implicit {
    pub fn new(settings: ImplicitSettings, interfaces: Vec<(String, usize, String)>) -> Self {
        let n: usize = interfaces.iter().map(|(_, nodes, _)| 3 * nodes).sum();
        Implicit {
            omega: settings.relaxation,
            settings,
            interfaces,
            estimate: vec![0.0; n],
            last_residual: None,
            iteration: 0,
            records: Vec::new(),
            unconverged: Vec::new(),
        }
    }

    /// The iteration now running.
    pub fn iteration(&self) -> u32 {
        self.iteration
    }

    /// The estimate of each interface, labelled `label`, to publish.
    fn estimates(&self, label: Label) -> Vec<(String, Label, Vec<f64>)> {
        let mut at = 0;
        self.interfaces
            .iter()
            .map(|(name, nodes, _)| {
                let part = self.estimate[at..at + 3 * nodes].to_vec();
                at += 3 * nodes;
                (name.clone(), label, part)
            })
            .collect()
    }

    /// The commands of iteration j of window k (after the checkpoint or the rollback).
    fn iteration_sends(&self, t: &Topology, w: &Windows, k: u64, j: u32) -> Sends {
        let label = Some(Label {
            window: k,
            iteration: j,
        });
        let mut out = Vec::new();
        for f in &t.fems {
            let mut a = w.advance(k, MotionRule::Linear, None, None, false);
            if let CommandBody::AdvanceWindow(a) = &mut a {
                a.iteration = j;
                a.input = label;
                a.output = label;
            }
            out.push((f.clone(), a));
        }
        if let Some(d) = &t.dem {
            let mut a = w.advance(k, MotionRule::Linear, None, None, false);
            if let CommandBody::AdvanceWindow(a) = &mut a {
                a.iteration = j;
                a.input = label;
                a.output = label;
            }
            out.push((d.clone(), a));
        }
        out
    }

    /// The users' forces of window k, iteration j arrived (per interface name): converged,
    /// or the next iteration's estimate and commands.
    pub fn on_forces(
        &mut self,
        t: &Topology,
        w: &Windows,
        k: u64,
        forces: &BTreeMap<String, Vec<f64>>,
    ) -> Result<Iterate, String> {
        let j = self.iteration;
        let mut h = Vec::with_capacity(self.estimate.len());
        for (name, nodes, _) in &self.interfaces {
            let f = forces
                .get(name)
                .ok_or_else(|| format!("no forces of interface `{name}` for window {k} iteration {j}"))?;
            if f.len() != 3 * nodes {
                return Err(format!(
                    "interface `{name}`: {} force values for {nodes} nodes",
                    f.len()
                ));
            }
            h.extend_from_slice(f);
        }
        let r: Vec<f64> = h.iter().zip(&self.estimate).map(|(a, b)| a - b).collect();
        let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
        let (rn, hn) = (norm(&r), norm(&h));
        let residual = if rn == 0.0 { 0.0 } else { rn / hn.max(f64::MIN_POSITIVE) };
        let omega = match (self.settings.acceleration, &self.last_residual) {
            (Acceleration::Aitken, Some(prev)) => {
                let (mut num, mut den) = (0.0, 0.0);
                for (a, b) in r.iter().zip(prev) {
                    let d = a - b;
                    num += b * d;
                    den += d * d;
                }
                if den > 0.0 {
                    -self.omega * num / den
                } else {
                    self.omega
                }
            }
            _ => self.settings.relaxation,
        };
        self.records.push(IterationRecord {
            window: k,
            iteration: j,
            residual,
            relaxation: omega,
        });
        if residual <= self.settings.tolerance {
            // the converged forces start the next window
            self.estimate = h;
            self.start_window();
            return Ok(Iterate::Converged);
        }
        if j + 1 >= self.settings.max_iterations {
            let history: Vec<String> = self
                .records
                .iter()
                .map(|r| format!("{:.3e}", r.residual))
                .collect();
            if !self.settings.continue_unconverged {
                return Err(format!(
                    "implicit coupling: window {k} did not converge in {} iterations (relative force residuals {}; tolerance {:.1e}): raise coupling.implicit.max_iterations, shorten the window, or set continue_unconverged = true",
                    self.settings.max_iterations,
                    history.join(", "),
                    self.settings.tolerance
                ));
            }
            self.unconverged.push(k);
            self.estimate = h;
            self.start_window();
            return Ok(Iterate::Converged);
        }
        for (e, ri) in self.estimate.iter_mut().zip(&r) {
            *e += omega * ri;
        }
        self.omega = omega;
        self.last_residual = Some(r);
        self.iteration = j + 1;
        let label = Label {
            window: k,
            iteration: j + 1,
        };
        let mut sends: Sends = t
            .all()
            .map(|n| (n.to_string(), CommandBody::Rollback { window: k }))
            .collect();
        sends.extend(self.iteration_sends(t, w, k, j + 1));
        Ok(Iterate::Repeat {
            sends,
            relaxed: self.estimates(label),
        })
    }

    fn start_window(&mut self) {
        self.iteration = 0;
        self.last_residual = None;
        self.omega = self.settings.relaxation;
    }

    /// Forces to publish before window k's commands (iteration 0's estimate).
    pub fn window_estimates(&self, k: u64) -> Vec<(String, Label, Vec<f64>)> {
        self.estimates(Label::window(k))
    }
}

/// What follows an iteration.
#[derive(Debug, Clone, PartialEq)]
pub enum Iterate {
    Converged,
    Repeat {
        sends: Sends,
        relaxed: Vec<(String, Label, Vec<f64>)>,
    },
}

impl Scheme for Implicit {
    fn prologue(&self, _: &Topology) -> Sends {
        Vec::new()
    }

    fn window(&self, t: &Topology, w: &Windows, k: u64) -> Sends {
        let mut out: Sends = t
            .all()
            .map(|n| (n.to_string(), CommandBody::Checkpoint { window: k }))
            .collect();
        out.extend(self.iteration_sends(t, w, k, 0));
        out
    }

    fn replay(&self, _: &Topology, _: u64) -> Sends {
        // the estimate of the window to come is the scheduler's (published with the window)
        Vec::new()
    }

    fn after_window(&mut self, _: &Topology, _: &Windows, _: u64, _: Option<f64>) -> Next {
        Next::Continue
    }
}
