//! Constant-strain patch tests (form B: boundary displacements prescribed from a linear field,
//! interior solved) on distorted meshes, for every element formulation.
#![allow(
    clippy::neg_cmp_op_on_partial_ord,
    clippy::needless_range_loop,
    clippy::nonminimal_bool
)]

mod common;
use common::*;
use fem::{mesh::box_mesh, ElementKind, Model};

const SIDES: [&str; 6] = ["xmin", "xmax", "ymin", "ymax", "zmin", "zmax"];

/// Box mesh with interior corner nodes moved randomly by up to ±`amp`·h per direction;
/// mid-side nodes of quadratic elements are re-centred on their (straight) edges.
fn distorted(kind: ElementKind, div: usize, amp: f64, seed: u64) -> fem::Mesh {
    let mut mesh = box_mesh([0.0; 3], [1.0, 1.2, 0.9], [div; 3], kind);
    let mut on_boundary = vec![false; mesh.num_nodes()];
    for s in SIDES {
        for &n in &mesh.node_sets[s] {
            on_boundary[n as usize] = true;
        }
    }
    let h = 1.0 / div as f64;
    let mut rng = Rng(seed);
    let nc = kind.num_corners();
    let mut is_corner = vec![false; mesh.num_nodes()];
    for e in 0..mesh.num_elements() {
        for &n in &mesh.element_nodes(e)[..nc] {
            is_corner[n as usize] = true;
        }
    }
    for n in 0..mesh.num_nodes() {
        if is_corner[n] && !on_boundary[n] {
            for k in 0..3 {
                mesh.nodes[n][k] += 2.0 * amp * h * rng.next();
            }
        }
    }
    let edges: &[(usize, usize)] = match kind {
        ElementKind::Tet10 => &[(0, 1), (1, 2), (2, 0), (0, 3), (1, 3), (2, 3)],
        ElementKind::Hex20 => &[
            (0, 1),
            (1, 2),
            (2, 3),
            (3, 0),
            (4, 5),
            (5, 6),
            (6, 7),
            (7, 4),
            (0, 4),
            (1, 5),
            (2, 6),
            (3, 7),
        ],
        _ => &[],
    };
    for e in 0..mesh.num_elements() {
        let en = mesh.element_nodes(e).to_vec();
        for (m, &(a, b)) in edges.iter().enumerate() {
            let (xa, xb) = (mesh.nodes[en[a] as usize], mesh.nodes[en[b] as usize]);
            mesh.nodes[en[nc + m] as usize] = [
                0.5 * (xa[0] + xb[0]),
                0.5 * (xa[1] + xb[1]),
                0.5 * (xa[2] + xb[2]),
            ];
        }
    }
    mesh
}

fn patch_config() -> String {
    let mut s = format!(
        "[fem]\nmesh = {{ size = [1, 1, 1], divisions = [1, 1, 1], element = \"hex8\" }}\n{STEEL}"
    );
    for side in SIDES {
        s.push_str(&format!("[[fem.supports]]\non = {{ set = \"{side}\" }}\n"));
    }
    s
}

/// u(x) = u0 + G x: constant strain plus rigid rotation.
const G: [[f64; 3]; 3] = [
    [1.0e-3, 2.0e-4, -3.0e-4],
    [-1.0e-4, -5.0e-4, 4.0e-4],
    [2.5e-4, 1.5e-4, 7.0e-4],
];
const U0: [f64; 3] = [1e-4, -2e-4, 3e-4];

fn linear_field(x: [f64; 3]) -> [f64; 3] {
    let mut u = U0;
    for i in 0..3 {
        for j in 0..3 {
            u[i] += G[i][j] * x[j];
        }
    }
    u
}

fn run_patch(kind: ElementKind, div: usize) -> (f64, f64) {
    run_patch_with(kind, div, "")
}

