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
//! 3. the coordinator: r = f̄⁽ʲ⁾ − F⁽ʲ⁾; converged when ‖r‖ ≤ tol maxᵢ≤ⱼ ‖f̄⁽ⁱ⁾‖ (all
//!    interfaces together; the largest forces of the window's iterations, since a contact that
//!    opens has a fixed point of zero forces); else F⁽ʲ⁺¹⁾ = F⁽ʲ⁾ + ω_j r with ω constant, by
//!    Aitken's Δ² rule or by IQN-ILS.
//!
//! The first estimate of window k is the converged f̄ of window k − 1 (zero in window 0). The
//! acceleration's state is part of the scheduler, so checkpoints hold it and resume is bitwise.
//!
//! Concurrent (`concurrent = true`, preCICE's parallel-implicit; block Jacobi): in iteration j
//! the coordinator publishes a force estimate F⁽ʲ⁾ for the FEM nodes *and* an estimate
//! X⁽ʲ⁾ = P_k + u⁽ʲ⁾ of each structure's end position for the DEM (labelled (k, j) on the
//! interface's `kinematics_relaxed` key), so both compute at once: the FEM gives
//! P⁽ʲ⁾ = S(F⁽ʲ⁾), the DEM f̄⁽ʲ⁾ = H(X⁽ʲ⁾). The fixed point of (F, u) ↦ (f̄, P − P_k) is
//! accelerated as one vector, each part scaled by its norm at the window's first iteration
//! (forces in N, displacements in m). Converged when both relative residuals are below the
//! tolerance: ‖f̄ − F‖ ≤ tol max‖f̄‖ and ‖(P − P_k) − u‖ ≤ tol max‖P − P_k‖ (max over the
//! window's iterations). The next window starts from the converged forces, from the positions
//! the DEM ended on (P_{k+1} = P_k + u), and with the FEM's displacement of this window as its
//! first estimate (a constant-velocity prediction).

use std::collections::BTreeMap;

use proto::{CommandBody, Label, MotionRule};

use super::{Publications, Scheme, Sends, Topology, Windows};

/// How the next force estimate is formed from the residual.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Acceleration {
    /// F⁽ʲ⁺¹⁾ = F⁽ʲ⁾ + ω r⁽ʲ⁾ with a fixed ω.
    Constant,
    /// Aitken's dynamic relaxation: ω_j = −ω_{j−1} r⁽ʲ⁻¹⁾·(r⁽ʲ⁾ − r⁽ʲ⁻¹⁾) / ‖r⁽ʲ⁾ − r⁽ʲ⁻¹⁾‖²,
    /// ω_0 the scene's relaxation in every window.
    Aitken,
    /// Interface quasi-Newton with an inverse Jacobian from least squares (Degroote et al.
    /// 2009, IQN-ILS): the secants ΔR = [r⁽ⁱ⁺¹⁾ − r⁽ⁱ⁾] and ΔH = [h⁽ⁱ⁺¹⁾ − h⁽ⁱ⁾] of this window
    /// and the last `reuse` windows; α = argmin ‖ΔR α + r⁽ʲ⁾‖ by a QR that drops nearly
    /// dependent columns (`filter`), F⁽ʲ⁺¹⁾ = h⁽ʲ⁾ + ΔH α; the scene's relaxation while no secant
    /// exists.
    IqnIls,
}

fn default_reuse() -> u32 {
    // contacts open and close between windows: older secants mislead (plate, tolerance 1e-4:
    // reuse 0 converges in 440 iterations over 300 windows, reuse 2 needs up to 22 in one
    // window, reuse 8 diverges at the first impacts)
    0
}

fn default_filter() -> f64 {
    1e-3
}

/// An estimate the coordinator publishes for an interface.
#[derive(Debug, Clone, PartialEq)]
pub enum Estimate {
    /// Forces for the provider (`forces_relaxed`).
    Forces(Vec<f64>),
    /// The provider's end state for the users (`kinematics_relaxed`): positions, and the mean
    /// velocity of the window (P − P_k)/Δt^C (the users' linear motion needs only positions).
    Kinematics {
        positions: Vec<f64>,
        velocities: Vec<f64>,
    },
}

