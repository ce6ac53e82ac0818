//! A structure of MITC4 shells ([`crate::shell`]) behind the node-facing API of [`crate::Model`]:
//! six degrees of freedom per node (three translations, three rotations in the global frame),
//! linear statics and Bossak–Newmark dynamics, and the coupling of Ullrich (2.6) and (3.9):
//! the DEM sees the reference surfaces at ± t/2 along the turned directors, and the forces on
//! them reach the mid-surface nodes as forces and moments.
//!
//! Interface nodes: for each face the DEM sees (`[fem.interface] faces`), one per mid-surface
//! node of the coupled shells; the top surface's keep the mesh's node ids, the bottom's are
//! shifted by the largest node id (id + max id).

use crate::assembly::{DofMap, Factor, LuFactor, Pattern, Symbolic, SymbolicLu, FIXED};
use crate::config::{Analysis, FemConfig, Load, MeshSpec, NewtonConfig, Output, ShellFaces};
use crate::history::History;
use crate::mesh::{plate_mesh, Mesh};
use crate::output;
use crate::shell::{self, Geometry, SurfaceNode, DOFS};
use crate::surface::select_nodes;
use crate::{FemError, InterfaceMesh};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

const SNAPSHOT_FORMAT: u32 = 1;

/// Largest angle between a shell's own normal at a corner and the node's mean director: the
/// averaged director of MITC4 models smooth shells, not folds.
const MAX_KINK_DEG: f64 = 20.0;

/// Everything that evolves in time; `snapshot` / `restore` serialise exactly this.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct State {
    format: u32,
    time: f64,
    /// Full dof vectors (6 per node: u_x, u_y, u_z, θ_x, θ_y, θ_z).
    u: Vec<f64>,
    v: Vec<f64>,
    a: Vec<f64>,
    interface_forces: Vec<f64>,
    accel_ready: bool,
    windows: u64,
    csv_started: bool,
    /// Nonlinear shells: Newton iterations and solves (static increments or Bossak steps)
    /// so far.
    newton_iterations: u64,
    newton_solves: u64,
    /// Nonlinear Bossak steps: the full displacements and Jacobian coefficients (ck, cm) of
    /// the tangent kept between steps, to rebuild it after a restore.
    tangent_at: Option<(Vec<f64>, f64, f64)>,
}

/// The coupled reference surfaces: per interface node its mid-surface node and side (+1 top,
/// −1 bottom); triangles index the interface nodes, oriented away from the shell.
#[derive(Clone, Debug, Default)]
struct ShellInterface {
    nodes: Vec<u32>,
    side: Vec<f64>,
    triangles: Vec<u32>,
}

/// A model of MITC4 shells ready to be stepped.
pub struct ShellModel {
    mesh: Mesh,
    thickness: Vec<f64>,
    /// Unit mid-surface normals per node (mean of the corner normals of its shells).
    directors: Vec<[f64; 3]>,
    /// Per node, the mean thickness of its shells (the reference surfaces' offset).
    node_thickness: Vec<f64>,
    material: shell::Material,
    density: f64,
    analysis: Analysis,
    /// Geometrically nonlinear: internal forces from the Green–Lagrange strains, Newton.
    nonlinear: bool,
    newton: NewtonConfig,
    /// Relative residuals of every Newton iteration of the last solve or step.
    last_newton: Vec<f64>,
    dofs: DofMap,
    pattern: Pattern,
    k: Vec<f64>,
    /// The analysis' mass (consistent, or lumped: block-diagonal per node) on the pattern.
    m: Vec<f64>,
    /// Lumped translational mass per node [kg].
    node_mass: Vec<f64>,
    symbolic: Option<Symbolic>,
    lu_symbolic: Option<SymbolicLu>,
    /// The tangent kept between nonlinear Bossak steps (taken at `State::tangent_at`).
    kept: Option<Tangent>,
    k_factor: Option<Factor>,
    /// The factor of ck K + cm M for the (ck, cm) bits it was made with.
    eff_factor: Option<((u64, u64), Factor)>,
    m_factor: Option<Factor>,
    loads: Vec<(Option<String>, Vec<f64>)>,
    histories: BTreeMap<String, History>,
    iface: ShellInterface,
    probes: Vec<(String, u32)>,
    output: Output,
    vtu_files: Vec<(f64, String)>,
    st: State,
}

