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

/// `auto` above 20,000 equations: the mixed solver for a one-shot static solve, the f64
/// factor for a structure solved every window (`advance`), both with the f64 answer.
#[test]
fn auto_picks_the_f32_factor_for_a_one_shot_solve_and_the_f64_factor_for_windows() {
    // 88 × 10 × 10 nodes, both ends clamped: 25,800 equations
    let beam = a3_beam("hex8", 0.0115);
    let (direct, none) = solve(&with_solver(&beam, "direct"));
    assert!(none.is_none());
    let (auto, info) = solve(&beam);
    let info = info.expect("auto solved a one-shot static problem of 25,800 equations mixed");
    let d = max_rel_diff(&auto, &direct);
    println!("auto, one shot: {info:?}, max difference {d:.1e}");
    assert!(d < 1e-9, "{d:e}");
    let mut m = model(&beam);
    m.advance(1e-3).unwrap();
    assert!(
        m.last_mixed_solve().is_none(),
        "windows keep the f64 factor"
    );
    let d = max_rel_diff(m.displacements(), &direct);
    assert!(d < 1e-12, "{d:e}");
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

/// The elastic stiffness of a steel cantilever of hex8 elements (`div` along x, y, z),
/// clamped at x = 0: its pattern and values.
fn cantilever(div: [usize; 3], kind: fem::ElementKind) -> (fem::assembly::Pattern, Vec<f64>) {
    use fem::assembly::{assemble, ElementProps, Operator, Pattern};
    let mesh = fem::mesh::box_mesh([0.0; 3], [1.0, 0.1, 0.1], div, kind);
    let mut fixed = vec![false; 3 * mesh.num_nodes()];
    for (n, x) in mesh.nodes.iter().enumerate() {
        if x[0] == 0.0 {
            fixed[3 * n..3 * n + 3].fill(true);
        }
    }
    let (dofs, p) = Pattern::build(&mesh, &fixed).unwrap();
    let of = vec![0u32; mesh.num_elements()];
    let lame = [fem::element::Lame::from_young_poisson(210e9, 0.3)];
    let props = ElementProps {
        of: &of,
        lame: &lame,
        density: &[7850.0],
    };
    let k = assemble(&mesh, &dofs, &p, Operator::Stiffness, props).unwrap();
    (p, k)
}

/// The tree split (fem::tree_factor): the two halves under the top separator factorised
/// side by side and the dense separator give the whole factor's answer on a cantilever's
/// stiffness (the cancellation in the separator's Schur complement bounded), the separator
/// is a cross-section of the bar, and the answer is the same bit for bit on one thread and
/// on two.
#[test]
fn the_tree_split_factor_solves_a_cantilever_as_the_whole_factor_does() {
    use fem::assembly::{analyse, Factor};
    for kind in [fem::ElementKind::Hex8, fem::ElementKind::Tet10] {
        let div = if kind == fem::ElementKind::Hex8 {
            [60, 6, 6]
        } else {
            [40, 3, 3]
        };
        let (p, k) = cantilever(div, kind);
        // hex8: planned on the node graph's tree; the tet10 bar without its nodes, so in
        // its bisection order (AMD, which fills less on this small bar, has a long dense
        // chain at the top of its tree: no split pays there) and planned on the equations'
        let p = if kind == fem::ElementKind::Tet10 {
            fem::assembly::Pattern {
                node_first: Vec::new(),
                ..p
            }
        } else {
            p
        };
        // a tip load and a spread of small loads
        let b: Vec<f64> = (0..p.n)
            .map(|i| {
                if i + 3 >= p.n {
                    -1e3
                } else {
                    ((i * 13) % 7) as f64 - 3.0
                }
            })
            .collect();
        let mut whole_plan = Some(analyse(&p, 0..0).unwrap());
        assert!(whole_plan.as_ref().unwrap().split().is_none());
        let whole = Factor::new(&p, &k, &mut whole_plan).unwrap();
        assert!(!whole.is_split());
        let mut x_whole = b.clone();
        whole.solve_in_place(&mut x_whole);

        let mut plan = Some(analyse(&p, 0..usize::MAX).unwrap());
        let split = plan
            .as_ref()
            .unwrap()
            .split()
            .unwrap_or_else(|| panic!("{kind:?}: the bar's tree splits"));
        // the top separator of a bar is a cross-section: (div_y + 1)(div_z + 1) nodes for
        // hex8 (3 equations each), about 4× that for tet10's corner and mid-side nodes
        let section = 3 * (div[1] + 1) * (div[2] + 1);
        let bound = if kind == fem::ElementKind::Hex8 {
            section
        } else {
            4 * section
        };
        assert!(
            split.separator() > 0 && split.separator() <= bound,
            "{kind:?}: separator {} (a cross-section has {section} equations)",
            split.separator()
        );
        assert!(split.predicted < 0.75, "{}", split.predicted);
        // faer's relaxed supernodes join the last own columns with the separator's: the
        // substitutions' partial supernodes are exercised (one per half here)
        assert!(split.straddling_supernodes() > 0, "{kind:?}");
        let f = Factor::new(&p, &k, &mut plan).unwrap();
        assert!(f.is_split());
        // the mixed solver's f32 factor (of the scaled matrix) splits on the same plan: its
        // preconditioned CG reaches the whole factor's answer in about as many iterations as
        // the whole f32 factor takes
        let mixed = fem::assembly::MixedFactor::new(&p, &k, &mut plan).unwrap();
        assert!(mixed.is_split());
        let mut x_mixed = b.clone();
        let info = mixed.solve(&p, &k, &mut x_mixed, 1e-11, 1e-9, 200).unwrap();
        let diff = max_rel_diff(&x_mixed, &x_whole);
        assert!(
            diff < 1e-8,
            "{kind:?}: split f32 + CG vs whole f64 {diff:e}"
        );
        let mixed_whole = fem::assembly::MixedFactor::new(&p, &k, &mut whole_plan).unwrap();
        assert!(!mixed_whole.is_split());
        let mut x_mw = b.clone();
        let info_whole = mixed_whole
            .solve(&p, &k, &mut x_mw, 1e-11, 1e-9, 200)
            .unwrap();
        assert!(
            info.iterations <= info_whole.iterations + 1,
            "{kind:?}: {} iterations with the split f32 factor, {} with the whole",
            info.iterations,
            info_whole.iterations
        );
        let mut x = b.clone();
        f.solve_in_place(&mut x);
        let diff = max_rel_diff(&x, &x_whole);
        assert!(diff < 1e-9, "{kind:?}: split vs whole {diff:e}");
        let mut ax = vec![0.0; p.n];
        p.mul(&k, &x, &mut ax);
        let scale = p.norm_inf(&k) * x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let res = ax
            .iter()
            .zip(&b)
            .fold(0.0f64, |m, (a, c)| m.max((a - c).abs()))
            / scale;
        assert!(res < 1e-13, "{kind:?}: backward error {res:e}");

        // the same bits on one thread and on two
        let on = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| {
                    let mut plan = Some(analyse(&p, 0..usize::MAX).unwrap());
                    let f = Factor::new(&p, &k, &mut plan).unwrap();
                    let mut x = b.clone();
                    f.solve_in_place(&mut x);
                    let mixed = fem::assembly::MixedFactor::new(&p, &k, &mut plan).unwrap();
                    let mut xm = b.clone();
                    mixed.solve(&p, &k, &mut xm, 1e-11, 1e-9, 200).unwrap();
                    (x, xm)
                })
        };
        let same = |u: &[f64], v: &[f64]| u.iter().zip(v).all(|(a, c)| a.to_bits() == c.to_bits());
        let ((x1, xm1), (x2, xm2)) = (on(1), on(2));
        assert!(same(&x1, &x2) && same(&x1, &x));
        assert!(same(&xm1, &xm2) && same(&xm1, &x_mixed));
    }
}

