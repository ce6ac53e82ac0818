//! The MITC4 shell element (Dvorkin & Bathe 1984; Bathe, *Finite Element Procedures*, §5.4):
//! a 4-node degenerated shell with mixed interpolation of the transverse shear strains, free
//! of shear locking as the thickness goes to zero. Linear, small displacements; six degrees
//! of freedom per node (three translations, three rotations in the global frame), the
//! rotation about the director held by a small Hughes–Brezzi drilling stiffness.
//!
//! Geometry and displacement (t ∈ [−1, 1] through the thickness a):
//!   X(r, s, t) = Σ N_i (x_i + t a/2 V_i),   U(r, s, t) = Σ N_i (u_i + t a/2 θ_i × V_i),
//! V_i the nodal directors (unit normals of the mid-surface, averaged over the elements at a
//! node on a smooth surface). Covariant strains ε̃_ij = ½ (g_i · U_,j + g_j · U_,i); ε̃_rr,
//! ε̃_ss and ε̃_rs at the integration points, ε̃_rt from the tying points (0, ±1) and ε̃_st from
//! (±1, 0) (the MITC interpolation), ε̃_tt dropped (plane stress). They are turned into a
//! local Cartesian frame (e1 along g_r, e3 normal to the mid-surface) and the plane-stress law
//! with the shear correction κ = 5/6 gives the stress. 2 × 2 points in the plane, 2 through
//! the thickness.
//!
//! Degrees of freedom in the element vector: node i's (u_x, u_y, u_z, θ_x, θ_y, θ_z) at 6i..6i+6.

use nalgebra::{Matrix3, Vector3};

/// The two-point Gauss rule's abscissae ±1/√3 (weights 1), also the membrane's.
pub(crate) const GAUSS: [f64; 2] = [-0.577_350_269_189_625_8, 0.577_350_269_189_625_8];

/// Degrees of freedom of one element.
pub const DOFS: usize = 24;

/// An element's stiffness, row-major 24 × 24.
pub type Stiffness = [[f64; DOFS]; DOFS];

/// Bilinear shape functions and their derivatives (∂/∂r, ∂/∂s) at (r, s); nodes at
/// (−1, −1), (1, −1), (1, 1), (−1, 1) counter-clockwise (also the membrane's).
pub(crate) fn shape(r: f64, s: f64) -> ([f64; 4], [[f64; 2]; 4]) {
    const C: [[f64; 2]; 4] = [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]];
    let mut n = [0.0; 4];
    let mut d = [[0.0; 2]; 4];
    for i in 0..4 {
        let (ri, si) = (C[i][0], C[i][1]);
        n[i] = 0.25 * (1.0 + ri * r) * (1.0 + si * s);
        d[i] = [0.25 * ri * (1.0 + si * s), 0.25 * si * (1.0 + ri * r)];
    }
    (n, d)
}

fn v3(a: [f64; 3]) -> Vector3<f64> {
    Vector3::new(a[0], a[1], a[2])
}

/// The element's geometry: corner positions, unit directors and thickness.
#[derive(Debug, Clone, Copy)]
pub struct Geometry {
    pub x: [[f64; 3]; 4],
    pub director: [[f64; 3]; 4],
    pub thickness: f64,
}

/// Linear isotropic elastic shell material.
#[derive(Debug, Clone, Copy)]
pub struct Material {
    pub youngs_modulus: f64,
    pub poisson_ratio: f64,
}

/// The unit normals of a flat or warped quadrilateral at its corners, g_r × g_s: the
/// directors of a lone element (meshes average them over the elements at a node).
pub fn corner_normals(x: &[[f64; 3]; 4]) -> [[f64; 3]; 4] {
    const C: [[f64; 2]; 4] = [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]];
    let mut out = [[0.0; 3]; 4];
    for (k, c) in C.iter().enumerate() {
        let (_, d) = shape(c[0], c[1]);
        let mut gr = Vector3::zeros();
        let mut gs = Vector3::zeros();
        for i in 0..4 {
            gr += d[i][0] * v3(x[i]);
            gs += d[i][1] * v3(x[i]);
        }
        let n = gr.cross(&gs).normalize();
        out[k] = [n.x, n.y, n.z];
    }
    out
}

/// The smallest signed Jacobian determinant g_r · (g_s × g_t) over the element's 2 × 2 × 2
/// integration points: ≤ 0 where the thickness is too large for the curvature (or the
/// directors point against the corners' normal), and the element cannot be integrated.
pub fn min_jacobian(geo: &Geometry) -> f64 {
    let mut min = f64::INFINITY;
    for &t in &GAUSS {
        for &r in &GAUSS {
            for &s in &GAUSS {
                let g = point(geo, r, s, t).g;
                min = min.min(g[0].dot(&g[1].cross(&g[2])));
            }
        }
    }
    min
}

