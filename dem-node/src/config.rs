//! The `[dem]` table of a scene file (see `DEM.md` for the format with an example).
//!
//! All quantities are SI (m, s, kg, Pa). Parsing rejects unknown fields
//! (`deny_unknown_fields`); [`crate::parse_scene_section`] reports the line
//! and column of the offending key or value, and value checks name the full field path, e.g.
//! `dem.materials.wheat.poisson_ratio`.

use crate::resources::format_number;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Default safety fraction of the Rayleigh time step (Ullrich eq. 2.27). LIGGGHTS and EDEM
/// guides recommend 20–40 % of Δt_R for dense packings; 0.3 lets the REFERENCE D dense bed
/// (Δt = 1e-5 s, Δt_R = 3.86e-5 s, fraction 0.26) run without the override.
pub const DEFAULT_RAYLEIGH_FRACTION: f64 = 0.3;
/// Largest `impact_substeps`.
pub const MAX_IMPACT_SUBSTEPS: usize = 1024;

/// A scene-file error with a 1-based position in the whole scene text (the one type of every
/// crate).
pub use scenefile::SceneError;

/// The `[dem]` table.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct DemConfig {
    /// Which engine: `bodies-3d` (this table, the default) or `discs-2d` (Madan's 2-D discs,
    /// [`crate::discs::config::DiscConfig`], read by the node when it sees that value).
    #[serde(default)]
    pub model: crate::discs::config::Model,
    /// DEM time step Δt^D in s.
    pub time_step: f64,
    /// Gravitational acceleration in m/s², default `[0, 0, -9.81]`.
    #[serde(default = "default_gravity")]
    pub gravity: [f64; 3],
    /// Named materials, `[dem.materials.<name>]`.
    pub materials: BTreeMap<String, MaterialConfig>,
    /// Per material pair overrides of friction / restitution / rolling friction.
    #[serde(default)]
    pub interactions: Vec<InteractionConfig>,
    /// Particle sources, `[[dem.particles]]`.
    #[serde(default)]
    pub particles: Vec<ParticleSource>,
    /// Static walls, `[[dem.walls]]`, optionally with a prescribed motion.
    #[serde(default)]
    pub walls: Vec<WallConfig>,
    /// Measurements, `[[dem.sensors]]`.
    #[serde(default)]
    pub sensors: Vec<SensorConfig>,
    /// `[[dem.sinks]]`: boxes of centres; a particle whose centre enters one is removed at the
    /// next neighbour-list build (a collecting container, an outlet: grains that left the part
    /// of the scene that matters stop costing time). Results count them
    /// (`removed_particles`, `removed_mass`).
    #[serde(default)]
    pub sinks: Vec<CentreBox>,
    /// Material of coupled (FEM interface) meshes; required when a coupled mesh is added.
    #[serde(default)]
    pub interface_material: Option<String>,
    /// Output settings, `[dem.output]`.
    #[serde(default)]
    pub output: OutputConfig,
    /// Worker threads for this engine (rayon pool); default: rayon's global pool.
    #[serde(default)]
    pub threads: Option<usize>,
    /// Run even if `time_step` exceeds `rayleigh_fraction` × Δt_R.
    #[serde(default)]
    pub allow_large_time_step: bool,
    /// Safety fraction of the Rayleigh time step (eq. 2.27), default 0.3.
    #[serde(default = "default_rayleigh_fraction")]
    pub rayleigh_fraction: f64,
    /// Verlet skin d_V in m; default 0.25 × mean radius (Wellmann B4).
    #[serde(default)]
    pub skin: Option<f64>,
    /// Integrate rotations (default true). `false` locks every particle's rotation.
    #[serde(default = "default_true")]
    pub rotation: bool,
    /// Impact refinement: a step during which a contact touches runs as this many sub-steps
    /// of Δt/N (default 1 = off; see `impact_refinement`).
    #[serde(default = "default_impact_substeps")]
    pub impact_substeps: usize,
    /// When the elliptic Hertz stiffness γ (Wellmann 3.19) of a contact of non-spherical
    /// bodies is evaluated: `every_step` (default, Wellmann) or `first_touch`.
    #[serde(default)]
    pub superquadric_stiffness: StiffnessUpdate,
    /// How far a tracked superquadric pair's linearised surfaces may be from the exact ones
    /// before they are evaluated exactly again, in multiples of the default (a quarter of the
    /// contact search's tolerance, ≈ 2.5e-11 of the grain size): 1 (default) keeps the results
    /// of the exact search to its tolerance; larger values trade that accuracy for speed (100:
    /// ≈ 1e-12 m on sand grains, 1.34× faster in a sheared RVE; docs/homogenisation.md).
    #[serde(default = "default_surface_budget")]
    pub superquadric_surface_budget: f64,
    /// `[dem.periodic]`: a periodic cell (Wellmann ch. 5's RVE) instead of walls.
    #[serde(default)]
    pub periodic: Option<crate::periodic::PeriodicConfig>,
    /// `[dem.volume_coupling]`: the settings of volume (Arlequin) interfaces with a continuum
    /// (projection, weight floor, drift limit; Wellmann ch. 6; the penalty is the provider's).
    #[serde(default)]
    pub volume_coupling: crate::volume_coupling::VolumeSettings,
}

/// When the elliptic Hertz stiffness γ of a superquadric contact is evaluated.
///
/// γ depends on the curvatures at the contact points and on the bodies' relative
/// orientation. Re-evaluating it every step (Wellmann) follows the geometry, but the force
/// γE*δ^{3/2} is then not the gradient of an energy: an oblique frictionless elastic impact of
/// two ellipsoids gains or loses ~5e-3 of its energy (measured, `tests/superquadrics.rs`).
/// Holding γ from the first touch until the contact opens makes the force −∂W/∂x of
/// W = (2/5)γE*δ^{5/2} with δ the exact penetration (the common-normal minimum), so impacts
/// conserve energy to the integrator's error (~1e-7), at the price of a stiffness that does
/// not follow a contact rolling far over a curved surface.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "snake_case")]
pub enum StiffnessUpdate {
    #[default]
    EveryStep,
    FirstTouch,
}

fn default_gravity() -> [f64; 3] {
    [0.0, 0.0, -9.81]
}
fn default_rayleigh_fraction() -> f64 {
    DEFAULT_RAYLEIGH_FRACTION
}
fn default_surface_budget() -> f64 {
    1.0
}
fn default_impact_substeps() -> usize {
    1
}
fn default_true() -> bool {
    true
}
fn default_one() -> f64 {
    1.0
}

/// `[dem.materials.<name>]`.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MaterialConfig {
    /// Young's modulus E in Pa (> 0).
    pub youngs_modulus: f64,
    /// Poisson's ratio ν, 0 ≤ ν < 0.5.
    pub poisson_ratio: f64,
    /// Density ρ in kg/m³ (> 0).
    pub density: f64,
    /// Coefficient of restitution e, 0 < e ≤ 1 (pair default: mean of the two materials).
    pub restitution: f64,
    /// Coulomb friction coefficient μ ≥ 0 (pair default: mean of the two materials).
    pub friction: f64,
    /// Rolling resistance coefficient μ_r ≥ 0 (constant directional torque), default 0.
    #[serde(default)]
    pub rolling_friction: f64,
    /// A linear spring-dashpot contact instead of Hertz–Mindlin: this material's half of the
    /// normal contact spring in N/m (> 0). A pair's normal stiffness is the two halves in
    /// series, k_n = 1/(1/k_a + 1/k_b) (a near-rigid wall: give its material a large value);
    /// the tangential spring is k_t = k_n · 4G*/E* (Mindlin's ratio of the same pair, from
    /// the Poisson ratios), the dashpot the one of an exact restitution e for the unclamped
    /// law, 2ζ√(k_n m*) with ζ = −ln e/√(ln²e + π²). All materials of a scene or none, spheres
    /// only. For verification (a lattice under homogeneous strain has stresses linear in the
    /// strain: the Arlequin patch test) and for codes calibrated with Hooke contacts.
    #[serde(default)]
    pub normal_stiffness: Option<f64>,
}

/// `[[dem.interactions]]`: overrides for one material pair.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct InteractionConfig {
    /// The two material names (order irrelevant; may be equal).
    pub materials: [String; 2],
    #[serde(default)]
    pub friction: Option<f64>,
    #[serde(default)]
    pub restitution: Option<f64>,
    #[serde(default)]
    pub rolling_friction: Option<f64>,
    /// Contacts of this pair (any shape): Wellmann's quasi-static dashpot ζ·2√(c_N m*) δ̇
    /// (W 3.29; ζ = 1 critical, W uses 0.9), normal only, instead of the
    /// restitution-calibrated normal and tangential dashpots.
    #[serde(default)]
    pub damping_ratio: Option<f64>,
    /// Contacts of this pair (any shape): Brilliantov's viscoelastic dashpot
    /// (3/2)γE*A√δ δ̇ = c_N A δ̇ with A in s (W 3.30), normal only, instead of the
    /// restitution-calibrated ones.
    #[serde(default)]
    pub viscoelastic_time: Option<f64>,
}

/// One explicitly listed sphere.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SphereConfig {
    /// Centre in m.
    pub position: [f64; 3],
    /// Radius in m (> 0).
    pub radius: f64,
    /// Velocity in m/s, default 0.
    #[serde(default)]
    pub velocity: [f64; 3],
    /// Angular velocity in rad/s, default 0.
    #[serde(default)]
    pub angular_velocity: [f64; 3],
    /// Orientation of a superquadric as a quaternion [w, x, y, z] (normalised), default
    /// random (or the identity with `random_orientation = false`).
    #[serde(default)]
    pub orientation: Option<[f64; 4]>,
}