/// The split is planned only where it can pay: a factor below the size range stays whole,
/// and a matrix whose elimination tree is a path (a chain of springs) has no branch to split.
#[test]
fn the_tree_split_is_planned_only_where_it_pays() {
    use fem::assembly::{analyse, ensure_symbolic, Factor, Pattern, SPLIT_FROM};
    let (p, k) = cantilever([20, 2, 2], fem::ElementKind::Hex8);
    let mut sym = None;
    let plan = ensure_symbolic(&p, &mut sym).unwrap();
    assert!(plan.factor_nnz() < SPLIT_FROM);
    assert!(plan.split().is_none());
    assert!(!Factor::new(&p, &k, &mut sym).unwrap().is_split());
    // a chain of 2,000 springs: tridiagonal, eliminated in order, its tree a path
    let n = 2000usize;
    let (mut col_ptr, mut row_idx) = (vec![0u32], Vec::new());
    for j in 0..n {
        row_idx.extend((j.saturating_sub(1)..(j + 2).min(n)).map(|i| i as u32));
        col_ptr.push(row_idx.len() as u32);
    }
    let chain = Pattern {
        n,
        col_ptr,
        row_idx,
        order: (0..n as u32).collect(),
        elem_order: Vec::new(),
        node_first: Vec::new(),
        anchors: Vec::new(),
    };
    let vals: Vec<f64> = (0..n)
        .flat_map(|j| {
            (j.saturating_sub(1)..(j + 2).min(n)).map(move |i| if i == j { 2.5 } else { -1.0 })
        })
        .collect();
    let plan = analyse(&chain, 0..usize::MAX).unwrap();
    assert!(plan.split().is_none());
    let mut sym = Some(plan);
    let f = Factor::new(&chain, &vals, &mut sym).unwrap();
    assert!(!f.is_split());
    let mut x = vec![1.0; n];
    f.solve_in_place(&mut x);
    let mut ax = vec![0.0; n];
    chain.mul(&vals, &x, &mut ax);
    assert!(max_rel_diff(&ax, &vec![1.0; n]) < 1e-12);
}

