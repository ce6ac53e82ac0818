//! Volume meshes: storage, readers (Gmsh `.msh` 4.1 ASCII, Abaqus/CalculiX `.inp`) and the
//! structured box generator.

mod abaqus;
mod generate;
mod gmsh;

pub use generate::{box_mesh, cylinder_mesh, plate_mesh};

use crate::element::{self, ElementKind};
use crate::FemError;
use rayon::prelude::*;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

/// A volume mesh: flat, data-oriented storage (node-major coordinates, CSR connectivity).
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    /// Reference coordinates [m].
    pub nodes: Vec<[f64; 3]>,
    /// The file's node ids (1-based sequential for generated meshes).
    pub node_ids: Vec<u64>,
    pub kinds: Vec<ElementKind>,
    /// `conn[offsets[e]..offsets[e + 1]]` are the node indices of element e (Abaqus order).
    pub offsets: Vec<usize>,
    pub conn: Vec<u32>,
    pub elem_ids: Vec<u64>,
    /// Line of the element's definition in its file (0 for generated meshes).
    pub elem_lines: Vec<usize>,
    /// Named node sets (Gmsh physical groups, Abaqus *NSET, generated box faces).
    pub node_sets: BTreeMap<String, Vec<u32>>,
    /// Named element sets (Gmsh 3-D physical groups, Abaqus *ELSET / ELSET=).
    pub elem_sets: BTreeMap<String, Vec<u32>>,
    /// Where the mesh came from, for error messages.
    pub source: String,
    /// Surface elements of a mesh without volume elements (Gmsh quadrangles and triangles,
    /// Abaqus S4/S4R/M3D4/M3D4R and S3/S3R/M3D3/STRI3); empty when the mesh has volume
    /// elements (its surface elements are then faces).
    pub shells: Shells,
    /// Arlequin factor 1 − w_I per node (Wellmann (6.3)) when the mesh overlaps particles
    /// ([`crate::config::OverlapSpec`]); empty otherwise. Every integral of an element
    /// (stiffness, internal forces, mass, body loads) is weighted by its interpolation.
    pub arlequin_scale: Vec<f64>,
}

/// Surface elements (shells or membranes): corners counter-clockwise about the element's
/// normal. A shell model takes quadrilaterals only; a membrane model takes both.
#[derive(Clone, Debug, Default)]
pub struct Shells {
    /// Corners; a triangle's fourth is [`Shells::NO_CORNER`].
    pub quads: Vec<[u32; 4]>,
    /// The file's element ids.
    pub ids: Vec<u64>,
    /// Line of each element's definition in its file (0 for generated meshes).
    pub lines: Vec<usize>,
    /// Thickness [m] from the file's shell section (Abaqus *SHELL SECTION); NaN where the file
    /// gives none.
    pub thickness: Vec<f64>,
    /// Named element sets of shells (Gmsh 2-D physical groups, Abaqus ELSET=).
    pub sets: BTreeMap<String, Vec<u32>>,
    /// Surface elements no model here uses (beams, trusses, higher-order surfaces), by
    /// (id, line, what it is): reported when a shell or membrane model is built from the mesh.
    pub unsupported: Vec<(u64, usize, &'static str)>,
}

impl Shells {
    /// The fourth corner of a triangle.
    pub const NO_CORNER: u32 = u32::MAX;
    /// The corners of element `s` (three or four).
    pub fn corners(&self, s: usize) -> &[u32] {
        let q = &self.quads[s];
        if q[3] == Self::NO_CORNER {
            &q[..3]
        } else {
            q
        }
    }
    /// Each element's thickness: the file's section, else `default`; an element with neither
    /// is refused, named, with `field` (the scene's key) and `section` (the deck's keyword)
    /// as the remedies.
    pub fn thicknesses(
        &self,
        default: Option<f64>,
        field: &str,
        section: &str,
        source: &str,
    ) -> Result<Vec<f64>, FemError> {
        (0..self.len())
            .map(|e| match self.thickness[e] {
                t if t.is_finite() => Ok(t),
                _ => default.ok_or_else(|| FemError::Config {
                    field: field.to_string(),
                    message: format!(
                        "element {} of {source} has no thickness: give {field} (m) or a \
                         {section} in the deck",
                        self.ids[e]
                    ),
                }),
            })
            .collect()
    }

