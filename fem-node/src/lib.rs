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
pub mod mesh;
mod model;
pub mod nonlinear;
pub mod output;
pub mod resources;
pub mod shell;
pub mod surface;

pub use config::{parse_scene_section, parse_scene_table};
pub use element::ElementKind;
pub use mesh::Mesh;
pub use model::Model;

/// The coupled surface handed to the DEM side (reference configuration).
#[derive(Clone, Debug, PartialEq)]
pub struct InterfaceMesh {
    /// The mesh file's node ids of the interface nodes.
    pub node_ids: Vec<u64>,
    /// Flat xyz of the interface nodes [m].
    pub positions: Vec<f64>,
    /// Outward-oriented triangles indexing the interface node list (0-based).
    pub triangles: Vec<u32>,
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