fn config(field: &str, message: impl Into<String>) -> FemError {
    FemError::Config {
        field: field.into(),
        message: message.into(),
    }
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dot3(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn norm(a: [f64; 3]) -> f64 {
    dot3(a, a).sqrt()
}

fn part(v: &[f64], node: usize, at: usize) -> [f64; 3] {
    [v[6 * node + at], v[6 * node + at + 1], v[6 * node + at + 2]]
}

impl ShellModel {
    /// Whether a scene's `[fem]` table describes shells (a generated plate; a mesh file is
    /// known to be a shell mesh only once read: see [`crate::build`]).
    pub fn is_plate(cfg: &FemConfig) -> bool {
        matches!(cfg.mesh, MeshSpec::Plate { .. })
    }

    /// Builds the model of a scene's `[fem]` table on a generated plate.
    pub fn from_config(cfg: &FemConfig) -> Result<ShellModel, FemError> {
        cfg.validate()
            .map_err(|(field, message)| FemError::Config { field, message })?;
        let MeshSpec::Plate { size, origin, .. } = &cfg.mesh else {
            return Err(config("fem.mesh", "not a plate of shells"));
        };
        let div = cfg
            .mesh
            .plate_divisions()
            .map_err(|m| config("fem.mesh", m))?;
        ShellModel::from_mesh(cfg, plate_mesh(*origin, *size, div))
    }

    /// Builds the model on a shell mesh (quadrangles, no volume elements).
    pub fn from_mesh(cfg: &FemConfig, mesh: Mesh) -> Result<ShellModel, FemError> {
        cfg.validate()
            .map_err(|(field, message)| FemError::Config { field, message })?;
        if cfg.overlap.is_some() {
            return Err(FemError::Config {
                field: "fem.overlap".into(),
                message: "a volume overlap with particles needs volume elements, not shells".into(),
            });
        }
        let mesh_err = |line: usize, message: String| FemError::Mesh {
            file: mesh.source.clone(),
            line,
            message,
        };
        if let Some(&(id, line, what)) = mesh.shells.unsupported.first() {
            return Err(mesh_err(line, format!("element {id} is {what}")));
        }
        if let Some((id, line)) = mesh.shells.first_triangle() {
            return Err(mesh_err(
                line,
                format!(
                    "element {id} is a triangle (a shell model takes 4-node S4 or S4R shells \
                     only; a membrane takes triangles)"
                ),
            ));
        }
        if !mesh.is_shell_mesh() {
            return Err(mesh_err(
                0,
                "no 4-node shells in a mesh without volume elements".into(),
            ));
        }
        // a mesh file's counts are known only now: refuse a model that cannot fit before the
        // matrices are built (six dofs a node: twice a volume node's share)
        crate::resources::check_memory(
            &format!(
                "the shell model of {} ({} nodes, {} shells)",
                mesh.source,
                mesh.num_nodes(),
                mesh.shells.len()
            ),
            2.0 * crate::resources::model_bytes(mesh.num_nodes() as u64, mesh.shells.len() as u64),
            crate::resources::available_memory(),
        )
        .map_err(|message| config("fem.mesh", message))?;
        let Some(mat) = &cfg.material else {
            return Err(config(
                "fem.material",
                "shells need [fem] material = { youngs_modulus, poisson_ratio, density }",
            ));
        };
        if !cfg.sections.is_empty() || !cfg.materials.is_empty() {
            return Err(config(
                "fem.sections",
                "shells take the one linear elastic [fem] material (sections of several \
                 materials are for volume meshes)",
            ));
        }
        if matches!(cfg.analysis, Analysis::Explicit { .. }) {
            return Err(config(
                "fem.analysis",
                "explicit stepping of shells is not offered (the rotary inertia of a thin \
                 shell makes its stable step tiny); use analysis = \"dynamic\" (Bossak)",
            ));
        }
        let nonlinear = cfg.shell.as_ref().is_some_and(|s| s.nonlinear);
        let defaults = crate::config::NewtonConfig::default();
        if cfg.newton != defaults && !nonlinear {
            return Err(config(
                "fem.newton",
                "applies to nonlinear shells (shell = { ..., nonlinear = true })",
            ));
        }
        for (given, field) in [
            (cfg.newton.always, "fem.newton.always"),
            (cfg.newton.tangent != defaults.tangent, "fem.newton.tangent"),
            (
                cfg.newton.displacement_tolerance != defaults.displacement_tolerance,
                "fem.newton.displacement_tolerance",
            ),
            (
                cfg.solver != crate::config::LinearSolver::Auto,
                "fem.solver",
            ),
            (
                matches!(
                    cfg.mesh,
                    MeshSpec::File {
                        hex8_incompatible: true,
                        ..
                    } | MeshSpec::File {
                        hex8_bbar: true,
                        ..
                    }
                ),
                "fem.mesh.hex8",
            ),
        ] {
            if given {
                return Err(config(
                    field,
                    "does not apply to shells (their Newton iterations: force_tolerance, \
                     max_iterations, increments, max_cutbacks; their solver: sparse Cholesky)",
                ));
            }
        }
        if !cfg.strain_gauges.is_empty() {
            return Err(config(
                "fem.strain_gauges",
                "strain gauges read volume elements; a shell model reports probes",
            ));
        }
        if let Analysis::Dynamic {
            max_step: Some(_), ..
        } = cfg.analysis
        {
            return Err(config(
                "fem.analysis.max_step",
                "substeps are offered for volume meshes only",
            ));
        }
        let default_t = cfg.shell.as_ref().and_then(|s| s.thickness);
        if let Some(t) = default_t.filter(|t| !(t.is_finite() && *t > 0.0)) {
            return Err(config(
                "fem.shell.thickness",
                format!("must be > 0 m, got {t}"),
            ));
        }
        let ns = mesh.shells.len();
        let thickness = mesh.shells.thicknesses(
            default_t,
            "fem.shell.thickness",
            "*SHELL SECTION",
            &mesh.source,
        )?;

        // directors: mean corner normals; a degenerate quad or a fold is refused
        let nn = mesh.num_nodes();
        let mut sum = vec![[0.0; 3]; nn];
        let mut tsum = vec![0.0; nn];
        let mut count = vec![0u32; nn];
        let mut corner = Vec::with_capacity(ns);
        for (e, q) in mesh.shells.quads.iter().enumerate() {
            let x = q.map(|n| mesh.nodes[n as usize]);
            // the corner normals of shell::corner_normals, guarded against a zero area
            for k in 0..4 {
                let c = cross(sub(x[(k + 1) % 4], x[k]), sub(x[(k + 3) % 4], x[k]));
                let scale = norm(sub(x[(k + 1) % 4], x[k])) * norm(sub(x[(k + 3) % 4], x[k]));
                if !(norm(c) > 1e-10 * scale) {
                    return Err(mesh_err(
                        mesh.shells.lines[e],
                        format!(
                            "shell {} is degenerate at its corner node {} (two edges along one \
                             line or of zero length)",
                            mesh.shells.ids[e], mesh.node_ids[q[k] as usize]
                        ),
                    ));
                }
            }
            let nrm = shell::corner_normals(&x);
            for k in 0..4 {
                let n = q[k] as usize;
                for c in 0..3 {
                    sum[n][c] += nrm[k][c];
                }
                tsum[n] += thickness[e];
                count[n] += 1;
            }
            corner.push(nrm);
        }
        let directors: Vec<[f64; 3]> = sum
            .iter()
            .map(|s| {
                let l = norm(*s);
                if l > 0.0 {
                    s.map(|c| c / l)
                } else {
                    [0.0, 0.0, 1.0]
                }
            })
            .collect();
        let cos_kink = MAX_KINK_DEG.to_radians().cos();
        for (e, q) in mesh.shells.quads.iter().enumerate() {
            for k in 0..4 {
                let n = q[k] as usize;
                let c = dot3(corner[e][k], directors[n]);
                if !(c >= cos_kink) {
                    let why = if c < 0.0 {
                        "faces the other way from its neighbours there: number the corners of \
                         every shell counter-clockwise about the same side"
                    } else {
                        "meets its neighbours there at a fold; the averaged director of these \
                         shells models smooth surfaces (split the structure at folds)"
                    };
                    return Err(mesh_err(
                        mesh.shells.lines[e],
                        format!(
                            "shell {} at node {}: its normal is {:.0}° from the node's mean \
                             normal (at most {MAX_KINK_DEG}°); it {why}",
                            mesh.shells.ids[e],
                            mesh.node_ids[n],
                            c.clamp(-1.0, 1.0).acos().to_degrees()
                        ),
                    ));
                }
            }
        }
        for (e, q) in mesh.shells.quads.iter().enumerate() {
            let det = shell::min_jacobian(&Geometry {
                x: q.map(|n| mesh.nodes[n as usize]),
                director: q.map(|n| directors[n as usize]),
                thickness: thickness[e],
            });
            if !(det > 0.0) {
                return Err(mesh_err(
                    mesh.shells.lines[e],
                    format!(
                        "shell {}: its thickness {} m is too large for its curvature (the \
                         Jacobian through the thickness is {det:.3e} ≤ 0 at an integration point)",
                        mesh.shells.ids[e], thickness[e]
                    ),
                ));
            }
        }
        let node_thickness: Vec<f64> = tsum
            .iter()
            .zip(&count)
            .map(|(t, &c)| if c > 0 { t / c as f64 } else { 0.0 })
            .collect();
        let material = shell::Material {
            youngs_modulus: mat.youngs_modulus,
            poisson_ratio: mat.poisson_ratio,
        };

        // supports: translations by `fix`, rotations by `rotations` (default all three)
        let nd = 6 * nn;
        let mut fixed = vec![false; nd];
        for (i, s) in cfg.supports.iter().enumerate() {
            if s.name.is_some() {
                return Err(config(
                    &format!("fem.supports[{i}].name"),
                    "reaction reports are offered for volume meshes only",
                ));
            }
            if s.displacement.is_some() {
                return Err(config(
                    &format!("fem.supports[{i}].displacement"),
                    "moving supports are offered for volume meshes only",
                ));
            }
            let nodes = select_nodes(&mesh, &s.on, &format!("fem.supports[{i}].on"))?;
            let rotations = s.rotations.clone().unwrap_or_else(|| {
                vec![
                    crate::config::Axis::X,
                    crate::config::Axis::Y,
                    crate::config::Axis::Z,
                ]
            });
            for n in nodes {
                for ax in &s.fix {
                    fixed[6 * n as usize + ax.index()] = true;
                }
                for ax in &rotations {
                    fixed[6 * n as usize + 3 + ax.index()] = true;
                }
            }
        }
        let used = mesh.used_nodes();
        let quads = &mesh.shells.quads;
        let (dofs, pattern) =
            Pattern::for_elements(&mesh.nodes, ns, |e| &quads[e][..], &fixed, &used, 6)?;
        let lumped = matches!(
            cfg.analysis,
            Analysis::Dynamic {
                lumped_mass: true,
                ..
            }
        );
        let geometry = |e: usize| Geometry {
            x: quads[e].map(|n| mesh.nodes[n as usize]),
            director: quads[e].map(|n| directors[n as usize]),
            thickness: thickness[e],
        };
        let density = mat.density;
        let (k, m) = {
            let parts: Vec<(Box<shell::Stiffness>, Box<shell::Stiffness>)> = (0..ns)
                .into_par_iter()
                .map(|e| {
                    let g = geometry(e);
                    (
                        Box::new(shell::stiffness(&g, material)),
                        Box::new(shell::mass(&g, density, lumped)),
                    )
                })
                .collect();
            let mut k = vec![0.0; pattern.nnz()];
            let mut m = vec![0.0; pattern.nnz()];
            for (e, (ke, me)) in parts.iter().enumerate() {
                let eq: [u32; DOFS] =
                    std::array::from_fn(|a| dofs.eq[6 * quads[e][a / 6] as usize + a % 6]);
                for c in 0..DOFS {
                    if eq[c] == FIXED {
                        continue;
                    }
                    for r in 0..DOFS {
                        if eq[r] == FIXED {
                            continue;
                        }
                        let at = pattern.find(eq[r], eq[c]).expect("in the pattern");
                        k[at] += ke[r][c];
                        m[at] += me[r][c];
                    }
                }
            }
            (k, m)
        };
        let mut node_mass = vec![0.0; nn];
        for e in 0..ns {
            let me = shell::mass(&geometry(e), density, true);
            for (a, &n) in quads[e].iter().enumerate() {
                node_mass[n as usize] += me[6 * a][6 * a];
            }
        }

        // loads (full 6-dof patterns scaled by their histories)
        let mut loads = Vec::new();
        for (i, l) in cfg.loads.iter().enumerate() {
            let what = format!("fem.loads[{i}].on");
            let mut f = vec![0.0; nd];
            let history = match l {
                Load::Pressure { on, value, history } => {
                    // positive pressure pushes against the director (onto the top surface)
                    let elems = selected_shells(&mesh, on, &what)?;
                    for e in elems {
                        let g = geometry(e);
                        let nrm = corner_mean(&g.director);
                        let fe = shell::area_load(&g, nrm.map(|c| -value * c));
                        scatter(&mut f, &quads[e], &fe);
                    }
                    history
                }
                Load::Force {
                    on,
                    per_node,
                    total,
                    history,
                } => {
                    let nodes = select_nodes(&mesh, on, &what)?;
                    let per = crate::config::nodal_force(per_node, total, nodes.len());
                    for n in nodes {
                        for c in 0..3 {
                            f[6 * n as usize + c] += per[c];
                        }
                    }
                    history
                }
                Load::Gravity {
                    acceleration,
                    history,
                } => {
                    for e in 0..ns {
                        let g = geometry(e);
                        let q = acceleration.map(|a| density * g.thickness * a);
                        scatter(&mut f, &quads[e], &shell::area_load(&g, q));
                    }
                    history
                }
            };
            loads.push((history.clone(), f));
        }

        let iface = match &cfg.interface {
            Some(spec) => {
                let elems = selected_shells(&mesh, &spec.on, "fem.interface.on")?;
                ShellInterface::new(&mesh, &elems, spec.faces.unwrap_or_default())
            }
            None => ShellInterface::new(&mesh, &(0..ns).collect::<Vec<_>>(), ShellFaces::Both),
        };

        let probes = crate::output::thin_probes(
            &cfg.probes,
            &mesh,
            &used,
            quads.iter().map(|q| &q[..]),
            "shell",
        )?;

        let n_iface = iface.nodes.len();
        Ok(ShellModel {
            st: State {
                format: SNAPSHOT_FORMAT,
                time: 0.0,
                u: vec![0.0; nd],
                v: vec![0.0; nd],
                a: vec![0.0; nd],
                interface_forces: vec![0.0; 3 * n_iface],
                accel_ready: false,
                windows: 0,
                csv_started: false,
                newton_iterations: 0,
                newton_solves: 0,
                tangent_at: None,
            },
            mesh,
            thickness,
            directors,
            node_thickness,
            material,
            density,
            analysis: cfg.analysis.clone(),
            nonlinear: cfg.shell.as_ref().is_some_and(|s| s.nonlinear),
            newton: cfg.newton.clone(),
            last_newton: Vec::new(),
            dofs,
            pattern,
            k,
            m,
            node_mass,
            symbolic: None,
            lu_symbolic: None,
            kept: None,
            k_factor: None,
            eff_factor: None,
            m_factor: None,
            loads,
            histories: cfg.histories.clone(),
            iface,
            probes,
            output: cfg.output.clone(),
            vtu_files: Vec::new(),
        })
    }

    // ----------------------------------------------------------------------------------------
    // The adapter-facing API (as crate::Model's)
    // ----------------------------------------------------------------------------------------

    /// Number of degrees of freedom (6 per mesh node).
    pub fn num_dofs(&self) -> usize {
        6 * self.mesh.num_nodes()
    }

    pub fn num_equations(&self) -> usize {
        self.dofs.n_eq
    }

    pub fn time(&self) -> f64 {
        self.st.time
    }

    pub fn mesh(&self) -> &Mesh {
        &self.mesh
    }

    /// Full dof vector (u_x, u_y, u_z, θ_x, θ_y, θ_z per node) [m, rad].
    pub fn displacements(&self) -> &[f64] {
        &self.st.u
    }

    /// The mean unit normal (director) of each node.
    pub fn directors(&self) -> &[[f64; 3]] {
        &self.directors
    }

    /// The coupled reference surfaces in the reference configuration.
    pub fn interface_mesh(&self) -> InterfaceMesh {
        let max_id = self.mesh.node_ids.iter().copied().max().unwrap_or(0);
        let mut node_ids = Vec::with_capacity(self.iface.nodes.len());
        let mut positions = Vec::with_capacity(3 * self.iface.nodes.len());
        for (&n, &s) in self.iface.nodes.iter().zip(&self.iface.side) {
            let id = self.mesh.node_ids[n as usize];
            node_ids.push(if s > 0.0 { id } else { id + max_id });
            let (top, bottom) = self
                .surface_node(n as usize, false)
                .points(self.mesh.nodes[n as usize]);
            positions.extend(if s > 0.0 { top } else { bottom });
        }
        InterfaceMesh {
            node_ids,
            positions,
            triangles: self.iface.triangles.clone(),
            volume: None,
        }
    }

    /// The coupled shells' mid-surface area [m²] and area-weighted normal along their
    /// directors: the side a positive `pressure` load pushes against, whichever faces the
    /// grains see.
    pub fn pressure_surface(&self) -> (f64, [f64; 3]) {
        let both =
            self.iface.side.iter().any(|&s| s > 0.0) && self.iface.side.iter().any(|&s| s < 0.0);
        let mut tris = Vec::new();
        for t in self.iface.triangles.chunks_exact(3) {
            let side = self.iface.side[t[0] as usize];
            if both && side < 0.0 {
                continue;
            }
            let n: [u32; 3] = std::array::from_fn(|k| self.iface.nodes[t[k] as usize]);
            // bottom triangles run the other way round: back to the director's orientation
            tris.extend(if side > 0.0 {
                [n[0], n[1], n[2]]
            } else {
                [n[0], n[2], n[1]]
            });
        }
        crate::area_and_normal(&self.mesh.nodes, &tris)
    }

    /// A node as the coupling sees it, turned by its current rotation (`turned`) or not.
    fn surface_node(&self, n: usize, turned: bool) -> SurfaceNode {
        SurfaceNode {
            theta: if turned {
                part(&self.st.u, n, 3)
            } else {
                [0.0; 3]
            },
            director: self.directors[n],
            thickness: self.node_thickness[n],
        }
    }

    /// Nodal forces [N] on the interface nodes (flat xyz, interface node order), held until
    /// the next call.
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
                self.interface_mesh().node_ids[i / 3],
                i % 3
            )));
        }
        self.st.interface_forces.copy_from_slice(forces);
        Ok(())
    }

    pub fn held_interface_forces(&self) -> &[f64] {
        &self.st.interface_forces
    }

    /// Positions, velocities and accelerations of the interface nodes: the mid-surface node's
    /// plus the arm r = ± t/2 d along the turned director, v + ω × r, a + α × r + ω × (ω × r).
    pub fn interface_kinematics(&self) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let k = self.iface.nodes.len();
        let (mut p, mut v, mut a) = (
            Vec::with_capacity(3 * k),
            Vec::with_capacity(3 * k),
            Vec::with_capacity(3 * k),
        );
        for (&n, &s) in self.iface.nodes.iter().zip(&self.iface.side) {
            let n = n as usize;
            let node = self.surface_node(n, true);
            let x = self.mesh.nodes[n];
            let u = part(&self.st.u, n, 0);
            let pos = std::array::from_fn(|c| x[c] + u[c]);
            let (top, bottom) = node.points(pos);
            let here = if s > 0.0 { top } else { bottom };
            let r = sub(here, pos);
            let omega = part(&self.st.v, n, 3);
            let alpha = part(&self.st.a, n, 3);
            let wr = cross(omega, r);
            let (vn, an) = (part(&self.st.v, n, 0), part(&self.st.a, n, 0));
            let (ar, wwr) = (cross(alpha, r), cross(omega, wr));
            p.extend(here);
            v.extend((0..3).map(|c| vn[c] + wr[c]));
            a.extend((0..3).map(|c| an[c] + ar[c] + wwr[c]));
        }
        (p, v, a)
    }

    /// Advances by `dt`: a static solve at t + dt or one Bossak step.
    pub fn advance(&mut self, dt: f64) -> Result<(), FemError> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(FemError::TimeStep(dt));
        }
        match self.analysis {
            Analysis::Dynamic { .. } if self.nonlinear => self.bossak_with_cutbacks(dt, 0)?,
            Analysis::Dynamic { .. } => self.bossak_step(dt)?,
            _ => {
                self.st.time += dt;
                self.solve_static()?;
            }
        }
        Ok(())
    }

    /// K u = F(t) at the current time (loads and interface forces); nonlinear shells:
    /// f_int(u) = F(t) by Newton in `[fem.newton] increments` from the last solution's load.
    pub fn solve_static(&mut self) -> Result<(), FemError> {
        if self.nonlinear {
            return self.newton_static();
        }
        let mut rhs = self.dofs.gather(&self.external_forces(self.st.time));
        self.initial_factor(1.0, 0.0)?.solve_in_place(&mut rhs);
        check_finite(&rhs, "static displacement")?;
        self.dofs.scatter(&rhs, &mut self.st.u);
        self.st.v.fill(0.0);
        self.st.a.fill(0.0);
        self.st.accel_ready = false;
        Ok(())
    }

    /// The full external force vector at `t`: loads × histories, and the interface forces
    /// carried to the nodes as forces and moments (Ullrich (3.9)) with the reference directors
    /// (linear shells) or the turned ones (nonlinear).
    pub fn external_forces(&self, t: f64) -> Vec<f64> {
        let mut f = vec![0.0; self.num_dofs()];
        for (history, pattern) in &self.loads {
            let h = match history {
                Some(name) => self
                    .histories
                    .get(name)
                    .map_or(f64::NAN, |h| h.eval(t, &self.histories)),
                None => 1.0,
            };
            for (fi, p) in f.iter_mut().zip(pattern) {
                *fi += h * p;
            }
        }
        for (i, (&n, &s)) in self.iface.nodes.iter().zip(&self.iface.side).enumerate() {
            let fi = std::array::from_fn(|c| self.st.interface_forces[3 * i + c]);
            // linear shells: the arms of the reference configuration (the linear theory's
            // load; repeated static solves then do not drift), nonlinear: the turned ones
            let node = self.surface_node(n as usize, self.nonlinear);
            let (force, moment) = if s > 0.0 {
                node.forces_to_node(fi, [0.0; 3])
            } else {
                node.forces_to_node([0.0; 3], fi)
            };
            for c in 0..3 {
                f[6 * n as usize + c] += force[c];
                f[6 * n as usize + 3 + c] += moment[c];
            }
        }
        f
    }

    fn rayleigh(&self) -> (f64, f64) {
        match self.analysis {
            Analysis::Dynamic {
                rayleigh_a,
                rayleigh_b,
                ..
            } => (rayleigh_a, rayleigh_b),
            _ => (0.0, 0.0),
        }
    }

    /// α_B, γ = ½ − α_B, β = (1 − α_B)²/4 and the Rayleigh a, b of a dynamic analysis.
    fn bossak_constants(&self) -> (f64, f64, f64, f64, f64) {
        let Analysis::Dynamic { alpha_b, .. } = self.analysis else {
            unreachable!("dynamic analyses only")
        };
        let (ra, rb) = self.rayleigh();
        (
            alpha_b,
            0.5 - alpha_b,
            0.25 * (1.0 - alpha_b).powi(2),
            ra,
            rb,
        )
    }

    /// M a₀ = F(t₀) − f(u₀) − C v₀ at the start of dynamic stepping: f = K u, or the
    /// nonlinear shells' f_int(u); C = a M + b K.
    fn initial_acceleration(&mut self) -> Result<(), FemError> {
        let (ra, rb) = self.rayleigh();
        let n = self.dofs.n_eq;
        let v = self.dofs.gather(&self.st.v);
        let mut rhs = self.dofs.gather(&self.external_forces(self.st.time));
        let stiffness = if self.nonlinear {
            self.free_internal_forces(&self.st.u)
        } else {
            let mut ku = vec![0.0; n];
            self.pattern
                .mul(&self.k, &self.dofs.gather(&self.st.u), &mut ku);
            ku
        };
        let (mut mv, mut kv) = (vec![0.0; n], vec![0.0; n]);
        self.pattern.mul(&self.m, &v, &mut mv);
        self.pattern.mul(&self.k, &v, &mut kv);
        for i in 0..n {
            rhs[i] -= stiffness[i] + ra * mv[i] + rb * kv[i];
        }
        if self.m_factor.is_none() {
            self.m_factor = Some(Factor::new(&self.pattern, &self.m, &mut self.symbolic)?);
        }
        self.m_factor
            .as_ref()
            .expect("set")
            .solve_in_place(&mut rhs);
        self.dofs.scatter(&rhs, &mut self.st.a);
        self.st.accel_ready = true;
        Ok(())
    }

    /// One Wood–Bossak–Zienkiewicz step, as the volume model's (REFERENCE A6; (2.85)–(2.87)):
    /// M[(1−α_B) a_{n+1} + α_B a_n] + C v_{n+1} + K u_{n+1} = F_{n+1}, C = a M + b K.
    fn bossak_step(&mut self, dt: f64) -> Result<(), FemError> {
        let (alpha_b, gamma, beta, ra, rb) = self.bossak_constants();
        let n = self.dofs.n_eq;
        let u = self.dofs.gather(&self.st.u);
        let v = self.dofs.gather(&self.st.v);
        let mut tmp = vec![0.0; n];
        if !self.st.accel_ready {
            self.initial_acceleration()?;
        }
        let a = self.dofs.gather(&self.st.a);
        let cm = (1.0 - alpha_b) + gamma * dt * ra;
        let ck = gamma * dt * rb + beta * dt * dt;
        let ut: Vec<f64> = (0..n)
            .map(|i| u[i] + dt * v[i] + dt * dt * (0.5 - beta) * a[i])
            .collect();
        let vt: Vec<f64> = (0..n).map(|i| v[i] + dt * (1.0 - gamma) * a[i]).collect();
        let t1 = self.st.time + dt;
        let mut rhs = self.dofs.gather(&self.external_forces(t1));
        let w: Vec<f64> = (0..n).map(|i| alpha_b * a[i] + ra * vt[i]).collect();
        self.pattern.mul(&self.m, &w, &mut tmp);
        let w: Vec<f64> = (0..n).map(|i| rb * vt[i] + ut[i]).collect();
        let mut kw = vec![0.0; n];
        self.pattern.mul(&self.k, &w, &mut kw);
        for i in 0..n {
            rhs[i] -= tmp[i] + kw[i];
        }
        self.initial_factor(ck, cm)?.solve_in_place(&mut rhs);
        check_finite(&rhs, "Bossak acceleration")?;
        let a1 = rhs;
        let u1: Vec<f64> = (0..n).map(|i| ut[i] + beta * dt * dt * a1[i]).collect();
        let v1: Vec<f64> = (0..n).map(|i| vt[i] + gamma * dt * a1[i]).collect();
        self.dofs.scatter(&u1, &mut self.st.u);
        self.dofs.scatter(&v1, &mut self.st.v);
        self.dofs.scatter(&a1, &mut self.st.a);
        self.st.time = t1;
        Ok(())
    }

    /// The element's geometry in the reference configuration.
    fn geometry(&self, e: usize) -> Geometry {
        let q = self.mesh.shells.quads[e];
        Geometry {
            x: q.map(|n| self.mesh.nodes[n as usize]),
            director: q.map(|n| self.directors[n as usize]),
            thickness: self.thickness[e],
        }
    }

    /// The element's 24 dofs from a full vector.
    fn element_dofs(&self, e: usize, full: &[f64]) -> [f64; DOFS] {
        let q = self.mesh.shells.quads[e];
        std::array::from_fn(|a| full[6 * q[a / 6] as usize + a % 6])
    }

    /// f_int(u) of the nonlinear shells on the free equations (elements in parallel, their
    /// forces added in element order: the same sum for any thread count).
    fn free_internal_forces(&self, u: &[f64]) -> Vec<f64> {
        let fe: Vec<[f64; DOFS]> = (0..self.mesh.shells.len())
            .into_par_iter()
            .map(|e| {
                shell::internal_forces(&self.geometry(e), self.material, &self.element_dofs(e, u))
            })
            .collect();
        let mut full = vec![0.0; self.num_dofs()];
        for (e, f) in fe.iter().enumerate() {
            scatter(&mut full, &self.mesh.shells.quads[e], f);
        }
        self.dofs.gather(&full)
    }

    /// ck K_T(u) + cm M on the pattern (K_T by central differences of the element forces).
    fn tangent_values(&self, u: &[f64], ck: f64, cm: f64) -> Vec<f64> {
        let ke: Vec<shell::Stiffness> = (0..self.mesh.shells.len())
            .into_par_iter()
            .map(|e| shell::tangent(&self.geometry(e), self.material, &self.element_dofs(e, u)))
            .collect();
        let mut vals: Vec<f64> = self.m.iter().map(|m| cm * m).collect();
        for (e, k) in ke.iter().enumerate() {
            let q = self.mesh.shells.quads[e];
            let eq: [u32; DOFS] =
                std::array::from_fn(|a| self.dofs.eq[6 * q[a / 6] as usize + a % 6]);
            for c in 0..DOFS {
                if eq[c] == FIXED {
                    continue;
                }
                for r in 0..DOFS {
                    if eq[r] != FIXED {
                        vals[self.pattern.find(eq[r], eq[c]).expect("in the pattern")] +=
                            ck * k[r][c];
                    }
                }
            }
        }
        vals
    }

    /// Newton on f_int(u) = λ F(t) + (1 − λ) F_prev, λ over `increments` equal steps, each
    /// halved on failure up to `max_cutbacks` times; a tangent at the increment's start,
    /// renewed whenever an iteration cuts the residual by less than 4×.
    fn newton_static(&mut self) -> Result<(), FemError> {
        let f_end = self.dofs.gather(&self.external_forces(self.st.time));
        let u0 = self.dofs.gather(&self.st.u);
        let f_start = self.free_internal_forces(&self.st.u);
        let n_inc = self.newton.increments.max(1) as f64;
        let (mut lambda, mut step, mut cutbacks) = (0.0f64, 1.0 / n_inc, 0u32);
        self.last_newton.clear();
        let mut u = u0;
        while lambda < 1.0 - 1e-12 {
            let target = (lambda + step).min(1.0);
            let load: Vec<f64> = f_start
                .iter()
                .zip(&f_end)
                .map(|(a, b)| a + target * (b - a))
                .collect();
            match self.newton_solve(&u, &load, 1.0, 0.0, None) {
                Ok(next) => {
                    u = next;
                    lambda = target;
                    cutbacks = 0;
                    step = (2.0 * step).min(1.0 / n_inc);
                }
                Err(why) => {
                    cutbacks += 1;
                    if cutbacks > self.newton.max_cutbacks {
                        return Err(FemError::Solver(format!(
                            "Newton iterations of the shells did not converge at t = {} s: load \
                             factor {lambda:.4} → {target:.4} after {} cut-backs; {why}. Try more \
                             [fem.newton] increments or smaller load changes per window",
                            self.st.time, self.newton.max_cutbacks
                        )));
                    }
                    step *= 0.5;
                }
            }
        }
        self.dofs.scatter(&u, &mut self.st.u);
        self.st.v.fill(0.0);
        self.st.a.fill(0.0);
        self.st.accel_ready = false;
        Ok(())
    }

    /// Newton iterations from the free displacements `u` for f_int(u) + extra(u) = load with
    /// the Jacobian ck K_T + cm M (`extra` adds the inertia and damping terms of a dynamic
    /// step and its scale). Returns the converged u.
    fn newton_solve(
        &mut self,
        start: &[f64],
        load: &[f64],
        ck: f64,
        cm: f64,
        dynamic: Option<&BossakTerms>,
    ) -> Result<Vec<f64>, String> {
        // a tangent kept for other Jacobian coefficients (another step size) is dropped, with
        // the state it was taken at, so that a restored run decides alike
        if dynamic.is_some()
            && self
                .st
                .tangent_at
                .as_ref()
                .is_some_and(|(_, k, m)| *k != ck || *m != cm)
        {
            self.st.tangent_at = None;
            self.kept = None;
        }
        let tol = self.newton.force_tolerance;
        let mut u = start.to_vec();
        let mut full = self.st.u.clone();
        let mut tangent: Option<Tangent> = None;
        let mut last = f64::INFINITY;
        let load_norm = load.iter().map(|v| v * v).sum::<f64>().sqrt();
        for it in 0..self.newton.max_iterations {
            self.dofs.scatter(&u, &mut full);
            let fint = self.free_internal_forces(&full);
            let (extra_f, extra_scale) = match dynamic {
                Some(terms) => self.inertia(terms, &u),
                None => (vec![0.0; u.len()], 0.0),
            };
            let mut r: Vec<f64> = (0..u.len())
                .map(|i| load[i] - fint[i] - extra_f[i])
                .collect();
            let fint_norm = fint.iter().map(|v| v * v).sum::<f64>().sqrt();
            let scale = load_norm
                .max(fint_norm)
                .max(extra_scale)
                .max(f64::MIN_POSITIVE);
            let rn = r.iter().map(|v| v * v).sum::<f64>().sqrt() / scale;
            if !rn.is_finite() {
                return Err("non-finite residual".into());
            }
            self.last_newton.push(rn);
            self.st.newton_iterations += 1;
            if rn <= tol {
                self.st.newton_solves += 1;
                return Ok(u);
            }
            // statics: a tangent from the start; a Bossak step: the tangent kept from an
            // earlier step (or the initial stiffness) while it converges fast; then a tangent
            // here, renewed whenever an iteration cuts the residual by less than 4×
            if (it == 0 && dynamic.is_none()) || (it > 0 && rn > 0.25 * last) {
                let fresh = self.factor_tangent(&full, ck, cm)?;
                if dynamic.is_some() {
                    self.kept = Some(fresh);
                    self.st.tangent_at = Some((full.clone(), ck, cm));
                } else {
                    tangent = Some(fresh);
                }
            }
            last = rn;
            if dynamic.is_some() && self.kept.is_none() {
                self.restore_kept(ck, cm)?;
            }
            match tangent.as_ref().or(if dynamic.is_some() {
                self.kept.as_ref()
            } else {
                None
            }) {
                Some(t) => t.solve_in_place(&mut r),
                None => self
                    .initial_factor(ck, cm)
                    .map_err(|e| e.to_string())?
                    .solve_in_place(&mut r),
            }
            if r.iter().any(|v| !v.is_finite()) {
                return Err("non-finite correction (singular tangent)".into());
            }
            for (ui, d) in u.iter_mut().zip(&r) {
                *ui += d;
            }
        }
        Err(format!(
            "no convergence in {} iterations (relative residual {last:.2e}, tolerance {tol:.0e})",
            self.newton.max_iterations
        ))
    }

    /// A factor of ck K_T(u) + cm M: Cholesky, or LU where an iterate off the equilibrium
    /// path has an indefinite tangent.
    fn factor_tangent(&mut self, full: &[f64], ck: f64, cm: f64) -> Result<Tangent, String> {
        let vals = self.tangent_values(full, ck, cm);
        Ok(
            match Factor::new(&self.pattern, &vals, &mut self.symbolic) {
                Ok(f) => Tangent::Cholesky(f),
                Err(_) => Tangent::Lu(Box::new(
                    LuFactor::new(&self.pattern, &vals, &mut self.lu_symbolic)
                        .map_err(|e| format!("tangent: {e}"))?,
                )),
            },
        )
    }

    /// Rebuilds the kept tangent from the state it was taken at (after a restore: so that a
    /// resumed run iterates as the uninterrupted one), if it was taken for these coefficients.
    fn restore_kept(&mut self, ck: f64, cm: f64) -> Result<(), String> {
        if let Some((u, k, m)) = self.st.tangent_at.clone() {
            debug_assert!(k == ck && m == cm, "dropped by newton_solve");
            self.kept = Some(self.factor_tangent(&u, ck, cm)?);
        }
        Ok(())
    }

    /// The cached factor of ck K₀ + cm M: K for statics (kept apart), the Bossak matrix of a
    /// step size (linear steps, and the nonlinear steps' start).
    fn initial_factor(&mut self, ck: f64, cm: f64) -> Result<&Factor, FemError> {
        if cm == 0.0 && ck == 1.0 {
            if self.k_factor.is_none() {
                self.k_factor = Some(Factor::new(&self.pattern, &self.k, &mut self.symbolic)?);
            }
            return Ok(self.k_factor.as_ref().expect("set"));
        }
        let key = (ck.to_bits(), cm.to_bits());
        if self.eff_factor.as_ref().map(|(bits, _)| *bits) != Some(key) {
            let vals: Vec<f64> = self
                .k
                .iter()
                .zip(&self.m)
                .map(|(k, m)| ck * k + cm * m)
                .collect();
            self.eff_factor = None;
            self.eff_factor = Some((key, Factor::new(&self.pattern, &vals, &mut self.symbolic)?));
        }
        Ok(&self.eff_factor.as_ref().expect("set").1)
    }

    /// One Bossak step of the nonlinear shells: Newton on u_{n+1} (a_{n+1}, v_{n+1} follow
    /// from the Newmark updates) for
    /// M[(1−α_B) a_{n+1} + α_B a_n] + C v_{n+1} + f_int(u_{n+1}) = F_{n+1}, C = a M + b K₀,
    /// Jacobian (1−α_B)/(βΔt²) M + γ/(βΔt) C + K_T (the step's one, scaled).
    fn bossak_nonlinear(&mut self, dt: f64) -> Result<(), FemError> {
        let (alpha_b, gamma, beta, ra, rb) = self.bossak_constants();
        let n = self.dofs.n_eq;
        if !self.st.accel_ready {
            self.initial_acceleration()?;
        }
        let u = self.dofs.gather(&self.st.u);
        let v = self.dofs.gather(&self.st.v);
        let a = self.dofs.gather(&self.st.a);
        let ut: Vec<f64> = (0..n)
            .map(|i| u[i] + dt * v[i] + dt * dt * (0.5 - beta) * a[i])
            .collect();
        let vt: Vec<f64> = (0..n).map(|i| v[i] + dt * (1.0 - gamma) * a[i]).collect();
        let t1 = self.st.time + dt;
        let load = self.dofs.gather(&self.external_forces(t1));
        let terms = BossakTerms {
            ut,
            vt,
            a,
            alpha_b,
            beta,
            gamma,
            dt,
            ra,
            rb,
        };
        let cm = ((1.0 - alpha_b) + gamma * dt * ra) / (beta * dt * dt);
        // the damping's b K₀ enters the Jacobian with K₀: folded into ck (K_T ≈ K₀ there)
        let ck = 1.0 + gamma * rb / (beta * dt);
        self.last_newton.clear();
        let start = terms.ut.clone();
        let u1 = self
            .newton_solve(&start, &load, ck, cm, Some(&terms))
            .map_err(|why| {
                FemError::Solver(format!(
                    "Newton iterations of the shells' Bossak step did not converge at t = {t1} s \
                     (Δt = {dt} s); {why}. Try a shorter step or more [fem.newton] max_iterations"
                ))
            })?;
        let (a1, v1) = terms.rates(&u1);
        check_finite(&u1, "Bossak displacement")?;
        self.dofs.scatter(&u1, &mut self.st.u);
        self.dofs.scatter(&v1, &mut self.st.v);
        self.dofs.scatter(&a1, &mut self.st.a);
        self.st.time = t1;
        Ok(())
    }

    /// The inertia and damping forces M[(1−α_B) a + α_B a_n] + C v of a Bossak step at the
    /// free displacements `x`, and their norm.
    fn inertia(&self, t: &BossakTerms, x: &[f64]) -> (Vec<f64>, f64) {
        let n = x.len();
        let (a1, v1) = t.rates(x);
        let mix: Vec<f64> = (0..n)
            .map(|i| (1.0 - t.alpha_b) * a1[i] + t.alpha_b * t.a[i] + t.ra * v1[i])
            .collect();
        let (mut ma, mut kv) = (vec![0.0; n], vec![0.0; n]);
        self.pattern.mul(&self.m, &mix, &mut ma);
        if t.rb != 0.0 {
            self.pattern.mul(&self.k, &v1, &mut kv);
        }
        let f: Vec<f64> = (0..n).map(|i| ma[i] + t.rb * kv[i]).collect();
        let norm = f.iter().map(|v| v * v).sum::<f64>().sqrt();
        (f, norm)
    }

    /// A nonlinear Bossak step; when its iterations fail, from the same state as two half
    /// steps, each of which may be halved again, up to `[fem.newton] max_cutbacks` levels.
    fn bossak_with_cutbacks(&mut self, dt: f64, level: u32) -> Result<(), FemError> {
        let saved = self.st.clone();
        match self.bossak_nonlinear(dt) {
            Ok(()) => Ok(()),
            Err(e) if level < self.newton.max_cutbacks => {
                tracing::debug!("{e}; halving the step");
                self.st = saved;
                // the kept factor may be the failed attempt's: rebuilt from the state's record
                self.kept = None;
                self.bossak_with_cutbacks(0.5 * dt, level + 1)?;
                self.bossak_with_cutbacks(0.5 * dt, level + 1)
            }
            Err(FemError::Solver(m)) if level > 0 => Err(FemError::Solver(format!(
                "{m} (after halving the step {level} times)"
            ))),
            Err(e) => Err(e),
        }
    }

    /// Relative residuals of the Newton iterations of the last nonlinear solve or step.
    pub fn last_newton_residuals(&self) -> &[f64] {
        &self.last_newton
    }

    /// Total mass ρ t A [kg].
    pub fn total_mass(&self) -> f64 {
        self.node_mass.iter().sum()
    }

    /// Highest natural frequency [Hz] with the analysis' mass (Lanczos on M⁻¹K).
    pub fn highest_frequency_hz(&mut self) -> Result<Option<f64>, FemError> {
        let n = self.dofs.n_eq;
        if n == 0 {
            return Ok(None);
        }
        if self.m_factor.is_none() {
            self.m_factor = Some(Factor::new(&self.pattern, &self.m, &mut self.symbolic)?);
        }
        let mf = self.m_factor.as_ref().expect("set");
        let lam = numeric::lanczos_largest(
            n,
            |x, y| {
                self.pattern.mul(&self.k, x, y);
                mf.solve_in_place(y);
            },
            |x, y| self.pattern.mul(&self.m, x, y),
            false,
            300,
            1e-8,
        );
        Ok(Some(lam.max(0.0).sqrt() / (2.0 * std::f64::consts::PI)))
    }

    /// Lowest natural frequency [Hz] (Lanczos on K⁻¹M); None when K is singular or nothing is
    /// free.
    pub fn lowest_frequency_hz(&mut self) -> Result<Option<f64>, FemError> {
        if self.dofs.n_eq == 0 {
            return Ok(None);
        }
        if self.k_factor.is_none() {
            self.k_factor = Some(Factor::new(&self.pattern, &self.k, &mut self.symbolic)?);
        }
        let kf = self.k_factor.as_ref().expect("set");
        let theta = numeric::lanczos_largest(
            self.dofs.n_eq,
            |x, y| {
                y.copy_from_slice(x);
                kf.solve_in_place(y);
            },
            |x, y| self.pattern.mul(&self.m, x, y),
            true,
            80,
            1e-10,
        );
        Ok((theta > 0.0).then(|| (1.0 / theta).sqrt() / (2.0 * std::f64::consts::PI)))
    }

    /// The figures of the coordinator's up-front checks (keys as [`crate::Model::limits`]).
    pub fn limits(&mut self) -> Result<BTreeMap<String, f64>, FemError> {
        let mut l = BTreeMap::from([
            ("dofs".to_string(), self.num_dofs() as f64),
            ("structure_mass".to_string(), self.total_mass()),
            ("interface_nodes".to_string(), self.iface.nodes.len() as f64),
            ("explicit".to_string(), 0.0),
        ]);
        let masses: Vec<f64> = self
            .iface
            .nodes
            .iter()
            .map(|&n| self.node_mass[n as usize])
            .collect();
        crate::insert_mass_limits(&mut l, &masses);
        if matches!(self.analysis, Analysis::Dynamic { .. }) {
            if let Some(f) = self.highest_frequency_hz()? {
                l.insert("highest_frequency_hz".to_string(), f);
            }
            if let Ok(Some(f)) = self.lowest_frequency_hz() {
                l.insert("lowest_frequency_hz".to_string(), f);
            }
        }
        Ok(l)
    }

    pub fn warnings(&self) -> Vec<String> {
        Vec::new()
    }

    /// MessagePack bytes of the time-dependent state.
    pub fn snapshot(&self) -> Vec<u8> {
        rmp_serde::to_vec(&self.st).expect("state serialises")
    }

    /// Restores a `snapshot` of a model built from the same scene; continuation is bitwise.
    pub fn restore(&mut self, bytes: &[u8]) -> Result<(), FemError> {
        let st: State = crate::decode_state(bytes, |s: &State| s.format, SNAPSHOT_FORMAT)?;
        let nd = self.num_dofs();
        if [st.u.len(), st.v.len(), st.a.len()] != [nd; 3]
            || st.interface_forces.len() != self.st.interface_forces.len()
            || st
                .tangent_at
                .as_ref()
                .is_some_and(|(u, _, _)| u.len() != nd)
        {
            return Err(FemError::Snapshot(format!(
                "snapshot has {} dofs / {} interface values, the shell model {nd} / {}",
                st.u.len(),
                st.interface_forces.len(),
                self.st.interface_forces.len()
            )));
        }
        self.st = st;
        self.kept = None;
        Ok(())
    }

    /// After each window: probe rows to `fem_probes.csv` and `fem_<window>.vtu` (+ `fem.pvd`)
    /// every `output.vtu_every` windows.
    pub fn write_outputs(&mut self, out_dir: &Path) -> Result<(), FemError> {
        let io = output::io_error;
        output::create_dir(out_dir)?;
        self.st.windows += 1;
        if self.output.csv && !self.probes.is_empty() {
            let path = out_dir.join("fem_probes.csv");
            let mut text = String::new();
            if !self.st.csv_started {
                text.push_str("time");
                output::probe_header(&mut text, &self.probes);
                text.push('\n');
            }
            text.push_str(&format!("{:.9e}", self.st.time));
            output::probe_row(&mut text, &self.probes, &self.st.u, 6);
            text.push('\n');
            output::append(&path, &text, !self.st.csv_started).map_err(|e| io(e, &path))?;
            self.st.csv_started = true;
        }
        if self.output.vtu_every > 0 && self.st.windows % self.output.vtu_every == 0 {
            let name = format!("fem_{:06}.vtu", self.st.windows);
            let path = out_dir.join(&name);
            let pick = |v: &[f64], at: usize| -> Vec<f64> {
                v.chunks_exact(6)
                    .flat_map(|c| [c[at], c[at + 1], c[at + 2]])
                    .collect()
            };
            let stresses = self.surface_stresses();
            let top: Vec<f64> = stresses.iter().map(|s| shell::von_mises(&s[0])).collect();
            let bottom: Vec<f64> = stresses.iter().map(|s| shell::von_mises(&s[1])).collect();
            let conn: Vec<u32> = self.mesh.shells.quads.iter().flatten().copied().collect();
            let directors: Vec<f64> = self.directors.iter().flatten().copied().collect();
            output::write_cells(
                &path,
                &self.mesh.nodes,
                &conn,
                4,
                output::VTK_QUAD,
                &[
                    ("displacement", &pick(&self.st.u, 0)),
                    ("velocity", &pick(&self.st.v, 0)),
                    ("rotation", &pick(&self.st.u, 3)),
                    ("director", &directors),
                ],
                &[
                    ("von_mises_top", &top),
                    ("von_mises_bottom", &bottom),
                    ("thickness", &self.thickness),
                ],
            )
            .map_err(|e| io(e, &path))?;
            output::add_to_series(out_dir, &mut self.vtu_files, self.st.time, name)?;
        }
        Ok(())
    }

    /// Result quantities for `summary.json`.
    pub fn results(&self) -> Vec<(String, f64)> {
        let mut r = vec![
            ("dofs".to_string(), self.num_dofs() as f64),
            ("free_dofs".to_string(), self.dofs.n_eq as f64),
            ("elements".to_string(), self.mesh.shells.len() as f64),
            ("time".to_string(), self.st.time),
        ];
        output::probe_results(&mut r, &self.probes, &self.st.u, 6);
        output::interface_force_results(&mut r, &self.st.interface_forces);
        let umax = (0..self.mesh.num_nodes())
            .map(|n| norm(part(&self.st.u, n, 0)))
            .fold(0.0, f64::max);
        r.push(("max_displacement".to_string(), umax));
        let vm = self
            .surface_stresses()
            .iter()
            .flat_map(|s| s.iter().map(shell::von_mises))
            .fold(0.0, f64::max);
        r.push(("max_von_mises".to_string(), vm));
        if self.nonlinear && self.st.newton_solves > 0 {
            r.push((
                "newton_iterations_per_solve".to_string(),
                self.st.newton_iterations as f64 / self.st.newton_solves as f64,
            ));
        }
        r
    }

    /// Per shell, the stresses (σ11, σ22, σ12, τ13, τ23) [Pa] at its centre on the top and
    /// bottom surfaces, in its local frame (e1 along its first edge's direction, e3 normal).
    pub fn surface_stresses(&self) -> Vec<[[f64; 5]; 2]> {
        (0..self.mesh.shells.len())
            .into_par_iter()
            .map(|e| {
                shell::surface_stresses(
                    &self.geometry(e),
                    self.material,
                    &self.element_dofs(e, &self.st.u),
                    self.nonlinear,
                )
            })
            .collect()
    }

    /// Displacement of a probe by name.
    pub fn probe_displacement(&self, name: &str) -> Option<[f64; 3]> {
        let &(_, n) = self.probes.iter().find(|(p, _)| p == name)?;
        Some(part(&self.st.u, n as usize, 0))
    }

    /// Strain energy ½ uᵀ K u of the free dofs [J].
    pub fn strain_energy(&self) -> f64 {
        let u = self.dofs.gather(&self.st.u);
        let mut ku = vec![0.0; u.len()];
        self.pattern.mul(&self.k, &u, &mut ku);
        0.5 * u.iter().zip(&ku).map(|(a, b)| a * b).sum::<f64>()
    }

    /// Kinetic energy ½ vᵀ M v [J].
    pub fn kinetic_energy(&self) -> f64 {
        let v = self.dofs.gather(&self.st.v);
        let mut mv = vec![0.0; v.len()];
        self.pattern.mul(&self.m, &v, &mut mv);
        0.5 * v.iter().zip(&mv).map(|(a, b)| a * b).sum::<f64>()
    }

    /// Sets the initial displacement and velocity (full 6-dof vectors); fixed dofs stay 0.
    pub fn set_initial_conditions(&mut self, u0: &[f64], v0: &[f64]) -> Result<(), FemError> {
        let nd = self.num_dofs();
        if u0.len() != nd || v0.len() != nd {
            return Err(FemError::Snapshot(format!(
                "initial conditions need {nd} values each, got {} and {}",
                u0.len(),
                v0.len()
            )));
        }
        self.dofs.scatter(&self.dofs.gather(u0), &mut self.st.u);
        self.dofs.scatter(&self.dofs.gather(v0), &mut self.st.v);
        self.st.accel_ready = false;
        Ok(())
    }

    /// The density and material the shells were built with.
    pub fn material(&self) -> (shell::Material, f64) {
        (self.material, self.density)
    }
}

