//! Finite-strain isotropic hyperelasticity for total-Lagrangian FEM.
//!
//! Conventions:
//! * symmetric tensors are `[f64; 6]` in Voigt order (11, 22, 33, 12, 23, 31),
//!   tensor components (shear not doubled);
//! * [`Tangent`] is ℂ = ∂S/∂E = 2 ∂S/∂C acting on engineering strain
//!   increments Ê = (E11, E22, E33, 2E12, 2E23, 2E31): δS_I = Σ_J ℂ_IJ δÊ_J,
//!   i.e. ℂ_IJ = ℂ_ijkl with I = (ij), J = (kl);
//! * Ψ is the stored energy per reference volume.
//!
//! The evaluation functions never panic and never touch the heap.

use nalgebra::{Matrix3, SMatrix};
use std::fmt;

/// Material tangent ℂ = ∂S/∂E in Voigt form (see module docs).
pub type Tangent = SMatrix<f64, 6, 6>;

/// Result of an evaluation: (S in Voigt, ℂ, Ψ).
pub type Response = ([f64; 6], Tangent, f64);

const VOIGT: [(usize, usize); 6] = [(0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (2, 0)];
const PAIRS: [(usize, usize); 3] = [(0, 1), (0, 2), (1, 2)];

/// J = det F is not a finite positive number (or F has non-finite entries).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NonPositiveJacobian {
    /// The offending J = det F.
    pub j: f64,
}

impl fmt::Display for NonPositiveJacobian {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "non-positive Jacobian: J = det F = {:e}", self.j)
    }
}

impl std::error::Error for NonPositiveJacobian {}

/// x > 0 (false for NaN).
fn positive(x: f64) -> bool {
    x > 0.0
}

fn jacobian(f: &Matrix3<f64>) -> Result<f64, NonPositiveJacobian> {
    let j = f.determinant();
    if f.iter().all(|x| x.is_finite()) && j.is_finite() && j > 0.0 {
        Ok(j)
    } else {
        Err(NonPositiveJacobian { j })
    }
}

fn to_voigt(a: &Matrix3<f64>) -> [f64; 6] {
    VOIGT.map(|(i, j)| 0.5 * (a[(i, j)] + a[(j, i)]))
}

fn from_voigt(s: &[f64; 6]) -> Matrix3<f64> {
    Matrix3::new(s[0], s[3], s[5], s[3], s[1], s[4], s[5], s[4], s[2])
}

/// a ⊗ b in Voigt form.
fn outer(a: &[f64; 6], b: &[f64; 6]) -> Tangent {
    Tangent::from_fn(|i, j| a[i] * b[j])
}

/// 𝕀_X with (𝕀_X)_ijkl = ½ (X_ik X_jl + X_il X_jk), X symmetric.
fn sym_prod(x: &Matrix3<f64>) -> Tangent {
    Tangent::from_fn(|r, c| {
        let ((i, j), (k, l)) = (VOIGT[r], VOIGT[c]);
        0.5 * (x[(i, k)] * x[(j, l)] + x[(i, l)] * x[(j, k)])
    })
}

/// Cauchy stress σ = J⁻¹ F S Fᵀ (Voigt, tensor components).
/// The caller guarantees J = det F > 0 (as checked by the `evaluate` functions).
pub fn cauchy_from_pk2(f: &Matrix3<f64>, s: &[f64; 6]) -> [f64; 6] {
    let j = f.determinant();
    to_voigt(&(f * from_voigt(s) * f.transpose() / j))
}

fn inverse_c(f: &Matrix3<f64>, j: f64) -> Result<Matrix3<f64>, NonPositiveJacobian> {
    let fi = f.try_inverse().ok_or(NonPositiveJacobian { j })?;
    Ok(fi * fi.transpose())
}

/// S and ℂ of an energy Ψ(I₁, I₂, I₃) (I₃ = det C), given d_a = ∂Ψ/∂I_a and
/// dd_ab = ∂²Ψ/∂I_a∂I_b (Holzapfel 2000, Ch. 6):
/// S = 2[(Ψ₁ + I₁Ψ₂) I − Ψ₂ C + I₃Ψ₃ C⁻¹],
/// ℂ = 4 Σ_ab Ψ_ab G_a⊗G_b + 4Ψ₂(I⊗I − 𝕀) + 4I₃Ψ₃(C⁻¹⊗C⁻¹ − 𝕀_{C⁻¹}),
/// with G₁ = I, G₂ = I₁I − C, G₃ = I₃C⁻¹.
fn invariant_response(
    c: &Matrix3<f64>,
    ci: &Matrix3<f64>,
    i3: f64,
    d: [f64; 3],
    dd: [[f64; 3]; 3],
) -> ([f64; 6], Tangent) {
    let id = Matrix3::identity();
    let i1 = c.trace();
    let g = [
        to_voigt(&id),
        to_voigt(&(id * i1 - c)),
        to_voigt(&(ci * i3)),
    ];
    let s = (id * (d[0] + i1 * d[1]) - c * d[1] + ci * (i3 * d[2])) * 2.0;
    let mut t = Tangent::zeros();
    for (a, ga) in g.iter().enumerate() {
        for (b, gb) in g.iter().enumerate() {
            if dd[a][b] != 0.0 {
                t += outer(ga, gb) * (4.0 * dd[a][b]);
            }
        }
    }
    t += (outer(&g[0], &g[0]) - sym_prod(&id)) * (4.0 * d[1]);
    let civ = to_voigt(ci);
    t += (outer(&civ, &civ) - sym_prod(ci)) * (4.0 * i3 * d[2]);
    (to_voigt(&s), t)
}

/// Volumetric energy U(J) = K/4 (J² − 1 − 2 ln J) (U(1) = U'(1) = 0, U''(1) = K).
fn vol_energy(k: f64, j: f64) -> f64 {
    0.25 * k * (j * j - 1.0 - 2.0 * j.ln())
}

