//! The MITC4 shell element (`fem::shell`): rigid-body modes and rank, the membrane and bending
//! patch tests, a cantilever plate against beam theory down to thickness/length 1e-3 (no shear
//! locking), and the Scordelis–Lo roof against its reference value.

#![allow(clippy::needless_range_loop)]

use fem::shell::{self, Geometry, Material, DOFS};
use nalgebra::{DMatrix, DVector, SymmetricEigen};

/// A mesh of quadrilateral shells with a dense global system (6 dofs per node).
struct Shells {
    x: Vec<[f64; 3]>,
    quads: Vec<[usize; 4]>,
    thickness: f64,
    mat: Material,
}

impl Shells {
    /// Directors: the normals of the elements at a node, averaged.
    fn directors(&self) -> Vec<[f64; 3]> {
        let mut d = vec![[0.0; 3]; self.x.len()];
        for q in &self.quads {
            let n = shell::corner_normals(&q.map(|i| self.x[i]));
            for (k, &i) in q.iter().enumerate() {
                for c in 0..3 {
                    d[i][c] += n[k][c];
                }
            }
        }
        for v in &mut d {
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            *v = v.map(|c| c / l);
        }
        d
    }

    fn geometry(&self, q: &[usize; 4], d: &[[f64; 3]]) -> Geometry {
        Geometry {
            x: q.map(|i| self.x[i]),
            director: q.map(|i| d[i]),
            thickness: self.thickness,
        }
    }

    fn stiffness(&self) -> DMatrix<f64> {
        let n = 6 * self.x.len();
        let d = self.directors();
        let mut k = DMatrix::zeros(n, n);
        for q in &self.quads {
            let ke = shell::stiffness(&self.geometry(q, &d), self.mat);
            for a in 0..DOFS {
                for b in 0..DOFS {
                    k[(6 * q[a / 6] + a % 6, 6 * q[b / 6] + b % 6)] += ke[a][b];
                }
            }
        }
        k
    }

    /// The consistent nodal forces of an area load q (force per area).
    fn area_load(&self, q: [f64; 3]) -> DVector<f64> {
        let d = self.directors();
        let mut f = DVector::zeros(6 * self.x.len());
        for quad in &self.quads {
            let fe = shell::area_load(&self.geometry(quad, &d), q);
            for a in 0..DOFS {
                f[6 * quad[a / 6] + a % 6] += fe[a];
            }
        }
        f
    }

    /// Solves K u = f with the dofs of `fixed` held at their values, by the FEM's sparse
    /// Cholesky (faer) on a pattern of the shells' six dofs per node.
    fn solve(&self, f: &DVector<f64>, fixed: &[(usize, f64)]) -> DVector<f64> {
        use std::collections::BTreeMap;
        let n = 6 * self.x.len();
        let mut held = vec![None; n];
        for &(d, v) in fixed {
            held[d] = Some(v);
        }
        let mut eq = vec![u32::MAX; n];
        let mut m = 0u32;
        for d in 0..n {
            if held[d].is_none() {
                eq[d] = m;
                m += 1;
            }
        }
        let mut b: Vec<f64> = (0..n)
            .filter(|&i| held[i].is_none())
            .map(|i| f[i])
            .collect();
        let d = self.directors();
        // columns of the free equations: (row → value), both triangles; held dofs move to b
        let mut cols: Vec<BTreeMap<u32, f64>> = vec![BTreeMap::new(); m as usize];
        for q in &self.quads {
            let ke = shell::stiffness(&self.geometry(q, &d), self.mat);
            for a in 0..DOFS {
                let ea = eq[6 * q[a / 6] + a % 6];
                if ea == u32::MAX {
                    continue;
                }
                for c in 0..DOFS {
                    let dof = 6 * q[c / 6] + c % 6;
                    match held[dof] {
                        Some(v) => b[ea as usize] -= ke[a][c] * v,
                        None => *cols[eq[dof] as usize].entry(ea).or_insert(0.0) += ke[a][c],
                    }
                }
            }
        }
        let mut col_ptr = vec![0u32];
        let mut row_idx = Vec::new();
        let mut vals = Vec::new();
        for c in &cols {
            for (&r, &v) in c {
                row_idx.push(r);
                vals.push(v);
            }
            col_ptr.push(row_idx.len() as u32);
        }
        let pattern = fem::assembly::Pattern {
            n: m as usize,
            col_ptr,
            row_idx,
            order: (0..m).collect(),
            elem_order: Vec::new(),
            node_first: Vec::new(),
            anchors: Vec::new(),
        };
        let factor = fem::assembly::Factor::new(&pattern, &vals, &mut None)
            .expect("the constrained stiffness is positive definite");
        factor.solve_in_place(&mut b);
        DVector::from_fn(n, |i, _| held[i].unwrap_or_else(|| b[eq[i] as usize]))
    }
}