/// Radius distribution of a region fill.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum SizeDistribution {
    /// Every radius equal.
    Constant { radius: f64 },
    /// Radius uniform in [min, max].
    Uniform { min: f64, max: f64 },
    /// Normal(mean, std_dev) truncated to [min, max] (rejection sampling).
    Normal {
        mean: f64,
        std_dev: f64,
        min: f64,
        max: f64,
    },
    /// Piecewise-linear cumulative distribution by number: `cumulative[k]` is the fraction of
    /// particles with radius ≤ `radius[k]`; radius increasing, cumulative from 0 to 1.
    Table {
        radius: Vec<f64>,
        cumulative: Vec<f64>,
    },
}

impl SizeDistribution {
    /// The largest radius it can draw.
    pub fn max_radius(&self) -> f64 {
        match self {
            SizeDistribution::Constant { radius } => *radius,
            SizeDistribution::Uniform { max, .. } | SizeDistribution::Normal { max, .. } => *max,
            SizeDistribution::Table { radius, .. } => radius.last().copied().unwrap_or(f64::NAN),
        }
    }
}

/// `shape` of a particle source: spheres (default) or superquadrics (Wellmann 3.1).
///
/// For a superquadric the source's radius (`radius`, the drawn radius of a `distribution`,
/// or a listed `radius`) is the radius of the sphere of equal volume, so masses, mass
/// targets and sizes read as for spheres. The semi-axis ratios are `aspect` (fixed) or each
/// uniform in [1, `elongation`]; the exponents ε1, ε2 are `exponents` (fixed) or each uniform
/// in [1 − `angularity`, 1 + `angularity`] (Wellmann §3.4.4); the default is a sphere-like
/// ellipsoid (ratios 1, ε = 1). Orientations are uniformly random (seeded) unless
/// `random_orientation = false`.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, Default)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum ShapeConfig {
    #[default]
    Sphere,
    Superquadric {
        /// Semi-axes r1, r2, r3 each drawn from its own distribution (Wellmann's sand,
        /// SEED-SPEC §3.4); the source's size is then not used (a fill gives no
        /// `distribution`).
        #[serde(default)]
        semi_axes: Option<Box<[SizeDistribution; 3]>>,
        #[serde(default)]
        aspect: Option<[f64; 3]>,
        #[serde(default)]
        elongation: Option<f64>,
        #[serde(default)]
        exponents: Option<[f64; 2]>,
        #[serde(default)]
        angularity: Option<f64>,
        /// Exponents each uniform in [lo, hi] (Wellmann's sand: [0.6, 1.2]).
        #[serde(default)]
        exponent_range: Option<[f64; 2]>,
        #[serde(default = "default_true")]
        random_orientation: bool,
    },
    /// Dilated convex polyhedra (Ullrich's ballast, U §2.1.1): every particle is a randomly
    /// oriented copy of a stone of the source's library, scaled so that its equivalent-volume
    /// diameter is twice the source's radius. The library is `library` (STL files of convex
    /// stones, relative to the scene folder; a non-convex one is refused) or `stones` random
    /// convex stones of `triangles` core triangles (even; U: 10, 30, 40) and `elongation`
    /// (axis ratios each uniform in [1/elongation, 1]), seeded. `dilation` is r_ds as a
    /// fraction of the size (U: 0.1).
    Polyhedron {
        #[serde(default = "default_triangles")]
        triangles: usize,
        #[serde(default = "default_elongation")]
        elongation: f64,
        #[serde(default = "default_dilation")]
        dilation: f64,
        #[serde(default = "default_stones")]
        stones: usize,
        #[serde(default)]
        library: Option<Vec<String>>,
        #[serde(default = "default_true")]
        random_orientation: bool,
    },
}

fn default_triangles() -> usize {
    30
}
fn default_elongation() -> f64 {
    1.5
}
fn default_dilation() -> f64 {
    0.1
}
fn default_stones() -> usize {
    50
}

impl ShapeConfig {
    pub fn is_sphere(&self) -> bool {
        matches!(self, ShapeConfig::Sphere)
    }
}

/// `[[dem.particles]]`: a particle source.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum ParticleSource {
    /// Explicit spheres.
    List {
        material: String,
        spheres: Vec<SphereConfig>,
        #[serde(default)]
        shape: ShapeConfig,
    },
    /// Simple-cubic lattice: centres `first + (i,j,k)·spacing`, `count = [nx, ny, nz]`.
    /// `jitter` (m, default 0) displaces every centre at random by up to ± jitter in x and y
    /// (seeded by `seed`, like LIGGGHTS' `displace_atoms random`): an exact lattice can stand as
    /// static columns, a jittered one buckles into a random packing.
    Lattice {
        material: String,
        radius: f64,
        first: [f64; 3],
        spacing: f64,
        count: [usize; 3],
        #[serde(default)]
        velocity: [f64; 3],
        #[serde(default)]
        jitter: f64,
        #[serde(default = "default_seed")]
        seed: u64,
        #[serde(default)]
        shape: ShapeConfig,
    },
    /// Random non-overlapping spheres inside the box [min, max] (whole spheres inside), until
    /// `count` particles or `mass` kg are placed (exactly one of them). With `radius`, inside
    /// the cylinder of that radius about the vertical axis through the box's centre (and
    /// between the box's z bounds): a triaxial sample's mould.
    ///
    /// In a periodic cell (`[dem.periodic]`) `min` and `max` may be left out: the fill fills
    /// the cell, [0, size].
    Fill {
        material: String,
        #[serde(default)]
        min: Option<[f64; 3]>,
        #[serde(default)]
        max: Option<[f64; 3]>,
        #[serde(default)]
        radius: Option<f64>,
        #[serde(default)]
        count: Option<usize>,
        #[serde(default)]
        mass: Option<f64>,
        /// Radius distribution (equal-volume radius for superquadrics); omitted when the
        /// shape draws its `semi_axes`.
        #[serde(default)]
        distribution: Option<SizeDistribution>,
        /// Seed of the deterministic generator, default 1.
        #[serde(default = "default_seed")]
        seed: u64,
        #[serde(default)]
        velocity: [f64; 3],
        #[serde(default)]
        shape: ShapeConfig,
    },
    /// Spheres from a CSV file (`path` relative to the scene folder) with the header
    /// `x,y,z,radius` and optionally `vx,vy,vz` (columns in any order), e.g. a settled bed
    /// written by `[dem.output] final_particles = true`. `keep` (optional) keeps only the
    /// spheres whose centre lies in the box {min = [..], max = [..]}, e.g. a settled bed cut at
    /// its nominal height (Ullrich ch. 6: particles with a centre above 0.8 m are removed).
    File {
        material: String,
        path: String,
        #[serde(default)]
        keep: Option<CentreBox>,
    },
}

fn default_seed() -> u64 {
    1
}

/// A box of particle centres, `{ min = [..], max = [..] }`, either bound optional (unbounded
/// on that side): what a particle file source keeps (`keep`), where a sink removes
/// (`[[dem.sinks]]`).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CentreBox {
    #[serde(default = "neg_inf3")]
    pub min: [f64; 3],
    #[serde(default = "pos_inf3")]
    pub max: [f64; 3],
}

fn neg_inf3() -> [f64; 3] {
    [f64::NEG_INFINITY; 3]
}
fn pos_inf3() -> [f64; 3] {
    [f64::INFINITY; 3]
}

impl CentreBox {
    /// Whether the centre `x` lies in the box (bounds included).
    pub fn contains(&self, x: [f64; 3]) -> bool {
        (0..3).all(|a| x[a] >= self.min[a] && x[a] <= self.max[a])
    }
}

/// `[[dem.walls]]`: a static wall.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum WallConfig {
    /// Infinite plane through `point`; particles live on the side `normal` points to.
    Plane {
        material: String,
        point: [f64; 3],
        normal: [f64; 3],
        #[serde(default)]
        motion: Option<WallMotion>,
        #[serde(default)]
        load: Option<WallLoad>,
        #[serde(default)]
        remove_at: Option<f64>,
    },
    /// Axis-aligned box [min, max] as a triangle mesh with inward normals; `open` lists the
    /// faces left out: any of "-x", "+x", "-y", "+y", "-z", "+z".
    Box {
        material: String,
        min: [f64; 3],
        max: [f64; 3],
        #[serde(default)]
        open: Vec<String>,
        #[serde(default)]
        motion: Option<WallMotion>,
        #[serde(default)]
        load: Option<WallLoad>,
        #[serde(default)]
        remove_at: Option<f64>,
    },
    /// A cylindrical wall about the z axis (e.g. the mould of a triaxial sample): bottom
    /// centre `centre`, `radius`, `height`, as `segments` flat facets (default 64) whose
    /// corners lie on the radius, facing the axis (particles live inside). No end caps.
    Cylinder {
        material: String,
        centre: [f64; 3],
        radius: f64,
        height: f64,
        #[serde(default = "default_segments")]
        segments: u32,
        #[serde(default)]
        motion: Option<WallMotion>,
        #[serde(default)]
        load: Option<WallLoad>,
        #[serde(default)]
        remove_at: Option<f64>,
    },
    /// Triangle mesh from an ASCII or binary STL file; `path` is relative to the scene file.
    /// Vertices are transformed as `scale · x + offset`.
    Stl {
        material: String,
        path: String,
        #[serde(default = "default_one")]
        scale: f64,
        #[serde(default)]
        offset: [f64; 3],
        #[serde(default)]
        motion: Option<WallMotion>,
        #[serde(default)]
        load: Option<WallLoad>,
        #[serde(default)]
        remove_at: Option<f64>,
    },
}

