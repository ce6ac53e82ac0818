//! A finite-strain 4-node (and 3-node) membrane with the incompressible Ogden law (the confining rubber
//! membrane of Wellmann's triaxial test, W ch. 4.3.4: a 0.3 mm sheet, three-term Ogden; the
//! element after Gruttmann & Taylor 1992, plane stress by incompressibility), and follower
//! pressure on the deformed surface.
//!
//! Kinematics at a point of the reference mid-surface, in an orthonormal frame (E_1, E_2) of
//! its tangent plane: the in-plane deformation gradient F = [g_r g_s] J₀⁻¹ (3 × 2; J₀ the
//! reference Jacobian in that frame), C = Fᵀ F with eigenvalues λ_1², λ_2² and eigenvectors
//! N_a; the thickness stretch λ_3 = 1/(λ_1 λ_2) (incompressible). The Ogden strain energy
//! W = Σ_p μ_p/α_p (λ_1^α_p + λ_2^α_p + λ_3^α_p − 3) with σ_33 = 0 gives the principal Cauchy
//! stresses σ_a = Σ_p μ_p (λ_a^α_p − λ_3^α_p) and S = Σ_a σ_a/λ_a² N_a N_aᵀ (J = 1). The
//! internal forces are f_i = t₀ ∫ F S b_i dA₀ with b_i = J₀⁻ᵀ ∇N_i; a pressure p on the deformed
//! surface gives f_i = ∫ N_i p (g_r × g_s) dr ds. Tangents by central differences of these
//! forces (12 × 12 per element: cheap for membranes of a few hundred elements, and exact
//! enough for Newton's quadratic convergence to show).

use crate::shell::{shape, GAUSS};
use nalgebra::{Matrix2, Matrix3x2, Vector2, Vector3};

/// The incompressible Ogden law in plane stress: terms (μ_p, α_p).
#[derive(Debug, Clone)]
pub struct Ogden {
    pub terms: Vec<(f64, f64)>,
}

impl Ogden {
    /// The in-plane principal Cauchy stresses at the principal stretches (λ_3 = 1/(λ_1 λ_2)).
    pub fn principal_stress(&self, l1: f64, l2: f64) -> (f64, f64) {
        let l3 = 1.0 / (l1 * l2);
        let mut s = (0.0, 0.0);
        for &(mu, alpha) in &self.terms {
            let c = l3.powf(alpha);
            s.0 += mu * (l1.powf(alpha) - c);
            s.1 += mu * (l2.powf(alpha) - c);
        }
        s
    }

    /// The shear modulus at small strain, ½ Σ μ_p α_p.
    pub fn shear_modulus(&self) -> f64 {
        0.5 * self.terms.iter().map(|(m, a)| m * a).sum::<f64>()
    }
}

fn v3(a: [f64; 3]) -> Vector3<f64> {
    Vector3::new(a[0], a[1], a[2])
}

/// The integration points of an element with `corners` corners (4: 2 × 2 Gauss; 3: the
/// centroid, the linear triangle's strain being constant): weight, shape functions and their
/// derivatives (∂/∂r, ∂/∂s).
type Rule = Vec<(f64, Vec<f64>, Vec<[f64; 2]>)>;

fn rule(corners: usize) -> Rule {
    match corners {
        4 => {
            let mut out = Vec::with_capacity(4);
            for r in GAUSS {
                for s in GAUSS {
                    let (n, d) = shape(r, s);
                    out.push((1.0, n.to_vec(), d.to_vec()));
                }
            }
            out
        }
        3 => {
            let t = 1.0 / 3.0;
            vec![(
                0.5,
                vec![1.0 - t - t, t, t],
                vec![[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]],
            )]
        }
        n => panic!("a membrane element has 3 or 4 corners, not {n}"),
    }
}

