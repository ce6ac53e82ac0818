//! The coupling interface: exterior surface extraction (Ullrich 3.3.1) and force transfer
//! (3.3.2: interface forces applied 1:1 as nodal forces).
#![allow(
    clippy::neg_cmp_op_on_partial_ord,
    clippy::needless_range_loop,
    clippy::nonminimal_bool
)]

mod common;
use common::*;
use std::collections::HashMap;

fn box_scene(element: &str, interface: &str) -> String {
    format!(
        r#"
[fem]
mesh = {{ size = [0.4, 0.2, 0.1], element_size = 0.05, element = "{element}" }}
{STEEL}
[[fem.supports]]
on = {{ set = "xmin" }}
{interface}
"#
    )
}

/// Every edge is shared by exactly two triangles with opposite orientation (closed, consistently
/// oriented), and the enclosed volume from the divergence theorem is +V (outward normals).
#[test]
fn extracted_surface_of_box_is_closed_and_outward() {
    for element in ["tet4", "tet10", "hex8", "hex20"] {
        let m = model(&box_scene(element, ""));
        let s = m.interface_mesh();
        let mut edges: HashMap<(u32, u32), i32> = HashMap::new();
        for t in s.triangles.chunks(3) {
            for k in 0..3 {
                *edges.entry((t[k], t[(k + 1) % 3])).or_default() += 1;
            }
        }
        for (&(a, b), &c) in &edges {
            assert_eq!(c, 1, "{element}: directed edge ({a},{b}) used {c} times");
            assert_eq!(
                edges.get(&(b, a)),
                Some(&1),
                "{element}: edge ({a},{b}) has no opposite"
            );
        }
        let p = |i: u32| {
            let i = i as usize;
            nalgebra::Vector3::new(
                s.positions[3 * i],
                s.positions[3 * i + 1],
                s.positions[3 * i + 2],
            )
        };
        let vol: f64 = s
            .triangles
            .chunks(3)
            .map(|t| p(t[0]).dot(&p(t[1]).cross(&p(t[2]))) / 6.0)
            .sum();
        println!(
            "{element}: {} triangles, {} nodes, volume {vol:.6e}",
            s.triangles.len() / 3,
            s.node_ids.len()
        );
        assert!(
            (vol - 0.4 * 0.2 * 0.1).abs() < 1e-12,
            "{element}: volume {vol}"
        );
        // quadratic faces are split with their mid-side nodes: every boundary node is on the surface
        let used: usize = m
            .mesh()
            .node_sets
            .iter()
            .filter(|(k, _)| k.len() == 4)
            .map(|(_, v)| v.len())
            .sum();
        assert!(s.node_ids.len() <= used);
    }
}

/// Σ interface forces + Σ reactions = 0 in a static solve (force and moment-free check of the
/// transfer), on a box-selected coupled part of the surface.
#[test]
fn interface_forces_balance_reactions() {
    let mut m = model(&box_scene(
        "hex20",
        "[fem.interface]\non = { box = { min = [0.1, -1.0, 0.1], max = [1.0, 1.0, 1.0] } }",
    ));
    let s = m.interface_mesh();
    let n = s.node_ids.len();
    assert!(n > 0);
    for i in 0..n {
        assert!((s.positions[3 * i + 2] - 0.1).abs() < 1e-12 && s.positions[3 * i] >= 0.1 - 1e-12);
    }
    let mut rng = Rng(99);
    let f: Vec<f64> = (0..3 * n).map(|_| 100.0 * rng.next()).collect();
    m.set_interface_forces(&f).unwrap();
    m.solve_static().unwrap();
    let r = m.reactions();
    let mut total = [0.0; 3];
    let mut scale: f64 = 0.0;
    for (i, v) in f.iter().enumerate() {
        total[i % 3] += v;
        scale = scale.max(v.abs());
    }
    let mut react = [0.0; 3];
    for (d, v) in r.iter().enumerate() {
        react[d % 3] += v;
    }
    for c in 0..3 {
        println!(
            "component {c}: applied {:.6e}, reaction {:.6e}",
            total[c], react[c]
        );
        assert!((total[c] + react[c]).abs() < 1e-9 * scale * n as f64);
    }
    let res = m.results();
    let get = |k: &str| res.iter().find(|(n, _)| n == k).unwrap().1;
    assert!((get("interface_force.z") - total[2]).abs() < 1e-9);
}

/// Kinematics: P = X + u at the interface nodes after a solve; wrong-length forces are refused.
#[test]
fn interface_kinematics_report_current_positions() {
    let mut m = model(&box_scene(
        "hex8",
        "[fem.interface]\non = { set = \"zmax\" }",
    ));
    let s = m.interface_mesh();
    let n = s.node_ids.len();
    assert!(m.set_interface_forces(&vec![0.0; 3 * n + 1]).is_err());
    let f: Vec<f64> = (0..n).flat_map(|_| [0.0, 0.0, -50.0]).collect();
    m.set_interface_forces(&f).unwrap();
    m.advance(1.0).unwrap();
    let (p, v, a) = m.interface_kinematics();
    let ids = m.mesh().node_index_map();
    for i in 0..n {
        let node = ids[&s.node_ids[i]] as usize;
        for c in 0..3 {
            assert_eq!(
                p[3 * i + c],
                s.positions[3 * i + c] + m.displacements()[3 * node + c]
            );
        }
    }
    assert!(p.iter().zip(&s.positions).any(|(a, b)| a != b));
    assert!(
        v.iter().chain(&a).all(|x| *x == 0.0),
        "static analysis reports zero V, A"
    );
    assert_eq!(m.time(), 1.0);
}
