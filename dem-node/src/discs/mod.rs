//! The 2-D disc engine of Madan (2019): discs per unit depth with a linear contact law, bonds,
//! viscous and non-viscous damping and central differences (standard DEM, M §2.1), and the
//! deformable-particle mode DDEM (M §2.2–2.6): every particle takes the uniform strain of the
//! average stress of its contact (and external) forces, and contacts act on the overlap of the
//! deformed particles (2.41)–(2.54).
//!
//! A step (the lagged explicit scheme, M (3.17), Fig. 2.7): particle strains from the stresses
//! of the previous step's forces → contacts of the deformed particles at the new positions →
//! contact forces → particle stresses → central differences. With `scheme = "fixed-point"` the
//! forces of a step are instead iterated to the fixed point F = F(X, E(F)) (3.5)–(3.7), which
//! converges only while ρ(B) < 1 ([`ddem::spectral_radius`]).
//!
//! Sign conventions (SEED-SPEC §5.11): normal forces are magnitudes, compression positive
//! (bonded contacts may go negative, in tension); stresses are tension positive; strain and
//! stress vectors ε̃ = [ε_xx, ε_yy, 2ε_xy], σ̃ = [σ_xx, σ_yy, σ_xy]. The normal n points from the
//! first disc i of a pair to the second j, t = ẑ × n; the force on j is f_n n + f_t t.

mod bagi;
pub mod config;
pub mod ddem;
mod output;

pub use bagi::BagiMesh;
use config::{DiscConfig, DiscSource, Dof, Model, Scheme, StrainKind, TestKind};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::Path;

pub use output::write_discs_vtk;

/// A 2-D vector.
pub type V2 = [f64; 2];

/// Pairs (or discs) per parallel task: below this the work stays on one thread.
const PAR_MIN: usize = 512;

/// Errors of the disc engine; each names the field, file, disc or contact concerned.
#[derive(Debug, thiserror::Error)]
pub enum DiscError {
    #[error("{path}: {message}")]
    Config { path: String, message: String },
    #[error("{path}{}: {message}", if *line > 0 { format!(", line {line}") } else { String::new() })]
    File {
        path: String,
        line: usize,
        message: String,
    },
    #[error("{path}: {message}")]
    Output { path: String, message: String },
    #[error("instability at t = {time:e} s (step {step}): {message}")]
    Unstable {
        time: f64,
        step: u64,
        message: String,
    },
    #[error("{0}")]
    Snapshot(String),
}

fn config_err(path: impl Into<String>, message: impl Into<String>) -> DiscError {
    DiscError::Config {
        path: path.into(),
        message: message.into(),
    }
}

/// Parses the top-level table `table` of a scene file as a disc scene (`model = "discs-2d"`),
/// every value checked; errors carry the line and column in the file.
pub fn parse_scene_table(
    text: &str,
    table: &str,
) -> Result<Option<DiscConfig>, scenefile::SceneError> {
    let cfg: Option<DiscConfig> = scenefile::named_table(text, table).map_err(|e| {
        let at = e.span().map_or(0, |s| s.start);
        let field = scenefile::path_at(text, at).unwrap_or_default();
        scenefile::SceneError::at(text, at, field, e.message().trim().to_string())
    })?;
    let Some(cfg) = cfg else { return Ok(None) };
    if let Some(err) = cfg.validate().into_iter().next() {
        let path = match err.path.strip_prefix("dem") {
            Some(rest) => format!("{table}{rest}"),
            None => err.path.clone(),
        };
        let at = scenefile::locate(text, &scenefile::split_path(&path)).map_or(0, |s| s.start);
        return Err(scenefile::SceneError::at(text, at, path, err.message));
    }
    Ok(Some(cfg))
}

/// Which model a `[dem]`-schema table asks for, read before the rest.
pub fn scene_model(text: &str, table: &str) -> Model {
    scenefile::named_table::<config::ModelOnly>(text, table)
        .ok()
        .flatten()
        .map(|m| m.model)
        .unwrap_or_default()
}

/// The contact state of a candidate pair (i < j).
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq)]
pub struct PairState {
    /// Bonded at t = 0 (2.21) and not broken since (2.38)–(2.39).
    pub bonded: bool,
    /// Touching (or bonded) in the last force evaluation.
    pub active: bool,
    /// The tangential spring's elongation u_t along t (m), incremental (2.27)–(2.32).
    pub ut: f64,
    /// Elastic normal force f_ne = k_n (h_c − rest) (N, compression positive) (2.54).
    pub fn_elastic: f64,
    /// Elastic tangential force on j along t (N).
    pub ft_elastic: f64,
    /// The whole normal force, with the viscous part (2.33).
    pub fn_total: f64,
    /// The whole tangential force on j along t, with the viscous part (2.34).
    pub ft_total: f64,
    /// The overlap of the deformed discs h_c (m) (2.53), positive in contact.
    pub overlap: f64,
    /// A bond's rest overlap (m): its t = 0 overlap with `bond_at_rest`, else 0.
    pub rest: f64,
}

/// The mutable state: all a snapshot holds, so a resumed run continues bit for bit.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct State {
    step: u64,
    time: f64,
    x: Vec<V2>,
    v: Vec<V2>,
    theta: Vec<f64>,
    omega: Vec<f64>,
    /// Candidate pairs (i < j, sorted) of the neighbour list and their contact state.
    pairs: Vec<(u32, u32)>,
    pair_state: Vec<PairState>,
    /// Positions at the last list build and the list's skin (m).
    x_build: Vec<V2>,
    list_skin: f64,
    /// σ̃ of each disc from the last force evaluation: the next step's strains (lagged).
    stress: Vec<[f64; 3]>,
    /// The work of the external loads at their points of application, of gravity and of the
    /// moving walls (J).
    work_external: f64,
    /// Per loaded disc: the displacement of its load point and its load at the last evaluation.
    load_point: Vec<V2>,
    load_previous: Vec<V2>,
    /// The measurement while the load rises: (σ_xx, σ_yy, σ_xy, ε_xx, ε_yy, ε_xy, and the load
    /// fraction or the test's stress magnitude).
    samples: Vec<[f64; 7]>,
    /// Fixed-point iterations of the last step and the most of any step.
    iterations_last: u32,
    iterations_most: u32,
    /// Bonds broken so far.
    bonds_broken: u64,
    /// Per wall: its displacement from `point`, its velocity, the force the discs exert on
    /// it (last evaluation) and each disc's contact with it.
    wall_shift: Vec<V2>,
    wall_velocity: Vec<V2>,
    wall_force: Vec<V2>,
    wall_state: Vec<Vec<PairState>>,
    /// Per probe: the largest displacement along the pulse so far and when (a wave's arrival).
    #[serde(default)]
    probe_track: Vec<ProbeTrack>,
}

/// A probe's reading along the pulse's displacement (its displacement's length without a
/// pulse) at the last two steps, and its largest value so far with the time of that peak (a
/// parabola through the three readings around it).
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
struct ProbeTrack {
    before: f64,
    last: f64,
    peak: f64,
    peak_time: f64,
}

/// A rigid plate (a straight wall), its unit normal pointing into the sample.
#[derive(Debug, Clone)]
struct Wall {
    name: String,
    point: V2,
    normal: V2,
    velocity: Option<V2>,
    /// (pressure, length, max_speed, gain) of a servo-controlled wall.
    servo: Option<(f64, f64, f64, f64)>,
    stop: Option<f64>,
}

/// xorshift64*: the random source's positions and radii, the same on every machine.
struct Rng(u64);

impl Rng {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// `count` non-overlapping discs in the box by random sequential addition, largest first.
/// The least-squares line through the points (x, y): its slope and the coefficient of
/// determination r² (NaN where the x or y do not vary).
fn line_fit(pts: &[(f64, f64)]) -> (f64, f64) {
    let n = pts.len() as f64;
    let mx = pts.iter().map(|p| p.0).sum::<f64>() / n;
    let my = pts.iter().map(|p| p.1).sum::<f64>() / n;
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let syy: f64 = pts.iter().map(|p| (p.1 - my).powi(2)).sum();
    (sxy / sxx, sxy * sxy / (sxx * syy))
}

/// The nearest periodic image of the branch vector `d`: along each axis of period
/// `len[k] > 0`, d_k − len_k · round(d_k/len_k).
fn image(mut d: V2, len: [f64; 2]) -> V2 {
    for k in 0..2 {
        if len[k] > 0.0 {
            d[k] -= len[k] * (d[k] / len[k]).round();
        }
    }
    d
}

/// A grid of square-ish cells at least `cell` wide for neighbour searches; along a periodic
/// axis a whole number of cells spans the period and the indices wrap.
#[derive(Debug, Clone, Copy)]
struct Grid {
    lo: [f64; 2],
    size: [f64; 2],
    /// Cells along a periodic axis (0: unbounded).
    count: [i64; 2],
}

impl Grid {
    fn new(cell: f64, lo: [f64; 2], len: [f64; 2]) -> Grid {
        let mut g = Grid {
            lo: [0.0; 2],
            size: [cell; 2],
            count: [0; 2],
        };
        for k in 0..2 {
            if len[k] > 0.0 {
                let n = ((len[k] / cell).floor() as i64).max(1);
                g.lo[k] = lo[k];
                g.size[k] = len[k] / n as f64;
                g.count[k] = n;
            }
        }
        g
    }

    fn wrap(&self, c: (i64, i64)) -> (i64, i64) {
        let w = |a: i64, n: i64| if n > 0 { a.rem_euclid(n) } else { a };
        (w(c.0, self.count[0]), w(c.1, self.count[1]))
    }

    fn key(&self, p: V2) -> (i64, i64) {
        self.wrap((
            ((p[0] - self.lo[0]) / self.size[0]).floor() as i64,
            ((p[1] - self.lo[1]) / self.size[1]).floor() as i64,
        ))
    }
}

/// `count` discs placed at random in the box without overlaps (random sequential addition,
/// largest first). Along a periodic axis (`period`: the cell's lower side and length, length 0
/// where not periodic) the discs fill the box edge to edge and keep clear of each other's
/// periodic images.
fn random_discs(
    count: usize,
    min: V2,
    max: V2,
    radius: &config::Triangular,
    seed: u64,
    period: ([f64; 2], [f64; 2]),
) -> Result<Vec<(V2, f64)>, String> {
    let mut rng = Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1);
    let mut radii: Vec<f64> = (0..count).map(|_| radius.quantile(rng.uniform())).collect();
    radii.sort_by(|a, b| b.total_cmp(a));
    let grid = Grid::new(2.0 * radius.max, period.0, period.1);
    let len = period.1;
    let mut cells: std::collections::HashMap<(i64, i64), Vec<usize>> = Default::default();
    let mut out: Vec<(V2, f64)> = Vec::with_capacity(count);
    let area = (max[0] - min[0]) * (max[1] - min[1]);
    for (k, &r) in radii.iter().enumerate() {
        let mut placed = false;
        // the margin from the box's sides: none along a periodic axis
        let margin = [0, 1].map(|a| if len[a] > 0.0 { 0.0 } else { r });
        if (0..2).all(|a| max[a] - min[a] > 2.0 * margin[a]) {
            for _ in 0..10_000 {
                let p = [0, 1].map(|a| {
                    min[a] + margin[a] + rng.uniform() * (max[a] - min[a] - 2.0 * margin[a])
                });
                let (a, b) = grid.key(p);
                let free = (-1..=1).all(|da| {
                    (-1..=1).all(|db| {
                        cells.get(&grid.wrap((a + da, b + db))).is_none_or(|v| {
                            v.iter()
                                .all(|&q| norm2(image(sub(out[q].0, p), len)) >= out[q].1 + r)
                        })
                    })
                });
                if free {
                    cells.entry((a, b)).or_default().push(out.len());
                    out.push((p, r));
                    placed = true;
                    break;
                }
            }
        }
        if !placed {
            let solid: f64 = out.iter().map(|d| std::f64::consts::PI * d.1 * d.1).sum();
            return Err(format!(
                "placed only {k} of {count} discs before the box was full (solid fraction {:.3}; random placement jams near 0.55): enlarge the box",
                solid / area
            ));
        }
    }
    Ok(out)
}

