//! Periodic cell (Wellmann ch. 5.1, SEED-SPEC §3): a box [0, L1]×[0, L2]×[0, L3] whose
//! faces are periodic, the homogenised quantities of its packing, and the servo that drives
//! its edges — the representative volume element (RVE) of the two-scale model.
//!
//! - **Contacts across the faces** (W 5.2): the neighbour lists find them from the ghosts of
//!   the 13 shifts N⁺ ([`crate::broad_phase::HALF_SHIFTS`]); a pair (a, b, s) is the contact of
//!   a with b's image at x_b + s∘L. The deformation is boundary-driven as in the thesis: the
//!   centres are not remapped when L changes, only the images move (with s∘L). *Departure*:
//!   an image also moves with s∘L̇ besides its body's velocity (the thesis copies the
//!   velocity), so the relative velocity a contact's damping and tangential spring see is the
//!   rate of its relative position; `image_velocity = "copied"` gives the thesis's rule.
//! - **Average stress** (W 5.5): ⟨σ⟩ = (1/V) Σ_{B⁺} d(n) ⊗ f over the contacts across the
//!   faces, f the force on the body whose partner is the image; tension positive.
//! - **Servo** (W 5.7–5.10): each edge a "wall" of mass ρ t_w per area under the applied
//!   stress outside and ⟨σ_ii⟩ inside, with the damping 2ζ√(E/(ρ t_w L)); the applied stress
//!   ramps to its target at E ε̇ with ε̇ from the inertial number (5.8); or the edge moves at a
//!   prescribed strain rate. A programme of stages switches the control of each axis, the
//!   friction, and ends when its targets are met.

use crate::broad_phase::{image_shift, NeighbourLists};
use crate::hertz_mindlin::V3;
use crate::particles::Particles;
use crate::resolve_forces::{pair_force_torques, ForceContext, Kinematics};
use nalgebra::Matrix3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The fraction of the full strain rate a ramped strain stage starts with.
const RAMP_FLOOR: f64 = 0.02;

/// `[dem.periodic]`: a periodic cell instead of walls.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PeriodicConfig {
    /// Edge lengths L (m) at the start, `[L1, L2, L3]`, or one number for a cube; the
    /// particle sources fill [0, L].
    #[serde(deserialize_with = "edges_or_cube")]
    pub size: [f64; 3],
    /// Inertial number I of the loading rates (5.8): ε̇ = I √(d̄ p / m̄). Default 1e-4 (W ch. 5).
    #[serde(default = "default_inertial_number")]
    pub inertial_number: f64,
    /// Servo wall thickness t_w (m); default the mean particle diameter d̄. *Departure*: W
    /// §5.1.3 takes 0.01 r̄, a wall ~200 times lighter than a layer of grains, whose explicit
    /// update oscillates from step to step at the grains' Δt (set it to reproduce the thesis).
    #[serde(default)]
    pub wall_thickness: Option<f64>,
    /// Servo damping ratio ζ (5.10), default 0.1.
    #[serde(default = "default_servo_damping")]
    pub servo_damping: f64,
    /// The approximate sample modulus E (Pa) of the servo's damping and stress ramp, default
    /// 0.1 GPa (W §5.1.3).
    #[serde(default = "default_servo_modulus")]
    pub servo_modulus: f64,
    /// A stress stage ends when every stress-controlled axis is within this fraction of its
    /// target (and its edge moves slower than the quasi-static rate ε̇). Default 0.01.
    #[serde(default = "default_tolerance")]
    pub tolerance: f64,
    /// The programme, `[[dem.periodic.stages]]`, run in order; after the last the cell is held
    /// and the run ends (the DEM reports `programme_finished`).
    #[serde(default)]
    pub stages: Vec<StageConfig>,
    /// How an image across a face moves: `"shifted"` (default) with its body's velocity plus
    /// s∘L̇, so a contact across a face sees the rate of its relative position; `"copied"`
    /// with its body's velocity only, as the thesis's ghosts (W §5.1.1: ghost states are
    /// updated "using the displacement vectors d(n)", a shift of position): every contact
    /// across a face then sees a relative velocity short by s∘L̇, which its damping and its
    /// tangential spring take as real sliding.
    #[serde(default)]
    pub image_velocity: ImageVelocity,
}

/// `[dem.periodic] image_velocity`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ImageVelocity {
    #[default]
    Shifted,
    Copied,
}

