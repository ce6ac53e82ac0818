//! The scene table of the 2-D disc engine: `[dem]` with `model = "discs-2d"` (Madan 2019).
//! Plain numbers in SI units; every field is checked with its path named.

use serde::Deserialize;

/// Which engine a `[dem]` table asks for (read before the rest of the table).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Model {
    /// 3-D bodies: spheres, superquadrics, dilated polyhedra (the default).
    #[default]
    #[serde(rename = "bodies-3d")]
    Bodies3d,
    /// 2-D discs per unit depth, standard DEM or DDEM (Madan).
    #[serde(rename = "discs-2d")]
    Discs2d,
}

/// Only the `model` key of a `[dem]` table.
#[derive(Debug, Deserialize)]
pub struct ModelOnly {
    #[serde(default)]
    pub model: Model,
}

/// `[dem]` of a disc scene.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DiscConfig {
    pub model: Model,
    /// Δt (s), central differences (Madan 2.9–2.13).
    pub time_step: f64,
    /// Depth l of the discs (m): masses, stiffnesses and forces are per this depth (default 1).
    #[serde(default = "one")]
    pub depth: f64,
    /// Particle density ρ (kg/m³).
    pub density: f64,
    /// Body force per unit mass (m/s²), default none.
    #[serde(default)]
    pub gravity: [f64; 2],
    pub contact: ContactConfig,
    /// Non-viscous background damping (2.7)–(2.8).
    #[serde(default)]
    pub damping: BackgroundDamping,
    /// The deformable-particle mode (2.41)–(2.54); absent: standard DEM.
    #[serde(default)]
    pub ddem: Option<DdemConfig>,
    /// Disc sources.
    #[serde(default)]
    pub discs: Vec<DiscSource>,
    /// Forces on discs (per disc, ramped).
    #[serde(default)]
    pub loads: Vec<LoadConfig>,
    /// Fixed degrees of freedom.
    #[serde(default)]
    pub constraints: Vec<ConstraintConfig>,
    /// Rigid plates (straight walls).
    #[serde(default)]
    pub walls: Vec<PlateConfig>,
    /// The measurement of a compression or shear test (Madan §4.4–4.5: E, ν, K or G).
    #[serde(default)]
    pub measure: Option<UniaxialConfig>,
    /// An initial displacement pulse (Madan (5.5), the wave-propagation bar).
    #[serde(default)]
    pub pulse: Option<PulseConfig>,
    /// Discs whose displacement `discs.csv` records (`<name>.ux`, `<name>.uy`).
    #[serde(default)]
    pub probes: Vec<ProbeConfig>,
    /// Periodic boundaries: the axes along which the sample repeats (Madan ch. 5's shear wave).
    #[serde(default)]
    pub periodic: PeriodicConfig,
    #[serde(default)]
    pub output: DiscOutput,
    /// Threads of the step (default: all cores); any count gives the same bits.
    #[serde(default)]
    pub threads: Option<usize>,
    /// Neighbour-list skin as a fraction of the mean radius (default 0.2); the list also
    /// covers the particles' own deformation.
    #[serde(default = "default_skin")]
    pub skin: f64,
}

fn one() -> f64 {
    1.0
}
fn default_skin() -> f64 {
    0.2
}

/// Linear contact law (2.20)–(2.40).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContactConfig {
    /// k_n (N/m for the depth l).
    pub normal_stiffness: f64,
    /// k_t (N/m), default 0.
    #[serde(default)]
    pub tangential_stiffness: f64,
    /// ξ_n: viscous normal damping as a fraction of c_cr = 2√(m_i m_j k_n / (m_i + m_j)).
    #[serde(default)]
    pub normal_damping: f64,
    /// ξ_t, the same for the tangential spring.
    #[serde(default)]
    pub tangential_damping: f64,
    /// Coulomb friction μ of unbonded contacts (2.40).
    #[serde(default)]
    pub friction: f64,
    /// Bonds: pairs whose gap at t = 0 is at most this (m) are bonded (2.21); absent: none.
    #[serde(default)]
    pub bond_gap: Option<f64>,
    /// A bond's spring is at rest at its t = 0 gap (the gap or overlap counts from there; the
    /// bonded sample starts free of stress, and neighbours up to `bond_gap` apart bond without
    /// pulling together). Default false: the thesis' (2.25), f_ne = k_n g from g = 0.
    #[serde(default)]
    pub bond_at_rest: bool,
    /// φ_n: a bond breaks under this tension (N), default never.
    #[serde(default = "never")]
    pub bond_normal_strength: f64,
    /// φ_t: ... or this shear force (N), default never.
    #[serde(default = "never")]
    pub bond_tangential_strength: f64,
}