/// A load on a set of discs, ramped.
#[derive(Debug, Clone)]
struct Load {
    discs: Vec<u32>,
    force: V2,
    ramp: f64,
}

impl Load {
    fn factor(&self, t: f64) -> f64 {
        if self.ramp > 0.0 {
            (t / self.ramp).min(1.0)
        } else {
            1.0
        }
    }
}

/// The disc sets of the measurement and the initial distances, or Bagi's triangulation.
#[derive(Debug, Clone)]
struct Measure {
    test: TestKind,
    bagi: Option<BagiMesh>,
    top: Vec<u32>,
    bottom: Vec<u32>,
    left: Vec<u32>,
    right: Vec<u32>,
    height0: f64,
    width0: f64,
    /// Simple shear of a slab (the centres' strain): the initial x offset of the mean top
    /// centre from the mean bottom one.
    offset0: f64,
    section: f64,
    fit: [f64; 2],
    /// The wall whose force is the load.
    plate: Option<usize>,
    /// Driven by a plate or by prescribed motion (the fit takes fractions of the peak stress),
    /// not by ramped loads (fractions of the load).
    driven: bool,
}

/// One pair's forces of an evaluation (not yet committed to [`PairState`]).
#[derive(Debug, Clone, Copy, Default)]
struct PairEval {
    state: PairState,
    /// n (i → j).
    n: V2,
    broke: bool,
}

/// The disc engine.
pub struct DiscEngine {
    cfg: DiscConfig,
    dt: f64,
    radius: Vec<f64>,
    mass: Vec<f64>,
    inertia: Vec<f64>,
    volume: Vec<f64>,
    x0: Vec<V2>,
    /// Free coordinates (x, y, θ) of each disc.
    free: Vec<[bool; 3]>,
    /// The velocity of each fixed coordinate (zero unless a constraint prescribes one).
    prescribed: Vec<V2>,
    /// The (disc, coordinate) pairs with a non-zero prescribed velocity.
    driven: Vec<(u32, u8)>,
    loads: Vec<Load>,
    /// Discs with a load, sorted, and the index of each disc among them (u32::MAX: none).
    loaded: Vec<u32>,
    loaded_index: Vec<u32>,
    compliance: Option<[[f64; 3]; 3]>,
    measure: Option<Measure>,
    r_mean: f64,
    r_max: f64,
    /// The periodic cell (`dem.periodic`): its lower corner and its lengths (0: not periodic).
    period_lo: V2,
    period: V2,
    state: State,
    /// Each disc's pairs in the list's order: `adjacency.1[adjacency.0[p]..adjacency.0[p + 1]]`
    /// holds 2k for pair k with p its first disc, 2k + 1 with p its second (rebuilt with the list).
    adjacency: (Vec<u32>, Vec<u32>),
    /// Scratch of a step.
    force: Vec<V2>,
    torque: Vec<f64>,
    external: Vec<V2>,
    strain: Vec<[f64; 3]>,
    stress_new: Vec<[f64; 3]>,
    eval: Vec<PairEval>,
    walls: Vec<Wall>,
    /// Active contacts of each wall in the last evaluation.
    wall_contacts: Vec<usize>,
    eval_walls: Vec<Vec<PairEval>>,
    wall_force_new: Vec<V2>,
    /// Limits at t = 0 (see [`DiscEngine::limits`]).
    initial_limits: Vec<(String, f64)>,
    /// The probes' names and discs.
    probes: Vec<(String, Vec<u32>)>,
    /// `dem.threads`: the engine's own pool (None: rayon's global one, all cores).
    pool: Option<rayon::ThreadPool>,
    output: output::OutputState,
}

/// Largest strain a particle may take before the run is stopped as unstable: the DDEM is a
/// small-strain model (M §2.2), and a diverging lagged scheme shows first as growing strains.
pub const STRAIN_LIMIT: f64 = 0.05;

fn add(a: V2, b: V2) -> V2 {
    [a[0] + b[0], a[1] + b[1]]
}
fn sub(a: V2, b: V2) -> V2 {
    [a[0] - b[0], a[1] - b[1]]
}
fn dot2(a: V2, b: V2) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}
fn norm2(a: V2) -> f64 {
    dot2(a, a).sqrt()
}
fn scale(a: V2, s: f64) -> V2 {
    [a[0] * s, a[1] * s]
}
/// ε s for a strain vector ε̃ = [ε_xx, ε_yy, 2ε_xy] (2.50).
fn strain_times(e: [f64; 3], s: V2) -> V2 {
    [
        e[0] * s[0] + 0.5 * e[2] * s[1],
        0.5 * e[2] * s[0] + e[1] * s[1],
    ]
}
/// The Frobenius norm of the strain tensor: a bound of |ε s| / |s|.
fn strain_norm(e: [f64; 3]) -> f64 {
    (e[0] * e[0] + e[1] * e[1] + 0.5 * e[2] * e[2]).sqrt()
}
/// Adds the symmetric part of s ⊗ f (2.44) to σ̃.
fn add_stress(s: &mut [f64; 3], arm: V2, f: V2) {
    s[0] += arm[0] * f[0];
    s[1] += arm[1] * f[1];
    s[2] += 0.5 * (arm[0] * f[1] + arm[1] * f[0]);
}

/// Reads the discs of a CSV file of `x,y,radius` rows (a header line and `#` comments are
/// allowed).
fn read_disc_file(path: &Path, field: &str) -> Result<Vec<(V2, f64)>, DiscError> {
    let text = std::fs::read_to_string(path).map_err(|e| DiscError::File {
        path: path.display().to_string(),
        line: 0,
        message: format!("cannot read ({e}); named by {field}"),
    })?;
    let mut out = Vec::new();
    for (k, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let cols: Vec<&str> = line.split(',').map(str::trim).collect();
        let nums: Result<Vec<f64>, _> = cols.iter().map(|c| c.parse::<f64>()).collect();
        let err = |message: String| DiscError::File {
            path: path.display().to_string(),
            line: k + 1,
            message,
        };
        match nums {
            Err(_) if out.is_empty() && k == 0 => continue, // a header
            Err(_) => return Err(err(format!("`{line}` is not three numbers x,y,radius"))),
            Ok(v) if v.len() != 3 => {
                return Err(err(format!(
                    "{} columns; a disc is x,y,radius (m)",
                    v.len()
                )))
            }
            Ok(v) => {
                if !(v.iter().all(|c| c.is_finite()) && v[2] > 0.0) {
                    return Err(err(format!(
                        "x,y must be finite and the radius positive, got {line}"
                    )));
                }
                out.push(([v[0], v[1]], v[2]));
            }
        }
    }
    if out.is_empty() {
        return Err(DiscError::File {
            path: path.display().to_string(),
            line: 0,
            message: "holds no discs".into(),
        });
    }
    Ok(out)
}

/// The linear contact law of a touching or bonded pair (M (2.25)–(2.40)): the elastic normal
/// force k_n h_c (a bond at rest: k_n (h_c − its t = 0 overlap)), the viscous c_n = ξ_n
/// 2√(m_red k_n) (2.33)–(2.37), the incremental tangential spring u_t with its dashpot, bond
/// breaking at φ_n in tension or φ_t in shear (2.38)–(2.39), then (unbonded) no tension and
/// Coulomb sliding |f_t| ≤ μ f_n (2.40). `v_n`, `v_t`: the second body's contact point relative to the first's along n and t = ẑ × n.
/// Returns the new state (inactive for an unbonded pair apart) and whether a bond broke.
fn contact_law(
    c: &config::ContactConfig,
    dt: f64,
    m_red: f64,
    overlap: f64,
    v_n: f64,
    v_t: f64,
    old: &PairState,
) -> (PairState, bool) {
    let c_n = c.normal_damping * 2.0 * (m_red * c.normal_stiffness).sqrt();
    let c_t = c.tangential_damping * 2.0 * (m_red * c.tangential_stiffness).sqrt();
    // a bond's spring counts from its rest overlap
    let rest = if old.bonded { old.rest } else { 0.0 };
    let mut fn_e = c.normal_stiffness * (overlap - rest);
    let mut fn_total = fn_e - c_n * v_n;
    let mut ut = old.ut + v_t * dt;
    let mut ft_e = -c.tangential_stiffness * ut;
    let mut ft_total = ft_e - c_t * v_t;
    let broke = old.bonded
        && ((fn_e < 0.0 && -fn_e >= c.bond_normal_strength)
            || ft_e.abs() >= c.bond_tangential_strength);
    let bonded = old.bonded && !broke;
    if broke && rest != 0.0 {
        // unbonded from now: the discs' own overlap
        fn_e = c.normal_stiffness * overlap;
        fn_total = fn_e - c_n * v_n;
    }
    if !bonded {
        if overlap <= 0.0 {
            let apart = PairState {
                overlap,
                ..Default::default()
            };
            return (apart, broke);
        }
        fn_total = fn_total.max(0.0);
        // Coulomb: the spring slides back to the limit
        let limit = c.friction * fn_e.max(0.0);
        if ft_e.abs() > limit {
            ft_e = limit.copysign(ft_e);
            ut = if c.tangential_stiffness > 0.0 {
                -ft_e / c.tangential_stiffness
            } else {
                0.0
            };
            ft_total = ft_e;
        }
    }
    let state = PairState {
        bonded,
        active: true,
        ut,
        fn_elastic: fn_e,
        ft_elastic: ft_e,
        fn_total,
        ft_total,
        overlap,
        rest: if bonded { rest } else { 0.0 },
    };
    (state, broke)
}