/// Compressible Neo-Hooke (Wellmann's thesis, §2.1.4, unnumbered eq.; standard
/// form, cf. Wriggers 2008, *Nonlinear Finite Element Methods*, Ch. 3):
///
/// Ψ = λ/4 (J² − 1 − 2 ln J) + μ/2 (tr C − 3 − 2 ln J),
/// S = λ/2 (J² − 1) C⁻¹ + μ (I − C⁻¹),
/// ℂ = λJ² C⁻¹⊗C⁻¹ + [2μ − λ(J² − 1)] 𝕀_{C⁻¹}.
///
/// **Erratum:** the thesis prints μ/2 (tr C − 3) without −2 ln J, which gives
/// S = μ I at F = I (stressed reference); the −μ ln J term is restored here.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NeoHooke {
    pub lambda: f64,
    pub mu: f64,
}

impl NeoHooke {
    /// From Young's modulus and Poisson's ratio: λ = Eν/((1+ν)(1−2ν)), μ = E/(2(1+ν)).
    pub fn from_young_poisson(e: f64, nu: f64) -> Self {
        Self {
            lambda: e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)),
            mu: e / (2.0 * (1.0 + nu)),
        }
    }

    /// (K, G) = (λ + 2μ/3, μ).
    pub fn small_strain_moduli(&self) -> (f64, f64) {
        (self.lambda + 2.0 * self.mu / 3.0, self.mu)
    }

    /// Requires μ > 0 and K = λ + 2μ/3 > 0.
    pub fn check(&self) -> Result<(), String> {
        let (k, g) = self.small_strain_moduli();
        if positive(g) && positive(k) {
            Ok(())
        } else {
            Err(format!("NeoHooke: need mu > 0 and lambda + 2 mu/3 > 0; got mu = {g:e}, lambda + 2 mu/3 = {k:e}"))
        }
    }

    /// (S, ℂ, Ψ) at deformation gradient `f`.
    pub fn evaluate(&self, f: &Matrix3<f64>) -> Result<Response, NonPositiveJacobian> {
        let j = jacobian(f)?;
        let ci = inverse_c(f, j)?;
        let c = f.transpose() * f;
        let (lam, mu) = (self.lambda, self.mu);
        let (j2, ln_j) = (j * j, j.ln());
        let psi = 0.25 * lam * (j2 - 1.0 - 2.0 * ln_j) + 0.5 * mu * (c.trace() - 3.0 - 2.0 * ln_j);
        let s = ci * (0.5 * lam * (j2 - 1.0)) + (Matrix3::identity() - ci) * mu;
        let civ = to_voigt(&ci);
        let t = outer(&civ, &civ) * (lam * j2) + sym_prod(&ci) * (2.0 * mu - lam * (j2 - 1.0));
        Ok((to_voigt(&s), t, psi))
    }

    /// [`NeoHooke::evaluate`] at F = I + H from the displacement gradient H, without losing
    /// the strain to the 1 of F: J − 1 = tr H + ½[(tr H)² − tr H²] + det H, and
    /// I − C⁻¹ = C⁻¹ (C − I) with C − I = H + Hᵀ + HᵀH. At the strains of a steel structure
    /// (1e-6) forming F first costs ten digits of the stress, and Newton iterations stall on
    /// that noise.
    pub fn evaluate_gradient(&self, h: &Matrix3<f64>) -> Result<Response, NonPositiveJacobian> {
        let tr = h.trace();
        let jm1 = tr + 0.5 * (tr * tr - (h * h).trace()) + h.determinant();
        let j = 1.0 + jm1;
        if !(h.iter().all(|x| x.is_finite()) && j.is_finite() && j > 0.0) {
            return Err(NonPositiveJacobian { j });
        }
        let f = Matrix3::identity() + h;
        let ci = inverse_c(&f, j)?;
        let c_minus_i = h + h.transpose() + h.transpose() * h;
        let (lam, mu) = (self.lambda, self.mu);
        let j2m1 = jm1 * (2.0 + jm1);
        let ln_j = jm1.ln_1p();
        let psi = 0.25 * lam * (j2m1 - 2.0 * ln_j) + 0.5 * mu * (c_minus_i.trace() - 2.0 * ln_j);
        let s = ci * (0.5 * lam * j2m1) + ci * c_minus_i * mu;
        let civ = to_voigt(&ci);
        let t = outer(&civ, &civ) * (lam * (1.0 + j2m1)) + sym_prod(&ci) * (2.0 * mu - lam * j2m1);
        Ok((to_voigt(&s), t, psi))
    }
}

/// Decoupled compressible Mooney–Rivlin (Mooney 1940; Rivlin 1948; split as in
/// Holzapfel 2000, *Nonlinear Solid Mechanics*, Ch. 6):
///
/// Ψ = U(J) + c₁(Ī₁ − 3) + c₂(Ī₂ − 3), Ī₁ = J^(−2/3) I₁, Ī₂ = J^(−4/3) I₂,
/// U(J) = K/4 (J² − 1 − 2 ln J). Small-strain moduli: K and G = 2(c₁ + c₂).
/// S and ℂ via Ψ(I₁, I₂, I₃) with I₃ = J² (see `invariant_response`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MooneyRivlin {
    pub bulk: f64,
    pub c1: f64,
    pub c2: f64,
}

impl MooneyRivlin {
    /// K = E/(3(1−2ν)), G = E/(2(1+ν)), c₁ = (1−c)G/2, c₂ = cG/2, where c is the
    /// share of the shear modulus carried by the second invariant.
    pub fn from_young_poisson_ratio(e: f64, nu: f64, c: f64) -> Self {
        let g = e / (2.0 * (1.0 + nu));
        Self {
            bulk: e / (3.0 * (1.0 - 2.0 * nu)),
            c1: 0.5 * (1.0 - c) * g,
            c2: 0.5 * c * g,
        }
    }