/// Covariant base vectors at (r, s, t) and the rows (24 entries each) that map the element's
/// degrees of freedom to U_,r, U_,s, U_,t dotted with a vector: `dot_rows(w)[b]` · q = w · U_,b.
struct Point {
    g: [Vector3<f64>; 3],
    /// dU/dξ_b as a linear map: for each b, per node the translation weight c_u (times the unit
    /// matrix) and the rotation weight c_θ: U_,b = Σ_i c_u u_i + c_θ θ_i × V_i.
    cu: [[f64; 4]; 3],
    ct: [[f64; 4]; 3],
}

fn point(geo: &Geometry, r: f64, s: f64, t: f64) -> Point {
    let (n, d) = shape(r, s);
    let h = 0.5 * geo.thickness;
    let mut g = [Vector3::zeros(); 3];
    let mut cu = [[0.0; 4]; 3];
    let mut ct = [[0.0; 4]; 3];
    for i in 0..4 {
        let xi = v3(geo.x[i]);
        let vi = v3(geo.director[i]);
        for b in 0..2 {
            g[b] += d[i][b] * (xi + t * h * vi);
            cu[b][i] = d[i][b];
            ct[b][i] = d[i][b] * t * h;
        }
        g[2] += n[i] * h * vi;
        cu[2][i] = 0.0;
        ct[2][i] = n[i] * h;
    }
    Point { g, cu, ct }
}

/// At a point: |det J|, the contravariant base vectors (rows of J⁻¹) and the local Cartesian
/// frame (e1 along g_r, e3 normal to g_r and g_s).
struct Frame {
    det: f64,
    gc: [Vector3<f64>; 3],
    e: [Vector3<f64>; 3],
}

impl Point {
    fn frame(&self) -> Frame {
        let jac = Matrix3::from_columns(&self.g);
        let inv = jac.try_inverse().expect("a degenerate shell element");
        let e3 = self.g[0].cross(&self.g[1]).normalize();
        let e1 = self.g[0].normalize();
        Frame {
            det: jac.determinant().abs(),
            gc: std::array::from_fn(|a| inv.row(a).transpose().into_owned()),
            e: [e1, e3.cross(&e1), e3],
        }
    }

    /// The row of w · U_,b over the 24 degrees of freedom.
    fn row(&self, geo: &Geometry, w: &Vector3<f64>, b: usize) -> [f64; DOFS] {
        let mut out = [0.0; DOFS];
        for i in 0..4 {
            // w · (c_u u_i) and w · (c_θ θ_i × V_i) = c_θ θ_i · (V_i × w)
            let vw = v3(geo.director[i]).cross(w);
            for k in 0..3 {
                out[6 * i + k] = self.cu[b][i] * w[k];
                out[6 * i + 3 + k] = self.ct[b][i] * vw[k];
            }
        }
        out
    }

    /// The row of the covariant strain ε̃_ab = ½ (g_a · U_,b + g_b · U_,a).
    fn strain(&self, geo: &Geometry, a: usize, b: usize) -> [f64; DOFS] {
        let p = self.row(geo, &self.g[a], b);
        let q = self.row(geo, &self.g[b], a);
        std::array::from_fn(|k| 0.5 * (p[k] + q[k]))
    }
}

/// The plane-stress law in the local frame on (ε11, ε22, γ12, γ13, γ23), shear correction 5/6.
fn plane_stress(mat: Material) -> [[f64; 5]; 5] {
    let (e, nu) = (mat.youngs_modulus, mat.poisson_ratio);
    let shear = e / (2.0 * (1.0 + nu));
    let kappa = 5.0 / 6.0;
    let c = e / (1.0 - nu * nu);
    [
        [c, c * nu, 0.0, 0.0, 0.0],
        [c * nu, c, 0.0, 0.0, 0.0],
        [0.0, 0.0, shear, 0.0, 0.0],
        [0.0, 0.0, 0.0, kappa * shear, 0.0],
        [0.0, 0.0, 0.0, 0.0, kappa * shear],
    ]
}

/// The deformed state of an element for the geometrically nonlinear path: its current
/// geometry (corners X + u, directors R(θ) V⁰) and per node the tangent T(θ) of the rotation
/// vector (δV = (T δθ) × V).
struct Deformed {
    geo: Geometry,
    t: [Matrix3<f64>; 4],
    /// The nodes' displacements and director changes R(θ) V⁰ − V⁰, from which the strains
    /// are formed without subtracting the large positions (their round-off would be the
    /// strains' floor: 10⁻¹⁶ × position / element size).
    du: [Vector3<f64>; 4],
    dv: [Vector3<f64>; 4],
}