/// `size = [L1, L2, L3]` or `size = L` (a cube).
fn edges_or_cube<'de, D: serde::Deserializer<'de>>(d: D) -> Result<[f64; 3], D::Error> {
    #[derive(Deserialize)]
    #[serde(
        untagged,
        expecting = "edge lengths [L1, L2, L3] or one length L (m) for a cube"
    )]
    enum Size {
        Cube(f64),
        Edges([f64; 3]),
    }
    Ok(match Size::deserialize(d)? {
        Size::Cube(l) => [l; 3],
        Size::Edges(e) => e,
    })
}

fn default_inertial_number() -> f64 {
    1e-4
}
fn default_servo_damping() -> f64 {
    0.1
}
fn default_servo_modulus() -> f64 {
    1e8
}
fn default_tolerance() -> f64 {
    0.01
}

/// Values per axis, `{ x = .., y = .., z = .. }` (any subset).
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Axes {
    #[serde(default)]
    pub x: Option<f64>,
    #[serde(default)]
    pub y: Option<f64>,
    #[serde(default)]
    pub z: Option<f64>,
}

impl Axes {
    pub fn get(&self, a: usize) -> Option<f64> {
        [self.x, self.y, self.z][a]
    }
}

/// `[[dem.periodic.stages]]`: how each axis is driven until the stage's targets are met.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct StageConfig {
    /// Name in outputs and messages (default `stage<k>`).
    #[serde(default)]
    pub name: Option<String>,
    /// Stress-controlled axes and their target σ̃ (Pa, tension positive: −1e3 presses with
    /// 1 kPa).
    #[serde(default)]
    pub stress: Axes,
    /// Strain-controlled axes and the engineering strain (L − L_start)/L_start of the stage
    /// to reach (−0.25: shortened by 25 %), at the rate of the inertial number (5.8) at the
    /// stage's stress targets (or the measured pressure), or at `strain_rate`.
    #[serde(default)]
    pub strain: Axes,
    /// The strain rate (1/s, > 0) of the strain-controlled axes instead of the inertial
    /// number's: e.g. to compact a stress-free loose packing, which has no pressure to take a
    /// rate from.
    #[serde(default)]
    pub strain_rate: Option<f64>,
    /// The strain over which the strain-controlled axes accelerate to their rate (rate ∝
    /// √(strain/ramp), as for a rate rising linearly in time), instead of starting at full
    /// speed: a start at full speed sends a stress wave through the cell that hides the
    /// initial (elastic) slope. *Not in thesis.* Default 0 (full speed at once).
    #[serde(default)]
    pub ramp: Option<f64>,
    /// Sets the friction coefficient of every particle pair from this stage on (W §5.3: the
    /// generation friction μ_gen while compressing, then the material's).
    #[serde(default)]
    pub friction: Option<f64>,
    /// At most this strain rate (1/s) on every axis (the servo's compression of a loose
    /// packing otherwise runs at the wall's terminal speed). Default: no cap.
    #[serde(default)]
    pub max_strain_rate: Option<f64>,
    /// Stops every grain (velocity and spin set to zero) as the stage starts: the thesis
    /// generates a *static* packing (random addition and geometric tightening, W §3.4.4)
    /// before the servo compresses it with μ_gen, where a compaction of ours leaves the
    /// grains moving. Default false.
    #[serde(default)]
    pub at_rest: bool,
}

impl StageConfig {
    pub fn label(&self, k: usize) -> String {
        self.name.clone().unwrap_or_else(|| format!("stage{k}"))
    }
}

/// The cell's state (part of snapshots).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct CellState {
    /// Edges L and their rates L̇.
    pub size: V3,
    pub rate: V3,
    /// Edges at the start (strains 5.6) and at the start of the current stage.
    pub size0: V3,
    pub stage_size0: V3,
    /// The applied stress σ_i of each axis (5.9) and the measured ⟨σ⟩ (5.5) of the last
    /// force evaluation.
    pub applied: V3,
    pub stress: Matrix3<f64>,
    /// Current stage (== number of stages when the programme is done) and when it began.
    pub stage: usize,
    pub stage_start: f64,
}

/// How the cell is driven: the scene's programme and the servo's constants.
#[derive(Debug, Clone)]
pub struct Servo {
    pub stages: Vec<StageConfig>,
    pub inertial_number: f64,
    /// Mass per unit area of a servo wall, ρ t_w.
    pub wall_mass: f64,
    pub damping: f64,
    pub modulus: f64,
    pub tolerance: f64,
    /// Mean particle mass m̄ and diameter d̄ (5.8).
    pub mean_mass: f64,
    pub mean_diameter: f64,
    pub image_velocity: ImageVelocity,
}

