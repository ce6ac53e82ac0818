//! `[fem] solver`: the mixed-precision static solver (f32 Cholesky factor preconditioning f64
//! conjugate gradients) gives the f64 factor's answer, and falls back to it where single
//! precision cannot carry the problem.
mod common;
use common::*;

fn with_solver(scene: &str, solver: &str) -> String {
    scene.replacen("[fem]\n", &format!("[fem]\nsolver = \"{solver}\"\n"), 1)
}

/// Every free displacement component of a static solve, node-major.
fn solve(scene: &str) -> (Vec<f64>, Option<fem::assembly::RefinedSolve>) {
    let mut m = model(scene);
    m.solve_static().unwrap();
    (m.displacements().to_vec(), m.last_mixed_solve())
}

fn max_rel_diff(a: &[f64], b: &[f64]) -> f64 {
    let scale = b.iter().fold(0.0f64, |s, v| s.max(v.abs()));
    a.iter()
        .zip(b)
        .fold(0.0f64, |s, (x, y)| s.max((x - y).abs()))
        / scale
}

#[test]
fn mixed_precision_solve_gives_the_f64_answer_on_the_a3_beam() {
    let beam = a3_beam("hex8", 0.025);
    let (direct, none) = solve(&with_solver(&beam, "direct"));
    assert!(none.is_none());
    let (mixed, info) = solve(&with_solver(&beam, "mixed"));
    let info = info.expect("the mixed solver was used");
    let d = max_rel_diff(&mixed, &direct);
    println!(
        "hex8 25 mm: {} PCG iterations, relative residual {:.1e}, max difference {d:.1e} of the \
         largest displacement",
        info.iterations, info.relative_residual
    );
    assert!(info.iterations <= 20, "{info:?}");
    assert!(info.relative_residual <= 1e-9, "{info:?}");
    assert!(d < 1e-9, "{d:e}");
    // `auto` keeps the f64 factor for small systems
    let (auto, none) = solve(&beam);
    assert!(none.is_none());
    assert_eq!(auto, direct);
}

/// A 1 m × 2 mm × 2 mm cantilever (κ(K) ~ (L/t)⁴): single precision cannot factor or
/// precondition it: the solver falls back to the f64 factor and gives its answer exactly.
#[test]
fn mixed_precision_solve_falls_back_to_f64_on_an_ill_conditioned_cantilever() {
    let scene = format!(
        r#"
[fem]
mesh = {{ size = [1.0, 0.002, 0.002], element_size = 0.002, element = "hex8i" }}
{STEEL}
[[fem.supports]]
on = {{ set = "xmin" }}
[[fem.loads]]
type = "gravity"
acceleration = [0.0, 0.0, -9.81]
"#
    );
    let (direct, _) = solve(&with_solver(&scene, "direct"));
    let (mixed, info) = solve(&with_solver(&scene, "mixed"));
    let d = max_rel_diff(&mixed, &direct);
    println!("thin cantilever: mixed path {info:?}, max difference {d:.1e}");
    assert!(info.is_none(), "fell back to the f64 factor: {info:?}");
    assert_eq!(d, 0.0);
}

#[test]
fn an_unknown_solver_is_a_scene_error_naming_the_choices() {
    let err = fem::parse_scene_section(&with_solver(&a3_beam("hex8", 0.05), "lu"))
        .unwrap_err()
        .to_string();
    println!("{err}");
    assert!(err.contains("solver") || err.contains("`lu`"), "{err}");
    assert!(err.contains("direct") && err.contains("mixed"), "{err}");
}

/// The nodes of an n×n×n grid of hex8 cells, and the cells.
fn grid(n: usize) -> (Vec<[f64; 3]>, Vec<[u32; 8]>) {
    let id = |i: usize, j: usize, k: usize| (i + (n + 1) * (j + (n + 1) * k)) as u32;
    let mut coords = Vec::new();
    for k in 0..=n {
        for j in 0..=n {
            for i in 0..=n {
                coords.push([i as f64, j as f64, k as f64]);
            }
        }
    }
    let mut cells = Vec::new();
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                cells.push([
                    id(i, j, k),
                    id(i + 1, j, k),
                    id(i + 1, j + 1, k),
                    id(i, j + 1, k),
                    id(i, j, k + 1),
                    id(i + 1, j, k + 1),
                    id(i + 1, j + 1, k + 1),
                    id(i, j + 1, k + 1),
                ]);
            }
        }
    }
    (coords, cells)
}