impl Deformed {
    fn new(reference: &Geometry, q: &[f64; DOFS]) -> Deformed {
        let theta = |i: usize| [q[6 * i + 3], q[6 * i + 4], q[6 * i + 5]];
        Deformed {
            geo: Geometry {
                x: std::array::from_fn(|i| {
                    std::array::from_fn(|c| reference.x[i][c] + q[6 * i + c])
                }),
                director: std::array::from_fn(|i| rotate(reference.director[i], theta(i))),
                thickness: reference.thickness,
            },
            t: std::array::from_fn(|i| rotation_tangent(theta(i))),
            du: std::array::from_fn(|i| Vector3::new(q[6 * i], q[6 * i + 1], q[6 * i + 2])),
            dv: std::array::from_fn(|i| rotation_change(reference.director[i], theta(i))),
        }
    }

    /// g_a − G_a at (r, s, t), a = r, s, t.
    fn base_change(&self, r: f64, s: f64, t: f64) -> [Vector3<f64>; 3] {
        let (n, d) = shape(r, s);
        let h = 0.5 * self.geo.thickness;
        let mut out = [Vector3::zeros(); 3];
        for i in 0..4 {
            for b in 0..2 {
                out[b] += d[i][b] * (self.du[i] + t * h * self.dv[i]);
            }
            out[2] += n[i] * h * self.dv[i];
        }
        out
    }
}

/// R(θ) v − v = sin φ k × v + (1 − cos φ) k × (k × v), k = θ/φ, without cancellation.
fn rotation_change(v: [f64; 3], theta: [f64; 3]) -> Vector3<f64> {
    let (v, t) = (v3(v), v3(theta));
    let phi = t.norm();
    if phi < 1e-300 {
        return Vector3::zeros();
    }
    let k = t / phi;
    let half = (0.5 * phi).sin();
    k.cross(&v) * phi.sin() + k.cross(&k.cross(&v)) * (2.0 * half * half)
}

/// T(θ) = I + (1 − cos φ)/φ² [θ]× + (φ − sin φ)/φ³ [θ]×², φ = |θ|: δ(R(θ) v) = (T δθ) × R v.
fn rotation_tangent(theta: [f64; 3]) -> Matrix3<f64> {
    let t = v3(theta);
    let phi = t.norm();
    let w = t.cross_matrix();
    let p2 = phi * phi;
    // (1 − cos φ)/φ² = 2 sin²(φ/2)/φ²; (φ − sin φ)/φ³ by its series below 0.1 (error < 1e-16)
    let a = if phi < 1e-8 {
        0.5
    } else {
        let half = (0.5 * phi).sin();
        2.0 * half * half / p2
    };
    let b = if phi < 0.1 {
        1.0 / 6.0 - p2 / 120.0 + p2 * p2 / 5040.0 - p2 * p2 * p2 / 362_880.0
    } else {
        (phi - phi.sin()) / (p2 * phi)
    };
    Matrix3::identity() + w * a + w * w * b
}

