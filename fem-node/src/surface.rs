//! Exterior surface of a volume mesh (Ullrich 3.3.1: the triangle mesh handed to DEM) and
//! node / face selection by set or geometric selector.

use crate::config::Selector;
use crate::element::triangulate_face;
use crate::mesh::Mesh;
use crate::FemError;
use std::collections::HashMap;

/// Faces that belong to exactly one element, in (element, local face) order.
#[derive(Clone, Debug, Default)]
pub struct Boundary {
    /// `nodes[offsets[f]..offsets[f + 1]]`: face nodes (corners then mid-sides), outward.
    pub offsets: Vec<usize>,
    pub nodes: Vec<u32>,
    pub elem: Vec<u32>,
}

impl Boundary {
    pub fn extract(mesh: &Mesh) -> Boundary {
        // key: sorted corner nodes (3 or 4; padded with MAX)
        let mut seen: HashMap<[u32; 4], (u32, u32, u8)> = HashMap::new();
        for e in 0..mesh.num_elements() {
            let kind = mesh.kinds[e];
            let en = mesh.element_nodes(e);
            for (fi, face) in kind.faces().iter().enumerate() {
                let nc = if face.len() == 3 || face.len() == 6 {
                    3
                } else {
                    4
                };
                let mut key = [u32::MAX; 4];
                for k in 0..nc {
                    key[k] = en[face[k]];
                }
                key.sort_unstable();
                seen.entry(key)
                    .and_modify(|v| v.0 += 1)
                    .or_insert((1, e as u32, fi as u8));
            }
        }
        let mut faces: Vec<(u32, u8)> = seen
            .values()
            .filter(|v| v.0 == 1)
            .map(|v| (v.1, v.2))
            .collect();
        faces.sort_unstable();
        let mut b = Boundary {
            offsets: vec![0],
            ..Default::default()
        };
        for (e, fi) in faces {
            let en = mesh.element_nodes(e as usize);
            let face = mesh.kinds[e as usize].faces()[fi as usize];
            b.nodes.extend(face.iter().map(|&l| en[l]));
            b.offsets.push(b.nodes.len());
            b.elem.push(e);
        }
        b
    }

    pub fn len(&self) -> usize {
        self.elem.len()
    }
    pub fn is_empty(&self) -> bool {
        self.elem.is_empty()
    }
    pub fn face(&self, f: usize) -> &[u32] {
        &self.nodes[self.offsets[f]..self.offsets[f + 1]]
    }
}

/// Nodes selected by a selector (sorted), only nodes used by elements. `what` names the
/// config field in errors.
pub fn select_nodes(mesh: &Mesh, sel: &Selector, what: &str) -> Result<Vec<u32>, FemError> {
    let used = mesh.used_nodes();
    let (lo, hi) = mesh.bounds();
    let diag = ((0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>()).sqrt();
    let out: Vec<u32> = if let Some(name) = &sel.set {
        let set = mesh.node_set(name).ok_or_else(|| {
            FemError::Selection(format!(
                "{what}: unknown node set '{name}' in {} (available: {})",
                mesh.source,
                mesh.node_sets
                    .keys()
                    .cloned()
                    .collect::<Vec<_>>()
                    .join(", ")
            ))
        })?;
        set.iter().copied().filter(|&n| used[n as usize]).collect()
    } else if let Some(b) = &sel.bbox {
        let tol = 1e-9 * diag;
        (0..mesh.num_nodes() as u32)
            .filter(|&n| {
                let p = mesh.nodes[n as usize];
                used[n as usize] && (0..3).all(|k| p[k] >= b.min[k] - tol && p[k] <= b.max[k] + tol)
            })
            .collect()
    } else if let Some(p) = &sel.plane {
        let tol = p.tol.unwrap_or(1e-6 * diag);
        let k = p.axis.index();
        (0..mesh.num_nodes() as u32)
            .filter(|&n| used[n as usize] && (mesh.nodes[n as usize][k] - p.value).abs() <= tol)
            .collect()
    } else {
        return Err(FemError::Selection(format!("{what}: empty selector")));
    };
    if out.is_empty() {
        return Err(FemError::Selection(format!(
            "{what}: selects no nodes of {}",
            mesh.source
        )));
    }
    Ok(out)
}

/// Boundary faces whose nodes are all selected.
pub fn select_faces(
    mesh: &Mesh,
    boundary: &Boundary,
    sel: &Selector,
    what: &str,
) -> Result<Vec<usize>, FemError> {
    let nodes = select_nodes(mesh, sel, what)?;
    let mut mark = vec![false; mesh.num_nodes()];
    for &n in &nodes {
        mark[n as usize] = true;
    }
    let faces: Vec<usize> = (0..boundary.len())
        .filter(|&f| boundary.face(f).iter().all(|&n| mark[n as usize]))
        .collect();
    if faces.is_empty() {
        return Err(FemError::Selection(format!(
            "{what}: selects no exterior faces of {}",
            mesh.source
        )));
    }
    Ok(faces)
}

/// The coupling interface: selected exterior faces as linear triangles over a compact node list.
#[derive(Clone, Debug, Default)]
pub struct Interface {
    /// Mesh node indices of the interface nodes (sorted).
    pub nodes: Vec<u32>,
    /// Triangles indexing `nodes`, outward oriented.
    pub triangles: Vec<u32>,
}

impl Interface {
    pub fn from_faces(mesh: &Mesh, boundary: &Boundary, faces: &[usize]) -> Interface {
        let mut tris: Vec<[u32; 3]> = Vec::new();
        for &f in faces {
            triangulate_face(boundary.face(f), &mut tris);
        }
        let mut nodes: Vec<u32> = tris.iter().flatten().copied().collect();
        nodes.sort_unstable();
        nodes.dedup();
        let mut local = vec![u32::MAX; mesh.num_nodes()];
        for (i, &n) in nodes.iter().enumerate() {
            local[n as usize] = i as u32;
        }
        let triangles = tris
            .iter()
            .flat_map(|t| t.map(|n| local[n as usize]))
            .collect();
        Interface { nodes, triangles }
    }
}