impl Servo {
    /// The cell as the force evaluation sees it: its edges, and the velocity shift s∘L̇ of an
    /// image (zero when images copy their body's velocity, as the thesis's ghosts).
    pub fn force_cell(&self, cell: &CellState) -> (V3, V3) {
        match self.image_velocity {
            ImageVelocity::Shifted => (cell.size, cell.rate),
            ImageVelocity::Copied => (cell.size, V3::zeros()),
        }
    }
}

/// How an axis is driven in a stage.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Control {
    Held,
    Stress(f64),
    Strain(f64),
}

impl Servo {
    fn control(&self, stage: usize, a: usize) -> Control {
        let Some(s) = self.stages.get(stage) else {
            return Control::Held;
        };
        match (s.stress.get(a), s.strain.get(a)) {
            (Some(t), _) => Control::Stress(t),
            (None, Some(e)) => Control::Strain(e),
            (None, None) => Control::Held,
        }
    }

    /// The quasi-static strain rate ε̇ = I √(d̄ p / m̄) at pressure p (5.8).
    pub fn strain_rate(&self, p: f64) -> f64 {
        self.inertial_number * (self.mean_diameter * p.abs() / self.mean_mass).sqrt()
    }

    /// The pressure a stage's rates refer to: its stress targets' mean magnitude, or the
    /// measured mean pressure when it has none.
    fn stage_pressure(&self, cell: &CellState) -> f64 {
        let targets: Vec<f64> = (0..3)
            .filter_map(|a| match self.control(cell.stage, a) {
                Control::Stress(t) => Some(t.abs()),
                _ => None,
            })
            .collect();
        if targets.is_empty() {
            mean_pressure(&cell.stress)
        } else {
            targets.iter().sum::<f64>() / targets.len() as f64
        }
    }

    /// The name of the current stage if it drives strain axes at a zero rate (no
    /// `strain_rate`, no stress target, and no pressure to take the rate of I from): it
    /// would never end.
    pub fn stalled_stage(&self, cell: &CellState) -> Option<String> {
        let s = self.stages.get(cell.stage)?;
        let strains = (0..3).any(|a| matches!(self.control(cell.stage, a), Control::Strain(_)));
        (strains && s.strain_rate.is_none() && self.strain_rate(self.stage_pressure(cell)) == 0.0)
            .then(|| s.label(cell.stage))
    }

    /// The friction in force at `stage`: the last stage up to it that set one.
    pub fn friction_at(&self, stage: usize) -> Option<f64> {
        self.stages
            .iter()
            .take(stage + 1)
            .rev()
            .find_map(|s| s.friction)
    }

    /// Moves the edges over `h` (symplectic Euler: rate, then edge) with the stress of the
    /// last evaluation, and ramps the applied stresses (5.7–5.10).
    pub fn advance(&self, cell: &mut CellState, h: f64) {
        let p_meas = mean_pressure(&cell.stress);
        let stage_rate = self
            .stages
            .get(cell.stage)
            .and_then(|s| s.strain_rate)
            .unwrap_or_else(|| self.strain_rate(self.stage_pressure(cell)));
        let cap = self.stages.get(cell.stage).and_then(|s| s.max_strain_rate);
        let ramp = self.stages.get(cell.stage).and_then(|s| s.ramp);
        for a in 0..3 {
            let l = cell.size[a];
            match self.control(cell.stage, a) {
                Control::Held => cell.rate[a] = 0.0,
                Control::Strain(target) => {
                    let l0 = cell.stage_size0[a];
                    // a rate rising linearly in time reaches strain e at √(e/ramp) of its
                    // full value; the floor starts the motion
                    let factor = ramp.map_or(1.0, |r| {
                        (((l - l0) / l0).abs() / r).sqrt().clamp(RAMP_FLOOR, 1.0)
                    });
                    cell.rate[a] = target.signum() * stage_rate * factor * l0;
                }
                Control::Stress(target) => {
                    // (5.8)–(5.9): the applied stress moves towards its target at E ε̇, ε̇
                    // from the measured pressure (at least the applied stress's or 1 % of
                    // the target's, so that a stress-free loose packing starts)
                    let p = p_meas.max(cell.applied[a].abs()).max(0.01 * target.abs());
                    let step = self.modulus * self.strain_rate(p) * h;
                    let gap = target - cell.applied[a];
                    cell.applied[a] += gap.signum() * step.min(gap.abs());
                    // (5.7), (5.10)
                    let c = 2.0 * self.damping * (self.modulus / (self.wall_mass * l)).sqrt();
                    let acc =
                        (cell.applied[a] - cell.stress[(a, a)]) / self.wall_mass - c * cell.rate[a];
                    cell.rate[a] += h * acc;
                }
            }
            if let Some(cap) = cap {
                let m = cap * l;
                cell.rate[a] = cell.rate[a].clamp(-m, m);
            }
            cell.size[a] += h * cell.rate[a];
        }
    }

