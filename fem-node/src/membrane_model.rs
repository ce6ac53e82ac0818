//! A structure of finite-strain membranes ([`crate::membrane`]: Gruttmann–Taylor kinematics,
//! incompressible Ogden law) behind the node-facing API of [`crate::Model`]: three
//! translations per node, explicit central differences with lumped mass (as Wellmann runs
//! the membrane of his triaxial test, ch. 4.3.4 with (2.53)–(2.56)), follower pressure on the
//! deformed surface, supports that may move by a history, and the coupling of the nodes'
//! kinematics and forces (Wellmann (4.3)–(4.4) on the DEM side).
//!
//! A membrane has no bending stiffness: a flat, unstressed one has no stiffness across its
//! plane at all, so it is stepped explicitly (never solved statically). Each coupling window
//! is split into equal substeps no longer than `safety` × the critical step, re-estimated at
//! the start of every window from the current stretches ([`crate::membrane::wave_speed`]).
//!
//! The DEM sees the mid-surface (the membrane's thickness is not offset) from the side
//! `[fem.interface] faces` names: `top` (the side the corner order's normal points to) or
//! `bottom`; the triangles are oriented towards that side, which is what the DEM's
//! concave/convex patch test reads.

use crate::config::{Analysis, FemConfig, Load, MeshSpec, Output, ShellFaces};
use crate::history::History;
use crate::membrane::{self, Ogden};
use crate::mesh::{cylinder_mesh, Mesh};
use crate::output;
use crate::shell_model::selected_shells;
use crate::surface::select_nodes;
use crate::{FemError, InterfaceMesh};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

const SNAPSHOT_FORMAT: u32 = 1;
const VTK_TRIANGLE: u8 = 5;

/// Everything that evolves in time; `snapshot` / `restore` serialise exactly this.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct State {
    format: u32,
    time: f64,
    /// Displacements, velocities, accelerations (3 per node).
    u: Vec<f64>,
    v: Vec<f64>,
    a: Vec<f64>,
    interface_forces: Vec<f64>,
    accel_ready: bool,
    windows: u64,
    substeps: u64,
    csv_started: bool,
}

/// A prescribed displacement component: node, component, amplitude [m], history.
#[derive(Clone, Debug)]
struct Prescribed {
    node: u32,
    comp: usize,
    amplitude: f64,
    history: Option<String>,
}

/// A driven support component: dof, velocity [m/s], start time [s].
#[derive(Clone, Debug)]
struct Drive {
    velocity: f64,
    start: f64,
}

/// A model of membranes ready to be stepped.
pub struct MembraneModel {
    mesh: Mesh,
    /// Corners of each element (3 or 4 node indices).
    elems: Vec<Vec<u32>>,
    /// Reference thickness of each element [m] (the mesh file's section, else the scene's).
    thickness: Vec<f64>,
    density: f64,
    law: Ogden,
    safety: f64,
    /// Mass-proportional damping C = a M [1/s].
    damping: f64,
    node_mass: Vec<f64>,
    /// Per dof: held (fixed or prescribed).
    held: Vec<bool>,
    prescribed: Vec<Prescribed>,
    /// Per dof: its drive (free before the start, then moving at the velocity).
    drives: Vec<Option<Drive>>,
    /// Follower pressures: elements, value [Pa], history.
    pressures: Vec<(Vec<usize>, f64, Option<String>)>,
    /// Dead loads (forces, gravity) as full vectors scaled by their histories.
    loads: Vec<(Option<String>, Vec<f64>)>,
    histories: BTreeMap<String, History>,
    /// Interface: membrane nodes and triangles over them (interface indices), oriented
    /// towards the side the DEM sees.
    iface_nodes: Vec<u32>,
    iface_triangles: Vec<u32>,
    /// Triangles over mesh nodes in the corner order's orientation (the pressure side).
    normal_triangles: Vec<u32>,
    /// Bottom centre of a generated cylinder: the enclosed volume is reported about its axis.
    cylinder_centre: Option<[f64; 3]>,
    probes: Vec<(String, u32)>,
    output: Output,
    vtu_files: Vec<(f64, String)>,
    st: State,
}

fn config(field: &str, message: impl Into<String>) -> FemError {
    FemError::Config {
        field: field.to_string(),
        message: message.into(),
    }
}

fn norm(a: [f64; 3]) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

impl MembraneModel {
    /// Whether a scene's `[fem]` table describes a membrane structure.
    pub fn is_membrane(cfg: &FemConfig) -> bool {
        cfg.membrane.is_some()
    }