impl WallConfig {
    /// The wall's prescribed motion, load and removal time (`motion`, `load`, `remove_at`).
    pub fn kinematics(&self) -> (Option<&WallMotion>, Option<&WallLoad>, Option<f64>) {
        match self {
            WallConfig::Plane {
                motion,
                load,
                remove_at,
                ..
            }
            | WallConfig::Box {
                motion,
                load,
                remove_at,
                ..
            }
            | WallConfig::Stl {
                motion,
                load,
                remove_at,
                ..
            }
            | WallConfig::Cylinder {
                motion,
                load,
                remove_at,
                ..
            } => (motion.as_ref(), load.as_ref(), *remove_at),
        }
    }
}

/// Prescribed rigid translation of a wall during [`start`, `end`], at rest before and after
/// (`end` absent: moves until the end of the run): constant `velocity` plus an optional
/// oscillation, displacement u(τ) = velocity·τ + amplitude·sin(2π·frequency·τ), τ = t − start
/// (e.g. the seed's compaction plate, moving down onto the bed with a sine, fig. 6.5).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct WallMotion {
    /// Velocity in m/s.
    #[serde(default)]
    pub velocity: [f64; 3],
    /// Start time in s, default 0.
    #[serde(default)]
    pub start: f64,
    /// End time in s (> start), default: never stops.
    #[serde(default)]
    pub end: Option<f64>,
    /// Oscillation amplitude in m (a vector: the direction of the oscillation), default 0.
    #[serde(default)]
    pub amplitude: [f64; 3],
    /// Oscillation frequency in Hz (> 0 when an amplitude is given).
    #[serde(default)]
    pub frequency: f64,
    /// Further constant-velocity stages, each adding its own displacement
    /// `velocity·(min(t, end) − start)` from its `start` on (a strain path in phases: a
    /// triaxial sample's wall compressed isotropically, then sheared at another rate).
    #[serde(default)]
    pub then: Vec<MotionStage>,
    /// Report the wall in `dem_timeseries.csv` and the summary: `<name>.force_{x,y,z}` (the
    /// particles' contact forces on it, weighted at their contact points in a volume overlap)
    /// and `<name>.displacement_{x,y,z}`.
    #[serde(default)]
    pub name: Option<String>,
}

/// A stage of a wall's prescribed motion (`motion.then`): constant `velocity` in
/// [`start`, `end`).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MotionStage {
    /// Velocity in m/s.
    pub velocity: [f64; 3],
    /// Start time in s.
    pub start: f64,
    /// End time in s (> start), default: never stops.
    #[serde(default)]
    pub end: Option<f64>,
}

/// Force-controlled rigid translation of a wall along one axis (`[[dem.walls]] load`): the wall
/// is a body of `mass` that moves under the particles' contact forces, its weight and the
/// applied force F(τ) = force + amplitude·sin(2π·frequency·τ), τ = t − start. A compaction
/// plate run like the experiment's vibratory compactor (Ullrich §6.2, fig. 6.5): the plate
/// sinks as far as the bed gives way under the load instead of being pushed to a prescribed
/// depth, so the bed stores no more elastic energy than the load puts in. Held at rest before
/// `start`; from `end` on the applied force and the weight ramp linearly to zero over
/// `release` seconds (the plate is lifted off gently, the bed unloads), after which only the
/// contact forces act on the wall until it is removed (`remove_at`).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct WallLoad {
    /// Name of the wall's columns in dem_timeseries.csv (`<name>.displacement`, `.velocity`,
    /// `.contact_force`), default `wall<k>`.
    #[serde(default)]
    pub name: Option<String>,
    /// The axis the wall moves along (default z); forces are signed along +axis.
    #[serde(default = "default_axis_z")]
    pub axis: Axis,
    /// Mass in kg (> 0); gravity acts on it.
    pub mass: f64,
    /// Static applied force in N along +axis (e.g. negative to press down along z).
    #[serde(default)]
    pub force: f64,
    /// Amplitude of the harmonic force in N, default 0.
    #[serde(default)]
    pub amplitude: f64,
    /// Frequency of the harmonic force in Hz (> 0 when an amplitude is given).
    #[serde(default)]
    pub frequency: f64,
    /// Time the wall is released (s), default 0.
    #[serde(default)]
    pub start: f64,
    /// Time the applied force and the weight start to ramp down (s, > start), default: never.
    #[serde(default)]
    pub end: Option<f64>,
    /// Duration of the ramp-down of the applied force and the weight (s), default 0 (off at
    /// once).
    #[serde(default)]
    pub release: f64,
    /// Duration (s) over which the applied force rises linearly from 0 after `start`,
    /// default 0 (at once); the weight acts in full from `start`.
    #[serde(default)]
    pub ramp: f64,
    /// Strain control from a time on (default: none, force control throughout).
    #[serde(default)]
    pub drive: Option<WallDrive>,
}

fn default_segments() -> u32 {
    64
}

/// Strain control after stress control (`[[dem.walls]] load.drive`): from `start` on the
/// wall moves at `velocity` along the load's axis whatever the forces on it (a triaxial
/// test's platen: consolidated under a load, then sheared at a constant rate).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct WallDrive {
    /// Velocity in m/s along +axis.
    pub velocity: f64,
    /// Time in s (≥ the load's start).
    pub start: f64,
}

fn default_axis_z() -> Axis {
    Axis::Z
}

/// A coordinate axis (the normal of a sensor plane).
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum Axis {
    X,
    Y,
    Z,
}

impl Axis {
    /// Index of the axis (x = 0) and of the two in-plane coordinates in increasing order.
    pub fn indices(self) -> (usize, [usize; 2]) {
        match self {
            Axis::X => (0, [1, 2]),
            Axis::Y => (1, [0, 2]),
            Axis::Z => (2, [0, 1]),
        }
    }
}

/// `[[dem.sensors]]`: a measurement written to `dem_sensors.csv` and the results.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum SensorConfig {
    /// Net mass flow rate (kg/s) through the plane `axis = value` in the negative axis
    /// direction, optionally only inside the rectangle [`min`, `max`] of the two other
    /// coordinates (in increasing axis order: x → (y, z), y → (x, z), z → (x, y)).
    Flow {
        name: String,
        axis: Axis,
        value: f64,
        #[serde(default)]
        min: Option<[f64; 2]>,
        #[serde(default)]
        max: Option<[f64; 2]>,
    },
    /// Normal stress (Pa, compression positive) transmitted through the rectangle
    /// [`min`, `max`] of the plane `axis = value`.
    Pressure {
        name: String,
        axis: Axis,
        value: f64,
        min: [f64; 2],
        max: [f64; 2],
    },
    /// Angle of repose (degrees) of a heap around the vertical (z) axis through `centre`:
    /// highest particle top per radial bin of width `bin_width` (default: the mean particle
    /// diameter), least-squares line over `r_min` ≤ ρ ≤ `r_max`. With `along = "x"` (or "y")
    /// ρ is the distance |x − centre_x| along that axis instead: the slope of a wedge-shaped
    /// pile across the whole width, e.g. the pile left on a hand-slide after draining.
    Repose {
        name: String,
        centre: [f64; 2],
        r_min: f64,
        r_max: f64,
        #[serde(default)]
        bin_width: Option<f64>,
        #[serde(default)]
        along: Option<Axis>,
    },
}

impl SensorConfig {
    pub fn name(&self) -> &str {
        match self {
            SensorConfig::Flow { name, .. }
            | SensorConfig::Pressure { name, .. }
            | SensorConfig::Repose { name, .. } => name,
        }
    }
}

/// `[dem.output]`.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct OutputConfig {
    /// Write VTK files every this many steps (0 = never), checked in `write_outputs`.
    #[serde(default)]
    pub vtk_every: u64,
    /// Append a row to `dem_timeseries.csv` at every `write_outputs` call.
    #[serde(default = "default_true")]
    pub csv: bool,
    /// Write `particles_final.csv` (the `kind = "file"` format) at the end of the run.
    #[serde(default)]
    pub final_particles: bool,
}

impl Default for OutputConfig {
    fn default() -> Self {
        OutputConfig {
            vtk_every: 0,
            csv: true,
            final_particles: false,
        }
    }
}

/// A path into the TOML document: keys and array indices.
pub(crate) use scenefile::{path_string, Seg};

#[derive(Debug, Clone)]
pub(crate) struct ValueError {
    pub path: Vec<Seg>,
    pub message: String,
}

struct Check {
    errors: Vec<ValueError>,
}

