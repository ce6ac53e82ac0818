//! A finite-strain 4-node membrane with the incompressible Ogden law (the confining rubber
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

use crate::shell::shape;
use nalgebra::{Matrix2, Matrix3x2, Vector2, Vector3};

/// Degrees of freedom of one element (three translations per node).
pub const DOFS: usize = 12;

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

const GAUSS: [f64; 2] = [-0.577_350_269_189_625_8, 0.577_350_269_189_625_8];

/// The tangent vectors (∂x/∂r, ∂x/∂s) at (r, s) of the corners `x`.
fn tangents(x: &[[f64; 3]; 4], d: &[[f64; 2]; 4]) -> (Vector3<f64>, Vector3<f64>) {
    let mut gr = Vector3::zeros();
    let mut gs = Vector3::zeros();
    for i in 0..4 {
        gr += d[i][0] * v3(x[i]);
        gs += d[i][1] * v3(x[i]);
    }
    (gr, gs)
}

/// The stretches and stresses at one point: (λ_1, λ_2, σ_1, σ_2).
pub type PointState = (f64, f64, f64, f64);

/// Internal forces of an element with reference corners `x0`, current corners `x`, reference
/// thickness `t0`; also each Gauss point's principal stretches and stresses.
pub fn internal_forces(
    x0: &[[f64; 3]; 4],
    x: &[[f64; 3]; 4],
    t0: f64,
    law: &Ogden,
) -> ([f64; DOFS], [PointState; 4]) {
    let mut f = [0.0; DOFS];
    let mut states = [(1.0, 1.0, 0.0, 0.0); 4];
    let mut k = 0;
    for &r in &GAUSS {
        for &s in &GAUSS {
            let (_, d) = shape(r, s);
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
            let pk2 =
                n1 * n1.transpose() * (s1 / (l1 * l1)) + n2 * n2.transpose() * (s2 / (l2 * l2));
            let p = fgrad * pk2;
            for i in 0..4 {
                let b = j0inv.transpose() * Vector2::new(d[i][0], d[i][1]);
                let fi = p * b * (t0 * da0);
                for c in 0..3 {
                    f[3 * i + c] += fi[c];
                }
            }
            states[k] = (l1, l2, s1, s2);
            k += 1;
        }
    }
    (f, states)
}

/// Nodal forces of a pressure `p` on the current surface, along g_r × g_s (the side the corner
/// order's right-hand normal points to): ∫ N_i p (g_r × g_s) dr ds.
pub fn pressure_forces(x: &[[f64; 3]; 4], p: f64) -> [f64; DOFS] {
    let mut f = [0.0; DOFS];
    for &r in &GAUSS {
        for &s in &GAUSS {
            let (n, d) = shape(r, s);
            let (gr, gs) = tangents(x, &d);
            let a = gr.cross(&gs) * p;
            for i in 0..4 {
                for c in 0..3 {
                    f[3 * i + c] += n[i] * a[c];
                }
            }
        }
    }
    f
}

/// The tangent ∂(f_int − f_pressure)/∂x of one element by central differences (step h, m):
/// row-major 12 × 12 (not symmetric: the follower pressure).
pub fn tangent(
    x0: &[[f64; 3]; 4],
    x: &[[f64; 3]; 4],
    t0: f64,
    law: &Ogden,
    p: f64,
    h: f64,
) -> [[f64; DOFS]; DOFS] {
    let residual = |xx: &[[f64; 3]; 4]| {
        let (fi, _) = internal_forces(x0, xx, t0, law);
        let fp = pressure_forces(xx, p);
        std::array::from_fn::<f64, DOFS, _>(|a| fi[a] - fp[a])
    };
    let mut k = [[0.0; DOFS]; DOFS];
    for b in 0..DOFS {
        let mut xp = *x;
        let mut xm = *x;
        xp[b / 3][b % 3] += h;
        xm[b / 3][b % 3] -= h;
        let (rp, rm) = (residual(&xp), residual(&xm));
        for a in 0..DOFS {
            k[a][b] = (rp[a] - rm[a]) / (2.0 * h);
        }
    }
    k
}