fn never() -> f64 {
    f64::INFINITY
}

/// α^t, α^r of (2.7)–(2.8).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BackgroundDamping {
    #[serde(default)]
    pub translational: f64,
    #[serde(default)]
    pub rotational: f64,
}

/// Plane strain (2.48) or plane stress (2.49).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Plane {
    #[default]
    Strain,
    Stress,
}

/// The explicit lagged scheme (Madan 3.17) or the fixed point of every step (3.5)–(3.7).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Scheme {
    #[default]
    Lagged,
    FixedPoint,
}

/// `[dem.ddem]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DdemConfig {
    /// E_p (Pa).
    pub youngs_modulus: f64,
    /// ν_p.
    pub poisson_ratio: f64,
    #[serde(default)]
    pub plane: Plane,
    #[serde(default)]
    pub scheme: Scheme,
    /// Fixed point: iterate until the largest force change is below this fraction of the
    /// largest force (default 1e-12).
    #[serde(default = "default_tolerance")]
    pub tolerance: f64,
    /// Fixed point: most iterations per step (default 10,000); more is an error naming the
    /// spectral radius.
    #[serde(default = "default_iterations")]
    pub max_iterations: usize,
}

fn default_tolerance() -> f64 {
    1e-12
}
fn default_iterations() -> usize {
    10_000
}

/// Square (simple cubic in the thesis' words) or hexagonal close packing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Arrangement {
    Square,
    Hexagonal,
}

/// `[[dem.discs]]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum DiscSource {
    /// A lattice of equal discs: `count = [columns, rows]`, centre spacing (the row spacing
    /// of a hexagonal packing is spacing·√3/2; its odd rows are shifted by `odd_row_offset`
    /// spacings, default ½, and hold `odd_row_count` discs, default `count[0]`).
    Lattice {
        arrangement: Arrangement,
        radius: f64,
        spacing: f64,
        first: [f64; 2],
        count: [usize; 2],
        #[serde(default)]
        odd_row_offset: Option<f64>,
        #[serde(default)]
        odd_row_count: Option<usize>,
    },
    /// A CSV file of `x,y,radius` rows (a header line is allowed).
    File { path: String },
    /// `count` discs at random places in the box [min, max] without overlaps (random
    /// sequential addition, largest first), radii from a triangular distribution; a loose
    /// start for a packing compacted by plates.
    Random {
        count: usize,
        min: [f64; 2],
        max: [f64; 2],
        radius: Triangular,
        #[serde(default = "default_seed")]
        seed: u64,
    },
}

fn default_seed() -> u64 {
    1
}

/// A triangular distribution on [min, max] with its peak at `mode` (mean (min + max + mode)/3).
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Triangular {
    pub min: f64,
    pub max: f64,
    pub mode: f64,
}

impl Triangular {
    /// The value at the quantile u ∈ [0, 1).
    pub fn quantile(&self, u: f64) -> f64 {
        let (a, b, c) = (self.min, self.max, self.mode);
        if b <= a {
            return a;
        }
        let fc = (c - a) / (b - a);
        if u < fc {
            a + (u * (b - a) * (c - a)).sqrt()
        } else {
            b - ((1.0 - u) * (b - a) * (b - c)).sqrt()
        }
    }
}

/// `[[dem.walls]]`: a rigid plate, the straight line through `point` with the unit `normal`
/// pointing into the sample, moving at a constant `velocity` or servo-controlled to a normal
/// `pressure` (Pa over `length` × depth, at most `max_speed`). Discs touch it with the
/// contact law of the pairs (no bonds).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlateConfig {
    pub name: String,
    pub point: [f64; 2],
    pub normal: [f64; 2],
    #[serde(default)]
    pub velocity: Option<[f64; 2]>,
    #[serde(default)]
    pub pressure: Option<f64>,
    #[serde(default)]
    pub length: Option<f64>,
    #[serde(default)]
    pub max_speed: Option<f64>,
    /// The servo's gain g: the plate moves at g (F_target − F)/(Δt k_n n_contacts), closing
    /// this fraction of the force error per step against a packing as stiff as its contacts
    /// (default 0.2; up to 1; a loose packing is softer and the plate slower).
    #[serde(default = "default_gain")]
    pub gain: f64,
    /// The plate stops moving at this time (s; default never).
    #[serde(default)]
    pub stop: Option<f64>,
    /// Move the plate along its normal at t = 0 until it just touches the outermost disc
    /// (`point` then only fixes the line's direction offset): plates for a packing read from
    /// a file.
    #[serde(default)]
    pub touch: bool,
}