/// The tangent vectors (∂x/∂r, ∂x/∂s) of the corners `x` at a point with derivatives `d`.
fn tangents(x: &[[f64; 3]], d: &[[f64; 2]]) -> (Vector3<f64>, Vector3<f64>) {
    let mut gr = Vector3::zeros();
    let mut gs = Vector3::zeros();
    for (xi, di) in x.iter().zip(d) {
        gr += di[0] * v3(*xi);
        gs += di[1] * v3(*xi);
    }
    (gr, gs)
}

/// The stretches and stresses at one point: (λ_1, λ_2, σ_1, σ_2).
pub type PointState = (f64, f64, f64, f64);

/// Internal forces (3 per corner) of a 4-node (bilinear) or 3-node (linear) element with
/// reference corners `x0`, current corners `x`, reference thickness `t0`; also each
/// integration point's principal stretches and stresses.
pub fn internal_forces(
    x0: &[[f64; 3]],
    x: &[[f64; 3]],
    t0: f64,
    law: &Ogden,
) -> (Vec<f64>, Vec<PointState>) {
    let nc = x0.len();
    let mut f = vec![0.0; 3 * nc];
    let mut states = Vec::new();
    for (w, _, d) in rule(nc) {
        let (gr0, gs0) = tangents(x0, &d);
        let e1 = gr0.normalize();
        let e3 = gr0.cross(&gs0).normalize();
        let e2 = e3.cross(&e1);
        let j0 = Matrix2::new(gr0.dot(&e1), gs0.dot(&e1), gr0.dot(&e2), gs0.dot(&e2));
        let da0 = j0.determinant();
        let j0inv = j0.try_inverse().expect("a degenerate membrane element");
        let (gr, gs) = tangents(x, &d);
        let g = Matrix3x2::from_columns(&[gr, gs]);
        let fgrad = g * j0inv;
        let c = fgrad.transpose() * fgrad;
        let eig = c.symmetric_eigen();
        let (l1, l2) = (eig.eigenvalues[0].sqrt(), eig.eigenvalues[1].sqrt());
        let (s1, s2) = law.principal_stress(l1, l2);
        let n1: Vector2<f64> = eig.eigenvectors.column(0).into_owned();
        let n2: Vector2<f64> = eig.eigenvectors.column(1).into_owned();
        let pk2 = n1 * n1.transpose() * (s1 / (l1 * l1)) + n2 * n2.transpose() * (s2 / (l2 * l2));
        let p = fgrad * pk2;
        for (i, di) in d.iter().enumerate() {
            let b = j0inv.transpose() * Vector2::new(di[0], di[1]);
            let fi = p * b * (t0 * da0 * w);
            for c in 0..3 {
                f[3 * i + c] += fi[c];
            }
        }
        states.push((l1, l2, s1, s2));
    }
    (f, states)
}

/// Nodal forces of a pressure `p` on the current surface, along g_r × g_s (the side the corner
/// order's right-hand normal points to): ∫ N_i p (g_r × g_s) dr ds.
pub fn pressure_forces(x: &[[f64; 3]], p: f64) -> Vec<f64> {
    let mut f = vec![0.0; 3 * x.len()];
    for (w, n, d) in rule(x.len()) {
        let (gr, gs) = tangents(x, &d);
        let a = gr.cross(&gs) * (p * w);
        for (i, ni) in n.iter().enumerate() {
            for c in 0..3 {
                f[3 * i + c] += ni * a[c];
            }
        }
    }
    f
}

/// The tangent ∂(f_int − f_pressure)/∂x of one element by central differences (step h, m):
/// rows and columns over the element's 3 × corners degrees of freedom (not symmetric: the
/// follower pressure).
pub fn tangent(
    x0: &[[f64; 3]],
    x: &[[f64; 3]],
    t0: f64,
    law: &Ogden,
    p: f64,
    h: f64,
) -> Vec<Vec<f64>> {
    let m = 3 * x.len();
    let residual = |xx: &[[f64; 3]]| {
        let (fi, _) = internal_forces(x0, xx, t0, law);
        let fp = pressure_forces(xx, p);
        fi.iter().zip(&fp).map(|(a, b)| a - b).collect::<Vec<f64>>()
    };
    let mut k = vec![vec![0.0; m]; m];
    for b in 0..m {
        let mut xp = x.to_vec();
        let mut xm = x.to_vec();
        xp[b / 3][b % 3] += h;
        xm[b / 3][b % 3] -= h;
        let (rp, rm) = (residual(&xp), residual(&xm));
        for a in 0..m {
            k[a][b] = (rp[a] - rm[a]) / (2.0 * h);
        }
    }
    k
}