/// A factor of a Newton iteration's tangent.
enum Tangent {
    Cholesky(Factor),
    Lu(Box<LuFactor>),
}

impl Tangent {
    fn solve_in_place(&self, b: &mut [f64]) {
        match self {
            Tangent::Cholesky(f) => f.solve_in_place(b),
            Tangent::Lu(f) => f.solve_in_place(b),
        }
    }
}

/// A Bossak step's predictors and constants (the free equations).
struct BossakTerms {
    ut: Vec<f64>,
    vt: Vec<f64>,
    a: Vec<f64>,
    alpha_b: f64,
    beta: f64,
    gamma: f64,
    dt: f64,
    ra: f64,
    rb: f64,
}

impl BossakTerms {
    /// a_{n+1} = (u − ũ)/(βΔt²) and v_{n+1} = ṽ + γΔt a_{n+1} at the displacements u.
    fn rates(&self, u: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let h2 = self.beta * self.dt * self.dt;
        let a: Vec<f64> = u.iter().zip(&self.ut).map(|(x, p)| (x - p) / h2).collect();
        let v = self
            .vt
            .iter()
            .zip(&a)
            .map(|(p, q)| p + self.gamma * self.dt * q)
            .collect();
        (a, v)
    }
}

impl ShellInterface {
    fn new(mesh: &Mesh, elems: &[usize], faces: ShellFaces) -> ShellInterface {
        let mut out = ShellInterface::default();
        let sides: &[f64] = match faces {
            ShellFaces::Top => &[1.0],
            ShellFaces::Bottom => &[-1.0],
            ShellFaces::Both => &[1.0, -1.0],
        };
        let mut used: Vec<u32> = elems.iter().flat_map(|&e| mesh.shells.quads[e]).collect();
        used.sort_unstable();
        used.dedup();
        let mut local = vec![u32::MAX; mesh.num_nodes()];
        for &side in sides {
            let base = out.nodes.len() as u32;
            for (i, &n) in used.iter().enumerate() {
                local[n as usize] = base + i as u32;
                out.nodes.push(n);
                out.side.push(side);
            }
            for &e in elems {
                let q = mesh.shells.quads[e].map(|n| local[n as usize]);
                // counter-clockwise about the director: the top faces away along +d, the
                // bottom (reversed) along −d
                let tris = if side > 0.0 {
                    [q[0], q[1], q[2], q[0], q[2], q[3]]
                } else {
                    [q[0], q[2], q[1], q[0], q[3], q[2]]
                };
                out.triangles.extend(tris);
            }
        }
        out
    }
}