/// An edge of the box the discs span.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Edge {
    Bottom,
    Top,
    Left,
    Right,
}

/// A set of discs: those whose centres lie in the box `min`–`max` (m), or those reaching
/// within `width` (m) of an `edge` of the box the discs span (bottom, top, left, right) — the
/// boundary discs of a packing read from a file.
#[derive(Debug, Clone, Copy, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Region {
    #[serde(default)]
    pub min: Option<[f64; 2]>,
    #[serde(default)]
    pub max: Option<[f64; 2]>,
    #[serde(default)]
    pub edge: Option<Edge>,
    #[serde(default)]
    pub width: Option<f64>,
}

impl Region {
    /// The box `min`–`max`.
    pub fn boxed(min: [f64; 2], max: [f64; 2]) -> Self {
        Region {
            min: Some(min),
            max: Some(max),
            ..Region::default()
        }
    }

    /// The discs (centres `x`, radii `r`) of the region, in index order.
    pub fn select(&self, x: &[[f64; 2]], r: &[f64]) -> Vec<u32> {
        if let (Some(edge), Some(width)) = (self.edge, self.width) {
            let (lo, hi) = span(x, r);
            return (0..x.len() as u32)
                .filter(|&i| {
                    let (p, rp) = (x[i as usize], r[i as usize]);
                    match edge {
                        Edge::Bottom => p[1] - rp <= lo[1] + width,
                        Edge::Top => p[1] + rp >= hi[1] - width,
                        Edge::Left => p[0] - rp <= lo[0] + width,
                        Edge::Right => p[0] + rp >= hi[0] - width,
                    }
                })
                .collect();
        }
        let (min, max) = (self.min.unwrap_or([0.0; 2]), self.max.unwrap_or([0.0; 2]));
        (0..x.len() as u32)
            .filter(|&i| (0..2).all(|k| x[i as usize][k] >= min[k] && x[i as usize][k] <= max[k]))
            .collect()
    }
}

/// The box the discs (centres `x`, radii `r`) span: its lower and upper corners.
pub fn span(x: &[[f64; 2]], r: &[f64]) -> ([f64; 2], [f64; 2]) {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for (p, rp) in x.iter().zip(r) {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k] - rp);
            hi[k] = hi[k].max(p[k] + rp);
        }
    }
    (lo, hi)
}

impl std::fmt::Display for Region {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match (self.edge, self.width, self.min, self.max) {
            (Some(e), Some(w), _, _) => write!(f, "edge {e:?}, width {w:e} m"),
            (_, _, Some(a), Some(b)) => write!(f, "min {a:?}, max {b:?}"),
            _ => write!(f, "(incomplete)"),
        }
    }
}

/// `[[dem.loads]]`: a force on each disc of the region, ramped linearly from 0 over `ramp`
/// seconds, then held.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LoadConfig {
    pub region: Region,
    /// N per disc (for the depth l).
    pub force: [f64; 2],
    /// Ramp time (s), default 0 (a step load).
    #[serde(default)]
    pub ramp: f64,
}

/// A degree of freedom a constraint fixes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Dof {
    X,
    Y,
    Rotation,
}

/// `[[dem.constraints]]`: the discs of the region keep their `fix`ed coordinates, or move them
/// at a prescribed velocity: `velocity` (m/s) plus `gradient` L (1/s) times the disc's initial
/// position from `origin`, v = velocity + L (x₀ − origin) (Madan §4.5's pure shear: the
/// boundary discs at v_x = γ̇ (y₀ − y_bottom), v_y = 0).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConstraintConfig {
    pub region: Region,
    pub fix: Vec<Dof>,
    #[serde(default)]
    pub velocity: [f64; 2],
    #[serde(default)]
    pub gradient: [[f64; 2]; 2],
    #[serde(default)]
    pub origin: [f64; 2],
}

/// Which test `[dem.measure]` evaluates (Madan §4.4–4.5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum TestKind {
    /// Uniaxial compression along y: E = Δσ_yy/Δε_yy (4.19), ν = −Δε_xx/Δε_yy (4.22), (4.31).
    #[default]
    Uniaxial,
    /// Isotropic biaxial compression: K = Δσ_h/Δε_vol, σ_h = (σ_xx + σ_yy)/2, ε_vol = ε_xx +
    /// ε_yy (4.33)–(4.35).
    Biaxial,
    /// Pure shear: G = Δσ_xy/(2Δε_xy) (4.36); with the centres' strain, simple shear of a
    /// slab: 2ε_xy = γ the change of the x offset between the mean centres of `top` and
    /// `bottom` over their initial distance, σ_xy the macroscopic stress (4.3).
    Shear,
}