    /// (K, G) = (K, 2(c₁ + c₂)).
    pub fn small_strain_moduli(&self) -> (f64, f64) {
        (self.bulk, 2.0 * (self.c1 + self.c2))
    }

    /// Requires K > 0, c₁ + c₂ > 0, c₁ ≥ 0, c₂ ≥ 0.
    pub fn check(&self) -> Result<(), String> {
        let (k, c1, c2) = (self.bulk, self.c1, self.c2);
        if positive(k) && positive(c1 + c2) && c1 >= 0.0 && c2 >= 0.0 {
            Ok(())
        } else {
            Err(format!("MooneyRivlin: need K > 0, c1 + c2 > 0, c1 >= 0, c2 >= 0; got K = {k:e}, c1 = {c1:e}, c2 = {c2:e}"))
        }
    }

    /// (S, ℂ, Ψ) at deformation gradient `f`.
    pub fn evaluate(&self, f: &Matrix3<f64>) -> Result<Response, NonPositiveJacobian> {
        let j = jacobian(f)?;
        let ci = inverse_c(f, j)?;
        let c = f.transpose() * f;
        let (k, c1, c2) = (self.bulk, self.c1, self.c2);
        let i1 = c.trace();
        let i2 = 0.5 * (i1 * i1 - (c * c).trace());
        let i3 = j * j;
        let jm23 = j.powf(-2.0 / 3.0);
        let jm43 = jm23 * jm23;
        let psi = vol_energy(k, j) + c1 * (jm23 * i1 - 3.0) + c2 * (jm43 * i2 - 3.0);
        // ∂Ψ/∂I_a and ∂²Ψ/∂I_a∂I_b (Ψ₁₁ = Ψ₁₂ = Ψ₂₂ = 0).
        let d3 = 0.25 * k * (1.0 - 1.0 / i3) - (c1 * i1 * jm23 + 2.0 * c2 * i2 * jm43) / (3.0 * i3);
        let d13 = -c1 * jm23 / (3.0 * i3);
        let d23 = -2.0 * c2 * jm43 / (3.0 * i3);
        let d33 =
            0.25 * k / (i3 * i3) + (4.0 * c1 * i1 * jm23 + 10.0 * c2 * i2 * jm43) / (9.0 * i3 * i3);
        let dd = [[0.0, 0.0, d13], [0.0, 0.0, d23], [d13, d23, d33]];
        let (s, t) = invariant_response(&c, &ci, i3, [c1 * jm23, c2 * jm43, d3], dd);
        Ok((s, t, psi))
    }
}

/// Decoupled compressible Ogden model (Ogden 1972, Proc. R. Soc. A 326:565):
///
/// Ψ = U(J) + Σ_p μ_p/α_p (λ̄₁^α_p + λ̄₂^α_p + λ̄₃^α_p − 3), λ̄_i = J^(−1/3) λ_i,
/// U(J) = K/4 (J² − 1 − 2 ln J). Small-strain moduli: K and G = ½ Σ μ_p α_p.
///
/// Spectral form (Simo & Taylor 1991, CMAME 85:273; Miehe 1994, IJNME 37:1981):
/// with y_a = λ_a² (eigenvalues of C), N_a eigenvectors, M_a = N_a⊗N_a,
/// τ_a = Σ_p μ_p (λ̄_a^α_p − ⅓ Σ_k λ̄_k^α_p) + J U'(J), S_a = τ_a / y_a,
/// S = Σ_a S_a M_a,
/// ℂ = Σ_ab 2 ∂S_a/∂y_b M_a⊗M_b + Σ_{a≠b} (S_b − S_a)/(y_b − y_a)
///     (N_a⊗N_b⊗N_a⊗N_b + N_a⊗N_b⊗N_b⊗N_a).
/// The quotient is evaluated as an exact divided difference
/// (S_a = Σ_p μ_p J^(−α_p/3) y_a^(α_p/2−1) + q / y_a, q symmetric), which is
/// smooth in (y_a, y_b) and equals the L'Hôpital limit at y_a = y_b, so the
/// tangent is consistent for coincident stretches without perturbation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ogden {
    pub bulk: f64,
    /// (μ_p, α_p); only the first `n_terms` are used.
    pub terms: [(f64, f64); 3],
    pub n_terms: usize,
}

impl Ogden {
    /// 1..=3 terms (μ_p, α_p) with finite, non-zero α_p.
    pub fn new(bulk: f64, terms: &[(f64, f64)]) -> Result<Self, String> {
        if terms.is_empty() || terms.len() > 3 {
            return Err(format!("Ogden: need 1..=3 terms, got {}", terms.len()));
        }
        for (p, &(_, alpha)) in terms.iter().enumerate() {
            if alpha == 0.0 || !alpha.is_finite() {
                return Err(format!("Ogden: term {} has alpha = {alpha:e}", p + 1));
            }
        }
        let mut t = [(0.0, 1.0); 3];
        t[..terms.len()].copy_from_slice(terms);
        Ok(Self {
            bulk,
            terms: t,
            n_terms: terms.len(),
        })
    }

    fn active(&self) -> &[(f64, f64)] {
        &self.terms[..self.n_terms.min(3)]
    }

    /// (K, G) = (K, ½ Σ μ_p α_p).
    pub fn small_strain_moduli(&self) -> (f64, f64) {
        let g = 0.5 * self.active().iter().map(|(m, a)| m * a).sum::<f64>();
        (self.bulk, g)
    }