/// The surface elements (shells or membranes) whose corners are all selected.
pub(crate) fn selected_shells(
    mesh: &Mesh,
    sel: &crate::config::Selector,
    what: &str,
) -> Result<Vec<usize>, FemError> {
    if let Some(set) = sel.set.as_deref().and_then(|s| mesh.shells.set(s)) {
        return Ok(set.iter().map(|&e| e as usize).collect());
    }
    let nodes = select_nodes(mesh, sel, what)?;
    let mut mark = vec![false; mesh.num_nodes()];
    for n in nodes {
        mark[n as usize] = true;
    }
    let out: Vec<usize> = (0..mesh.shells.len())
        .filter(|&e| mesh.shells.corners(e).iter().all(|&n| mark[n as usize]))
        .collect();
    if out.is_empty() {
        return Err(FemError::Selection(format!(
            "{what}: selects no whole element of {} (all its corners must be selected)",
            mesh.source
        )));
    }
    Ok(out)
}

/// The unit mean of four directors.
fn corner_mean(d: &[[f64; 3]; 4]) -> [f64; 3] {
    let s: [f64; 3] = std::array::from_fn(|c| d.iter().map(|v| v[c]).sum::<f64>());
    let l = norm(s);
    s.map(|c| c / l)
}

/// Adds an element vector (24) into a full 6-dof vector.
fn scatter(f: &mut [f64], quad: &[u32; 4], fe: &[f64; DOFS]) {
    for a in 0..DOFS {
        f[6 * quad[a / 6] as usize + a % 6] += fe[a];
    }
}

fn check_finite(v: &[f64], what: &str) -> Result<(), FemError> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(FemError::NonFinite(what.into()))
    }
}