/// How `[dem.measure]` takes the sample's stress and strain.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StrainKind {
    /// The distances between the mean centres of `top` and `bottom` (`left` and `right`), the
    /// stress the load over `section` × depth (the SC sample, (4.19)–(4.22)).
    #[default]
    Centres,
    /// Bagi's strain over the Delaunay triangulation of the initial centres (4.4)–(4.6) and
    /// the macroscopic stress (4.1)–(4.3) over the box the discs span (the irregular sample).
    Bagi,
}

/// `[dem.measure]`: the elastic moduli of a compression or shear test (Madan §4.4–4.5). With
/// `strain = "centres"` the strain is the change of the distance between the mean centres of
/// `top` and `bottom` (of `left` and `right`) over its initial value and the stress the load
/// on `top` over `section` × depth; with `strain = "bagi"` both are the sample's averages.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UniaxialConfig {
    #[serde(default)]
    pub test: TestKind,
    #[serde(default)]
    pub strain: StrainKind,
    #[serde(default)]
    pub top: Option<Region>,
    #[serde(default)]
    pub bottom: Option<Region>,
    #[serde(default)]
    pub left: Option<Region>,
    #[serde(default)]
    pub right: Option<Region>,
    /// A (m): the sample's width the stress is taken over (`strain = "centres"`).
    #[serde(default)]
    pub section: Option<f64>,
    /// The plate whose normal force is the load (default: the loads on the `top` discs); the
    /// fit then uses fractions of the peak stress of the loading branch.
    #[serde(default)]
    pub plate: Option<String>,
    /// `strain = "bagi"`: average over the triangles whose corners lie at least this far (m)
    /// inside the box the discs span at t = 0 (default 0: all, the thesis'): a free side's
    /// loosely bonded outermost discs move more than the sample does.
    #[serde(default)]
    pub margin: f64,
    /// The load fractions between which the moduli are fitted (default [0.4, 0.8]): of the
    /// ramped loads with the centres' strain, or of the peak stress (|σ_yy|, |σ_h| or |σ_xy|)
    /// of the loading branch when a plate, prescribed motion or Bagi's strain is used.
    #[serde(default = "default_fit")]
    pub fit: [f64; 2],
}

fn default_gain() -> f64 {
    0.2
}

impl UniaxialConfig {
    /// Simple shear of a slab: a shear test with the centres' strain.
    pub fn slab(&self) -> bool {
        self.strain == StrainKind::Centres && self.test == TestKind::Shear
    }
}

fn default_fit() -> [f64; 2] {
    [0.4, 0.8]
}

/// `[dem.pulse]`: at t = 0, after the bonds are made, each disc is displaced along
/// `displacement` (default `direction`) by u = `amplitude` · ½ (1 + cos(2π ξ/`wavelength`)) for 0 ≤ ξ ≤ `wavelength`/2,
/// ξ the distance of its centre from `start` along `direction`, at rest (our reading of
/// Madan (5.5), A cos(2πx/L + 1) on 0 ≤ x ≤ L/2: a smooth half-bell from A at the end of the
/// bar to 0).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PulseConfig {
    pub direction: [f64; 2],
    /// The direction the discs are displaced in (default `direction`: a longitudinal pulse;
    /// across it: a shear pulse).
    #[serde(default)]
    pub displacement: Option<[f64; 2]>,
    /// The point the pulse starts from (m); default: the lowest centre along `direction`.
    #[serde(default)]
    pub start: Option<[f64; 2]>,
    pub amplitude: f64,
    pub wavelength: f64,
}

/// `[dem.periodic]`: the sample repeats along x over `x = [min, max]` and/or along y over
/// `y = [min, max]` (m): pairs interact across the cell's sides through the nearest image.
/// Centres are not wrapped back into the cell (displacements stay continuous).
#[derive(Debug, Clone, Copy, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PeriodicConfig {
    #[serde(default)]
    pub x: Option<[f64; 2]>,
    #[serde(default)]
    pub y: Option<[f64; 2]>,
}

impl PeriodicConfig {
    /// Per axis (the cell's lower side, its length), the length 0 where not periodic.
    pub fn cell(&self) -> ([f64; 2], [f64; 2]) {
        let mut lo = [0.0; 2];
        let mut len = [0.0; 2];
        for (k, a) in [self.x, self.y].into_iter().enumerate() {
            if let Some([a, b]) = a {
                lo[k] = a;
                len[k] = b - a;
            }
        }
        (lo, len)
    }
}