impl Check {
    fn fail(&mut self, path: Vec<Seg>, message: String) {
        let message = format!("{}: {}", path_string(&path), message);
        self.errors.push(ValueError { path, message });
    }
    fn positive(&mut self, path: Vec<Seg>, v: f64) {
        if !(v.is_finite() && v > 0.0) {
            self.fail(path, format!("must be a finite number > 0, got {v}"));
        }
    }
    /// A source's `shape` (`base` is the path of the source).
    fn shape(&mut self, base: &[Seg], shape: &ShapeConfig) {
        if let ShapeConfig::Polyhedron {
            triangles,
            elongation,
            dilation,
            stones,
            library,
            ..
        } = shape
        {
            let f = |field: &str| {
                let mut v = base.to_vec();
                v.push(Seg::Key("shape".into()));
                v.push(Seg::Key(field.into()));
                v
            };
            if *triangles < 4 || triangles % 2 != 0 || *triangles > 1000 {
                self.fail(
                    f("triangles"),
                    format!(
                        "a closed convex core has an even number of triangles >= 4 (<= 1000), \
                         got {triangles}"
                    ),
                );
            }
            if !(elongation.is_finite() && *elongation >= 1.0 && *elongation <= 100.0) {
                self.fail(
                    f("elongation"),
                    format!("must be in [1, 100] (largest to smallest axis), got {elongation}"),
                );
            }
            let max = crate::shape::polyhedron::DILATION_MAX;
            if !(dilation.is_finite() && *dilation > 0.0 && *dilation <= max) {
                self.fail(
                    f("dilation"),
                    format!(
                        "the dilation radius as a fraction of the size must be in (0, {max}] \
                         (Ullrich: 0.1), got {dilation}"
                    ),
                );
            }
            if *stones == 0 || *stones > 100_000 {
                self.fail(f("stones"), format!("must be in [1, 100000], got {stones}"));
            }
            if library.as_ref().is_some_and(|l| l.is_empty()) {
                self.fail(f("library"), "is empty: give STL files or remove it".into());
            }
            return;
        }
        let ShapeConfig::Superquadric {
            semi_axes,
            aspect,
            elongation,
            exponents,
            angularity,
            exponent_range,
            ..
        } = shape
        else {
            return;
        };
        let f = |field: &str| {
            let mut v = base.to_vec();
            v.push(Seg::Key("shape".into()));
            v.push(Seg::Key(field.into()));
            v
        };
        use crate::shape::superquadric::{EXPONENT_MAX, EXPONENT_MIN};
        let sizes = [semi_axes.is_some(), aspect.is_some(), elongation.is_some()];
        if sizes.iter().filter(|x| **x).count() > 1 {
            self.fail(
                f("elongation"),
                "give one of `semi_axes`, `aspect` and `elongation`, not two".into(),
            );
        }
        if let Some(axes) = semi_axes {
            for (k, d) in axes.iter().enumerate() {
                let mut path = f("semi_axes");
                path.push(Seg::Index(k));
                self.size_distribution(path, d);
            }
        }
        if let Some(a) = aspect {
            if !a.iter().all(|r| r.is_finite() && *r > 0.0) {
                self.fail(
                    f("aspect"),
                    format!("ratios must be finite and > 0, got {a:?}"),
                );
            }
        }
        if let Some(e) = elongation {
            if !(e.is_finite() && *e >= 1.0 && *e <= 100.0) {
                self.fail(
                    f("elongation"),
                    format!("must be >= 1 (largest ratio of semi-axes) and <= 100, got {e}"),
                );
            }
        }
        if exponents.is_some() && angularity.is_some() {
            self.fail(
                f("angularity"),
                "give `exponents` or `angularity`, not both".into(),
            );
        }
        let range = format!(
            "the convex range [{EXPONENT_MIN}, {EXPONENT_MAX}] (ε → 0 is a cuboid and ε = 2 an \
             octahedron, bodies with edges where the contact normal is undefined)"
        );
        if let Some(e) = exponents {
            if !e.iter().all(|x| (EXPONENT_MIN..=EXPONENT_MAX).contains(x)) {
                self.fail(f("exponents"), format!("must lie in {range}, got {e:?}"));
            }
        }
        if let Some(e) = exponent_range {
            if !(e.iter().all(|x| (EXPONENT_MIN..=EXPONENT_MAX).contains(x)) && e[0] <= e[1]) {
                self.fail(
                    f("exponent_range"),
                    format!("must be [lo, hi] with lo <= hi in {range}, got {e:?}"),
                );
            }
        }
        if let Some(a) = angularity {
            let limit = (1.0 - EXPONENT_MIN).min(EXPONENT_MAX - 1.0);
            if !(a.is_finite() && *a >= 0.0 && *a <= limit) {
                self.fail(
                    f("angularity"),
                    format!(
                        "must be in [0, {}] so that 1 ± angularity stays in {range}, got {a}",
                        format_number(limit)
                    ),
                );
            }
        }
    }
    /// A radius distribution at `path`.
    fn size_distribution(&mut self, path: Vec<Seg>, distribution: &SizeDistribution) {
        let c = self;
        let d = |field: &str| {
            let mut v = path.clone();
            v.push(Seg::Key(field.into()));
            v
        };
        match distribution {
            SizeDistribution::Constant { radius } => c.positive(d("radius"), *radius),
            SizeDistribution::Uniform { min, max } => {
                c.positive(d("min"), *min);
                if !(max >= min && max.is_finite()) {
                    c.fail(d("max"), format!("must be >= min = {min}, got {max}"));
                }
            }
            SizeDistribution::Normal {
                mean,
                std_dev,
                min,
                max,
            } => {
                c.positive(d("mean"), *mean);
                c.non_negative(d("std_dev"), *std_dev);
                c.positive(d("min"), *min);
                if !(max >= min && max.is_finite()) {
                    c.fail(d("max"), format!("must be >= min = {min}, got {max}"));
                }
            }
            SizeDistribution::Table { radius, cumulative } => {
                if radius.len() < 2 || radius.len() != cumulative.len() {
                    c.fail(
                        d("cumulative"),
                        "needs >= 2 entries and as many as `radius`".into(),
                    );
                } else {
                    if radius[0].partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)
                        || radius.iter().any(|r| !r.is_finite())
                        || radius.windows(2).any(|w| w[1] < w[0])
                    {
                        c.fail(
                            d("radius"),
                            format!(
                                "must be finite, > 0 and non-decreasing, got \
                                 {radius:?}"
                            ),
                        );
                    }
                    if cumulative[0] != 0.0
                        || cumulative.iter().any(|c| !c.is_finite())
                        || *cumulative.last().unwrap() != 1.0
                        || cumulative.windows(2).any(|w| w[1] < w[0])
                    {
                        c.fail(
                            d("cumulative"),
                            "must rise from 0 to 1 (non-decreasing)".into(),
                        );
                    }
                }
            }
        }
    }
    fn non_negative(&mut self, path: Vec<Seg>, v: f64) {
        if !(v.is_finite() && v >= 0.0) {
            self.fail(path, format!("must be a finite number >= 0, got {v}"));
        }
    }
    /// A box's `max` exceeds its `min` on every axis (NaN fails too).
    fn box_max(&mut self, path: Vec<Seg>, min: &[f64; 3], max: &[f64; 3]) {
        if (0..3).any(|a| max[a].partial_cmp(&min[a]) != Some(std::cmp::Ordering::Greater)) {
            self.fail(
                path,
                format!("must exceed min {min:?} on every axis, got {max:?}"),
            );
        }
    }
    /// A name that becomes a CSV column / result key: letters, digits, `_`, `-`. Returns
    /// whether it is one.
    fn column_name(&mut self, path: Vec<Seg>, name: &str) -> bool {
        let ok = !name.is_empty()
            && name
                .chars()
                .all(|ch| ch.is_ascii_alphanumeric() || ch == '_' || ch == '-');
        if !ok {
            self.fail(
                path,
                format!("must be non-empty letters, digits, `_` or `-`, got `{name}`"),
            );
        }
        ok
    }
    /// An oscillation's frequency: ≥ 0, and > 0 when it has an amplitude (`amplitude` as
    /// written in the message).
    fn frequency(&mut self, path: Vec<Seg>, frequency: f64, oscillates: bool, amplitude: &str) {
        if oscillates && frequency.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            self.fail(
                path,
                format!("must be > 0 (Hz) with an amplitude {amplitude}, got {frequency}"),
            );
        } else {
            self.non_negative(path, frequency);
        }
    }
    fn finite3(&mut self, path: Vec<Seg>, v: &[f64; 3]) {
        if v.iter().any(|x| !x.is_finite()) {
            self.fail(path, format!("must be finite, got {v:?}"));
        }
    }
    fn restitution(&mut self, path: Vec<Seg>, v: f64) {
        if !(v > 0.0 && v <= 1.0) {
            self.fail(path, format!("must satisfy 0 < e <= 1, got {v}"));
        }
    }
    fn material(&mut self, path: Vec<Seg>, name: &str, cfg: &DemConfig) {
        if !cfg.materials.contains_key(name) {
            let known: Vec<&str> = cfg.materials.keys().map(|s| s.as_str()).collect();
            self.fail(path, format!("unknown material `{name}`, known: {known:?}"));
        }
    }
}

fn p(parts: &[&str]) -> Vec<Seg> {
    parts.iter().map(|s| Seg::Key(s.to_string())).collect()
}

fn pi(parts: &[&str], index: usize, rest: &[&str]) -> Vec<Seg> {
    let mut v = p(parts);
    v.push(Seg::Index(index));
    v.extend(rest.iter().map(|s| Seg::Key(s.to_string())));
    v
}