/// What the nodes computed in an iteration, per interface: the users' forces and (concurrent)
/// the providers' end positions.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Outputs {
    pub forces: BTreeMap<String, Vec<f64>>,
    pub positions: BTreeMap<String, Vec<f64>>,
}

fn default_tolerance() -> f64 {
    1e-3
}
fn default_max_iterations() -> u32 {
    30
}
fn default_relaxation() -> f64 {
    0.5
}

/// `[coupling.implicit]`: the scene's settings of the implicit scheme (the scene file's table
/// as it is; scene.rs checks the ranges).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImplicitSettings {
    /// Relative residual ‖f̄ − F‖ / max‖f̄‖ (max over the window's iterations) below which a
    /// window is converged (default 1e-3).
    #[serde(default = "default_tolerance")]
    pub tolerance: f64,
    /// Most iterations of a window (default 30).
    #[serde(default = "default_max_iterations")]
    pub max_iterations: u32,
    /// `aitken`, `constant` or `iqn-ils`; absent: [`ImplicitSettings::acceleration`]'s default.
    #[serde(default)]
    pub acceleration: Option<Acceleration>,
    /// ω of `constant`, the first ω of each window with `aitken` (default 0.5).
    #[serde(default = "default_relaxation")]
    pub relaxation: f64,
    /// Go on (with a warning) when a window does not converge in `max_iterations`, instead of
    /// stopping the run with the residual history.
    #[serde(default)]
    pub continue_unconverged: bool,
    /// IQN-ILS: the secants of this many earlier windows are reused (default 0: contacts open
    /// and close between windows, and older secants mislead; docs/coupling.md).
    #[serde(default = "default_reuse")]
    pub reuse: u32,
    /// IQN-ILS: a secant whose part orthogonal to the newer ones is below this fraction of its
    /// length is dropped (QR filter; default 1e-3).
    #[serde(default = "default_filter")]
    pub filter: f64,
    /// Both solvers compute each iteration at once (block Jacobi), the DEM on the
    /// coordinator's estimate of the structure's motion; the acceleration acts on forces and
    /// positions together (module doc; default false: FEM first, then the DEM on the FEM's
    /// motion).
    #[serde(default)]
    pub concurrent: bool,
}

impl Default for ImplicitSettings {
    fn default() -> Self {
        ImplicitSettings {
            tolerance: default_tolerance(),
            max_iterations: default_max_iterations(),
            acceleration: None,
            relaxation: default_relaxation(),
            continue_unconverged: false,
            reuse: default_reuse(),
            filter: default_filter(),
            concurrent: false,
        }
    }
}

impl ImplicitSettings {
    /// The acceleration: the scene's, else Aitken, or IQN-ILS for the concurrent scheme
    /// (Aitken's single ω barely damps a Jacobi pair).
    pub fn acceleration(&self) -> Acceleration {
        self.acceleration.unwrap_or(if self.concurrent {
            Acceleration::IqnIls
        } else {
            Acceleration::Aitken
        })
    }
}

/// An iteration's outcome, for windows.csv and the summary.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct IterationRecord {
    pub window: u64,
    pub iteration: u32,
    /// ‖f̄ − F‖ / max‖f̄‖ (0 when equal; max over the window's iterations so far);
    /// concurrent: the larger of it and the displacements' ‖(P − P_k) − u‖ / max‖P − P_k‖.
    pub residual: f64,
    pub relaxation: f64,
}

