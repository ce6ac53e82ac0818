//! The FEM model: mesh + material + boundary conditions + solvers, behind the small
//! solver-facing API the `fem-node` adapter calls (set forces → advance → read kinematics).

mod newton;

use crate::assembly::{
    self, DofMap, ElementProps, Factor, MixedFactor, Operator, Pattern, RefinedSolve, FIXED,
};
use crate::config::{Analysis, FemConfig, LinearSolver, Load, MeshSpec, NewtonConfig, Output};
use crate::element::{self, Lame};
use crate::history::History;
use crate::material::Material;
use crate::mesh::{box_mesh, Mesh};
use crate::output;
use crate::surface::{self, Boundary, Interface};
use crate::{FemError, InterfaceMesh};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::OnceLock;

const SNAPSHOT_FORMAT: u32 = 1;

/// Everything that evolves in time; `snapshot` / `restore` serialise exactly this.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct State {
    format: u32,
    n_dofs: usize,
    time: f64,
    /// Full dof vectors (3 per node, node-major).
    u: Vec<f64>,
    v: Vec<f64>,
    a: Vec<f64>,
    /// Prescribed displacement of fixed dofs (g of (2.48)); zero unless set.
    prescribed: Vec<f64>,
    interface_forces: Vec<f64>,
    /// Whether `a` is consistent with the equation of motion (initial acceleration solved).
    accel_ready: bool,
    steps: u64,
    windows: u64,
    csv_started: bool,
    /// Per strain gauge, the extremes over all outputs so far: largest max-principal strain,
    /// smallest min-principal strain, largest von Mises strain. (Absent in older snapshots.)
    #[serde(default)]
    strain_peaks: Vec<[f64; 3]>,
    /// Committed integration-point states of materials with state (`state_stride` values per
    /// element; empty when no material has state). (Absent in older snapshots.)
    #[serde(default)]
    points: Vec<f64>,
}

/// A support with a prescribed displacement `value × history(t)` per dof.
struct MovingSupport {
    dofs: Vec<(usize, f64)>,
    history: Option<String>,
}

struct LoadVector {
    history: Option<String>,
    /// Spatial pattern (full dof vector) multiplied by history(t).
    f: Vec<f64>,
}

/// A finite element model ready to be stepped.
pub struct Model {
    mesh: Mesh,
    /// The scene's materials; element e has `materials[elem_mat[e]]`.
    materials: Vec<Material>,
    elem_mat: Vec<u32>,
    /// Per material: the initial (small-strain) Lamé constants of the linear stiffness K.
    lame: Vec<Lame>,
    /// Internal forces from stresses and Newton iterations (some material is not linear
    /// elastic, or `newton.always`); otherwise K u with the cached factor.
    nonlinear: bool,
    /// Whether every material in use has a symmetric tangent (Cholesky, else LU).
    symmetric_tangent: bool,
    /// Point-state values per element (max over the elements; 0 without stateful materials).
    state_stride: usize,
    newton: NewtonConfig,
    lu_symbolic: Option<assembly::SymbolicLu>,
    /// Relative residuals ‖R‖ / force scale of every Newton iteration, per increment (static)
    /// or step (Bossak), of the last nonlinear solve.
    last_newton: Vec<Vec<f64>>,
    analysis: Analysis,
    dofs: DofMap,
    pattern: Pattern,
    k: Vec<f64>,
    /// ε V ⊗ I of a volume overlap on the pattern (also inside `k`): the Newton path adds it to
    /// its tangent and ε V u to its internal forces.
    penalty_matrix: Option<Vec<f64>>,
    /// The same ε V_e per overlap element (scalar n×n, row-major) over all dofs: ε V u in the
    /// internal forces reaches the supported dofs too (reactions, and K_fg g of a support that
    /// moves inside the overlap).
    penalty_blocks: Vec<(usize, Vec<f64>)>,
    m_consistent: Option<Vec<f64>>,
    m_lumped: Vec<f64>,
    diag_pos: Vec<usize>,
    symbolic: Option<assembly::Symbolic>,
    k_factor: Option<Factor>,
    /// Static solves: the linear solver asked for, its f32 factor, whether it failed (then
    /// the f64 factor is used from there on) and the last solve's PCG figures.
    solver: LinearSolver,
    k_mixed: Option<MixedFactor>,
    mixed_failed: bool,
    last_refined: Option<RefinedSolve>,
    eff_factor: Option<(u64, Factor)>,
    m_factor: Option<Factor>,
    loads: Vec<LoadVector>,
    moving: Vec<MovingSupport>,
    histories: BTreeMap<String, History>,
    boundary: Boundary,
    iface: Interface,
    /// The volume overlap with particles (`[fem.overlap]`), whose nodes are `iface.nodes`.
    overlap: Option<crate::overlap::Overlap>,
    probes: Vec<(String, u32)>,
    /// Named supports (`[[fem.supports]] name`) and the dofs each reports: those it fixes and
    /// no earlier support fixes (a dof held by two supports reports to the first).
    reported_supports: Vec<(String, Vec<usize>)>,
    /// Strain gauges: name and the elements they watch.
    gauges: Vec<(String, Vec<u32>)>,
    output: Output,
    st: State,
    crit: OnceLock<Option<f64>>,
    lumped_max_eigenvalue: OnceLock<Option<f64>>,
    vtu_files: Vec<(f64, String)>,
}

impl Model {
    /// Builds the model of a scene's `[fem]` table; relative mesh paths are resolved against
    /// `base_dir` (the scene file's directory).
    pub fn from_config(cfg: &FemConfig, base_dir: &Path) -> Result<Model, FemError> {
        cfg.validate()
            .map_err(|(field, message)| FemError::Config { field, message })?;
        let mesh = match &cfg.mesh {
            MeshSpec::File { path, .. } => Mesh::read(&base_dir.join(path))?,
            MeshSpec::Plate { .. } | MeshSpec::Cylinder { .. } => {
                return Err(FemError::Config {
                    field: "fem.mesh.element".into(),
                    message: "a plate of shells or a cylinder of membranes is a \
                              crate::ShellModel / crate::MembraneModel (fem::build picks it)"
                        .into(),
                })
            }
            MeshSpec::Box {
                size,
                origin,
                element,
                ..
            } => {
                let div = cfg.mesh.box_divisions().ok_or_else(|| FemError::Config {
                    field: "fem.mesh".into(),
                    message: "a generated box needs element_size (or divisions)".into(),
                })?;
                box_mesh(*origin, *size, div, *element)
            }
        };
        Model::from_mesh(cfg, mesh)
    }