impl DemConfig {
    /// Checks value ranges; errors name the field path (`dem.materials.wheat.poisson_ratio`).
    pub(crate) fn validate_values(&self) -> Vec<ValueError> {
        let mut c = Check { errors: Vec::new() };
        c.positive(p(&["dem", "time_step"]), self.time_step);
        c.finite3(p(&["dem", "gravity"]), &self.gravity);
        if !(self.rayleigh_fraction > 0.0 && self.rayleigh_fraction <= 1.0) {
            // above 1 the check would pass time steps beyond the Rayleigh step itself; that
            // is what `allow_large_time_step` is for
            c.fail(
                p(&["dem", "rayleigh_fraction"]),
                format!(
                    "must satisfy 0 < fraction <= 1 (use allow_large_time_step to run beyond \
                     the Rayleigh step), got {}",
                    self.rayleigh_fraction
                ),
            );
        }
        if let Some(s) = self.skin {
            c.positive(p(&["dem", "skin"]), s);
        }
        if !(self.superquadric_surface_budget > 0.0 && self.superquadric_surface_budget <= 1e6) {
            c.fail(
                p(&["dem", "superquadric_surface_budget"]),
                format!(
                    "must satisfy 0 < budget <= 1e6 (a multiple of the default linearisation \
                     error), got {}",
                    self.superquadric_surface_budget
                ),
            );
        }
        if !(1..=MAX_IMPACT_SUBSTEPS).contains(&self.impact_substeps) {
            c.fail(
                p(&["dem", "impact_substeps"]),
                format!(
                    "must be in 1..={MAX_IMPACT_SUBSTEPS}, got {}",
                    self.impact_substeps
                ),
            );
        }
        let vc = &self.volume_coupling;
        if !(vc.min_weight > 0.0 && vc.min_weight <= 1.0) {
            c.fail(
                p(&["dem", "volume_coupling", "min_weight"]),
                format!("must be in (0, 1], got {}", vc.min_weight),
            );
        }
        if vc.max_drift.is_nan() || vc.max_drift < 0.0 {
            c.fail(
                p(&["dem", "volume_coupling", "max_drift"]),
                format!("must be >= 0, got {}", vc.max_drift),
            );
        }
        match self.threads {
            Some(0) => c.fail(p(&["dem", "threads"]), "must be >= 1".into()),
            Some(n) if n > crate::resources::max_threads() => c.fail(
                p(&["dem", "threads"]),
                format!(
                    "{n} threads is more than this machine can use: at most {} (4 x the {} \
                     cores available, never more than {})",
                    crate::resources::max_threads(),
                    std::thread::available_parallelism().map_or(1, |n| n.get()),
                    crate::resources::MAX_THREADS
                ),
            ),
            _ => {}
        }
        if self.materials.is_empty() {
            c.fail(
                p(&["dem", "materials"]),
                "at least one material is required".into(),
            );
        }
        for (name, m) in &self.materials {
            let f = |field: &str| p(&["dem", "materials", name, field]);
            c.positive(f("youngs_modulus"), m.youngs_modulus);
            if !(m.poisson_ratio >= 0.0 && m.poisson_ratio < 0.5) {
                c.fail(
                    f("poisson_ratio"),
                    format!("must satisfy 0 <= nu < 0.5, got {}", m.poisson_ratio),
                );
            }
            c.positive(f("density"), m.density);
            c.restitution(f("restitution"), m.restitution);
            c.non_negative(f("friction"), m.friction);
            c.non_negative(f("rolling_friction"), m.rolling_friction);
            if let Some(k) = m.normal_stiffness {
                c.positive(f("normal_stiffness"), k);
            }
        }
        // the linear law is the scene's, not a pair's: a Hertz material touching a linear one
        // would have no defined contact
        let linear: Vec<&String> = (self.materials.iter())
            .filter(|(_, m)| m.normal_stiffness.is_some())
            .map(|(n, _)| n)
            .collect();
        if !linear.is_empty() {
            if let Some((name, _)) =
                (self.materials.iter()).find(|(_, m)| m.normal_stiffness.is_none())
            {
                c.fail(
                    p(&["dem", "materials", name, "normal_stiffness"]),
                    format!(
                        "missing: material '{}' has a linear contact spring (normal_stiffness),                          so every material needs one (the contact law is the scene's)",
                        linear[0]
                    ),
                );
            }
            for (k, src) in self.particles.iter().enumerate() {
                let shape = match src {
                    ParticleSource::List { shape, .. }
                    | ParticleSource::Lattice { shape, .. }
                    | ParticleSource::Fill { shape, .. } => shape,
                    ParticleSource::File { .. } => continue,
                };
                if !shape.is_sphere() {
                    c.fail(
                        pi(&["dem", "particles"], k, &["shape"]),
                        "the linear contact law (materials' normal_stiffness) is for spheres only; shaped particles use their own laws"
                            .into(),
                    );
                }
            }
        }
        for (k, ia) in self.interactions.iter().enumerate() {
            for name in &ia.materials {
                c.material(pi(&["dem", "interactions"], k, &["materials"]), name, self);
            }
            if let Some(v) = ia.friction {
                c.non_negative(pi(&["dem", "interactions"], k, &["friction"]), v);
            }
            if let Some(v) = ia.restitution {
                c.restitution(pi(&["dem", "interactions"], k, &["restitution"]), v);
            }
            if let Some(v) = ia.rolling_friction {
                c.non_negative(pi(&["dem", "interactions"], k, &["rolling_friction"]), v);
            }
            if ia.restitution.is_some()
                && (ia.damping_ratio.is_some() || ia.viscoelastic_time.is_some())
            {
                c.fail(
                    pi(&["dem", "interactions"], k, &["restitution"]),
                    "`restitution` calibrates the dashpot that `damping_ratio` / \
                     `viscoelastic_time` replace: give one of them"
                        .into(),
                );
            }
            match (ia.damping_ratio, ia.viscoelastic_time) {
                (Some(_), Some(_)) => c.fail(
                    pi(&["dem", "interactions"], k, &["viscoelastic_time"]),
                    "give `damping_ratio` or `viscoelastic_time`, not both".into(),
                ),
                (Some(z), None) => {
                    c.non_negative(pi(&["dem", "interactions"], k, &["damping_ratio"]), z)
                }
                (None, Some(a)) => {
                    c.non_negative(pi(&["dem", "interactions"], k, &["viscoelastic_time"]), a)
                }
                (None, None) => {}
            }
        }
        if let Some(m) = &self.interface_material {
            c.material(p(&["dem", "interface_material"]), m, self);
        }
        for (k, src) in self.particles.iter().enumerate() {
            let f = |field: &str| pi(&["dem", "particles"], k, &[field]);
            match src {
                ParticleSource::List {
                    material,
                    spheres,
                    shape,
                } => {
                    c.material(f("material"), material, self);
                    c.shape(&pi(&["dem", "particles"], k, &[]), shape);
                    for (s, sp) in spheres.iter().enumerate() {
                        let g = |field: &str| {
                            let mut v = f("spheres");
                            v.push(Seg::Index(s));
                            v.push(Seg::Key(field.into()));
                            v
                        };
                        c.positive(g("radius"), sp.radius);
                        c.finite3(g("position"), &sp.position);
                        c.finite3(g("velocity"), &sp.velocity);
                        c.finite3(g("angular_velocity"), &sp.angular_velocity);
                        if let Some(q) = sp.orientation {
                            let norm = q.iter().map(|x| x * x).sum::<f64>().sqrt();
                            if !(norm.is_finite() && norm > 0.0) {
                                c.fail(
                                    g("orientation"),
                                    format!("must be a finite non-zero quaternion [w, x, y, z], got {q:?}"),
                                );
                            } else if shape.is_sphere() {
                                c.fail(
                                    g("orientation"),
                                    "a sphere has no orientation (give the source a `shape`)"
                                        .into(),
                                );
                            }
                        }
                    }
                    // spheres written twice (or nearly): as for particle files (the bounding
                    // spheres of superquadrics may overlap: the engine checks those)
                    let as_file: Vec<crate::particle_file::FileParticle> = spheres
                        .iter()
                        .enumerate()
                        .map(|(s, sp)| {
                            crate::particle_file::FileParticle::sphere(
                                sp.position.into(),
                                sp.radius,
                                sp.velocity.into(),
                                s,
                            )
                        })
                        .collect();
                    let overlap = if shape.is_sphere() {
                        crate::particle_file::find_overlap(
                            &as_file,
                            crate::particle_file::MAX_FILE_OVERLAP,
                        )
                    } else {
                        None
                    };
                    if let Some((a, b, fraction)) = overlap {
                        let mut at = f("spheres");
                        at.push(Seg::Index(b));
                        c.fail(
                            at,
                            format!(
                                "spheres {a} and {b} overlap by {} of the smaller radius (at most {} is accepted): a sphere written twice?",
                                format_number(fraction),
                                crate::particle_file::MAX_FILE_OVERLAP
                            ),
                        );
                    }
                }
                ParticleSource::Lattice {
                    material,
                    radius,
                    first,
                    spacing,
                    count,
                    velocity,
                    jitter,
                    shape,
                    ..
                } => {
                    c.material(f("material"), material, self);
                    c.shape(&pi(&["dem", "particles"], k, &[]), shape);
                    c.positive(f("radius"), *radius);
                    c.finite3(f("first"), first);
                    c.finite3(f("velocity"), velocity);
                    c.non_negative(f("jitter"), *jitter);
                    if !(spacing.is_finite() && *spacing >= 2.0 * radius) {
                        c.fail(
                            f("spacing"),
                            format!(
                                "must be >= 2 * radius = {} m, got {}",
                                format_number(2.0 * radius),
                                format_number(*spacing)
                            ),
                        );
                    } else if *jitter > 0.0 && 2.0 * jitter > spacing - 2.0 * radius {
                        // neighbours along x or y may approach each other by 2·jitter
                        c.fail(
                            f("jitter"),
                            format!(
                                "must be <= (spacing - 2 * radius) / 2 = {} m so that jittered \
                                 spheres cannot overlap, got {}",
                                format_number((spacing - 2.0 * radius) / 2.0),
                                format_number(*jitter)
                            ),
                        );
                    }
                    if count.contains(&0) {
                        c.fail(
                            f("count"),
                            format!("all counts must be >= 1, got {count:?}"),
                        );
                    }
                }
                ParticleSource::Fill {
                    material,
                    min,
                    max,
                    count,
                    mass,
                    distribution,
                    velocity,
                    shape,
                    radius,
                    ..
                } => {
                    c.material(f("material"), material, self);
                    c.shape(&pi(&["dem", "particles"], k, &[]), shape);
                    for (name, v) in [("min", min), ("max", max)] {
                        match v {
                            Some(v) => c.finite3(f(name), v),
                            // a periodic fill fills its cell (checked with the cell)
                            None if self.periodic.is_some() => {}
                            None => c.fail(
                                f(name),
                                "missing: a fill needs the box it fills, `min = [x, y, z]` and \
                                 `max = [x, y, z]` (m); only a fill of a periodic cell may leave \
                                 them out"
                                    .into(),
                            ),
                        }
                    }
                    if let Some(r) = radius {
                        c.positive(f("radius"), *r);
                    }
                    c.finite3(f("velocity"), velocity);
                    if let (Some(min), Some(max)) = (min, max) {
                        c.box_max(f("max"), min, max);
                    }
                    match (count, mass) {
                        (Some(0), None) => c.fail(f("count"), "must be >= 1".into()),
                        (Some(_), None) => {}
                        (None, Some(m)) => c.positive(f("mass"), *m),
                        _ => c.fail(f("count"), "give exactly one of `count` and `mass`".into()),
                    }
                    let with_axes = matches!(
                        shape,
                        ShapeConfig::Superquadric {
                            semi_axes: Some(_),
                            ..
                        }
                    );
                    match (distribution, with_axes) {
                        (Some(d), false) => c.size_distribution(f("distribution"), d),
                        (None, false) => c.fail(
                            f("distribution"),
                            "missing: give the radius distribution (or the shape's `semi_axes`)"
                                .into(),
                        ),
                        (Some(_), true) => c.fail(
                            f("distribution"),
                            "the size comes from `shape.semi_axes`: remove `distribution`".into(),
                        ),
                        (None, true) => {}
                    }
                }
                ParticleSource::File {
                    material,
                    path,
                    keep,
                } => {
                    c.material(f("material"), material, self);
                    if path.is_empty() {
                        c.fail(f("path"), "must name a CSV file".into());
                    }
                    if let Some(k) = keep {
                        c.box_max(f("keep"), &k.min, &k.max);
                    }
                }
            }
        }
        for (k, w) in self.walls.iter().enumerate() {
            let f = |field: &str| pi(&["dem", "walls"], k, &[field]);
            match w {
                WallConfig::Plane {
                    material,
                    point,
                    normal,
                    ..
                } => {
                    c.material(f("material"), material, self);
                    c.finite3(f("point"), point);
                    let n2: f64 = normal.iter().map(|x| x * x).sum();
                    if !(n2.is_finite() && n2 > 0.0) {
                        c.fail(
                            f("normal"),
                            format!("must be a non-zero vector, got {normal:?}"),
                        );
                    }
                }
                WallConfig::Box {
                    material,
                    min,
                    max,
                    open,
                    ..
                } => {
                    c.material(f("material"), material, self);
                    c.finite3(f("min"), min);
                    c.finite3(f("max"), max);
                    c.box_max(f("max"), min, max);
                    for o in open {
                        if !["-x", "+x", "-y", "+y", "-z", "+z"].contains(&o.as_str()) {
                            c.fail(
                                f("open"),
                                format!("unknown face `{o}`, expected one of -x +x -y +y -z +z"),
                            );
                        }
                    }
                }
                WallConfig::Stl {
                    material,
                    scale,
                    offset,
                    ..
                } => {
                    c.material(f("material"), material, self);
                    c.positive(f("scale"), *scale);
                    c.finite3(f("offset"), offset);
                }
                WallConfig::Cylinder {
                    material,
                    centre,
                    radius,
                    height,
                    segments,
                    ..
                } => {
                    c.material(f("material"), material, self);
                    c.finite3(f("centre"), centre);
                    c.positive(f("radius"), *radius);
                    c.positive(f("height"), *height);
                    if !(8..=100_000).contains(segments) {
                        c.fail(
                            f("segments"),
                            format!("must lie in [8, 100000], got {segments}"),
                        );
                    }
                }
            }
            let (motion, load, remove_at) = w.kinematics();
            if let Some(l) = load {
                let g = |field: &str| pi(&["dem", "walls"], k, &["load", field]);
                if motion.is_some() {
                    c.fail(
                        f("load"),
                        "a wall has either a prescribed `motion` or a `load`, not both".into(),
                    );
                }
                c.positive(g("mass"), l.mass);
                for (field, v) in [("force", l.force), ("amplitude", l.amplitude)] {
                    if !v.is_finite() {
                        c.fail(g(field), format!("must be finite (N), got {v}"));
                    }
                }
                let amplitude = l.amplitude.to_string();
                c.frequency(g("frequency"), l.frequency, l.amplitude != 0.0, &amplitude);
                c.non_negative(g("start"), l.start);
                c.non_negative(g("release"), l.release);
                c.non_negative(g("ramp"), l.ramp);
                if let Some(d) = &l.drive {
                    let h = |field: &str| pi(&["dem", "walls"], k, &["load", "drive", field]);
                    if !d.velocity.is_finite() {
                        c.fail(
                            h("velocity"),
                            format!("must be finite (m/s), got {}", d.velocity),
                        );
                    }
                    if !(d.start.is_finite() && d.start >= l.start) {
                        c.fail(
                            h("start"),
                            format!(
                                "must be ≥ the load's start ({} s), got {}",
                                l.start, d.start
                            ),
                        );
                    }
                }
                if let Some(end) = l.end {
                    if !(end.is_finite() && end > l.start) {
                        c.fail(
                            g("end"),
                            format!("must be finite and > start = {}, got {end}", l.start),
                        );
                    }
                }
                if let Some(name) = &l.name {
                    c.column_name(g("name"), name);
                }
            }
            if let Some(m) = motion {
                let g = |field: &str| pi(&["dem", "walls"], k, &["motion", field]);
                c.finite3(g("velocity"), &m.velocity);
                c.finite3(g("amplitude"), &m.amplitude);
                let amplitude = format!("{:?}", m.amplitude);
                let oscillates = m.amplitude.iter().any(|a| *a != 0.0);
                c.frequency(g("frequency"), m.frequency, oscillates, &amplitude);
                c.non_negative(g("start"), m.start);
                if let Some(end) = m.end {
                    if !(end.is_finite() && end > m.start) {
                        c.fail(
                            g("end"),
                            format!("must be finite and > start = {}, got {end}", m.start),
                        );
                    }
                }
                for (j, st) in m.then.iter().enumerate() {
                    let g = |field: &str| {
                        pi(
                            &["dem", "walls"],
                            k,
                            &["motion", &format!("then[{j}]"), field],
                        )
                    };
                    c.finite3(g("velocity"), &st.velocity);
                    c.non_negative(g("start"), st.start);
                    if let Some(end) = st.end {
                        if !(end.is_finite() && end > st.start) {
                            c.fail(
                                g("end"),
                                format!("must be finite and > start = {}, got {end}", st.start),
                            );
                        }
                    }
                }
                if let Some(name) = &m.name {
                    c.column_name(g("name"), name);
                }
            }
            if let Some(t) = remove_at {
                c.non_negative(f("remove_at"), t);
            }
        }
        // the walls' report columns (`load.name`, default wall<k>, and `motion.name`)
        let mut wall_names: Vec<(String, Vec<Seg>)> = Vec::new();
        for (k, w) in self.walls.iter().enumerate() {
            let (motion, load, _) = w.kinematics();
            let named = match (motion, load) {
                (_, Some(l)) => Some((
                    l.name.clone().unwrap_or_else(|| format!("wall{k}")),
                    pi(&["dem", "walls"], k, &["load", "name"]),
                )),
                (Some(m), None) => m
                    .name
                    .clone()
                    .map(|n| (n, pi(&["dem", "walls"], k, &["motion", "name"]))),
                _ => None,
            };
            if let Some((name, field)) = named {
                if let Some((_, first)) = wall_names.iter().find(|(n, _)| *n == name) {
                    let first = scenefile::path_string(first);
                    c.fail(field, format!("'{name}' already names the wall of {first}"));
                } else {
                    wall_names.push((name, field));
                }
            }
        }
        self.check_particle_counts(&mut c);
        let mut names: Vec<&str> = Vec::new();
        for (k, s) in self.sinks.iter().enumerate() {
            c.box_max(pi(&["dem", "sinks"], k, &["max"]), &s.min, &s.max);
            if s.min.iter().chain(&s.max).all(|x| x.is_infinite()) {
                c.fail(
                    pi(&["dem", "sinks"], k, &[]),
                    "a sink needs a bound (`min` or `max`): without one it removes every particle"
                        .into(),
                );
            }
        }
        for (k, s) in self.sensors.iter().enumerate() {
            let f = |field: &str| pi(&["dem", "sensors"], k, &[field]);
            let name = s.name();
            if c.column_name(f("name"), name) && names.contains(&name) {
                c.fail(f("name"), format!("duplicate sensor name `{name}`"));
            }
            names.push(name);
            let rectangle = |c: &mut Check, min: &[f64; 2], max: &[f64; 2]| {
                if min.iter().chain(max).any(|x| !x.is_finite()) {
                    c.fail(f("min"), format!("must be finite, got {min:?} .. {max:?}"));
                } else if (0..2).any(|a| max[a] <= min[a]) {
                    c.fail(
                        f("max"),
                        format!("must exceed min {min:?} in both coordinates, got {max:?}"),
                    );
                }
            };
            match s {
                SensorConfig::Flow {
                    value, min, max, ..
                } => {
                    if !value.is_finite() {
                        c.fail(f("value"), format!("must be finite, got {value}"));
                    }
                    match (min, max) {
                        (None, None) => {}
                        (Some(lo), Some(hi)) => rectangle(&mut c, lo, hi),
                        _ => c.fail(f("min"), "give both `min` and `max`, or neither".into()),
                    }
                }
                SensorConfig::Pressure {
                    value, min, max, ..
                } => {
                    if !value.is_finite() {
                        c.fail(f("value"), format!("must be finite, got {value}"));
                    }
                    rectangle(&mut c, min, max);
                }
                SensorConfig::Repose {
                    centre,
                    r_min,
                    r_max,
                    bin_width,
                    along,
                    ..
                } => {
                    if centre.iter().any(|x| !x.is_finite()) {
                        c.fail(f("centre"), format!("must be finite, got {centre:?}"));
                    }
                    c.non_negative(f("r_min"), *r_min);
                    if !(r_max.is_finite() && r_max > r_min) {
                        c.fail(
                            f("r_max"),
                            format!("must be > r_min = {r_min}, got {r_max}"),
                        );
                    }
                    if let Some(w) = bin_width {
                        c.positive(f("bin_width"), *w);
                    }
                    if *along == Some(Axis::Z) {
                        c.fail(
                            f("along"),
                            "must be a horizontal axis, \"x\" or \"y\", got \"z\"".into(),
                        );
                    }
                }
            }
        }
        if let Some(cell) = &self.periodic {
            self.validate_periodic(cell, &mut c);
        }
        c.errors
    }