#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct Implicit {
    pub settings: ImplicitSettings,
    /// Interfaces (name, nodes), in the scene's order.
    pub interfaces: Vec<(String, usize)>,
    /// The current estimate F⁽ʲ⁾, all interfaces concatenated in `interfaces` order.
    estimate: Vec<f64>,
    /// Aitken's and IQN-ILS's memory: the last residual of this window and its ω ...
    last_residual: Option<Vec<f64>>,
    omega: f64,
    /// ... and the users' last response h = H(F) of this window (IQN-ILS).
    #[serde(default)]
    last_output: Option<Vec<f64>>,
    /// IQN-ILS secants (window, Δr, Δh), oldest first.
    #[serde(default)]
    secants: Vec<(u64, Vec<f64>, Vec<f64>)>,
    iteration: u32,
    /// The iterations since the run loop last took them.
    #[serde(default)]
    records: Vec<IterationRecord>,
    /// Windows that ended unconverged (with `continue_unconverged`).
    #[serde(default)]
    unconverged: Vec<u64>,
    /// The residuals of the window now running (for the message when it does not converge).
    #[serde(default)]
    window_residuals: Vec<f64>,
    /// Concurrent: the positions P_k the users start the window from (all interfaces), ...
    #[serde(default)]
    start: Vec<f64>,
    /// ... the estimated displacement u⁽ʲ⁾ of the window ...
    #[serde(default)]
    displacement: Vec<f64>,
    /// ... and the scales of forces and displacements in this window's acceleration.
    #[serde(default)]
    scales: Option<(f64, f64)>,
    /// The largest norms of the users' forces and (concurrent) the FEM's displacements in this
    /// window's iterations so far: the residuals' denominators.
    #[serde(default)]
    largest: (f64, f64),
    /// Concurrent: `largest` when the scales were set (a part whose norm was 0 was scaled by 1).
    #[serde(default)]
    scaled_from: (f64, f64),
    /// Concurrent: the window length `displacement` was measured over (0: the run's start);
    /// a window of another length (adaptive windows) scales it, constant velocity.
    #[serde(default)]
    displacement_for: f64,
}

impl Implicit {
    /// `positions`: the interfaces' reference positions, concatenated (the concurrent scheme's
    /// P_0; unused otherwise).
    pub fn new(
        settings: ImplicitSettings,
        interfaces: Vec<(String, usize)>,
        positions: Vec<f64>,
    ) -> Self {
        let n: usize = interfaces.iter().map(|(_, nodes)| 3 * nodes).sum();
        let concurrent = settings.concurrent;
        Implicit {
            displacement: if concurrent { vec![0.0; n] } else { Vec::new() },
            start: if concurrent { positions } else { Vec::new() },
            scales: None,
            largest: (0.0, 0.0),
            scaled_from: (0.0, 0.0),
            displacement_for: 0.0,
            omega: settings.relaxation,
            settings,
            interfaces,
            estimate: vec![0.0; n],
            last_residual: None,
            last_output: None,
            secants: Vec::new(),
            iteration: 0,
            records: Vec::new(),
            unconverged: Vec::new(),
            window_residuals: Vec::new(),
        }
    }

    /// The estimates of each interface, labelled `label`, to publish: forces, and
    /// (concurrent) the end positions.
    fn estimates(&self, label: Label, dt: f64) -> Publications {
        let mut out = Vec::new();
        let mut at = 0;
        for (name, nodes) in &self.interfaces {
            let part = at..at + 3 * nodes;
            at += 3 * nodes;
            out.push((
                name.clone(),
                label,
                Estimate::Forces(self.estimate[part.clone()].to_vec()),
            ));
            if self.settings.concurrent {
                let u = &self.displacement[part.clone()];
                out.push((
                    name.clone(),
                    label,
                    Estimate::Kinematics {
                        positions: add(&self.start[part], u),
                        velocities: u.iter().map(|x| x / dt).collect(),
                    },
                ));
            }
        }
        out
    }