    /// Whether the current stage's targets are met. A stage with strain-controlled axes ends
    /// when each reached its strain (its stress axes follow); one of stress-controlled axes
    /// only when every axis is within the tolerance of its target (with the applied stress
    /// at it) and moves slower than the quasi-static rate.
    pub fn stage_done(&self, cell: &CellState) -> bool {
        if cell.stage >= self.stages.len() {
            return false;
        }
        let rate = self.strain_rate(self.stage_pressure(cell));
        let strain_driven =
            (0..3).any(|a| matches!(self.control(cell.stage, a), Control::Strain(_)));
        (0..3).all(|a| match self.control(cell.stage, a) {
            Control::Held => true,
            Control::Stress(_) if strain_driven => true,
            Control::Strain(target) => {
                let e = (cell.size[a] - cell.stage_size0[a]) / cell.stage_size0[a];
                if target < 0.0 {
                    e <= target
                } else {
                    e >= target
                }
            }
            Control::Stress(target) => {
                cell.applied[a] == target
                    && (cell.stress[(a, a)] - target).abs() <= self.tolerance * target.abs()
                    && (cell.rate[a] / cell.size[a]).abs() <= rate
            }
        })
    }
}

/// How far the current stage has come, for progress displays: a strain-driven stage by
/// the least advanced of its strain axes (e/ẽ, 1 when each reached its strain), a stage of
/// stress-controlled axes only by the least advanced of their measured stresses (σ/σ̃, which
/// can pass 1 while the servo settles). `None` once the programme is done.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StageProgress {
    Strain(f64),
    Stress(f64),
}

impl Servo {
    /// The current stage's progress ([`StageProgress`]); always finite.
    pub fn stage_progress(&self, cell: &CellState) -> Option<StageProgress> {
        if cell.stage >= self.stages.len() {
            return None;
        }
        let least = |v: Vec<f64>| {
            let m = v.into_iter().fold(f64::INFINITY, f64::min);
            if m.is_finite() {
                m
            } else {
                0.0
            }
        };
        let strains: Vec<f64> = (0..3)
            .filter_map(|a| match self.control(cell.stage, a) {
                Control::Strain(target) if target != 0.0 => {
                    let e = (cell.size[a] - cell.stage_size0[a]) / cell.stage_size0[a];
                    Some((e / target).clamp(0.0, 1.0))
                }
                Control::Strain(_) => Some(1.0),
                _ => None,
            })
            .collect();
        if !strains.is_empty() {
            return Some(StageProgress::Strain(least(strains)));
        }
        let stresses: Vec<f64> = (0..3)
            .filter_map(|a| match self.control(cell.stage, a) {
                Control::Stress(target) if target != 0.0 => Some(cell.stress[(a, a)] / target),
                _ => None,
            })
            .collect();
        Some(StageProgress::Stress(least(stresses)))
    }
}

/// Mean pressure −tr σ/3 (compression positive).
pub fn mean_pressure(s: &Matrix3<f64>) -> f64 {
    -s.trace() / 3.0
}