impl DiscEngine {
    /// Builds the engine: the discs of every source, bonds at t = 0, loads, constraints, the
    /// neighbour list, and the limits of the initial packing.
    pub fn from_config(cfg: &DiscConfig, base: &Path) -> Result<Self, DiscError> {
        if cfg.model != Model::Discs2d {
            return Err(config_err(
                "dem.model",
                "the disc engine reads scenes with model = \"discs-2d\"",
            ));
        }
        if let Some(e) = cfg.validate().into_iter().next() {
            return Err(config_err(e.path, e.message));
        }
        let mut x = Vec::new();
        let mut radius = Vec::new();
        for (k, s) in cfg.discs.iter().enumerate() {
            match s {
                DiscSource::Lattice {
                    arrangement,
                    radius: r,
                    spacing,
                    first,
                    count,
                    odd_row_offset,
                    odd_row_count,
                } => {
                    let hex = *arrangement == config::Arrangement::Hexagonal;
                    let dy = if hex {
                        spacing * 3f64.sqrt() / 2.0
                    } else {
                        *spacing
                    };
                    for row in 0..count[1] {
                        let odd = row % 2 == 1 && hex;
                        let (offset, n) = if odd {
                            (
                                odd_row_offset.unwrap_or(0.5) * spacing,
                                odd_row_count.unwrap_or(count[0]),
                            )
                        } else {
                            (0.0, count[0])
                        };
                        for col in 0..n {
                            x.push([
                                first[0] + offset + col as f64 * spacing,
                                first[1] + row as f64 * dy,
                            ]);
                            radius.push(*r);
                        }
                    }
                    if !hex && (odd_row_offset.is_some() || odd_row_count.is_some()) {
                        return Err(config_err(
                            format!("dem.discs[{k}]"),
                            "odd_row_offset and odd_row_count belong to hexagonal lattices",
                        ));
                    }
                }
                DiscSource::Random {
                    count,
                    min,
                    max,
                    radius: dist,
                    seed,
                } => {
                    let discs = random_discs(*count, *min, *max, dist, *seed, cfg.periodic.cell())
                        .map_err(|m| config_err(format!("dem.discs[{k}]"), m))?;
                    for (p, r) in discs {
                        x.push(p);
                        radius.push(r);
                    }
                }
                DiscSource::File { path } => {
                    let field = format!("dem.discs[{k}].path");
                    for (p, r) in read_disc_file(&base.join(path), &field)? {
                        x.push(p);
                        radius.push(r);
                    }
                }
            }
        }
        let n = x.len();
        if n > u32::MAX as usize / 2 {
            return Err(config_err("dem.discs", format!("{n} discs are too many")));
        }
        let l = cfg.depth;
        let volume: Vec<f64> = radius
            .iter()
            .map(|r| std::f64::consts::PI * r * r * l)
            .collect();
        let mass: Vec<f64> = volume.iter().map(|v| cfg.density * v).collect();
        // J = ½ m R² (2.3)
        let inertia: Vec<f64> = mass
            .iter()
            .zip(&radius)
            .map(|(m, r)| 0.5 * m * r * r)
            .collect();
        let r_mean = radius.iter().sum::<f64>() / n as f64;
        let r_max = radius.iter().copied().fold(0.0, f64::max);
        let (period_lo, period) = cfg.periodic.cell();
        for (k, axis) in ["x", "y"].into_iter().enumerate() {
            // the nearest image is the only one in reach: a pair's centres, with the list's
            // skin (also covering 5 % strains) or the bond tolerance, stay within half a period
            let reach = 2.0 * r_max
                + (cfg.skin * r_mean)
                    .max(0.2 * r_max)
                    .max(1.01 * cfg.contact.bond_gap.unwrap_or(0.0));
            if period[k] > 0.0 && period[k] <= 2.0 * reach {
                return Err(config_err(
                    format!("dem.periodic.{axis}"),
                    format!(
                        "the period {:e} m must exceed twice a pair's reach {reach:e} m (two of the largest discs with the list's skin)",
                        period[k]
                    ),
                ));
            }
        }
        let mut free = vec![[true; 3]; n];
        let mut prescribed = vec![[0.0; 2]; n];
        for (k, c) in cfg.constraints.iter().enumerate() {
            let discs = c.region.select(&x, &radius);
            if discs.is_empty() {
                return Err(config_err(
                    format!("dem.constraints[{k}].region"),
                    format!("holds no disc ({})", c.region),
                ));
            }
            for &p in &discs {
                let p = p as usize;
                let d = sub(x[p], c.origin);
                for dof in &c.fix {
                    let k = match dof {
                        Dof::X => 0,
                        Dof::Y => 1,
                        Dof::Rotation => 2,
                    };
                    free[p][k] = false;
                    if k < 2 {
                        prescribed[p][k] = c.velocity[k] + dot2(c.gradient[k], d);
                    }
                }
            }
        }
        let walls: Vec<Wall> = cfg
            .walls
            .iter()
            .map(|w| {
                let l = norm2(w.normal);
                let normal = scale(w.normal, 1.0 / l);
                let mut point = w.point;
                if w.touch {
                    // the largest overlap of any disc with the line (negative: the gap),
                    // taken back: the line moves by −most along its normal
                    let most = x
                        .iter()
                        .zip(&radius)
                        .map(|(p, r)| r - dot2(sub(*p, point), normal))
                        .fold(f64::NEG_INFINITY, f64::max);
                    point = add(point, scale(normal, -most));
                }
                Wall {
                    name: w.name.clone(),
                    point,
                    normal,
                    velocity: w.velocity,
                    servo: w.pressure.map(|p| {
                        (
                            p,
                            w.length.unwrap_or(1.0),
                            w.max_speed.unwrap_or(0.0),
                            w.gain,
                        )
                    }),
                    stop: w.stop,
                }
            })
            .collect();
        let mut loads = Vec::new();
        for (k, ld) in cfg.loads.iter().enumerate() {
            let discs = ld.region.select(&x, &radius);
            if discs.is_empty() {
                return Err(config_err(
                    format!("dem.loads[{k}].region"),
                    format!("holds no disc ({})", ld.region),
                ));
            }
            loads.push(Load {
                discs,
                force: ld.force,
                ramp: ld.ramp,
            });
        }
        let mut loaded: Vec<u32> = loads.iter().flat_map(|l| l.discs.clone()).collect();
        loaded.sort_unstable();
        loaded.dedup();
        let mut loaded_index = vec![u32::MAX; n];
        for (k, &p) in loaded.iter().enumerate() {
            loaded_index[p as usize] = k as u32;
        }
        let measure = match &cfg.measure {
            None => None,
            Some(m) => {
                let mut sets = Vec::new();
                let mut height0 = 0.0;
                let mut width0 = 0.0;
                let mut offset0 = 0.0;
                let slab = m.slab();
                if m.strain == StrainKind::Centres {
                    // the sets' discs (a slab's shear reads only top and bottom)
                    let all = [
                        ("top", &m.top),
                        ("bottom", &m.bottom),
                        ("left", &m.left),
                        ("right", &m.right),
                    ];
                    for (name, r) in &all[..if slab { 2 } else { 4 }] {
                        let r = r.unwrap_or_default();
                        let s = r.select(&x, &radius);
                        if s.is_empty() {
                            return Err(config_err(
                                format!("dem.measure.{name}"),
                                format!("holds no disc ({r})"),
                            ));
                        }
                        sets.push(s);
                    }
                }
                let mean = |s: &[u32], k: usize| {
                    s.iter().map(|&p| x[p as usize][k]).sum::<f64>() / s.len() as f64
                };
                if slab {
                    height0 = mean(&sets[0], 1) - mean(&sets[1], 1);
                    offset0 = mean(&sets[0], 0) - mean(&sets[1], 0);
                    if height0 <= 0.0 {
                        return Err(config_err(
                            "dem.measure",
                            format!(
                                "the top discs must lie above the bottom ones (mean distance {height0:e} m)"
                            ),
                        ));
                    }
                } else if m.strain == StrainKind::Centres {
                    height0 = mean(&sets[0], 1) - mean(&sets[1], 1);
                    width0 = mean(&sets[3], 0) - mean(&sets[2], 0);
                    if height0 <= 0.0 || width0 <= 0.0 {
                        return Err(config_err(
                            "dem.measure",
                            format!(
                                "the top discs must lie above the bottom ones and the right ones right of the left ones (mean distances {height0:e} m, {width0:e} m)"
                            ),
                        ));
                    }
                }
                let bagi = if m.strain == StrainKind::Bagi {
                    let mut mesh = BagiMesh::new(&x).ok_or_else(|| {
                        config_err(
                            "dem.measure.strain",
                            "Bagi's strain needs a triangulation: at least three disc centres not on one line",
                        )
                    })?;
                    if m.margin > 0.0 {
                        let (lo, hi) = config::span(&x, &radius);
                        let inside = |p: u32| {
                            (0..2).all(|k| {
                                x[p as usize][k] >= lo[k] + m.margin
                                    && x[p as usize][k] <= hi[k] - m.margin
                            })
                        };
                        if !mesh.retain(inside) {
                            return Err(config_err(
                                "dem.measure.margin",
                                format!("{:e} m leaves no triangle inside the sample", m.margin),
                            ));
                        }
                    }
                    Some(mesh)
                } else {
                    None
                };
                sets.resize(4, Vec::new());
                let right = sets.pop().unwrap_or_default();
                let left = sets.pop().unwrap_or_default();
                let bottom = sets.pop().unwrap_or_default();
                let top = sets.pop().unwrap_or_default();
                Some(Measure {
                    test: m.test,
                    bagi,
                    top,
                    bottom,
                    left,
                    right,
                    height0,
                    width0,
                    offset0,
                    section: m.section.unwrap_or(1.0),
                    fit: m.fit,
                    plate: m
                        .plate
                        .as_ref()
                        .and_then(|name| cfg.walls.iter().position(|w| &w.name == name)),
                    driven: m.plate.is_some()
                        || m.strain == StrainKind::Bagi
                        || cfg.loads.iter().all(|l| l.ramp == 0.0),
                })
            }
        };
        let pool = match cfg.threads {
            Some(t) => Some(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(t)
                    .build()
                    .map_err(|e| config_err("dem.threads", e.to_string()))?,
            ),
            None => None,
        };
        let compliance = cfg
            .ddem
            .as_ref()
            .map(|d| ddem::compliance(d.youngs_modulus, d.poisson_ratio, d.plane));
        let state = State {
            step: 0,
            time: 0.0,
            x: x.clone(),
            v: vec![[0.0; 2]; n],
            theta: vec![0.0; n],
            omega: vec![0.0; n],
            pairs: Vec::new(),
            pair_state: Vec::new(),
            x_build: x.clone(),
            list_skin: cfg.skin * r_mean,
            stress: vec![[0.0; 3]; n],
            work_external: 0.0,
            load_point: vec![[0.0; 2]; loaded.len()],
            load_previous: vec![[0.0; 2]; loaded.len()],
            samples: Vec::new(),
            iterations_last: 0,
            iterations_most: 0,
            bonds_broken: 0,
            wall_shift: vec![[0.0; 2]; walls.len()],
            wall_velocity: walls
                .iter()
                .map(|w| w.velocity.unwrap_or([0.0; 2]))
                .collect(),
            wall_force: vec![[0.0; 2]; walls.len()],
            wall_state: vec![vec![PairState::default(); n]; walls.len()],
            probe_track: Vec::new(),
        };
        let mut probes = Vec::new();
        for (k, pr) in cfg.probes.iter().enumerate() {
            let discs = match (&pr.point, &pr.region) {
                (Some(point), _) => (0..n)
                    .min_by(|&a, &b| norm2(sub(x[a], *point)).total_cmp(&norm2(sub(x[b], *point))))
                    .map(|p| vec![p as u32])
                    .unwrap_or_default(),
                (None, Some(r)) => r.select(&x, &radius),
                (None, None) => Vec::new(),
            };
            if discs.is_empty() {
                return Err(config_err(
                    format!("dem.probes[{k}]"),
                    format!("`{}` reads no disc", pr.name),
                ));
            }
            probes.push((pr.name.clone(), discs));
        }
        let mut e = DiscEngine {
            cfg: cfg.clone(),
            dt: cfg.time_step,
            radius,
            mass,
            inertia,
            volume,
            x0: x,
            free,
            driven: (0..n)
                .flat_map(|p| (0..2).map(move |k| (p, k)))
                .filter(|&(p, k)| prescribed[p][k] != 0.0)
                .map(|(p, k)| (p as u32, k as u8))
                .collect(),
            prescribed,
            loads,
            loaded,
            loaded_index,
            compliance,
            measure,
            r_mean,
            r_max,
            period_lo,
            period,
            state,
            adjacency: (Vec::new(), Vec::new()),
            force: vec![[0.0; 2]; n],
            torque: vec![0.0; n],
            external: vec![[0.0; 2]; n],
            strain: vec![[0.0; 3]; n],
            stress_new: vec![[0.0; 3]; n],
            eval: Vec::new(),
            eval_walls: vec![vec![PairEval::default(); n]; walls.len()],
            wall_contacts: vec![0; walls.len()],
            wall_force_new: vec![[0.0; 2]; walls.len()],
            walls,
            initial_limits: Vec::new(),
            probes,
            pool,
            output: output::OutputState::default(),
        };
        // the first list holds every pair the bond tolerance (2.21) reaches
        let skin = e.state.list_skin;
        e.state.list_skin = skin.max(1.01 * cfg.contact.bond_gap.unwrap_or(0.0));
        e.build_list();
        e.state.list_skin = skin;
        e.check_coincident()?;
        e.check_seam()?;
        // bonds at t = 0 (2.21)
        if let Some(g) = cfg.contact.bond_gap {
            for (k, &(i, j)) in e.state.pairs.iter().enumerate() {
                let gap = e.gap(i as usize, j as usize);
                if gap <= g {
                    e.state.pair_state[k].bonded = true;
                    if cfg.contact.bond_at_rest {
                        e.state.pair_state[k].rest = -gap;
                    }
                }
            }
        }
        e.initial_limits = e.compute_limits();
        if let Some(pl) = &cfg.pulse {
            // (5.5): displaced at rest after the bonds; x0 stays the packing
            let d = scale(pl.direction, 1.0 / norm2(pl.direction));
            let along = pl.displacement.map_or(d, |u| scale(u, 1.0 / norm2(u)));
            let start = pl.start.unwrap_or_else(|| {
                let lo =
                    e.x0.iter()
                        .map(|p| dot2(*p, d))
                        .fold(f64::INFINITY, f64::min);
                scale(d, lo)
            });
            for p in 0..n {
                let xi = dot2(sub(e.x0[p], start), d);
                if (0.0..=0.5 * pl.wavelength).contains(&xi) {
                    let u = pl.amplitude
                        * 0.5
                        * (1.0 + (2.0 * std::f64::consts::PI * xi / pl.wavelength).cos());
                    e.state.x[p] = add(e.state.x[p], scale(along, u));
                }
            }
        }
        let values = e.probe_values();
        e.state.probe_track = values
            .into_iter()
            .map(|v| ProbeTrack {
                before: v,
                last: v,
                peak: v,
                peak_time: 0.0,
            })
            .collect();
        // the row of the state at t = 0
        let first = output::row(&e);
        e.output.pending.push(first);
        Ok(e)
    }