    /// The values of every interface in `map`, concatenated in `interfaces` order.
    fn gather(
        &self,
        map: &BTreeMap<String, Vec<f64>>,
        what: &str,
        k: u64,
        j: u32,
    ) -> Result<Vec<f64>, String> {
        let mut out = Vec::with_capacity(self.estimate.len());
        for (name, nodes) in &self.interfaces {
            let f = map.get(name).ok_or_else(|| {
                format!("no {what} of interface `{name}` for window {k} iteration {j}")
            })?;
            if f.len() != 3 * nodes {
                return Err(format!(
                    "interface `{name}`: {} {what} values for {nodes} nodes",
                    f.len()
                ));
            }
            out.extend_from_slice(f);
        }
        Ok(out)
    }

    /// The commands of iteration j of window k (after the checkpoint or the rollback).
    fn iteration_sends(&self, t: &Topology, w: &Windows, k: u64, j: u32) -> Sends {
        let label = Some(Label {
            window: k,
            iteration: j,
        });
        // every node reads and writes the data of (k, j): the FEM nodes first, then the DEM
        t.fems
            .iter()
            .chain(&t.dem)
            .map(|n| {
                let mut a = w.advance(k, MotionRule::Linear, None, None, false);
                if let CommandBody::AdvanceWindow(a) = &mut a {
                    a.iteration = j;
                    a.input = label;
                    a.output = label;
                }
                (n.clone(), a)
            })
            .collect()
    }

