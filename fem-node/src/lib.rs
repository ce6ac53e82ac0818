//! `fem`: the finite element engine of the DEM–FEM co-simulation (Ullrich 2022, ch. 2.2, 3.3).
//!
//! Linear elastic solids (tet4, tet10, hex8, hex8 with incompatible modes or mean-dilatation
//! B̄, hex20), static solves and Bossak–Newmark / explicit dynamics with faer's sparse
//! Cholesky, exterior-surface extraction for the coupling interface, snapshots, VTK/CSV output
//! and strain gauges. No transport here:
//! the `fem-node` binary adapts this library to zenoh.
//!
//! ```no_run
//! let text = std::fs::read_to_string("scene.toml").unwrap();
//! let cfg = fem::parse_scene_section(&text).unwrap().expect("[fem] table");
//! let mut model = fem::Model::from_config(&cfg, std::path::Path::new(".")).unwrap();
//! let iface = model.interface_mesh();
//! model.set_interface_forces(&vec![0.0; iface.positions.len()]).unwrap();
//! model.advance(1e-4).unwrap();
//! let (p, v, a) = model.interface_kinematics();
//! # let _ = (p, v, a);
//! ```

// `!(a <= b)` checks deliberately reject NaN; index loops mirror the element equations.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]

pub mod assembly;
pub mod config;
pub mod element;
pub mod history;
pub mod material;
pub mod membrane;
mod membrane_model;
pub mod mesh;
mod model;
pub mod nonlinear;
pub mod output;
pub mod overlap;
pub mod resources;
pub mod shell;
mod shell_model;
pub mod surface;
pub mod tree_factor;

pub use config::{parse_scene_section, parse_scene_table};
pub use element::ElementKind;
pub use membrane_model::MembraneModel;
pub use mesh::Mesh;
pub use model::Model;
pub use shell_model::ShellModel;

use std::collections::BTreeMap;
use std::path::Path;

/// What the `fem-node` adapter asks of a structure, volume ([`Model`]), shells
/// ([`ShellModel`]) or membranes ([`MembraneModel`]); [`build`] picks the kind from the
/// scene's mesh and `[fem.membrane]`.
pub trait Structure: Send {
    fn time(&self) -> f64;
    /// The coupled surface in the reference configuration.
    fn interface_mesh(&self) -> InterfaceMesh;
    /// Nodal interface forces [N], flat xyz in interface node order, held until the next call.
    fn set_interface_forces(&mut self, forces: &[f64]) -> Result<(), FemError>;
    fn held_interface_forces(&self) -> &[f64];
    /// Positions, velocities and accelerations of the interface nodes (flat xyz).
    fn interface_kinematics(&self) -> (Vec<f64>, Vec<f64>, Vec<f64>);
    fn advance(&mut self, dt: f64) -> Result<(), FemError>;
    fn solve_static(&mut self) -> Result<(), FemError>;
    /// Figures for the coordinator's up-front checks (FEM.md).
    fn limits(&mut self) -> Result<BTreeMap<String, f64>, FemError>;
    fn warnings(&self) -> Vec<String>;
    fn snapshot(&self) -> Vec<u8>;
    fn restore(&mut self, bytes: &[u8]) -> Result<(), FemError>;
    fn write_outputs(&mut self, out_dir: &Path) -> Result<(), FemError>;
    /// Result quantities for `summary.json`.
    fn results(&self) -> Vec<(String, f64)>;
    /// The coupled surface's area [m²] and area-weighted normal: a positive `pressure` load
    /// on the interface's selection pushes against it (a volume: the outward normal).
    fn pressure_surface(&self) -> (f64, [f64; 3]);
}

/// `interface_node_mass_min` / `_mean` of the interface nodes' `masses` (none: nothing).
pub(crate) fn insert_mass_limits(l: &mut BTreeMap<String, f64>, masses: &[f64]) {
    if !masses.is_empty() {
        let min = masses.iter().copied().fold(f64::INFINITY, f64::min);
        let mean = masses.iter().sum::<f64>() / masses.len() as f64;
        l.insert("interface_node_mass_min".to_string(), min);
        l.insert("interface_node_mass_mean".to_string(), mean);
    }
}

/// A model's snapshot state decoded from MessagePack, refused unless its `format` is
/// `expected`.
pub(crate) fn decode_state<T: serde::de::DeserializeOwned>(
    bytes: &[u8],
    format: impl Fn(&T) -> u32,
    expected: u32,
) -> Result<T, FemError> {
    let st: T = rmp_serde::from_slice(bytes)
        .map_err(|e| FemError::Snapshot(format!("cannot decode: {e}")))?;
    if format(&st) != expected {
        return Err(FemError::Snapshot(format!(
            "format {} (expected {expected})",
            format(&st)
        )));
    }
    Ok(st)
}

