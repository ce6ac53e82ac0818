//! The overlap of the FE mesh with a particle region for the Arlequin volume coupling
//! (Wellmann ch. 6, SEED-SPEC §4): nodal weights w_I of the particles (6.27), the overlap's
//! elements Ω^C, and the mesh's Arlequin factors 1 − w that weight every FE integral (6.3).

use crate::config::OverlapSpec;
use crate::element::ElementKind;
use crate::mesh::Mesh;
use crate::FemError;

/// The overlap as the DEM needs it: its nodes (mesh indices, sorted), its elements in one
/// interpolation (local node indices), the nodal weights.
#[derive(Clone, Debug, PartialEq)]
pub struct Overlap {
    /// "tet4", "tet10", "hex8" or "hex20" (hex8i and hex8b interpolate as hex8).
    pub shape: &'static str,
    pub nodes: Vec<u32>,
    /// Node count of the shape per element, indexing `nodes`.
    pub elements: Vec<u32>,
    pub weights: Vec<f64>,
    /// The mesh's element indices of the overlap.
    pub mesh_elements: Vec<usize>,
    /// The Arlequin factor 1 − w of every mesh node, for `Mesh::arlequin_scale`.
    pub scale: Vec<f64>,
    /// ε of (6.23).
    pub penalty: f64,
}

fn shape_of(kind: ElementKind) -> &'static str {
    match kind {
        ElementKind::Tet4 => "tet4",
        ElementKind::Tet10 => "tet10",
        ElementKind::Hex8 | ElementKind::Hex8i | ElementKind::Hex8b => "hex8",
        ElementKind::Hex20 => "hex20",
    }
}

/// Nodal weights closer than this to 0 or 1 are taken as 0 or 1 (round-off of grid
/// coordinates at exactly one width from the particle box, or on it).
const WEIGHT_SNAP: f64 = 1e-9;

/// The particles' weight at node `x`, w = max(0, 1 − d/width) with d its distance from the
/// particle box. A node one width away as a grid puts it (0.015 − 0.01 = 0.004999…) is out,
/// one on the box's face by round-off (27.5 mm as 11 × 2.5 mm) in: weights within 1e-9 of 0
/// or 1 snap to them, for the overlap and for `carve` alike.
fn node_weight(x: &[f64; 3], spec: &OverlapSpec) -> f64 {
    let w = 1.0 - box_distance(x, &spec.de_region.min, &spec.de_region.max) / spec.width;
    if w < WEIGHT_SNAP {
        0.0
    } else if w > 1.0 - WEIGHT_SNAP {
        1.0
    } else {
        w
    }
}

/// Distance from `x` to the box [min, max] (0 inside).
fn box_distance(x: &[f64; 3], min: &[f64; 3], max: &[f64; 3]) -> f64 {
    (0..3)
        .map(|k| {
            let d = (min[k] - x[k]).max(x[k] - max[k]).max(0.0);
            d * d
        })
        .sum::<f64>()
        .sqrt()
}

/// With `carve`, removes the elements that lie in the particle box (all nodes at w = 1);
/// returns how many. An error when nothing is left.
pub fn carve(mesh: &mut Mesh, spec: &OverlapSpec) -> Result<usize, FemError> {
    if !spec.carve {
        return Ok(0);
    }
    let keep: Vec<bool> = (0..mesh.num_elements())
        .map(|e| {
            !(mesh.element_nodes(e).iter())
                .all(|&n| node_weight(&mesh.nodes[n as usize], spec) == 1.0)
        })
        .collect();
    let removed = mesh.retain_elements(&keep);
    if mesh.num_elements() == 0 {
        return Err(FemError::Config {
            field: "fem.overlap.carve".into(),
            message: format!(
                "every element of {} lies in de_region: nothing is left",
                mesh.source
            ),
        });
    }
    Ok(removed)
}