/// Visits the 2 × 2 × 2 points of the MITC4 interpolation with |det J| and the rows of the
/// five local strains (ε11, ε22, γ12, γ13, γ23) over the 24 dofs: the small-strain
/// ε̃_ab = ½ (g_a · U_,b + g_b · U_,a), the transverse shears from the tying points (0, ±1) and
/// (±1, 0), mapped to the local frame.
fn strain_points(geo: &Geometry, mut visit: impl FnMut(f64, &[[f64; DOFS]; 5])) {
    let covariant =
        |r: f64, s: f64, t: f64, a: usize, b: usize| point(geo, r, s, t).strain(geo, a, b);
    for &t in &GAUSS {
        // the tying points' transverse shear strains at this t: ε̃_rt at A (0, 1), C (0, −1);
        // ε̃_st at D (1, 0), B (−1, 0)
        let ert_a = covariant(0.0, 1.0, t, 0, 2);
        let ert_c = covariant(0.0, -1.0, t, 0, 2);
        let est_d = covariant(1.0, 0.0, t, 1, 2);
        let est_b = covariant(-1.0, 0.0, t, 1, 2);
        for &r in &GAUSS {
            for &s in &GAUSS {
                let Frame { det, gc, e: frame } = point(geo, r, s, t).frame();
                // covariant strain rows ε̃_ab (a ≤ b), the MITC shear interpolated
                let mix = |w1: f64, x: &[f64; DOFS], y: &[f64; DOFS]| -> [f64; DOFS] {
                    std::array::from_fn(|q| w1 * x[q] + (1.0 - w1) * y[q])
                };
                let mut cov = [[[0.0; DOFS]; 3]; 3];
                cov[0][0] = covariant(r, s, t, 0, 0);
                cov[1][1] = covariant(r, s, t, 1, 1);
                cov[0][1] = covariant(r, s, t, 0, 1);
                cov[0][2] = mix(0.5 * (1.0 + s), &ert_a, &ert_c);
                cov[1][2] = mix(0.5 * (1.0 + r), &est_d, &est_b);
                for a in 0..3 {
                    for b in 0..a {
                        cov[a][b] = cov[b][a];
                    }
                }
                // local strains ε_kl = Σ_ab ε̃_ab (g^a · e_k)(g^b · e_l)
                let tr: [[f64; 3]; 3] =
                    std::array::from_fn(|a| std::array::from_fn(|kk| gc[a].dot(&frame[kk])));
                let local = |kk: usize, l: usize, scale: f64| -> [f64; DOFS] {
                    let mut out = [0.0; DOFS];
                    for a in 0..3 {
                        for b in 0..3 {
                            let f = scale * tr[a][kk] * tr[b][l];
                            if f != 0.0 {
                                for q in 0..DOFS {
                                    out[q] += f * cov[a][b][q];
                                }
                            }
                        }
                    }
                    out
                };
                visit(
                    det,
                    &[
                        local(0, 0, 1.0),
                        local(1, 1, 1.0),
                        local(0, 1, 2.0),
                        local(0, 2, 2.0),
                        local(1, 2, 2.0),
                    ],
                );
            }
        }
    }
}

/// The MITC4 stiffness of one element (24 × 24, symmetric), with the drilling stiffness.
pub fn stiffness(geo: &Geometry, mat: Material) -> Stiffness {
    let dmat = plane_stress(mat);
    let mut k = [[0.0; DOFS]; DOFS];
    strain_points(geo, |w, bm| {
        let mut db = [[0.0; DOFS]; 5];
        for i in 0..5 {
            for j in 0..5 {
                if dmat[i][j] != 0.0 {
                    for q in 0..DOFS {
                        db[i][q] += dmat[i][j] * bm[j][q];
                    }
                }
            }
        }
        for i in 0..5 {
            for a in 0..DOFS {
                if bm[i][a] == 0.0 {
                    continue;
                }
                let f = w * bm[i][a];
                for b in 0..DOFS {
                    k[a][b] += f * db[i][b];
                }
            }
        }
    });
    add_drilling(geo, mat, &mut k);
    k
}

/// The internal forces of the geometrically nonlinear MITC4 element (Dvorkin & Bathe 1984's
/// total Lagrangian form): f = ∫ (∂E/∂q)ᵀ D E dV₀ with the Green–Lagrange strains E of the
/// element displaced by `q` (translations, and rotation vectors turning the directors:
/// V = R(θ) V⁰), plus the drilling stiffness's K_d q — a linear term, exact while the
/// rotations about the director stay small. Large rotations, small strains (the law is the
/// linear one, on E).
pub fn internal_forces(geo: &Geometry, mat: Material, q: &[f64; DOFS]) -> [f64; DOFS] {
    nonlinear_element(geo, mat, q, None)
}

/// The tangent ∂f/∂q of [`internal_forces`]: the material part ∫ Bᵀ D B dV₀ with the deformed
/// strain rows, and the geometric part Σ W^ab ½ (J_aᵀ J_b + J_bᵀ J_a) — W^ab the stress pulled
/// back to the covariant strains, J_a = ∂g_a/∂q — without the second derivative of a node's
/// director in its own rotation (a quasi-Newton tangent, exact for the translations; central
/// differences of the forces gave no fewer iterations at ten times the cost).
pub fn tangent(geo: &Geometry, mat: Material, q: &[f64; DOFS]) -> Stiffness {
    let mut k = [[0.0; DOFS]; DOFS];
    nonlinear_element(geo, mat, q, Some(&mut k));
    // symmetric in exact arithmetic: average the round-off away
    for a in 0..DOFS {
        for b in 0..a {
            let m = 0.5 * (k[a][b] + k[b][a]);
            k[a][b] = m;
            k[b][a] = m;
        }
    }
    k
}