    fn validate_periodic(&self, cell: &crate::periodic::PeriodicConfig, c: &mut Check) {
        let f = |field: &str| p(&["dem", "periodic", field]);
        for (a, l) in cell.size.iter().enumerate() {
            c.positive(pi(&["dem", "periodic", "size"], a, &[]), *l);
        }
        c.positive(f("inertial_number"), cell.inertial_number);
        if let Some(t) = cell.wall_thickness {
            c.positive(f("wall_thickness"), t);
        }
        c.non_negative(f("servo_damping"), cell.servo_damping);
        c.positive(f("servo_modulus"), cell.servo_modulus);
        if !(cell.tolerance > 0.0 && cell.tolerance < 1.0) {
            c.fail(
                f("tolerance"),
                format!("must satisfy 0 < tolerance < 1, got {}", cell.tolerance),
            );
        }
        // the cell's faces are its only boundaries
        let refuse = |c: &mut Check, what: &str, path: Vec<Seg>| {
            c.fail(
                path,
                format!(
                    "a periodic cell ([dem.periodic]) has no {what}: its faces are periodic; \
                     remove it"
                ),
            )
        };
        if !self.walls.is_empty() {
            refuse(c, "walls", p(&["dem", "walls"]));
        }
        if !self.sinks.is_empty() {
            refuse(c, "sinks", p(&["dem", "sinks"]));
        }
        if !self.sensors.is_empty() {
            refuse(c, "sensors", p(&["dem", "sensors"]));
        }
        if self.impact_substeps > 1 {
            c.fail(
                p(&["dem", "impact_substeps"]),
                format!(
                    "must be 1 in a periodic cell (the impact refinement does not see the \
                     contacts across its faces), got {}",
                    self.impact_substeps
                ),
            );
        }
        if cell.stages.is_empty() {
            c.fail(
                p(&["dem", "periodic", "stages"]),
                "a periodic cell needs at least one `[[dem.periodic.stages]]` (the run ends \
                 when they are done)"
                    .into(),
            );
        }
        if self.interface_material.is_some() {
            refuse(c, "coupled meshes", p(&["dem", "interface_material"]));
        }
        if self.gravity.iter().any(|g| *g != 0.0) {
            c.fail(
                p(&["dem", "gravity"]),
                format!(
                    "must be [0, 0, 0] in a periodic cell (every image would fall with its \
                     body: nothing holds the packing), got {:?}",
                    self.gravity
                ),
            );
        }
        for (k, src) in self.particles.iter().enumerate() {
            if let ParticleSource::Fill {
                min, max, radius, ..
            } = src
            {
                let field = if min.is_some_and(|m| m != [0.0; 3]) {
                    Some("min")
                } else if max.is_some_and(|m| m != cell.size) {
                    Some("max")
                } else if radius.is_some() {
                    Some("radius")
                } else {
                    None
                };
                if let Some(field) = field {
                    c.fail(
                        pi(&["dem", "particles"], k, &[field]),
                        format!(
                            "a fill of a periodic cell fills the whole cell: min = [0, 0, 0], \
                             max = size = {:?} (or leave both out), no radius (got min {}, max {})",
                            cell.size,
                            min.map_or("none".into(), |m| format!("{m:?}")),
                            max.map_or("none".into(), |m| format!("{m:?}")),
                        ),
                    );
                }
            }
        }
        for (k, st) in cell.stages.iter().enumerate() {
            let sf = |field: &str| pi(&["dem", "periodic", "stages"], k, &[field]);
            for a in 0..3 {
                let axis = ["x", "y", "z"][a];
                match (st.stress.get(a), st.strain.get(a)) {
                    (Some(_), Some(_)) => c.fail(
                        pi(&["dem", "periodic", "stages"], k, &["strain", axis]),
                        format!(
                             "axis {axis} is stress-controlled in this stage already (stress.{axis}); \
                             an axis has one control"
                        ),
                    ),
                    (Some(t), None) if !(t.is_finite() && t < 0.0) => c.fail(
                        pi(&["dem", "periodic", "stages"], k, &["stress", axis]),
                        format!(
                             "must be a finite compressive stress < 0 (Pa, tension positive: \
                             -1e3 presses with 1 kPa), got {t}"
                        ),
                    ),
                    (None, Some(e)) if !(e.is_finite() && e != 0.0 && e > -1.0) => c.fail(
                        pi(&["dem", "periodic", "stages"], k, &["strain", axis]),
                        format!("must be a finite strain > -1 and not 0, got {e}"),
                    ),
                    _ => {}
                }
            }
            if (0..3).all(|a| st.stress.get(a).is_none() && st.strain.get(a).is_none()) {
                c.fail(
                    pi(&["dem", "periodic", "stages"], k, &[]),
                    "drives no axis: give `stress = { x = .., .. }` and/or \
                     `strain = { z = .. }` (a stage ends when their targets are met)"
                        .into(),
                );
            }
            if let Some(m) = st.friction {
                c.non_negative(sf("friction"), m);
            }
            if let Some(r) = st.max_strain_rate {
                c.positive(sf("max_strain_rate"), r);
            }
            if let Some(r) = st.ramp {
                if !(r.is_finite() && r > 0.0 && r < 1.0) {
                    c.fail(
                        sf("ramp"),
                        format!("must be a strain in (0, 1), e.g. 0.005, got {r}"),
                    );
                }
            }
            if let Some(r) = st.strain_rate {
                c.positive(sf("strain_rate"), r);
                if (0..3).all(|a| st.strain.get(a).is_none()) {
                    c.fail(
                        sf("strain_rate"),
                        "is the rate of strain-controlled axes; this stage has none (give \
                         `strain = { .. }`)"
                            .into(),
                    );
                }
            }
            if let Some(name) = &st.name {
                c.column_name(sf("name"), name);
            }
        }
    }
}