    /// Builds the model on a given mesh (the config's `mesh` entry is ignored).
    pub fn from_mesh(cfg: &FemConfig, mut mesh: Mesh) -> Result<Model, FemError> {
        cfg.validate()
            .map_err(|(field, message)| FemError::Config { field, message })?;
        if let MeshSpec::File {
            hex8_incompatible,
            hex8_bbar,
            ..
        } = cfg.mesh
        {
            if hex8_incompatible {
                mesh.set_hex8_formulation(element::ElementKind::Hex8i);
            } else if hex8_bbar {
                mesh.set_hex8_formulation(element::ElementKind::Hex8b);
            }
        }
        // a mesh file's counts are known only now: refuse a model that cannot fit before
        // the matrices are built (a generated box was checked with the scene)
        crate::resources::check_memory(
            &format!(
                "the model of {} ({} nodes, {} elements)",
                mesh.source,
                mesh.num_nodes(),
                mesh.num_elements()
            ),
            crate::resources::model_bytes(mesh.num_nodes() as u64, mesh.num_elements() as u64),
            crate::resources::available_memory(),
        )
        .map_err(|message| FemError::Config {
            field: "fem.mesh".into(),
            message,
        })?;
        let timing = tracing::enabled!(tracing::Level::DEBUG);
        let t0 = std::time::Instant::now();
        let lap = |what: &str| {
            if timing {
                tracing::debug!("  {what}: {:?}", t0.elapsed());
            }
        };
        if mesh.kinds.is_empty() {
            return Err(FemError::Mesh {
                file: mesh.source.clone(),
                line: 0,
                message: "no volume elements (a shell mesh is a crate::ShellModel: fem::build \
                          picks it)"
                    .into(),
            });
        }
        for (i, s) in cfg.supports.iter().enumerate() {
            if s.rotations.is_some() {
                return Err(FemError::Config {
                    field: format!("fem.supports[{i}].rotations"),
                    message: "rotations are shell dofs; a volume mesh has translations only".into(),
                });
            }
        }
        if cfg.shell.is_some() {
            return Err(FemError::Config {
                field: "fem.shell".into(),
                message: format!(
                    "{} is a volume mesh; [fem.shell] describes shells",
                    mesh.source
                ),
            });
        }
        if cfg.interface.as_ref().is_some_and(|i| i.faces.is_some()) {
            return Err(FemError::Config {
                field: "fem.interface.faces".into(),
                message: "faces (top / bottom) are the sides of shells; a volume mesh's \
                          interface is its exterior surface"
                    .into(),
            });
        }
        mesh.check_elements()?;
        lap("check_elements");
        // the overlap's Arlequin factors weight every integral assembled below
        let overlap = match &cfg.overlap {
            Some(_) if cfg.interface.is_some() => {
                return Err(FemError::Config {
                    field: "fem.overlap".into(),
                    message: "a FEM node provides one interface: [fem.interface] (a surface) \
                              or [fem.overlap] (a volume), not both"
                        .into(),
                })
            }
            Some(spec) => {
                let carved = crate::overlap::carve(&mut mesh, spec)?;
                if carved > 0 {
                    tracing::info!(
                        "fem.overlap.carve: removed {carved} elements inside de_region, {} left",
                        mesh.num_elements()
                    );
                }
                Some(crate::overlap::select(&mesh, spec)?)
            }
            None => None,
        };
        let (materials, elem_mat) = newton::assign_materials(cfg, &mesh)?;
        let lame: Vec<Lame> = materials.iter().map(|m| m.model.initial_lame()).collect();
        let densities: Vec<f64> = materials.iter().map(|m| m.density).collect();
        // only the materials some element has count
        let mut used = vec![false; materials.len()];
        for &m in &elem_mat {
            used[m as usize] = true;
        }
        let nonlinear = cfg.newton.always
            || materials
                .iter()
                .zip(&used)
                .any(|(m, &u)| u && !m.model.is_linear());
        if overlap.is_some() {
            let refuse = match cfg.analysis {
                Analysis::Explicit { .. } => Some(
                    "an explicit analysis would apply the penalty ε V explicitly (its step \
                     √((1 − w) ρ / ε)); use \"static\" or \"dynamic\"",
                ),
                Analysis::Dynamic { rayleigh_b, .. } if rayleigh_b != 0.0 => Some(
                    "stiffness-proportional damping (rayleigh_b) would damp the penalty ε V on \
                     the FE side only; use rayleigh_a",
                ),
                _ => None,
            };
            if let Some(message) = refuse {
                return Err(FemError::Config {
                    field: "fem.overlap".into(),
                    message: message.into(),
                });
            }
        }
        if nonlinear {
            newton::check_element_kinds(&mesh, &materials, &elem_mat)?;
        }
        let symmetric_tangent = materials
            .iter()
            .zip(&used)
            .all(|(m, &u)| !u || m.model.symmetric_tangent());
        let state_stride = (0..mesh.num_elements())
            .map(|e| {
                crate::nonlinear::num_points(mesh.kinds[e])
                    * materials[elem_mat[e] as usize].model.state_len()
            })
            .max()
            .unwrap_or(0);
        let props = ElementProps {
            of: &elem_mat,
            lame: &lame,
            density: &densities,
        };
        let nd = 3 * mesh.num_nodes();

        // Supports: eliminated dofs (η_g of (2.52)–(2.53)).
        let mut fixed = vec![false; nd];
        for (i, s) in cfg.supports.iter().enumerate() {
            let nodes = surface::select_nodes(&mesh, &s.on, &format!("fem.supports[{i}].on"))?;
            for n in nodes {
                for ax in &s.fix {
                    fixed[3 * n as usize + ax.index()] = true;
                }
            }
        }
        let (dofs, pattern) = Pattern::build(&mesh, &fixed)?;
        lap("pattern");
        let mut moving = Vec::new();
        for (i, s) in cfg.supports.iter().enumerate() {
            if let Some(d) = s.displacement {
                let nodes = surface::select_nodes(&mesh, &s.on, &format!("fem.supports[{i}].on"))?;
                let mut dofs_moved = Vec::new();
                for n in nodes {
                    for ax in &s.fix {
                        let c = ax.index();
                        dofs_moved.push((3 * n as usize + c, d[c]));
                    }
                }
                moving.push(MovingSupport {
                    dofs: dofs_moved,
                    history: s.history.clone(),
                });
            }
        }
        lap("supports");
        // The implicit penalty (Wellmann (6.25) on the FE side): ε V_IJ ⊗ I over the overlap's
        // elements enters the operator, the DEM's ε V u^DE arrives as the interface forces,
        // so that (K + ε V) u = F + ε V u^DE is solved at any ε (an explicit penalty force from
        // the particles is unstable once ε V exceeds the FE stiffness).
        let penalty_matrix = match &overlap {
            Some(o) => {
                let mut of = vec![0u32; mesh.num_elements()];
                for &e in &o.mesh_elements {
                    of[e] = 1;
                }
                let pen_props = ElementProps {
                    of: &of,
                    lame: &[Lame::from_young_poisson(0.0, 0.0); 2],
                    density: &[0.0, o.penalty],
                };
                // V_IJ is unweighted: assembled before the mesh gets its Arlequin factors
                Some(assembly::assemble(
                    &mesh,
                    &dofs,
                    &pattern,
                    Operator::Mass,
                    pen_props,
                )?)
            }
            None => None,
        };
        let mut penalty_blocks = Vec::new();
        if let Some(o) = &overlap {
            let mut x = Vec::new();
            for &e in &o.mesh_elements {
                mesh.element_coords(e, &mut x);
                let mut v = Vec::new();
                element::mass(mesh.kinds[e], &x, o.penalty, None, &mut v).map_err(|_| {
                    FemError::Config {
                        field: "fem.overlap".into(),
                        message: format!("element {e} of the overlap is inverted"),
                    }
                })?;
                penalty_blocks.push((e, v));
            }
        }
        if let Some(o) = &overlap {
            mesh.arlequin_scale = o.scale.clone();
        }
        // the elimination order and symbolic analysis (every analysis but the explicit one
        // factorises on this pattern) run beside the stiffness assembly: the ordering is
        // mostly sequential, the assembly parallel
        let explicit = matches!(cfg.analysis, Analysis::Explicit { .. });
        let (k, symbolic) = rayon::join(
            || assembly::assemble(&mesh, &dofs, &pattern, Operator::Stiffness, props),
            || {
                let mut sym = None;
                (!explicit)
                    .then(|| assembly::ensure_symbolic(&pattern, &mut sym))
                    .transpose()
            },
        );
        let mut k = k?;
        let symbolic = symbolic?;
        // the linear operator holds the penalty; the Newton path adds it itself
        if let Some(pm) = &penalty_matrix {
            for (a, b) in k.iter_mut().zip(pm) {
                *a += b;
            }
        }
        lap("stiffness");
        let m_lumped = assembly::lumped_mass(&mesh, props)?;
        lap("lumped mass");
        let diag_pos: Vec<usize> = (0..pattern.n)
            .map(|j| {
                let (a, b) = (pattern.col_ptr[j] as usize, pattern.col_ptr[j + 1] as usize);
                a + pattern.row_idx[a..b]
                    .binary_search(&(j as u32))
                    .expect("diagonal present")
            })
            .collect();
        let m_consistent = match cfg.analysis {
            Analysis::Dynamic {
                lumped_mass: false, ..
            } => Some(assembly::assemble(
                &mesh,
                &dofs,
                &pattern,
                Operator::Mass,
                props,
            )?),
            _ => None,
        };

        let boundary = Boundary::extract(&mesh);
        lap("boundary");
        let mut loads = Vec::new();
        for (i, l) in cfg.loads.iter().enumerate() {
            let what = format!("fem.loads[{i}].on");
            let mut f = vec![0.0; nd];
            let history = match l {
                Load::Pressure { on, value, history } => {
                    let faces = surface::select_faces(&mesh, &boundary, on, &what)?;
                    let mut fx = Vec::new();
                    let mut out = [[0.0; 3]; 8];
                    for fc in faces {
                        let nodes = boundary.face(fc);
                        fx.clear();
                        fx.extend(nodes.iter().map(|&n| mesh.nodes[n as usize]));
                        element::face_pressure_loads(&fx, *value, &mut out[..nodes.len()]);
                        for (a, &n) in nodes.iter().enumerate() {
                            for c in 0..3 {
                                f[3 * n as usize + c] += out[a][c];
                            }
                        }
                    }
                    history
                }
                Load::Force {
                    on,
                    per_node,
                    total,
                    history,
                } => {
                    let nodes = surface::select_nodes(&mesh, on, &what)?;
                    let per = crate::config::nodal_force(per_node, total, nodes.len());
                    for n in nodes {
                        for c in 0..3 {
                            f[3 * n as usize + c] += per[c];
                        }
                    }
                    history
                }
                Load::Gravity {
                    acceleration,
                    history,
                } => {
                    gravity_loads(&mesh, props, *acceleration, &mut f)?;
                    history
                }
            };
            loads.push(LoadVector {
                history: history.clone(),
                f,
            });
        }

        let iface = match (&overlap, &cfg.interface) {
            (Some(o), _) => Interface {
                nodes: o.nodes.clone(),
                triangles: Vec::new(),
            },
            (None, Some(spec)) => {
                let faces = surface::select_faces(&mesh, &boundary, &spec.on, "fem.interface.on")?;
                Interface::from_faces(&mesh, &boundary, &faces)
            }
            (None, None) => {
                Interface::from_faces(&mesh, &boundary, &(0..boundary.len()).collect::<Vec<_>>())
            }
        };

        lap("loads, interface");
        let used = mesh.used_nodes();
        let mut probes = Vec::new();
        for (i, p) in cfg.probes.iter().enumerate() {
            let node = if let Some(id) = p.node {
                let ix = mesh.node_ids.iter().position(|&x| x == id).ok_or_else(|| {
                    FemError::Selection(format!(
                        "fem.probes[{i}] '{}': node {id} is not in {}",
                        p.name, mesh.source
                    ))
                })?;
                ix as u32
            } else {
                let q = p.point.expect("validated");
                let mut best = (f64::INFINITY, 0u32);
                for (n, x) in mesh.nodes.iter().enumerate() {
                    if !used[n] {
                        continue;
                    }
                    let d = (0..3).map(|k| (x[k] - q[k]).powi(2)).sum::<f64>();
                    if d < best.0 {
                        best = (d, n as u32);
                    }
                }
                if !point_in_body(&mesh, q) {
                    let x = mesh.nodes[best.1 as usize];
                    return Err(FemError::Selection(format!(
                        "fem.probes[{i}] '{}': point {} lies outside the body (farther than \
                         {} % of an element's size from every element); the nearest node is \
                         {} at {}, {} m away",
                        p.name,
                        fmt_point(q),
                        PROBE_TOLERANCE * 100.0,
                        mesh.node_ids[best.1 as usize],
                        fmt_point(x),
                        crate::resources::format_number(best.0.sqrt())
                    )));
                }
                best.1
            };
            probes.push((p.name.clone(), node));
        }

        let mut reported_supports = Vec::new();
        if cfg.supports.iter().any(|s| s.name.is_some()) {
            let mut claimed = vec![false; 3 * mesh.num_nodes()];
            for (i, s) in cfg.supports.iter().enumerate() {
                let nodes = surface::select_nodes(&mesh, &s.on, &format!("fem.supports[{i}].on"))?;
                let mut dofs = Vec::new();
                for n in nodes {
                    for a in &s.fix {
                        let d = 3 * n as usize + a.index();
                        if !std::mem::replace(&mut claimed[d], true) {
                            dofs.push(d);
                        }
                    }
                }
                let Some(name) = &s.name else { continue };
                if reported_supports.iter().any(|(n, _)| n == name) {
                    return Err(FemError::Config {
                        field: format!("fem.supports[{i}].name"),
                        message: format!("'{name}' names two supports"),
                    });
                }
                reported_supports.push((name.clone(), dofs));
            }
        }

        let mut gauges = Vec::new();
        for (i, g) in cfg.strain_gauges.iter().enumerate() {
            let elements =
                gauge_elements(&mesh, g.on.as_ref(), &format!("fem.strain_gauges[{i}].on"))?;
            gauges.push((g.name.clone(), elements));
        }

        let n_iface = iface.nodes.len();
        Ok(Model {
            st: State {
                format: SNAPSHOT_FORMAT,
                n_dofs: nd,
                time: 0.0,
                u: vec![0.0; nd],
                v: vec![0.0; nd],
                a: vec![0.0; nd],
                prescribed: vec![0.0; nd],
                interface_forces: vec![0.0; 3 * n_iface],
                accel_ready: false,
                steps: 0,
                windows: 0,
                csv_started: false,
                strain_peaks: vec![NO_PEAK; gauges.len()],
                points: newton::initial_points(&mesh, &materials, &elem_mat, state_stride),
            },
            mesh,
            materials,
            elem_mat,
            lame,
            nonlinear,
            symmetric_tangent,
            state_stride,
            newton: cfg.newton.clone(),
            lu_symbolic: None,
            last_newton: Vec::new(),
            analysis: cfg.analysis.clone(),
            dofs,
            pattern,
            k,
            m_consistent,
            m_lumped,
            diag_pos,
            symbolic,
            k_factor: None,
            penalty_matrix,
            penalty_blocks,
            solver: cfg.solver,
            k_mixed: None,
            mixed_failed: false,
            last_refined: None,
            eff_factor: None,
            m_factor: None,
            loads,
            moving,
            histories: cfg.histories.clone(),
            boundary,
            iface,
            overlap,
            probes,
            reported_supports,
            gauges,
            output: cfg.output.clone(),
            crit: OnceLock::new(),
            lumped_max_eigenvalue: OnceLock::new(),
            vtu_files: Vec::new(),
        })
    }