/// Forces of the sphere pairs across the faces of a periodic cell: each contact is evaluated
/// on its own (in parallel, into its record), then the forces and torques are added to the
/// bodies in list order (bitwise the same for any thread count).
pub fn periodic_forces(lists: &mut NeighbourLists, p: &mut Particles, ctx: &ForceContext) {
    let Some((size, rate)) = ctx.cell else {
        return;
    };
    if lists.periodic_pairs.is_empty() {
        return;
    }
    let k = Kinematics::of(p);
    lists
        .periodic_pairs
        .par_iter_mut()
        .with_min_len(256)
        .for_each(|pp| {
            let (i, j) = (pp.pair[0] as usize, pp.pair[1] as usize);
            let d = p.position[i] - (p.position[j] + image_shift(&size, pp.image));
            let dist2 = d.norm_squared();
            let sum = p.radius[i] + p.radius[j];
            if dist2 >= sum * sum {
                pp.shear = V3::zeros();
                pp.force = V3::zeros();
                pp.overlap = sum - dist2.sqrt();
                pp.torques = [V3::zeros(); 2];
                return;
            }
            let vj = p.velocity[j] + image_shift(&rate, pp.image);
            let (f, ti, tj) = pair_force_torques(&k, ctx, (i, j), d, dist2, vj, &mut pp.shear);
            pp.force = f;
            pp.overlap = sum - dist2.sqrt();
            pp.torques = [ti, tj];
        });
    for pp in &lists.periodic_pairs {
        if pp.overlap < 0.0 {
            continue;
        }
        let (i, j) = (pp.pair[0] as usize, pp.pair[1] as usize);
        p.force[i] += pp.force;
        p.force[j] -= pp.force;
        p.torque[i] += pp.torques[0];
        p.torque[j] += pp.torques[1];
    }
}

/// The average stress of the cell (W 5.5): (1/V) Σ d(n) ⊗ f over the touching contacts across
/// its faces (sphere pairs and shaped pairs with an image), f the force on the first body.
pub fn boundary_stress(lists: &NeighbourLists, size: &V3) -> Matrix3<f64> {
    let mut s = Matrix3::zeros();
    for pp in &lists.periodic_pairs {
        if pp.overlap >= 0.0 {
            s += image_shift(size, pp.image) * pp.force.transpose();
        }
    }
    for (c, image) in lists
        .shaped_pair_contacts
        .iter()
        .zip(&lists.shaped_pair_image)
    {
        if *image != [0; 3] && c.touching() && c.force.x.is_finite() {
            s += image_shift(size, *image) * c.force.transpose();
        }
    }
    s / (size.x * size.y * size.z)
}

/// Homogenised quantities of the packing in the cell (W §5.1.2).
#[derive(Debug, Clone, PartialEq)]
pub struct Averages {
    /// (5.5)
    pub stress: Matrix3<f64>,
    /// The Love–Weber sum (1/V) Σ_c l_c ⊗ f_c over all contacts (branch vector to the
    /// partner's nearest image, force on the body), evaluated as (5.5) − (1/V) Σ_p x_p ⊗ F_p
    /// with F_p the contact force on body p (the same sum regrouped: the interior terms of
    /// every contact are −x_a ⊗ f − x_b ⊗ (−f)); equal to (5.5) in static equilibrium.
    pub love_weber: Matrix3<f64>,
    /// Solid fraction Σ V_p / V.
    pub solid_fraction: f64,
    /// Touching contacts (particle pairs) and the coordination number 2 N_c / N.
    pub contacts: usize,
    pub coordination: f64,
    /// Fabric tensor (1/N_c) Σ n ⊗ n.
    pub fabric: Matrix3<f64>,
}

/// The averages of the current state: `contact_force` is each particle's contact force
/// (its total force less gravity).
pub fn averages(
    lists: &NeighbourLists,
    p: &Particles,
    size: &V3,
    contact_force: impl Fn(usize) -> V3,
) -> Averages {
    let volume = size.x * size.y * size.z;
    let stress = boundary_stress(lists, size);
    let mut moment = Matrix3::zeros();
    for k in 0..p.len() {
        moment += p.position[k] * contact_force(k).transpose();
    }
    let mut fabric = Matrix3::zeros();
    let mut contacts = 0usize;
    let mut add = |n: V3| {
        let len = n.norm();
        if len > 0.0 {
            let n = n / len;
            fabric += n * n.transpose();
            contacts += 1;
        }
    };
    for i in 0..p.len() {
        for pk in lists.first_pair[i] as usize..lists.first_pair[i + 1] as usize {
            let j = lists.partner[pk] as usize;
            let d = p.position[j] - p.position[i];
            if d.norm() < p.radius[i] + p.radius[j] {
                add(d);
            }
        }
    }
    for pp in &lists.periodic_pairs {
        if pp.overlap >= 0.0 {
            let (i, j) = (pp.pair[0] as usize, pp.pair[1] as usize);
            add(p.position[j] + image_shift(size, pp.image) - p.position[i]);
        }
    }
    for c in &lists.shaped_pair_contacts {
        if c.touching() {
            add(c.normal);
        }
    }
    let solid: f64 = (0..p.len()).map(|k| p.volume(k)).sum();
    Averages {
        stress,
        love_weber: stress - moment / volume,
        solid_fraction: solid / volume,
        contacts,
        coordination: if p.is_empty() {
            0.0
        } else {
            2.0 * contacts as f64 / p.len() as f64
        },
        fabric: if contacts > 0 {
            fabric / contacts as f64
        } else {
            fabric
        },
    }
}