    /// Two discs at one place make no contact normal: refuse them by name.
    fn check_coincident(&self) -> Result<(), DiscError> {
        for &(i, j) in &self.state.pairs {
            let d = norm2(self.branch(i as usize, j as usize));
            if d <= 1e-9 * self.r_mean {
                return Err(config_err(
                    "dem.discs",
                    format!(
                        "discs {i} and {j} have the same centre {:?}",
                        self.state.x[i as usize]
                    ),
                ));
            }
        }
        Ok(())
    }

    /// A sample that does not fit its period overlaps its own images across the cell's sides:
    /// refuse pairs that overlap across a side by more than 5 % of the smaller radius.
    fn check_seam(&self) -> Result<(), DiscError> {
        if self.period == [0.0; 2] {
            return Ok(());
        }
        for &(i, j) in &self.state.pairs {
            let (i, j) = (i as usize, j as usize);
            let Some(d) = self.across(i, j) else {
                continue;
            };
            let direct = sub(self.state.x[j], self.state.x[i]);
            let overlap = self.radius[i] + self.radius[j] - norm2(d);
            if overlap > 0.05 * self.radius[i].min(self.radius[j]) {
                let axis = if d[0] != direct[0] { "x" } else { "y" };
                return Err(config_err(
                    format!("dem.periodic.{axis}"),
                    format!(
                        "discs {i} and {j} overlap by {overlap:e} m across the periodic side: the sample does not fit the period (its discs must repeat across it without overlapping)"
                    ),
                ));
            }
        }
        Ok(())
    }

    /// The branch vector from disc i's centre to disc j's (the nearest periodic image).
    fn branch(&self, i: usize, j: usize) -> V2 {
        image(sub(self.state.x[j], self.state.x[i]), self.period)
    }

    /// The branch vector of a pair that reaches across a periodic side (None within the cell).
    fn across(&self, i: usize, j: usize) -> Option<V2> {
        let d = self.branch(i, j);
        (d != sub(self.state.x[j], self.state.x[i])).then_some(d)
    }

    fn gap(&self, i: usize, j: usize) -> f64 {
        norm2(self.branch(i, j)) - self.radius[i] - self.radius[j]
    }

    /// Rebuilds the candidate pairs (centre distance below R_i + R_j + skin) from a cell grid,
    /// keeping the state of pairs that stay and every bonded pair.
    fn build_list(&mut self) {
        let s = &mut self.state;
        let skin = s.list_skin;
        let grid = Grid::new(2.0 * self.r_max + skin, self.period_lo, self.period);
        let len = self.period;
        let n = s.x.len();
        let mut order: Vec<(i64, i64, u32)> = (0..n)
            .map(|i| {
                let (a, b) = grid.key(s.x[i]);
                (a, b, i as u32)
            })
            .collect();
        order.sort_unstable();
        let mut pairs = Vec::new();
        for i in 0..n {
            let (a, b) = grid.key(s.x[i]);
            for da in -1..=1 {
                for db in -1..=1 {
                    // (with fewer than three cells across a period a cell comes twice: the
                    // pairs are deduplicated below)
                    let c = grid.wrap((a + da, b + db));
                    let start = order.partition_point(|o| (o.0, o.1) < c);
                    for o in &order[start..] {
                        if (o.0, o.1) != c {
                            break;
                        }
                        let j = o.2 as usize;
                        if j <= i {
                            continue;
                        }
                        let d = norm2(image(sub(s.x[j], s.x[i]), len));
                        if d < self.radius[i] + self.radius[j] + skin {
                            pairs.push((i as u32, j as u32));
                        }
                    }
                }
            }
        }
        // bonded pairs stay candidates however far they stretch
        for (k, p) in s.pairs.iter().enumerate() {
            if s.pair_state[k].bonded {
                pairs.push(*p);
            }
        }
        pairs.sort_unstable();
        pairs.dedup();
        let mut states = vec![PairState::default(); pairs.len()];
        let mut k_old = 0;
        for (k, p) in pairs.iter().enumerate() {
            while k_old < s.pairs.len() && s.pairs[k_old] < *p {
                k_old += 1;
            }
            if k_old < s.pairs.len() && s.pairs[k_old] == *p {
                states[k] = s.pair_state[k_old];
            }
        }
        s.pairs = pairs;
        s.pair_state = states;
        s.x_build = s.x.clone();
        self.build_adjacency();
    }

    /// Each disc's pairs, in the order of the list (see `adjacency`).
    fn build_adjacency(&mut self) {
        let n = self.state.x.len();
        let mut start = vec![0u32; n + 1];
        for &(i, j) in &self.state.pairs {
            start[i as usize + 1] += 1;
            start[j as usize + 1] += 1;
        }
        for p in 0..n {
            start[p + 1] += start[p];
        }
        let mut fill = start.clone();
        let mut list = vec![0u32; start[n] as usize];
        for (k, &(i, j)) in self.state.pairs.iter().enumerate() {
            for (p, side) in [(i, 0), (j, 1)] {
                list[fill[p as usize] as usize] = 2 * k as u32 + side;
                fill[p as usize] += 1;
            }
        }
        self.adjacency = (start, list);
    }

    /// The list is valid while no pair outside it can touch: 2 δ_max + 2 R_max ε_max < skin
    /// (δ: displacement since the build, ε: the particles' strains, Madan Fig. 2.4).
    fn list_still_valid(&self, strain_max: f64) -> bool {
        let s = &self.state;
        let moved =
            s.x.iter()
                .zip(&s.x_build)
                .map(|(a, b)| norm2(sub(*a, *b)))
                .fold(0.0, f64::max);
        2.0 * moved + 2.0 * self.r_max * strain_max < s.list_skin
    }

    fn ensure_list(&mut self, strain_max: f64) {
        if !self.list_still_valid(strain_max) {
            self.state.list_skin = (self.cfg.skin * self.r_mean).max(4.0 * self.r_max * strain_max);
            self.build_list();
        }
    }

    /// The strains ε̃ = D̃ σ̃ (2.47) of the stresses `stress` into `self.strain`; the largest
    /// strain norm.
    fn strains_of(&mut self, stress_new: bool) -> f64 {
        let Some(d) = self.compliance else {
            return 0.0;
        };
        let src = if stress_new {
            &self.stress_new
        } else {
            &self.state.stress
        };
        let mut most = 0.0f64;
        for (e, s) in self.strain.iter_mut().zip(src) {
            *e = ddem::mul3(&d, *s);
            most = most.max(strain_norm(*e));
        }
        most
    }

    /// The external force of each disc at time t (loads ramped, gravity).
    fn external_at(&self, t: f64, out: &mut [V2]) {
        let g = self.cfg.gravity;
        for (o, m) in out.iter_mut().zip(&self.mass) {
            *o = [m * g[0], m * g[1]];
        }
        for l in &self.loads {
            let f = scale(l.force, l.factor(t));
            for &p in &l.discs {
                out[p as usize] = add(out[p as usize], f);
            }
        }
    }

    /// The loads alone (without gravity) on disc p at time t.
    fn load_on(&self, p: usize, t: f64) -> V2 {
        let mut f = [0.0; 2];
        for l in &self.loads {
            if l.discs.binary_search(&(p as u32)).is_ok() {
                f = add(f, scale(l.force, l.factor(t)));
            }
        }
        f
    }

    /// Evaluates every candidate pair's contact with the strains in `self.strain` (zero in
    /// standard DEM) into `self.eval`, from the committed pair states (so that a fixed-point
    /// iteration can repeat it).
    fn evaluate_pairs(&mut self) {
        let mut eval = std::mem::take(&mut self.eval);
        eval.resize(self.state.pairs.len(), PairEval::default());
        let this = &*self;
        this.parallel(|| {
            eval.par_iter_mut()
                .with_min_len(PAR_MIN)
                .enumerate()
                .for_each(|(k, e)| *e = this.pair_eval(k));
        });
        self.eval = eval;
        self.evaluate_walls();
    }

    /// Runs `f` in the scene's thread pool (`dem.threads`), or rayon's global one.
    fn parallel<R: Send>(&self, f: impl FnOnce() -> R + Send) -> R {
        match &self.pool {
            Some(p) => p.install(f),
            None => f(),
        }
    }

    /// A probe's reading: its mean displacement along the pulse's displacement, or its length.
    fn probe_values(&self) -> Vec<f64> {
        // along the pulse's displacement, signed so the pulse itself is a peak
        let along = self.cfg.pulse.as_ref().map(|pl| {
            let u = pl.displacement.unwrap_or(pl.direction);
            scale(u, pl.amplitude.signum() / norm2(u))
        });
        self.probes
            .iter()
            .map(|(_, discs)| {
                let u = self.probe_mean(discs).1;
                along.map_or(norm2(u), |a| dot2(u, a))
            })
            .collect()
    }