/// A symmetric positive definite matrix on `p`: diagonally dominant, off-diagonals from the
/// row and column numbers (not a multiple of the identity: the solve must use the pattern).
fn spd_values(p: &fem::assembly::Pattern) -> Vec<f64> {
    let mut vals = vec![0.0; p.nnz()];
    for j in 0..p.n {
        let (a, b) = (p.col_ptr[j] as usize, p.col_ptr[j + 1] as usize);
        for (v, &i) in vals[a..b].iter_mut().zip(&p.row_idx[a..b]) {
            let i = i as usize;
            *v = if i == j {
                2.0 * (b - a) as f64
            } else {
                -1.0 / (1.0 + ((i + j) % 7) as f64)
            };
        }
    }
    vals
}

/// The AMD safeguard: where coordinate bisection is poor (here the grid's coordinates are
/// shuffled among its nodes, so the geometric separators cut nothing), the factor takes the
/// minimum-degree order of the node graph or METIS's dissection, whichever fills least; the
/// orders give the same solution, and the chosen factor is never fuller than any of them.
#[test]
fn the_amd_safeguard_replaces_nested_dissection_where_bisection_is_poor() {
    use fem::assembly::{Factor, Pattern};
    let (mut coords, cells) = grid(8);
    // a fixed shuffle of the coordinates (an LCG), keeping the connectivity
    let mut state = 12345u64;
    for i in (1..coords.len()).rev() {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        coords.swap(i, (state >> 33) as usize % (i + 1));
    }
    let nd = 3 * coords.len();
    let mut fixed = vec![false; nd];
    fixed[..3 * 81].fill(true); // the face k = 0
    let used = vec![true; coords.len()];
    let (_, p) =
        Pattern::for_elements(&coords, cells.len(), |e| &cells[e][..], &fixed, &used, 3).unwrap();
    let amd = fem::assembly::amd_order(&p).expect("AMD order");
    let mut sorted = amd.clone();
    sorted.sort_unstable();
    assert_eq!(sorted, (0..p.n as u32).collect::<Vec<_>>(), "a permutation");
    let vals = spd_values(&p);
    let b: Vec<f64> = (0..p.n).map(|i| ((i * 37) % 11) as f64 - 5.0).collect();

    // a pattern without its node ranges keeps its own order (bisection)
    let nd_only = Pattern {
        node_first: Vec::new(),
        ..p.clone()
    };
    let amd_only = Pattern {
        order: amd,
        node_first: Vec::new(),
        ..p.clone()
    };
    let mut x_nd = b.clone();
    let f_nd = Factor::new(&nd_only, &vals, &mut None).unwrap();
    f_nd.solve_in_place(&mut x_nd);
    let mut x_amd = b.clone();
    let f_amd = Factor::new(&amd_only, &vals, &mut None).unwrap();
    f_amd.solve_in_place(&mut x_amd);
    let chosen = Factor::new(&p, &vals, &mut None).unwrap();
    assert!(
        f_amd.factor_nnz() * 3 < f_nd.factor_nnz() * 2,
        "shuffled coordinates: AMD fill {} should be well below bisection's {}",
        f_amd.factor_nnz(),
        f_nd.factor_nnz()
    );
    // METIS (tried because AMD beat bisection) works on the graph alone, so the shuffle
    // does not hurt it either
    let metis = fem::assembly::metis_order(&p).expect("METIS ordering");
    let mut sorted = metis.clone();
    sorted.sort_unstable();
    assert_eq!(sorted, (0..p.n as u32).collect::<Vec<_>>(), "a permutation");
    let metis_only = Pattern {
        order: metis,
        node_first: Vec::new(),
        ..p.clone()
    };
    let f_metis = Factor::new(&metis_only, &vals, &mut None).unwrap();
    println!(
        "fill: bisection {}, AMD {}, METIS {}, chosen {}",
        f_nd.factor_nnz(),
        f_amd.factor_nnz(),
        f_metis.factor_nnz(),
        chosen.factor_nnz()
    );
    assert!(f_metis.factor_nnz() * 3 < f_nd.factor_nnz() * 2);
    // the choice is made on the node graph, whose fill ranks the orders as the equations'
    // does up to the supernodes' padding
    let least = f_amd.factor_nnz().min(f_metis.factor_nnz());
    assert!(
        chosen.factor_nnz() * 100 <= least * 105,
        "{}",
        chosen.factor_nnz()
    );
    assert!(max_rel_diff(&x_amd, &x_nd) < 1e-12);
    // and A x = b
    let mut ax = vec![0.0; p.n];
    p.mul(&vals, &x_amd, &mut ax);
    assert!(max_rel_diff(&ax, &b) < 1e-12);

    // on the true coordinates bisection is kept when it fills less
    let (coords, _) = grid(8);
    let (_, p) =
        Pattern::for_elements(&coords, cells.len(), |e| &cells[e][..], &fixed, &used, 3).unwrap();
    let vals = spd_values(&p);
    let nd_only = Pattern {
        node_first: Vec::new(),
        ..p.clone()
    };
    let chosen = Factor::new(&p, &vals, &mut None).unwrap();
    let f_nd = Factor::new(&nd_only, &vals, &mut None).unwrap();
    assert!(chosen.factor_nnz() <= f_nd.factor_nnz());
}

