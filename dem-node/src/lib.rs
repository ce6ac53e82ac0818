//! `dem`: the discrete element engine of the DEM–FEM co-simulation (no transport).
//!
//! Spheres with Hertz–Mindlin–Deresiewicz contacts (Ullrich ch. 2.1, eqs. 2.6–2.19), a cell
//! grid with Verlet skin, velocity Verlet, static and coupled triangle-mesh walls with
//! face/edge/vertex contact without force jumps (Wellmann ch. 4), rayon parallelism with
//! bitwise-identical results for any thread count, snapshot/restore and VTK/CSV output.
//! Static walls may translate or vanish on a prescribed schedule ([`walls::PrescribedMotion`]);
//! sensors measure flow, pressure and the angle of repose ([`sensors`]); particle beds are read
//! from and written to CSV ([`particle_file`]); [`Engine::limits`] reports the physics limits
//! for the coordinator's checks. `impact_substeps` sub-steps the steps with touching contacts
//! for accurate impacts in dilute scenes ([`impact_refinement`]).
//!
//! [`Engine::step`] reads like Ullrich's Algorithm 1: detect contacts → resolve forces →
//! update particle states, each stage in its own module.

pub mod broad_phase;
pub mod config;
pub mod contact_detection;
pub mod discs;
pub mod elliptic_hertz;
pub mod generate;
pub mod hertz_mindlin;
pub mod impact_refinement;
pub mod integrate;
pub mod limits;
pub mod materials;
pub mod narrow;
pub mod output;
pub mod particle_file;
pub mod particles;
pub mod periodic;
pub mod resolve_forces;
pub mod resources;
pub mod rotation;
pub mod sensors;
pub mod shape;
pub mod shaped_forces;
pub mod snapshot;
pub mod stl;
pub mod triangle_contact;
pub mod volume_coupling;
pub mod walls;

use config::{DemConfig, ParticleSource, WallConfig};
use hertz_mindlin::V3;
use materials::MaterialTable;
use particles::Particles;
use resolve_forces::ForceContext;
use snapshot::EngineState;
use std::path::Path;
use walls::{LoadedWall, LoadedWallState, Mesh, Plane, PrescribedMotion, WallRef};

pub use config::{parse_scene_section, parse_scene_table, SceneError};
pub use walls::MotionRule;

/// Errors of the DEM engine; messages name the file, field, mesh or particle concerned.
#[derive(Debug, thiserror::Error)]
pub enum DemError {
    #[error("{field}: {message}")]
    Config { field: String, message: String },
    #[error("STL file {file}, {location}: {message}")]
    Stl {
        file: String,
        location: String,
        message: String,
    },
    #[error(
        "time step {time_step:e} s exceeds {fraction} x the Rayleigh time step {rayleigh:e} s \
         (Ullrich eq. 2.27, smallest for particle {particle}); reduce dem.time_step below \
         {limit:e} s or set dem.allow_large_time_step = true"
    )]
    TimeStepTooLarge {
        time_step: f64,
        rayleigh: f64,
        fraction: f64,
        limit: f64,
        particle: u32,
    },
    #[error("{field}: particle file {file}{}: {message}", line_part(.line))]
    ParticleFile {
        field: String,
        file: String,
        line: usize,
        message: String,
    },
    #[error("dem.particles[{source_index}]: {message}")]
    Generation {
        source_index: usize,
        message: String,
    },
    #[error("mesh `{mesh}`: {message}")]
    Mesh { mesh: String, message: String },
    #[error("no coupled mesh with index {0}")]
    UnknownMesh(usize),
    #[error(
        "instability at t = {time:e} s (step {step}): particle {particle} has a non-finite \
         {quantity}; reduce dem.time_step (Rayleigh step {rayleigh:e} s)"
    )]
    Unstable {
        time: f64,
        step: u64,
        particle: u32,
        quantity: &'static str,
        rayleigh: f64,
    },
    #[error(
        "instability at t = {time:e} s (step {step}): the cores of {first} and {second} \
         interpenetrate (overlap {overlap:e} m of the dilated bodies, more than their dilation \
         radii {dilation:e} m: the dilated-polyhedron model is no longer valid); reduce \
         dem.time_step or the impact speeds, or raise the Young's modulus or the dilation"
    )]
    CoresIntersect {
        time: f64,
        step: u64,
        first: String,
        second: String,
        overlap: f64,
        dilation: f64,
    },
    #[error(
        "instability at t = {time:e} s (step {step}): the loaded wall `{wall}` has a non-finite \
         displacement or velocity; give it more mass or reduce dem.time_step"
    )]
    UnstableWall { time: f64, step: u64, wall: String },
    #[error("periodic cell at t = {time:e} s (step {step}): {message}")]
    Cell {
        time: f64,
        step: u64,
        message: String,
    },
    #[error("snapshot: {0}")]
    Snapshot(String),
    #[error("volume interface `{interface}`: {message}")]
    Volume { interface: String, message: String },
    #[error("output {path}: {message}")]
    Output { path: String, message: String },
}

/// ", line N" for a file error on line N, nothing for one about the whole file (line 0).
fn line_part(line: &usize) -> String {
    if *line > 0 {
        format!(", line {line}")
    } else {
        String::new()
    }
}

/// Rayleigh time step of one particle, Ullrich eq. (2.27).
pub fn rayleigh_time_step_of(
    radius: f64,
    poisson_ratio: f64,
    density: f64,
    shear_modulus: f64,
) -> f64 {
    std::f64::consts::PI * radius / (0.1631 * poisson_ratio + 0.8766)
        * (density / shear_modulus).sqrt()
}

struct OutputState {
    last_vtk_step: Option<u64>,
    /// The step of the last CSV rows: a second call at the same step (the node's `finish`
    /// right after a window) writes no duplicate row.
    last_row_step: Option<u64>,
    vtk_files: u64,
}

/// Where a step's drift stage leaves the clock.
#[derive(Debug, Clone, Copy)]
enum StepClock {
    /// At the end of a step.
    Step,
    /// At the end of sub-step k of n of the step that began at t0.
    Substep { t0: f64, k: usize, n: usize },
}

/// The passes over the particles of [`integrate`].
#[derive(Debug, Clone, Copy)]
enum Pass {
    KickDrift,
    Kick,
    KickThenKickDrift,
}

/// The DEM engine.
pub struct Engine {
    cfg: DemConfig,
    dt: f64,
    gravity: V3,
    materials: MaterialTable,
    planes: Vec<Plane>,
    state: EngineState,
    pool: Option<rayon::ThreadPool>,
    output: OutputState,
    /// Footprint of the first box wall (for the packing fraction).
    box_region: Option<(V3, V3)>,
    /// Static walls with a prescribed motion or removal time.
    wall_motions: Vec<PrescribedMotion>,
    /// Walls moved by a load (their state is `state.loaded_walls`).
    loaded_walls: Vec<LoadedWall>,
    /// Steps run as `impact_substeps` sub-steps (not part of snapshots).
    refined_steps: u64,
    /// Scratch: the positions the next unrefined step would reach.
    predicted: Vec<V3>,
    /// The periodic cell's programme and servo constants (its state is `state.cell`).
    servo: Option<periodic::Servo>,
    /// The pair frictions of the scene, which a periodic stage's `friction` replaces.
    scene_frictions: Vec<f64>,
    /// Volume interfaces' operators and scratch (their state is `state.volumes`).
    volumes: Vec<volume_coupling::VolumeInterface>,
    /// The bodies' Arlequin weights by slot, while a volume interface exists.
    volume_weights: Option<volume_coupling::SlotWeights>,
    /// The periodic cell's results at the start of the last window [`Engine::advance`] ran
    /// inside its programme, with the step they are of: what `summary.json` reports once the
    /// programme is done (the cell is held after its last stage, and a held cell relaxes — at
    /// I = 1e-3 the ratio σ1/σ3 fell by 12 % within the rest of the last window). Kept by
    /// [`Engine::write_outputs`] from the averages of its `periodic.csv` row, else computed by
    /// `advance`; not part of snapshots (the first window after a restore computes it).
    programme_end: Option<(u64, std::collections::BTreeMap<String, f64>)>,
}

/// The penalty's explicit step limit of a volume coupling, 2 min_α √(w_α m_α / k̂_α) with the
/// Gershgorin bound k̂_α ([`volume_coupling::VolumeCoupling::particle_stiffness`]) and w floored
/// at `min_weight`, and the particle that sets it. `by_id` maps ids to slots of `mass`.
fn penalty_step_limit(
    coupling: &volume_coupling::VolumeCoupling,
    mass: &[f64],
    by_id: &std::collections::HashMap<u32, usize>,
    min_weight: f64,
) -> (f64, u32) {
    let mut worst = (f64::INFINITY, u32::MAX);
    for (k, &kk) in coupling.particle_stiffness().iter().enumerate() {
        let id = coupling.ids()[k];
        let m = mass[by_id[&id]] * coupling.weight(k).max(min_weight);
        let limit = 2.0 * (m / kk).sqrt();
        if limit < worst.0 {
            worst = (limit, id);
        }
    }
    worst
}

/// The shaped bodies' wall contacts, planes then meshes in list order, with their wall
/// index (planes first, then meshes).
fn shaped_wall_contacts(
    l: &broad_phase::NeighbourLists,
) -> impl Iterator<Item = (u32, &broad_phase::ShapedContact)> + '_ {
    let planes = (l.shaped_walls.iter())
        .zip(&l.shaped_wall_contacts)
        .map(|(&[_, w], k)| (w, k));
    let meshes = (l.shaped_mesh.iter())
        .zip(&l.shaped_mesh_contacts)
        .map(|(&(_, c), k)| (c.wall, k));
    planes.chain(meshes)
}

/// Nodal forces of a window as flat xyz: the mean of `sum` over `substeps` (zeros before the
/// first) with `averaged`, else `last`.
fn window_forces(averaged: bool, sum: &[V3], substeps: u64, last: &[V3]) -> Vec<f64> {
    let flat = |f: &[V3], scale: f64| {
        f.iter()
            .flat_map(|v| [v.x * scale, v.y * scale, v.z * scale])
            .collect()
    };
    match (averaged, substeps) {
        (true, 0) => vec![0.0; 3 * sum.len()],
        (true, n) => flat(sum, 1.0 / n as f64),
        (false, _) => flat(last, 1.0),
    }
}

/// The generator of a source's shapes and orientations: its own stream, so that drawing
/// shapes leaves the positions of sphere sources as they were.
/// The stones of a polyhedral source (its `library` of STL files, or its random stones),
/// added to the particles' library; their indices there. Empty for other sources.
fn stone_library(
    src: &ParticleSource,
    k: usize,
    base_dir: &std::path::Path,
    particles: &mut Particles,
) -> Result<Vec<u32>, DemError> {
    let (shape, seed) = match src {
        ParticleSource::List { shape, .. } => (shape, 1),
        ParticleSource::Lattice { shape, seed, .. } | ParticleSource::Fill { shape, seed, .. } => {
            (shape, *seed)
        }
        ParticleSource::File { .. } => return Ok(Vec::new()),
    };
    let config::ShapeConfig::Polyhedron {
        triangles,
        elongation,
        dilation,
        stones,
        library,
        ..
    } = shape
    else {
        return Ok(Vec::new());
    };
    let error = |message: String| DemError::Generation {
        source_index: k,
        message,
    };
    let mut out = Vec::new();
    match library {
        Some(files) => {
            for (i, file) in files.iter().enumerate() {
                let full = base_dir.join(file);
                let mesh = stl::read_stl(&full)
                    .map_err(|e| error(format!("shape.library[{i}] ({}): {e}", full.display())))?;
                let stone = shape::Stone::from_mesh(&mesh.positions, &mesh.triangles, *dilation)
                    .map_err(|e| error(format!("shape.library[{i}] ({}): {e}", full.display())))?;
                out.push(particles.add_stone(stone));
            }
        }
        None => {
            let mut rng = shape_rng(seed ^ 0x57_0E5, k);
            for _ in 0..*stones {
                let stone = shape::Stone::random(*triangles, *elongation, *dilation, &mut rng)
                    .map_err(|e| error(format!("shape: {e}")))?;
                out.push(particles.add_stone(stone));
            }
        }
    }
    Ok(out)
}

fn shape_rng(seed: u64, source: usize) -> generate::SplitMix64 {
    generate::SplitMix64::new(
        seed.wrapping_mul(0x9E37_79B9_7F4A_7C15)
            ^ (source as u64).wrapping_mul(0xD1B5_4A32_D192_ED03)
            ^ 0x5EED,
    )
}

fn v3(a: &[f64; 3]) -> V3 {
    V3::new(a[0], a[1], a[2])
}