    /// Builds the model of a scene's `[fem]` table with `[fem.membrane]`: a generated
    /// cylinder, or a mesh file of quadrilaterals without volume elements.
    pub fn from_config(cfg: &FemConfig, base_dir: &Path) -> Result<MembraneModel, FemError> {
        cfg.validate()
            .map_err(|(field, message)| FemError::Config { field, message })?;
        match &cfg.mesh {
            MeshSpec::Cylinder {
                radius,
                height,
                origin,
                divisions,
                triangles,
            } => {
                let mesh = cylinder_mesh(*origin, *radius, *height, *divisions);
                MembraneModel::from_mesh(cfg, mesh, *triangles, Some(*origin))
            }
            MeshSpec::File { path, .. } => {
                let mesh = Mesh::read(&base_dir.join(path))?;
                if !mesh.kinds.is_empty() {
                    return Err(FemError::Mesh {
                        file: mesh.source.clone(),
                        line: 0,
                        message: "has volume elements; a membrane mesh has only surface \
                                  elements (Gmsh quadrangles and triangles, Abaqus M3D4/M3D3, \
                                  S4/S3)"
                            .into(),
                    });
                }
                MembraneModel::from_mesh(cfg, mesh, false, None)
            }
            _ => Err(config(
                "fem.mesh",
                "a membrane is a generated cylinder (element = \"m3d4\" / \"m3d3\") or a mesh \
                 file of quadrilaterals and triangles",
            )),
        }
    }