/// Quadratic meshes: METIS orders the corners only, and every mid-side node is eliminated just
/// before the earlier of its two ends (no fill of its own); the order is a permutation and its
/// factor solves the system.
#[test]
fn metis_on_a_tet10_mesh_orders_the_corners_and_places_each_midside_node_before_its_ends() {
    use fem::assembly::{Factor, Pattern};
    let mesh = fem::mesh::box_mesh(
        [0.0; 3],
        [1.0, 0.6, 0.4],
        [5, 3, 2],
        fem::ElementKind::Tet10,
    );
    let mut fixed = vec![false; 3 * mesh.num_nodes()];
    for (n, x) in mesh.nodes.iter().enumerate() {
        if x[0] == 0.0 {
            fixed[3 * n..3 * n + 3].fill(true);
        }
    }
    let (_, p) = Pattern::build(&mesh, &fixed).unwrap();
    assert_eq!(p.anchors.len(), p.node_first.len() - 1);
    let midside = p.anchors.iter().filter(|a| a[0] != u32::MAX).count();
    assert!(midside > 0 && midside < p.anchors.len());
    // every free mid-side node of this mesh has both ends free, except on the fixed face
    assert!(
        p.anchors
            .iter()
            .filter(|a| a[0] != u32::MAX && a[1] != u32::MAX)
            .count()
            > midside / 2
    );
    let order = fem::assembly::metis_order(&p).expect("METIS ordering");
    let mut sorted = order.clone();
    sorted.sort_unstable();
    assert_eq!(sorted, (0..p.n as u32).collect::<Vec<_>>(), "a permutation");
    // node positions in the order (node i owns equations node_first[i]..)
    let node_of_eq = |e: u32| p.node_first.partition_point(|&f| f <= e) - 1;
    let mut pos = vec![usize::MAX; p.anchors.len()];
    for (k, &e) in order.iter().enumerate() {
        let node = node_of_eq(e);
        if pos[node] == usize::MAX {
            pos[node] = k;
        }
    }
    for (i, a) in p.anchors.iter().enumerate() {
        if a[0] == u32::MAX {
            continue;
        }
        let ends: Vec<usize> = a
            .iter()
            .filter(|&&x| x != u32::MAX)
            .map(|&x| pos[x as usize])
            .collect();
        let first_end = *ends.iter().min().unwrap();
        assert!(pos[i] < first_end, "mid-side node {i} after its end");
    }
    // and its factor solves
    let vals = spd_values(&p);
    let b: Vec<f64> = (0..p.n).map(|i| ((i * 13) % 7) as f64 - 3.0).collect();
    let metis_only = Pattern {
        order,
        node_first: Vec::new(),
        ..p.clone()
    };
    let f = Factor::new(&metis_only, &vals, &mut None).unwrap();
    let mut x = b.clone();
    f.solve_in_place(&mut x);
    let mut ax = vec![0.0; p.n];
    p.mul(&vals, &x, &mut ax);
    assert!(max_rel_diff(&ax, &b) < 1e-12);
}