    /// Ogden's sufficient condition μ_p α_p > 0 for every term, and K > 0.
    pub fn check(&self) -> Result<(), String> {
        if self.n_terms == 0 || self.n_terms > 3 {
            return Err(format!("Ogden: n_terms = {} not in 1..=3", self.n_terms));
        }
        for (p, &(mu, alpha)) in self.active().iter().enumerate() {
            if !positive(mu * alpha) {
                return Err(format!(
                    "Ogden: term {} has mu_p*alpha_p = {:e} (must be > 0)",
                    p + 1,
                    mu * alpha
                ));
            }
        }
        if !positive(self.bulk) {
            return Err(format!("Ogden: bulk = {:e} must be > 0", self.bulk));
        }
        Ok(())
    }

    /// (S, ℂ, Ψ) at deformation gradient `f`.
    pub fn evaluate(&self, f: &Matrix3<f64>) -> Result<Response, NonPositiveJacobian> {
        let j = jacobian(f)?;
        let (y, v) = super::sym_eigen(&(f.transpose() * f));
        if !y.iter().all(|&x| x > 0.0 && x.is_finite()) {
            return Err(NonPositiveJacobian { j });
        }
        let (k, j2, ln_j) = (self.bulk, j * j, j.ln());
        let vol = 0.5 * k * (j2 - 1.0); // J U'(J)
        let mut psi = vol_energy(k, j);
        let mut tau = [vol; 3];
        // dtau[a][b] = λ_b ∂τ_a/∂λ_b; volumetric part J (J U')' = K J².
        let mut dtau = [[k * j2; 3]; 3];
        let mut q = vol;
        let mut g = [0.0; 3]; // divided differences for PAIRS
        for &(mu, alpha) in self.active() {
            let s = (-alpha * ln_j / 3.0).exp(); // J^(−α/3)
            let b = y.map(|ya| s * ya.powf(0.5 * alpha)); // λ̄_a^α
            let sb = b[0] + b[1] + b[2];
            psi += mu / alpha * (sb - 3.0);
            q -= mu * sb / 3.0;
            for a in 0..3 {
                tau[a] += mu * (b[a] - sb / 3.0);
                for c in 0..3 {
                    let diag = if a == c { b[a] } else { 0.0 };
                    dtau[a][c] += mu * alpha * (diag - (b[a] + b[c]) / 3.0 + sb / 9.0);
                }
            }
            for (gp, &(a, c)) in g.iter_mut().zip(PAIRS.iter()) {
                *gp += mu * s * divided_power(y[a], y[c], 0.5 * alpha - 1.0);
            }
        }
        let n = [v.column(0), v.column(1), v.column(2)];
        let m = n.map(|na| to_voigt(&(na * na.transpose())));
        let mut stress = [0.0; 6];
        let mut t = Tangent::zeros();
        for a in 0..3 {
            let sa = tau[a] / y[a];
            for (si, ma) in stress.iter_mut().zip(m[a].iter()) {
                *si += sa * ma;
            }
            for c in 0..3 {
                let diag = if a == c {
                    2.0 * tau[a] / (y[a] * y[a])
                } else {
                    0.0
                };
                t += outer(&m[a], &m[c]) * (dtau[a][c] / (y[a] * y[c]) - diag);
            }
        }
        for (gp, &(a, c)) in g.iter().zip(PAIRS.iter()) {
            let coeff = gp - q / (y[a] * y[c]); // (S_c − S_a)/(y_c − y_a)
            let p = to_voigt(&(n[a] * n[c].transpose()));
            t += outer(&p, &p) * (4.0 * coeff);
        }
        Ok((stress, t, psi))
    }
}

/// (b^γ − a^γ)/(b − a) for a, b > 0, exact limit γ a^(γ−1) at a = b.
/// Written as a^(γ−1) expm1(γL)/expm1(L), L = ln(b/a): smooth, no cancellation.
fn divided_power(a: f64, b: f64, gamma: f64) -> f64 {
    let l = ((b - a) / a).ln_1p();
    let base = a.powf(gamma - 1.0);
    if l == 0.0 {
        gamma * base
    } else {
        base * (gamma * l).exp_m1() / l.exp_m1()
    }
}

#[cfg(test)]
mod tests {
    /// The gradient form agrees with the F form at large strain and stays accurate at tiny
    /// strain, where S must equal the linear law λ tr E I + 2μ E to O(E²).
    #[test]
    fn neo_hooke_gradient_form_is_accurate_at_tiny_strain() {
        let m = NeoHooke::from_young_poisson(210e9, 0.3);
        let base = Matrix3::new(0.3, -0.2, 0.1, 0.05, -0.1, 0.2, -0.15, 0.25, 0.12);
        let (s1, t1, p1) = m.evaluate(&(Matrix3::identity() + base)).unwrap();
        let (s2, t2, p2) = m.evaluate_gradient(&base).unwrap();
        let smax = s1.iter().fold(0.0f64, |a, b| a.max(b.abs()));
        for k in 0..6 {
            assert!((s1[k] - s2[k]).abs() < 1e-13 * smax, "{s1:?} vs {s2:?}");
        }
        assert!((t1 - t2).norm() < 1e-13 * t1.norm());
        assert!((p1 - p2).abs() < 1e-12 * p1.abs());
        for scale in [1e-6, 1e-9] {
            let h = base * scale;
            let e = (h + h.transpose() + h.transpose() * h) * 0.5;
            let lin = Matrix3::identity() * (m.lambda * e.trace()) + e * (2.0 * m.mu);
            let (s, _, _) = m.evaluate_gradient(&h).unwrap();
            let (sf, _, _) = m.evaluate(&(Matrix3::identity() + h)).unwrap();
            let lv = to_voigt(&lin);
            let lmax = lv.iter().fold(0.0f64, |a, b| a.max(b.abs()));
            let err = (0..6).fold(0.0f64, |a, k| a.max((s[k] - lv[k]).abs() / lmax));
            let err_f = (0..6).fold(0.0f64, |a, k| a.max((sf[k] - lv[k]).abs() / lmax));
            println!("strain {scale:e}: gradient form {err:.1e}, F form {err_f:.1e}");
            assert!(err < 10.0 * scale, "strain {scale}: {err:e}");
        }
    }