/// ∫ N_i dA₀ of each corner on the reference surface (the lumped mass per unit ρ t₀).
pub fn corner_areas(x0: &[[f64; 3]]) -> Vec<f64> {
    let mut out = vec![0.0; x0.len()];
    for (w, n, d) in rule(x0.len()) {
        let (gr, gs) = tangents(x0, &d);
        let da = gr.cross(&gs).norm() * w;
        for (o, ni) in out.iter_mut().zip(&n) {
            *o += ni * da;
        }
    }
    out
}

/// ½ ∫ (x − c)_⊥ · n dA over the current element, ⊥ the part normal to the z axis through
/// `c`, n dA = g_r × g_s dr ds: summed over a surface closed by planes normal to z, the
/// volume it encloses (divergence theorem; the end planes add nothing). Exact for these
/// elements (the 2 × 2 rule integrates the bilinear quadrilateral's cubic integrand).
pub fn lateral_volume(x: &[[f64; 3]], c: [f64; 3]) -> f64 {
    let mut v = 0.0;
    for (w, n, d) in rule(x.len()) {
        let (gr, gs) = tangents(x, &d);
        let a = gr.cross(&gs);
        let mut p = [0.0; 2];
        for (xi, ni) in x.iter().zip(&n) {
            p[0] += ni * (xi[0] - c[0]);
            p[1] += ni * (xi[1] - c[1]);
        }
        v += 0.5 * w * (p[0] * a[0] + p[1] * a[1]);
    }
    v
}

/// The speed of the fastest in-plane wave at stretches (λ_1, λ_2) of a membrane of density
/// ρ: √(D_max/ρ), D_max the largest eigenvalue of the tangent dσ_a/d ln λ_b (by central
/// differences) plus the larger positive stress (the geometric stiffness). At small strain
/// D_max = 6 G (the equibiaxial mode), an upper bound of the P-wave's 4 G.
pub fn wave_speed(law: &Ogden, l1: f64, l2: f64, density: f64) -> f64 {
    let h: f64 = 1e-6;
    let (e, f) = (h.exp(), (-h).exp());
    let (a1, b1) = law.principal_stress(l1 * e, l2);
    let (a0, b0) = law.principal_stress(l1 * f, l2);
    let (c1, d1) = law.principal_stress(l1, l2 * e);
    let (c0, d0) = law.principal_stress(l1, l2 * f);
    let d11 = (a1 - a0) / (2.0 * h);
    let d21 = (b1 - b0) / (2.0 * h);
    let d12 = (c1 - c0) / (2.0 * h);
    let d22 = (d1 - d0) / (2.0 * h);
    let (m, q) = (0.5 * (d11 + d22), 0.5 * (d12 + d21));
    let r = (0.25 * (d11 - d22).powi(2) + q * q).sqrt();
    let (s1, s2) = law.principal_stress(l1, l2);
    let dmax = (m + r).max(0.0) + s1.max(s2).max(0.0);
    (dmax / density).sqrt()
}

/// The normal g_r × g_s at each integration point of an element with corners `x`.
pub fn point_normals(x: &[[f64; 3]]) -> Vec<[f64; 3]> {
    rule(x.len())
        .into_iter()
        .map(|(_, _, d)| {
            let (gr, gs) = tangents(x, &d);
            let n = gr.cross(&gs);
            [n[0], n[1], n[2]]
        })
        .collect()
}