    /// Builds the model on a mesh of quadrilaterals and triangles (`triangles`: each
    /// quadrilateral split in two).
    pub fn from_mesh(
        cfg: &FemConfig,
        mesh: Mesh,
        triangles: bool,
        cylinder_centre: Option<[f64; 3]>,
    ) -> Result<MembraneModel, FemError> {
        if cfg.overlap.is_some() {
            return Err(config(
                "fem.overlap",
                "a volume overlap with particles needs volume elements, not membranes",
            ));
        }
        let sec = cfg
            .membrane
            .as_ref()
            .ok_or_else(|| config("fem.membrane", "missing"))?;
        let mesh_err = |line: usize, message: String| FemError::Mesh {
            file: mesh.source.clone(),
            line,
            message,
        };
        if let Some(&(id, line, what)) = mesh.shells.unsupported.first() {
            return Err(mesh_err(line, format!("element {id} is {what}")));
        }
        if mesh.shells.is_empty() {
            return Err(mesh_err(
                0,
                "no surface elements (quadrilaterals or triangles)".into(),
            ));
        }
        let (safety, damping) = match cfg.analysis {
            Analysis::Explicit {
                safety,
                rayleigh_a,
                rayleigh_b,
            } => {
                if rayleigh_b != 0.0 {
                    return Err(config(
                        "fem.analysis.rayleigh_b",
                        "membranes take mass-proportional damping only (rayleigh_a)",
                    ));
                }
                (safety, rayleigh_a)
            }
            _ => {
                return Err(config(
                    "fem.analysis",
                    "a membrane steps explicitly (central differences, lumped mass): give \
                     analysis = \"explicit\" (a membrane has no stiffness across its plane \
                     until it is stretched, so it is not solved statically)",
                ))
            }
        };
        for (given, field) in [
            (cfg.shell.is_some(), "fem.shell"),
            (!cfg.strain_gauges.is_empty(), "fem.strain_gauges"),
            (
                cfg.newton != crate::config::NewtonConfig::default(),
                "fem.newton",
            ),
            (
                cfg.solver != crate::config::LinearSolver::Auto,
                "fem.solver",
            ),
        ] {
            if given {
                return Err(config(
                    field,
                    "does not apply to a membrane (explicit, no solver)",
                ));
            }
        }
        // elements, refusing degenerate ones
        let mut elems = Vec::new();
        let mut lines = Vec::new();
        let mut ids = Vec::new();
        let section_thickness = mesh.shells.thicknesses(
            sec.thickness,
            "fem.membrane.thickness",
            "*MEMBRANE SECTION",
            &mesh.source,
        )?;
        let mut thickness = Vec::new();
        // the membranes made from each mesh element
        let mut parts_of = Vec::with_capacity(mesh.shells.len());
        for e in 0..mesh.shells.len() {
            let q = mesh.shells.corners(e);
            let parts: Vec<Vec<u32>> = if triangles && q.len() == 4 {
                vec![vec![q[0], q[1], q[2]], vec![q[0], q[2], q[3]]]
            } else {
                vec![q.to_vec()]
            };
            let t = section_thickness[e];
            let first = elems.len();
            for p in parts {
                let x: Vec<[f64; 3]> = p.iter().map(|&n| mesh.nodes[n as usize]).collect();
                let area: f64 = membrane::corner_areas(&x).iter().sum();
                let edge = (0..x.len())
                    .map(|k| norm(sub(x[(k + 1) % x.len()], x[k])))
                    .fold(0.0, f64::max);
                if !(area > 1e-10 * edge * edge) {
                    return Err(mesh_err(
                        mesh.shells.lines[e],
                        format!("element {} is degenerate (no area)", mesh.shells.ids[e]),
                    ));
                }
                elems.push(p);
                lines.push(mesh.shells.lines[e]);
                ids.push(mesh.shells.ids[e]);
                thickness.push(t);
            }
            parts_of.push(first..elems.len());
        }
        let nn = mesh.num_nodes();
        // orientation: every integration point's normal on its element's side, and every
        // element facing the same side as its neighbours at a shared node (a bow-tie or an
        // element numbered the other way round would take pressure and grains on the wrong
        // side)
        let mut node_normal = vec![[0.0; 3]; nn];
        let mut elem_normal = Vec::with_capacity(elems.len());
        for (e, p) in elems.iter().enumerate() {
            let x: Vec<[f64; 3]> = p.iter().map(|&n| mesh.nodes[n as usize]).collect();
            let normals = membrane::point_normals(&x);
            let mean = normals
                .iter()
                .fold([0.0; 3], |a, n| [a[0] + n[0], a[1] + n[1], a[2] + n[2]]);
            if normals.iter().any(|n| dot(*n, mean) <= 0.0) {
                return Err(mesh_err(
                    lines[e],
                    format!(
                        "element {} is folded over itself (its corners cross)",
                        ids[e]
                    ),
                ));
            }
            for &n in p {
                for c in 0..3 {
                    node_normal[n as usize][c] += mean[c];
                }
            }
            elem_normal.push(mean);
        }
        for (e, p) in elems.iter().enumerate() {
            for &n in p {
                if dot(elem_normal[e], node_normal[n as usize]) < 0.0 {
                    return Err(mesh_err(
                        lines[e],
                        format!(
                            "element {} faces the other way from its neighbours at node {}: \
                             number the corners of every element counter-clockwise about the \
                             same side",
                            ids[e], mesh.node_ids[n as usize]
                        ),
                    ));
                }
            }
        }
        let mut node_mass = vec![0.0; nn];
        let mut used = vec![false; nn];
        for (p, t) in elems.iter().zip(&thickness) {
            let x: Vec<[f64; 3]> = p.iter().map(|&n| mesh.nodes[n as usize]).collect();
            for (&n, a) in p.iter().zip(membrane::corner_areas(&x)) {
                node_mass[n as usize] += sec.density * t * a;
                used[n as usize] = true;
            }
        }
        // supports
        let mut held = vec![false; 3 * nn];
        for n in 0..nn {
            if !used[n] {
                held[3 * n..3 * n + 3].fill(true);
            }
        }
        let mut prescribed = Vec::new();
        let mut drives: Vec<Option<Drive>> = vec![None; 3 * nn];
        for (i, s) in cfg.supports.iter().enumerate() {
            if s.name.is_some() {
                return Err(config(
                    &format!("fem.supports[{i}].name"),
                    "reaction reports are offered for volume meshes only",
                ));
            }
            if s.rotations.is_some() {
                return Err(config(
                    &format!("fem.supports[{i}].rotations"),
                    "a membrane node has no rotations",
                ));
            }
            let nodes = select_nodes(&mesh, &s.on, &format!("fem.supports[{i}].on"))?;
            for n in nodes {
                for ax in &s.fix {
                    let c = ax.index();
                    if let Some(d) = &s.drive {
                        drives[3 * n as usize + c] = Some(Drive {
                            velocity: d.velocity[c],
                            start: d.start,
                        });
                        continue;
                    }
                    held[3 * n as usize + c] = true;
                    if let Some(d) = s.displacement.filter(|d| d[c] != 0.0) {
                        prescribed.push(Prescribed {
                            node: n,
                            comp: c,
                            amplitude: d[c],
                            history: s.history.clone(),
                        });
                    }
                }
            }
        }
        if let Some(k) = (0..3 * nn).find(|&k| drives[k].is_some() && held[k]) {
            return Err(config(
                "fem.supports",
                format!(
                    "node {} component {} is both driven and held by another support",
                    mesh.node_ids[k / 3],
                    ["x", "y", "z"][k % 3]
                ),
            ));
        }
        if let Some(p) = prescribed
            .iter()
            .find(|p| drives[3 * p.node as usize + p.comp].is_some())
        {
            return Err(config(
                "fem.supports",
                format!(
                    "node {} component {} is both driven and displaced by a history",
                    mesh.node_ids[p.node as usize],
                    ["x", "y", "z"][p.comp]
                ),
            ));
        }
        // loads
        let as_quads = |list: Vec<usize>| -> Vec<usize> {
            // element indices of the (possibly split) membranes made from these mesh elements
            list.iter().flat_map(|&q| parts_of[q].clone()).collect()
        };
        let mut pressures = Vec::new();
        let mut loads = Vec::new();
        for (i, l) in cfg.loads.iter().enumerate() {
            let what = format!("fem.loads[{i}].on");
            match l {
                Load::Pressure { on, value, history } => {
                    let list = selected_shells(&mesh, on, &what)?;
                    pressures.push((as_quads(list), *value, history.clone()));
                }
                Load::Force {
                    on,
                    per_node,
                    total,
                    history,
                } => {
                    let nodes = select_nodes(&mesh, on, &what)?;
                    let per = crate::config::nodal_force(per_node, total, nodes.len());
                    let mut f = vec![0.0; 3 * nn];
                    for n in nodes {
                        for c in 0..3 {
                            f[3 * n as usize + c] += per[c];
                        }
                    }
                    loads.push((history.clone(), f));
                }
                Load::Gravity {
                    acceleration,
                    history,
                } => {
                    let f: Vec<f64> = (0..3 * nn)
                        .map(|k| node_mass[k / 3] * acceleration[k % 3])
                        .collect();
                    loads.push((history.clone(), f));
                }
            }
        }
        // interface
        let (elems_iface, faces) = match &cfg.interface {
            Some(spec) => {
                let faces = match spec.faces {
                    Some(ShellFaces::Top) => false,
                    Some(ShellFaces::Bottom) => true,
                    Some(ShellFaces::Both) | None => {
                        return Err(config(
                            "fem.interface.faces",
                            "a membrane has one surface: say which side the grains see, \
                             \"top\" (where the corner order's normal points; a generated \
                             cylinder: outside) or \"bottom\"",
                        ))
                    }
                };
                (
                    as_quads(selected_shells(&mesh, &spec.on, "fem.interface.on")?),
                    faces,
                )
            }
            None => {
                return Err(config(
                    "fem.interface",
                    "a membrane needs [fem.interface] on = ..., faces = \"top\" | \"bottom\" \
                     (the side the grains see)",
                ))
            }
        };
        let mut local = vec![u32::MAX; nn];
        let mut iface_nodes = Vec::new();
        let mut iface_triangles = Vec::new();
        for &e in &elems_iface {
            let p = &elems[e];
            let tris: Vec<[u32; 3]> = if p.len() == 4 {
                vec![[p[0], p[1], p[2]], [p[0], p[2], p[3]]]
            } else {
                vec![[p[0], p[1], p[2]]]
            };
            for t in tris {
                let t = if faces { [t[0], t[2], t[1]] } else { t };
                for n in t {
                    if local[n as usize] == u32::MAX {
                        local[n as usize] = iface_nodes.len() as u32;
                        iface_nodes.push(n);
                    }
                    iface_triangles.push(local[n as usize]);
                }
            }
        }
        let normal_triangles: Vec<u32> = elems_iface
            .iter()
            .flat_map(|&e| {
                let p = &elems[e];
                if p.len() == 4 {
                    vec![p[0], p[1], p[2], p[0], p[2], p[3]]
                } else {
                    p.clone()
                }
            })
            .collect();
        let probes = crate::output::thin_probes(
            &cfg.probes,
            &mesh,
            &used,
            elems.iter().map(|p| &p[..]),
            "membrane",
        )?;
        let n_iface = iface_nodes.len();
        Ok(MembraneModel {
            st: State {
                format: SNAPSHOT_FORMAT,
                time: 0.0,
                u: vec![0.0; 3 * nn],
                v: vec![0.0; 3 * nn],
                a: vec![0.0; 3 * nn],
                interface_forces: vec![0.0; 3 * n_iface],
                accel_ready: false,
                windows: 0,
                substeps: 0,
                csv_started: false,
            },
            mesh,
            elems,
            thickness,
            density: sec.density,
            law: Ogden {
                terms: sec.ogden.iter().map(|t| (t[0], t[1])).collect(),
            },
            safety,
            damping,
            node_mass,
            held,
            prescribed,
            drives,
            pressures,
            loads,
            histories: cfg.histories.clone(),
            iface_nodes,
            iface_triangles,
            normal_triangles,
            cylinder_centre,
            probes,
            output: cfg.output.clone(),
            vtu_files: Vec::new(),
        })
    }