    // ----------------------------------------------------------------------------------------
    // The adapter-facing API
    // ----------------------------------------------------------------------------------------

    /// Number of degrees of freedom (3 per mesh node).
    pub fn num_dofs(&self) -> usize {
        3 * self.mesh.num_nodes()
    }

    /// Number of free (unknown) equations after eliminating supports.
    pub fn num_equations(&self) -> usize {
        self.dofs.n_eq
    }

    pub fn time(&self) -> f64 {
        self.st.time
    }

    /// The coupled surface in the reference configuration.
    pub fn interface_mesh(&self) -> InterfaceMesh {
        InterfaceMesh {
            node_ids: self
                .iface
                .nodes
                .iter()
                .map(|&n| self.mesh.node_ids[n as usize])
                .collect(),
            positions: self
                .iface
                .nodes
                .iter()
                .flat_map(|&n| self.mesh.nodes[n as usize])
                .collect(),
            triangles: self.iface.triangles.clone(),
            volume: self.overlap.as_ref().map(|o| crate::VolumeMesh {
                shape: o.shape.to_string(),
                elements: o.elements.clone(),
                weights: o.weights.clone(),
                penalty: o.penalty,
            }),
        }
    }

    /// Nodal interface forces [N] (flat xyz, interface node order), held until the next call.
    pub fn set_interface_forces(&mut self, forces: &[f64]) -> Result<(), FemError> {
        let expected = 3 * self.iface.nodes.len();
        if forces.len() != expected {
            return Err(FemError::InterfaceSize {
                expected,
                got: forces.len(),
            });
        }
        if let Some(i) = forces.iter().position(|f| !f.is_finite()) {
            return Err(FemError::NonFinite(format!(
                "interface force of node {} (component {})",
                self.mesh.node_ids[self.iface.nodes[i / 3] as usize],
                i % 3
            )));
        }
        self.st.interface_forces.copy_from_slice(forces);
        Ok(())
    }