    use super::*;
    use nalgebra::{Rotation3, Unit, Vector3};

    /// SplitMix64: deterministic, seeded.
    struct Rng(u64);
    impl Rng {
        fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^= z >> 31;
            lo + (hi - lo) * ((z >> 11) as f64 / (1u64 << 53) as f64)
        }
        fn rotation(&mut self) -> Matrix3<f64> {
            let axis = Vector3::from_fn(|i, _| self.uniform(-1.0, 1.0) + 0.1 * i as f64);
            let angle = self.uniform(0.2, 3.0);
            Rotation3::from_axis_angle(&Unit::new_normalize(axis), angle).into_inner()
        }
        /// Random F with det F uniform in [0.6, 1.6].
        fn def_grad(&mut self) -> Matrix3<f64> {
            loop {
                let g =
                    Matrix3::from_fn(|i, j| f64::from(u8::from(i == j)) + self.uniform(-0.4, 0.4));
                let d = g.determinant();
                if d > 0.2 {
                    let target = self.uniform(0.6, 1.6);
                    return g * (target / d).cbrt();
                }
            }
        }
    }

    #[derive(Clone, Copy, Debug)]
    enum Model {
        Nh(NeoHooke),
        Mr(MooneyRivlin),
        Og(Ogden),
    }

    impl Model {
        fn eval(&self, f: &Matrix3<f64>) -> Response {
            self.try_eval(f).expect("J > 0 in test")
        }
        fn try_eval(&self, f: &Matrix3<f64>) -> Result<Response, NonPositiveJacobian> {
            match self {
                Model::Nh(m) => m.evaluate(f),
                Model::Mr(m) => m.evaluate(f),
                Model::Og(m) => m.evaluate(f),
            }
        }
        fn moduli(&self) -> (f64, f64) {
            match self {
                Model::Nh(m) => m.small_strain_moduli(),
                Model::Mr(m) => m.small_strain_moduli(),
                Model::Og(m) => m.small_strain_moduli(),
            }
        }
    }

    const MU_W: f64 = 0.5e6;

    fn wellmann(bulk: f64) -> Ogden {
        let terms = [
            (1.491 * MU_W, 1.3),
            (0.003 * MU_W, 5.0),
            (-0.0237 * MU_W, -2.0),
        ];
        Ogden::new(bulk, &terms).unwrap()
    }

    fn models() -> Vec<(&'static str, Model)> {
        let nh = |nu| Model::Nh(NeoHooke::from_young_poisson(2.0e6, nu));
        let mr = |nu, c| Model::Mr(MooneyRivlin::from_young_poisson_ratio(2.0e6, nu, c));
        let og = |k, t: &[(f64, f64)]| Model::Og(Ogden::new(k, t).unwrap());
        vec![
            ("NH", nh(0.3)),
            ("NH nu=.45", nh(0.45)),
            ("MR c=.3", mr(0.3, 0.3)),
            ("MR c=1", mr(0.2, 1.0)),
            ("Ogden 1", og(2.0e6, &[(6.0e5, 1.7)])),
            ("Ogden 2", og(3.0e6, &[(4.0e5, 2.6), (-3.0e4, -1.5)])),
            ("Ogden W K=1e9", Model::Og(wellmann(1.0e9))),
            ("Ogden W K=2mu", Model::Og(wellmann(2.0 * MU_W))),
        ]
    }

    fn norm6(a: &[f64; 6]) -> f64 {
        SMatrix::<f64, 6, 1>::from(*a).norm()
    }

    fn diff6(a: &[f64; 6], b: &[f64; 6]) -> f64 {
        (SMatrix::<f64, 6, 1>::from(*a) - SMatrix::<f64, 6, 1>::from(*b)).norm()
    }

    /// Isochoric Ogden principal Kirchhoff stresses Σ μ_p (λ̄_i^α − ⅓ Σ_k λ̄_k^α).
    fn ogden_dev_tau(og: &Ogden, lbar: [f64; 3]) -> [f64; 3] {
        let mut t = [0.0; 3];
        for &(mu, a) in &og.terms[..og.n_terms] {
            let p = lbar.map(|x| x.powf(a));
            let mean = (p[0] + p[1] + p[2]) / 3.0;
            for i in 0..3 {
                t[i] += mu * (p[i] - mean);
            }
        }
        t
    }

    fn closed_form_models() -> (NeoHooke, MooneyRivlin, Ogden) {
        let og = Ogden::new(3.0e6, &[(4.0e5, 2.6), (-3.0e4, -1.5), (2.0e3, 4.0)]);
        (
            NeoHooke::from_young_poisson(2.0e6, 0.3),
            MooneyRivlin::from_young_poisson_ratio(2.0e6, 0.3, 0.4),
            og.unwrap(),
        )
    }

    fn isotropic(k: f64, g: f64) -> Tangent {
        let mut t = Tangent::zeros();
        for i in 0..3 {
            for j in 0..3 {
                t[(i, j)] = k - 2.0 * g / 3.0 + if i == j { 2.0 * g } else { 0.0 };
            }
            t[(i + 3, i + 3)] = g;
        }
        t
    }

    /// Engineering Voigt vector of sym(Fᵀ D) (= dE/dt exactly for central stencils).
    fn eng_rate(f: &Matrix3<f64>, d: &Matrix3<f64>) -> [f64; 6] {
        let e = to_voigt(&(f.transpose() * d));
        [e[0], e[1], e[2], 2.0 * e[3], 2.0 * e[4], 2.0 * e[5]]
    }

    const H: f64 = 1e-3;

    /// Five-point central derivative of g(F + tD) at t = 0.
    fn deriv<T, G>(g: G, f: &Matrix3<f64>, d: &Matrix3<f64>) -> T
    where
        G: Fn(&Matrix3<f64>) -> T,
        T: std::ops::Sub<Output = T> + std::ops::Mul<f64, Output = T>,
    {
        let at = |t: f64| g(&(f + d * t));
        ((at(H) - at(-H)) * 8.0 - (at(2.0 * H) - at(-2.0 * H))) * (1.0 / (12.0 * H))
    }

    fn unit(k: usize) -> Matrix3<f64> {
        let mut d = Matrix3::zeros();
        d[(k / 3, k % 3)] = 1.0;
        d
    }

    /// ‖∂Ψ/∂F|_fd − F S‖ / ‖F S‖.
    fn stress_fd_error(m: &Model, f: &Matrix3<f64>) -> f64 {
        let p = f * from_voigt(&m.eval(f).0);
        let mut err = 0.0;
        for k in 0..9 {
            let fd: f64 = deriv(|x| m.eval(x).2, f, &unit(k));
            err += (fd - p[(k / 3, k % 3)]).powi(2);
        }
        err.sqrt() / p.norm()
    }

    /// ‖δS_fd − ℂ δÊ‖ / ‖ℂ δÊ‖ over the 9 directions D = e_k ⊗ e_l.
    fn tangent_fd_error(m: &Model, f: &Matrix3<f64>) -> f64 {
        let t = m.eval(f).1;
        let (mut err, mut nrm) = (0.0, 0.0);
        for k in 0..9 {
            let d = unit(k);
            let fd = deriv(|x| SMatrix::<f64, 6, 1>::from(m.eval(x).0), f, &d);
            let an = t * SMatrix::<f64, 6, 1>::from(eng_rate(f, &d));
            err += (fd - an).norm_squared();
            nrm += an.norm_squared();
        }
        (err / nrm).sqrt()
    }

    fn degenerate_states(rng: &mut Rng) -> Vec<(&'static str, Matrix3<f64>)> {
        let r = rng.rotation();
        let q = rng.rotation();
        let d2 = Matrix3::from_diagonal(&Vector3::new(1.35, 0.85, 0.85));
        let d2b = Matrix3::from_diagonal(&Vector3::new(0.7, 1.2, 0.7));
        let near = Matrix3::from_diagonal(&Vector3::new(1.35, 0.85, 0.85 * (1.0 + 1e-9)));
        vec![
            ("diag(a,b,b)", d2),
            ("diag(a,b,a)", d2b),
            ("R diag(a,b,b) R^T", r * d2 * r.transpose()),
            ("Q R diag(a,b,b) R^T", q * r * d2b * r.transpose()),
            ("R diag(a,b,b+1e-9) R^T", r * near * r.transpose()),
            ("s I", Matrix3::identity() * 1.1),
            ("s I (compr.)", Matrix3::identity() * 0.85),
            ("I", Matrix3::identity()),
            ("rotation", q),
        ]
    }

    #[test]
    fn reference_state_is_stress_free_with_isotropic_tangent() {
        let mut all = models();
        let w = wellmann(1.0e9);
        let one = Ogden::new(1.0e9, &[(w.terms[0].0, 1.3)]).unwrap();
        let two = Ogden::new(1.0e9, &w.terms[..2]).unwrap();
        all.push(("Ogden W 1-term", Model::Og(one)));
        all.push(("Ogden W 2-term", Model::Og(two)));
        let mut worst: f64 = 0.0;
        for (name, m) in &all {
            let (s, t, psi) = m.eval(&Matrix3::identity());
            let (k, g) = m.moduli();
            assert!(norm6(&s) <= 1e-12 * g, "{name}: S = {s:?}");
            assert!(psi.abs() <= 1e-12 * g, "{name}: psi = {psi}");
            let iso = isotropic(k, g);
            let rel = (t - iso).amax() / iso.amax();
            worst = worst.max(rel);
            assert!(rel <= 1e-12, "{name}: tangent rel err {rel:e}");
        }
        println!("reference tangent: max rel err {worst:e}");
        let (_, g) = w.small_strain_moduli();
        assert!((g / MU_W - 1.00035).abs() < 1e-12);
    }

    #[test]
    fn stress_is_energy_gradient() {
        let mut rng = Rng(0x5eed_0001);
        let fs: Vec<_> = (0..8).map(|_| rng.def_grad()).collect();
        let mut worst: f64 = 0.0;
        for (name, m) in models() {
            for f in &fs {
                let j = f.determinant();
                assert!((0.6..=1.6).contains(&j));
                let e = stress_fd_error(&m, f);
                worst = worst.max(e);
                assert!(e <= 1e-6, "{name}: rel err {e:e} at {f}");
            }
        }
        println!("S vs dPsi/dE (FD): max rel err {worst:e}");
    }

    #[test]
    fn tangent_is_stress_derivative_random() {
        let mut rng = Rng(0x5eed_0002);
        let fs: Vec<_> = (0..8).map(|_| rng.def_grad()).collect();
        let mut worst: f64 = 0.0;
        for (name, m) in models() {
            for f in &fs {
                let e = tangent_fd_error(&m, f);
                worst = worst.max(e);
                assert!(e <= 1e-6, "{name}: rel err {e:e} at {f}");
                let t = m.eval(f).1;
                assert!(
                    (t - t.transpose()).amax() <= 1e-12 * t.amax(),
                    "{name}: asym"
                );
            }
        }
        println!("C vs dS/dE (FD), random F: max rel err {worst:e}");
    }

    #[test]
    fn tangent_is_stress_derivative_equal_stretches() {
        let mut rng = Rng(0x5eed_0003);
        let states = degenerate_states(&mut rng);
        let mut worst: f64 = 0.0;
        for (name, m) in models() {
            for (sname, f) in &states {
                let e = tangent_fd_error(&m, f);
                worst = worst.max(e);
                assert!(e <= 1e-6, "{name} at {sname}: rel err {e:e}");
                if *sname != "I" && *sname != "rotation" {
                    let es = stress_fd_error(&m, f);
                    assert!(es <= 1e-6, "{name} at {sname}: stress rel err {es:e}");
                }
            }
        }
        println!("C vs dS/dE (FD), equal stretches: max rel err {worst:e}");
    }

    /// Ogden with (2c₁, 2), (−2c₂, −2) is exactly the decoupled Mooney–Rivlin.
    #[test]
    fn ogden_reproduces_mooney_rivlin() {
        let mr = MooneyRivlin::from_young_poisson_ratio(2.0e6, 0.3, 0.3);
        let og = Ogden::new(mr.bulk, &[(2.0 * mr.c1, 2.0), (-2.0 * mr.c2, -2.0)]).unwrap();
        let mut rng = Rng(0x5eed_0004);
        let mut fs: Vec<_> = (0..6).map(|_| rng.def_grad()).collect();
        fs.extend(degenerate_states(&mut rng).into_iter().map(|(_, f)| f));
        let mut worst: f64 = 0.0;
        for f in &fs {
            let (s1, t1, p1) = mr.evaluate(f).unwrap();
            let (s2, t2, p2) = og.evaluate(f).unwrap();
            let scale = mr.small_strain_moduli().1;
            let es = diff6(&s1, &s2) / norm6(&s1).max(scale);
            let et = (t1 - t2).amax() / t1.amax();
            let ep = (p1 - p2).abs() / p1.abs().max(scale);
            worst = worst.max(es).max(et).max(ep);
            assert!(
                es <= 1e-10 && et <= 1e-10 && ep <= 1e-10,
                "{es:e} {et:e} {ep:e}"
            );
        }
        println!("Ogden(2,-2) vs Mooney-Rivlin: max rel diff {worst:e}");
    }

    /// Compares σ computed by the model with a hand formula, relative to max|σ|.
    fn cauchy_error(m: &Model, f: &Matrix3<f64>, expected: &[f64; 6]) -> f64 {
        let sigma = cauchy_from_pk2(f, &m.eval(f).0);
        let (sigma, expected) = (SMatrix::<f64, 6, 1>::from(sigma), SMatrix::from(*expected));
        (sigma - expected).amax() / expected.amax()
    }

    #[test]
    fn principal_cauchy_stresses_match_closed_forms() {
        let (nh, mr, og) = closed_form_models();
        let stretches = [
            [1.3, 0.9, 0.9],   // uniaxial tension
            [0.7, 1.05, 1.05], // uniaxial compression
            [1.2, 1.2, 0.75],  // equibiaxial
            [1.4, 0.8, 1.1],   // general triaxial
            [1.25, 1.25, 1.25],
        ];
        let mut worst: f64 = 0.0;
        for l in &stretches {
            let f = Matrix3::from_diagonal(&Vector3::new(l[0], l[1], l[2]));
            let j = l[0] * l[1] * l[2];
            let pv = |k: f64| 0.5 * k * (j * j - 1.0);
            // Neo-Hooke: σ_i = [λ/2 (J² − 1) + μ(λ_i² − 1)] / J.
            let s_nh = l.map(|li| (0.5 * nh.lambda * (j * j - 1.0) + nh.mu * (li * li - 1.0)) / j);
            // Mooney-Rivlin: τ = dev[2(c1 + c2 Ī1) b̄ − 2c2 b̄²] + J U' I.
            let bb = l.map(|li| j.powf(-2.0 / 3.0) * li * li);
            let i1b = bb[0] + bb[1] + bb[2];
            let x = bb.map(|b| 2.0 * (mr.c1 + mr.c2 * i1b) * b - 2.0 * mr.c2 * b * b);
            let xm = (x[0] + x[1] + x[2]) / 3.0;
            let s_mr = x.map(|xi| (xi - xm + pv(mr.bulk)) / j);
            // Ogden: τ_i = Σ μ_p (λ̄_i^α − ⅓ Σ_k λ̄_k^α) + J U'.
            let tau = ogden_dev_tau(&og, l.map(|li| j.powf(-1.0 / 3.0) * li));
            let s_og = tau.map(|t| (t + pv(og.bulk)) / j);
            for (m, s) in [
                (Model::Nh(nh), s_nh),
                (Model::Mr(mr), s_mr),
                (Model::Og(og), s_og),
            ] {
                let e = cauchy_error(&m, &f, &[s[0], s[1], s[2], 0.0, 0.0, 0.0]);
                worst = worst.max(e);
                assert!(e <= 1e-10, "{m:?} at {l:?}: {e:e}");
            }
        }
        println!("principal Cauchy closed forms: max rel err {worst:e}");
    }

    #[test]
    fn simple_shear_matches_closed_forms() {
        let (nh, mr, og) = closed_form_models();
        let mut worst: f64 = 0.0;
        for gamma in [0.05, 0.4, 1.0, 2.5] {
            let mut f = Matrix3::identity();
            f[(0, 1)] = gamma;
            let g2 = gamma * gamma;
            // Neo-Hooke, J = 1: σ = μ(b − I).
            let s_nh = [nh.mu * g2, 0.0, 0.0, nh.mu * gamma, 0.0, 0.0];
            // Mooney-Rivlin, J = 1: σ = dev[A b − B b²], A = 2(c1 + c2 I1), B = 2 c2.
            let (a, b) = (2.0 * (mr.c1 + mr.c2 * (3.0 + g2)), 2.0 * mr.c2);
            let x = [
                a * (1.0 + g2) - b * ((1.0 + g2).powi(2) + g2),
                a - b * (1.0 + g2),
                a - b,
            ];
            let xm = (x[0] + x[1] + x[2]) / 3.0;
            let s12 = 2.0 * (mr.c1 + mr.c2) * gamma;
            let s_mr = [x[0] - xm, x[1] - xm, x[2] - xm, s12, 0.0, 0.0];
            // Ogden: λ₁ = √(1 + γ²/4) + γ/2, λ₂ = 1/λ₁, λ₃ = 1; principal axes of b
            // at angle θ, cos 2θ = γ/(λ₁ + λ₂), sin 2θ = 2/(λ₁ + λ₂).
            let l1 = (1.0 + 0.25 * g2).sqrt() + 0.5 * gamma;
            let t = ogden_dev_tau(&og, [l1, 1.0 / l1, 1.0]);
            let sum = l1 + 1.0 / l1;
            let (half_sum, half_diff) = (0.5 * (t[0] + t[1]), 0.5 * (t[0] - t[1]));
            let s_og = [
                half_sum + half_diff * gamma / sum,
                half_sum - half_diff * gamma / sum,
                t[2],
                (t[0] - t[1]) / sum,
                0.0,
                0.0,
            ];
            for (m, s) in [
                (Model::Nh(nh), s_nh),
                (Model::Mr(mr), s_mr),
                (Model::Og(og), s_og),
            ] {
                let e = cauchy_error(&m, &f, &s);
                worst = worst.max(e);
                assert!(e <= 1e-10, "{m:?} at gamma {gamma}: {e:e}");
            }
        }
        println!("simple shear closed forms: max rel err {worst:e}");
    }

    #[test]
    fn frame_indifference() {
        let mut rng = Rng(0x5eed_0005);
        let mut worst: f64 = 0.0;
        for (name, m) in models() {
            for _ in 0..6 {
                let f = rng.def_grad();
                let q = rng.rotation();
                let (s1, t1, p1) = m.eval(&f);
                let (s2, t2, p2) = m.eval(&(q * f));
                let ep = (p1 - p2).abs() / p1.abs();
                let es = diff6(&s1, &s2) / norm6(&s1);
                let et = (t1 - t2).amax() / t1.amax();
                worst = worst.max(ep).max(es).max(et);
                assert!(
                    ep <= 1e-12 && es <= 1e-12 && et <= 1e-12,
                    "{name}: {ep:e} {es:e} {et:e}"
                );
            }
        }
        println!("frame indifference: max rel diff {worst:e}");
    }

    #[test]
    fn nonpositive_jacobian_is_an_error() {
        let diag = |a, b, c| Matrix3::from_diagonal(&Vector3::new(a, b, c));
        let (reflect, flat) = (diag(1.0, 1.0, -1.0), diag(1.0, 0.0, 1.0));
        let mut nan = Matrix3::identity();
        nan[(0, 1)] = f64::NAN;
        let mut inf = Matrix3::identity();
        inf[(0, 1)] = f64::INFINITY;
        let cases = [
            (reflect, -1.0),
            (flat, 0.0),
            (-Matrix3::identity() * 1.2, -1.728),
        ];
        for (name, m) in models() {
            for (f, j) in &cases {
                let e = m.try_eval(f).unwrap_err();
                assert!((e.j - j).abs() < 1e-12, "{name}: {e}");
                assert!(e.to_string().contains("J = det F"));
            }
            assert!(m.try_eval(&nan).is_err(), "{name}: NaN accepted");
            assert!(m.try_eval(&inf).is_err(), "{name}: inf accepted");
        }
    }

    #[test]
    fn stability_checks_and_constructors() {
        assert!(wellmann(1.0e9).check().is_ok());
        let bad = Ogden::new(1.0e9, &[(1.0e5, 2.0), (1.0e4, -2.0)]).unwrap();
        let msg = bad.check().unwrap_err();
        assert!(msg.contains("term 2") && msg.contains("-2e4"), "{msg}");
        let zero = Ogden::new(1.0e9, &[(0.0, 2.0)]).unwrap();
        assert!(zero.check().unwrap_err().contains("term 1"));
        assert!(Ogden::new(-1.0, &[(1.0e5, 2.0)]).unwrap().check().is_err());
        assert!(Ogden::new(1.0, &[]).is_err());
        assert!(Ogden::new(1.0, &[(1.0, 2.0); 4]).is_err());
        assert!(Ogden::new(1.0, &[(1.0, 2.0), (1.0, 0.0)])
            .unwrap_err()
            .contains("term 2"));

        let (e, nu) = (2.0e6, 0.3);
        let (k0, g0) = (e / (3.0 * (1.0 - 2.0 * nu)), e / (2.0 * (1.0 + nu)));
        let nh = NeoHooke::from_young_poisson(e, nu);
        let (k, g) = nh.small_strain_moduli();
        assert!((k / k0 - 1.0).abs() < 1e-14 && (g / g0 - 1.0).abs() < 1e-14);
        assert!(nh.check().is_ok());
        for (lambda, mu) in [(1.0, -1.0), (-3.0, 1.0), (f64::NAN, 1.0)] {
            assert!(NeoHooke { lambda, mu }.check().is_err());
        }

        let mr = MooneyRivlin::from_young_poisson_ratio(e, nu, 0.25);
        let (k, g) = mr.small_strain_moduli();
        assert!((k / k0 - 1.0).abs() < 1e-14 && (g / g0 - 1.0).abs() < 1e-14);
        assert!((mr.c2 / (mr.c1 + mr.c2) - 0.25).abs() < 1e-14);
        assert!(mr.check().is_ok());
        for (bulk, c1, c2) in [
            (1.0, 1.0, -1.0),
            (0.0, 1.0, 1.0),
            (1.0, -1.0, 0.5),
            (1.0, 0.0, 0.0),
        ] {
            assert!(MooneyRivlin { bulk, c1, c2 }.check().is_err());
        }
    }
}