impl Engine {
    /// Builds the engine: materials, walls (paths relative to `base_dir`), particles; checks
    /// the time step against the Rayleigh step and evaluates the initial forces.
    pub fn from_config(cfg: &DemConfig, base_dir: &Path) -> Result<Engine, DemError> {
        if let Some(e) = cfg.validate_values().into_iter().next() {
            return Err(DemError::Config {
                field: config::path_string(&e.path),
                message: e.message,
            });
        }
        let materials = MaterialTable::from_config(cfg);
        let mat = |name: &str, field: String| {
            materials.index(name).ok_or_else(|| DemError::Config {
                field,
                message: format!("unknown material `{name}`"),
            })
        };
        let mut planes: Vec<Plane> = Vec::new();
        let mut meshes: Vec<Mesh> = Vec::new();
        let mut box_region = None;
        let mut wall_motions = Vec::new();
        let mut loaded_walls = Vec::new();
        for (k, w) in cfg.walls.iter().enumerate() {
            let field = format!("dem.walls[{k}].material");
            match w {
                WallConfig::Plane {
                    material,
                    point,
                    normal,
                    ..
                } => planes.push(Plane {
                    point: v3(point),
                    normal: v3(normal).normalize(),
                    material: mat(material, field)?,
                    velocity: V3::zeros(),
                    active: true,
                }),
                WallConfig::Box {
                    material,
                    min,
                    max,
                    open,
                    ..
                } => {
                    let (pos, tris) = walls::box_mesh(v3(min), v3(max), open);
                    if box_region.is_none() {
                        box_region = Some((v3(min), v3(max)));
                    }
                    meshes.push(Mesh::new(
                        &format!("box{k}"),
                        mat(material, field)?,
                        false,
                        pos,
                        tris,
                    ));
                }
                WallConfig::Cylinder {
                    material,
                    centre,
                    radius,
                    height,
                    segments,
                    ..
                } => {
                    let (pos, tris) = walls::cylinder_mesh(v3(centre), *radius, *height, *segments);
                    meshes.push(Mesh::new(
                        &format!("cylinder{k}"),
                        mat(material, field)?,
                        false,
                        pos,
                        tris,
                    ));
                }
                WallConfig::Stl {
                    material,
                    path,
                    scale,
                    offset,
                    ..
                } => {
                    let full = base_dir.join(path);
                    let mut tm = stl::read_stl(&full)?;
                    for x in tm.positions.iter_mut() {
                        *x = *x * *scale + v3(offset);
                    }
                    meshes.push(Mesh::new(
                        path,
                        mat(material, field)?,
                        false,
                        tm.positions,
                        tm.triangles,
                    ));
                }
            }
            let (motion, load, remove_at) = w.kinematics();
            if motion.is_some() || load.is_some() || remove_at.is_some() {
                let (wall, base) = match w {
                    WallConfig::Plane { .. } => {
                        let k = planes.len() - 1;
                        (WallRef::Plane(k), vec![planes[k].point])
                    }
                    _ => {
                        let k = meshes.len() - 1;
                        (WallRef::Mesh(k), meshes[k].positions.clone())
                    }
                };
                let remove_at = remove_at.unwrap_or(f64::INFINITY);
                if let Some(l) = load {
                    let mut axis = V3::zeros();
                    axis[l.axis.indices().0] = 1.0;
                    loaded_walls.push(LoadedWall {
                        name: l.name.clone().unwrap_or_else(|| format!("wall{k}")),
                        wall,
                        axis,
                        mass: l.mass,
                        force: l.force,
                        amplitude: l.amplitude,
                        omega: 2.0 * std::f64::consts::PI * l.frequency,
                        start: l.start,
                        end: l.end.unwrap_or(f64::INFINITY),
                        release: l.release,
                        remove_at,
                        base,
                        drive: l.drive.as_ref().map(|d| (d.velocity, d.start)),
                        ramp: l.ramp,
                    });
                } else {
                    wall_motions.push(PrescribedMotion {
                        wall,
                        velocity: motion.map_or(V3::zeros(), |m| v3(&m.velocity)),
                        amplitude: motion.map_or(V3::zeros(), |m| v3(&m.amplitude)),
                        omega: motion.map_or(0.0, |m| 2.0 * std::f64::consts::PI * m.frequency),
                        start: motion.map_or(0.0, |m| m.start),
                        end: motion.and_then(|m| m.end).unwrap_or(f64::INFINITY),
                        remove_at,
                        base,
                        stages: motion.map_or(Vec::new(), |m| {
                            (m.then.iter())
                                .map(|s| (v3(&s.velocity), s.start, s.end.unwrap_or(f64::INFINITY)))
                                .collect()
                        }),
                        name: motion.and_then(|m| m.name.clone()),
                    });
                }
            }
        }
        let mut particles = Particles::default();
        for (k, src) in cfg.particles.iter().enumerate() {
            let field = format!("dem.particles[{k}].material");
            let library = stone_library(src, k, base_dir, &mut particles)?;
            match src {
                ParticleSource::List {
                    material,
                    spheres,
                    shape,
                } => {
                    let m = mat(material, field)?;
                    let rho = materials.materials[m as usize].density;
                    let mut rng = shape_rng(1, k);
                    for s in spheres {
                        let (x, v, w) = (v3(&s.position), v3(&s.velocity), v3(&s.angular_velocity));
                        match generate::sample_body(
                            shape,
                            s.radius,
                            &mut rng,
                            &library,
                            &particles.stones,
                        ) {
                            None => particles.push(x, v, w, s.radius, rho, m),
                            Some((body, q)) => {
                                let q = s.orientation.map_or(q, |[w0, x0, y0, z0]| {
                                    nalgebra::UnitQuaternion::from_quaternion(
                                        nalgebra::Quaternion::new(w0, x0, y0, z0),
                                    )
                                });
                                particles.push_drawn(x, v, w, q, body, rho, m)
                            }
                        }
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
                    seed,
                    shape,
                } => {
                    let m = mat(material, field)?;
                    let rho = materials.materials[m as usize].density;
                    let mut rng = generate::SplitMix64::new(
                        seed.wrapping_mul(0x2545_F491_4F6C_DD1D) ^ 0x5A5A,
                    );
                    let mut shapes = shape_rng(*seed, k);
                    for mut x in generate::lattice(v3(first), *spacing, *count) {
                        if *jitter > 0.0 {
                            x.x += jitter * (2.0 * rng.uniform() - 1.0);
                            x.y += jitter * (2.0 * rng.uniform() - 1.0);
                        }
                        match generate::sample_body(
                            shape,
                            *radius,
                            &mut shapes,
                            &library,
                            &particles.stones,
                        ) {
                            None => particles.push(x, v3(velocity), V3::zeros(), *radius, rho, m),
                            Some((body, q)) => {
                                // bounding spheres apart: no two bodies can overlap
                                let reach = 2.0 * body.bounding_radius() + 2.0 * jitter;
                                if *spacing < reach {
                                    return Err(DemError::Generation {
                                        source_index: k,
                                        message: format!(
                                            "spacing {} m is less than the bounding diameter \
                                             {} m of a drawn superquadric (plus twice the \
                                             jitter): the bodies could overlap; increase \
                                             `spacing`",
                                            resources::format_number(*spacing),
                                            resources::format_number(reach)
                                        ),
                                    });
                                }
                                particles.push_drawn(x, v3(velocity), V3::zeros(), q, body, rho, m)
                            }
                        }
                    }
                }
                ParticleSource::Fill {
                    material,
                    min,
                    max,
                    radius,
                    count,
                    mass,
                    distribution,
                    seed,
                    velocity,
                    shape,
                } => {
                    let m = mat(material, field)?;
                    let rho = materials.materials[m as usize].density;
                    let mut rng = generate::SplitMix64::new(
                        seed.wrapping_mul(0x2545_F491_4F6C_DD1D) ^ 0xA5A5,
                    );
                    // equal-volume radii (spheres: the radii), or the bodies themselves when
                    // the shape draws its semi-axes
                    let mut shapes_rng = shape_rng(*seed, k);
                    let mut radii = Vec::new();
                    let mut drawn = Vec::new();
                    let mut total = 0.0;
                    let enough = |n: usize, total: f64| match (count, mass) {
                        (Some(c), _) => n >= *c,
                        (None, Some(target)) => total >= *target,
                        (None, None) => true, // validated: count or mass
                    };
                    while !enough(radii.len().max(drawn.len()), total) {
                        match distribution {
                            Some(d) => {
                                let r = generate::sample_radius(d, &mut rng);
                                total += rho * 4.0 / 3.0 * std::f64::consts::PI * r.powi(3);
                                radii.push(r);
                            }
                            None => {
                                let b = generate::sample_body(shape, 0.0, &mut shapes_rng, &library, &particles.stones)
                                    .expect("validated: without a distribution the shape draws its semi-axes");
                                total += rho * b.0.volume();
                                drawn.push(b);
                            }
                        }
                        if radii.len().max(drawn.len()) > 50_000_000 {
                            return Err(DemError::Generation {
                                source_index: k,
                                message: "mass target needs more than 5e7 particles".into(),
                            });
                        }
                    }
                    let existing: Vec<(V3, f64)> = particles
                        .position
                        .iter()
                        .cloned()
                        .zip(particles.radius.iter().cloned())
                        .collect();
                    // superquadrics are placed by their bounding spheres (never overlapping),
                    // largest first as fill_box sorts (a stable sort keeps ties in order)
                    let mut bodies: Vec<_> = radii
                        .iter()
                        .filter_map(|&r| {
                            generate::sample_body(
                                shape,
                                r,
                                &mut shapes_rng,
                                &library,
                                &particles.stones,
                            )
                        })
                        .collect();
                    bodies.extend(drawn);
                    if !bodies.is_empty() {
                        bodies.sort_by(|a, b| {
                            b.0.bounding_radius().total_cmp(&a.0.bounding_radius())
                        });
                        radii = bodies.iter().map(|b| b.0.bounding_radius()).collect();
                    }
                    let cell = cfg.periodic.as_ref().map(|c| c.size);
                    let period = cell.as_ref().map(v3);
                    // a periodic fill without a box fills its cell [0, size] (validated: the
                    // others have one)
                    let (Some(min), Some(max)) = (min.or(cell.map(|_| [0.0; 3])), max.or(cell))
                    else {
                        return Err(DemError::Generation {
                            source_index: k,
                            message: "a fill needs `min` and `max` (only a periodic cell's fill \
                                      may leave them out)"
                                .into(),
                        });
                    };
                    let placed = generate::fill_box(
                        v3(&min),
                        v3(&max),
                        *radius,
                        &mut radii,
                        *seed,
                        &existing,
                        period,
                    )
                    .map_err(|message| DemError::Generation {
                        source_index: k,
                        message,
                    })?;
                    if bodies.is_empty() {
                        for (x, r) in placed {
                            particles.push(x, v3(velocity), V3::zeros(), r, rho, m);
                        }
                    } else {
                        for ((x, _), (body, q)) in placed.into_iter().zip(bodies) {
                            particles.push_drawn(x, v3(velocity), V3::zeros(), q, body, rho, m);
                        }
                    }
                }
                ParticleSource::File {
                    material,
                    path,
                    keep,
                } => {
                    let m = mat(material, field)?;
                    let rho = materials.materials[m as usize].density;
                    let full = base_dir.join(path);
                    let spheres =
                        particle_file::read(&full).map_err(|e| DemError::ParticleFile {
                            field: format!("dem.particles[{k}].path"),
                            file: full.display().to_string(),
                            line: e.line,
                            message: e.message,
                        })?;
                    let read = spheres.len();
                    let file_error = |line: usize, message: String| DemError::ParticleFile {
                        field: format!("dem.particles[{k}].path"),
                        file: full.display().to_string(),
                        line,
                        message,
                    };
                    let spheres: Vec<particle_file::FileParticle> = spheres
                        .into_iter()
                        .filter(|s| {
                            let p = s.position;
                            keep.as_ref().is_none_or(|b| b.contains([p.x, p.y, p.z]))
                        })
                        .collect();
                    // the stone library of a file with dilated polyhedra
                    let stones = if spheres.iter().any(|s| s.stone.is_some()) {
                        let lib_path = particle_file::stones_path(&full);
                        let stones = particle_file::read_stones(&lib_path).map_err(|e| {
                            DemError::ParticleFile {
                                field: format!("dem.particles[{k}].path"),
                                file: lib_path.display().to_string(),
                                line: e.line,
                                message: e.message,
                            }
                        })?;
                        if let Some(s) = spheres
                            .iter()
                            .find(|s| s.stone.is_some_and(|(i, _)| i as usize >= stones.len()))
                        {
                            return Err(file_error(
                                s.line,
                                format!(
                                    "stone {} but the library {} has {} stones",
                                    s.stone.unwrap().0,
                                    lib_path.display(),
                                    stones.len()
                                ),
                            ));
                        }
                        stones
                    } else {
                        Vec::new()
                    };
                    if let Some((a, b, fraction)) = particle_file::find_overlap_with_stones(
                        &spheres,
                        &stones,
                        particle_file::MAX_FILE_OVERLAP,
                    ) {
                        let (a, b) = (&spheres[a], &spheres[b]);
                        if a.stone.is_some() || b.stone.is_some() {
                            return Err(file_error(
                                a.line,
                                format!(
                                    "the bodies on lines {} and {} overlap by {} of the sum of \
                                     their dilations (at most {} is accepted; 1 means the cores \
                                     meet): bodies written twice or a wrong column?",
                                    a.line,
                                    b.line,
                                    resources::format_number(fraction),
                                    particle_file::MAX_FILE_OVERLAP
                                ),
                            ));
                        }
                        if a.shape.is_some() || b.shape.is_some() {
                            return Err(file_error(
                                a.line,
                                format!(
                                    "the particles on lines {} and {} overlap by {} of the \
                                     smaller inscribed radius (at most {} is accepted): \
                                     particles written twice or a wrong column?",
                                    a.line,
                                    b.line,
                                    resources::format_number(fraction),
                                    particle_file::MAX_FILE_OVERLAP
                                ),
                            ));
                        }
                        return Err(file_error(
                            a.line,
                            format!(
                                "the spheres on lines {} and {} overlap by {} of the smaller \
                                 radius (radii {} and {} m, centres {} m apart; at most {} is \
                                 accepted): spheres written twice or a wrong column?",
                                a.line,
                                b.line,
                                resources::format_number(fraction),
                                resources::format_number(a.radius),
                                resources::format_number(b.radius),
                                resources::format_number((a.position - b.position).norm()),
                                particle_file::MAX_FILE_OVERLAP
                            ),
                        ));
                    }
                    let total = particles.len() as f64 + spheres.len() as f64;
                    resources::check_memory(
                        &format!(
                            "its {} particles ({} with the sources before)",
                            spheres.len(),
                            resources::format_number(total)
                        ),
                        total * resources::BYTES_PER_PARTICLE as f64,
                        resources::available_memory(),
                    )
                    .map_err(|message| file_error(0, message))?;
                    let before = particles.len();
                    let first_stone = particles.stones.len() as u32;
                    particles.stones.extend(stones);
                    for s in spheres {
                        if let Some((stone, size)) = s.stone {
                            particles.push_polyhedron(
                                s.position,
                                s.velocity,
                                s.angular_velocity,
                                s.orientation
                                    .unwrap_or_else(particles::Orientation::identity),
                                first_stone + stone,
                                size,
                                rho,
                                m,
                            );
                            continue;
                        }
                        match s.shape {
                            None => particles.push(
                                s.position,
                                s.velocity,
                                s.angular_velocity,
                                s.radius,
                                rho,
                                m,
                            ),
                            Some(body) => particles.push_superquadric(
                                s.position,
                                s.velocity,
                                s.angular_velocity,
                                s.orientation
                                    .unwrap_or_else(particles::Orientation::identity),
                                body,
                                rho,
                                m,
                            ),
                        }
                    }
                    if let Some(b) = keep.as_ref().filter(|_| particles.len() == before) {
                        return Err(DemError::Generation {
                            source_index: k,
                            message: format!(
                                "`keep` (min {:?}, max {:?}) removed all {read} spheres of {}",
                                b.min,
                                b.max,
                                full.display()
                            ),
                        });
                    }
                }
            }
        }
        let skin = cfg.skin.unwrap_or_else(|| {
            if particles.is_empty() {
                1e-3
            } else if particles.has_shapes() {
                // Wellmann (3.49): d_V = 0.05 r̄, r̄ = (r_max + r_min)/2 of the bounding radii
                let r = &particles.radius;
                let (lo, hi) = r
                    .iter()
                    .fold((f64::MAX, 0.0f64), |(a, b), &x| (a.min(x), b.max(x)));
                0.05 * 0.5 * (lo + hi)
            } else {
                // Wellmann B4: d_V = 0.25 r̄
                0.25 * particles.radius.iter().sum::<f64>() / particles.len() as f64
            }
        });
        let pool = match cfg.threads {
            Some(n) => Some(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(n)
                    .build()
                    .map_err(|e| DemError::Config {
                        field: "dem.threads".into(),
                        message: e.to_string(),
                    })?,
            ),
            None => None,
        };
        let threads = pool
            .as_ref()
            .map_or_else(rayon::current_num_threads, |p| p.current_num_threads());
        tracing::info!(
            "{} particles on {threads} thread{}",
            particles.len(),
            if threads == 1 { "" } else { "s" }
        );
        let sensors = sensors::SensorState::new(&cfg.sensors, &particles, 0.0);
        let mut engine = Engine {
            cfg: cfg.clone(),
            dt: cfg.time_step,
            gravity: v3(&cfg.gravity),
            materials,
            planes,
            state: EngineState {
                version: snapshot::SNAPSHOT_VERSION,
                time: 0.0,
                steps: 0,
                particles,
                lists: broad_phase::NeighbourLists {
                    skin,
                    ..Default::default()
                },
                records: Vec::new(),
                meshes,
                sensors,
                loaded_walls: vec![LoadedWallState::default(); loaded_walls.len()],
                removed_particles: 0,
                removed_mass: 0.0,
                cell: None,
                volumes: Vec::new(),
            },
            pool,
            output: OutputState {
                last_vtk_step: None,
                last_row_step: None,
                vtk_files: 0,
            },
            box_region,
            wall_motions,
            loaded_walls,
            refined_steps: 0,
            predicted: Vec::new(),
            servo: None,
            scene_frictions: Vec::new(),
            volumes: Vec::new(),
            volume_weights: None,
            programme_end: None,
        };
        engine.scene_frictions = engine.materials.pairs.iter().map(|p| p.friction).collect();
        if let Some(cell) = &cfg.periodic {
            engine.start_cell(cell);
        }
        engine.place_walls(false);
        engine.check_time_step()?;
        engine.check_cell()?;
        engine.refresh_forces();
        Ok(engine)
    }

    /// Sets up the periodic cell: its state at the start, the servo's constants from the
    /// particles (W §5.1.3: t_w = 0.01 r̄, ρ the particles' density; m̄, d̄ of (5.8) with d̄
    /// the mean equal-volume diameter), the first stage's friction.
    fn start_cell(&mut self, cfg: &periodic::PeriodicConfig) {
        let p = &self.state.particles;
        let n = p.len().max(1) as f64;
        let volume: f64 = (0..p.len()).map(|k| p.volume(k)).sum();
        let mass: f64 = p.mass.iter().sum();
        let diameter: f64 = (0..p.len())
            .map(|k| 2.0 * (3.0 * p.volume(k) / (4.0 * std::f64::consts::PI)).cbrt())
            .sum::<f64>()
            / n;
        let density = if volume > 0.0 { mass / volume } else { 1.0 };
        // departure: the thesis's t_w = 0.01 r̄ makes the wall ~200 times lighter than a layer
        // of grains, and its explicit update oscillates from step to step at any Δt that
        // suits the grains (measured: the test cell at Δt = 0.22 Δt_R); one mean diameter
        // gives the wall a grain layer's mass
        let thickness = cfg.wall_thickness.unwrap_or(diameter);
        let size = v3(&cfg.size);
        self.servo = Some(periodic::Servo {
            stages: cfg.stages.clone(),
            inertial_number: cfg.inertial_number,
            wall_mass: density * thickness,
            damping: cfg.servo_damping,
            modulus: cfg.servo_modulus,
            tolerance: cfg.tolerance,
            mean_mass: (mass / n).max(f64::MIN_POSITIVE),
            mean_diameter: diameter,
            image_velocity: cfg.image_velocity,
        });
        self.state.cell = Some(periodic::CellState {
            size,
            rate: V3::zeros(),
            size0: size,
            stage_size0: size,
            applied: V3::zeros(),
            stress: nalgebra::Matrix3::zeros(),
            stage: 0,
            stage_start: 0.0,
        });
        self.apply_stage_friction();
    }

    /// Puts the friction of the current periodic stage (or the scene's) into every pair.
    fn apply_stage_friction(&mut self) {
        let (Some(servo), Some(cell)) = (&self.servo, &self.state.cell) else {
            return;
        };
        let mu = servo.friction_at(cell.stage);
        for (pair, &scene) in self.materials.pairs.iter_mut().zip(&self.scene_frictions) {
            pair.friction = mu.unwrap_or(scene);
        }
    }

    /// The periodic cell's edges must stay finite and hold one image per pair: at least twice
    /// the reach of a pair (2 r_max + d_V (1 + margin)) in every direction.
    fn check_cell(&self) -> Result<(), DemError> {
        let Some(cell) = &self.state.cell else {
            return Ok(());
        };
        let p = &self.state.particles;
        let r_max = p.radius.iter().cloned().fold(0.0, f64::max);
        let skin = self.state.lists.skin;
        let reach = 2.0 * r_max + skin * (1.0 + broad_phase::CELL_MARGIN);
        for (a, axis) in ["x", "y", "z"].iter().enumerate() {
            let l = cell.size[a];
            if !(l.is_finite() && cell.rate[a].is_finite()) {
                return Err(self.cell_error(format!(
                    "the edge {axis} is no longer finite (L = {l:e} m, rate {:e} m/s): the \
                     servo diverged; give it a thicker wall (dem.periodic.wall_thickness), more \
                     damping, or a smaller dem.time_step",
                    cell.rate[a]
                )));
            }
            if let Some(stage) = self.servo.as_ref().and_then(|s| s.stalled_stage(cell)) {
                return Err(self.cell_error(format!(
                    "stage `{stage}` strains its axes at the rate of the inertial number at the \
                     measured pressure, which is 0 (no contact carries stress yet): give the \
                     stage a `strain_rate` (1/s)"
                )));
            }
            if l < 2.0 * reach {
                return Err(self.cell_error(format!(
                    "the edge {axis} is {l:e} m, less than twice the reach of a pair \
                     (2 x (2 r_max + 1.5 d_V) = {:e} m): a particle would meet two images of \
                     another; make dem.periodic.size larger",
                    2.0 * reach
                )));
            }
        }
        Ok(())
    }

    fn cell_error(&self, message: String) -> DemError {
        DemError::Cell {
            time: self.state.time,
            step: self.state.steps,
            message,
        }
    }

    /// After a step's forces: the cell's average stress (5.5), then the next stage if the
    /// current one's targets are met.
    fn update_cell(&mut self) {
        let Some(cell) = self.state.cell.as_mut() else {
            return;
        };
        cell.stress = periodic::boundary_stress(&self.state.lists, &cell.size);
        let Some(servo) = &self.servo else { return };
        if !servo.stage_done(cell) {
            return;
        }
        tracing::info!(
            "periodic cell: stage `{}` done at t = {:.6e} s",
            servo.stages[cell.stage].label(cell.stage),
            self.state.time
        );
        cell.stage += 1;
        cell.stage_start = self.state.time;
        cell.stage_size0 = cell.size;
        // an axis that becomes stress-controlled starts from the stress it carries
        for a in 0..3 {
            if let Some(next) = servo.stages.get(cell.stage) {
                let was = servo.stages[cell.stage - 1].stress.get(a).is_some();
                if next.stress.get(a).is_some() && !was {
                    cell.applied[a] = cell.stress[(a, a)];
                }
            }
        }
        if servo.stages.get(cell.stage).is_some_and(|s| s.at_rest) {
            let p = &mut self.state.particles;
            p.velocity.fill(V3::zeros());
            p.angular_velocity.fill(V3::zeros());
            tracing::info!(
                "periodic cell: the grains start stage `{}` at rest",
                servo.stages[cell.stage].label(cell.stage)
            );
        }
        self.apply_stage_friction();
    }

    /// The periodic cell's programme: the current stage (0-based; the number of stages once
    /// done) and its progress (`None` once done or without a programme).
    pub fn programme_progress(&self) -> Option<(usize, Option<periodic::StageProgress>)> {
        match (&self.servo, &self.state.cell) {
            (Some(s), Some(c)) => Some((c.stage, s.stage_progress(c))),
            _ => None,
        }
    }

    /// Whether the periodic cell's programme has run all its stages.
    pub fn programme_finished(&self) -> bool {
        match (&self.servo, &self.state.cell) {
            (Some(s), Some(c)) => c.stage >= s.stages.len(),
            _ => false,
        }
    }

    /// The periodic cell's homogenised quantities now (`None` without a cell).
    pub fn cell_averages(&self) -> Option<periodic::Averages> {
        let cell = self.state.cell.as_ref()?;
        let p = &self.state.particles;
        let g = self.gravity;
        Some(periodic::averages(&self.state.lists, p, &cell.size, |k| {
            p.force[k] - g * p.mass[k]
        }))
    }

    /// The periodic cell's state (`None` without one).
    pub fn cell(&self) -> Option<&periodic::CellState> {
        self.state.cell.as_ref()
    }

    fn check_time_step(&self) -> Result<(), DemError> {
        let (rayleigh, particle) = self.rayleigh_with_particle();
        let limit = self.cfg.rayleigh_fraction * rayleigh;
        if self.dt > limit && !self.cfg.allow_large_time_step {
            return Err(DemError::TimeStepTooLarge {
                time_step: self.dt,
                rayleigh,
                fraction: self.cfg.rayleigh_fraction,
                limit,
                particle,
            });
        }
        Ok(())
    }

    fn run<R: Send>(&mut self, f: impl FnOnce(&mut Engine) -> R + Send) -> R {
        match self.pool.take() {
            Some(pool) => {
                let r = pool.install(|| f(self));
                self.pool = Some(pool);
                r
            }
            None => f(self),
        }
    }

    pub fn time(&self) -> f64 {
        self.state.time
    }

    pub fn time_step(&self) -> f64 {
        self.dt
    }

    /// Smallest Rayleigh time step over all particles (eq. 2.27); +∞ without particles.
    pub fn rayleigh_time_step(&self) -> f64 {
        self.rayleigh_with_particle().0
    }

    fn rayleigh_with_particle(&self) -> (f64, u32) {
        let p = &self.state.particles;
        let mut best = (f64::INFINITY, 0u32);
        for k in 0..p.len() {
            let m = &self.materials.materials[p.material[k] as usize];
            // a shaped body's from its smallest lump that vibrates
            let r = p.vibration_radius(k);
            let t = rayleigh_time_step_of(r, m.poisson_ratio, m.density, m.shear_modulus());
            if t < best.0 {
                best = (t, p.id[k]);
            }
        }
        best
    }

    pub fn num_particles(&self) -> usize {
        self.state.particles.len()
    }

    /// Read access to the particles (storage order is the broad phase's cell order; use `id`).
    pub fn particles(&self) -> &Particles {
        &self.state.particles
    }

    /// Mutable access to the particles for setting up tests and scenes; the neighbour lists
    /// are rebuilt and the forces re-evaluated at the next step.
    pub fn particles_mut(&mut self) -> &mut Particles {
        self.state.lists.valid = false;
        &mut self.state.particles
    }

    pub fn meshes(&self) -> &[Mesh] {
        &self.state.meshes
    }

    /// Overlaps δ = r_i + r_j − |x_i − x_j| of the listed pairs (≤ 0 when not touching).
    fn pair_overlaps(&self) -> impl Iterator<Item = f64> + '_ {
        let p = &self.state.particles;
        let l = &self.state.lists;
        let n = if l.valid { p.len() } else { 0 };
        (0..n).flat_map(move |i| {
            l.partner[l.first_pair[i] as usize..l.first_pair[i + 1] as usize]
                .iter()
                .map(move |&j| {
                    let j = j as usize;
                    p.radius[i] + p.radius[j] - (p.position[i] - p.position[j]).norm()
                })
        })
    }