/// A structured grid of nx × ny quads mapping (ξ, η) ∈ [0, 1]² through `map`.
fn grid(
    nx: usize,
    ny: usize,
    map: impl Fn(f64, f64) -> [f64; 3],
) -> (Vec<[f64; 3]>, Vec<[usize; 4]>) {
    let mut x = Vec::new();
    for j in 0..=ny {
        for i in 0..=nx {
            x.push(map(i as f64 / nx as f64, j as f64 / ny as f64));
        }
    }
    let id = |i: usize, j: usize| j * (nx + 1) + i;
    let mut q = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            q.push([id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    (x, q)
}

const STEEL: Material = Material {
    youngs_modulus: 2.1e11,
    poisson_ratio: 0.3,
};

#[test]
fn a_warped_element_has_six_rigid_modes_and_no_spurious_one() {
    let x = [
        [0.0, 0.0, 0.0],
        [1.2, 0.1, 0.05],
        [1.1, 0.9, -0.04],
        [-0.1, 1.0, 0.03],
    ];
    for thickness in [0.1, 1e-3] {
        let geo = Geometry {
            x,
            director: shell::corner_normals(&x),
            thickness,
        };
        let ke = shell::stiffness(&geo, STEEL);
        let k = DMatrix::from_fn(DOFS, DOFS, |a, b| ke[a][b]);
        let asym = (&k - k.transpose()).amax() / k.amax();
        assert!(asym < 1e-12, "symmetric: {asym}");
        // rigid motions u = c + ω × x, θ = ω: no force
        for m in 0..6 {
            let mut q = DVector::zeros(DOFS);
            for i in 0..4 {
                let mut w = [0.0; 3];
                if m < 3 {
                    q[6 * i + m] = 1.0;
                    continue;
                }
                w[m - 3] = 1.0;
                let xi = x[i];
                let u = [
                    w[1] * xi[2] - w[2] * xi[1],
                    w[2] * xi[0] - w[0] * xi[2],
                    w[0] * xi[1] - w[1] * xi[0],
                ];
                for c in 0..3 {
                    q[6 * i + c] = u[c];
                    q[6 * i + 3 + c] = w[c];
                }
            }
            let f = &k * &q;
            assert!(
                f.amax() < 1e-9 * k.amax(),
                "mode {m}: {}",
                f.amax() / k.amax()
            );
        }
        // exactly six zero eigenvalues (the drilling stiffness included)
        let eig = SymmetricEigen::new(k.clone()).eigenvalues;
        let top = eig.amax();
        let zero = eig.iter().filter(|v| v.abs() < 1e-10 * top).count();
        let mut sorted: Vec<f64> = eig.iter().copied().collect();
        sorted.sort_by(f64::total_cmp);
        assert_eq!(zero, 6, "t = {thickness}: {:?}", &sorted[..8]);
    }
}

/// The MacNeal–Harder patch: a 0.24 × 0.12 rectangle, four interior nodes, five elements.
fn patch() -> (Vec<[f64; 3]>, Vec<[usize; 4]>, Vec<usize>) {
    let x = vec![
        [0.0, 0.0, 0.0],
        [0.24, 0.0, 0.0],
        [0.24, 0.12, 0.0],
        [0.0, 0.12, 0.0],
        [0.04, 0.02, 0.0],
        [0.18, 0.03, 0.0],
        [0.16, 0.08, 0.0],
        [0.08, 0.08, 0.0],
    ];
    let quads = vec![
        [0, 1, 5, 4],
        [1, 2, 6, 5],
        [2, 3, 7, 6],
        [3, 0, 4, 7],
        [4, 5, 6, 7],
    ];
    (x, quads, vec![0, 1, 2, 3])
}

#[test]
fn the_patch_tests_are_passed() {
    let (x, quads, boundary) = patch();
    let mat = Material {
        youngs_modulus: 1e6,
        poisson_ratio: 0.25,
    };
    let mesh = Shells {
        x: x.clone(),
        quads,
        thickness: 0.001,
        mat,
    };
    let f = DVector::zeros(6 * x.len());
    // membrane: u = 1e-3 (x + y/2), v = 1e-3 (y + x/2); the boundary holds the exact field,
    // the interior nodes must follow it
    let membrane = |p: [f64; 3]| [1e-3 * (p[0] + 0.5 * p[1]), 1e-3 * (p[1] + 0.5 * p[0]), 0.0];
    // bending: w = 1e-3 (x² + xy + y²)/2, θ_x = ∂w/∂y, θ_y = −∂w/∂x (rotations of the normal)
    let bending = |p: [f64; 3]| {
        let (x, y) = (p[0], p[1]);
        [
            1e-3 * (x * x + x * y + y * y) / 2.0,
            1e-3 * (x + 2.0 * y) / 2.0,
            -1e-3 * (2.0 * x + y) / 2.0,
        ]
    };
    let membrane_field = |p: [f64; 3]| {
        let u = membrane(p);
        [u[0], u[1], u[2], 0.0, 0.0, 0.0]
    };
    let bending_field = |p: [f64; 3]| {
        let b = bending(p);
        [0.0, 0.0, b[0], b[1], b[2], 0.0]
    };
    type Field<'a> = &'a dyn Fn([f64; 3]) -> [f64; 6];
    let cases: [(&str, Field); 2] = [("membrane", &membrane_field), ("bending", &bending_field)];
    for (name, exact) in cases {
        let mut fixed = Vec::new();
        for &n in &boundary {
            let e = exact(x[n]);
            for c in 0..6 {
                // the drilling rotation of the membrane field: ½(∂v/∂x − ∂u/∂y) = 0 here
                fixed.push((6 * n + c, e[c]));
            }
        }
        let u = mesh.solve(&f, &fixed);
        for n in 4..8 {
            let e = exact(x[n]);
            for c in 0..5 {
                let scale = 1e-3 * 0.24;
                assert!(
                    (u[6 * n + c] - e[c]).abs() < 1e-6 * scale,
                    "{name}: node {n} dof {c}: {} against {}",
                    u[6 * n + c],
                    e[c]
                );
            }
        }
    }
}

#[test]
fn a_thin_cantilever_plate_bends_as_the_beam_does() {
    // L = 1 m, width 0.1 m, ν = 0 (plate and beam agree), tip load P spread over the end
    let (len, width, p) = (1.0, 0.1, 1.0);
    let mat = Material {
        youngs_modulus: 2.1e11,
        poisson_ratio: 0.0,
    };
    for thickness in [1e-2, 1e-3] {
        let (x, quads) = grid(16, 2, |a, b| [len * a, width * b, 0.0]);
        let mesh = Shells {
            x: x.clone(),
            quads,
            thickness,
            mat,
        };
        let mut f = DVector::zeros(6 * x.len());
        let tip: Vec<usize> = (0..x.len())
            .filter(|&n| (x[n][0] - len).abs() < 1e-12)
            .collect();
        // consistent end load of a uniform line load: ¼, ½, ¼ over the three tip nodes
        for &n in &tip {
            let edge = x[n][1] == 0.0 || (x[n][1] - width).abs() < 1e-12;
            f[6 * n + 2] = if edge { 0.25 * p } else { 0.5 * p };
        }
        let fixed: Vec<(usize, f64)> = (0..x.len())
            .filter(|&n| x[n][0] == 0.0)
            .flat_map(|n| (0..6).map(move |c| (6 * n + c, 0.0)))
            .collect();
        let u = mesh.solve(&f, &fixed);
        let w = tip.iter().map(|&n| u[6 * n + 2]).sum::<f64>() / tip.len() as f64;
        let inertia = width * thickness.powi(3) / 12.0;
        let beam = p * len.powi(3) / (3.0 * mat.youngs_modulus * inertia);
        // Timoshenko's shear part, κ = 5/6: P L/(κ G A)
        let shear = p * len / (5.0 / 6.0 * mat.youngs_modulus / 2.0 * width * thickness);
        let want = beam + shear;
        println!(
            "t/L = {thickness:e}: w = {w:.6e} against {want:.6e} ({:+.3} %)",
            100.0 * (w / want - 1.0)
        );
        assert!(
            (w / want - 1.0).abs() < 0.01,
            "t = {thickness}: {w} vs {want}"
        );
    }
}

#[test]
fn the_scordelis_lo_roof_meets_its_reference_deflection() {
    // R = 25, L = 50, 40° half-angle, t = 0.25, E = 4.32e8, ν = 0, self-weight 90 per unit
    // area; ends on rigid diaphragms (u_x = u_z = 0), free straight edges; the quarter with
    // symmetry. Reference: the vertical deflection at the middle of a free edge, 0.3024
    // (MacNeal & Harder 1985; 0.3086 by deep-shell theory).
    let (r, half_len, phi) = (25.0, 25.0, 40f64.to_radians());
    let mat = Material {
        youngs_modulus: 4.32e8,
        poisson_ratio: 0.0,
    };
    let mut found = Vec::new();
    for n in [8, 16] {
        // ξ along the axis y from the diaphragm (0) to mid-span (1), η around from the crown
        // (0) to the free edge (1)
        let (x, quads) = grid(n, n, |a, b| {
            let th = phi * b;
            [r * th.sin(), half_len * a, r * th.cos()]
        });
        let mesh = Shells {
            x: x.clone(),
            quads,
            thickness: 0.25,
            mat,
        };
        let f = mesh.area_load([0.0, 0.0, -90.0]);
        let mut fixed = Vec::new();
        for (i, p) in x.iter().enumerate() {
            if p[1].abs() < 1e-9 {
                // the diaphragm: u_x = u_z = 0
                fixed.extend([(6 * i, 0.0), (6 * i + 2, 0.0)]);
            }
            if (p[1] - half_len).abs() < 1e-9 {
                // symmetry at mid-span: u_y = 0, θ_x = θ_z = 0
                fixed.extend([(6 * i + 1, 0.0), (6 * i + 3, 0.0), (6 * i + 5, 0.0)]);
            }
            if p[0].abs() < 1e-9 {
                // symmetry at the crown: u_x = 0, θ_y = θ_z = 0
                fixed.extend([(6 * i, 0.0), (6 * i + 4, 0.0), (6 * i + 5, 0.0)]);
            }
        }
        fixed.sort_by_key(|a| a.0);
        fixed.dedup_by_key(|a| a.0);
        let u = mesh.solve(&f, &fixed);
        let edge_mid = x
            .iter()
            .position(|p| (p[1] - half_len).abs() < 1e-9 && (p[0] - r * phi.sin()).abs() < 1e-9)
            .unwrap();
        let w = -u[6 * edge_mid + 2];
        println!(
            "Scordelis–Lo {n} × {n}: {w:.5} ({:+.2} % of 0.3024)",
            100.0 * (w / 0.3024 - 1.0)
        );
        found.push(w);
    }
    // MITC4 converges to it from either side within a few % at 16 × 16
    assert!((found[1] / 0.3024 - 1.0).abs() < 0.02, "{found:?}");
    assert!((found[1] / 0.3024 - 1.0).abs() < (found[0] / 0.3024 - 1.0).abs() + 0.005);
}

#[test]
fn the_pinched_cylinder_converges_to_its_reference_deflection() {
    // R = 300, L = 600, t = 3, E = 3e6, ν = 0.3; two opposite unit loads at mid-length, ends
    // on rigid diaphragms; the octant with symmetry. Reference: the radial deflection under
    // the load, 1.8248e-5 (MacNeal & Harder 1985). The axis along y; θ from the loaded
    // crown (x = 0, z = R) to the side (x = R, z = 0); y from mid-length (0) to the diaphragm.
    let (r, half_len) = (300.0, 300.0);
    let mat = Material {
        youngs_modulus: 3e6,
        poisson_ratio: 0.3,
    };
    let mut found = Vec::new();
    for n in [8, 16, 32] {
        let (x, quads) = grid(n, n, |a, b| {
            let th = std::f64::consts::FRAC_PI_2 * b;
            [r * th.sin(), half_len * a, r * th.cos()]
        });
        let mesh = Shells {
            x: x.clone(),
            quads,
            thickness: 3.0,
            mat,
        };
        let mut f = DVector::zeros(6 * x.len());
        let crown = x
            .iter()
            .position(|p| p[0].abs() < 1e-9 && p[1].abs() < 1e-9)
            .unwrap();
        f[6 * crown + 2] = -0.25;
        let mut fixed = Vec::new();
        for (i, p) in x.iter().enumerate() {
            let dof = |c: usize| 6 * i + c;
            if (p[1] - half_len).abs() < 1e-9 {
                // the diaphragm: u_x = u_z = 0, θ_y = 0
                fixed.extend([dof(0), dof(2), dof(4)]);
            }
            if p[1].abs() < 1e-9 {
                // mid-length symmetry: u_y = 0, θ_x = θ_z = 0
                fixed.extend([dof(1), dof(3), dof(5)]);
            }
            if p[0].abs() < 1e-9 {
                // the plane x = 0: u_x = 0, θ_y = θ_z = 0
                fixed.extend([dof(0), dof(4), dof(5)]);
            }
            if p[2].abs() < 1e-9 {
                // the plane z = 0: u_z = 0, θ_x = θ_y = 0
                fixed.extend([dof(2), dof(3), dof(4)]);
            }
        }
        fixed.sort_unstable();
        fixed.dedup();
        let fixed: Vec<(usize, f64)> = fixed.into_iter().map(|d| (d, 0.0)).collect();
        let u = mesh.solve(&f, &fixed);
        let w = -u[6 * crown + 2] / 1.8248e-5;
        println!("pinched cylinder {n} × {n}: {w:.4} of the reference");
        found.push(w);
    }
    // converging from below (the element is not over-stiff in bending: no locking)
    assert!(found[0] < found[1] && found[1] < found[2], "{found:?}");
    assert!((found[2] - 1.0).abs() < 0.05, "{found:?}");
}

#[test]
fn a_simply_supported_plate_vibrates_at_its_closed_form_frequency() {
    // 1 × 1 m, 10 mm steel; ω_11 = 2π² √(D/(ρ t)), D = E t³/(12 (1 − ν²))
    let (t, rho): (f64, f64) = (0.01, 7850.0);
    let d = STEEL.youngs_modulus * t.powi(3) / (12.0 * (1.0 - STEEL.poisson_ratio.powi(2)));
    let want = 2.0 * std::f64::consts::PI.powi(2) * (d / (rho * t)).sqrt();
    let (x, quads) = grid(12, 12, |a, b| [a, b, 0.0]);
    let mesh = Shells {
        x: x.clone(),
        quads,
        thickness: t,
        mat: STEEL,
    };
    let k = mesh.stiffness();
    let dirs = mesh.directors();
    // edges: w = 0, in-plane translations held, the rotation along the edge held (hard
    // simple support), the rotation about the edge free
    let mut held = vec![false; 6 * x.len()];
    for (i, p) in x.iter().enumerate() {
        let on_x = p[0] == 0.0 || p[0] == 1.0;
        let on_y = p[1] == 0.0 || p[1] == 1.0;
        if on_x || on_y {
            for c in 0..3 {
                held[6 * i + c] = true;
            }
        }
        if on_x {
            held[6 * i + 3] = true;
        }
        if on_y {
            held[6 * i + 4] = true;
        }
    }
    let free: Vec<usize> = (0..held.len()).filter(|&i| !held[i]).collect();
    for lumped in [false, true] {
        let mut m = DMatrix::<f64>::zeros(6 * x.len(), 6 * x.len());
        for q in &mesh.quads {
            let me = shell::mass(&mesh.geometry(q, &dirs), rho, lumped);
            for a in 0..DOFS {
                for b in 0..DOFS {
                    m[(6 * q[a / 6] + a % 6, 6 * q[b / 6] + b % 6)] += me[a][b];
                }
            }
        }
        let kf = DMatrix::from_fn(free.len(), free.len(), |a, b| k[(free[a], free[b])]);
        let mf = DMatrix::from_fn(free.len(), free.len(), |a, b| m[(free[a], free[b])]);
        // the mass's total: ρ t A on each translation
        let total: f64 = (0..x.len()).map(|i| m.row(6 * i).sum()).sum();
        assert!((total / (rho * t) - 1.0).abs() < 1e-12, "{total}");
        let l = mf.cholesky().expect("a positive mass").l();
        let li = l.clone().try_inverse().unwrap();
        let a = &li * kf * li.transpose();
        let a = 0.5 * (&a + a.transpose());
        let lowest = a
            .symmetric_eigenvalues()
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min);
        let omega = lowest.sqrt();
        println!(
            "{} mass: ω_11 = {omega:.3} rad/s against {want:.3} ({:+.2} %)",
            if lumped { "lumped" } else { "consistent" },
            100.0 * (omega / want - 1.0)
        );
        assert!((omega / want - 1.0).abs() < 0.02, "{omega} vs {want}");
    }
}

#[test]
fn the_coupling_surfaces_follow_the_node_and_carry_its_force_and_moment() {
    let (x, theta, dir, t) = ([0.3, -0.2, 1.1], [0.2, -0.4, 0.1], [0.0, 0.6, 0.8], 0.01);
    let node = shell::SurfaceNode {
        theta,
        director: dir,
        thickness: t,
    };
    let (top, bottom) = node.points(x);
    // the points lie a thickness apart, symmetric about the node, along the rotated director
    let gap: f64 = (0..3)
        .map(|c| (top[c] - bottom[c]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!((gap - t).abs() < 1e-15);
    for c in 0..3 {
        assert!((0.5 * (top[c] + bottom[c]) - x[c]).abs() < 1e-15);
    }
    // the director turned by θ and back by −θ is the director again
    let back = shell::rotate(shell::rotate(dir, theta), theta.map(|c| -c));
    for c in 0..3 {
        assert!((back[c] - dir[c]).abs() < 1e-15);
    }
    // velocities: the rigid motion of the thickness, v ± ω × (a/2 d), checked by moving the
    // node a little along v, ω
    let (v, w) = ([1.0, 2.0, -0.5], [3.0, -1.0, 2.0]);
    let dt = 1e-7;
    let (vt, vb) = node.velocities(v, w);
    let d_now = shell::rotate(dir, theta);
    let d_next = shell::rotate(d_now, w.map(|c| c * dt));
    for c in 0..3 {
        let top_next = x[c] + v[c] * dt + 0.5 * t * d_next[c];
        let bottom_next = x[c] + v[c] * dt - 0.5 * t * d_next[c];
        assert!(((top_next - top[c]) / dt - vt[c]).abs() < 1e-6);
        assert!(((bottom_next - bottom[c]) / dt - vb[c]).abs() < 1e-6);
    }
    // forces: the node's force and moment equal the pair's resultant and moment about the
    // origin
    let (ft, fb) = ([2.0, -1.0, 5.0], [-0.5, 3.0, 1.0]);
    let (f, m) = node.forces_to_node(ft, fb);
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let (mt, mb, mx) = (cross(top, ft), cross(bottom, fb), cross(x, f));
    for c in 0..3 {
        assert!((f[c] - ft[c] - fb[c]).abs() < 1e-15);
        assert!((mx[c] + m[c] - mt[c] - mb[c]).abs() < 1e-12, "moment {c}");
    }
}

/// A flat, skewed element in the plane z = 0.
fn flat() -> Geometry {
    let x = [
        [0.0, 0.0, 0.0],
        [1.0, 0.1, 0.0],
        [1.1, 0.9, 0.0],
        [-0.05, 1.0, 0.0],
    ];
    Geometry {
        x,
        director: shell::corner_normals(&x),
        thickness: 0.02,
    }
}

/// A warped element for the nonlinear checks.
fn warped() -> Geometry {
    let x = [
        [0.0, 0.0, 0.0],
        [1.0, 0.1, 0.05],
        [1.1, 0.9, -0.03],
        [-0.05, 1.0, 0.02],
    ];
    Geometry {
        x,
        director: shell::corner_normals(&x),
        thickness: 0.02,
    }
}

#[test]
fn nonlinear_element_starts_as_the_linear_one() {
    let geo = warped();
    let k = shell::stiffness(&geo, STEEL);
    let zero = [0.0; DOFS];
    let f0 = shell::internal_forces(&geo, STEEL, &zero);
    assert!(f0.iter().all(|f| *f == 0.0));
    let kt = shell::tangent(&geo, STEEL, &zero);
    let scale = (0..DOFS).map(|a| k[a][a].abs()).fold(0.0, f64::max);
    let worst = (0..DOFS)
        .flat_map(|a| (0..DOFS).map(move |b| (a, b)))
        .map(|(a, b)| (kt[a][b] - k[a][b]).abs())
        .fold(0.0, f64::max);
    assert!(
        worst < 1e-6 * scale,
        "tangent at rest vs K: {worst:e} of {scale:e}"
    );
    // small displacements: f = K q to second order
    let mut rng = 0x1234_5678_u64;
    let q: [f64; DOFS] = std::array::from_fn(|_| {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        1e-7 * ((rng >> 11) as f64 / (1u64 << 53) as f64 - 0.5)
    });
    let f = shell::internal_forces(&geo, STEEL, &q);
    let kq: Vec<f64> = (0..DOFS)
        .map(|a| (0..DOFS).map(|b| k[a][b] * q[b]).sum())
        .collect();
    let norm = kq.iter().map(|v| v * v).sum::<f64>().sqrt();
    let diff = (0..DOFS)
        .map(|a| (f[a] - kq[a]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(diff < 1e-5 * norm, "f(q) vs K q: {diff:e} of {norm:e}");
}

#[test]
fn nonlinear_element_is_free_of_strain_under_large_rigid_rotations() {
    // turned by 1 rad and moved: the Green–Lagrange strains vanish, so do the forces but for
    // the drilling term's, which is linear: none for a flat element turned about an in-plane
    // axis, a little where the director of a warped one tilts from the plane
    for (geo, axis, bound) in [
        (flat(), [1.0, 0.0, 0.0], 1e-12),
        (flat(), [0.6, 0.8, 0.0], 1e-12),
        (warped(), [1.0, 0.0, 0.0], 1e-5),
        (warped(), [0.6, 0.8, 0.0], 1e-5),
        // about the normal the linear drilling term sees 1 − sin 1 = 0.16 rad of "strain"
        (flat(), [0.0, 0.0, 1.0], 1e-2),
    ] {
        let theta = axis.map(|a: f64| 1.0 * a);
        let mut q = [0.0; DOFS];
        for i in 0..4 {
            let x = shell::rotate(geo.x[i], theta);
            for c in 0..3 {
                q[6 * i + c] = x[c] - geo.x[i][c] + 0.3;
                q[6 * i + 3 + c] = theta[c];
            }
        }
        let f = shell::internal_forces(&geo, STEEL, &q);
        let k = shell::stiffness(&geo, STEEL);
        let kq: f64 = (0..DOFS)
            .map(|a| (0..DOFS).map(|b| k[a][b] * q[b]).sum::<f64>().powi(2))
            .sum::<f64>()
            .sqrt();
        let fn_: f64 = f.iter().map(|v| v * v).sum::<f64>().sqrt();
        eprintln!("rigid rotation 1 rad about {axis:?}: |f| = {fn_:.3e}, |K q| = {kq:.3e}");
        assert!(fn_ < bound * kq, "{axis:?}: {fn_:e} vs {kq:e}");
    }
}

#[test]
fn nonlinear_tangent_is_close_to_the_forces_derivative() {
    // at a deformed state (displacements ~5 % of the size, rotations ~0.1 rad) the tangent
    // against central differences of the forces: exact in the translations, the rotation
    // columns without a director's second derivative in its own rotation
    let geo = warped();
    let mut rng = 0x9e37_79b9_u64;
    let q: [f64; DOFS] = std::array::from_fn(|a| {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        let x = (rng >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
        if a % 6 < 3 {
            0.1 * x
        } else {
            0.2 * x
        }
    });
    let kt = shell::tangent(&geo, STEEL, &q);
    let mut fd = [[0.0; DOFS]; DOFS];
    let mut qq = q;
    for b in 0..DOFS {
        let h = 1e-6;
        qq[b] = q[b] + h;
        let fp = shell::internal_forces(&geo, STEEL, &qq);
        qq[b] = q[b] - h;
        let fm = shell::internal_forces(&geo, STEEL, &qq);
        qq[b] = q[b];
        for a in 0..DOFS {
            fd[a][b] = (fp[a] - fm[a]) / (2.0 * h);
        }
    }
    let norm = |m: &dyn Fn(usize, usize) -> f64, rows: &dyn Fn(usize) -> bool| {
        (0..DOFS)
            .filter(|&a| rows(a))
            .flat_map(|a| (0..DOFS).filter(|&b| rows(b)).map(move |b| (a, b)))
            .map(|(a, b)| m(a, b).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    let translations = |a: usize| a % 6 < 3;
    let all = |_: usize| true;
    let d_t =
        norm(&|a, b| kt[a][b] - fd[a][b], &translations) / norm(&|a, b| fd[a][b], &translations);
    let d_all = norm(&|a, b| kt[a][b] - fd[a][b], &all) / norm(&|a, b| fd[a][b], &all);
    eprintln!("tangent vs differences: translations {d_t:.2e}, all {d_all:.2e}");
    assert!(d_t < 1e-6, "{d_t}");
    assert!(d_all < 2e-2, "{d_all}");
}