impl DemConfig {
    /// The particle counts of the sources, checked before anything is allocated: overflow of
    /// a lattice's `nx · ny · nz`, and the memory the particles need (≈
    /// [`crate::resources::BYTES_PER_PARTICLE`] each, summed over the sources in order)
    /// against the memory available. A `mass` fill is counted at its fewest particles (all of
    /// the largest radius), so a refusal is certain, not a guess. File sources are counted
    /// when they are read (`Engine::from_config`).
    fn check_particle_counts(&self, c: &mut Check) {
        use crate::resources::{check_memory, BYTES_PER_PARTICLE};
        let available = crate::resources::available_memory();
        let mut total = 0.0_f64;
        for (k, src) in self.particles.iter().enumerate() {
            let f = |field: &str| pi(&["dem", "particles"], k, &[field]);
            let (field, count, how) = match src {
                ParticleSource::List { spheres, .. } => (
                    f("spheres"),
                    spheres.len() as f64,
                    (String::new(), String::new()),
                ),
                ParticleSource::Lattice { count, .. } => {
                    let n = count
                        .iter()
                        .try_fold(1_u64, |a, &n| a.checked_mul(u64::try_from(n).ok()?));
                    match n {
                        Some(n) => (
                            f("count"),
                            n as f64,
                            (format!("{count:?} = "), String::new()),
                        ),
                        None => {
                            c.fail(
                                f("count"),
                                format!(
                                    "{count:?} is more than {} particles (the product \
                                     overflows)",
                                    format_number(u64::MAX as f64)
                                ),
                            );
                            continue;
                        }
                    }
                }
                ParticleSource::Fill { count: Some(n), .. } => {
                    (f("count"), *n as f64, (String::new(), String::new()))
                }
                ParticleSource::Fill {
                    mass: Some(mass),
                    distribution,
                    material,
                    shape,
                    ..
                } => {
                    let Some(rho) = self.materials.get(material).map(|m| m.density) else {
                        continue;
                    };
                    // the heaviest possible particle: the largest sphere, or the box around the
                    // largest semi-axes
                    let largest = match (distribution, shape) {
                        (Some(d), _) => {
                            rho * 4.0 / 3.0 * std::f64::consts::PI * d.max_radius().powi(3)
                        }
                        (
                            None,
                            ShapeConfig::Superquadric {
                                semi_axes: Some(axes),
                                ..
                            },
                        ) => rho * 8.0 * axes.iter().map(|d| d.max_radius()).product::<f64>(),
                        _ => continue, // reported above
                    };
                    let n = (mass / largest).ceil();
                    if !(n.is_finite() && n >= 0.0) {
                        continue; // the ranges are reported above
                    }
                    (
                        f("mass"),
                        n,
                        (
                            "at least ".to_string(),
                            " (all as heavy as the largest possible particle)".to_string(),
                        ),
                    )
                }
                ParticleSource::Fill { .. } | ParticleSource::File { .. } => continue,
            };
            total += count;
            let what = format!(
                "{}{} particles{}{}",
                how.0,
                format_number(count),
                how.1,
                if total > count {
                    format!(" ({} with the sources before)", format_number(total))
                } else {
                    String::new()
                }
            );
            if let Err(m) = check_memory(&what, total * BYTES_PER_PARTICLE as f64, available) {
                c.fail(field, m);
            }
        }
    }
}