/// Principal stresses of a symmetric stress, most compressive first (tension positive: the
/// smallest value first).
pub fn principal_stresses(s: &Matrix3<f64>) -> [f64; 3] {
    let sym = (s + s.transpose()) * 0.5;
    let e = sym.symmetric_eigenvalues();
    let mut v = [e[0], e[1], e[2]];
    v.sort_by(f64::total_cmp);
    v
}

/// One row of `periodic.csv`: the cell, its strains (5.6) and the averages.
pub fn csv_row(time: f64, cell: &CellState, servo: &Servo, avg: &Averages) -> Vec<(String, f64)> {
    let mut row: Vec<(String, f64)> =
        vec![("time".into(), time), ("stage".into(), cell.stage as f64)];
    let axes = ["x", "y", "z"];
    for (a, n) in axes.iter().enumerate() {
        row.push((format!("length_{n}"), cell.size[a]));
    }
    for (a, n) in axes.iter().enumerate() {
        // (5.6), engineering strain from the start
        row.push((
            format!("strain_{n}"),
            (cell.size[a] - cell.size0[a]) / cell.size0[a],
        ));
    }
    let v0 = cell.size0.x * cell.size0.y * cell.size0.z;
    let v = cell.size.x * cell.size.y * cell.size.z;
    row.push(("volumetric_strain".into(), (v - v0) / v0));
    // the same from the start of the current stage (a triaxial curve starts at its shear)
    for (a, n) in axes.iter().enumerate() {
        row.push((
            format!("stage_strain_{n}"),
            (cell.size[a] - cell.stage_size0[a]) / cell.stage_size0[a],
        ));
    }
    let vs = cell.stage_size0.x * cell.stage_size0.y * cell.stage_size0.z;
    row.push(("stage_volumetric_strain".into(), (v - vs) / vs));
    for (name, (r, c)) in [
        ("xx", (0, 0)),
        ("yy", (1, 1)),
        ("zz", (2, 2)),
        ("xy", (0, 1)),
        ("xz", (0, 2)),
        ("yz", (1, 2)),
    ] {
        row.push((format!("stress_{name}"), avg.stress[(r, c)]));
    }
    for (a, n) in axes.iter().enumerate() {
        row.push((format!("applied_{n}"), cell.applied[a]));
    }
    let pr = principal_stresses(&avg.stress);
    let p = mean_pressure(&avg.stress);
    row.push(("pressure".into(), p));
    // deviatoric q = σ1 − σ3 of the principal stresses (compression positive)
    row.push(("deviator".into(), pr[2] - pr[0]));
    row.push((
        "stress_ratio".into(),
        if pr[2] < 0.0 { pr[0] / pr[2] } else { f64::NAN },
    ));
    row.push(("pressure_love_weber".into(), mean_pressure(&avg.love_weber)));
    row.push(("solid_fraction".into(), avg.solid_fraction));
    row.push(("coordination".into(), avg.coordination));
    for (a, n) in axes.iter().enumerate() {
        row.push((format!("fabric_{n}{n}"), avg.fabric[(a, a)]));
    }
    row.push(("strain_rate_quasi_static".into(), {
        servo.strain_rate(p.max(0.0))
    }));
    row
}

/// Result keys for summary.json.
pub fn results(cell: &CellState, servo: &Servo, avg: &Averages) -> BTreeMap<String, f64> {
    let pr = principal_stresses(&avg.stress);
    let mut r = BTreeMap::new();
    r.insert("cell.stage".into(), cell.stage as f64);
    r.insert(
        "cell.programme_finished".into(),
        (cell.stage >= servo.stages.len()) as u8 as f64,
    );
    r.insert("cell.pressure".into(), mean_pressure(&avg.stress));
    r.insert(
        "cell.stress_ratio".into(),
        if pr[2] < 0.0 { pr[0] / pr[2] } else { f64::NAN },
    );
    r.insert("cell.solid_fraction".into(), avg.solid_fraction);
    r.insert("cell.coordination".into(), avg.coordination);
    for (a, n) in ["x", "y", "z"].iter().enumerate() {
        r.insert(
            format!("cell.strain_{n}"),
            (cell.size[a] - cell.size0[a]) / cell.size0[a],
        );
    }
    r
}