    /// The nodes' outputs of window k, iteration j arrived: converged, or the next iteration's
    /// estimate and commands.
    fn iterate(
        &mut self,
        t: &Topology,
        w: &Windows,
        k: u64,
        outputs: &Outputs,
    ) -> Result<Iterate, String> {
        let j = self.iteration;
        let h_forces = self.gather(&outputs.forces, "force", k, j)?;
        // relative to the largest forces of the window's iterations, not only this one's: when
        // a contact opens the fixed point's forces are zero, and a residual relative to them
        // alone could never fall below any tolerance
        self.largest.0 = self.largest.0.max(norm(&h_forces));
        let force_residual = relative(&h_forces, &self.estimate, self.largest.0);
        // the fixed-point variable z and its image h = H(z) in the acceleration's space:
        // the forces, or (concurrent) forces and displacements, each part scaled
        let (z, h, residual, h_displacement) = if self.settings.concurrent {
            let p = self.gather(&outputs.positions, "position", k, j)?;
            let hu: Vec<f64> = p.iter().zip(&self.start).map(|(a, b)| a - b).collect();
            self.largest.1 = self.largest.1.max(norm(&hu));
            // each part scaled by its largest norm in the window so far (1 while it is zero);
            // when a part appears (forces as a contact closes) or grows past twice its scale,
            // the scales are renewed and the acceleration restarts from a relaxation step, its
            // history being in the old scales
            let wanted = (
                if self.largest.0 > 0.0 {
                    self.largest.0
                } else {
                    1.0
                },
                if self.largest.1 > 0.0 {
                    self.largest.1
                } else {
                    1.0
                },
            );
            let renew = match self.scales {
                None => true,
                Some((sf, su)) => {
                    let (f0, u0) = self.scaled_from;
                    (f0 == 0.0 && self.largest.0 > 0.0)
                        || (u0 == 0.0 && self.largest.1 > 0.0)
                        || wanted.0 > 2.0 * sf
                        || wanted.1 > 2.0 * su
                }
            };
            if renew {
                if self.scales.is_some() {
                    self.restart_acceleration(k);
                }
                self.scales = Some(wanted);
                self.scaled_from = self.largest;
            }
            let (sf, su) = self.scales.expect("set above");
            let join = |f: &[f64], u: &[f64]| -> Vec<f64> {
                f.iter()
                    .map(|x| x / sf)
                    .chain(u.iter().map(|x| x / su))
                    .collect()
            };
            let position_residual = relative(&hu, &self.displacement, self.largest.1);
            tracing::debug!(
                "window {k} iteration {j}: force residual {force_residual:.3e}, displacement residual {position_residual:.3e} (‖f̄‖ {:.3e} N, ‖P − P_k‖ {:.3e} m, scales {sf:.3e}, {su:.3e})",
                norm(&h_forces),
                norm(&hu)
            );
            (
                join(&self.estimate, &self.displacement),
                join(&h_forces, &hu),
                force_residual.max(position_residual),
                Some(hu),
            )
        } else {
            (
                self.estimate.clone(),
                h_forces.clone(),
                force_residual,
                None,
            )
        };
        let r: Vec<f64> = h.iter().zip(&z).map(|(a, b)| a - b).collect();
        let omega = match (self.settings.acceleration(), &self.last_residual) {
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
        self.window_residuals.push(residual);
        self.records.push(IterationRecord {
            window: k,
            iteration: j,
            residual,
            relaxation: omega,
        });
        if residual <= self.settings.tolerance {
            self.next_window(h_forces, h_displacement, w.length);
            return Ok(Iterate::Converged);
        }
        if j + 1 >= self.settings.max_iterations {
            let history: Vec<String> = self
                .window_residuals
                .iter()
                .map(|r| format!("{r:.3e}"))
                .collect();
            if !self.settings.continue_unconverged {
                return Err(format!(
                    "implicit coupling: window {k} did not converge in {} iterations (relative {} residuals {}; tolerance {:.1e}): raise coupling.implicit.max_iterations, shorten the window, or set continue_unconverged = true",
                    self.settings.max_iterations,
                    if self.settings.concurrent {
                        "force and displacement (the larger)"
                    } else {
                        "force"
                    },
                    history.join(", "),
                    self.settings.tolerance
                ));
            }
            self.unconverged.push(k);
            self.next_window(h_forces, h_displacement, w.length);
            return Ok(Iterate::Converged);
        }
        let next = match self.settings.acceleration() {
            Acceleration::IqnIls => {
                if let (Some(rp), Some(hp)) = (&self.last_residual, &self.last_output) {
                    let dr: Vec<f64> = r.iter().zip(rp).map(|(a, b)| a - b).collect();
                    let dh = h.iter().zip(hp).map(|(a, b)| a - b).collect();
                    if norm(&dr) <= 1e-9 * norm(&r) {
                        // the nodes answered as before (to round-off): the secant explains
                        // nothing new and the least-squares step would repeat itself; start
                        // again from a relaxation step
                        self.secants.retain(|(w, ..)| *w != k);
                    } else {
                        self.secants.push((k, dr, dh));
                    }
                }
                let oldest = k.saturating_sub(self.settings.reuse as u64);
                self.secants.retain(|(w, ..)| *w >= oldest);
                iqn_ils_step(&self.secants, &r, &h, self.settings.filter)
                    .unwrap_or_else(|| relax(&z, &r, omega))
            }
            _ => relax(&z, &r, omega),
        };
        match self.scales {
            Some((sf, su)) if self.settings.concurrent => {
                let n = self.estimate.len();
                self.estimate = next[..n].iter().map(|x| x * sf).collect();
                self.displacement = next[n..].iter().map(|x| x * su).collect();
            }
            _ => self.estimate = next,
        }
        self.omega = omega;
        self.last_residual = Some(r);
        self.last_output = Some(h);
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
            relaxed: self.estimates(label, w.length),
        })
    }

    /// Forgets this window's acceleration history (secants, last residual, Aitken's ω).
    fn restart_acceleration(&mut self, k: u64) {
        self.secants.retain(|(w, ..)| *w != k);
        self.last_residual = None;
        self.last_output = None;
        self.omega = self.settings.relaxation;
    }

    /// The window is over (`forces`: the users' last; `displacement`: concurrent, the FEM's
    /// last): the next one starts from those forces, from the positions the users ended on,
    /// and with the FEM's displacement as its first estimate.
    fn next_window(&mut self, forces: Vec<f64>, displacement: Option<Vec<f64>>, length: f64) {
        self.estimate = forces;
        if let Some(u) = displacement {
            self.start = add(&self.start, &self.displacement);
            self.displacement = u;
            self.displacement_for = length;
        }
        self.scales = None;
        self.largest = (0.0, 0.0);
        self.iteration = 0;
        self.window_residuals.clear();
        self.last_residual = None;
        self.last_output = None;
        self.omega = self.settings.relaxation;
    }
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// ‖h − e‖ / `scale` (0 when h = e).
fn relative(h: &[f64], e: &[f64], scale: f64) -> f64 {
    let d = h
        .iter()
        .zip(e)
        .map(|(a, b)| (a - b) * (a - b))
        .sum::<f64>()
        .sqrt();
    if d == 0.0 {
        0.0
    } else {
        d / scale.max(f64::MIN_POSITIVE)
    }
}