    pub fn num_dofs(&self) -> usize {
        3 * self.mesh.num_nodes()
    }

    pub fn time(&self) -> f64 {
        self.st.time
    }

    pub fn mesh(&self) -> &Mesh {
        &self.mesh
    }

    pub fn displacements(&self) -> &[f64] {
        &self.st.u
    }

    /// Substeps taken so far.
    pub fn substeps(&self) -> u64 {
        self.st.substeps
    }

    fn current(&self, n: usize) -> [f64; 3] {
        let x = self.mesh.nodes[n];
        [
            x[0] + self.st.u[3 * n],
            x[1] + self.st.u[3 * n + 1],
            x[2] + self.st.u[3 * n + 2],
        ]
    }

    fn corners(&self, e: usize, current: bool) -> Vec<[f64; 3]> {
        self.elems[e]
            .iter()
            .map(|&n| {
                if current {
                    self.current(n as usize)
                } else {
                    self.mesh.nodes[n as usize]
                }
            })
            .collect()
    }

    /// The coupled surface in the reference configuration.
    pub fn interface_mesh(&self) -> InterfaceMesh {
        InterfaceMesh {
            node_ids: self
                .iface_nodes
                .iter()
                .map(|&n| self.mesh.node_ids[n as usize])
                .collect(),
            positions: self
                .iface_nodes
                .iter()
                .flat_map(|&n| self.mesh.nodes[n as usize])
                .collect(),
            triangles: self.iface_triangles.clone(),
            volume: None,
        }
    }