/// `[[dem.probes]]`: the disc whose centre lies nearest `point`, or the mean of the discs of
/// a `region` (a layer across a plane wave).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ProbeConfig {
    pub name: String,
    #[serde(default)]
    pub point: Option<[f64; 2]>,
    #[serde(default)]
    pub region: Option<Region>,
}

/// `[dem.output]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DiscOutput {
    /// A row of `discs.csv` (energies, forces, measurement) every this many steps.
    #[serde(default = "default_csv_every")]
    pub csv_every: u64,
    /// A VTK file of the discs (radius, velocity, stress, strain) every this many steps (0:
    /// only the last state).
    #[serde(default)]
    pub vtk_every: u64,
    /// Write `discs_final.csv` (x,y,radius: a `file` source of a later scene) at the end.
    #[serde(default)]
    pub final_discs: bool,
}

fn default_csv_every() -> u64 {
    10
}

impl Default for DiscOutput {
    fn default() -> Self {
        DiscOutput {
            csv_every: default_csv_every(),
            vtk_every: 0,
            final_discs: false,
        }
    }
}

/// A value error: the dotted path of the field and what is wrong.
#[derive(Debug, Clone)]
pub struct ValueError {
    pub path: String,
    pub message: String,
}

fn positive(path: &str, v: f64, out: &mut Vec<ValueError>) {
    if !(v.is_finite() && v > 0.0) {
        out.push(ValueError {
            path: path.into(),
            message: format!("must be a positive number, got {v}"),
        });
    }
}

fn direction(path: &str, v: [f64; 2], out: &mut Vec<ValueError>) {
    let n = (v[0].powi(2) + v[1].powi(2)).sqrt();
    if !(n.is_finite() && n > 0.0) {
        out.push(ValueError {
            path: path.into(),
            message: format!("must be a finite non-zero vector, got {v:?}"),
        });
    }
}

fn non_negative(path: &str, v: f64, out: &mut Vec<ValueError>) {
    if !(v.is_finite() && v >= 0.0) {
        out.push(ValueError {
            path: path.into(),
            message: format!("must be zero or positive, got {v}"),
        });
    }
}

fn region(path: &str, r: &Region, out: &mut Vec<ValueError>) {
    match (r.min, r.max, r.edge, r.width) {
        (Some(min), Some(max), None, None) => {
            if !(0..2).all(|k| min[k].is_finite() && max[k].is_finite() && min[k] <= max[k]) {
                out.push(ValueError {
                    path: path.into(),
                    message: format!("min {min:?} must be finite and not above max {max:?}"),
                });
            }
        }
        (None, None, Some(_), Some(w)) => positive(&format!("{path}.width"), w, out),
        _ => out.push(ValueError {
            path: path.into(),
            message: "is a box of centres (`min` and `max`, m) or a band along an edge of the sample (`edge` = bottom/top/left/right and `width`, m), not a mix".into(),
        }),
    }
}