fn add(a: &[f64], b: &[f64]) -> Vec<f64> {
    a.iter().zip(b).map(|(x, y)| x + y).collect()
}

/// z + ω r.
fn relax(z: &[f64], r: &[f64], omega: f64) -> Vec<f64> {
    z.iter().zip(r).map(|(x, y)| x + omega * y).collect()
}

/// The IQN-ILS estimate h + ΔH α with α = argmin ‖ΔR α + r‖, from the secants newest first
/// through a modified Gram–Schmidt QR that drops a column whose part orthogonal to the kept
/// (newer) ones is below `filter` × its length. `None` when no column is left.
fn iqn_ils_step(
    secants: &[(u64, Vec<f64>, Vec<f64>)],
    r: &[f64],
    h: &[f64],
    filter: f64,
) -> Option<Vec<f64>> {
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    // Q (orthonormal), R (upper triangular, by kept column), the kept columns' ΔH
    let mut q: Vec<Vec<f64>> = Vec::new();
    let mut rmat: Vec<Vec<f64>> = Vec::new();
    let mut kept: Vec<&Vec<f64>> = Vec::new();
    for (_, dr, dh) in secants.iter().rev() {
        let length = dot(dr, dr).sqrt();
        if length == 0.0 {
            continue;
        }
        let mut v = dr.clone();
        let mut coeffs = Vec::with_capacity(q.len() + 1);
        for qi in &q {
            let c = dot(qi, &v);
            for (x, y) in v.iter_mut().zip(qi) {
                *x -= c * y;
            }
            coeffs.push(c);
        }
        let rest = dot(&v, &v).sqrt();
        if rest < filter * length {
            continue;
        }
        v.iter_mut().for_each(|x| *x /= rest);
        coeffs.push(rest);
        q.push(v);
        rmat.push(coeffs);
        kept.push(dh);
    }
    if q.is_empty() {
        return None;
    }
    // R α = −Qᵀ r, back substitution (column i of R is rmat[i], its diagonal rmat[i][i])
    let m = q.len();
    let b: Vec<f64> = q.iter().map(|qi| -dot(qi, r)).collect();
    let mut alpha = vec![0.0; m];
    for i in (0..m).rev() {
        let mut s = b[i];
        for j in i + 1..m {
            s -= rmat[j][i] * alpha[j];
        }
        alpha[i] = s / rmat[i][i];
    }
    let mut next = h.to_vec();
    for (a, dh) in alpha.iter().zip(&kept) {
        for (x, d) in next.iter_mut().zip(dh.iter()) {
            *x += a * d;
        }
    }
    Some(next)
}

/// What follows an iteration.
#[derive(Debug, Clone, PartialEq)]
pub enum Iterate {
    Converged,
    Repeat { sends: Sends, relaxed: Publications },
}

impl Scheme for Implicit {
    fn window(&self, t: &Topology, w: &Windows, k: u64) -> Sends {
        let mut out: Sends = t
            .all()
            .map(|n| (n.to_string(), CommandBody::Checkpoint { window: k }))
            .collect();
        out.extend(self.iteration_sends(t, w, k, 0));
        out
    }