    /// The coupled membranes' area and area-weighted normal in the corner order's
    /// orientation: the side a positive `pressure` pushes against.
    pub fn pressure_surface(&self) -> (f64, [f64; 3]) {
        crate::area_and_normal(&self.mesh.nodes, &self.normal_triangles)
    }

    pub fn set_interface_forces(&mut self, forces: &[f64]) -> Result<(), FemError> {
        let expected = 3 * self.iface_nodes.len();
        if forces.len() != expected {
            return Err(FemError::InterfaceSize {
                expected,
                got: forces.len(),
            });
        }
        if let Some(i) = forces.iter().position(|f| !f.is_finite()) {
            return Err(FemError::NonFinite(format!(
                "interface force of node {} (component {})",
                self.mesh.node_ids[self.iface_nodes[i / 3] as usize],
                i % 3
            )));
        }
        self.st.interface_forces.copy_from_slice(forces);
        // the window's first half kick takes the forces held over it
        self.st.accel_ready = false;
        Ok(())
    }

    pub fn held_interface_forces(&self) -> &[f64] {
        &self.st.interface_forces
    }

    pub fn interface_kinematics(&self) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let pick = |v: &[f64]| -> Vec<f64> {
            self.iface_nodes
                .iter()
                .flat_map(|&n| {
                    [
                        v[3 * n as usize],
                        v[3 * n as usize + 1],
                        v[3 * n as usize + 2],
                    ]
                })
                .collect()
        };
        let p = self
            .iface_nodes
            .iter()
            .flat_map(|&n| self.current(n as usize))
            .collect();
        (p, pick(&self.st.v), pick(&self.st.a))
    }

    /// The critical step of central differences at the current stretches: the smallest
    /// over the elements of L_min / (c √2), L_min the shortest current edge, c the fastest
    /// in-plane wave at the element's largest stretches ([`membrane::wave_speed`]).
    pub fn critical_time_step(&self) -> f64 {
        (0..self.elems.len())
            .map(|e| {
                let x = self.corners(e, true);
                let lmin = (0..x.len())
                    .map(|k| norm(sub(x[(k + 1) % x.len()], x[k])))
                    .fold(f64::INFINITY, f64::min);
                let (_, states) = membrane::internal_forces(
                    &self.corners(e, false),
                    &x,
                    self.thickness[e],
                    &self.law,
                );
                let c = states
                    .iter()
                    .map(|s| membrane::wave_speed(&self.law, s.0, s.1, self.density))
                    .fold(0.0, f64::max);
                lmin / (c * std::f64::consts::SQRT_2)
            })
            .fold(f64::INFINITY, f64::min)
    }

    fn history(&self, h: &Option<String>, t: f64) -> f64 {
        match h {
            Some(name) => self.histories[name].eval(t, &self.histories),
            None => 1.0,
        }
    }

    /// Net force per dof at time t with displacements `u`: loads, interface forces, follower
    /// pressures, minus the internal forces.
    fn net_forces(&self, t: f64, u: &[f64]) -> Vec<f64> {
        let nn = self.mesh.num_nodes();
        let mut f = vec![0.0; 3 * nn];
        for (h, pattern) in &self.loads {
            let s = self.history(h, t);
            for (fi, p) in f.iter_mut().zip(pattern) {
                *fi += s * p;
            }
        }
        for (k, &n) in self.iface_nodes.iter().enumerate() {
            for c in 0..3 {
                f[3 * n as usize + c] += self.st.interface_forces[3 * k + c];
            }
        }
        let at = |n: u32| -> [f64; 3] {
            let (x, n) = (self.mesh.nodes[n as usize], 3 * n as usize);
            [x[0] + u[n], x[1] + u[n + 1], x[2] + u[n + 2]]
        };
        for (elems, value, h) in &self.pressures {
            // positive pushes against the corner order's normal
            let p = -value * self.history(h, t);
            for &e in elems {
                let x: Vec<[f64; 3]> = self.elems[e].iter().map(|&n| at(n)).collect();
                let fe = membrane::pressure_forces(&x, p);
                for (a, &n) in self.elems[e].iter().enumerate() {
                    for c in 0..3 {
                        f[3 * n as usize + c] += fe[3 * a + c];
                    }
                }
            }
        }
        for (e, p) in self.elems.iter().enumerate() {
            let x: Vec<[f64; 3]> = p.iter().map(|&n| at(n)).collect();
            let (fe, _) = membrane::internal_forces(
                &self.corners(e, false),
                &x,
                self.thickness[e],
                &self.law,
            );
            for (a, &n) in p.iter().enumerate() {
                for c in 0..3 {
                    f[3 * n as usize + c] -= fe[3 * a + c];
                }
            }
        }
        f
    }

    /// Accelerations of the free dofs from net forces and velocities (C = a M).
    fn accelerations(&self, f: &[f64], v: &[f64]) -> Vec<f64> {
        (0..f.len())
            .map(|k| {
                if self.held[k]
                    || self.drives[k]
                        .as_ref()
                        .is_some_and(|d| self.st.time >= d.start)
                {
                    0.0
                } else {
                    f[k] / self.node_mass[k / 3] - self.damping * v[k]
                }
            })
            .collect()
    }

    /// Puts the prescribed dofs at their values at time t (velocity by the history's slope
    /// over the substep `h` ending at t).
    fn apply_prescribed(&mut self, t: f64, h: f64) {
        for p in &self.prescribed {
            let k = 3 * p.node as usize + p.comp;
            let u = p.amplitude * self.history(&p.history, t);
            let u0 = p.amplitude * self.history(&p.history, t - h);
            self.st.u[k] = u;
            self.st.v[k] = (u - u0) / h;
            self.st.a[k] = 0.0;
        }
    }

    /// Advances by `dt` in equal substeps of at most `safety` × the critical step (velocity
    /// Verlet, i.e. central differences with the velocity at full steps; mass damping
    /// implicit in the second half step).
    pub fn advance(&mut self, dt: f64) -> Result<(), FemError> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(FemError::TimeStep(dt));
        }
        if !self.st.accel_ready {
            if self.st.substeps == 0 {
                // the prescribed supports where their histories put them at the start
                for p in &self.prescribed {
                    let k = 3 * p.node as usize + p.comp;
                    self.st.u[k] = p.amplitude * self.history(&p.history, self.st.time);
                }
            }
            let f = self.net_forces(self.st.time, &self.st.u);
            self.st.a = self.accelerations(&f, &self.st.v);
            self.st.accel_ready = true;
        }
        let crit = self.critical_time_step();
        if !(crit.is_finite() && crit > 0.0) {
            return Err(FemError::NonFinite(format!(
                "membrane critical time step ({crit:e} s) at t = {} s",
                self.st.time
            )));
        }
        let n = (dt / (self.safety * crit)).ceil().max(1.0) as u64;
        let h = dt / n as f64;
        let t0 = self.st.time;
        for i in 0..n {
            let ts = t0 + dt * i as f64 / n as f64;
            let t = t0 + dt * (i + 1) as f64 / n as f64;
            // a driven component over this substep: from its start on (by the substep's start)
            let driven =
                |d: &Option<Drive>| d.as_ref().filter(|d| ts >= d.start).map(|d| d.velocity);
            for k in 0..self.st.u.len() {
                if self.held[k] {
                    continue;
                }
                if let Some(vel) = driven(&self.drives[k]) {
                    self.st.v[k] = vel;
                    self.st.a[k] = 0.0;
                    self.st.u[k] += h * vel;
                } else {
                    self.st.v[k] += 0.5 * h * self.st.a[k];
                    self.st.u[k] += h * self.st.v[k];
                }
            }
            self.apply_prescribed(t, h);
            let f = self.net_forces(t, &self.st.u);
            let damp = 1.0 / (1.0 + 0.5 * h * self.damping);
            for k in 0..f.len() {
                if self.held[k] || driven(&self.drives[k]).is_some() {
                    continue;
                }
                let af = f[k] / self.node_mass[k / 3];
                self.st.v[k] = (self.st.v[k] + 0.5 * h * af) * damp;
                self.st.a[k] = af - self.damping * self.st.v[k];
            }
            self.st.substeps += 1;
        }
        self.st.time = t0 + dt;
        if let Some(k) = self.st.u.iter().position(|x| !x.is_finite()) {
            return Err(FemError::NonFinite(format!(
                "membrane displacement of node {} at t = {} s",
                self.mesh.node_ids[k / 3],
                self.st.time
            )));
        }
        Ok(())
    }

    /// A membrane is not solved statically (see the module docs).
    pub fn solve_static(&mut self) -> Result<(), FemError> {
        Err(config(
            "fem.analysis",
            "a membrane steps explicitly; it has no static solve",
        ))
    }

    pub fn total_mass(&self) -> f64 {
        self.node_mass.iter().sum()
    }

    /// The volume enclosed by a generated cylinder and the planes through its end rings
    /// (held axially: the rings stay in those planes), [m³].
    pub fn enclosed_volume(&self) -> Option<f64> {
        let c = self.cylinder_centre?;
        Some(
            (0..self.elems.len())
                .map(|e| membrane::lateral_volume(&self.corners(e, true), c))
                .sum(),
        )
    }

    /// For a generated cylinder: the interface forces' sum along each node's outward radial
    /// direction [N] (grains inside pushing out: positive; a confined sample carries the
    /// confining pressure times the membrane's area this way).
    pub fn outward_force(&self) -> Option<f64> {
        let c = self.cylinder_centre?;
        Some(
            self.iface_nodes
                .iter()
                .enumerate()
                .map(|(k, &n)| {
                    let x = self.current(n as usize);
                    let (dx, dy) = (x[0] - c[0], x[1] - c[1]);
                    let r = (dx * dx + dy * dy).sqrt();
                    let f = &self.st.interface_forces[3 * k..3 * k + 2];
                    if r > 0.0 {
                        (f[0] * dx + f[1] * dy) / r
                    } else {
                        0.0
                    }
                })
                .sum(),
        )
    }

    /// For a generated cylinder: the mean current height of its top ring [m] (the plane that
    /// closes [`Self::enclosed_volume`] there).
    pub fn top_ring_height(&self) -> Option<f64> {
        self.cylinder_centre?;
        let ring = self.mesh.node_sets.get("top")?;
        Some(
            ring.iter()
                .map(|&n| self.current(n as usize)[2])
                .sum::<f64>()
                / ring.len() as f64,
        )
    }

    /// Per element, the mean over its points of (λ_1, λ_2, σ_1, σ_2) (largest stretch first).
    pub fn element_states(&self) -> Vec<[f64; 4]> {
        (0..self.elems.len())
            .map(|e| {
                let (_, states) = membrane::internal_forces(
                    &self.corners(e, false),
                    &self.corners(e, true),
                    self.thickness[e],
                    &self.law,
                );
                let mut m = [0.0; 4];
                for s in &states {
                    let (big, small) = if s.0 >= s.1 {
                        ([s.0, s.2], [s.1, s.3])
                    } else {
                        ([s.1, s.3], [s.0, s.2])
                    };
                    m[0] += big[0];
                    m[1] += small[0];
                    m[2] += big[1];
                    m[3] += small[1];
                }
                m.map(|x| x / states.len() as f64)
            })
            .collect()
    }

    pub fn limits(&mut self) -> Result<BTreeMap<String, f64>, FemError> {
        let mut l = BTreeMap::from([
            ("dofs".to_string(), self.num_dofs() as f64),
            ("structure_mass".to_string(), self.total_mass()),
            ("interface_nodes".to_string(), self.iface_nodes.len() as f64),
            ("explicit".to_string(), 1.0),
            ("membrane".to_string(), 1.0),
            ("critical_time_step".to_string(), self.critical_time_step()),
        ]);
        // the nodes that can move (a clamped ring's do not ring against the grains)
        let masses: Vec<f64> = self
            .iface_nodes
            .iter()
            .filter(|&&n| (0..3).any(|c| !self.held[3 * n as usize + c]))
            .map(|&n| self.node_mass[n as usize])
            .collect();
        crate::insert_mass_limits(&mut l, &masses);
        l.insert("static_solve".to_string(), 0.0);
        Ok(l)
    }

    pub fn warnings(&self) -> Vec<String> {
        Vec::new()
    }

    pub fn snapshot(&self) -> Vec<u8> {
        rmp_serde::to_vec(&self.st).expect("state serialises")
    }

    /// Restores a `snapshot` of a model built from the same scene; continuation is bitwise.
    pub fn restore(&mut self, bytes: &[u8]) -> Result<(), FemError> {
        let st: State = crate::decode_state(bytes, |s: &State| s.format, SNAPSHOT_FORMAT)?;
        let nd = self.num_dofs();
        if [st.u.len(), st.v.len(), st.a.len()] != [nd; 3]
            || st.interface_forces.len() != self.st.interface_forces.len()
        {
            return Err(FemError::Snapshot(format!(
                "snapshot has {} dofs / {} interface values, the membrane model {nd} / {}",
                st.u.len(),
                st.interface_forces.len(),
                self.st.interface_forces.len()
            )));
        }
        self.st = st;
        Ok(())
    }

    /// After each window: a row of `fem_probes.csv` (time; for a cylinder its enclosed
    /// volume and outward interface force; probe displacements) and `fem_<window>.vtu` every `output.vtu_every`
    /// windows.
    pub fn write_outputs(&mut self, out_dir: &Path) -> Result<(), FemError> {
        let io = output::io_error;
        output::create_dir(out_dir)?;
        self.st.windows += 1;
        let volume = self.enclosed_volume();
        if self.output.csv && (!self.probes.is_empty() || volume.is_some()) {
            let path = out_dir.join("fem_probes.csv");
            let mut text = String::new();
            if !self.st.csv_started {
                text.push_str("time");
                if volume.is_some() {
                    text.push_str(",volume,outward_force,top_ring_z");
                }
                output::probe_header(&mut text, &self.probes);
                text.push('\n');
            }
            text.push_str(&format!("{:.9e}", self.st.time));
            if let Some(v) = volume {
                let f = self.outward_force().unwrap_or(0.0);
                let z = self.top_ring_height().unwrap_or(f64::NAN);
                text.push_str(&format!(",{v:.9e},{f:.9e},{z:.9e}"));
            }
            output::probe_row(&mut text, &self.probes, &self.st.u, 3);
            text.push('\n');
            output::append(&path, &text, !self.st.csv_started).map_err(|e| io(e, &path))?;
            self.st.csv_started = true;
        }
        if self.output.vtu_every > 0 && self.st.windows % self.output.vtu_every == 0 {
            let name = format!("fem_{:06}.vtu", self.st.windows);
            let path = out_dir.join(&name);
            let states = self.element_states();
            let col = |i: usize| -> Vec<f64> { states.iter().map(|s| s[i]).collect() };
            let thickness: Vec<f64> = states
                .iter()
                .zip(&self.thickness)
                .map(|(s, t)| t / (s[0] * s[1]))
                .collect();
            let conn: Vec<u32> = self.elems.iter().flatten().copied().collect();
            let ends: Vec<usize> = self
                .elems
                .iter()
                .scan(0, |end, p| {
                    *end += p.len();
                    Some(*end)
                })
                .collect();
            let types: Vec<u8> = self
                .elems
                .iter()
                .map(|p| {
                    if p.len() == 4 {
                        output::VTK_QUAD
                    } else {
                        VTK_TRIANGLE
                    }
                })
                .collect();
            let (l1, l2, s1, s2) = (col(0), col(1), col(2), col(3));
            output::write_grid(
                &path,
                &self.mesh.nodes,
                &conn,
                &ends,
                &types,
                &[("displacement", &self.st.u), ("velocity", &self.st.v)],
                &[
                    ("stretch_1", 1, &l1),
                    ("stretch_2", 1, &l2),
                    ("stress_1", 1, &s1),
                    ("stress_2", 1, &s2),
                    ("thickness", 1, &thickness),
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
            ("elements".to_string(), self.elems.len() as f64),
            ("time".to_string(), self.st.time),
            ("substeps".to_string(), self.st.substeps as f64),
        ];
        if let Some(v) = self.enclosed_volume() {
            r.push(("volume".to_string(), v));
        }
        if let Some(f) = self.outward_force() {
            r.push(("interface_force.outward".to_string(), f));
        }
        if let Some(z) = self.top_ring_height() {
            r.push(("top_ring_z".to_string(), z));
        }
        output::probe_results(&mut r, &self.probes, &self.st.u, 3);
        output::interface_force_results(&mut r, &self.st.interface_forces);
        let umax = self
            .st
            .u
            .chunks_exact(3)
            .map(|u| norm([u[0], u[1], u[2]]))
            .fold(0.0, f64::max);
        r.push(("max_displacement".to_string(), umax));
        let states = self.element_states();
        r.push((
            "max_stretch".to_string(),
            states.iter().map(|s| s[0]).fold(0.0, f64::max),
        ));
        r.push((
            "max_stress".to_string(),
            states
                .iter()
                .map(|s| s[2])
                .fold(f64::NEG_INFINITY, f64::max),
        ));
        r
    }

    pub fn probe_displacement(&self, name: &str) -> Option<[f64; 3]> {
        let &(_, n) = self.probes.iter().find(|(p, _)| p == name)?;
        let n = 3 * n as usize;
        Some([self.st.u[n], self.st.u[n + 1], self.st.u[n + 2]])
    }
}