    /// The probes' peaks: a reading below the last one that was above the one before makes
    /// the last one a local maximum; the largest so far is the wave's arrival.
    fn track_probes(&mut self) {
        if self.probes.is_empty() {
            return;
        }
        let values = self.probe_values();
        let t = self.state.time;
        for (tr, r) in self.state.probe_track.iter_mut().zip(values) {
            if tr.last > tr.before && tr.last >= r && tr.last > tr.peak {
                let curve = tr.before - 2.0 * tr.last + r;
                let shift = if curve < 0.0 {
                    0.5 * (tr.before - r) / curve
                } else {
                    0.0
                };
                tr.peak = tr.last;
                // the last reading was at t − Δt; the parabola's top lies `shift` steps on
                tr.peak_time = t - self.dt * (1.0 - shift);
            }
            tr.before = tr.last;
            tr.last = r;
        }
    }

    /// The speed of a wave past the probes: the least-squares slope of their positions along
    /// the pulse's direction over their peak times (probes that peaked after t = 0; at least
    /// two, at different places), and the fit's coefficient of determination r² (near 1: one
    /// pulse running past the probes at one speed; far from it: no coherent wave).
    pub fn wave_speed(&self) -> Option<(f64, f64)> {
        let pl = self.cfg.pulse.as_ref()?;
        let d = scale(pl.direction, 1.0 / norm2(pl.direction));
        let pts: Vec<(f64, f64)> = self
            .probes
            .iter()
            .zip(&self.state.probe_track)
            .filter(|(_, tr)| tr.peak_time > 0.0)
            .map(|((_, discs), tr)| (tr.peak_time, dot2(self.probe_mean(discs).0, d)))
            .collect();
        let (c, r2) = line_fit(&pts);
        (pts.len() >= 2 && c.is_finite() && r2.is_finite()).then_some((c, r2))
    }

    /// Each probe's name, its discs' mean centre in the packing and their mean displacement
    /// from it.
    pub fn probe_readings(&self) -> Vec<(String, V2, V2)> {
        self.probes
            .iter()
            .map(|(name, discs)| {
                let (at, u) = self.probe_mean(discs);
                (name.clone(), at, u)
            })
            .collect()
    }

    /// The discs' mean centre in the packing and their mean displacement from it.
    fn probe_mean(&self, discs: &[u32]) -> (V2, V2) {
        let mut at = [0.0; 2];
        let mut u = [0.0; 2];
        for &p in discs {
            let p = p as usize;
            at = add(at, self.x0[p]);
            u = add(u, sub(self.state.x[p], self.x0[p]));
        }
        let w = 1.0 / discs.len() as f64;
        (scale(at, w), scale(u, w))
    }

    /// Pair k's contact of this evaluation (a pure function of the state: the same for any
    /// thread count).
    fn pair_eval(&self, k: usize) -> PairEval {
        let c = &self.cfg.contact;
        let ddem = self.compliance.is_some();
        let dt = self.dt;
        let s = &self.state;
        let (i, j) = s.pairs[k];
        let (i, j) = (i as usize, j as usize);
        {
            let old = s.pair_state[k];
            let d = self.branch(i, j);
            let dist = norm2(d);
            let n = scale(d, 1.0 / dist);
            let (ri, rj) = (self.radius[i], self.radius[j]);
            // h_c = h + u_c^i·n_c^i + u_c^j·n_c^j (2.53), u_c = ε s (2.50), s_i = R_i n,
            // s_j = −R_j n, n_c^i = n, n_c^j = −n
            let mut overlap = ri + rj - dist;
            if ddem {
                overlap += dot2(strain_times(self.strain[i], scale(n, ri)), n)
                    + dot2(strain_times(self.strain[j], scale(n, rj)), n);
            }
            let mut e = PairEval {
                n,
                ..Default::default()
            };
            e.state.bonded = old.bonded;
            e.state.overlap = overlap;
            if !(old.bonded || overlap > 0.0) {
                // apart: no force, the tangential spring relaxes
                return e;
            }
            let t = [-n[1], n[0]];
            // relative velocity of j's contact point to i's: (v_j + ω_j ẑ × s_j) − (v_i + ω_i ẑ × s_i)
            let vr = sub(s.v[j], s.v[i]);
            let v_n = dot2(vr, n);
            let v_t = dot2(vr, t) - s.omega[j] * rj - s.omega[i] * ri;
            let (mi, mj) = (self.mass[i], self.mass[j]);
            let (state, broke) = contact_law(c, dt, mi * mj / (mi + mj), overlap, v_n, v_t, &old);
            e.state = state;
            e.broke = broke;
            e
        }
    }

    /// The discs' contacts with the walls (the pairs' law, without bonds): the wall is the
    /// first body, its normal n points to the disc, the disc's contact point is s = −R n.
    fn evaluate_walls(&mut self) {
        let mut evals = std::mem::take(&mut self.eval_walls);
        let this = &*self;
        for (w, ev) in evals.iter_mut().enumerate() {
            this.parallel(|| {
                ev.par_iter_mut()
                    .with_min_len(PAR_MIN)
                    .enumerate()
                    .for_each(|(p, e)| *e = this.wall_eval(w, p));
            });
        }
        self.eval_walls = evals;
    }

    /// Disc p's contact with wall w in this evaluation.
    fn wall_eval(&self, w: usize, p: usize) -> PairEval {
        let c = &self.cfg.contact;
        let dt = self.dt;
        let s = &self.state;
        let wall = &self.walls[w];
        let n = wall.normal;
        let t = [-n[1], n[0]];
        let origin = add(wall.point, s.wall_shift[w]);
        let vw = s.wall_velocity[w];
        let r = self.radius[p];
        let mut overlap = r - dot2(sub(s.x[p], origin), n);
        if self.compliance.is_some() {
            overlap += dot2(strain_times(self.strain[p], scale(n, r)), n);
        }
        let mut e = PairEval {
            n,
            ..Default::default()
        };
        e.state.overlap = overlap;
        if overlap <= 0.0 {
            return e;
        }
        let old = s.wall_state[w][p];
        let vr = sub(s.v[p], vw);
        let v_n = dot2(vr, n);
        let v_t = dot2(vr, t) - s.omega[p] * r;
        e.state = contact_law(c, dt, self.mass[p], overlap, v_n, v_t, &old).0;
        e
    }

    /// Sums the evaluated contact forces, the external forces at `t` and the constraint
    /// reactions into `self.force` / `self.torque`, and the particle stresses (2.41)–(2.45)
    /// into `self.stress_new`.
    fn assemble(&mut self) {
        // the walls' totals (the force the discs exert on each, in disc order)
        for w in 0..self.walls.len() {
            let mut on_wall = [0.0; 2];
            self.wall_contacts[w] = 0;
            for e in &self.eval_walls[w] {
                if e.state.active {
                    self.wall_contacts[w] += 1;
                    let nw = e.n;
                    let t = [-nw[1], nw[0]];
                    on_wall = sub(
                        on_wall,
                        add(scale(nw, e.state.fn_total), scale(t, e.state.ft_total)),
                    );
                }
            }
            self.wall_force_new[w] = on_wall;
        }
        // each disc gathers its contacts in the list's order: the same sums on any thread
        // count (and as a scatter over the pairs would give)
        let mut force = std::mem::take(&mut self.force);
        let mut torque = std::mem::take(&mut self.torque);
        let mut stress = std::mem::take(&mut self.stress_new);
        let this = &*self;
        this.parallel(|| {
            force
                .par_iter_mut()
                .zip(torque.par_iter_mut())
                .zip(stress.par_iter_mut())
                .with_min_len(PAR_MIN)
                .enumerate()
                .for_each(|(p, ((f, m), st))| this.gather(p, f, m, st));
        });
        self.force = force;
        self.torque = torque;
        self.stress_new = stress;
    }

    /// Disc p's force, moment and particle stress σ̃ (2.41)–(2.46) from its contacts, walls,
    /// load and the reactions of its held coordinates.
    fn gather(&self, p: usize, force: &mut V2, torque: &mut f64, stress: &mut [f64; 3]) {
        let r = self.radius[p];
        let mut f_sum = self.external[p];
        let mut m_sum = 0.0;
        let mut st = [0.0; 3];
        let (start, list) = &self.adjacency;
        for &code in &list[start[p] as usize..start[p + 1] as usize] {
            let e = &self.eval[(code / 2) as usize];
            if !e.state.active {
                continue;
            }
            let n_ = e.n;
            let t = [-n_[1], n_[0]];
            let fj = add(scale(n_, e.state.fn_total), scale(t, e.state.ft_total));
            // moments s × f with s_i = R_i n, s_j = −R_j n: both −R f_t
            m_sum -= r * e.state.ft_total;
            if code % 2 == 0 {
                let fi = scale(fj, -1.0);
                f_sum = add(f_sum, fi);
                add_stress(&mut st, scale(n_, r), fi);
            } else {
                f_sum = add(f_sum, fj);
                add_stress(&mut st, scale(n_, -r), fj);
            }
        }
        for evals in &self.eval_walls {
            let e = &evals[p];
            if !e.state.active {
                continue;
            }
            let nw = e.n;
            let t = [-nw[1], nw[0]];
            let f = add(scale(nw, e.state.fn_total), scale(t, e.state.ft_total));
            f_sum = add(f_sum, f);
            m_sum -= r * e.state.ft_total;
            add_stress(&mut st, scale(nw, -r), f);
        }
        // loads act at the point opposite their direction, s = −R F̂ (pushing on the surface),
        // as do the reactions of fixed coordinates: end discs then deform as interior ones do
        let load = if self.loaded_index[p] != u32::MAX {
            self.load_on(p, self.state.time)
        } else {
            [0.0; 2]
        };
        let reaction: V2 = std::array::from_fn(|k| if self.free[p][k] { 0.0 } else { -f_sum[k] });
        for f in [load, reaction] {
            let size = norm2(f);
            if size > 0.0 {
                add_stress(&mut st, scale(f, -r / size), f);
            }
        }
        let v = self.volume[p];
        *force = f_sum;
        *torque = m_sum;
        *stress = st.map(|c| c / v);
    }

    /// One step of Δt.
    pub fn step(&mut self) -> Result<(), DiscError> {
        let t = self.state.time;
        let mut ext = std::mem::take(&mut self.external);
        self.external_at(t, &mut ext);
        self.external = ext;
        let scheme = self.cfg.ddem.as_ref().map(|d| d.scheme);
        // strains from the last step's stresses (the lagged scheme; the fixed point's start)
        let strain_max = self.strains_of(false);
        self.check_strain(strain_max)?;
        self.ensure_list(strain_max);
        self.evaluate_pairs();
        self.assemble();
        if scheme == Some(Scheme::FixedPoint) {
            self.fixed_point()?;
        }
        // commit the pairs
        for (k, e) in self.eval.iter().enumerate() {
            if e.broke {
                self.state.bonds_broken += 1;
            }
            self.state.pair_state[k] = e.state;
        }
        for (w, evals) in self.eval_walls.iter().enumerate() {
            for (st, e) in self.state.wall_state[w].iter_mut().zip(evals) {
                *st = e.state;
            }
        }
        self.state.wall_force.copy_from_slice(&self.wall_force_new);
        std::mem::swap(&mut self.state.stress, &mut self.stress_new);
        self.account_work();
        self.record_measure();
        self.integrate();
        self.move_walls();
        self.account_gravity();
        self.state.step += 1;
        self.state.time = self.state.step as f64 * self.dt;
        self.check_finite()?;
        self.track_probes();
        if self.state.step % self.cfg.output.csv_every == 0 {
            let row = output::row(self);
            self.output.pending.push(row);
        }
        Ok(())
    }