/// The nonlinear element's forces, and with `tangent` its tangent added there.
fn nonlinear_element(
    geo: &Geometry,
    mat: Material,
    q: &[f64; DOFS],
    mut tangent: Option<&mut Stiffness>,
) -> [f64; DOFS] {
    let dmat = plane_stress(mat);
    let d = Deformed::new(geo, q);
    // per node ∂V/∂θ = −[V]× T(θ)
    let dvdt: [Matrix3<f64>; 4] =
        std::array::from_fn(|i| -(v3(d.geo.director[i]).cross_matrix() * d.t[i]));
    let mut f = [0.0; DOFS];
    // at (r, s, t): the deformed point (base vectors and the rows' weights)
    let deformed_point = |r: f64, s: f64, t: f64| point(&d.geo, r, s, t);
    // ∂ε̃_ab/∂q at a deformed point, the rotation columns through T(θ)
    let row = |p: &Point, a: usize, b: usize| -> [f64; DOFS] {
        let mut row = p.strain(&d.geo, a, b);
        for i in 0..4 {
            let rot =
                d.t[i].transpose() * Vector3::new(row[6 * i + 3], row[6 * i + 4], row[6 * i + 5]);
            for k in 0..3 {
                row[6 * i + 3 + k] = rot[k];
            }
        }
        row
    };
    // ε̃_ab = ½ (G_a · Δ_b + Δ_a · G_b + Δ_a · Δ_b), Δ = g − G from the displacements
    let value = |r: f64, s: f64, t: f64, a: usize, b: usize| -> f64 {
        let g = point(geo, r, s, t).g;
        let dg = d.base_change(r, s, t);
        0.5 * (g[a].dot(&dg[b]) + dg[a].dot(&g[b]) + dg[a].dot(&dg[b]))
    };
    // J_x = ∂g_x/∂q at a deformed point, 3 × 24: node i's columns [cu_x,i I | ct_x,i ∂V_i/∂θ_i]
    let jacobians = |p: &Point| -> [[[f64; DOFS]; 3]; 3] {
        std::array::from_fn(|x| {
            let mut j = [[0.0; DOFS]; 3];
            for i in 0..4 {
                for c in 0..3 {
                    j[c][6 * i + c] = p.cu[x][i];
                    for m in 0..3 {
                        j[c][6 * i + 3 + m] = p.ct[x][i] * dvdt[i][(c, m)];
                    }
                }
            }
            j
        })
    };
    // k += w ½ (J_aᵀ J_b + J_bᵀ J_a)
    let geometric = |k: &mut Stiffness, j: &[[[f64; DOFS]; 3]; 3], a: usize, b: usize, w: f64| {
        if w == 0.0 {
            return;
        }
        let (ja, jb) = (&j[a], &j[b]);
        for x in 0..DOFS {
            for y in 0..DOFS {
                let mut v = 0.0;
                for c in 0..3 {
                    v += ja[c][x] * jb[c][y] + jb[c][x] * ja[c][y];
                }
                k[x][y] += 0.5 * w * v;
            }
        }
    };
    const KL: [(usize, usize, f64); 5] = [
        (0, 0, 1.0),
        (1, 1, 1.0),
        (0, 1, 2.0),
        (0, 2, 2.0),
        (1, 2, 2.0),
    ];
    for &t in &GAUSS {
        // tying points: ε̃_rt at A (0, 1), C (0, −1); ε̃_st at D (1, 0), B (−1, 0)
        let tying = [
            (0.0, 1.0, 0usize),
            (0.0, -1.0, 0),
            (1.0, 0.0, 1),
            (-1.0, 0.0, 1),
        ];
        let tp = tying.map(|(r, s, _)| deformed_point(r, s, t));
        let tv = tying.map(|(r, s, a)| value(r, s, t, a, 2));
        let trow: [[f64; DOFS]; 4] = std::array::from_fn(|k| row(&tp[k], tying[k].2, 2));
        let mut tw = [0.0; 4];
        for &r in &GAUSS {
            for &s in &GAUSS {
                let Frame { det, gc, e: frame } = point(geo, r, s, t).frame();
                let p = deformed_point(r, s, t);
                let (wa, wd) = (0.5 * (1.0 + s), 0.5 * (1.0 + r));
                let mut cov = [[0.0; 3]; 3];
                cov[0][0] = value(r, s, t, 0, 0);
                cov[1][1] = value(r, s, t, 1, 1);
                cov[0][1] = value(r, s, t, 0, 1);
                cov[0][2] = wa * tv[0] + (1.0 - wa) * tv[1];
                cov[1][2] = wd * tv[2] + (1.0 - wd) * tv[3];
                cov[1][0] = cov[0][1];
                cov[2][0] = cov[0][2];
                cov[2][1] = cov[1][2];
                let tr: [[f64; 3]; 3] =
                    std::array::from_fn(|a| std::array::from_fn(|k| gc[a].dot(&frame[k])));
                // local strains (ε11, ε22, γ12, γ13, γ23) = Σ_ab c_i^ab ε̃_ab
                let c = |i: usize, a: usize, b: usize| {
                    let (k, l, scale) = KL[i];
                    scale * tr[a][k] * tr[b][l]
                };
                // the coefficient of ε̃_ab (a ≤ b, symmetric pairs summed) in strain i
                let cs = |i: usize, a: usize, b: usize| {
                    c(i, a, b) + if a != b { c(i, b, a) } else { 0.0 }
                };
                let e: [f64; 5] = std::array::from_fn(|i| {
                    (0..3)
                        .flat_map(|a| (0..3).map(move |b| (a, b)))
                        .map(|(a, b)| c(i, a, b) * cov[a][b])
                        .sum()
                });
                let stress: [f64; 5] =
                    std::array::from_fn(|i| (0..5).map(|j| dmat[i][j] * e[j]).sum::<f64>());
                let w = |a: usize, b: usize| -> f64 {
                    det * (0..5).map(|i| stress[i] * cs(i, a, b)).sum::<f64>()
                };
                let rows = [row(&p, 0, 0), row(&p, 1, 1), row(&p, 0, 1)];
                for (k, (a, b)) in [(0, 0), (1, 1), (0, 1)].into_iter().enumerate() {
                    let wk = w(a, b);
                    for x in 0..DOFS {
                        f[x] += wk * rows[k][x];
                    }
                }
                let (wrt, wst) = (w(0, 2), w(1, 2));
                tw[0] += wa * wrt;
                tw[1] += (1.0 - wa) * wrt;
                tw[2] += wd * wst;
                tw[3] += (1.0 - wd) * wst;
                if let Some(k) = tangent.as_deref_mut() {
                    // B_i = Σ_ab cs_i^ab ∂ε̃_ab/∂q, the shears through the tying rows
                    let bm: [[f64; DOFS]; 5] = std::array::from_fn(|i| {
                        std::array::from_fn(|x| {
                            cs(i, 0, 0) * rows[0][x]
                                + cs(i, 1, 1) * rows[1][x]
                                + cs(i, 0, 1) * rows[2][x]
                                + cs(i, 0, 2) * (wa * trow[0][x] + (1.0 - wa) * trow[1][x])
                                + cs(i, 1, 2) * (wd * trow[2][x] + (1.0 - wd) * trow[3][x])
                        })
                    });
                    for i in 0..5 {
                        let db: [f64; DOFS] = std::array::from_fn(|x| {
                            (0..5).map(|j| dmat[i][j] * bm[j][x]).sum::<f64>()
                        });
                        for x in 0..DOFS {
                            if bm[i][x] == 0.0 {
                                continue;
                            }
                            let fx = det * bm[i][x];
                            for y in 0..DOFS {
                                k[x][y] += fx * db[y];
                            }
                        }
                    }
                    let j = jacobians(&p);
                    for (a, b) in [(0, 0), (1, 1), (0, 1)] {
                        geometric(k, &j, a, b, w(a, b));
                    }
                }
            }
        }
        for (k, (_, _, a)) in tying.iter().enumerate() {
            for x in 0..DOFS {
                f[x] += tw[k] * trow[k][x];
            }
            if let Some(kt) = tangent.as_deref_mut() {
                geometric(kt, &jacobians(&tp[k]), *a, 2, tw[k]);
            }
        }
    }
    let mut kd = [[0.0; DOFS]; DOFS];
    add_drilling(geo, mat, &mut kd);
    for a in 0..DOFS {
        f[a] += (0..DOFS).map(|b| kd[a][b] * q[b]).sum::<f64>();
    }
    if let Some(k) = tangent {
        for a in 0..DOFS {
            for b in 0..DOFS {
                k[a][b] += kd[a][b];
            }
        }
    }
    f
}