/// The total area and the area-weighted normal (½ Σ (b − a) × (c − a)) of triangles indexing
/// `points`.
pub fn area_and_normal(points: &[[f64; 3]], triangles: &[u32]) -> (f64, [f64; 3]) {
    let (mut area, mut normal) = (0.0, [0.0; 3]);
    for t in triangles.chunks_exact(3) {
        let [a, b, c] = [0, 1, 2].map(|k| points[t[k] as usize]);
        let (e1, e2) = (
            [b[0] - a[0], b[1] - a[1], b[2] - a[2]],
            [c[0] - a[0], c[1] - a[1], c[2] - a[2]],
        );
        let n = [
            e1[1] * e2[2] - e1[2] * e2[1],
            e1[2] * e2[0] - e1[0] * e2[2],
            e1[0] * e2[1] - e1[1] * e2[0],
        ];
        area += 0.5 * (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        for i in 0..3 {
            normal[i] += 0.5 * n[i];
        }
    }
    (area, normal)
}

impl Model {
    /// The interface triangles' area and outward area-weighted normal.
    pub fn pressure_surface(&self) -> (f64, [f64; 3]) {
        let m = self.interface_mesh();
        let points: Vec<[f64; 3]> = m
            .positions
            .chunks_exact(3)
            .map(|p| [p[0], p[1], p[2]])
            .collect();
        area_and_normal(&points, &m.triangles)
    }
}

macro_rules! structure_by_delegation {
    ($t:ty) => {
        impl Structure for $t {
            fn time(&self) -> f64 {
                <$t>::time(self)
            }
            fn interface_mesh(&self) -> InterfaceMesh {
                <$t>::interface_mesh(self)
            }
            fn set_interface_forces(&mut self, forces: &[f64]) -> Result<(), FemError> {
                <$t>::set_interface_forces(self, forces)
            }
            fn held_interface_forces(&self) -> &[f64] {
                <$t>::held_interface_forces(self)
            }
            fn interface_kinematics(&self) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
                <$t>::interface_kinematics(self)
            }
            fn advance(&mut self, dt: f64) -> Result<(), FemError> {
                <$t>::advance(self, dt)
            }
            fn solve_static(&mut self) -> Result<(), FemError> {
                <$t>::solve_static(self)
            }
            fn limits(&mut self) -> Result<BTreeMap<String, f64>, FemError> {
                <$t>::limits(self)
            }
            fn warnings(&self) -> Vec<String> {
                <$t>::warnings(self)
            }
            fn snapshot(&self) -> Vec<u8> {
                <$t>::snapshot(self)
            }
            fn restore(&mut self, bytes: &[u8]) -> Result<(), FemError> {
                <$t>::restore(self, bytes)
            }
            fn write_outputs(&mut self, out_dir: &Path) -> Result<(), FemError> {
                <$t>::write_outputs(self, out_dir)
            }
            fn results(&self) -> Vec<(String, f64)> {
                <$t>::results(self)
            }
            fn pressure_surface(&self) -> (f64, [f64; 3]) {
                <$t>::pressure_surface(self)
            }
        }
    };
}
structure_by_delegation!(Model);
structure_by_delegation!(ShellModel);
structure_by_delegation!(MembraneModel);

/// Builds the structure of a scene's `[fem]` table: membranes with `[fem.membrane]`, shells
/// for a generated plate or a mesh file without volume elements, a volume model otherwise. Relative mesh paths are resolved
/// against `base_dir`.
pub fn build(cfg: &config::FemConfig, base_dir: &Path) -> Result<Box<dyn Structure>, FemError> {
    if MembraneModel::is_membrane(cfg) {
        return Ok(Box::new(MembraneModel::from_config(cfg, base_dir)?));
    }
    if ShellModel::is_plate(cfg) {
        return Ok(Box::new(ShellModel::from_config(cfg)?));
    }
    if let config::MeshSpec::File { path, .. } = &cfg.mesh {
        cfg.validate()
            .map_err(|(field, message)| FemError::Config { field, message })?;
        let mesh = Mesh::read(&base_dir.join(path))?;
        if mesh.kinds.is_empty() {
            return Ok(Box::new(ShellModel::from_mesh(cfg, mesh)?));
        }
        return Ok(Box::new(Model::from_mesh(cfg, mesh)?));
    }
    Ok(Box::new(Model::from_config(cfg, base_dir)?))
}

/// The coupled surface handed to the DEM side (reference configuration).
#[derive(Clone, Debug, PartialEq)]
pub struct InterfaceMesh {
    /// The mesh file's node ids of the interface nodes.
    pub node_ids: Vec<u64>,
    /// Flat xyz of the interface nodes [m].
    pub positions: Vec<f64>,
    /// Outward-oriented triangles indexing the interface node list (0-based).
    pub triangles: Vec<u32>,
    /// A volume interface ([`config::OverlapSpec`]): its elements and nodal weights; then
    /// `triangles` is empty.
    pub volume: Option<VolumeMesh>,
}

/// The elements and weights of a volume (Arlequin) interface.
#[derive(Clone, Debug, PartialEq)]
pub struct VolumeMesh {
    /// "tet4", "tet10", "hex8" or "hex20".
    pub shape: String,
    /// The shape's node count of indices into the interface node list per element.
    pub elements: Vec<u32>,
    /// The particles' weight w_I at each interface node (6.27).
    pub weights: Vec<f64>,
    /// ε of (6.23) [N/m⁴].
    pub penalty: f64,
}

/// Errors of the FEM engine; each names the file/line, config field, set or node concerned.
#[derive(Debug, thiserror::Error)]
pub enum FemError {
    #[error("{path}: {message}")]
    Io { path: String, message: String },
    /// `line` 0: the file as a whole (printed without a line number, not as `file:0`).
    #[error("{file}{}: {message}", line_part(.line))]
    Mesh {
        file: String,
        line: usize,
        message: String,
    },
    #[error("{field}: {message}")]
    Config { field: String, message: String },
    #[error("{0}")]
    Selection(String),
    #[error("solver: {0}")]
    Solver(String),
    #[error("interface forces: expected {expected} values (xyz of {} interface nodes), got {got}", expected / 3)]
    InterfaceSize { expected: usize, got: usize },
    #[error("invalid time step {0}: must be finite and > 0 s")]
    TimeStep(f64),
    #[error("snapshot: {0}")]
    Snapshot(String),
    #[error("non-finite value in {0} (diverged?)")]
    NonFinite(String),
}

/// ":N" for an error on line N of a file, nothing for one about the whole file (line 0).
fn line_part(line: &usize) -> String {
    if *line > 0 {
        format!(":{line}")
    } else {
        String::new()
    }
}