    /// Repeats evaluate → stresses → strains until the normal forces change by less than the
    /// tolerance (3.5)–(3.7); the last evaluation stays in `self.eval`, its stresses in
    /// `self.stress_new`.
    fn fixed_point(&mut self) -> Result<(), DiscError> {
        let (tol, most) = self
            .cfg
            .ddem
            .as_ref()
            .map(|d| (d.tolerance, d.max_iterations))
            .unwrap_or((1e-12, 1));
        let mut previous: Vec<f64> = self.eval.iter().map(|e| e.state.fn_elastic).collect();
        for it in 1..=most {
            let strain_max = self.strains_of(true);
            self.check_strain(strain_max)?;
            if !self.list_still_valid(strain_max) {
                // the deformation outgrew the list: rebuild and start the iteration over
                self.ensure_list(strain_max);
                self.evaluate_pairs();
                self.assemble();
                previous = self.eval.iter().map(|e| e.state.fn_elastic).collect();
                continue;
            }
            self.evaluate_pairs();
            self.assemble();
            let mut change = 0.0f64;
            let mut size = 0.0f64;
            for (e, p) in self.eval.iter().zip(&mut previous) {
                change = change.max((e.state.fn_elastic - *p).abs());
                size = size.max(e.state.fn_elastic.abs());
                *p = e.state.fn_elastic;
            }
            if change <= tol * size || size == 0.0 {
                self.state.iterations_last = it as u32;
                self.state.iterations_most = self.state.iterations_most.max(it as u32);
                return Ok(());
            }
        }
        let rho = self.limit("ddem_spectral_radius");
        Err(DiscError::Unstable {
            time: self.state.time,
            step: self.state.step,
            message: format!(
                "the DDEM fixed-point iteration did not converge in {most} iterations \
                 (dem.ddem.max_iterations); it converges only for ρ(B) < 1 and the initial \
                 packing has ρ(B) = {rho:.4} (Madan (3.13)–(3.14)): raise dem.ddem.youngs_modulus \
                 or lower dem.contact.normal_stiffness"
            ),
        })
    }

    fn check_strain(&self, strain_max: f64) -> Result<(), DiscError> {
        if strain_max.is_finite() && strain_max <= STRAIN_LIMIT {
            return Ok(());
        }
        let (p, e) = self
            .strain
            .iter()
            .enumerate()
            .map(|(p, e)| (p, strain_norm(*e)))
            .fold(
                (0, 0.0),
                |a, b| if b.1 > a.1 || b.1.is_nan() { b } else { a },
            );
        let rho = self.limit("ddem_spectral_radius");
        Err(DiscError::Unstable {
            time: self.state.time,
            step: self.state.step,
            message: format!(
                "disc {p} at {:?} takes a strain of {e:.3e}, beyond the small strains of the \
                 DDEM ({STRAIN_LIMIT}): the lagged scheme diverges; the initial packing has \
                 ρ(B) = {rho:.4} (stable only below 1, Madan (3.13)) and Δt/Δt_cr = {:.4}",
                self.state.x[p],
                self.dt / self.limit("critical_time_step")
            ),
        })
    }

    fn check_finite(&self) -> Result<(), DiscError> {
        let s = &self.state;
        for p in 0..s.x.len() {
            if !(s.x[p][0].is_finite()
                && s.x[p][1].is_finite()
                && s.v[p][0].is_finite()
                && s.v[p][1].is_finite()
                && s.omega[p].is_finite())
            {
                return Err(DiscError::Unstable {
                    time: s.time,
                    step: s.step,
                    message: format!(
                        "disc {p} has a non-finite position or velocity; Δt = {:e} s, critical \
                         step {:e} s",
                        self.dt,
                        self.limit("critical_time_step")
                    ),
                });
            }
        }
        for (k, &(i, j)) in s.pairs.iter().enumerate() {
            let h = s.pair_state[k].overlap;
            let r = self.radius[i as usize].min(self.radius[j as usize]);
            if h > r {
                return Err(DiscError::Unstable {
                    time: s.time,
                    step: s.step,
                    message: format!(
                        "discs {i} and {j} overlap by {h:.3e} m, more than the smaller radius \
                         {r:.3e} m: the contacts are too soft for the loads, or the run is \
                         unstable (Δt = {:e} s, critical step {:e} s)",
                        self.dt,
                        self.limit("critical_time_step")
                    ),
                });
            }
        }
        Ok(())
    }

    /// Central differences (2.9)–(2.13) with the non-viscous background damping (2.7)–(2.8).
    fn integrate(&mut self) {
        let dt = self.dt;
        let (at, ar) = (self.cfg.damping.translational, self.cfg.damping.rotational);
        // the moving parts out of the state, so that the rest can be read meanwhile
        let st = &mut self.state;
        let (mut xs, mut vs) = (std::mem::take(&mut st.x), std::mem::take(&mut st.v));
        let (mut thetas, mut omegas) =
            (std::mem::take(&mut st.theta), std::mem::take(&mut st.omega));
        let this = &*self;
        this.parallel(|| {
            xs.par_iter_mut()
                .zip(vs.par_iter_mut())
                .zip(thetas.par_iter_mut().zip(omegas.par_iter_mut()))
                .with_min_len(PAR_MIN)
                .enumerate()
                .for_each(|(p, ((x, v), (theta, omega)))| {
                    let mut f = this.force[p];
                    let mut tq = this.torque[p];
                    if at > 0.0 {
                        // over the free coordinates only: a held or driven coordinate's force
                        // is cancelled by its reaction, its velocity prescribed
                        let free = this.free[p];
                        let fm = [f[0] * free[0] as u8 as f64, f[1] * free[1] as u8 as f64];
                        let vm = [v[0] * free[0] as u8 as f64, v[1] * free[1] as u8 as f64];
                        let speed = norm2(vm);
                        if speed > 0.0 {
                            f = sub(f, scale(vm, at * norm2(fm) / speed));
                        }
                    }
                    if ar > 0.0 && *omega != 0.0 {
                        tq -= ar * tq.abs() * omega.signum();
                    }
                    for (k, fk) in f.iter().enumerate() {
                        if this.free[p][k] {
                            v[k] += dt * fk / this.mass[p];
                        } else {
                            v[k] = this.prescribed[p][k];
                        }
                        x[k] += dt * v[k];
                    }
                    if this.free[p][2] {
                        *omega += dt * tq / this.inertia[p];
                        *theta += dt * *omega;
                    } else {
                        *omega = 0.0;
                    }
                });
        });
        self.state.x = xs;
        self.state.v = vs;
        self.state.theta = thetas;
        self.state.omega = omegas;
    }

    /// The work of the loads at their points of application (the centre's displacement plus
    /// the particle's own ε s there, s = −R F̂) and of gravity at the centres, by the
    /// trapezoidal rule over the step just evaluated.
    fn account_work(&mut self) {
        let t = self.state.time;
        let d = self.compliance;
        for (k, &p) in self.loaded.iter().enumerate() {
            let p = p as usize;
            let f = self.load_on(p, t);
            let size = norm2(f);
            let mut u = sub(self.state.x[p], self.x0[p]);
            if let (Some(d), true) = (d, size > 0.0) {
                let e = ddem::mul3(&d, self.state.stress[p]);
                u = add(u, strain_times(e, scale(f, -self.radius[p] / size)));
            }
            let mid = scale(add(f, self.state.load_previous[k]), 0.5);
            self.state.work_external += dot2(mid, sub(u, self.state.load_point[k]));
            self.state.load_point[k] = u;
            self.state.load_previous[k] = f;
        }
        // the reactions of coordinates driven at a prescribed velocity, R = −F over the
        // step's move v Δt
        for &(p, k) in &self.driven {
            let (p, k) = (p as usize, k as usize);
            self.state.work_external -= self.force[p][k] * self.prescribed[p][k] * self.dt;
        }
    }

    /// Walls: a prescribed velocity until `stop`, or a servo to the target pressure (the
    /// wall advances into the sample at up to `max_speed` while the discs' normal stress on it
    /// is below the target, backs off while above).
    fn move_walls(&mut self) {
        let t = self.state.time;
        for (w, wall) in self.walls.iter().enumerate() {
            let stopped = wall.stop.is_some_and(|s| t >= s);
            let v = if stopped {
                [0.0; 2]
            } else if let Some((pressure, length, speed, gain)) = wall.servo {
                // v = g (F_target − F)/(Δt k_w), k_w = k_n × the wall's contacts: the force
                // closes the fraction g of its error per step (default 0.2: a larger gain
                // against the stiff contacts oscillates), at most `max_speed` while approaching
                let push = -dot2(self.state.wall_force[w], wall.normal);
                let target = pressure * length * self.cfg.depth;
                let k_w = self.cfg.contact.normal_stiffness * self.wall_contacts[w].max(1) as f64;
                let v = (gain * (target - push) / (self.dt * k_w)).clamp(-speed, speed);
                scale(wall.normal, v)
            } else {
                wall.velocity.unwrap_or([0.0; 2])
            };
            self.state.wall_velocity[w] = v;
            self.state.wall_shift[w] = add(self.state.wall_shift[w], scale(v, self.dt));
            // the work the wall does on the discs (they push it with wall_force)
            self.state.work_external -= dot2(self.state.wall_force[w], scale(v, self.dt));
        }
    }

    /// The normal force (N, pushing on it positive) and displacement along its normal (m) of
    /// each wall.
    pub fn wall_readings(&self) -> Vec<(String, f64, f64)> {
        self.walls
            .iter()
            .enumerate()
            .map(|(w, wall)| {
                (
                    wall.name.clone(),
                    -dot2(self.state.wall_force[w], wall.normal),
                    dot2(self.state.wall_shift[w], wall.normal),
                )
            })
            .collect()
    }

    /// Gravity's work over the step just integrated: Σ m g · Δt v^{n+½}.
    fn account_gravity(&mut self) {
        let g = self.cfg.gravity;
        if g != [0.0, 0.0] {
            let s = &self.state;
            let w: f64 = (0..s.x.len())
                .map(|p| self.mass[p] * self.dt * dot2(g, s.v[p]))
                .sum();
            self.state.work_external += w;
        }
    }

    /// The measurement (σ_xx, σ_yy, σ_xy, ε_xx, ε_yy, ε_xy): with the centres' strain (M
    /// (4.19)–(4.22)) the stress σ_yy of the top load over the section (the others zero) and
    /// the strains of the distances between the mean centres of the measured sets; with Bagi's
    /// strain the macroscopic stress (4.3) and strain (4.4)–(4.6).
    pub fn measurement(&self) -> Option<[f64; 6]> {
        let m = self.measure.as_ref()?;
        let s = &self.state;
        if let Some(mesh) = &m.bagi {
            let u: Vec<V2> = s.x.iter().zip(&self.x0).map(|(a, b)| sub(*a, *b)).collect();
            let e = mesh.strain(&u);
            let st = self.macroscopic_stress();
            return Some([st[0], st[1], st[2], e[0], e[1], e[2]]);
        }
        let mean = |set: &[u32], k: usize| {
            set.iter().map(|&p| s.x[p as usize][k]).sum::<f64>() / set.len() as f64
        };
        if m.bagi.is_none() && m.test == TestKind::Shear {
            // γ = 2ε_xy: the top's shift against the bottom over their distance
            let gamma = (mean(&m.top, 0) - mean(&m.bottom, 0) - m.offset0) / m.height0;
            let st = self.macroscopic_stress();
            return Some([st[0], st[1], st[2], 0.0, 0.0, 0.5 * gamma]);
        }
        let load: f64 = match m.plate {
            // the plate's push, compressive: a negative stress as from loads pressing down
            Some(w) => dot2(s.wall_force[w], self.walls[w].normal),
            None => m
                .top
                .iter()
                .map(|&p| self.load_on(p as usize, s.time)[1])
                .sum(),
        };
        let sigma = load / (m.section * self.cfg.depth);
        let eyy = (mean(&m.top, 1) - mean(&m.bottom, 1)) / m.height0 - 1.0;
        let exx = (mean(&m.right, 0) - mean(&m.left, 0)) / m.width0 - 1.0;
        Some([0.0, sigma, 0.0, exx, eyy, 0.0])
    }