    /// Advances by `dt`: static solve at t + dt, one Bossak step, or ⌈dt / Δt_safe⌉ explicit
    /// central-difference substeps, depending on the analysis type.
    pub fn advance(&mut self, dt: f64) -> Result<(), FemError> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(FemError::TimeStep(dt));
        }
        match self.analysis {
            Analysis::Static => {
                let t = self.st.time + dt;
                // a volume overlap's grains follow the continuum's nodes through the window:
                // they get the rate of the quasi-static path (u(t + dt) − u(t)) / dt, so the
                // DEM carries the nodes on with it instead of holding them a window behind
                // (the stiff penalty ε V would turn that lag into a spurious load). Taken
                // before the supports move (a linear model writes them into u), and not on
                // the first step, whose jump from the unloaded start is no rate.
                let before =
                    (self.overlap.is_some() && self.st.steps > 0).then(|| self.st.u.clone());
                self.move_supports(t);
                self.static_solve_at(t, false)?;
                if let Some(u0) = before {
                    for ((v, u), u0) in self.st.v.iter_mut().zip(&self.st.u).zip(&u0) {
                        *v = (u - u0) / dt;
                    }
                }
                self.st.time = t;
            }
            Analysis::Dynamic { max_step, .. } => {
                // equal substeps no longer than max_step, the interface forces held
                let n = match max_step {
                    Some(h) if dt > h * (1.0 + 1e-9) => (dt / h * (1.0 - 1e-9)).ceil() as u64,
                    _ => 1,
                };
                let (t0, h) = (self.st.time, dt / n as f64);
                for i in 1..=n {
                    let t = if i == n { t0 + dt } else { t0 + i as f64 * h };
                    self.move_supports(t);
                    if self.nonlinear {
                        self.bossak_nonlinear(h)?
                    } else {
                        self.bossak_step(h)?
                    }
                    self.st.time = t;
                }
            }
            Analysis::Explicit { safety, .. } => {
                let crit = self.critical_time_step().ok_or_else(|| {
                    FemError::Solver("no free dofs: explicit stepping undefined".into())
                })?;
                let h_max = safety * crit;
                let n = (dt / h_max).ceil().max(1.0) as u64;
                let h = dt / n as f64;
                let t_end = self.st.time + dt;
                self.explicit_steps(h, n)?;
                // avoid drift of t from summing substeps
                self.st.time = t_end;
            }
        }
        self.st.steps += 1;
        Ok(())
    }

    /// Static solve at the current time (loads(t) + interface forces), any analysis type.
    pub fn solve_static(&mut self) -> Result<(), FemError> {
        let t = self.st.time;
        self.static_solve_at(t, true)
    }

    /// The interface forces held since the last `set_interface_forces` (flat xyz, interface
    /// node order) [N].
    pub fn held_interface_forces(&self) -> &[f64] {
        &self.st.interface_forces
    }

    /// Current positions (reference + u), velocities and accelerations of the interface nodes.
    pub fn interface_kinematics(&self) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let n = self.iface.nodes.len();
        let (mut p, mut v, mut a) = (
            Vec::with_capacity(3 * n),
            Vec::with_capacity(3 * n),
            Vec::with_capacity(3 * n),
        );
        for &node in &self.iface.nodes {
            let x = self.mesh.nodes[node as usize];
            for c in 0..3 {
                let d = 3 * node as usize + c;
                p.push(x[c] + self.st.u[d]);
                v.push(self.st.v[d]);
                a.push(self.st.a[d]);
            }
        }
        (p, v, a)
    }

    /// Stability limit of explicit central differences with the lumped mass:
    /// Δt_crit = 2/ω_max (√(1+ξ²) − ξ), ξ = a/(2ω_max) + b ω_max/2 for Rayleigh damping,
    /// ω_max² the largest eigenvalue of M_L⁻¹K (Lanczos). None when nothing is free.
    pub fn critical_time_step(&self) -> Option<f64> {
        *self.crit.get_or_init(|| {
            let lam = self.max_eigenvalue()?;
            let w = lam.sqrt();
            let (ra, rb) = self.rayleigh();
            let xi = ra / (2.0 * w) + rb * w / 2.0;
            Some(2.0 / w * ((1.0 + xi * xi).sqrt() - xi))
        })
    }

    /// The model's own stability and sizing figures for the coordinator's up-front checks
    /// (the `limits` of the node's ready message; keys in FEM.md):
    /// `dofs`, `critical_time_step`, `interface_nodes`, `interface_node_mass_min`,
    /// `interface_node_mass_mean` [kg], `structure_mass` [kg], and for dynamic and explicit
    /// analyses `highest_frequency_hz` and (up to `LOWEST_FREQUENCY_MAX_EQUATIONS` free dofs)
    /// `lowest_frequency_hz`.
    pub fn limits(&mut self) -> Result<BTreeMap<String, f64>, FemError> {
        let mut l = BTreeMap::from([
            ("dofs".to_string(), self.num_dofs() as f64),
            ("structure_mass".to_string(), self.total_mass()),
            ("interface_nodes".to_string(), self.iface.nodes.len() as f64),
        ]);
        if let Some(dt) = self.critical_time_step() {
            l.insert("critical_time_step".to_string(), dt);
        }
        // the coordinator's checks need to know whether Δt_crit binds (it does not for Bossak)
        let explicit = matches!(self.analysis, Analysis::Explicit { .. });
        l.insert("explicit".to_string(), if explicit { 1.0 } else { 0.0 });
        if let Some(o) = &self.overlap {
            // the penalty is implicit here (ε V in the operator): no contact-period window limit
            l.insert("volume_interface".to_string(), 1.0);
            l.insert("volume_penalty".to_string(), o.penalty);
        }
        let masses = self.interface_node_masses();
        crate::insert_mass_limits(&mut l, &masses);
        if !matches!(self.analysis, Analysis::Static) {
            if let Some(f) = self.highest_frequency_hz()? {
                l.insert("highest_frequency_hz".to_string(), f);
            }
            // a free-floating body (e.g. a sleeper resting on ballast) has a singular K and
            // rigid-body modes at 0 Hz: no lowest frequency, and no error for it
            if self.dofs.n_eq <= LOWEST_FREQUENCY_MAX_EQUATIONS {
                if let Ok(Some(f)) = self.lowest_frequency_hz() {
                    l.insert("lowest_frequency_hz".to_string(), f);
                }
            }
        }
        Ok(l)
    }

    /// Warnings about the scene that do not stop it (shown by the coordinator): elements that
    /// lock volumetrically at the scene's Poisson ratio (measured table in FEM.md).
    pub fn warnings(&self) -> Vec<String> {
        let mut out = Vec::new();
        for (m, mat) in self.materials.iter().enumerate() {
            let nu = mat.model.poisson_ratio();
            if nu <= LOCKING_POISSON_RATIO {
                continue;
            }
            let has = |k: element::ElementKind| {
                (0..self.mesh.num_elements())
                    .any(|e| self.mesh.kinds[e] == k && self.elem_mat[e] as usize == m)
            };
            let name = &mat.name;
            if has(element::ElementKind::Tet4) {
                out.push(format!(
                    "{name}.poisson_ratio = {nu}: linear tetrahedra (tet4, C3D4) lock \
                     volumetrically above ν = {LOCKING_POISSON_RATIO} (in pure bending 3.6× too \
                     stiff at ν = 0.49, 15× at 0.499; FEM.md); use tet10 (C3D10)"
                ));
            }
            if has(element::ElementKind::Hex8) {
                out.push(format!(
                    "{name}.poisson_ratio = {nu}: fully integrated hexahedra (hex8, C3D8) lock \
                     volumetrically above ν = {LOCKING_POISSON_RATIO} (in pure bending 17 % too \
                     stiff at ν = 0.49, 33 % at 0.499; FEM.md); use hex8b (mean-dilatation B̄: \
                     mesh = {{ file = ..., hex8 = \"bbar\" }} or element = \"hex8b\"), hex8i or \
                     hex20"
                ));
            }
        }
        out
    }

    /// Lumped (HRZ) nodal masses of the interface nodes [kg], in interface node order: the
    /// mass a DEM contact pushes against.
    pub fn interface_node_masses(&self) -> Vec<f64> {
        self.iface
            .nodes
            .iter()
            .map(|&n| self.m_lumped[3 * n as usize])
            .collect()
    }

    /// PCG iterations and relative residual of the last static solve when it used the
    /// mixed-precision solver (None: the f64 factor solved it).
    pub fn last_mixed_solve(&self) -> Option<RefinedSolve> {
        self.last_refined
    }

    /// Lowest natural frequency f₁ = ω₁/2π [Hz] of K φ = ω² M φ with the analysis' mass
    /// (consistent unless lumped; lumped for static and explicit analyses): Lanczos on K⁻¹M
    /// in the M inner product, one solve with a Cholesky factor of K per step. None when
    /// nothing is free. Factorises K once (not kept unless the analysis is static).
    pub fn lowest_frequency_hz(&mut self) -> Result<Option<f64>, FemError> {
        let n = self.dofs.n_eq;
        if n == 0 {
            return Ok(None);
        }
        let local;
        let factor = match &self.k_factor {
            Some(f) => f,
            None => {
                local = Factor::new(&self.pattern, &self.k, &mut self.symbolic)?;
                &local
            }
        };
        let theta = numeric::lanczos_largest(
            n,
            |x, y| {
                y.copy_from_slice(x);
                factor.solve_in_place(y);
            },
            |x, y| self.mass_mul(x, y),
            true,
            80,
            1e-10,
        );
        Ok((theta > 0.0).then(|| (1.0 / theta).sqrt() / (2.0 * std::f64::consts::PI)))
    }

    /// Highest natural frequency f_max = ω_max/2π [Hz] of the discrete model with the
    /// analysis' mass (Lanczos; with a consistent mass, on M⁻¹K using a Cholesky factor of M).
    /// None when nothing is free.
    pub fn highest_frequency_hz(&mut self) -> Result<Option<f64>, FemError> {
        let lam = match &self.m_consistent {
            None => self.max_eigenvalue(),
            Some(m) => {
                if self.dofs.n_eq == 0 {
                    return Ok(None);
                }
                if self.m_factor.is_none() {
                    self.m_factor = Some(Factor::new(&self.pattern, m, &mut self.symbolic)?);
                }
                let mf = self.m_factor.as_ref().expect("set");
                Some(numeric::lanczos_largest(
                    self.dofs.n_eq,
                    |x, y| {
                        self.pattern.mul(&self.k, x, y);
                        mf.solve_in_place(y);
                    },
                    |x, y| self.mass_mul(x, y),
                    false,
                    300,
                    1e-8,
                ))
            }
        };
        Ok(lam.map(|l| l.max(0.0).sqrt() / (2.0 * std::f64::consts::PI)))
    }

    /// MessagePack bytes of the time-dependent state.
    pub fn snapshot(&self) -> Vec<u8> {
        rmp_serde::to_vec(&self.st).expect("state serialises")
    }

    /// Restores a `snapshot` of a model built from the same scene; continuation is bitwise.
    pub fn restore(&mut self, bytes: &[u8]) -> Result<(), FemError> {
        let st: State = crate::decode_state(bytes, |s: &State| s.format, SNAPSHOT_FORMAT)?;
        let nd = self.num_dofs();
        if st.n_dofs != nd
            || st.u.len() != nd
            || st.v.len() != nd
            || st.a.len() != nd
            || st.prescribed.len() != nd
            || st.interface_forces.len() != 3 * self.iface.nodes.len()
            || st.points.len() != self.st.points.len()
        {
            return Err(FemError::Snapshot(format!(
                "snapshot has {} dofs / {} interface values, model has {nd} / {}",
                st.n_dofs,
                st.interface_forces.len(),
                3 * self.iface.nodes.len()
            )));
        }
        self.st = st;
        if self.st.strain_peaks.len() != self.gauges.len() {
            // a snapshot from before strain gauges existed, or of a scene without them
            self.st.strain_peaks = vec![NO_PEAK; self.gauges.len()];
        }
        Ok(())
    }

    /// Called after each coupling window: appends probe rows to `fem_probes.csv` and writes
    /// `fem_<window>.vtu` (+ `fem.pvd`) every `output.vtu_every` windows.
    pub fn write_outputs(&mut self, out_dir: &Path) -> Result<(), FemError> {
        let io = output::io_error;
        output::create_dir(out_dir)?;
        self.st.windows += 1;
        let strains = self.gauge_strains();
        for (peak, now) in self.st.strain_peaks.iter_mut().zip(&strains) {
            *peak = [
                peak[0].max(now[0]),
                peak[1].min(now[1]),
                peak[2].max(now[2]),
            ];
        }
        if self.output.csv
            && !(self.probes.is_empty()
                && self.gauges.is_empty()
                && self.reported_supports.is_empty())
        {
            let path = out_dir.join("fem_probes.csv");
            let mut text = String::new();
            if !self.st.csv_started {
                text.push_str("time");
                output::probe_header(&mut text, &self.probes);
                for (name, _) in &self.gauges {
                    for q in STRAIN_QUANTITIES {
                        text.push_str(&format!(",strain.{name}.{q}"));
                    }
                }
                if self.nonlinear {
                    for (name, _) in &self.gauges {
                        for q in &GAUGE_STRESS_QUANTITIES[..self.gauge_stress_columns()] {
                            text.push_str(&format!(",{q}.{name}"));
                        }
                    }
                }
                for (name, _) in &self.reported_supports {
                    for c in ["x", "y", "z"] {
                        text.push_str(&format!(",reaction.{name}.{c}"));
                    }
                }
                text.push('\n');
            }
            text.push_str(&format!("{:.9e}", self.st.time));
            output::probe_row(&mut text, &self.probes, &self.st.u, 3);
            for v in strains.iter().flatten() {
                text.push_str(&format!(",{v:.9e}"));
            }
            if self.nonlinear {
                let k = self.gauge_stress_columns();
                for v in self.gauge_stresses() {
                    for x in &v[..k] {
                        text.push_str(&format!(",{x:.9e}"));
                    }
                }
            }
            for (_, f) in self.support_reactions() {
                for x in f {
                    text.push_str(&format!(",{x:.9e}"));
                }
            }
            text.push('\n');
            output::append(&path, &text, !self.st.csv_started).map_err(|e| io(e, &path))?;
            self.st.csv_started = true;
        }
        if self.output.vtu_every > 0 && self.st.windows % self.output.vtu_every == 0 {
            let name = format!("fem_{:06}.vtu", self.st.windows);
            let path = out_dir.join(&name);
            let material: Vec<f64> = self.elem_mat.iter().map(|&m| m as f64).collect();
            let written = if self.nonlinear {
                // stresses (Cauchy), the largest equivalent plastic strain of each element and
                // the share of its points that yielded in the last update (the plastic zone)
                let (stress, peeq, zone) = self.element_point_summaries();
                output::write_vtu(
                    &path,
                    &self.mesh,
                    &self.st.u,
                    &self.st.v,
                    &stress,
                    &[
                        ("material", &material),
                        ("equivalent_plastic_strain", &peeq),
                        ("plastic_zone", &zone),
                    ],
                )
            } else {
                let stress = self.element_stresses();
                output::write_vtu(
                    &path,
                    &self.mesh,
                    &self.st.u,
                    &self.st.v,
                    &stress,
                    &[("material", &material)],
                )
            };
            written.map_err(|e| io(e, &path))?;
            output::add_to_series(out_dir, &mut self.vtu_files, self.st.time, name)?;
        }
        Ok(())
    }

    /// Result quantities for `summary.json`.
    pub fn results(&self) -> Vec<(String, f64)> {
        let mut r = vec![
            ("dofs".to_string(), self.num_dofs() as f64),
            ("free_dofs".to_string(), self.dofs.n_eq as f64),
            ("elements".to_string(), self.mesh.num_elements() as f64),
            ("time".to_string(), self.st.time),
        ];
        output::probe_results(&mut r, &self.probes, &self.st.u, 3);
        for (name, f) in self.support_reactions() {
            for (c, ax) in ["x", "y", "z"].iter().enumerate() {
                r.push((format!("reaction.{name}.{ax}"), f[c]));
            }
        }
        output::interface_force_results(&mut r, &self.st.interface_forces);
        let umax = (0..self.mesh.num_nodes())
            .map(|n| {
                (0..3)
                    .map(|c| self.st.u[3 * n + c].powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
            .fold(0.0, f64::max);
        r.push(("max_displacement".to_string(), umax));
        let strains = self.gauge_strains();
        for ((name, _), (now, peak)) in self
            .gauges
            .iter()
            .zip(strains.iter().zip(&self.st.strain_peaks))
        {
            let peak = [
                peak[0].max(now[0]),
                peak[1].min(now[1]),
                peak[2].max(now[2]),
            ];
            for (k, q) in STRAIN_QUANTITIES.iter().enumerate() {
                r.push((format!("strain.{name}.{q}"), now[k]));
                r.push((format!("strain.{name}.{q}.peak"), peak[k]));
            }
        }
        if self.nonlinear {
            let k = self.gauge_stress_columns();
            for ((name, _), v) in self.gauges.iter().zip(self.gauge_stresses()) {
                for (q, x) in GAUGE_STRESS_QUANTITIES[..k].iter().zip(v) {
                    r.push((format!("{q}.{name}"), x));
                }
            }
        }
        if let Some(Some(dt)) = self.crit.get() {
            r.push(("critical_time_step".to_string(), *dt));
        }
        r
    }

    /// How many of [`GAUGE_STRESS_QUANTITIES`] a nonlinear model reports: the plastic ones only
    /// when a material with plastic state is in use.
    fn gauge_stress_columns(&self) -> usize {
        if self.state_stride > 0 {
            3
        } else {
            1
        }
    }

    /// Per strain gauge of a nonlinear model: the largest element-mean von Mises (Cauchy)
    /// stress, equivalent plastic strain and plastic-zone share over its elements.
    fn gauge_stresses(&self) -> Vec<[f64; 3]> {
        if self.gauges.is_empty() {
            return Vec::new();
        }
        let (stress, peeq, zone) = self.element_point_summaries();
        self.gauges
            .iter()
            .map(|(_, elements)| {
                elements.iter().fold([0.0f64; 3], |acc, &e| {
                    let e = e as usize;
                    [
                        acc[0].max(element::von_mises(&stress[e])),
                        acc[1].max(peeq[e]),
                        acc[2].max(zone[e]),
                    ]
                })
            })
            .collect()
    }

    // ----------------------------------------------------------------------------------------
    // Further public API (tests, benchmarks, tools)
    // ----------------------------------------------------------------------------------------

    pub fn mesh(&self) -> &Mesh {
        &self.mesh
    }
    /// Exterior faces of the mesh.
    pub fn boundary(&self) -> &Boundary {
        &self.boundary
    }
    /// Full displacement vector (3 per node) [m].
    pub fn displacements(&self) -> &[f64] {
        &self.st.u
    }
    pub fn velocities(&self) -> &[f64] {
        &self.st.v
    }
    pub fn accelerations(&self) -> &[f64] {
        &self.st.a
    }
    /// Displacement of a probe by name.
    pub fn probe_displacement(&self, name: &str) -> Option<[f64; 3]> {
        self.probes
            .iter()
            .find(|(n, _)| n == name)
            .map(|&(_, node)| {
                let d = 3 * node as usize;
                [self.st.u[d], self.st.u[d + 1], self.st.u[d + 2]]
            })
    }
    /// Whether a dof is eliminated by a support (or belongs to an unused node).
    pub fn is_fixed(&self, dof: usize) -> bool {
        self.dofs.eq[dof] == FIXED
    }
    /// Prescribes the displacement of a fixed dof (g of (2.48)); used from the next solve on.
    pub fn set_prescribed_displacement(&mut self, dof: usize, value: f64) -> Result<(), FemError> {
        if dof >= self.num_dofs() || !self.is_fixed(dof) {
            return Err(FemError::Selection(format!(
                "dof {dof} is not a supported (fixed) dof"
            )));
        }
        self.st.prescribed[dof] = value;
        // a nonlinear model moves it there over the next solve's load increments
        if !self.nonlinear {
            self.st.u[dof] = value;
        }
        Ok(())
    }
    /// Sets initial displacements and velocities (full vectors; supported dofs keep their
    /// prescribed values, velocity zero); the initial acceleration is solved at the next step.
    pub fn set_initial_conditions(&mut self, u0: &[f64], v0: &[f64]) -> Result<(), FemError> {
        let nd = self.num_dofs();
        if u0.len() != nd || v0.len() != nd {
            return Err(FemError::Solver(format!(
                "initial conditions need {nd} values each"
            )));
        }
        for d in 0..nd {
            if self.is_fixed(d) {
                self.st.u[d] = self.st.prescribed[d];
                self.st.v[d] = 0.0;
            } else {
                self.st.u[d] = u0[d];
                self.st.v[d] = v0[d];
            }
            self.st.a[d] = 0.0;
        }
        self.st.accel_ready = false;
        Ok(())
    }
    /// Strain energy ½ uᵀ K u over the free dofs [J]; for a nonlinear model the stored
    /// energy ∫ Ψ dV₀ (elastic part for plasticity).
    pub fn strain_energy(&self) -> f64 {
        if self.nonlinear {
            return self.stored_energy();
        }
        let u = self.dofs.gather(&self.st.u);
        let mut ku = vec![0.0; u.len()];
        self.pattern.mul(&self.k, &u, &mut ku);
        0.5 * numeric::dot(&u, &ku)
    }
    /// Kinetic energy ½ vᵀ M v with the analysis' mass matrix [J].
    pub fn kinetic_energy(&self) -> f64 {
        let v = self.dofs.gather(&self.st.v);
        let mut mv = vec![0.0; v.len()];
        self.mass_mul(&v, &mut mv);
        0.5 * numeric::dot(&v, &mv)
    }
    /// External load vector F(t) (loads × histories + interface forces), full dofs [N].
    pub fn external_forces(&self, t: f64) -> Vec<f64> {
        let mut f = vec![0.0; self.num_dofs()];
        for l in &self.loads {
            let h = self.history_factor(&l.history, t);
            if h != 0.0 {
                for (fi, li) in f.iter_mut().zip(&l.f) {
                    *fi += h * li;
                }
            }
        }
        for (i, &n) in self.iface.nodes.iter().enumerate() {
            for c in 0..3 {
                f[3 * n as usize + c] += self.st.interface_forces[3 * i + c];
            }
        }
        f
    }
    /// Internal forces K u assembled element by element over all dofs [N].
    pub fn internal_forces(&self) -> Vec<f64> {
        if self.nonlinear {
            return self
                .internal_forces_at(&self.st.u)
                .unwrap_or_else(|_| vec![f64::NAN; self.num_dofs()]);
        }
        self.element_forces(&self.st.u)
    }
    /// The summed reaction force of every named support, over the dofs it reports [N].
    pub fn support_reactions(&self) -> Vec<(String, [f64; 3])> {
        if self.reported_supports.is_empty() {
            return Vec::new();
        }
        let r = self.reactions();
        (self.reported_supports.iter())
            .map(|(name, dofs)| {
                let mut f = [0.0; 3];
                for &d in dofs {
                    f[d % 3] += r[d];
                }
                (name.clone(), f)
            })
            .collect()
    }

    /// Support reactions R = K u − F(t) (non-zero only on supported dofs) [N].
    pub fn reactions(&self) -> Vec<f64> {
        let fi = self.internal_forces();
        let fe = self.external_forces(self.st.time);
        (0..self.num_dofs())
            .map(|d| if self.is_fixed(d) { fi[d] - fe[d] } else { 0.0 })
            .collect()
    }
    /// Node coordinates and displacements of element `e`.
    fn element_state(&self, e: usize) -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
        let mut x = Vec::new();
        self.mesh.element_coords(e, &mut x);
        let u = self
            .mesh
            .element_nodes(e)
            .iter()
            .map(|&n| {
                let d = 3 * n as usize;
                [self.st.u[d], self.st.u[d + 1], self.st.u[d + 2]]
            })
            .collect();
        (x, u)
    }
    /// Element-mean stress (Voigt xx, yy, zz, xy, yz, zx) [Pa].
    pub fn element_stresses(&self) -> Vec<[f64; 6]> {
        if self.nonlinear {
            return self.element_point_summaries().0;
        }
        (0..self.mesh.num_elements())
            .into_par_iter()
            .map(|e| {
                let (x, u) = self.element_state(e);
                element::mean_stress(self.mesh.kinds[e], &x, &u, self.lame_of(e))
                    .unwrap_or([f64::NAN; 6])
            })
            .collect()
    }
    fn lame_of(&self, e: usize) -> Lame {
        self.lame[self.elem_mat[e] as usize]
    }
    /// Per strain gauge (in scene order): name and the current [largest max-principal strain,
    /// smallest min-principal strain, largest von Mises equivalent strain] over its elements'
    /// integration points.
    pub fn strain_gauges(&self) -> Vec<(String, [f64; 3])> {
        self.gauges
            .iter()
            .map(|(n, _)| n.clone())
            .zip(self.gauge_strains())
            .collect()
    }
    /// Per element: [max principal, min principal, max von Mises] strain over its integration
    /// points (NaN for an element that cannot be integrated).
    pub fn element_strain_extremes(&self, elements: &[u32]) -> Vec<[f64; 3]> {
        elements
            .par_iter()
            .map(|&e| {
                let e = e as usize;
                let (x, u) = self.element_state(e);
                match element::point_strains(self.mesh.kinds[e], &x, &u, self.lame_of(e)) {
                    Ok(eps) => eps.iter().fold(NO_PEAK, |acc, ep| {
                        let p = element::principal_values(ep);
                        [
                            acc[0].max(p[2]),
                            acc[1].min(p[0]),
                            acc[2].max(element::von_mises_strain(ep)),
                        ]
                    }),
                    Err(_) => [f64::NAN; 3],
                }
            })
            .collect()
    }
    fn gauge_strains(&self) -> Vec<[f64; 3]> {
        self.gauges
            .iter()
            .map(|(_, elements)| {
                self.element_strain_extremes(elements)
                    .iter()
                    .fold(NO_PEAK, |acc, v| {
                        // NaN (a collapsed element) propagates: it must not hide as a maximum
                        let pick = |a: f64, b: f64, hi: bool| {
                            if a.is_nan() || b.is_nan() {
                                f64::NAN
                            } else if hi {
                                a.max(b)
                            } else {
                                a.min(b)
                            }
                        };
                        [
                            pick(acc[0], v[0], true),
                            pick(acc[1], v[1], false),
                            pick(acc[2], v[2], true),
                        ]
                    })
            })
            .collect()
    }
    /// One explicit central-difference step of exactly `h` (no stability check).
    pub fn explicit_step(&mut self, h: f64) -> Result<(), FemError> {
        if !(h.is_finite() && h > 0.0) {
            return Err(FemError::TimeStep(h));
        }
        self.explicit_steps(h, 1)?;
        self.st.steps += 1;
        Ok(())
    }
    /// Dense K and M on the free equations (row-major n×n), M being the analysis' mass matrix
    /// (consistent for dynamic analyses unless lumped, else lumped). For small models only
    /// (tests, modal checks).
    pub fn dense_free_matrices(&self) -> (usize, Vec<f64>, Vec<f64>) {
        let n = self.dofs.n_eq;
        let mut k = vec![0.0; n * n];
        let mut m = vec![0.0; n * n];
        let ml = self.dofs.gather(&self.m_lumped);
        for j in 0..n {
            for p in self.pattern.col_ptr[j] as usize..self.pattern.col_ptr[j + 1] as usize {
                let i = self.pattern.row_idx[p] as usize;
                k[i * n + j] = self.k[p];
                if let Some(mc) = &self.m_consistent {
                    m[i * n + j] = mc[p];
                }
            }
            if self.m_consistent.is_none() {
                m[j * n + j] = ml[j];
            }
        }
        (n, k, m)
    }
    /// Scatters a free-equation vector to a full dof vector (supported dofs zero).
    pub fn free_to_full(&self, free: &[f64]) -> Vec<f64> {
        let mut full = vec![0.0; self.num_dofs()];
        self.dofs.scatter(free, &mut full);
        full
    }
    /// Total mass from the lumped mass [kg].
    pub fn total_mass(&self) -> f64 {
        self.m_lumped.iter().step_by(3).sum()
    }
    /// The materials (scene order: `[fem.materials]` by name, then `[fem.material]`).
    pub fn materials(&self) -> &[Material] {
        &self.materials
    }
    /// Whether the model is solved by Newton iterations (internal forces from stresses).
    pub fn is_nonlinear(&self) -> bool {
        self.nonlinear
    }
    /// Relative residuals of each Newton iteration, per increment (static) or step (Bossak,
    /// after cut-backs) of the last nonlinear solve; empty for linear models. The number of
    /// iterations of an increment is its length − 1.
    pub fn last_newton_residuals(&self) -> &[Vec<f64>] {
        &self.last_newton
    }

    // ----------------------------------------------------------------------------------------
    // Solvers
    // ----------------------------------------------------------------------------------------

    /// The factor of a load or moving support at `t`: its named history's value, 1 without
    /// one (NaN for an unknown name, which the scene's validation excludes).
    fn history_factor(&self, history: &Option<String>, t: f64) -> f64 {
        match history {
            Some(name) => self
                .histories
                .get(name)
                .map_or(f64::NAN, |h| h.eval(t, &self.histories)),
            None => 1.0,
        }
    }

    /// Sets the prescribed displacements of the moving supports to their values at `t`.
    fn move_supports(&mut self, t: f64) {
        for ms in &self.moving {
            let h = self.history_factor(&ms.history, t);
            for &(d, v) in &ms.dofs {
                self.st.prescribed[d] = v * h;
                if !self.nonlinear {
                    self.st.u[d] = v * h;
                }
            }
        }
    }

    /// Free-equation right-hand side F_f(t) − K_fg g (2.57).
    fn free_rhs(&self, t: f64) -> Vec<f64> {
        let kg = self.prescribed_load();
        self.free_rhs_with(t, kg.as_deref())
    }

    /// K_fg g on the free equations, when any support has a non-zero prescribed value.
    fn prescribed_load(&self) -> Option<Vec<f64>> {
        // a nonlinear model's internal forces see the prescribed values directly
        if self.nonlinear {
            return None;
        }
        if self.st.prescribed.iter().any(|&g| g != 0.0) {
            Some(self.dofs.gather(&self.element_forces(&self.st.prescribed)))
        } else {
            None
        }
    }

    fn free_rhs_with(&self, t: f64, kg: Option<&[f64]>) -> Vec<f64> {
        let f = self.external_forces(t);
        let mut rhs = self.dofs.gather(&f);
        if let Some(kg) = kg {
            for (r, k) in rhs.iter_mut().zip(kg) {
                *r -= k;
            }
        }
        rhs
    }

    fn set_free(&mut self, which: u8, free: &[f64]) {
        let target = match which {
            0 => &mut self.st.u,
            1 => &mut self.st.v,
            _ => &mut self.st.a,
        };
        self.dofs.scatter(free, target);
        if which == 0 {
            for (d, &e) in self.dofs.eq.iter().enumerate() {
                if e == FIXED {
                    self.st.u[d] = self.st.prescribed[d];
                }
            }
        }
    }

    /// K u = F (2.28) with the cached Cholesky factor of K.
    /// With the mixed-precision solver (`[fem] solver`), an f32 factor preconditions f64
    /// conjugate gradients; when that fails the f64 factor takes over (logged once).
    /// `one_shot`: a solve not repeated every window ([`Model::solve_static`]), for the
    /// choice of `[fem] solver = "auto"`.
    fn static_solve_at(&mut self, t: f64, one_shot: bool) -> Result<(), FemError> {
        if self.nonlinear {
            return self.newton_static(t);
        }
        let mut rhs = self.free_rhs(t);
        let mut solved = false;
        if self.k_factor.is_none()
            && !self.mixed_failed
            && self
                .solver
                .mixed_for(self.dofs.n_eq, one_shot || self.k_mixed.is_some())
        {
            if self.k_mixed.is_none() {
                match MixedFactor::new(&self.pattern, &self.k, &mut self.symbolic) {
                    Ok(f) => self.k_mixed = Some(f),
                    Err(e) => {
                        tracing::warn!("{e}; solving with the f64 factor instead");
                        self.mixed_failed = true;
                    }
                }
            }
            if let Some(f) = &self.k_mixed {
                // on failure `solve` leaves the right-hand side as it was
                match f.solve(&self.pattern, &self.k, &mut rhs, 1e-11, 1e-9, 200) {
                    Ok(info) => {
                        self.last_refined = Some(info);
                        solved = true;
                    }
                    Err(e) => {
                        tracing::warn!("{e}; solving with the f64 factor instead");
                        self.k_mixed = None;
                        self.mixed_failed = true;
                    }
                }
            }
        }
        if !solved {
            if self.k_factor.is_none() {
                self.k_factor = Some(Factor::new(&self.pattern, &self.k, &mut self.symbolic)?);
            }
            self.last_refined = None;
            self.k_factor
                .as_ref()
                .expect("set")
                .solve_in_place(&mut rhs);
        }
        check_finite(&rhs, "static displacement")?;
        self.set_free(0, &rhs);
        self.st.v.fill(0.0);
        self.st.a.fill(0.0);
        self.st.accel_ready = false;
        Ok(())
    }

    /// The stiffness part of the balance on the free equations: K (u + b v) for a linear
    /// model, f_int(u) + b K₀ v for a nonlinear one (committing the point states with
    /// `commit`, as an explicit step does).
    fn stiffness_forces(
        &mut self,
        u: &[f64],
        v: &[f64],
        rb: f64,
        out: &mut [f64],
        commit: bool,
    ) -> Result<(), FemError> {
        if self.nonlinear {
            let f = self.free_internal_forces(u, commit)?;
            if rb != 0.0 {
                self.pattern.mul(&self.k, v, out);
            } else {
                out.fill(0.0);
            }
            for (o, fi) in out.iter_mut().zip(&f) {
                *o = fi + rb * *o;
            }
        } else {
            let w: Vec<f64> = u.iter().zip(v).map(|(a, b)| a + rb * b).collect();
            self.pattern.mul(&self.k, &w, out);
        }
        Ok(())
    }

    /// vals += cm M on the pattern (the analysis' mass: consistent, or lumped on the diagonal).
    fn add_mass(&self, vals: &mut [f64], cm: f64) {
        match &self.m_consistent {
            Some(m) => {
                for (v, mm) in vals.iter_mut().zip(m) {
                    *v += cm * mm;
                }
            }
            None => {
                let ml = self.dofs.gather(&self.m_lumped);
                for (j, &p) in self.diag_pos.iter().enumerate() {
                    vals[p] += cm * ml[j];
                }
            }
        }
    }

    fn mass_mul(&self, x: &[f64], y: &mut [f64]) {
        match &self.m_consistent {
            Some(m) => self.pattern.mul(m, x, y),
            None => {
                let ml = self.dofs.gather(&self.m_lumped);
                for i in 0..x.len() {
                    y[i] = ml[i] * x[i];
                }
            }
        }
    }

    fn rayleigh(&self) -> (f64, f64) {
        match self.analysis {
            Analysis::Dynamic {
                rayleigh_a,
                rayleigh_b,
                ..
            }
            | Analysis::Explicit {
                rayleigh_a,
                rayleigh_b,
                ..
            } => (rayleigh_a, rayleigh_b),
            Analysis::Static => (0.0, 0.0),
        }
    }

    /// M a₀ = F(t₀) − K u₀ − C v₀ at the start of dynamic stepping.
    fn initial_acceleration(&mut self) -> Result<(), FemError> {
        let (ra, rb) = self.rayleigh();
        let u = self.dofs.gather(&self.st.u);
        let v = self.dofs.gather(&self.st.v);
        let mut rhs = self.free_rhs(self.st.time);
        let mut tmp = vec![0.0; u.len()];
        // K (u + b v), or f_int(u) + b K₀ v
        self.stiffness_forces(&u, &v, rb, &mut tmp, false)?;
        for (r, t) in rhs.iter_mut().zip(&tmp) {
            *r -= t;
        }
        self.mass_mul(&v, &mut tmp);
        for (r, t) in rhs.iter_mut().zip(&tmp) {
            *r -= ra * t;
        }
        if let Some(m) = &self.m_consistent {
            if self.m_factor.is_none() {
                self.m_factor = Some(Factor::new(&self.pattern, m, &mut self.symbolic)?);
            }
            self.m_factor
                .as_ref()
                .expect("set")
                .solve_in_place(&mut rhs);
        } else {
            let ml = self.dofs.gather(&self.m_lumped);
            for (r, m) in rhs.iter_mut().zip(ml) {
                *r /= m;
            }
        }
        self.set_free(2, &rhs);
        self.st.accel_ready = true;
        Ok(())
    }

    /// One step of the Wood–Bossak–Zienkiewicz scheme (REFERENCE A6; the update rules are
    /// (2.85)–(2.86), the balance is the corrected (2.87)):
    /// M[(1−α_B) a_{n+1} + α_B a_n] + C v_{n+1} + K u_{n+1} = F_{n+1},
    /// γ = ½ − α_B, β = (1 − α_B)²/4, C = a M + b K (2.84).
    fn bossak_step(&mut self, dt: f64) -> Result<(), FemError> {
        let Analysis::Dynamic { alpha_b, .. } = self.analysis else {
            unreachable!()
        };
        let (ra, rb) = self.rayleigh();
        let gamma = 0.5 - alpha_b;
        let beta = 0.25 * (1.0 - alpha_b).powi(2);
        if !self.st.accel_ready {
            self.initial_acceleration()?;
        }
        // Effective matrix [(1−α_B) M + γΔt C + βΔt² K], factorised once per Δt.
        let cm = (1.0 - alpha_b) + gamma * dt * ra;
        let ck = gamma * dt * rb + beta * dt * dt;
        if self.eff_factor.as_ref().map(|(bits, _)| *bits) != Some(dt.to_bits()) {
            let mut vals: Vec<f64> = self.k.iter().map(|k| ck * k).collect();
            self.add_mass(&mut vals, cm);
            self.eff_factor = None;
            let f = Factor::new(&self.pattern, &vals, &mut self.symbolic)?;
            self.eff_factor = Some((dt.to_bits(), f));
        }
        let u = self.dofs.gather(&self.st.u);
        let v = self.dofs.gather(&self.st.v);
        let a = self.dofs.gather(&self.st.a);
        let n = u.len();
        // predictors (2.85), (2.86) without the a_{n+1} terms
        let mut ut = vec![0.0; n];
        let mut vt = vec![0.0; n];
        for i in 0..n {
            ut[i] = u[i] + dt * v[i] + dt * dt * (0.5 - beta) * a[i];
            vt[i] = v[i] + dt * (1.0 - gamma) * a[i];
        }
        let t1 = self.st.time + dt;
        let mut rhs = self.free_rhs(t1);
        let mut tmp = vec![0.0; n];
        let w: Vec<f64> = (0..n).map(|i| alpha_b * a[i] + ra * vt[i]).collect();
        self.mass_mul(&w, &mut tmp);
        for i in 0..n {
            rhs[i] -= tmp[i];
        }
        let w: Vec<f64> = (0..n).map(|i| rb * vt[i] + ut[i]).collect();
        self.pattern.mul(&self.k, &w, &mut tmp);
        for i in 0..n {
            rhs[i] -= tmp[i];
        }
        self.eff_factor
            .as_ref()
            .expect("set")
            .1
            .solve_in_place(&mut rhs);
        check_finite(&rhs, "Bossak acceleration")?;
        let a1 = rhs;
        for i in 0..n {
            ut[i] += beta * dt * dt * a1[i];
            vt[i] += gamma * dt * a1[i];
        }
        self.set_free(0, &ut);
        self.set_free(1, &vt);
        self.set_free(2, &a1);
        self.st.time = t1;
        Ok(())
    }

    /// `n` central-difference steps of size h with the lumped mass (velocity-Verlet form):
    /// v_{n+½} = v_n + h/2 a_n, u_{n+1} = u_n + h v_{n+½}, a_{n+1} = M_L⁻¹(F − K u_{n+1} − C v_{n+½}).
    fn explicit_steps(&mut self, h: f64, n: u64) -> Result<(), FemError> {
        let (ra, rb) = self.rayleigh();
        let ml = self.dofs.gather(&self.m_lumped);
        if !self.st.accel_ready {
            let u = self.dofs.gather(&self.st.u);
            let v = self.dofs.gather(&self.st.v);
            let mut r = self.free_rhs(self.st.time);
            let mut tmp = vec![0.0; u.len()];
            self.stiffness_forces(&u, &v, rb, &mut tmp, false)?;
            for i in 0..r.len() {
                r[i] = (r[i] - tmp[i] - ra * ml[i] * v[i]) / ml[i];
            }
            self.set_free(2, &r);
            self.st.accel_ready = true;
        }
        let mut u = self.dofs.gather(&self.st.u);
        let mut v = self.dofs.gather(&self.st.v);
        let mut a = self.dofs.gather(&self.st.a);
        let m = u.len();
        let mut tmp = vec![0.0; m];
        let mut w = vec![0.0; m];
        // loads: constant part of the rhs (−K_fg g) computed once
        let has_hist = !self.loads.is_empty();
        let moving = !self.moving.is_empty();
        let mut kg = self.prescribed_load();
        let mut f_const = if has_hist || moving {
            Vec::new()
        } else {
            self.free_rhs_with(self.st.time, kg.as_deref())
        };
        let mut t = self.st.time;
        for _ in 0..n {
            for i in 0..m {
                v[i] += 0.5 * h * a[i];
                u[i] += h * v[i];
            }
            t += h;
            if moving {
                // the supports move every substep (their K_fg g with them)
                self.move_supports(t);
                kg = self.prescribed_load();
            }
            if has_hist || moving {
                f_const = self.free_rhs_with(t, kg.as_deref());
            }
            if self.nonlinear {
                self.stiffness_forces(&u, &v, rb, &mut tmp, true)?;
            } else {
                for i in 0..m {
                    w[i] = u[i] + rb * v[i];
                }
                self.pattern.mul(&self.k, &w, &mut tmp);
            }
            for i in 0..m {
                a[i] = (f_const[i] - tmp[i] - ra * ml[i] * v[i]) / ml[i];
                v[i] += 0.5 * h * a[i];
            }
        }
        self.set_free(0, &u);
        self.set_free(1, &v);
        self.set_free(2, &a);
        self.st.time = t;
        Ok(())
    }

    /// Largest eigenvalue of M_L⁻¹ K (computed once).
    fn max_eigenvalue(&self) -> Option<f64> {
        *self
            .lumped_max_eigenvalue
            .get_or_init(|| self.compute_max_eigenvalue())
    }

    /// Largest eigenvalue of M_L⁻¹ K by Lanczos on the symmetric M_L^{-½} K M_L^{-½}.
    fn compute_max_eigenvalue(&self) -> Option<f64> {
        let n = self.dofs.n_eq;
        if n == 0 {
            return None;
        }
        let s: Vec<f64> = self
            .dofs
            .gather(&self.m_lumped)
            .iter()
            .map(|m| 1.0 / m.sqrt())
            .collect();
        let mut tmp = vec![0.0; n];
        Some(numeric::lanczos_largest(
            n,
            |q, w| {
                for i in 0..n {
                    tmp[i] = s[i] * q[i];
                }
                self.pattern.mul(&self.k, &tmp, w);
                for i in 0..n {
                    w[i] *= s[i];
                }
            },
            |x, y| y.copy_from_slice(x),
            false,
            300,
            1e-10,
        ))
    }

    /// Σ_e K_e u_e over all dofs, parallel in element batches with an ordered scatter.
    fn element_forces(&self, u: &[f64]) -> Vec<f64> {
        let ne = self.mesh.num_elements();
        let mut out = vec![0.0; self.num_dofs()];
        const BATCH: usize = 4096;
        let mut start = 0;
        while start < ne {
            let end = (start + BATCH).min(ne);
            let fe: Vec<Vec<f64>> = (start..end)
                .into_par_iter()
                .map_init(
                    || (Vec::new(), Vec::new(), Vec::new()),
                    |(x, ke, sc), e| {
                        self.mesh.element_coords(e, x);
                        let kind = self.mesh.kinds[e];
                        let nodes = self.mesh.element_nodes(e);
                        let nd = 3 * nodes.len();
                        let scale = self.mesh.element_scale(e, sc);
                        if element::stiffness(kind, x, self.lame_of(e), scale, ke).is_err() {
                            return vec![f64::NAN; nd];
                        }
                        let ue: Vec<f64> = nodes
                            .iter()
                            .flat_map(|&n| (0..3).map(move |c| u[3 * n as usize + c]))
                            .collect();
                        (0..nd)
                            .map(|i| (0..nd).map(|j| ke[i * nd + j] * ue[j]).sum())
                            .collect()
                    },
                )
                .collect();
            for (e, f) in (start..end).zip(fe) {
                for (a, &n) in self.mesh.element_nodes(e).iter().enumerate() {
                    for c in 0..3 {
                        out[3 * n as usize + c] += f[3 * a + c];
                    }
                }
            }
            start = end;
        }
        self.add_penalty_forces(u, &mut out);
        out
    }

    /// Adds ε V u of a volume overlap (Wellmann (6.25), FE side) over all dofs.
    pub(super) fn add_penalty_forces(&self, u: &[f64], out: &mut [f64]) {
        for (e, v) in &self.penalty_blocks {
            let nodes = self.mesh.element_nodes(*e);
            let nn = nodes.len();
            for (a, &na) in nodes.iter().enumerate() {
                for c in 0..3 {
                    let f: f64 = (0..nn)
                        .map(|b| v[a * nn + b] * u[3 * nodes[b] as usize + c])
                        .sum();
                    out[3 * na as usize + c] += f;
                }
            }
        }
    }
}

/// Poisson ratio above which tet4 and full-integration hex8 meshes draw a locking warning.
pub const LOCKING_POISSON_RATIO: f64 = 0.45;

/// Above this many free dofs, `limits` skips the lowest frequency (a Cholesky factor of K and
/// tens of solves).
pub const LOWEST_FREQUENCY_MAX_EQUATIONS: usize = 200_000;

/// Column/result names of a strain gauge's three quantities.
const STRAIN_QUANTITIES: [&str; 3] = ["max_principal", "min_principal", "von_mises"];
/// Gauge columns of nonlinear models (`<quantity>.<gauge>`), largest over the gauge's elements.
const GAUGE_STRESS_QUANTITIES: [&str; 3] = [
    "stress_von_mises",
    "equivalent_plastic_strain",
    "plastic_zone",
];
/// Neutral element of the [max, min, max] strain reductions.
const NO_PEAK: [f64; 3] = [f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY];

/// Elements of a strain gauge: a `set` naming an element set gives its elements; otherwise
/// the elements whose nodes are all selected; no selector means every element.
fn gauge_elements(
    mesh: &Mesh,
    on: Option<&crate::config::Selector>,
    what: &str,
) -> Result<Vec<u32>, FemError> {
    let Some(sel) = on else {
        return Ok((0..mesh.num_elements() as u32).collect());
    };
    if let Some(set) = sel.set.as_ref().and_then(|name| mesh.elem_set(name)) {
        if !set.is_empty() {
            return Ok(set.clone());
        }
    }
    let nodes = surface::select_nodes(mesh, sel, what)?;
    let mut mark = vec![false; mesh.num_nodes()];
    for n in nodes {
        mark[n as usize] = true;
    }
    let elements: Vec<u32> = (0..mesh.num_elements())
        .filter(|&e| mesh.element_nodes(e).iter().all(|&n| mark[n as usize]))
        .map(|e| e as u32)
        .collect();
    if elements.is_empty() {
        return Err(FemError::Selection(format!(
            "{what}: selects nodes but no whole element of {} (an element counts when all its nodes are selected)",
            mesh.source
        )));
    }
    Ok(elements)
}

/// How far outside an element a probe point may lie, as a fraction of the element's
/// bounding-box diagonal: round-off of a point written on the surface, not a point elsewhere.
const PROBE_TOLERANCE: f64 = 0.05;

/// Whether `q` lies in the bounding box of some element, grown by [`PROBE_TOLERANCE`] of its
/// diagonal: inside the body up to that tolerance (a bounding box is looser than a
/// tetrahedron or a curved element, so points near such a surface pass as well).
fn point_in_body(mesh: &Mesh, q: [f64; 3]) -> bool {
    let mut x = Vec::new();
    (0..mesh.num_elements()).any(|e| {
        mesh.element_coords(e, &mut x);
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in &x {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let diagonal = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
        let tol = PROBE_TOLERANCE * diagonal;
        (0..3).all(|k| q[k] >= lo[k] - tol && q[k] <= hi[k] + tol)
    })
}

/// `[x, y, z]` with readable numbers.
fn fmt_point(p: [f64; 3]) -> String {
    let f = crate::resources::format_number;
    format!("[{}, {}, {}]", f(p[0]), f(p[1]), f(p[2]))
}

fn gravity_loads(
    mesh: &Mesh,
    props: ElementProps<'_>,
    g: [f64; 3],
    f: &mut [f64],
) -> Result<(), FemError> {
    // f_a = ρ g ∫ N_a dV, the body-force term (v, f) of (2.45)
    for e in 0..mesh.num_elements() {
        let mut x = Vec::new();
        mesh.element_coords(e, &mut x);
        let kind = mesh.kinds[e];
        let nn = kind.num_nodes();
        let mut m = Vec::new();
        let mut sc = Vec::new();
        let scale = mesh.element_scale(e, &mut sc);
        element::mass(kind, &x, 1.0, scale, &mut m).map_err(|b| FemError::Mesh {
            file: mesh.source.clone(),
            line: mesh.elem_lines[e],
            message: format!("element {} has det J = {:.3e}", mesh.elem_ids[e], b.det_j),
        })?;
        // Σ_b ∫ N_a N_b dV = ∫ N_a dV (partition of unity)
        let rho = props.density(e);
        for (a, &n) in mesh.element_nodes(e).iter().enumerate() {
            let w: f64 = (0..nn).map(|b| m[a * nn + b]).sum();
            for c in 0..3 {
                f[3 * n as usize + c] += rho * g[c] * w;
            }
        }
    }
    Ok(())
}

fn check_finite(v: &[f64], what: &str) -> Result<(), FemError> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(FemError::NonFinite(what.into()))
    }
}