/// The stresses (σ11, σ22, σ12, τ13, τ23) in the local frame (e1 along g_r, e3 normal) at the
/// element's centre on its top (t = +1) and bottom (t = −1) surfaces, of the element displaced
/// by `q`: the small strains (linear) or the Green–Lagrange strains, giving the second
/// Piola–Kirchhoff stresses (`nonlinear`); the transverse shears from the tying points as in
/// the stiffness.
pub fn surface_stresses(
    geo: &Geometry,
    mat: Material,
    q: &[f64; DOFS],
    nonlinear: bool,
) -> [[f64; 5]; 2] {
    let dmat = plane_stress(mat);
    let d = Deformed::new(geo, q);
    let value = |r: f64, s: f64, t: f64, a: usize, b: usize| -> f64 {
        if nonlinear {
            let g = point(geo, r, s, t).g;
            let dg = d.base_change(r, s, t);
            0.5 * (g[a].dot(&dg[b]) + dg[a].dot(&g[b]) + dg[a].dot(&dg[b]))
        } else {
            let row = point(geo, r, s, t).strain(geo, a, b);
            row.iter().zip(q).map(|(x, y)| x * y).sum()
        }
    };
    [1.0, -1.0].map(|t| {
        let mut cov = [[0.0; 3]; 3];
        cov[0][0] = value(0.0, 0.0, t, 0, 0);
        cov[1][1] = value(0.0, 0.0, t, 1, 1);
        cov[0][1] = value(0.0, 0.0, t, 0, 1);
        cov[0][2] = 0.5 * (value(0.0, 1.0, t, 0, 2) + value(0.0, -1.0, t, 0, 2));
        cov[1][2] = 0.5 * (value(1.0, 0.0, t, 1, 2) + value(-1.0, 0.0, t, 1, 2));
        cov[1][0] = cov[0][1];
        cov[2][0] = cov[0][2];
        cov[2][1] = cov[1][2];
        let Frame { gc, e: frame, .. } = point(geo, 0.0, 0.0, t).frame();
        let tr: [[f64; 3]; 3] =
            std::array::from_fn(|a| std::array::from_fn(|k| gc[a].dot(&frame[k])));
        let local = |k: usize, l: usize, scale: f64| -> f64 {
            (0..3)
                .flat_map(|a| (0..3).map(move |b| (a, b)))
                .map(|(a, b)| scale * tr[a][k] * tr[b][l] * cov[a][b])
                .sum()
        };
        let e = [
            local(0, 0, 1.0),
            local(1, 1, 1.0),
            local(0, 1, 2.0),
            local(0, 2, 2.0),
            local(1, 2, 2.0),
        ];
        std::array::from_fn(|i| (0..5).map(|j| dmat[i][j] * e[j]).sum::<f64>())
    })
}