    fn record_measure(&mut self) {
        let Some(m) = self.measure.as_ref() else {
            return;
        };
        let (test, driven) = (m.test, m.driven);
        if driven {
            // a plate or prescribed motion: the whole history, every csv_every steps
            if self.state.step % self.cfg.output.csv_every != 0 {
                return;
            }
            let Some(v) = self.measurement() else {
                return;
            };
            let size = match test {
                TestKind::Uniaxial => v[1].abs(),
                TestKind::Biaxial => (0.5 * (v[0] + v[1])).abs(),
                TestKind::Shear => v[2].abs(),
            };
            self.state
                .samples
                .push([v[0], v[1], v[2], v[3], v[4], v[5], size]);
            return;
        }
        // while any load still rises
        let t = self.state.time;
        if self.loads.iter().any(|l| l.ramp > 0.0 && t <= l.ramp) {
            let Some(v) = self.measurement() else {
                return;
            };
            let fraction = self.loads.iter().map(|l| l.factor(t)).fold(0.0, f64::max);
            self.state
                .samples
                .push([v[0], v[1], v[2], v[3], v[4], v[5], fraction]);
        }
    }

    /// The moduli of the test by least squares over the load fractions of `measure.fit`:
    /// uniaxial E = Δσ_yy/Δε_yy and ν = −Δε_xx/Δε_yy (M (4.19)–(4.22), (4.31)), biaxial K =
    /// Δσ_h/Δε_vol (4.33)–(4.35), shear G = Δσ_xy/(2Δε_xy) (4.36). A driven test takes
    /// fractions of the peak stress on the loading branch (M §4.5: 0.2–0.5 of the peak).
    pub fn moduli(&self) -> Vec<(String, f64)> {
        let Some(m) = self.measure.as_ref() else {
            return Vec::new();
        };
        let samples = &self.state.samples;
        if samples.is_empty() {
            return Vec::new();
        }
        let pts: Vec<&[f64; 7]> = if m.driven {
            let (peak_at, peak) = samples.iter().enumerate().fold((0, 0.0f64), |a, (k, s)| {
                if s[6] > a.1 {
                    (k, s[6])
                } else {
                    a
                }
            });
            samples[..=peak_at.min(samples.len().saturating_sub(1))]
                .iter()
                .filter(|s| s[6] >= m.fit[0] * peak && s[6] <= m.fit[1] * peak)
                .collect()
        } else {
            samples
                .iter()
                .filter(|s| s[6] >= m.fit[0] && s[6] <= m.fit[1])
                .collect()
        };
        if pts.len() < 3 {
            return Vec::new();
        }
        let slope = |xs: &dyn Fn(&[f64; 7]) -> f64, ys: &dyn Fn(&[f64; 7]) -> f64| {
            let xy: Vec<(f64, f64)> = pts.iter().map(|p| (xs(p), ys(p))).collect();
            line_fit(&xy).0
        };
        match m.test {
            TestKind::Uniaxial => vec![
                ("youngs_modulus".to_string(), slope(&|p| p[4], &|p| p[1])),
                ("poisson_ratio".to_string(), -slope(&|p| p[4], &|p| p[3])),
            ],
            TestKind::Biaxial => vec![(
                "bulk_modulus".to_string(),
                slope(&|p| p[3] + p[4], &|p| 0.5 * (p[0] + p[1])),
            )],
            TestKind::Shear => vec![(
                "shear_modulus".to_string(),
                slope(&|p| 2.0 * p[5], &|p| p[2]),
            )],
        }
    }

    /// Advances `steps` steps.
    pub fn advance(&mut self, steps: u64) -> Result<(), DiscError> {
        for _ in 0..steps {
            self.step()?;
        }
        Ok(())
    }

    pub fn time(&self) -> f64 {
        self.state.time
    }
    pub fn time_step(&self) -> f64 {
        self.dt
    }
    pub fn steps(&self) -> u64 {
        self.state.step
    }
    pub fn num_discs(&self) -> usize {
        self.state.x.len()
    }
    pub fn positions(&self) -> &[V2] {
        &self.state.x
    }
    pub fn initial_positions(&self) -> &[V2] {
        &self.x0
    }
    pub fn radii(&self) -> &[f64] {
        &self.radius
    }
    /// σ̃ of each disc from the last force evaluation.
    pub fn stresses(&self) -> &[[f64; 3]] {
        &self.state.stress
    }
    /// ε̃ = D̃ σ̃ of each disc (zero in standard DEM).
    pub fn strains(&self) -> Vec<[f64; 3]> {
        match self.compliance {
            Some(d) => self
                .state
                .stress
                .iter()
                .map(|s| ddem::mul3(&d, *s))
                .collect(),
            None => vec![[0.0; 3]; self.state.x.len()],
        }
    }
    /// The candidate pairs and their contact state.
    pub fn pairs(&self) -> impl Iterator<Item = ((u32, u32), &PairState)> {
        self.state.pairs.iter().copied().zip(&self.state.pair_state)
    }
    /// The elastic normal force of the pair (i, j) (compression positive), if a candidate.
    pub fn normal_force(&self, i: u32, j: u32) -> Option<f64> {
        let key = (i.min(j), i.max(j));
        let k = self.state.pairs.binary_search(&key).ok()?;
        Some(self.state.pair_state[k].fn_elastic)
    }
    /// Fixed-point iterations of the last step and the most of any step.
    pub fn iterations(&self) -> (u32, u32) {
        (self.state.iterations_last, self.state.iterations_most)
    }

    /// E_k = Σ ½ m v² + ½ J ω² (2.58), at the half-step velocities.
    pub fn kinetic_energy(&self) -> f64 {
        let s = &self.state;
        (0..s.x.len())
            .map(|p| {
                0.5 * self.mass[p] * dot2(s.v[p], s.v[p])
                    + 0.5 * self.inertia[p] * s.omega[p].powi(2)
            })
            .sum()
    }

    /// E_el,c = Σ f_ne²/(2k_n) + f_te²/(2k_t) (2.59, with the ½ the print lacks).
    pub fn contact_energy(&self) -> f64 {
        let c = &self.cfg.contact;
        self.state
            .pair_state
            .iter()
            .filter(|p| p.active)
            .map(|p| {
                let mut e = p.fn_elastic.powi(2) / (2.0 * c.normal_stiffness);
                if c.tangential_stiffness > 0.0 {
                    e += p.ft_elastic.powi(2) / (2.0 * c.tangential_stiffness);
                }
                e
            })
            .sum()
    }

    /// E_el,p = ½ Σ V_p σ_p : ε_p (2.61) (σ:ε = σ̃ · ε̃ with ε̃_3 = 2ε_xy).
    pub fn particle_energy(&self) -> f64 {
        let Some(d) = self.compliance else {
            return 0.0;
        };
        self.state
            .stress
            .iter()
            .zip(&self.volume)
            .map(|(s, v)| {
                let e = ddem::mul3(&d, *s);
                0.5 * v * (s[0] * e[0] + s[1] * e[1] + s[2] * e[2])
            })
            .sum()
    }

    /// W_ext: the work of the loads (at their points) and of gravity so far (2.55).
    pub fn external_work(&self) -> f64 {
        self.state.work_external
    }

    /// The macroscopic stress σ̄ = (1/V) Σ_p V_p σ_p (4.1)–(4.3) over the box the discs span
    /// (along a periodic axis: the period).
    pub fn macroscopic_stress(&self) -> [f64; 3] {
        let s = &self.state;
        let mut sum = [0.0; 3];
        for p in 0..s.x.len() {
            for (sk, st) in sum.iter_mut().zip(s.stress[p]) {
                *sk += self.volume[p] * st;
            }
        }
        let v = self.sample_area();
        sum.map(|c| c / v)
    }

    /// The sample's volume: the box the discs span (along a periodic axis: the period) times
    /// the depth.
    fn sample_area(&self) -> f64 {
        let (lo, hi) = config::span(&self.state.x, &self.radius);
        let side = |k: usize| {
            if self.period[k] > 0.0 {
                self.period[k]
            } else {
                hi[k] - lo[k]
            }
        };
        side(0) * side(1) * self.cfg.depth
    }

    /// The limits of the scene, for the coordinator's checks: `time_step`,
    /// `critical_time_step` (2/ν_max of the initial contacts, (2.14)–(2.16)), and in DDEM
    /// `ddem_spectral_radius` ρ(B) of the initial packing's iteration matrix (3.8),
    /// `ddem_kn_over_ep`, `ddem_poisson_ratio` and `ddem_kn_over_ep_limit` (k_n/E_p at which
    /// ρ(B) = 1 for this packing).
    pub fn limits(&self) -> Vec<(String, f64)> {
        self.initial_limits.clone()
    }

    fn limit(&self, name: &str) -> f64 {
        self.initial_limits
            .iter()
            .find(|(k, _)| k == name)
            .map_or(f64::NAN, |(_, v)| *v)
    }

    /// The pairs touching (gap ≤ 1e-6 R̄) or bonded now.
    fn touching(&self) -> Vec<(usize, usize)> {
        let tol = 1e-6 * self.r_mean;
        self.state
            .pairs
            .iter()
            .zip(&self.state.pair_state)
            .filter(|((i, j), st)| st.bonded || self.gap(*i as usize, *j as usize) <= tol)
            .map(|((i, j), _)| (*i as usize, *j as usize))
            .collect()
    }