/// Two bodies in one model (two cubes apart): the elimination tree is a forest, the split
/// takes one body per half with an empty separator, and solves as the whole factor does.
#[test]
fn the_tree_split_of_two_separate_bodies_has_an_empty_separator() {
    use fem::assembly::{analyse, Factor, Pattern};
    let (mut coords, mut cells) = grid(10);
    let n0 = coords.len() as u32;
    let shifted: Vec<[f64; 3]> = coords.iter().map(|x| [x[0] + 100.0, x[1], x[2]]).collect();
    let more: Vec<[u32; 8]> = cells.iter().map(|c| c.map(|i| i + n0)).collect();
    coords.extend(shifted);
    cells.extend(more);
    // each cube held at its x = min face
    let mut fixed = vec![false; 3 * coords.len()];
    for (n, x) in coords.iter().enumerate() {
        if x[0] == 0.0 || x[0] == 100.0 {
            fixed[3 * n..3 * n + 3].fill(true);
        }
    }
    let used = vec![true; coords.len()];
    let (_, p) =
        Pattern::for_elements(&coords, cells.len(), |e| &cells[e][..], &fixed, &used, 3).unwrap();
    let vals = spd_values(&p);
    let b: Vec<f64> = (0..p.n).map(|i| ((i * 29) % 13) as f64 - 6.0).collect();
    let mut plan = Some(analyse(&p, 0..usize::MAX).unwrap());
    let split = plan.as_ref().unwrap().split().expect("two bodies split");
    assert_eq!(split.separator(), 0);
    let f = Factor::new(&p, &vals, &mut plan).unwrap();
    assert!(f.is_split());
    let mut x = b.clone();
    f.solve_in_place(&mut x);
    let mut whole_plan = Some(analyse(&p, 0..0).unwrap());
    let whole = Factor::new(&p, &vals, &mut whole_plan).unwrap();
    let mut x_whole = b.clone();
    whole.solve_in_place(&mut x_whole);
    assert!(max_rel_diff(&x, &x_whole) < 1e-12);
    let mut ax = vec![0.0; p.n];
    p.mul(&vals, &x, &mut ax);
    assert!(max_rel_diff(&ax, &b) < 1e-12);
    // the f32 factor of the mixed solver splits the same way
    let mixed = fem::assembly::MixedFactor::new(&p, &vals, &mut plan).unwrap();
    assert!(mixed.is_split());
    let mut xm = b.clone();
    let info = mixed.solve(&p, &vals, &mut xm, 1e-11, 1e-9, 200).unwrap();
    assert!(max_rel_diff(&xm, &x_whole) < 1e-9);
    // as good a preconditioner as the whole f32 factor
    let whole_mixed = fem::assembly::MixedFactor::new(&p, &vals, &mut whole_plan).unwrap();
    let mut xw = b.clone();
    let info_whole = whole_mixed
        .solve(&p, &vals, &mut xw, 1e-11, 1e-9, 200)
        .unwrap();
    assert!(
        info.iterations <= info_whole.iterations,
        "{} iterations split, {} whole",
        info.iterations,
        info_whole.iterations
    );
}