/// Computes the weights and the overlap (the caller puts `scale` into the mesh once the
/// unweighted penalty matrix is assembled). Refuses (naming the field or element) a bad box,
/// width or penalty, an element inside the particle region (its FE integrals would vanish),
/// an overlap without elements or with several interpolations.
pub fn select(mesh: &Mesh, spec: &OverlapSpec) -> Result<Overlap, FemError> {
    let cerr = |field: &str, message: String| FemError::Config {
        field: format!("fem.overlap.{field}"),
        message,
    };
    let (min, max) = (&spec.de_region.min, &spec.de_region.max);
    if !(0..3).all(|k| min[k].is_finite() && max[k].is_finite() && min[k] <= max[k]) {
        return Err(cerr(
            "de_region",
            format!("min {min:?} must not exceed max {max:?} (finite)"),
        ));
    }
    if !(spec.width.is_finite() && spec.width > 0.0) {
        return Err(cerr(
            "width",
            format!("must be positive, got {}", spec.width),
        ));
    }
    if !(spec.penalty.is_finite() && spec.penalty > 0.0) {
        return Err(cerr(
            "penalty",
            format!("must be positive (Pa/m²), got {}", spec.penalty),
        ));
    }
    let w: Vec<f64> = mesh.nodes.iter().map(|x| node_weight(x, spec)).collect();
    let mut elements = Vec::new();
    let mut kind: Option<ElementKind> = None;
    for e in 0..mesh.num_elements() {
        let nodes = mesh.element_nodes(e);
        if !nodes.iter().any(|&n| w[n as usize] > 0.0) {
            continue;
        }
        if nodes.iter().all(|&n| w[n as usize] == 1.0) {
            return Err(FemError::Mesh {
                file: mesh.source.clone(),
                line: mesh.elem_lines[e],
                message: format!(
                    "element {} lies in fem.overlap.de_region, where the particles alone carry \
                     the load (its FE integrals would vanish): remove it from the mesh",
                    mesh.elem_ids[e]
                ),
            });
        }
        let k = mesh.kinds[e];
        match kind {
            None => kind = Some(k),
            Some(first) if shape_of(first) != shape_of(k) => {
                return Err(FemError::Mesh {
                    file: mesh.source.clone(),
                    line: mesh.elem_lines[e],
                    message: format!(
                        "element {} is a {} but the overlap's first element is a {}: the \
                         overlap needs one interpolation",
                        mesh.elem_ids[e],
                        k.name(),
                        first.name()
                    ),
                });
            }
            Some(_) => {}
        }
        elements.push(e);
    }
    let Some(kind) = kind else {
        return Err(cerr(
            "de_region",
            format!(
                "no element has a node within width {} of the box: the overlap is empty",
                spec.width
            ),
        ));
    };
    let mut nodes: Vec<u32> = elements
        .iter()
        .flat_map(|&e| mesh.element_nodes(e).iter().copied())
        .collect();
    nodes.sort_unstable();
    nodes.dedup();
    let mut local = vec![u32::MAX; mesh.num_nodes()];
    for (i, &n) in nodes.iter().enumerate() {
        local[n as usize] = i as u32;
    }
    let conn: Vec<u32> = elements
        .iter()
        .flat_map(|&e| mesh.element_nodes(e).iter().map(|&n| local[n as usize]))
        .collect();
    Ok(Overlap {
        shape: shape_of(kind),
        weights: nodes.iter().map(|&n| w[n as usize]).collect(),
        nodes,
        elements: conn,
        mesh_elements: elements,
        scale: w.iter().map(|w| 1.0 - w).collect(),
        penalty: spec.penalty,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::BoxSelector;
    use crate::mesh::box_mesh;

    fn spec(zmin: f64, width: f64) -> OverlapSpec {
        OverlapSpec {
            de_region: BoxSelector {
                min: [-10.0, -10.0, zmin],
                max: [10.0, 10.0, 20.0],
            },
            width,
            penalty: 1e14,
            carve: false,
        }
    }

    /// A 2 × 2 × 4 block of 1 m hexahedra under a particle region from z = 4 m: the top layer
    /// is the overlap with w = 1 on top, 0 one layer down; the FE mass is ρ ∫ (1 − w) dv.
    #[test]
    fn one_layer_overlap_weights_and_weighted_mass() {
        let mut mesh = box_mesh([0.0; 3], [2.0, 2.0, 4.0], [2, 2, 4], ElementKind::Hex8);
        let o = select(&mesh, &spec(4.0, 1.0)).unwrap();
        mesh.arlequin_scale = o.scale.clone();
        assert_eq!(o.shape, "hex8");
        assert_eq!(o.elements.len(), 4 * 8);
        assert_eq!(o.nodes.len(), 18);
        for (i, &n) in o.nodes.iter().enumerate() {
            let z = mesh.nodes[n as usize][2];
            assert_eq!(o.weights[i], if z == 4.0 { 1.0 } else { 0.0 });
        }
        // total consistent mass with ρ = 1: 3 full layers + the overlap's ∫(1 − w) = ½ layer
        let mut total = 0.0;
        let mut sc = Vec::new();
        for e in 0..mesh.num_elements() {
            let mut x = Vec::new();
            mesh.element_coords(e, &mut x);
            let mut m = Vec::new();
            crate::element::mass(
                mesh.kinds[e],
                &x,
                1.0,
                mesh.element_scale(e, &mut sc),
                &mut m,
            )
            .unwrap();
            total += m.iter().sum::<f64>();
        }
        assert!((total - (3.0 * 4.0 + 0.5 * 4.0)).abs() < 1e-12, "{total}");
    }

    /// A grid node one width below the particle box by round-off (0.015 − 0.01 = 0.00499…)
    /// has w = 0, so the layer beneath stays out of the overlap.
    #[test]
    fn a_node_one_width_away_by_round_off_is_out() {
        let mesh = box_mesh(
            [0.0; 3],
            [0.005, 0.005, 0.015],
            [2, 2, 6],
            ElementKind::Hex8,
        );
        let o = select(&mesh, &spec(0.015, 0.005)).unwrap();
        // two layers (z ∈ [10, 15] mm): nodes at z = 10, 12.5 and 15 mm
        assert_eq!(o.elements.len(), 2 * 4 * 8);
        for (i, &n) in o.nodes.iter().enumerate() {
            let z = mesh.nodes[n as usize][2];
            let want = ((z - 0.01) / 0.005).clamp(0.0, 1.0);
            assert!(
                (o.weights[i] - want).abs() < 1e-12,
                "z {z}: {}",
                o.weights[i]
            );
            if z < 0.0101 {
                assert_eq!(o.weights[i], 0.0);
            }
        }
        // and `carve` takes a layer whose lower face lies on the box by round-off (11 × 2.5 mm
        // against 27.5 mm)
        let mut mesh = box_mesh(
            [0.0; 3],
            [0.005, 0.005, 0.03],
            [2, 2, 12],
            ElementKind::Hex8,
        );
        let mut sp = spec(0.0275, 0.005);
        sp.carve = true;
        assert_eq!(carve(&mut mesh, &sp).unwrap(), 4);
        let o = select(&mesh, &sp).unwrap();
        assert_eq!(o.elements.len(), 2 * 4 * 8);
    }

    #[test]
    fn elements_in_the_particle_region_and_empty_overlaps_are_refused() {
        let mesh = box_mesh([0.0; 3], [2.0, 2.0, 4.0], [2, 2, 4], ElementKind::Hex8);
        let e = select(&mesh, &spec(3.0, 1.0)).unwrap_err().to_string();
        assert!(e.contains("lies in fem.overlap.de_region"), "{e}");
        let e = select(&mesh, &spec(10.0, 1.0)).unwrap_err().to_string();
        assert!(
            e.contains("fem.overlap.de_region") && e.contains("empty"),
            "{e}"
        );
        let e = select(&mesh, &spec(4.0, -1.0)).unwrap_err().to_string();
        assert!(e.contains("fem.overlap.width"), "{e}");
    }

    /// `carve` cuts a pocket for the particles out of a box mesh: a 4 × 4 × 4 block with the
    /// particles in its top-centre 2 × 2 × 2 elements loses those 8, keeps its element sets
    /// consistent, and the ring of elements around the pocket is the overlap.
    #[test]
    fn carve_cuts_a_pocket_and_the_ring_around_it_is_the_overlap() {
        let mut mesh = box_mesh([0.0; 3], [4.0, 4.0, 4.0], [4, 4, 4], ElementKind::Hex8);
        let all = mesh.elem_sets.get("all").map(|s| s.len());
        let mut sp = spec(2.0, 1.0);
        sp.de_region = BoxSelector {
            min: [1.0, 1.0, 2.0],
            max: [3.0, 3.0, 10.0],
        };
        // refused without carve, as before
        assert!(select(&mesh, &sp).is_err());
        sp.carve = true;
        assert_eq!(carve(&mut mesh, &sp).unwrap(), 8);
        assert_eq!(mesh.num_elements(), 56);
        assert_eq!(mesh.offsets.len(), 57);
        if let Some(n) = all {
            assert_eq!(mesh.elem_sets["all"].len(), n - 8);
        }
        for set in mesh.elem_sets.values() {
            assert!(set.iter().all(|&e| (e as usize) < 56));
        }
        // no element left with all its nodes in the pocket
        let o = select(&mesh, &sp).unwrap();
        // the overlap: the elements touching the pocket (w = 1 on its faces, 0 one element
        // away): the 4 × 4 × 2 upper half less the pocket, and the 4 × 4 layer under it
        assert_eq!(o.elements.len() / 8, 32 - 8 + 16);
        // nothing left to carve: an error says so
        let mut tiny = box_mesh(
            [1.0, 1.0, 2.0],
            [2.0, 2.0, 2.0],
            [1, 1, 1],
            ElementKind::Hex8,
        );
        let e = carve(&mut tiny, &sp).unwrap_err().to_string();
        assert!(e.contains("nothing is left"), "{e}");
    }
}