    fn compute_limits(&self) -> Vec<(String, f64)> {
        let c = &self.cfg.contact;
        let mut l = vec![
            ("time_step".to_string(), self.dt),
            ("discs".to_string(), self.num_discs() as f64),
        ];
        let touching = self.touching();
        let s = &self.state;
        let springs: Vec<ddem::Spring> = touching
            .iter()
            .map(|&(i, j)| {
                let d = self.branch(i, j);
                let n = scale(d, 1.0 / norm2(d));
                ddem::Spring {
                    i,
                    j,
                    n,
                    si: scale(n, self.radius[i]),
                    sj: scale(n, -self.radius[j]),
                }
            })
            .collect();
        // the walls touching at t = 0: springs to a fixed ground body (index n)
        let ground = self.num_discs();
        let tol = 1e-6 * self.r_mean;
        let mut wall_contacts = Vec::new();
        for (w, wall) in self.walls.iter().enumerate() {
            let origin = add(wall.point, s.wall_shift[w]);
            for p in 0..ground {
                let gap = dot2(sub(s.x[p], origin), wall.normal) - self.radius[p];
                if gap <= tol {
                    wall_contacts.push((p, wall.normal));
                }
            }
        }
        let mut springs = springs;
        springs.extend(wall_contacts.iter().map(|&(p, nw)| ddem::Spring {
            i: p,
            j: ground,
            n: scale(nw, -1.0),
            si: scale(nw, -self.radius[p]),
            sj: [0.0; 2],
        }));
        let mut free: Vec<bool> = self.free.iter().flatten().copied().collect();
        free.extend([false; 3]);
        let mut mass = self.mass.clone();
        mass.push(1.0);
        let mut inertia = self.inertia.clone();
        inertia.push(1.0);
        let critical = ddem::critical_time_step(
            &springs,
            &mass,
            &inertia,
            &free,
            c.normal_stiffness,
            c.tangential_stiffness,
        )
        .unwrap_or_else(|| {
            // no contact yet (or nothing free): the densest packing's value for the lightest
            // disc, 2/√6 √(m/k_n) (a disc of an infinite hexagonal lattice, normal springs)
            let m_min = self.mass.iter().copied().fold(f64::INFINITY, f64::min);
            2.0 / 6f64.sqrt() * (m_min / c.normal_stiffness).sqrt()
        });
        // viscous contact damping computed from the lagged velocities shortens it: with
        // c = ξ 2√(m_red k_n) ≈ β k_n the highest mode has ζ = β ν_max / 2 and
        // Δt_cr = (2/ν_max)(√(1 + ζ²) − ζ) (β the largest over the discs' pairs)
        // (the highest modes live on the lightest discs: β of the lightest disc's contact with
        // the heaviest, m/2 for equal discs)
        let m_max = self.mass.iter().copied().fold(0.0, f64::max);
        let m_min = self.mass.iter().copied().fold(f64::INFINITY, f64::min);
        let m_red = m_min * m_max / (m_min + m_max);
        let beta = c.normal_damping * 2.0 * (m_red / c.normal_stiffness).sqrt();
        let zeta = beta * (2.0 / critical) / 2.0;
        // the non-viscous damping (2.7)–(2.8) scales the force by 1 ± α (1 + α while it opposes
        // the velocity): a stiffer oscillator over half a cycle, Δt_cr / √(1 + α). The
        // irregular 4979-disc sample with α = 0.2 (M §4.5) runs stable at 0.925 of the
        // undamped step and diverges at 0.93 (the bound: 0.913)
        let alpha = self
            .cfg
            .damping
            .translational
            .max(self.cfg.damping.rotational);
        let damped = critical * ((1.0 + zeta * zeta).sqrt() - zeta) / (1.0 + alpha).sqrt();
        l.push(("critical_time_step".to_string(), damped));
        l.push(("critical_time_step_undamped".to_string(), critical));
        l.push(("contacts_initial".to_string(), touching.len() as f64));
        // the mean coordination number and the Voigt (uniform strain) estimates of the 2-D
        // moduli of standard DEM (Madan (4.15)–(4.18)) over the box the discs span
        let n_discs = self.num_discs() as f64;
        l.push((
            "coordination_initial".to_string(),
            2.0 * touching.len() as f64 / n_discs,
        ));
        let area = self.sample_area();
        let r2 = self.radius.iter().map(|r| r * r).sum::<f64>() / n_discs;
        let (kn, kt) = (c.normal_stiffness, c.tangential_stiffness);
        let voigt = 4.0 * touching.len() as f64 * r2 * kn / area;
        l.push((
            "voigt_youngs_modulus".to_string(),
            voigt * (kn + kt) / (3.0 * kn + kt),
        ));
        l.push((
            "voigt_poisson_ratio".to_string(),
            (kn - kt) / (3.0 * kn + kt),
        ));
        // K = N_c R² k_n / V, G = N_c R² (k_n + k_t) / (2V) (4.17)–(4.18)
        l.push(("voigt_bulk_modulus".to_string(), voigt / 4.0));
        l.push((
            "voigt_shear_modulus".to_string(),
            voigt / 4.0 * (kn + kt) / (2.0 * kn),
        ));
        l.push((
            "solid_fraction_initial".to_string(),
            self.volume.iter().sum::<f64>() / area,
        ));
        l.push((
            "wall_contacts_initial".to_string(),
            wall_contacts.len() as f64,
        ));
        if let (Some(d), Some(cfgd)) = (self.compliance, &self.cfg.ddem) {
            let ends: Vec<ddem::End> = touching
                .iter()
                .enumerate()
                .flat_map(|(k, &(i, j))| {
                    let dv = self.branch(i, j);
                    let n = scale(dv, 1.0 / norm2(dv));
                    [
                        ddem::End {
                            contact: k,
                            particle: i,
                            arm: ddem::normal_arm(self.radius[i], n),
                        },
                        ddem::End {
                            contact: k,
                            particle: j,
                            arm: ddem::normal_arm(self.radius[j], n),
                        },
                    ]
                })
                .collect();
            let mut ends = ends;
            ends.extend(
                wall_contacts
                    .iter()
                    .enumerate()
                    .map(|(k, &(p, nw))| ddem::End {
                        contact: touching.len() + k,
                        particle: p,
                        arm: ddem::normal_arm(self.radius[p], nw),
                    }),
            );
            let rho = ddem::spectral_radius(
                touching.len() + wall_contacts.len(),
                &ends,
                &self.volume,
                &d,
                c.normal_stiffness,
            );
            let ratio = c.normal_stiffness / (cfgd.youngs_modulus * self.cfg.depth);
            l.push(("ddem_spectral_radius".to_string(), rho));
            l.push(("ddem_kn_over_ep".to_string(), ratio));
            l.push(("ddem_poisson_ratio".to_string(), cfgd.poisson_ratio));
            l.push(("ddem_youngs_modulus".to_string(), cfgd.youngs_modulus));
            if rho > 0.0 {
                // ρ(B) is proportional to k_n/E_p
                l.push(("ddem_kn_over_ep_limit".to_string(), ratio / rho));
            }
            // the regular lattices' analytic values (3.41), (3.76)–(3.78)
            if let [DiscSource::Lattice { arrangement, .. }] = self.cfg.discs.as_slice() {
                let (e, nu) = (cfgd.youngs_modulus, cfgd.poisson_ratio);
                let kn = c.normal_stiffness;
                let a = match arrangement {
                    config::Arrangement::Square => {
                        ddem::square_spectral_radius(kn, e, nu, self.cfg.depth)
                    }
                    config::Arrangement::Hexagonal => {
                        ddem::hexagonal_spectral_radius(kn, e, nu, self.cfg.depth)
                    }
                };
                if cfgd.plane == config::Plane::Strain {
                    l.push(("ddem_spectral_radius_lattice".to_string(), a));
                }
            }
        }
        l
    }

    /// Results at the end of a run: energies, the measurement and the fitted moduli.
    pub fn results(&self) -> Vec<(String, f64)> {
        let mut r = vec![
            ("time".to_string(), self.time()),
            ("steps".to_string(), self.steps() as f64),
            ("kinetic_energy".to_string(), self.kinetic_energy()),
            ("contact_energy".to_string(), self.contact_energy()),
            ("particle_energy".to_string(), self.particle_energy()),
            ("external_work".to_string(), self.external_work()),
            (
                "contacts".to_string(),
                self.state.pair_state.iter().filter(|p| p.active).count() as f64,
            ),
            (
                "bonds".to_string(),
                self.state.pair_state.iter().filter(|p| p.bonded).count() as f64,
            ),
            ("bonds_broken".to_string(), self.state.bonds_broken as f64),
        ];
        let m = self.macroscopic_stress();
        r.push(("macro_stress_xx".to_string(), m[0]));
        r.push(("macro_stress_yy".to_string(), m[1]));
        r.push(("macro_stress_xy".to_string(), m[2]));
        r.push((
            "strain_max".to_string(),
            self.strains()
                .iter()
                .map(|e| strain_norm(*e))
                .fold(0.0, f64::max),
        ));
        if let Some(v) = self.measurement() {
            for (k, name) in [
                "stress_xx",
                "stress_yy",
                "stress_xy",
                "strain_xx",
                "strain_yy",
                "strain_xy",
            ]
            .into_iter()
            .enumerate()
            {
                r.push((name.to_string(), v[k]));
            }
        }
        for (name, force, shift) in self.wall_readings() {
            r.push((format!("{name}.force"), force));
            r.push((format!("{name}.displacement"), shift));
        }
        r.extend(self.moduli());
        for ((name, _), tr) in self.probes.iter().zip(&self.state.probe_track) {
            r.push((format!("{name}.peak"), tr.peak));
            r.push((format!("{name}.peak_time"), tr.peak_time));
        }
        if let Some((c, r2)) = self.wave_speed() {
            r.push(("wave_speed".to_string(), c));
            r.push(("wave_speed_r2".to_string(), r2));
        }
        if self.cfg.ddem.as_ref().map(|d| d.scheme) == Some(Scheme::FixedPoint) {
            r.push((
                "iterations_most".to_string(),
                self.state.iterations_most as f64,
            ));
        }
        r
    }

    /// The state as bytes (MessagePack).
    pub fn snapshot(&self) -> Vec<u8> {
        // plain data into a Vec: cannot fail
        rmp_serde::to_vec(&self.state).expect("disc state serialises")
    }

    /// Restores a snapshot of an engine built from the same scene.
    pub fn restore(&mut self, bytes: &[u8]) -> Result<(), DiscError> {
        let s: State = rmp_serde::from_slice(bytes)
            .map_err(|e| DiscError::Snapshot(format!("cannot decode the disc snapshot: {e}")))?;
        let n = self.num_discs();
        if s.x.len() != n
            || s.pairs.len() != s.pair_state.len()
            || s.load_point.len() != self.loaded.len()
            || s.wall_state.len() != self.walls.len()
        {
            return Err(DiscError::Snapshot(format!(
                "the snapshot holds {} discs and {} loaded ones, this scene {n} and {}",
                s.x.len(),
                s.load_point.len(),
                self.loaded.len()
            )));
        }
        let pairs_ok = s.pairs.iter().all(|&(i, j)| i < j && (j as usize) < n);
        let walls_ok = s.wall_state.iter().all(|w| w.len() == n)
            && [
                s.wall_shift.len(),
                s.wall_velocity.len(),
                s.wall_force.len(),
            ]
            .iter()
            .all(|&l| l == self.walls.len());
        let discs_ok = [
            s.v.len(),
            s.theta.len(),
            s.omega.len(),
            s.x_build.len(),
            s.stress.len(),
        ]
        .iter()
        .all(|&l| l == n);
        if !(pairs_ok && walls_ok && discs_ok) {
            return Err(DiscError::Snapshot(
                "the snapshot's pairs, walls or per-disc arrays do not fit this scene".into(),
            ));
        }
        if s.probe_track.len() != self.probes.len() {
            return Err(DiscError::Snapshot(format!(
                "the snapshot tracks {} probes, this scene has {}",
                s.probe_track.len(),
                self.probes.len()
            )));
        }
        self.state = s;
        self.build_adjacency();
        self.output.pending.clear();
        self.output.last_vtk_step = None;
        Ok(())
    }

    /// Writes the CSV row and, when due, the VTK files of the discs and contacts.
    pub fn write_outputs(&mut self, dir: &Path) -> Result<(), DiscError> {
        output::write(self, dir)
    }

    /// The outputs of the end of a run: the waiting rows and the VTK files of the last state.
    pub fn write_final(&mut self, dir: &Path) -> Result<(), DiscError> {
        output::write(self, dir)?;
        if self.output.last_vtk_step != Some(self.steps()) {
            output::write_vtk_now(self, dir)?;
        }
        if self.cfg.output.final_discs {
            output::write_final_discs(self, dir)?;
        }
        Ok(())
    }
}