impl DiscConfig {
    /// Every value check, each naming its field (`dem.contact.normal_stiffness`, ...).
    pub fn validate(&self) -> Vec<ValueError> {
        let mut e = Vec::new();
        positive("dem.time_step", self.time_step, &mut e);
        positive("dem.depth", self.depth, &mut e);
        positive("dem.density", self.density, &mut e);
        positive("dem.skin", self.skin, &mut e);
        if let Some(t) = self.threads {
            let most = crate::resources::max_threads();
            if t == 0 || t > most {
                e.push(ValueError {
                    path: "dem.threads".into(),
                    message: format!(
                        "must be between 1 and {most} (4 × the cores available), got {t}"
                    ),
                });
            }
        }
        let c = &self.contact;
        positive("dem.contact.normal_stiffness", c.normal_stiffness, &mut e);
        non_negative(
            "dem.contact.tangential_stiffness",
            c.tangential_stiffness,
            &mut e,
        );
        non_negative("dem.contact.normal_damping", c.normal_damping, &mut e);
        non_negative(
            "dem.contact.tangential_damping",
            c.tangential_damping,
            &mut e,
        );
        non_negative("dem.contact.friction", c.friction, &mut e);
        if let Some(g) = c.bond_gap {
            if !g.is_finite() {
                e.push(ValueError {
                    path: "dem.contact.bond_gap".into(),
                    message: format!("must be a finite gap in m, got {g}"),
                });
            }
        }
        if c.bond_normal_strength.is_nan() || c.bond_normal_strength <= 0.0 {
            positive(
                "dem.contact.bond_normal_strength",
                c.bond_normal_strength,
                &mut e,
            );
        }
        if c.bond_tangential_strength.is_nan() || c.bond_tangential_strength <= 0.0 {
            positive(
                "dem.contact.bond_tangential_strength",
                c.bond_tangential_strength,
                &mut e,
            );
        }
        for (k, v) in [
            ("translational", self.damping.translational),
            ("rotational", self.damping.rotational),
        ] {
            if !(v.is_finite() && (0.0..1.0).contains(&v)) {
                e.push(ValueError {
                    path: format!("dem.damping.{k}"),
                    message: format!("must lie in [0, 1), got {v}"),
                });
            }
        }
        if let Some(d) = &self.ddem {
            positive("dem.ddem.youngs_modulus", d.youngs_modulus, &mut e);
            if !(d.poisson_ratio.is_finite() && d.poisson_ratio > -1.0 && d.poisson_ratio < 0.5) {
                e.push(ValueError {
                    path: "dem.ddem.poisson_ratio".into(),
                    message: format!("must lie in (−1, 0.5), got {}", d.poisson_ratio),
                });
            }
            positive("dem.ddem.tolerance", d.tolerance, &mut e);
            if d.max_iterations == 0 {
                e.push(ValueError {
                    path: "dem.ddem.max_iterations".into(),
                    message: "must be at least 1".into(),
                });
            }
        }
        if self.discs.is_empty() {
            e.push(ValueError {
                path: "dem.discs".into(),
                message: "the scene has no discs: add a [[dem.discs]] source".into(),
            });
        }
        for (i, s) in self.discs.iter().enumerate() {
            if let DiscSource::Lattice {
                radius,
                spacing,
                first,
                count,
                ..
            } = s
            {
                positive(&format!("dem.discs[{i}].radius"), *radius, &mut e);
                positive(&format!("dem.discs[{i}].spacing"), *spacing, &mut e);
                if !first.iter().all(|v| v.is_finite()) {
                    e.push(ValueError {
                        path: format!("dem.discs[{i}].first"),
                        message: "must be finite".into(),
                    });
                }
                if count[0] == 0 || count[1] == 0 || count[0].saturating_mul(count[1]) > 10_000_000
                {
                    e.push(ValueError {
                        path: format!("dem.discs[{i}].count"),
                        message: format!(
                            "must be two positive counts with at most 1e7 discs, got {count:?}"
                        ),
                    });
                }
            }
        }
        for (i, s) in self.discs.iter().enumerate() {
            if let DiscSource::Random {
                count,
                min,
                max,
                radius,
                ..
            } = s
            {
                if *count == 0 || *count > 10_000_000 {
                    e.push(ValueError {
                        path: format!("dem.discs[{i}].count"),
                        message: format!("must be between 1 and 1e7, got {count}"),
                    });
                }
                region(
                    &format!("dem.discs[{i}]"),
                    &Region::boxed(*min, *max),
                    &mut e,
                );
                if !(radius.min > 0.0
                    && radius.min <= radius.mode
                    && radius.mode <= radius.max
                    && radius.max.is_finite())
                {
                    e.push(ValueError {
                        path: format!("dem.discs[{i}].radius"),
                        message: format!(
                            "needs 0 < min ≤ mode ≤ max, got min {}, mode {}, max {}",
                            radius.min, radius.mode, radius.max
                        ),
                    });
                }
            }
        }
        let mut names = std::collections::BTreeSet::new();
        for (i, w) in self.walls.iter().enumerate() {
            let path = format!("dem.walls[{i}]");
            if w.name.is_empty() || !names.insert(w.name.clone()) {
                e.push(ValueError {
                    path: format!("{path}.name"),
                    message: format!("`{}` must be a name no other wall has", w.name),
                });
            }
            let n = (w.normal[0].powi(2) + w.normal[1].powi(2)).sqrt();
            if !(n.is_finite() && n > 0.0 && w.point.iter().all(|v| v.is_finite())) {
                e.push(ValueError {
                    path: format!("{path}.normal"),
                    message: format!(
                        "point and normal must be finite and the normal non-zero, got {:?}, {:?}",
                        w.point, w.normal
                    ),
                });
            }
            match (w.velocity, w.pressure) {
                (Some(_), Some(_)) => e.push(ValueError {
                    path: format!("{path}.pressure"),
                    message: "a wall moves at a velocity or to a pressure, not both".into(),
                }),
                (Some(v), None) if !v.iter().all(|c| c.is_finite()) => e.push(ValueError {
                    path: format!("{path}.velocity"),
                    message: "must be finite".into(),
                }),
                (None, Some(p)) => {
                    positive(&format!("{path}.pressure"), p, &mut e);
                    match (w.length, w.max_speed) {
                        (Some(l), Some(v)) => {
                            positive(&format!("{path}.length"), l, &mut e);
                            positive(&format!("{path}.max_speed"), v, &mut e);
                        }
                        _ => e.push(ValueError {
                            path: format!("{path}.pressure"),
                            message: "a pressure-controlled wall needs `length` (m) and `max_speed` (m/s)".into(),
                        }),
                    }
                }
                _ => {}
            }
            if !(w.gain > 0.0 && w.gain <= 1.0) {
                e.push(ValueError {
                    path: format!("{path}.gain"),
                    message: format!("must lie in (0, 1], got {}", w.gain),
                });
            }
            if let Some(t) = w.stop {
                non_negative(&format!("{path}.stop"), t, &mut e);
            }
        }
        if let Some(name) = self.measure.as_ref().and_then(|m| m.plate.as_ref()) {
            if !self.walls.iter().any(|w| &w.name == name) {
                e.push(ValueError {
                    path: "dem.measure.plate".into(),
                    message: format!("names no wall: `{name}`"),
                });
            }
        }
        for (i, l) in self.loads.iter().enumerate() {
            region(&format!("dem.loads[{i}].region"), &l.region, &mut e);
            if !l.force.iter().all(|v| v.is_finite()) {
                e.push(ValueError {
                    path: format!("dem.loads[{i}].force"),
                    message: "must be finite".into(),
                });
            }
            non_negative(&format!("dem.loads[{i}].ramp"), l.ramp, &mut e);
        }
        for (i, c) in self.constraints.iter().enumerate() {
            region(&format!("dem.constraints[{i}].region"), &c.region, &mut e);
            if c.fix.is_empty() {
                e.push(ValueError {
                    path: format!("dem.constraints[{i}].fix"),
                    message: "names no degree of freedom (x, y, rotation)".into(),
                });
            }
        }
        for (i, c) in self.constraints.iter().enumerate() {
            let finite = c
                .velocity
                .iter()
                .chain(c.gradient.iter().flatten())
                .chain(&c.origin);
            if !finite.into_iter().all(|v| v.is_finite()) {
                e.push(ValueError {
                    path: format!("dem.constraints[{i}].velocity"),
                    message: "velocity, gradient and origin must be finite".into(),
                });
            }
            for (k, (dof, name)) in [(Dof::X, "x"), (Dof::Y, "y")].into_iter().enumerate() {
                let moves = c.velocity[k] != 0.0 || c.gradient[k].iter().any(|g| *g != 0.0);
                if moves && !c.fix.contains(&dof) {
                    e.push(ValueError {
                        path: format!("dem.constraints[{i}].velocity"),
                        message: format!(
                            "prescribes a motion along {name}, which `fix` does not hold: add \"{name}\" to fix"
                        ),
                    });
                }
            }
        }
        if let Some(m) = &self.measure {
            let slab = m.slab();
            if slab {
                // simple shear of a slab: the mean centres of top and bottom, σ̄_xy (4.3)
                for (k, r) in [("top", &m.top), ("bottom", &m.bottom)] {
                    match r {
                        Some(r) => region(&format!("dem.measure.{k}"), r, &mut e),
                        None => e.push(ValueError {
                            path: format!("dem.measure.{k}"),
                            message: "a shear test with the centres' strain needs the regions top and bottom (or strain = \"bagi\")".into(),
                        }),
                    }
                }
            } else if m.strain == StrainKind::Centres {
                for (k, r) in [
                    ("top", &m.top),
                    ("bottom", &m.bottom),
                    ("left", &m.left),
                    ("right", &m.right),
                ] {
                    match r {
                        Some(r) => region(&format!("dem.measure.{k}"), r, &mut e),
                        None => e.push(ValueError {
                            path: format!("dem.measure.{k}"),
                            message: "the centres' strain needs the regions top, bottom, left and right (or strain = \"bagi\")".into(),
                        }),
                    }
                }
                match m.section {
                    Some(a) => positive("dem.measure.section", a, &mut e),
                    None => e.push(ValueError {
                        path: "dem.measure.section".into(),
                        message: "the centres' strain needs the sample's width `section` (m)"
                            .into(),
                    }),
                }
                if m.test != TestKind::Uniaxial {
                    e.push(ValueError {
                        path: "dem.measure.test".into(),
                        message: "a biaxial test takes Bagi's strain: set strain = \"bagi\"".into(),
                    });
                }
            }
            // keys the chosen measurement would not read: refused rather than ignored
            let unused: Vec<(&str, bool)> = match m.strain {
                StrainKind::Bagi => vec![
                    ("top", m.top.is_some()),
                    ("bottom", m.bottom.is_some()),
                    ("left", m.left.is_some()),
                    ("right", m.right.is_some()),
                    ("section", m.section.is_some()),
                    ("plate", m.plate.is_some()),
                ],
                StrainKind::Centres if slab => vec![
                    ("left", m.left.is_some()),
                    ("right", m.right.is_some()),
                    ("section", m.section.is_some()),
                    ("plate", m.plate.is_some()),
                    ("margin", m.margin != 0.0),
                ],
                StrainKind::Centres => vec![("margin", m.margin != 0.0)],
            };
            for (key, given) in unused {
                if given {
                    let how = match (m.strain, slab) {
                        (StrainKind::Bagi, _) => "Bagi's strain and the macroscopic stress (4.3) over the whole sample",
                        (_, true) => "a slab's simple shear (the mean centres of top and bottom, the macroscopic σ_xy)",
                        _ => "the centres' strain (margin belongs to Bagi's)",
                    };
                    e.push(ValueError {
                        path: format!("dem.measure.{key}"),
                        message: format!("is not used by {how}: remove it"),
                    });
                }
            }
            non_negative("dem.measure.margin", m.margin, &mut e);
            if !(0.0 <= m.fit[0] && m.fit[0] < m.fit[1] && m.fit[1] <= 1.0) {
                e.push(ValueError {
                    path: "dem.measure.fit".into(),
                    message: format!("must be two load fractions 0 ≤ a < b ≤ 1, got {:?}", m.fit),
                });
            }
        }
        if let Some(pl) = &self.pulse {
            direction("dem.pulse.direction", pl.direction, &mut e);
            if let Some(u) = pl.displacement {
                direction("dem.pulse.displacement", u, &mut e);
            }
            if !pl.amplitude.is_finite() {
                e.push(ValueError {
                    path: "dem.pulse.amplitude".into(),
                    message: format!("must be finite, got {}", pl.amplitude),
                });
            }
            positive("dem.pulse.wavelength", pl.wavelength, &mut e);
            if pl.start.is_some_and(|s| !s.iter().all(|v| v.is_finite())) {
                e.push(ValueError {
                    path: "dem.pulse.start".into(),
                    message: "must be finite".into(),
                });
            }
        }
        let mut probe_names = std::collections::BTreeSet::new();
        for (i, pr) in self.probes.iter().enumerate() {
            if pr.name.is_empty() || !probe_names.insert(pr.name.clone()) {
                e.push(ValueError {
                    path: format!("dem.probes[{i}].name"),
                    message: format!("`{}` must be a name no other probe has", pr.name),
                });
            }
            match (&pr.point, &pr.region) {
                (Some(p), None) if !p.iter().all(|v| v.is_finite()) => e.push(ValueError {
                    path: format!("dem.probes[{i}].point"),
                    message: "must be finite".into(),
                }),
                (None, Some(r)) => region(&format!("dem.probes[{i}].region"), r, &mut e),
                (Some(_), None) => {}
                _ => e.push(ValueError {
                    path: format!("dem.probes[{i}]"),
                    message: "reads the disc nearest a `point` or the mean of a `region`'s discs: give one of them".into(),
                }),
            }
        }
        for (k, (axis, a)) in [("x", self.periodic.x), ("y", self.periodic.y)]
            .into_iter()
            .enumerate()
        {
            let Some([lo, hi]) = a else { continue };
            if !(lo.is_finite() && hi.is_finite() && hi > lo && (hi - lo).is_finite()) {
                e.push(ValueError {
                    path: format!("dem.periodic.{axis}"),
                    message: format!("must be [min, max] with min < max, got [{lo}, {hi}]"),
                });
            }
            for (i, w) in self.walls.iter().enumerate() {
                if w.normal[k] != 0.0 {
                    e.push(ValueError {
                        path: format!("dem.walls[{i}].normal"),
                        message: format!(
                            "the sample is periodic along {axis}: a wall must lie along it (its normal without a {axis} component), got {:?}",
                            w.normal
                        ),
                    });
                }
            }
        }
        if (self.periodic.x.is_some() || self.periodic.y.is_some())
            && self
                .measure
                .as_ref()
                .is_some_and(|m| m.strain == StrainKind::Bagi)
        {
            e.push(ValueError {
                path: "dem.measure.strain".into(),
                message: "Bagi's strain triangulates the centres without their periodic images: with dem.periodic use strain = \"centres\"".into(),
            });
        }
        if self.output.csv_every == 0 {
            e.push(ValueError {
                path: "dem.output.csv_every".into(),
                message: "must be at least 1 step".into(),
            });
        }
        e
    }
}