    /// Iteration 0's estimate, before window k's commands (concurrent: the last window's
    /// displacement, scaled to this window's length).
    fn window_publications(&mut self, w: &Windows, k: u64) -> Publications {
        if self.settings.concurrent
            && self.displacement_for > 0.0
            && self.displacement_for != w.length
        {
            let ratio = w.length / self.displacement_for;
            self.displacement.iter_mut().for_each(|u| *u *= ratio);
            self.displacement_for = w.length;
        }
        self.estimates(Label::window(k), w.length)
    }

    fn iteration(&self) -> Option<u32> {
        Some(self.iteration)
    }

    fn needs_positions(&self) -> bool {
        self.settings.concurrent
    }

    fn on_outputs(
        &mut self,
        t: &Topology,
        w: &Windows,
        k: u64,
        outputs: &Outputs,
    ) -> Result<Iterate, String> {
        self.iterate(t, w, k, outputs)
    }

    fn take_iterations(&mut self) -> Vec<IterationRecord> {
        std::mem::take(&mut self.records)
    }

    fn unconverged_windows(&self) -> &[u64] {
        &self.unconverged
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iqn_ils_solves_a_linear_fixed_point_in_as_many_steps_as_its_rank_allows() {
        // H(F) = A F + c with a non-symmetric contraction A: the secants span the space after n
        // iterations, and the least-squares step then lands on the fixed point
        let a = [[-0.5, 0.3, 0.0], [0.1, -0.7, 0.2], [0.0, 0.4, 0.6]];
        let c = [1.0, -2.0, 0.5];
        let hmap = |f: &[f64]| -> Vec<f64> {
            (0..3)
                .map(|i| (0..3).map(|j| a[i][j] * f[j]).sum::<f64>() + c[i])
                .collect()
        };
        let mut f = vec![0.0; 3];
        let mut secants = Vec::new();
        let (mut rp, mut hp): (Option<Vec<f64>>, Option<Vec<f64>>) = (None, None);
        let mut steps = 0;
        loop {
            let h = hmap(&f);
            let r: Vec<f64> = h.iter().zip(&f).map(|(x, y)| x - y).collect();
            if r.iter().map(|x| x * x).sum::<f64>().sqrt() < 1e-12 {
                break;
            }
            if let (Some(rp), Some(hp)) = (&rp, &hp) {
                let dr: Vec<f64> = r.iter().zip(rp).map(|(x, y)| x - y).collect();
                let dh: Vec<f64> = h.iter().zip(hp).map(|(x, y)| x - y).collect();
                secants.push((0u64, dr, dh));
            }
            f = match iqn_ils_step(&secants, &r, &h, 1e-9) {
                Some(next) => next,
                None => f.iter().zip(&r).map(|(x, y)| x + 0.5 * y).collect(),
            };
            rp = Some(r);
            hp = Some(h);
            steps += 1;
            assert!(steps < 10, "no convergence");
        }
        // one relaxation step, then at most n = 3 quasi-Newton steps (exact for a linear map)
        assert!(steps <= 5, "{steps} steps");
        // the fixed point: (I − A) F = c
        for i in 0..3 {
            let lhs = f[i] - (0..3).map(|j| a[i][j] * f[j]).sum::<f64>();
            assert!((lhs - c[i]).abs() < 1e-10);
        }
    }

    #[test]
    fn the_qr_filter_drops_a_repeated_secant() {
        let col = (0u64, vec![1.0, 0.0], vec![2.0, 0.0]);
        let twice = vec![col.clone(), col.clone()];
        let one = vec![col];
        let r = [0.5, 0.0];
        let h = [1.0, 1.0];
        // the same column twice gives the same step as once (the copy is filtered, no 0/0)
        assert_eq!(
            iqn_ils_step(&twice, &r, &h, 1e-3),
            iqn_ils_step(&one, &r, &h, 1e-3)
        );
        assert_eq!(iqn_ils_step(&one, &r, &h, 1e-3), Some(vec![0.0, 1.0]));
        assert_eq!(iqn_ils_step(&[], &r, &h, 1e-3), None);
    }
}