/// The von Mises stress of a shell's (σ11, σ22, σ12, τ13, τ23).
pub fn von_mises(s: &[f64; 5]) -> f64 {
    (s[0] * s[0] - s[0] * s[1] + s[1] * s[1] + 3.0 * (s[2] * s[2] + s[3] * s[3] + s[4] * s[4]))
        .max(0.0)
        .sqrt()
}

/// Hughes–Brezzi drilling stiffness: γ ∫ (θ · e3 − ω3)² dA with ω3 = ½ (e2 · U_,1 − e1 · U_,2)
/// the mid-surface's in-plane rotation, γ = 1e-3 G a (small: it only holds the rotation about
/// the director, which the shell theory leaves without stiffness; zero for rigid motions).
fn add_drilling(geo: &Geometry, mat: Material, k: &mut Stiffness) {
    let shear = mat.youngs_modulus / (2.0 * (1.0 + mat.poisson_ratio));
    let gamma = 1e-3 * shear * geo.thickness;
    for &r in &GAUSS {
        for &s in &GAUSS {
            let p = point(geo, r, s, 0.0);
            let (n, _) = shape(r, s);
            let Frame {
                det,
                gc,
                e: [e1, e2, e3],
            } = p.frame();
            // w · U_,x_l = Σ_b (w · U_,b)(g^b · e_l), b over r, s (the mid-surface: t = 0)
            let grad = |w: &Vector3<f64>, l: &Vector3<f64>| -> [f64; DOFS] {
                let mut out = [0.0; DOFS];
                for b in 0..3 {
                    let f = gc[b].dot(l);
                    let row = p.row(geo, w, b);
                    for q in 0..DOFS {
                        out[q] += f * row[q];
                    }
                }
                out
            };
            let a = grad(&e2, &e1);
            let b = grad(&e1, &e2);
            let mut row: [f64; DOFS] = std::array::from_fn(|q| -0.5 * (a[q] - b[q]));
            for i in 0..4 {
                for c in 0..3 {
                    row[6 * i + 3 + c] += n[i] * e3[c];
                }
            }
            let w = gamma * det * 2.0 / geo.thickness;
            for a in 0..DOFS {
                if row[a] == 0.0 {
                    continue;
                }
                for b in 0..DOFS {
                    k[a][b] += w * row[a] * row[b];
                }
            }
        }
    }
}

/// The mid-surface's 2 × 2 points: the shape functions there and the area element |g_r × g_s|.
fn mid_surface(geo: &Geometry) -> impl Iterator<Item = ([f64; 4], f64)> + '_ {
    GAUSS.iter().flat_map(move |&r| {
        GAUSS.iter().map(move |&s| {
            let p = point(geo, r, s, 0.0);
            (shape(r, s).0, p.g[0].cross(&p.g[1]).norm())
        })
    })
}