/// The patch test with extra scene text (e.g. `[fem.newton] always = true`).
fn run_patch_with(kind: ElementKind, div: usize, extra: &str) -> (f64, f64) {
    let mesh = distorted(kind, div, 0.2, 0x1234_5678 + div as u64);
    let cfg = config(&format!("{}{extra}", patch_config()));
    let mut model = Model::from_mesh(&cfg, mesh).expect("model");
    for n in 0..model.mesh().num_nodes() {
        let u = linear_field(model.mesh().nodes[n]);
        for c in 0..3 {
            if model.is_fixed(3 * n + c) {
                model.set_prescribed_displacement(3 * n + c, u[c]).unwrap();
            }
        }
    }
    assert!(
        model.num_equations() > 0,
        "{kind:?}: patch has interior dofs"
    );
    model.solve_static().unwrap();
    let u = model.displacements();
    let mut err_u: f64 = 0.0;
    for n in 0..model.mesh().num_nodes() {
        let exact = linear_field(model.mesh().nodes[n]);
        for c in 0..3 {
            err_u = err_u.max((u[3 * n + c] - exact[c]).abs());
        }
    }
    // σ = λ tr ε I + 2 μ ε (2.37)
    let (e, nu) = (210e9, 0.3);
    let lam = e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
    let mu = e / (2.0 * (1.0 + nu));
    let eps = |i: usize, j: usize| 0.5 * (G[i][j] + G[j][i]);
    let tr = eps(0, 0) + eps(1, 1) + eps(2, 2);
    let exact = [
        lam * tr + 2.0 * mu * eps(0, 0),
        lam * tr + 2.0 * mu * eps(1, 1),
        lam * tr + 2.0 * mu * eps(2, 2),
        2.0 * mu * eps(0, 1),
        2.0 * mu * eps(1, 2),
        2.0 * mu * eps(2, 0),
    ];
    let smax = exact.iter().fold(0.0f64, |a, b| a.max(b.abs()));
    let mut err_s: f64 = 0.0;
    for s in model.element_stresses() {
        for c in 0..6 {
            err_s = err_s.max((s[c] - exact[c]).abs() / smax);
        }
    }
    (err_u / 1.5e-3, err_s)
}

fn assert_patch(kind: ElementKind, div: usize) {
    let (eu, es) = run_patch(kind, div);
    println!("{kind:?}: relative displacement error {eu:.2e}, stress error {es:.2e}");
    assert!(eu < 1e-10, "{kind:?}: displacement error {eu:e}");
    assert!(es < 1e-10, "{kind:?}: stress error {es:e}");
}

#[test]
fn patch_test_tet4_constant_strain_exact() {
    assert_patch(ElementKind::Tet4, 3);
}

#[test]
fn patch_test_tet10_constant_strain_exact() {
    assert_patch(ElementKind::Tet10, 3);
}

#[test]
fn patch_test_hex8_constant_strain_exact() {
    assert_patch(ElementKind::Hex8, 3);
}

#[test]
fn patch_test_hex8_incompatible_constant_strain_exact() {
    assert_patch(ElementKind::Hex8i, 3);
}

#[test]
fn patch_test_hex8_bbar_constant_strain_exact() {
    assert_patch(ElementKind::Hex8b, 3);
}

#[test]
fn patch_test_hex20_constant_strain_exact() {
    assert_patch(ElementKind::Hex20, 3);
}

#[test]
fn distortion_is_real() {
    // the patch meshes above are genuinely distorted: all 8 interior corners of the 3×3×3
    // box are moved off the regular grid
    let mesh = distorted(ElementKind::Hex8, 3, 0.2, 0x1234_5678 + 3);
    let reg = box_mesh([0.0; 3], [1.0, 1.2, 0.9], [3; 3], ElementKind::Hex8);
    let moved = mesh
        .nodes
        .iter()
        .zip(&reg.nodes)
        .filter(|(a, b)| a != b)
        .count();
    assert_eq!(moved, 8, "the 8 interior corner nodes are moved");
}

/// The same patch tests through the stress-based path and Newton iterations (issue 17):
/// a linear material gives the linear field exactly there too (hex8i has no such path).
#[test]
fn patch_tests_through_the_newton_path() {
    let newton = "[fem.newton]\nalways = true\nforce_tolerance = 1e-12\n";
    for (kind, div) in [
        (ElementKind::Tet4, 3),
        (ElementKind::Tet10, 3),
        (ElementKind::Hex8, 3),
        (ElementKind::Hex8b, 3),
        (ElementKind::Hex20, 3),
    ] {
        let (eu, es) = run_patch_with(kind, div, newton);
        println!("{kind:?} (Newton path): displacement error {eu:.2e}, stress error {es:.2e}");
        assert!(eu < 1e-10 && es < 1e-10, "{kind:?}: {eu:e} {es:e}");
    }
}