    /// The first triangle (its id and line), which a shell model refuses.
    pub fn first_triangle(&self) -> Option<(u64, usize)> {
        self.quads
            .iter()
            .position(|q| q[3] == Self::NO_CORNER)
            .map(|s| (self.ids[s], self.lines[s]))
    }
    pub fn len(&self) -> usize {
        self.quads.len()
    }
    pub fn is_empty(&self) -> bool {
        self.quads.is_empty()
    }
    pub(crate) fn push_triangle(&mut self, tri: [u32; 3], id: u64, line: usize) -> u32 {
        self.push([tri[0], tri[1], tri[2], Self::NO_CORNER], id, line)
    }
    pub(crate) fn push(&mut self, quad: [u32; 4], id: u64, line: usize) -> u32 {
        self.quads.push(quad);
        self.ids.push(id);
        self.lines.push(line);
        self.thickness.push(f64::NAN);
        (self.quads.len() - 1) as u32
    }
    /// Shell set by name (exact, then case-insensitive).
    pub fn set(&self, name: &str) -> Option<&Vec<u32>> {
        self.sets.get(name).or_else(|| {
            self.sets
                .iter()
                .find(|(k, _)| k.eq_ignore_ascii_case(name))
                .map(|(_, v)| v)
        })
    }
}

impl Mesh {
    pub fn num_nodes(&self) -> usize {
        self.nodes.len()
    }
    pub fn num_elements(&self) -> usize {
        self.kinds.len()
    }
    pub fn element_nodes(&self, e: usize) -> &[u32] {
        &self.conn[self.offsets[e]..self.offsets[e + 1]]
    }
    /// The nodal Arlequin factors 1 − w of element e into `buf`, or `None` when the mesh has
    /// none or they are all 1 (the element lies outside the overlap).
    pub fn element_scale<'a>(&self, e: usize, buf: &'a mut Vec<f64>) -> Option<&'a [f64]> {
        if self.arlequin_scale.is_empty() {
            return None;
        }
        buf.clear();
        buf.extend(
            self.element_nodes(e)
                .iter()
                .map(|&n| self.arlequin_scale[n as usize]),
        );
        if buf.iter().all(|&s| s == 1.0) {
            None
        } else {
            Some(&buf[..])
        }
    }

    /// Keeps the elements with `keep[e]` (in order), renumbering the element sets; the nodes
    /// stay (those no element uses any more carry no dofs). Returns how many were removed.
    pub fn retain_elements(&mut self, keep: &[bool]) -> usize {
        let mut new_index = vec![u32::MAX; self.kinds.len()];
        let (mut kinds, mut offsets, mut conn) = (Vec::new(), vec![0], Vec::new());
        let (mut ids, mut lines) = (Vec::new(), Vec::new());
        for e in 0..self.kinds.len() {
            if !keep[e] {
                continue;
            }
            new_index[e] = kinds.len() as u32;
            kinds.push(self.kinds[e]);
            conn.extend_from_slice(self.element_nodes(e));
            offsets.push(conn.len());
            ids.push(self.elem_ids[e]);
            lines.push(self.elem_lines[e]);
        }
        let removed = self.kinds.len() - kinds.len();
        for set in self.elem_sets.values_mut() {
            set.retain(|&e| new_index[e as usize] != u32::MAX);
            set.iter_mut().for_each(|e| *e = new_index[*e as usize]);
        }
        (self.kinds, self.offsets, self.conn) = (kinds, offsets, conn);
        (self.elem_ids, self.elem_lines) = (ids, lines);
        removed
    }

    pub fn element_coords(&self, e: usize, buf: &mut Vec<[f64; 3]>) {
        buf.clear();
        buf.extend(
            self.element_nodes(e)
                .iter()
                .map(|&n| self.nodes[n as usize]),
        );
    }
    pub(crate) fn push_element(&mut self, kind: ElementKind, id: u64, line: usize, nodes: &[u32]) {
        if self.offsets.is_empty() {
            self.offsets.push(0);
        }
        self.kinds.push(kind);
        self.conn.extend_from_slice(nodes);
        self.offsets.push(self.conn.len());
        self.elem_ids.push(id);
        self.elem_lines.push(line);
    }

    /// Reads a `.msh` (Gmsh 4.1 ASCII) or `.inp` (Abaqus / CalculiX) file.
    pub fn read(path: &Path) -> Result<Mesh, FemError> {
        // the text and the mesh parsed from it (a node line of ~40 characters becomes 24 B
        // of coordinates plus its id and index entries) take about twice the file's size
        let text = crate::resources::read_text_within_memory(path, "the mesh file").map_err(
            |message| FemError::Io {
                path: path.display().to_string(),
                message,
            },
        )?;
        let name = path.display().to_string();
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .unwrap_or("")
            .to_ascii_lowercase();
        let mesh = match ext.as_str() {
            "msh" => gmsh::parse(&text, &name)?,
            "inp" => abaqus::parse(&text, &name)?,
            _ => {
                return Err(FemError::Mesh {
                    file: name,
                    line: 0,
                    message: format!("unknown mesh format '.{ext}' (expected .msh or .inp)"),
                })
            }
        };
        mesh.check_elements()?;
        Ok(mesh)
    }

    /// Parses mesh text in the given format ("msh" or "inp"); `name` is used in errors.
    pub fn parse(text: &str, format: &str, name: &str) -> Result<Mesh, FemError> {
        let mesh = match format {
            "msh" => gmsh::parse(text, name)?,
            "inp" => abaqus::parse(text, name)?,
            _ => {
                return Err(FemError::Mesh {
                    file: name.into(),
                    line: 0,
                    message: format!("unknown mesh format '{format}'"),
                })
            }
        };
        mesh.check_elements()?;
        Ok(mesh)
    }

    /// Whether this is a shell mesh (quadrangles and no volume elements).
    pub fn is_shell_mesh(&self) -> bool {
        self.kinds.is_empty() && !self.shells.is_empty()
    }

    /// Keeps the surface elements as shells only when there is no volume element (then they
    /// are the model); otherwise they are faces, already recorded as node sets.
    pub(crate) fn settle_shells(&mut self) {
        if !self.kinds.is_empty() {
            self.shells = Shells::default();
        }
    }

    /// Detects inverted or degenerate elements from the Jacobian at the integration points
    /// (shell meshes are checked when their model is built).
    pub fn check_elements(&self) -> Result<(), FemError> {
        if self.kinds.is_empty() {
            if !self.shells.is_empty() || !self.shells.unsupported.is_empty() {
                return Ok(());
            }
            return Err(FemError::Mesh {
                file: self.source.clone(),
                line: 0,
                message: "mesh has no volume elements (tet4, tet10, hex8, hex20) and no \
                          surface elements (Gmsh quadrangles or triangles, Abaqus \
                          S4/S4R/M3D4/M3D4R, S3/S3R/M3D3/STRI3)"
                    .into(),
            });
        }
        let bad: Option<(usize, element::BadJacobian)> = (0..self.num_elements())
            .into_par_iter()
            .map(|e| {
                let mut x = Vec::new();
                self.element_coords(e, &mut x);
                element::check_jacobian(self.kinds[e], &x)
                    .err()
                    .map(|b| (e, b))
            })
            .find_first(|r| r.is_some())
            .flatten();
        if let Some((e, b)) = bad {
            let what = if b.inverted { "inverted" } else { "degenerate" };
            return Err(FemError::Mesh {
                file: self.source.clone(),
                line: self.elem_lines[e],
                message: format!(
                    "element {} ({}) is {what}: Jacobian determinant {:.3e} at an integration point",
                    self.elem_ids[e],
                    self.kinds[e].name(),
                    b.det_j
                ),
            });
        }
        Ok(())
    }

    /// Map from file node id to node index.
    pub fn node_index_map(&self) -> HashMap<u64, u32> {
        self.node_ids
            .iter()
            .enumerate()
            .map(|(i, &id)| (id, i as u32))
            .collect()
    }

    /// Switches 8-node hexahedra between full integration and incompatible modes.
    pub fn set_hex8_incompatible(&mut self, incompatible: bool) {
        self.set_hex8_formulation(if incompatible {
            ElementKind::Hex8i
        } else {
            ElementKind::Hex8
        });
    }

    /// Gives every 8-node hexahedron the formulation `kind` (hex8, hex8i or hex8b).
    pub fn set_hex8_formulation(&mut self, kind: ElementKind) {
        for k in &mut self.kinds {
            if matches!(
                *k,
                ElementKind::Hex8 | ElementKind::Hex8i | ElementKind::Hex8b
            ) {
                *k = kind;
            }
        }
    }

    /// Node set by name (exact, then case-insensitive as Abaqus names are).
    pub fn node_set(&self, name: &str) -> Option<&Vec<u32>> {
        self.node_sets.get(name).or_else(|| {
            self.node_sets
                .iter()
                .find(|(k, _)| k.eq_ignore_ascii_case(name))
                .map(|(_, v)| v)
        })
    }

    /// Element set by name (exact, then case-insensitive).
    pub fn elem_set(&self, name: &str) -> Option<&Vec<u32>> {
        self.elem_sets.get(name).or_else(|| {
            self.elem_sets
                .iter()
                .find(|(k, _)| k.eq_ignore_ascii_case(name))
                .map(|(_, v)| v)
        })
    }

    /// Marks which nodes are referenced by at least one element.
    pub fn used_nodes(&self) -> Vec<bool> {
        let mut used = vec![false; self.num_nodes()];
        let corners = self.shells.quads.iter().flatten();
        for &n in self.conn.iter().chain(corners) {
            if n != Shells::NO_CORNER {
                used[n as usize] = true;
            }
        }
        used
    }

    /// Bounding box (min, max).
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in &self.nodes {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        (lo, hi)
    }
}

/// Sorted, de-duplicated node list.
pub(crate) fn sort_dedup(mut v: Vec<u32>) -> Vec<u32> {
    v.sort_unstable();
    v.dedup();
    v
}