/// Consistent nodal forces of a pressure or area load q (force per area, a global vector) on
/// the mid-surface: ∫ N_i q dA (translations only).
pub fn area_load(geo: &Geometry, q: [f64; 3]) -> [f64; DOFS] {
    let mut f = [0.0; DOFS];
    for (n, da) in mid_surface(geo) {
        for i in 0..4 {
            for c in 0..3 {
                f[6 * i + c] += n[i] * q[c] * da;
            }
        }
    }
    f
}

/// The element's mass (24 × 24): consistent, ρ ∫ N_i N_j a dA for the translations and the
/// rotary inertia ρ a³/12 ∫ N_i N_j dA (about the in-plane axes, and a small fraction of it
/// about the director, so the drilling rotation has a mass) for the rotations; or lumped, each
/// corner's share ∫ N_i dA of both: diagonal in the translations, a 3 × 3 block per node in
/// the rotations (ρ a³/12 (1 − 0.99 V⊗V), diagonal only when the director lies along an axis).
pub fn mass(geo: &Geometry, density: f64, lumped: bool) -> Stiffness {
    let a = geo.thickness;
    let dirs = geo.director.map(v3);
    let mut m = [[0.0; DOFS]; DOFS];
    for (n, da) in mid_surface(geo) {
        for i in 0..4 {
            for j in 0..4 {
                let w = if lumped {
                    if i != j {
                        continue;
                    }
                    n[i] * da
                } else {
                    n[i] * n[j] * da
                };
                let rot = density * a.powi(3) / 12.0 * w;
                let (vi, vj) = (dirs[i], dirs[j]);
                for c in 0..3 {
                    m[6 * i + c][6 * j + c] += density * a * w;
                    for d in 0..3 {
                        // J (1 − V⊗V) + 1e-2 J V⊗V about the director
                        let vv = 0.5 * (vi[c] * vi[d] + vj[c] * vj[d]);
                        let unit = if c == d { 1.0 } else { 0.0 };
                        m[6 * i + 3 + c][6 * j + 3 + d] += rot * (unit - 0.99 * vv);
                    }
                }
            }
        }
    }
    m
}

/// Rotates `v` by the rotation vector `theta` (Rodrigues: about θ/|θ| by |θ|).
pub fn rotate(v: [f64; 3], theta: [f64; 3]) -> [f64; 3] {
    let (v, t) = (v3(v), v3(theta));
    let angle = t.norm();
    if angle < 1e-300 {
        return [v.x, v.y, v.z];
    }
    let k = t / angle;
    let r = v * angle.cos() + k.cross(&v) * angle.sin() + k * k.dot(&v) * (1.0 - angle.cos());
    [r.x, r.y, r.z]
}

/// A shell node as the coupling sees it (Ullrich Fig. 2.6, (3.9)): its rotation vector
/// `theta`, its reference director and the thickness a; the two reference-surface points lie
/// at ± a/2 along the director turned by θ.
#[derive(Debug, Clone, Copy)]
pub struct SurfaceNode {
    pub theta: [f64; 3],
    pub director: [f64; 3],
    pub thickness: f64,
}

/// (a + w, a − w).
fn plus_minus(a: [f64; 3], w: Vector3<f64>) -> ([f64; 3], [f64; 3]) {
    (
        std::array::from_fn(|c| a[c] + w[c]),
        std::array::from_fn(|c| a[c] - w[c]),
    )
}

impl SurfaceNode {
    /// The half-thickness arm a/2 d along the turned director d.
    fn arm(&self) -> Vector3<f64> {
        v3(rotate(self.director, self.theta)) * (0.5 * self.thickness)
    }

    /// The two reference-surface points (top, bottom) of the node at `x`.
    pub fn points(&self, x: [f64; 3]) -> ([f64; 3], [f64; 3]) {
        plus_minus(x, self.arm())
    }

    /// Their velocities v ± ω × (a/2 d).
    pub fn velocities(&self, v: [f64; 3], omega: [f64; 3]) -> ([f64; 3], [f64; 3]) {
        plus_minus(v, v3(omega).cross(&self.arm()))
    }

    /// The forces the DEM puts on the two points, carried to the node: the force F_top +
    /// F_bottom ((3.9)) and the moment of the pair about the node, (a/2 d) × (F_top − F_bottom)
    /// — the node then carries the same resultant and moment about any point as the two
    /// surface forces did.
    pub fn forces_to_node(&self, f_top: [f64; 3], f_bottom: [f64; 3]) -> ([f64; 3], [f64; 3]) {
        let m = self.arm().cross(&(v3(f_top) - v3(f_bottom)));
        (
            std::array::from_fn(|c| f_top[c] + f_bottom[c]),
            [m.x, m.y, m.z],
        )
    }
}