/// The string value a serde message quotes (`invalid type: string "big", expected f64`).
fn quoted_value(message: &str) -> Option<String> {
    let rest = message.split_once("string \"")?.1;
    Some(rest.split('"').next()?.to_string())
}

/// `"3 kg"`, `"0.1 ms"`: a number followed by a unit, as other tables of a scene accept.
fn looks_like_quantity(value: &str) -> bool {
    let mut parts = value.split_whitespace();
    matches!(
        (parts.next().map(str::parse::<f64>), parts.next(), parts.next()),
        (Some(Ok(_)), Some(unit), None) if unit.chars().all(|c| c.is_alphabetic() || c == '/')
    )
}

/// The field path (`dem.particles[0].radius`) and byte offset of the value an error span
/// points at: the leaf whose string equals the value the message quotes, inside the span
/// (internally tagged tables report the span of the whole table), else the innermost key or
/// value containing the span's start. Only paths under the DEM's table `table` count.
fn field_at(
    text: &str,
    table: &str,
    span: std::ops::Range<usize>,
    message: &str,
) -> Option<(String, usize)> {
    use toml::de::{DeTable, DeValue};
    fn walk<'a>(
        v: &'a toml::Spanned<DeValue<'a>>,
        path: String,
        key_start: usize,
        out: &mut Vec<(String, usize, std::ops::Range<usize>, &'a DeValue<'a>)>,
    ) {
        out.push((path.clone(), key_start, v.span(), v.get_ref()));
        match v.get_ref() {
            DeValue::Table(t) => {
                for (k, child) in t.iter() {
                    let p = format!("{path}.{}", k.get_ref());
                    walk(child, p, k.span().start, out);
                }
            }
            DeValue::Array(a) => {
                for (i, child) in a.iter().enumerate() {
                    walk(child, format!("{path}[{i}]"), child.span().start, out);
                }
            }
            _ => {}
        }
    }
    let doc = DeTable::parse(text).ok()?;
    let dem = doc
        .get_ref()
        .iter()
        .find(|(k, _)| k.get_ref().as_ref() == table)?;
    let mut nodes = Vec::new();
    walk(dem.1, table.into(), dem.0.span().start, &mut nodes);
    // innermost: the last node (depth-first order) whose key or value contains the start
    let (inner, at) = nodes
        .iter()
        .rev()
        .find(|(_, key, s, _)| s.contains(&span.start) || *key == span.start)
        .map(|(path, key, _, _)| (path.clone(), *key))?;
    // inside it, the value the message quotes
    if let Some(value) = quoted_value(message) {
        let hit = nodes.iter().find(|(path, _, _, v)| {
            path.starts_with(&inner)
                && matches!(v, DeValue::String(x) if x.as_ref() == value)
                && path.rsplit('.').next() != Some("kind")
        });
        if let Some((path, key, _, _)) = hit {
            return Some((path.clone(), *key));
        }
    }
    Some((inner, at))
}

/// Byte offset of a line `name = ...` after `from` and before the next table header.
fn find_key_in_table(text: &str, from: usize, name: &str) -> Option<usize> {
    let mut offset = text[..from.min(text.len())]
        .rfind('\n')
        .map(|i| i + 1)
        .unwrap_or(0);
    let mut first = true;
    for line in text[offset..].split_inclusive('\n') {
        let trimmed = line.trim_start();
        if !first && trimmed.starts_with('[') {
            return None;
        }
        first = false;
        let indent = line.len() - trimmed.len();
        if let Some(rest) = trimmed.strip_prefix(name) {
            if rest.trim_start().starts_with('=') {
                return Some(offset + indent);
            }
        }
        // inline tables: `{ ..., name = ... }`
        if let Some(pos) = line
            .find(&format!(" {name} ="))
            .or_else(|| line.find(&format!("{{{name} =")))
        {
            return Some(offset + pos + 1);
        }
        offset += line.len();
    }
    None
}

/// Byte offset of the string value `"value"` after `from` and before the next table header.
fn find_string_value_in_table(text: &str, from: usize, value: &str) -> Option<usize> {
    let mut offset = text[..from.min(text.len())]
        .rfind('\n')
        .map(|i| i + 1)
        .unwrap_or(0);
    let quoted = format!("\"{value}\"");
    for (k, line) in text[offset..].split_inclusive('\n').enumerate() {
        if k > 0 && line.trim_start().starts_with('[') {
            return None;
        }
        if let Some(pos) = line.find(&quoted) {
            return Some(offset + pos);
        }
        offset += line.len();
    }
    None
}

/// Parses the `[dem]` table of a whole scene file; other top-level tables are ignored.
pub fn parse_scene_section(text: &str) -> Result<Option<DemConfig>, SceneError> {
    parse_scene_table(text, "dem")
}

/// Parses the top-level table `table` of a whole scene file with the `[dem]` schema (the DEM
/// node reads the table of its id).
pub fn parse_scene_table(text: &str, table: &str) -> Result<Option<DemConfig>, SceneError> {
    let doc: Option<DemConfig> = scenefile::named_table(text, table).map_err(|e| {
        let mut start = e.span().map(|s| s.start).unwrap_or(0);
        let reported = start;
        // Internally tagged tables (`kind = ...`) report the span of the whole table; point at
        // the unknown key itself when it is found inside that table.
        if let Some(name) = e
            .message()
            .strip_prefix("unknown field `")
            .and_then(|m| m.split('`').next())
        {
            if let Some(off) = find_key_in_table(text, start, name) {
                start = off;
            }
        }
        // ... and at the offending string value for an unknown variant (`axis = "w"`)
        if let Some(value) = e
            .message()
            .strip_prefix("unknown variant `")
            .and_then(|m| m.split('`').next())
        {
            if let Some(off) = find_string_value_in_table(text, start, value) {
                start = off;
            }
        }
        let mut message = e.message().trim().to_string();
        // a wrong type or value (`radius = "big"`) names no field: find it in the document
        if !message.starts_with("unknown field") {
            // already at the offending value (an unknown variant): name its field, stay there
            let moved = start != reported;
            let span = if moved {
                start..start + 1
            } else {
                e.span().unwrap_or(start..start)
            };
            if let Some((path, at)) = field_at(text, table, span, &message) {
                if !moved {
                    start = at;
                }
                message = format!("{path}: {message}");
            }
        }
        if quoted_value(&message).is_some_and(|v| looks_like_quantity(&v)) {
            message.push_str(
                "; [dem] takes plain numbers in SI units (m, s, kg, Pa), not strings with a unit",
            );
        }
        // toml's message names the offending key, e.g. "unknown field `radiuss`, expected ...".
        SceneError::at(text, start, "", message)
    })?;
    let Some(cfg) = doc else { return Ok(None) };
    if let Some(mut err) = cfg.validate_values().into_iter().next() {
        // the checks name paths under `dem`; this table may have another name
        if table != "dem" && err.path.first() == Some(&Seg::Key("dem".into())) {
            err.path[0] = Seg::Key(table.into());
            if let Some(rest) = err.message.strip_prefix("dem") {
                err.message = format!("{table}{rest}");
            }
        }
        let at = scenefile::locate(text, &err.path).map_or(0, |s| s.start);
        return Err(SceneError::at(text, at, "", err.message));
    }
    Ok(Some(cfg))
}