    /// The listed pairs with a non-spherical body, by particle ids, with their contact
    /// records (normal, overlap, contact point, force on the first body).
    pub fn shaped_pair_contacts(
        &self,
    ) -> impl Iterator<Item = ([u32; 2], &broad_phase::ShapedContact)> + '_ {
        let (p, l) = (&self.state.particles, &self.state.lists);
        (l.shaped_pairs.iter())
            .zip(&l.shaped_pair_contacts)
            .map(|(&[i, j], c)| ([p.id[i as usize], p.id[j as usize]], c))
    }

    /// Number of particle–particle contacts (overlap > 0).
    pub fn num_contacts(&self) -> usize {
        let l = &self.state.lists;
        self.pair_overlaps().filter(|&d| d > 0.0).count()
            + l.periodic_pairs.iter().filter(|p| p.overlap > 0.0).count()
            + l.shaped_pair_contacts
                .iter()
                .filter(|c| c.overlap > 0.0)
                .count()
    }

    /// Number of particle–wall contacts.
    pub fn num_wall_contacts(&self) -> usize {
        let l = &self.state.lists;
        l.wall_contacts.iter().filter(|c| c.touching()).count()
            + (l.shaped_wall_contacts.iter())
                .chain(&l.shaped_mesh_contacts)
                .filter(|c| c.touching())
                .count()
    }

    /// Largest overlap of any contact (pair or wall), m.
    pub fn max_overlap(&self) -> f64 {
        let l = &self.state.lists;
        let a = self
            .pair_overlaps()
            .chain(l.periodic_pairs.iter().map(|p| p.overlap))
            .fold(0.0, f64::max);
        let b = l
            .wall_contacts
            .iter()
            .map(|c| c.overlap)
            .fold(0.0, f64::max);
        let shaped = (l.shaped_pair_contacts.iter())
            .chain(&l.shaped_wall_contacts)
            .chain(&l.shaped_mesh_contacts)
            .map(|c| c.overlap)
            .fold(0.0, f64::max);
        a.max(b).max(shaped)
    }

    /// Heap bytes of the mutable state (particles, neighbour lists, contact histories, wall
    /// states, mesh records; not the meshes), by allocated capacity.
    pub fn memory_bytes(&self) -> usize {
        fn b<T>(v: &Vec<T>) -> usize {
            v.capacity() * std::mem::size_of::<T>()
        }
        let p = &self.state.particles;
        let l = &self.state.lists;
        b(&p.id)
            + b(&p.position)
            + b(&p.velocity)
            + b(&p.angular_velocity)
            + b(&p.radius)
            + b(&p.mass)
            + b(&p.inertia)
            + b(&p.material)
            + b(&p.force)
            + b(&p.torque)
            + b(&l.first_pair)
            + b(&l.partner)
            + b(&l.shear)
            + b(&l.wall_start)
            + b(&l.walls)
            + b(&l.wall_contacts)
            + b(&l.position_at_build)
            + b(&l.cross.block_start)
            + b(&l.cross.receivers)
            + b(&l.cross.block_receivers)
            + b(&l.cross.receiver_start)
            + b(&l.cross.incoming)
            + b(&l.cross.force)
            + b(&self.state.records)
            + b(&l.periodic_pairs)
            + b(&l.shaped_pair_image)
    }

    /// Number of neighbour-list builds so far.
    pub fn neighbour_list_builds(&self) -> u64 {
        self.state.lists.builds
    }

    /// Adds a coupled mesh (FEM interface) with the `interface_material`; returns its index.
    pub fn add_coupled_mesh(
        &mut self,
        name: &str,
        positions: &[f64],
        triangles: &[u32],
    ) -> Result<usize, DemError> {
        let merr = |message: String| DemError::Mesh {
            mesh: name.to_string(),
            message,
        };
        let Some(mat_name) = &self.cfg.interface_material else {
            return Err(merr("a coupled mesh needs dem.interface_material".into()));
        };
        let material = self
            .materials
            .index(mat_name)
            .ok_or_else(|| merr(format!("unknown interface material `{mat_name}`")))?;
        if positions.len() % 3 != 0 || positions.is_empty() {
            return Err(merr(format!(
                "positions length {} is not a positive multiple of 3",
                positions.len()
            )));
        }
        if let Some(k) = positions.iter().position(|x| !x.is_finite()) {
            return Err(merr(format!("non-finite coordinate at positions[{k}]")));
        }
        if triangles.len() % 3 != 0 || triangles.is_empty() {
            return Err(merr(format!(
                "triangles length {} is not a positive multiple of 3",
                triangles.len()
            )));
        }
        let nn = positions.len() / 3;
        if let Some(k) = triangles.iter().position(|&t| t as usize >= nn) {
            return Err(merr(format!(
                "triangles[{k}] = {} but there are only {nn} nodes",
                triangles[k]
            )));
        }
        let pos: Vec<V3> = positions
            .chunks(3)
            .map(|c| V3::new(c[0], c[1], c[2]))
            .collect();
        let tris: Vec<[u32; 3]> = triangles.chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
        for (t, tri) in tris.iter().enumerate() {
            let [a, b, c] = tri.map(|k| pos[k as usize]);
            if (b - a).cross(&(c - a)).norm() == 0.0 {
                return Err(merr(format!(
                    "triangle {t} {tri:?} is degenerate (zero area)"
                )));
            }
        }
        self.state
            .meshes
            .push(Mesh::new(name, material, true, pos, tris));
        self.state.lists.valid = false;
        Ok(self.state.meshes.len() - 1)
    }

    /// Adds a volume (Arlequin) interface: the overlap's elements, nodes (ids, reference
    /// positions) and nodal weights w_I as the FE side declares them. The particles whose
    /// centres lie in the overlap now are its coupled particles, their displacements measured
    /// from here (Wellmann §6.3: the coupling terms are built once in this reference
    /// configuration). Refused with a periodic cell or particle sinks, without a particle in
    /// the overlap, with a node no particle supports, and when the penalty's explicit step
    /// limit, 2 √(w m / k̂_α) with w floored at `min_weight`, is below the DEM step (naming
    /// the particle). Returns the interface's index.
    pub fn add_volume_interface(
        &mut self,
        name: &str,
        mesh: volume_coupling::OverlapMesh,
        settings: volume_coupling::VolumeSettings,
    ) -> Result<usize, DemError> {
        let verr = |message: String| DemError::Volume {
            interface: name.to_string(),
            message,
        };
        if self.state.cell.is_some() {
            return Err(verr(
                "a periodic cell cannot be coupled to a continuum".into(),
            ));
        }
        if !self.cfg.sinks.is_empty() {
            return Err(verr(
                "particle sinks would remove coupled particles; remove dem.sinks".into(),
            ));
        }
        if !(settings.min_weight > 0.0 && settings.min_weight <= 1.0) {
            return Err(verr(format!(
                "min_weight {} is not in (0, 1]",
                settings.min_weight
            )));
        }
        if settings.max_drift.is_nan() || settings.max_drift < 0.0 {
            return Err(verr(format!(
                "max_drift {} is negative",
                settings.max_drift
            )));
        }
        if self.state.volumes.iter().any(|v| v.name == name) {
            return Err(verr("a volume interface of this name exists".into()));
        }
        if self.cfg.impact_substeps > 1 {
            return Err(verr(
                "impact_substeps > 1 would step the particles between the FE nodes' window \
                 positions; set dem.impact_substeps = 1"
                    .into(),
            ));
        }
        let p = &self.state.particles;
        let cands: Vec<volume_coupling::Candidate> = (0..p.len())
            .map(|k| volume_coupling::Candidate {
                id: p.id[k],
                centre: p.position[k],
                volume: p.volume(k),
            })
            .collect();
        let coupling = volume_coupling::VolumeCoupling::new(
            mesh.clone(),
            &cands,
            settings.projection,
            settings.penalty,
        )
        .map_err(|e| verr(e.to_string()))?;
        if coupling.is_empty() {
            return Err(verr(
                "no particle centre lies in the overlap's elements".into(),
            ));
        }
        // a particle in two overlaps would be weighted twice
        for other in &self.state.volumes {
            let theirs: std::collections::HashSet<u32> =
                other.particles.iter().map(|p| p.0).collect();
            if let Some(id) = coupling.ids().iter().find(|id| theirs.contains(id)) {
                return Err(verr(format!(
                    "particle {id} also lies in the overlap of volume interface `{}`: \
                     overlaps must not share particles",
                    other.name
                )));
            }
        }
        // the penalty's explicit step limit per coupled particle (§4.3's caution)
        let by_id: std::collections::HashMap<u32, usize> =
            (0..p.len()).map(|k| (p.id[k], k)).collect();
        let (limit, id) = penalty_step_limit(&coupling, &p.mass, &by_id, settings.min_weight);
        if self.dt > limit {
            return Err(verr(format!(
                "the penalty makes the explicit step limit 2 √(w m / k) = {limit:e} s \
                 (particle {id}) smaller than dem.time_step {:e} s; lower the penalty, \
                 raise min_weight or reduce the time step",
                self.dt
            )));
        }
        let particles = (0..coupling.len())
            .map(|k| {
                (
                    coupling.ids()[k],
                    coupling.reference(k),
                    cands[by_id[&coupling.ids()[k]]].volume,
                )
            })
            .collect();
        let n = mesh.nodes.len();
        let state = volume_coupling::VolumeInterfaceState {
            name: name.to_string(),
            shape: volume_coupling::shape_name(mesh.shape).to_string(),
            node_ids: mesh.node_ids,
            nodes: mesh.nodes.clone(),
            elements: mesh.elements,
            weights: mesh.weights,
            settings,
            penalty: settings.penalty,
            particles,
            window_p: mesh.nodes,
            window_v: vec![V3::zeros(); n],
            window_a: vec![V3::zeros(); n],
            rule: MotionRule::Quadratic,
            window_steps: 0,
            force_sum: vec![V3::zeros(); n],
            window_substeps: 0,
            energy: 0.0,
            window_work: 0.0,
            prediction_defect: 0.0,
        };
        // the coupling located above is the one a restore rebuilds from `state`
        let iface = volume_coupling::VolumeInterface::new(coupling);
        self.state.volumes.push(state);
        self.volumes.push(iface);
        self.refresh_volume_slots();
        // the stored forces become the weighted ones
        self.refresh_forces();
        Ok(self.volumes.len() - 1)
    }

    /// The slots of the coupled particles and the bodies' weights by slot, after the
    /// particles were sorted (or restored). False if a coupled particle is missing.
    fn refresh_volume_slots(&mut self) -> bool {
        let p = &self.state.particles;
        let n = p.len();
        let by_id: std::collections::HashMap<u32, u32> =
            (0..n).map(|k| (p.id[k], k as u32)).collect();
        let mut w = volume_coupling::SlotWeights {
            weight: vec![1.0; n],
            gradient: vec![V3::zeros(); n],
        };
        let mut complete = true;
        for v in &mut self.volumes {
            for (k, id) in v.coupling.ids().iter().enumerate() {
                match by_id.get(id) {
                    Some(&slot) => {
                        v.slot[k] = slot;
                        w.weight[slot as usize] = v.coupling.weight(k);
                        w.gradient[slot as usize] = v.coupling.weight_gradient(k);
                    }
                    None => {
                        v.slot[k] = u32::MAX;
                        complete = false;
                    }
                }
            }
        }
        self.volume_weights = Some(w);
        complete
    }

    /// Index of the volume interface `name`.
    pub fn volume_interface(&self, name: &str) -> Option<usize> {
        self.state.volumes.iter().position(|v| v.name == name)
    }

    /// Sets the window kinematics P, V, A of a volume interface's nodes (flat node-major xyz,
    /// the FE side's current positions, velocities, accelerations) and the motion rule;
    /// resets the window clock and the force accumulator. Stops with an error naming the
    /// particle when a coupled particle has left its element by more than `max_drift`.
    pub fn set_volume_kinematics(
        &mut self,
        iface: usize,
        positions: &[f64],
        velocities: &[f64],
        accelerations: &[f64],
        rule: MotionRule,
    ) -> Result<(), DemError> {
        let Some(st) = self.state.volumes.get_mut(iface) else {
            return Err(DemError::Volume {
                interface: format!("#{iface}"),
                message: "no such volume interface".into(),
            });
        };
        let verr = |message: String| DemError::Volume {
            interface: st.name.clone(),
            message,
        };
        let n3 = 3 * st.nodes.len();
        for (what, a) in [
            ("positions", positions),
            ("velocities", velocities),
            ("accelerations", accelerations),
        ] {
            if a.len() != n3 {
                return Err(verr(format!(
                    "{what} has {} values, expected {n3} (3 per node)",
                    a.len()
                )));
            }
            if let Some(k) = a.iter().position(|x| !x.is_finite()) {
                return Err(verr(format!(
                    "non-finite {what}[{k}] (node {})",
                    st.node_ids[k / 3]
                )));
            }
        }
        let v = &self.volumes[iface];
        let pos = &self.state.particles.position;
        let to_v = |a: &[f64]| {
            a.chunks(3)
                .map(|c| V3::new(c[0], c[1], c[2]))
                .collect::<Vec<V3>>()
        };
        let new_p = to_v(positions);
        for k in 0..v.coupling.len() {
            let x = pos[v.slot[k] as usize];
            // against the continuum's elements where they are now
            let d = v.coupling.drift(k, x, &new_p);
            if d > st.settings.max_drift {
                return Err(verr(format!(
                    "particle {} at ({:.4e}, {:.4e}, {:.4e}) m left its overlap element by \
                     {d:.3} element sizes (max_drift {}) relative to the continuum: the \
                     coupling terms built in the reference configuration no longer hold \
                     (Wellmann §6.3)",
                    v.coupling.ids()[k],
                    x.x,
                    x.y,
                    x.z,
                    st.settings.max_drift
                )));
            }
        }
        if st.window_steps > 0 {
            let tau = st.window_steps as f64 * self.dt;
            let miss: Vec<V3> = (0..new_p.len())
                .map(|i| new_p[i] - st.node_motion(i, tau).0)
                .collect();
            let mut f = vec![V3::zeros(); miss.len()];
            v.coupling.pull(&miss, &mut f);
            st.prediction_defect = f.iter().sum::<V3>().norm();
        }
        st.window_p = new_p;
        st.window_v = to_v(velocities);
        st.window_a = to_v(accelerations);
        st.rule = rule;
        st.window_steps = 0;
        st.force_sum.iter_mut().for_each(|f| *f = V3::zeros());
        st.window_substeps = 0;
        st.window_work = 0.0;
        Ok(())
    }

    /// What a volume interface's provider reads as its forces (flat xyz): the penalty pull
    /// ε V u^DE on its nodes (it holds ε V in its operator, so that the penalty force
    /// ε V (u^DE − u^FE) acts implicitly on its side), of the last step, or with `averaged`
    /// the mean over the window's substeps. Empty for an unknown index.
    pub fn volume_forces(&self, iface: usize, averaged: bool) -> Vec<f64> {
        let (Some(st), Some(v)) = (self.state.volumes.get(iface), self.volumes.get(iface)) else {
            return Vec::new();
        };
        window_forces(averaged, &st.force_sum, st.window_substeps, &v.pull)
    }

    /// The penalty forces (6.25) on the FE nodes of a volume interface at their window motion
    /// (flat xyz) of the last evaluation; empty for an unknown index.
    pub fn volume_penalty_forces(&self, iface: usize) -> Vec<f64> {
        self.volumes.get(iface).map_or_else(Vec::new, |v| {
            v.on_nodes.iter().flat_map(|f| [f.x, f.y, f.z]).collect()
        })
    }

    /// The FE nodes' positions of a volume interface now (flat xyz; empty for an unknown
    /// index).
    pub fn volume_node_positions(&self, iface: usize) -> Vec<f64> {
        let Some(st) = self.state.volumes.get(iface) else {
            return Vec::new();
        };
        let tau = st.window_steps as f64 * self.dt;
        (0..st.nodes.len())
            .flat_map(|i| {
                let x = st.node_motion(i, tau).0;
                [x.x, x.y, x.z]
            })
            .collect()
    }

    /// Work of the penalty forces on the FE nodes of a volume interface as they moved in the
    /// DEM since its window kinematics were set [J] (0 for an unknown index).
    pub fn volume_work(&self, iface: usize) -> f64 {
        self.state.volumes.get(iface).map_or(0.0, |v| v.window_work)
    }

    /// The penalty energy C (6.23) of the last evaluation of a volume interface (0 for an
    /// unknown index).
    pub fn volume_energy(&self, iface: usize) -> f64 {
        self.state.volumes.get(iface).map_or(0.0, |v| v.energy)
    }

    /// The projected particle displacements u^DE (6.16) at the nodes of a volume interface
    /// (flat xyz) of the last evaluation.
    pub fn volume_projected_displacements(&self, iface: usize) -> Vec<f64> {
        self.volumes.get(iface).map_or_else(Vec::new, |v| {
            v.u_de.iter().flat_map(|u| [u.x, u.y, u.z]).collect()
        })
    }

    /// u^DE, u^FE, the penalty forces and the pull of every volume interface at the current
    /// state and window time, without touching the particles or the window sums.
    fn evaluate_volumes(&mut self) {
        let dt = self.dt;
        let s = &mut self.state;
        for (st, v) in s.volumes.iter_mut().zip(&mut self.volumes) {
            let tau = st.window_steps as f64 * dt;
            for (k, u) in v.u_d.iter_mut().enumerate() {
                *u = s.particles.position[v.slot[k] as usize] - st.particles[k].1;
            }
            v.coupling.project(&v.u_d, &mut v.u_de);
            for (i, u) in v.u_fe.iter_mut().enumerate() {
                *u = st.node_motion(i, tau).0 - st.nodes[i];
            }
            st.energy = v.coupling.penalty_forces(
                &v.u_de,
                &v.u_fe,
                &mut v.on_nodes,
                &mut v.on_particles,
                &mut v.scratch,
            );
            v.coupling.pull(&v.u_de, &mut v.pull);
        }
    }

    /// The volume interfaces after the contact forces: the penalty forces (6.25)–(6.26) from
    /// the particles' displacements and the FE nodes' at window time τ, and the weighted
    /// equations of motion (6.10)–(6.11) of the coupled particles — their contact forces and
    /// torques were weighted at the contact points by the kernels; here they are divided by
    /// the floored weight w̃ of mass and inertia, gravity is weighted by w (w m g / w̃), the
    /// penalty force is added.
    /// The nodal forces enter the window sum with `weight`; `count_step` counts a substep.
    fn volume_stage(&mut self, weight: f64, count_step: bool) {
        self.evaluate_volumes();
        let dt = self.dt;
        let g = self.gravity;
        let s = &mut self.state;
        for (st, v) in s.volumes.iter_mut().zip(&self.volumes) {
            let tau = st.window_steps as f64 * dt;
            if weight > 0.0 {
                let power: f64 = (0..v.on_nodes.len())
                    .map(|i| v.on_nodes[i].dot(&st.node_motion(i, tau).1))
                    .sum();
                for (sum, f) in st.force_sum.iter_mut().zip(&v.pull) {
                    *sum += f * weight;
                }
                st.window_work += power * dt * weight;
            }
            if count_step {
                st.window_substeps += 1;
            }
            let p = &mut s.particles;
            for k in 0..v.coupling.len() {
                let slot = v.slot[k] as usize;
                let wk = v.coupling.weight(k);
                let w = wk.max(st.settings.min_weight);
                // (6.10): w m c̈ = w m g + Σ w_β f_β + f^C, the mass weight floored
                let mg = g * p.mass[slot];
                p.force[slot] = mg * (wk / w) + (p.force[slot] - mg + v.on_particles[k]) / w;
                p.torque[slot] /= w;
            }
        }
    }

    fn coupled_mesh(&self, mesh: usize) -> Option<&Mesh> {
        self.state.meshes.get(mesh).filter(|m| m.coupled)
    }

    /// Sets the window kinematics P, V, A of a coupled mesh (flat node-major xyz) and its
    /// motion rule; resets the window clock τ = 0 and the force-averaging accumulator.
    pub fn set_mesh_kinematics(
        &mut self,
        mesh: usize,
        positions: &[f64],
        velocities: &[f64],
        accelerations: &[f64],
        rule: MotionRule,
    ) -> Result<(), DemError> {
        let Some(m) = self.state.meshes.get_mut(mesh).filter(|m| m.coupled) else {
            return Err(DemError::UnknownMesh(mesh));
        };
        let n3 = 3 * m.positions.len();
        for (what, a) in [
            ("positions", positions),
            ("velocities", velocities),
            ("accelerations", accelerations),
        ] {
            if a.len() != n3 {
                return Err(DemError::Mesh {
                    mesh: m.name.clone(),
                    message: format!("{what} has {} values, expected {n3} (3 per node)", a.len()),
                });
            }
            if let Some(k) = a.iter().position(|x| !x.is_finite()) {
                return Err(DemError::Mesh {
                    mesh: m.name.clone(),
                    message: format!("non-finite {what}[{k}]"),
                });
            }
        }
        let to_v = |a: &[f64]| {
            a.chunks(3)
                .map(|c| V3::new(c[0], c[1], c[2]))
                .collect::<Vec<V3>>()
        };
        m.window_p = to_v(positions);
        m.window_v = to_v(velocities);
        m.window_a = to_v(accelerations);
        m.rule = rule;
        m.tau = 0.0;
        m.window_steps = 0;
        m.move_to(0.0);
        m.nodal_force_sum.iter_mut().for_each(|f| *f = V3::zeros());
        m.window_substeps = 0;
        m.window_work = 0.0;
        // The lists stay valid while no node moved d_V/2 since the build (checked every step,
        // eq. 4.10) and the contact patches are unchanged; new patch ids must reach the
        // candidate lists, so a deformation that changes them forces a rebuild.
        let patch = walls::compute_patches(&m.positions, &m.triangles);
        if patch != m.patch {
            m.patch = patch;
            self.state.lists.valid = false;
        }
        Ok(())
    }

    /// Re-evaluates the contact forces of the current state without advancing time and without
    /// tangential-history increments, e.g. after adding meshes or editing particles at set-up
    /// (otherwise the first half kick uses the forces of the previous configuration).
    pub fn refresh_forces(&mut self) {
        self.run(|e| {
            let moved = broad_phase::particles_moved(&e.state.lists, &e.state.particles);
            e.detect_contacts(moved);
            e.resolve_forces(0.0, 0.0, false);
        });
    }

    /// Runs `substeps` DEM steps of `time_step` (bitwise the same as calling [`Engine::step`]
    /// `substeps` times; the second half kick of a step and the first of the next share one
    /// pass over the particles).
    pub fn advance(&mut self, substeps: usize) -> Result<(), DemError> {
        if substeps == 0 {
            return Ok(());
        }
        let steps = self.state.steps;
        if let (Some(cell), Some(servo), false, false) = (
            &self.state.cell,
            &self.servo,
            self.programme_finished(),
            self.programme_end
                .as_ref()
                .is_some_and(|(s, _)| *s == steps),
        ) {
            let avg = self.cell_averages().expect("a cell has averages");
            self.programme_end = Some((steps, periodic::results(cell, servo, &avg)));
        }
        if self.cfg.impact_substeps > 1 {
            // each step decides on refinement from its start state: no fused passes
            return self.run(|e| (0..substeps).try_for_each(|_| e.step_in_pool()));
        }
        self.run(|e| {
            let dt = e.dt;
            let mut moved = e.drift_stage(dt, StepClock::Step, None);
            for s in 0..substeps {
                let walls_finite = e.force_stage(moved, dt, 1.0, true);
                if s + 1 == substeps {
                    return e.kick_stage(dt, walls_finite);
                }
                // the second half kick of this step and the first of the next share one pass
                let (finite, m) = e.particle_passes(dt, Pass::KickThenKickDrift);
                if !(finite && walls_finite) {
                    return Err(e.instability());
                }
                e.check_cell()?;
                moved = e.drift_stage(dt, StepClock::Step, Some(m));
            }
            Ok(())
        })
    }

    /// One DEM step, Ullrich's Algorithm 1 in velocity-Verlet form: the first half kick and
    /// drift move the particles (and coupled meshes by their motion rule) to t + Δt, then
    /// contacts are detected, forces resolved, and the state update completed.
    ///
    /// With `impact_substeps` = N > 1, a step during which a contact is predicted to touch
    /// runs as N sub-steps of Δt/N ([`impact_refinement`]).
    pub fn step(&mut self) -> Result<(), DemError> {
        self.run(|e| e.step_in_pool())
    }

    fn step_in_pool(&mut self) -> Result<(), DemError> {
        let n = self.cfg.impact_substeps;
        if n > 1 && self.contact_during_step() {
            return self.refined_step(n);
        }
        let moved = self.drift_stage(self.dt, StepClock::Step, None);
        let walls_finite = self.force_stage(moved, self.dt, 1.0, true);
        self.kick_stage(self.dt, walls_finite)
    }

    // The stages of a step (Algorithm 1), written once: a plain step, the fused steps of
    // `advance` and the sub-steps of an impact-refined step all run drift → forces → kick.

    /// Stage "update particle states", first half: half kick and drift of the particles over
    /// `h` (unless `particles_moved` says a fused pass did it), of the loaded walls, then the
    /// clock, coupled meshes and moving walls go to the step's (or sub-step's) end and the
    /// flow sensors book the crossings. Returns true if a particle moved half the skin.
    fn drift_stage(&mut self, h: f64, clock: StepClock, particles_moved: Option<bool>) -> bool {
        let moved = particles_moved.unwrap_or_else(|| self.particle_passes(h, Pass::KickDrift).1);
        self.loaded_walls_kick_drift(h);
        if let (Some(servo), Some(cell)) = (&self.servo, self.state.cell.as_mut()) {
            servo.advance(cell, h);
        }
        match clock {
            StepClock::Step => self.advance_clock(),
            StepClock::Substep { t0, k, n } if k < n => {
                self.set_substep_clock(t0, k as f64 / n as f64)
            }
            StepClock::Substep { t0, .. } => {
                // from t0 by the unrefined step's own operation, so the end time is bitwise
                self.state.time = t0;
                self.advance_clock();
            }
        }
        self.track_flow();
        moved
    }

    /// Stages "detect contacts" and "resolve forces" (Algorithm 1, lines 3–4), then the
    /// loaded walls' second half kick. Returns false if a loaded wall's state is not finite.
    fn force_stage(&mut self, moved: bool, h: f64, weight: f64, ends_step: bool) -> bool {
        self.detect_contacts(moved);
        self.resolve_forces(h, weight, ends_step);
        if ends_step {
            self.update_cell();
        }
        self.loaded_walls_kick(h)
    }

    /// Stage "update particle states", second half: the particles' half kick over `h`.
    fn kick_stage(&mut self, h: f64, walls_finite: bool) -> Result<(), DemError> {
        let (finite, _) = self.particle_passes(h, Pass::Kick);
        self.check_cell()?;
        if finite && walls_finite {
            Ok(())
        } else {
            Err(self.instability())
        }
    }

    /// One pass over the particles ([`integrate`]): (finite, moved half the skin).
    fn particle_passes(&mut self, h: f64, pass: Pass) -> (bool, bool) {
        let rotation = self.cfg.rotation;
        let p = &mut self.state.particles;
        let l = &self.state.lists;
        match pass {
            Pass::KickDrift => (
                true,
                integrate::kick_drift(p, &l.position_at_build, 0.5 * l.skin, h, rotation),
            ),
            Pass::Kick => (integrate::kick(p, h, rotation), false),
            Pass::KickThenKickDrift => {
                integrate::kick_then_kick_drift(p, &l.position_at_build, 0.5 * l.skin, h, rotation)
            }
        }
    }

    /// Does a contact touch during the next step (see [`impact_refinement`])?
    fn contact_during_step(&mut self) -> bool {
        let wall_shift_at_step_end = self.wall_shift_since_build(self.state.time + self.dt);
        let s = &self.state;
        let walls = impact_refinement::WallsView {
            planes: &self.planes,
            meshes: &s.meshes,
            wall_shift_at_step_end,
        };
        impact_refinement::contact_during_step(
            &s.lists,
            &s.particles,
            &walls,
            self.dt,
            &mut self.predicted,
        )
    }

    /// One step of Δt as `n` velocity-Verlet sub-steps of Δt/n. The clock, coupled meshes and
    /// prescribed walls follow the sub-step times; the step counter, the meshes' window step
    /// count and the end time are those of an unrefined step (bitwise). Each sub-step's nodal
    /// forces enter the window average with weight 1/n, so the average stays a time average
    /// (Ullrich eq. 3.8 with the substeps' forces weighted by their duration).
    fn refined_step(&mut self, n: usize) -> Result<(), DemError> {
        let h = self.dt / n as f64;
        let t0 = self.state.time;
        for k in 1..=n {
            let moved = self.drift_stage(h, StepClock::Substep { t0, k, n }, None);
            let walls_finite = self.force_stage(moved, h, 1.0 / n as f64, k == n);
            self.kick_stage(h, walls_finite)?;
        }
        self.refined_steps += 1;
        Ok(())
    }

    /// Puts the clock, coupled meshes and prescribed walls at t0 + fraction·Δt inside the
    /// current step (the step and window-step counters stay).
    fn set_substep_clock(&mut self, t0: f64, fraction: f64) {
        let dt = self.dt;
        let s = &mut self.state;
        s.time = t0 + fraction * dt;
        for m in s.meshes.iter_mut().filter(|m| m.coupled) {
            m.tau = (m.window_steps as f64 + fraction) * dt;
            m.move_to(m.tau);
        }
        self.place_walls(true);
    }

    /// Number of steps run as `impact_substeps` sub-steps since the engine was built.
    pub fn refined_steps(&self) -> u64 {
        self.refined_steps
    }

    /// Number of DEM steps since the start (snapshots included); a refined step counts once.
    pub fn steps(&self) -> u64 {
        self.state.steps
    }

    /// First half kick and drift of the loaded walls over `h`, with the forces of the last
    /// evaluation (velocity Verlet, as the particles; the clock still shows that evaluation's
    /// time).
    fn loaded_walls_kick_drift(&mut self, h: f64) {
        let t = self.state.time;
        for (w, st) in self.loaded_walls.iter().zip(&mut self.state.loaded_walls) {
            match w.driven_velocity(t) {
                Some(v) => st.v = v,
                None => st.v += 0.5 * h * w.acceleration(t, st.contact_force, &self.gravity),
            }
            st.u += h * st.v;
        }
    }

    /// Second half kick of the loaded walls over `h`. Returns false if a state is non-finite.
    fn loaded_walls_kick(&mut self, h: f64) -> bool {
        let t = self.state.time;
        let mut finite = true;
        for (w, st) in self.loaded_walls.iter().zip(&mut self.state.loaded_walls) {
            match w.driven_velocity(t) {
                Some(v) => st.v = v,
                None => st.v += 0.5 * h * w.acceleration(t, st.contact_force, &self.gravity),
            }
            finite &= st.u.is_finite() && st.v.is_finite();
        }
        finite
    }

    /// The particles' contact force on wall `w` (planes first, then meshes) from the force
    /// records of the last evaluation (weighted at the contact points in a volume overlap).
    fn wall_contact_force(&self, w: usize) -> V3 {
        let s = &self.state;
        let mut f = V3::zeros();
        for (k, rec) in s.records.iter().enumerate() {
            if s.lists.wall_contacts[k].touching() && s.lists.walls[k].wall as usize == w {
                f += rec.force;
            }
        }
        for (cw, c) in shaped_wall_contacts(&s.lists) {
            if c.touching() && cw as usize == w {
                f -= c.force;
            }
        }
        f
    }

    /// The axis components of the particles' contact forces on the loaded walls (from the
    /// force records of the touching wall contacts, in list order); a wall that is held or
    /// removed is at rest.
    fn loaded_wall_forces(&mut self) {
        if self.loaded_walls.is_empty() {
            return;
        }
        let n_planes = self.planes.len();
        let s = &mut self.state;
        let index = |w: &LoadedWall| match w.wall {
            WallRef::Plane(k) => k,
            WallRef::Mesh(k) => n_planes + k,
        };
        for st in &mut s.loaded_walls {
            st.contact_force = 0.0;
        }
        for (k, rec) in s.records.iter().enumerate() {
            if !s.lists.wall_contacts[k].touching() {
                continue;
            }
            let w = s.lists.walls[k].wall as usize;
            for (lw, st) in self.loaded_walls.iter().zip(&mut s.loaded_walls) {
                if index(lw) == w {
                    st.contact_force += rec.force.dot(&lw.axis);
                }
            }
        }
        // shaped bodies on loaded walls: the reaction of their contact force
        for (w, c) in shaped_wall_contacts(&s.lists) {
            if !c.touching() {
                continue;
            }
            for (lw, st) in self.loaded_walls.iter().zip(&mut s.loaded_walls) {
                if index(lw) == w as usize {
                    st.contact_force -= c.force.dot(&lw.axis);
                }
            }
        }
        let t = s.time;
        for (lw, st) in self.loaded_walls.iter().zip(&mut s.loaded_walls) {
            if let Some(v) = lw.driven_velocity(t) {
                st.v = v;
            } else if !lw.free(t) {
                st.v = 0.0;
            }
        }
    }

    fn advance_clock(&mut self) {
        let dt = self.dt;
        let s = &mut self.state;
        s.time += dt;
        s.steps += 1;
        for m in s.meshes.iter_mut().filter(|m| m.coupled) {
            m.window_steps += 1;
            m.tau = m.window_steps as f64 * dt;
            m.move_to(m.tau);
        }
        for v in &mut s.volumes {
            v.window_steps += 1;
        }
        self.place_walls(true);
    }

    /// Puts the static walls with a prescribed motion where they are at the current time.
    /// A wall appearing or disappearing invalidates the neighbour lists if `invalidate`
    /// (not on restore: the restored lists already match the restored time).
    fn place_walls(&mut self, invalidate: bool) {
        let t = self.state.time;
        let s = &mut self.state;
        let mut changed = false;
        for m in &self.wall_motions {
            changed |= m.apply(t, &mut self.planes, &mut s.meshes);
        }
        for (w, st) in self.loaded_walls.iter().zip(&s.loaded_walls) {
            changed |= w.apply(t, st, &mut self.planes, &mut s.meshes);
        }
        if changed && invalidate {
            s.lists.valid = false;
        }
    }

    /// Books the flow sensors' plane crossings of the last drift.
    fn track_flow(&mut self) {
        if self.cfg.sensors.is_empty() {
            return;
        }
        let s = &mut self.state;
        s.sensors.track_flow(&self.cfg.sensors, &s.particles);
    }

    /// The displacements of the prescribed-motion walls, then of the loaded walls, at time `t`
    /// (a loaded wall extrapolated from the current time with its velocity).
    fn wall_displacements(&self, t: f64) -> impl Iterator<Item = V3> + '_ {
        let now = self.state.time;
        let prescribed = self.wall_motions.iter().map(move |m| m.displacement(t));
        let loaded = (self.loaded_walls.iter().zip(&self.state.loaded_walls))
            .map(move |(w, st)| w.axis * (st.u + st.v * (t - now)));
        prescribed.chain(loaded)
    }

    /// The farthest a moving static wall is at time `t` from where it was at the last list
    /// build (∞ when the lists predate the walls).
    fn wall_shift_since_build(&self, t: f64) -> f64 {
        let at_build = &self.state.lists.wall_shift_at_build;
        if at_build.len() != self.wall_motions.len() + self.loaded_walls.len() {
            return f64::INFINITY;
        }
        self.wall_displacements(t)
            .zip(at_build)
            .map(|(d, d0)| (d - d0).norm())
            .fold(0.0, f64::max)
    }

    /// Algorithm 1, line 3. Prescribed-motion walls are rigid translations: the lists are
    /// rebuilt when one moved d_V/2 since the last build (eq. 4.10), like coupled meshes.
    fn detect_contacts(&mut self, particles_moved: bool) {
        let t = self.state.time;
        let walls_moved = self.wall_shift_since_build(t) > 0.5 * self.state.lists.skin;
        let keep_records = !self.loaded_walls.is_empty()
            || self.state.meshes.iter().any(|m| m.coupled)
            || self.wall_motions.iter().any(|m| m.name.is_some());
        let s = &mut self.state;
        let rebuilt = contact_detection::detect(
            &mut s.lists,
            &mut s.particles,
            particles_moved || walls_moved,
            &self.planes,
            &mut s.meshes,
            &mut s.records,
            keep_records,
            &self.cfg.sinks,
            s.cell.as_ref().map(|c| c.size),
        );
        if let Some(removed) = rebuilt {
            if !self.volumes.is_empty() {
                // the build sorted the particles: the coupled ones have new slots
                self.refresh_volume_slots();
            }
            let s = &mut self.state;
            s.removed_particles += removed.count;
            s.removed_mass += removed.mass;
            // refill the list's own buffer (no allocation per build)
            let mut shifts = std::mem::take(&mut s.lists.wall_shift_at_build);
            shifts.clear();
            shifts.extend(self.wall_displacements(t));
            self.state.lists.wall_shift_at_build = shifts;
        }
    }

    /// Algorithm 1, line 4. `dt` is the history increment time (0: pure evaluation); the
    /// coupled meshes' nodal forces enter the window sum with `weight`, and `ends_step` counts
    /// one window substep.
    fn resolve_forces(&mut self, dt: f64, weight: f64, ends_step: bool) {
        let s = &mut self.state;
        let ctx = ForceContext {
            materials: &self.materials,
            planes: &self.planes,
            meshes: &s.meshes,
            gravity: self.gravity,
            hold_stiffness: self.cfg.superquadric_stiffness == config::StiffnessUpdate::FirstTouch,
            surface_budget: self.cfg.superquadric_surface_budget,
            dt,
            cell: force_cell(&self.servo, &s.cell),
            weights: self.volume_weights.as_ref(),
        };
        resolve_forces::contact_forces(&mut s.lists, &mut s.particles, &mut s.records, &ctx);
        shaped_forces::shaped_forces(&mut s.lists, &mut s.particles, &ctx);
        periodic::periodic_forces(&mut s.lists, &mut s.particles, &ctx);
        if !self.volumes.is_empty() {
            self.volume_stage(if dt > 0.0 { weight } else { 0.0 }, dt > 0.0 && ends_step);
        }
        let s = &mut self.state;
        if s.meshes.iter().any(|m| m.coupled) {
            resolve_forces::accumulate_nodal_forces(
                &mut s.meshes,
                &s.lists,
                self.planes.len(),
                &s.records,
                if dt > 0.0 { weight } else { 0.0 },
                dt > 0.0 && ends_step,
                dt,
            );
        }
        self.loaded_wall_forces();
    }

    /// The first shaped contact whose cores interpenetrate (its force is NaN), as an error
    /// naming the two bodies (particle ids, or the wall).
    fn intersecting_cores(&self) -> Option<DemError> {
        let (p, l) = (&self.state.particles, &self.state.lists);
        let bad = |c: &broad_phase::ShapedContact| c.touching() && !c.force.x.is_finite();
        let dilation = |k: usize| match p.polyhedron(k) {
            Some((s, scale)) => s.dilation * scale,
            None if p.template(k).is_none() => p.radius[k],
            None => 0.0,
        };
        let wall_name = |w: usize| match w.checked_sub(self.planes.len()) {
            None => format!("plane wall {w}"),
            Some(m) => format!("mesh `{}`", self.state.meshes[m].name),
        };
        let (first, second, overlap, dilation) = if let Some((&[i, j], c)) = l
            .shaped_pairs
            .iter()
            .zip(&l.shaped_pair_contacts)
            .find(|(_, c)| bad(c))
        {
            let (i, j) = (i as usize, j as usize);
            (
                format!("particle {}", p.id[i]),
                format!("particle {}", p.id[j]),
                c.overlap,
                dilation(i) + dilation(j),
            )
        } else if let Some((&[k, w], c)) = l
            .shaped_walls
            .iter()
            .zip(&l.shaped_wall_contacts)
            .find(|(_, c)| bad(c))
        {
            let k = k as usize;
            (
                format!("particle {}", p.id[k]),
                wall_name(w as usize),
                c.overlap,
                dilation(k),
            )
        } else {
            let ((k, w), c) = l
                .shaped_mesh
                .iter()
                .zip(&l.shaped_mesh_contacts)
                .find(|(_, c)| bad(c))?;
            let k = *k as usize;
            (
                format!("particle {}", p.id[k]),
                wall_name(w.wall as usize),
                c.overlap,
                dilation(k),
            )
        };
        Some(DemError::CoresIntersect {
            time: self.state.time,
            step: self.state.steps,
            first,
            second,
            overlap,
            dilation,
        })
    }

    /// The error naming the first loaded wall or particle with a non-finite state.
    fn instability(&self) -> DemError {
        let wall = (self.loaded_walls.iter().zip(&self.state.loaded_walls))
            .find(|(_, st)| !(st.u.is_finite() && st.v.is_finite()));
        if let Some((w, _)) = wall {
            return DemError::UnstableWall {
                time: self.state.time,
                step: self.state.steps,
                wall: w.name.clone(),
            };
        }
        if let Some(e) = self.intersecting_cores() {
            return e;
        }
        let p = &self.state.particles;
        let bad = |v: &V3| !(v.x.is_finite() && v.y.is_finite() && v.z.is_finite());
        let (particle, quantity) = (0..p.len())
            .find_map(|k| {
                [
                    ("position", &p.position[k]),
                    ("velocity", &p.velocity[k]),
                    ("angular velocity", &p.angular_velocity[k]),
                ]
                .into_iter()
                .find(|(_, v)| bad(v))
                .map(|(q, _)| (p.id[k], q))
            })
            .unwrap_or_else(|| {
                // all components finite but their sum overflowed (|value| > 1e307)
                let k = (0..p.len())
                    .find(|&k| {
                        let s =
                            p.position[k].sum() + p.velocity[k].sum() + p.angular_velocity[k].sum();
                        !s.is_finite()
                    })
                    .unwrap_or(0);
                (
                    p.id.get(k).copied().unwrap_or(0),
                    "state (magnitude overflow)",
                )
            });
        DemError::Unstable {
            time: self.state.time,
            step: self.state.steps,
            particle,
            quantity,
            rayleigh: self.rayleigh_time_step(),
        }
    }

    /// Nodal forces exerted by the particles on a coupled mesh (flat xyz): the last substep's,
    /// or with `averaged` the mean over the window's substeps (Ullrich eq. 3.8). Empty for an
    /// unknown mesh index.
    pub fn interface_forces(&self, mesh: usize, averaged: bool) -> Vec<f64> {
        let Some(m) = self.coupled_mesh(mesh) else {
            return Vec::new();
        };
        window_forces(
            averaged,
            &m.nodal_force_sum,
            m.window_substeps,
            &m.nodal_force_last,
        )
    }

    /// Work the particles did on a coupled mesh since its window kinematics were set,
    /// Σ Δt Σ_nodes f·v over the steps [J] (0 for an unknown index).
    pub fn interface_work(&self, mesh: usize) -> f64 {
        self.coupled_mesh(mesh).map_or(0.0, |m| m.window_work)
    }

    /// Current node positions of a coupled mesh (flat xyz); empty for an unknown index.
    pub fn mesh_positions(&self, mesh: usize) -> Vec<f64> {
        self.coupled_mesh(mesh)
            .map(|m| m.positions.iter().flat_map(|v| [v.x, v.y, v.z]).collect())
            .unwrap_or_default()
    }

    /// The shortest time in which a particle not yet near a coupled mesh could reach the
    /// mesh's bounding box at the present speeds (the particle's radius taken off, the mesh's
    /// fastest node closing in too), s: 0 when a particle is within reach now, `None` when no
    /// particle approaches. Adaptive coupling windows shorten ahead of an impact with it.
    pub fn interface_approach_time(&self, mesh: usize) -> Option<f64> {
        let m = self.coupled_mesh(mesh)?;
        let (mut lo, mut hi) = (V3::repeat(f64::INFINITY), V3::repeat(f64::NEG_INFINITY));
        for p in &m.positions {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        let mesh_speed = m.velocities.iter().fold(0.0f64, |a, v| a.max(v.norm()));
        let ps = &self.state.particles;
        let mut best: Option<f64> = None;
        for i in 0..ps.position.len() {
            let c = ps.position[i];
            let nearest = c.sup(&lo).inf(&hi);
            let gap = c - nearest;
            let d = gap.norm();
            let clearance = d - ps.radius[i];
            let t = if clearance <= 0.0 {
                0.0
            } else {
                let closing = -ps.velocity[i].dot(&(gap / d)) + mesh_speed;
                if closing <= 0.0 {
                    continue;
                }
                clearance / closing
            };
            best = Some(best.map_or(t, |b: f64| b.min(t)));
        }
        best
    }

    /// Translational plus rotational kinetic energy, J.
    pub fn kinetic_energy(&self) -> f64 {
        self.state.particles.kinetic_energy()
    }

    /// The full mutable state as bytes (MessagePack).
    pub fn snapshot(&self) -> Vec<u8> {
        snapshot::encode(&self.state)
    }

    /// Restores a snapshot of an engine built from the same configuration.
    pub fn restore(&mut self, bytes: &[u8]) -> Result<(), DemError> {
        let s = snapshot::decode(bytes).map_err(DemError::Snapshot)?;
        if s.meshes.len() < self.state.meshes.iter().filter(|m| !m.coupled).count() {
            return Err(DemError::Snapshot(format!(
                "snapshot has {} meshes, this engine's scene defines more static walls",
                s.meshes.len()
            )));
        }
        let n = s.particles.len();
        if !s.lists.consistent(n)
            || !(s.records.is_empty() || s.records.len() == s.lists.walls.len())
            || s.lists.walls.iter().any(|c| {
                let w = c.wall as usize;
                let np = self.planes.len();
                match w.checked_sub(np) {
                    None => false,
                    Some(m) => s
                        .meshes
                        .get(m)
                        .is_none_or(|mesh| c.triangle as usize >= mesh.triangles.len()),
                }
            })
            || s.particles
                .material
                .iter()
                .any(|&m| m as usize >= self.materials.materials.len())
            || s.lists.shaped_mesh.iter().any(|(_, c)| {
                (c.wall as usize)
                    .checked_sub(self.planes.len())
                    .and_then(|m| s.meshes.get(m))
                    .is_none_or(|mesh| c.triangle as usize >= mesh.triangles.len())
            })
            || s.lists
                .shaped_walls
                .iter()
                .any(|&[_, w]| w as usize >= self.planes.len())
        {
            return Err(DemError::Snapshot(
                "snapshot does not match this scene's materials/particles".into(),
            ));
        }
        if s.loaded_walls.len() != self.loaded_walls.len() {
            return Err(DemError::Snapshot(format!(
                "snapshot has {} loaded walls, this scene defines {}",
                s.loaded_walls.len(),
                self.loaded_walls.len()
            )));
        }
        if s.sensors.sensors.len() != self.cfg.sensors.len() {
            return Err(DemError::Snapshot(format!(
                "snapshot has {} sensors, this scene defines {}",
                s.sensors.sensors.len(),
                self.cfg.sensors.len()
            )));
        }
        if s.cell.is_some() != self.servo.is_some() {
            return Err(DemError::Snapshot(format!(
                "snapshot {} a periodic cell, this scene {}",
                if s.cell.is_some() { "has" } else { "has no" },
                if self.servo.is_some() {
                    "defines one ([dem.periodic])"
                } else {
                    "defines none"
                }
            )));
        }
        if let (Some(c), Some(servo)) = (&s.cell, &self.servo) {
            if c.stage > servo.stages.len() {
                return Err(DemError::Snapshot(format!(
                    "snapshot's periodic cell is at stage {}, this scene has {} stages",
                    c.stage,
                    servo.stages.len()
                )));
            }
        }
        // the volume interfaces the node attached at set-up, with their coupled particles
        let names = |v: &[volume_coupling::VolumeInterfaceState]| -> Vec<String> {
            v.iter().map(|i| i.name.clone()).collect()
        };
        if names(&s.volumes) != names(&self.state.volumes) {
            return Err(DemError::Snapshot(format!(
                "snapshot has volume interfaces {:?}, this run attached {:?}",
                names(&s.volumes),
                names(&self.state.volumes)
            )));
        }
        let ids: std::collections::HashSet<u32> = s.particles.id.iter().copied().collect();
        if let Some((v, id)) = s.volumes.iter().find_map(|v| {
            v.particles
                .iter()
                .find(|p| !ids.contains(&p.0))
                .map(|p| (v, p.0))
        }) {
            return Err(DemError::Snapshot(format!(
                "coupled particle {id} of volume interface `{}` is missing from the snapshot",
                v.name
            )));
        }
        let volumes = s
            .volumes
            .iter()
            .map(|v| {
                volume_coupling::VolumeInterface::from_state(v)
                    .map_err(|e| DemError::Snapshot(format!("volume interface `{}`: {e}", v.name)))
            })
            .collect::<Result<Vec<_>, _>>()?;
        self.state = s;
        self.volumes = volumes;
        if self.volumes.is_empty() {
            self.volume_weights = None;
        } else {
            // every coupled id is in the snapshot (checked above)
            self.refresh_volume_slots();
            // the last evaluation's penalty forces and pull, as they were when the snapshot
            // was taken (same positions and window time): a replayed `publish` sends them
            self.evaluate_volumes();
        }
        if self.state.lists.valid {
            self.state.lists.index_blocks();
        }
        self.apply_stage_friction();
        self.place_walls(false);
        // the row of the restored step was written before the snapshot; the rows after it were
        // cut (a resume or an implicit scheme's rollback), so the step an abandoned iteration
        // ended on gets its row again when it is reached again
        self.output.last_row_step = Some(self.state.steps);
        Ok(())
    }

    /// Writes outputs after a window: a CSV row every call (if enabled) and VTK files when
    /// `vtk_every` steps have passed since the last VTK output.
    pub fn write_outputs(&mut self, out_dir: &Path) -> Result<(), DemError> {
        std::fs::create_dir_all(out_dir).map_err(|e| DemError::Output {
            path: out_dir.display().to_string(),
            message: e.to_string(),
        })?;
        let new_rows = self.output.last_row_step != Some(self.state.steps);
        self.output.last_row_step = Some(self.state.steps);
        if self.cfg.output.csv && new_rows {
            let mut row = vec![
                ("time".to_string(), self.time()),
                ("step".to_string(), self.state.steps as f64),
            ];
            row.extend(self.engine_results());
            output::append_csv(&out_dir.join("dem_timeseries.csv"), &row)?;
        }
        if let (true, Some(cell), Some(servo), Some(avg)) = (
            new_rows,
            &self.state.cell,
            &self.servo,
            self.cell_averages(),
        ) {
            output::append_csv(
                &out_dir.join("periodic.csv"),
                &periodic::csv_row(self.time(), cell, servo, &avg),
            )?;
            // the next window's start state: `advance` need not average it again
            if cell.stage < servo.stages.len() {
                self.programme_end = Some((self.state.steps, periodic::results(cell, servo, &avg)));
            }
        }
        if let Some(values) = new_rows.then(|| self.sample_sensors()).flatten() {
            let mut row = vec![("time".to_string(), self.time())];
            row.extend(
                sensors::column_names(&self.cfg.sensors)
                    .into_iter()
                    .zip(values),
            );
            output::append_csv(&out_dir.join("dem_sensors.csv"), &row)?;
        }
        let every = self.cfg.output.vtk_every;
        let due = every > 0
            && self
                .output
                .last_vtk_step
                .is_none_or(|last| self.state.steps >= last + every);
        if due {
            let step = self.state.steps;
            output::write_particles_vtk(
                &out_dir.join(format!("particles_{step:09}.vtk")),
                &self.state.particles,
                self.time(),
            )?;
            output::write_pvd(out_dir, "particles", self.dt)?;
            let p = &self.state.particles;
            if p.templates.iter().any(|t| t.superquadric().is_some()) {
                output::write_superquadrics_vtk(
                    &out_dir.join(format!("superquadrics_{step:09}.vtk")),
                    p,
                    self.time(),
                    16,
                )?;
                output::write_pvd(out_dir, "superquadrics", self.dt)?;
            }
            if !p.stones.is_empty() {
                output::write_polyhedra_vtk(
                    &out_dir.join(format!("polyhedra_{step:09}.vtk")),
                    p,
                    self.time(),
                    16,
                )?;
                output::write_pvd(out_dir, "polyhedra", self.dt)?;
            }
            for (k, m) in self.state.meshes.iter().enumerate() {
                let moving = (self.wall_motions.iter())
                    .any(|w| w.wall == WallRef::Mesh(k) && w.moves())
                    || self.loaded_walls.iter().any(|w| w.wall == WallRef::Mesh(k));
                if !m.active {
                    continue;
                }
                if m.coupled || moving || step == 0 || self.output.vtk_files == 0 {
                    let safe: String = m
                        .name
                        .chars()
                        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
                        .collect();
                    output::write_mesh_vtk(
                        &out_dir.join(format!("mesh{k}_{safe}_{step:09}.vtk")),
                        m,
                    )?;
                    output::write_pvd(out_dir, &format!("mesh{k}_{safe}"), self.dt)?;
                }
            }
            self.output.last_vtk_step = Some(step);
            self.output.vtk_files += 1;
        }
        Ok(())
    }

    /// Packing fraction inside the first box wall: particle volume over the box footprint
    /// times the bed height (floor to the highest particle top), when a box wall exists.
    pub fn packing_fraction(&self) -> Option<f64> {
        if let Some(cell) = &self.state.cell {
            let p = &self.state.particles;
            let solid: f64 = (0..p.len()).map(|k| p.volume(k)).sum();
            return Some(solid / (cell.size.x * cell.size.y * cell.size.z));
        }
        let (lo, hi) = self.box_region?;
        let p = &self.state.particles;
        if p.is_empty() {
            return None;
        }
        // "up" is against gravity; fall back to +z without gravity
        let g = self.gravity;
        let axis = if g.norm() > 0.0 { g.iamax() } else { 2 };
        let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
        let area = (hi[a] - lo[a]) * (hi[b] - lo[b]);
        let up = g[axis] <= 0.0;
        let height = if up {
            (0..p.len())
                .map(|k| p.position[k][axis] + p.radius[k])
                .fold(f64::MIN, f64::max)
                - lo[axis]
        } else {
            hi[axis]
                - (0..p.len())
                    .map(|k| p.position[k][axis] - p.radius[k])
                    .fold(f64::MAX, f64::min)
        };
        let vol: f64 = (0..p.len()).map(|k| p.volume(k)).sum();
        Some(vol / (area * height))
    }

    /// Samples the sensors at the current time (once per time), see [`sensors`].
    fn sample_sensors(&mut self) -> Option<Vec<f64>> {
        if self.cfg.sensors.is_empty() {
            return None;
        }
        let s = &mut self.state;
        let ctx = ForceContext {
            materials: &self.materials,
            planes: &self.planes,
            meshes: &s.meshes,
            gravity: self.gravity,
            hold_stiffness: self.cfg.superquadric_stiffness == config::StiffnessUpdate::FirstTouch,
            surface_budget: self.cfg.superquadric_surface_budget,
            dt: 0.0,
            cell: force_cell(&self.servo, &s.cell),
            weights: None,
        };
        s.sensors
            .sample(&self.cfg.sensors, s.time, &s.particles, &s.lists, &ctx)
    }

    /// Scene result quantities for summary.json: the engine's and the sensors'
    /// (`sensor.<name>.last`, `.max`, `.mean`, flow also `.mass`).
    pub fn results(&self) -> Vec<(String, f64)> {
        let mut r = self.engine_results();
        // a finished programme: the cell's quantities at its end (the last window-end state
        // inside it), the held cell's ratio beside them
        if let (Some((_, end)), true) = (&self.programme_end, self.programme_finished()) {
            let mut held = None;
            for (k, v) in r.iter_mut() {
                if !k.starts_with("cell.") || k == "cell.stage" || k == "cell.programme_finished" {
                    continue;
                }
                if let Some(e) = end.get(k.as_str()) {
                    if k == "cell.stress_ratio" {
                        held = Some(*v);
                    }
                    *v = *e;
                }
            }
            if let Some(h) = held {
                r.push(("cell.held_stress_ratio".into(), h));
            }
        }
        let s = &self.state;
        let ctx = ForceContext {
            materials: &self.materials,
            planes: &self.planes,
            meshes: &s.meshes,
            gravity: self.gravity,
            hold_stiffness: self.cfg.superquadric_stiffness == config::StiffnessUpdate::FirstTouch,
            surface_budget: self.cfg.superquadric_surface_budget,
            dt: 0.0,
            cell: force_cell(&self.servo, &s.cell),
            weights: None,
        };
        r.extend(
            s.sensors
                .results(&self.cfg.sensors, s.time, &s.particles, &s.lists, &ctx),
        );
        r
    }

    /// Writes `particles_final.csv` (the `kind = "file"` format; with dilated polyhedra also
    /// their library `particles_final.stones.json`) into `out_dir` when
    /// `[dem.output] final_particles` is set; returns the path written.
    pub fn write_final_particles(
        &self,
        out_dir: &Path,
    ) -> Result<Option<std::path::PathBuf>, DemError> {
        if !self.cfg.output.final_particles {
            return Ok(None);
        }
        let path = out_dir.join("particles_final.csv");
        let p = &self.state.particles;
        if !p.stones.is_empty() {
            let lib = particle_file::stones_path(&path);
            std::fs::create_dir_all(out_dir)
                .and_then(|_| std::fs::write(&lib, particle_file::format_stones(p)))
                .map_err(|e| DemError::Output {
                    path: lib.display().to_string(),
                    message: e.to_string(),
                })?;
        }
        std::fs::create_dir_all(out_dir)
            .and_then(|_| std::fs::write(&path, particle_file::format(&self.state.particles)))
            .map_err(|e| DemError::Output {
                path: path.display().to_string(),
                message: e.to_string(),
            })?;
        Ok(Some(path))
    }

    /// Physics limits for the coordinator's up-front checks: `time_step`,
    /// `rayleigh_time_step`, `particles`, and with particles `particle_mass_min/max`,
    /// `particle_radius_min/max`, `contact_stiffness_max`, `contact_stiffness_typical`,
    /// `contact_duration_min` (see [`limits`]).
    pub fn limits(&self) -> Vec<(String, f64)> {
        let mut l = vec![
            ("time_step".to_string(), self.time_step()),
            ("rayleigh_time_step".to_string(), self.rayleigh_time_step()),
            ("particles".to_string(), self.num_particles() as f64),
        ];
        if let Some(servo) = &self.servo {
            // a programme ends the run by itself: the coordinator keeps windows in lockstep
            l.push(("programme_stages".to_string(), servo.stages.len() as f64));
        }
        let interface = self
            .cfg
            .interface_material
            .as_deref()
            .and_then(|m| self.materials.index(m));
        l.extend(limits::contact_limits(
            &self.state.particles,
            &self.materials,
            interface,
            self.cfg.rotation,
        ));
        if !self.volumes.is_empty() {
            let p = &self.state.particles;
            let by_id: std::collections::HashMap<u32, usize> =
                (0..p.len()).map(|k| (p.id[k], k)).collect();
            let limit = self
                .volumes
                .iter()
                .zip(&self.state.volumes)
                .map(|(v, st)| {
                    penalty_step_limit(&v.coupling, &p.mass, &by_id, st.settings.min_weight).0
                })
                .fold(f64::INFINITY, f64::min);
            l.push(("volume_interfaces".to_string(), self.volumes.len() as f64));
            l.push(("volume_penalty_step_limit".to_string(), limit));
        }
        l
    }

    /// Engine result quantities (also the columns of `dem_timeseries.csv`).
    fn engine_results(&self) -> Vec<(String, f64)> {
        let mut r = vec![
            ("particles".to_string(), self.num_particles() as f64),
            ("kinetic_energy".to_string(), self.kinetic_energy()),
            ("contacts".to_string(), self.num_contacts() as f64),
            ("wall_contacts".to_string(), self.num_wall_contacts() as f64),
            ("max_overlap".to_string(), self.max_overlap()),
            ("rayleigh_time_step".to_string(), self.rayleigh_time_step()),
            (
                "neighbour_list_builds".to_string(),
                self.state.lists.builds as f64,
            ),
        ];
        if let Some(phi) = self.packing_fraction() {
            r.push(("packing_fraction".to_string(), phi));
        }
        if !self.cfg.sinks.is_empty() {
            r.push((
                "removed_particles".to_string(),
                self.state.removed_particles as f64,
            ));
            r.push(("removed_mass".to_string(), self.state.removed_mass));
        }
        if let (Some(cell), Some(servo), Some(avg)) =
            (&self.state.cell, &self.servo, self.cell_averages())
        {
            r.extend(periodic::results(cell, servo, &avg));
        }
        let t = self.state.time;
        for m in &self.wall_motions {
            let Some(name) = &m.name else { continue };
            let w = match m.wall {
                WallRef::Plane(k) => k,
                WallRef::Mesh(k) => self.planes.len() + k,
            };
            let (f, u) = (self.wall_contact_force(w), m.displacement(t));
            for (c, ax) in ["x", "y", "z"].iter().enumerate() {
                r.push((format!("{name}.force_{ax}"), f[c]));
            }
            for (c, ax) in ["x", "y", "z"].iter().enumerate() {
                r.push((format!("{name}.displacement_{ax}"), u[c]));
            }
        }
        for (w, st) in self.loaded_walls.iter().zip(&self.state.loaded_walls) {
            r.push((format!("{}.displacement", w.name), st.u));
            r.push((format!("{}.velocity", w.name), st.v));
            r.push((format!("{}.contact_force", w.name), st.contact_force));
        }
        // volume interfaces: the penalty forces on the FE nodes balance, at rest, the bodies'
        // weighted weight Σ w m g (plus weighted wall forces): the load the continuum carries
        if let Some(ws) = &self.volume_weights {
            let p = &self.state.particles;
            for (st, v) in self.state.volumes.iter().zip(&self.volumes) {
                let gravity: V3 = (0..p.len())
                    .map(|k| self.gravity * (p.mass[k] * ws.weight[k]))
                    .sum();
                let force: V3 = v.on_nodes.iter().sum();
                let n = &st.name;
                r.push((
                    format!("volume.{n}.coupled_particles"),
                    v.coupling.len() as f64,
                ));
                r.push((format!("volume.{n}.penalty_energy"), st.energy));
                r.push((
                    format!("volume.{n}.prediction_defect"),
                    st.prediction_defect,
                ));
                for (c, ax) in ["x", "y", "z"].iter().enumerate() {
                    r.push((format!("volume.{n}.penalty_force_{ax}"), force[c]));
                    r.push((format!("volume.{n}.weighted_gravity_{ax}"), gravity[c]));
                }
            }
        }
        r
    }
}

/// The periodic cell as a force evaluation sees it ([`periodic::Servo::force_cell`]).
fn force_cell(
    servo: &Option<periodic::Servo>,
    cell: &Option<periodic::CellState>,
) -> Option<(hertz_mindlin::V3, hertz_mindlin::V3)> {
    let c = cell.as_ref()?;
    Some(match servo {
        Some(s) => s.force_cell(c),
        None => (c.size, c.rate),
    })
}
