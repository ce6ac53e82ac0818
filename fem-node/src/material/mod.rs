//! Constitutive models with Gauss-point state (DESIGN "FEM materials"): linear elasticity
//! (Ullrich (2.35)–(2.37)), the finite-strain hyperelastic models of Wellmann ch. 4 (Neo-Hooke,
//! Mooney–Rivlin, Ogden; total Lagrangian) and the small-strain non-associative Mohr–Coulomb
//! plasticity of Wellmann §2.1.5 / ch. 5 ((2.31)–(2.37), with the (2.32) erratum corrected).
//!
//! A point is evaluated from its displacement gradient H = ∂u/∂X and its committed state; it
//! returns the stress measure its kinematics works with (Cauchy σ for small strain, the second
//! Piola–Kirchhoff S for finite strain), the consistent tangent and the stored energy, and
//! writes its new (trial) state. Symmetric tensors are Voigt `[f64; 6]` in the order
//! (11, 22, 33, 12, 23, 31) with tensor components; tangents act on engineering strains
//! (doubled shear). Dispatch is a `match` per point: no dynamic dispatch in the element loop.

pub mod hyperelastic;
pub mod mohr_coulomb;

use crate::element::Lame;
use hyperelastic::{MooneyRivlin, NeoHooke, Ogden};
use mohr_coulomb::{MohrCoulomb, Return};
use nalgebra::Matrix3;

/// 6×6 tangent acting on engineering strain increments (see the module doc).
pub type Tangent = nalgebra::SMatrix<f64, 6, 6>;

/// Number of state values per integration point of a Mohr–Coulomb material: the plastic
/// strain (6, tensor components), the equivalent plastic strain ε̄ᵖ = ∫√(⅔ ε̇ᵖ:ε̇ᵖ) dt, and
/// 1 when the point's last converged update was plastic (the "plastic zone"), else 0.
pub const MOHR_COULOMB_STATE: usize = 8;

/// Share of the elastic stiffness added to the Mohr–Coulomb tangent at edge and apex returns
/// (see [`Model::evaluate`]).
pub const EDGE_REGULARISATION: f64 = 1e-6;

/// A constitutive model with its parameters.
#[derive(Clone, Debug)]
pub enum Model {
    Linear(Lame),
    NeoHooke(NeoHooke),
    MooneyRivlin(MooneyRivlin),
    Ogden(Ogden),
    MohrCoulomb(MohrCoulomb),
}

/// A named material of a scene: model and density.
#[derive(Clone, Debug)]
pub struct Material {
    pub name: String,
    pub model: Model,
    /// ρ [kg/m³] (per reference volume).
    pub density: f64,
}

/// What a point evaluation returns.
#[derive(Clone, Copy, Debug)]
pub struct PointResponse {
    /// σ (small strain) or S (finite strain), Voigt tensor components [Pa].
    pub stress: [f64; 6],
    /// ∂σ/∂ε̂ or ∂S/∂Ê on engineering strains [Pa].
    pub tangent: Tangent,
    /// Stored (elastic) energy per reference volume [J/m³].
    pub energy: f64,
}

/// A point that cannot be evaluated.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PointFailure {
    /// det F ≤ 0: the element turned inside out.
    NonPositiveJacobian(f64),
}

impl std::fmt::Display for PointFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PointFailure::NonPositiveJacobian(j) => {
                write!(f, "det F = {j:.3e} ≤ 0 (the element is inverted)")
            }
        }
    }
}

impl Model {
    /// The short name used in scene files (`model = "..."`).
    pub fn kind_name(&self) -> &'static str {
        match self {
            Model::Linear(_) => "linear_elastic",
            Model::NeoHooke(_) => "neo_hooke",
            Model::MooneyRivlin(_) => "mooney_rivlin",
            Model::Ogden(_) => "ogden",
            Model::MohrCoulomb(_) => "mohr_coulomb",
        }
    }
    /// Linear elastic: internal forces are K u and the cached factor applies.
    pub fn is_linear(&self) -> bool {
        matches!(self, Model::Linear(_))
    }
    /// Finite strain (total Lagrangian, S and F) rather than small strain (σ and ε).
    pub fn finite_strain(&self) -> bool {
        matches!(
            self,
            Model::NeoHooke(_) | Model::MooneyRivlin(_) | Model::Ogden(_)
        )
    }
    /// Number of state values per integration point.
    pub fn state_len(&self) -> usize {
        match self {
            Model::MohrCoulomb(_) => MOHR_COULOMB_STATE,
            _ => 0,
        }
    }
    /// Whether the consistent tangent is symmetric (non-associative flow makes it not).
    pub fn symmetric_tangent(&self) -> bool {
        match self {
            Model::MohrCoulomb(m) => m.sin_phi == m.sin_psi,
            _ => true,
        }
    }
    /// Small-strain bulk and shear moduli (K, G) [Pa]: the initial stiffness, used for the
    /// linear stiffness matrix (critical time step, Rayleigh damping, frequencies).
    pub fn small_strain_moduli(&self) -> (f64, f64) {
        match self {
            Model::Linear(l) => (l.lambda + 2.0 / 3.0 * l.mu, l.mu),
            Model::NeoHooke(m) => m.small_strain_moduli(),
            Model::MooneyRivlin(m) => m.small_strain_moduli(),
            Model::Ogden(m) => m.small_strain_moduli(),
            Model::MohrCoulomb(m) => (m.bulk, m.shear),
        }
    }
    /// The initial (small-strain) isotropic stiffness in Lamé form.
    pub fn initial_lame(&self) -> Lame {
        let (k, g) = self.small_strain_moduli();
        Lame {
            lambda: k - 2.0 / 3.0 * g,
            mu: g,
        }
    }
    /// The small-strain Poisson ratio ν = (3K − 2G) / (2(3K + G)).
    pub fn poisson_ratio(&self) -> f64 {
        let (k, g) = self.small_strain_moduli();
        (3.0 * k - 2.0 * g) / (2.0 * (3.0 * k + g))
    }

    /// Evaluates a point with displacement gradient `h` (H_ij = ∂u_i/∂X_j) from the committed
    /// state `state_n`, writing the trial state to `state_new` (both `state_len()` long).
    #[inline]
    pub fn evaluate(
        &self,
        h: &[[f64; 3]; 3],
        state_n: &[f64],
        state_new: &mut [f64],
    ) -> Result<PointResponse, PointFailure> {
        match self {
            Model::Linear(l) => {
                let eps = small_strain(h);
                let tr = eps[0] + eps[1] + eps[2];
                let mut s = [0.0; 6];
                for i in 0..3 {
                    s[i] = l.lambda * tr + 2.0 * l.mu * eps[i];
                    s[i + 3] = 2.0 * l.mu * eps[i + 3];
                }
                Ok(PointResponse {
                    stress: s,
                    tangent: isotropic_tangent(l.lambda, l.mu),
                    energy: 0.5 * double_contract(&s, &eps),
                })
            }
            Model::NeoHooke(m) => {
                let hm = Matrix3::from_fn(|i, j| h[i][j]);
                match m.evaluate_gradient(&hm) {
                    Ok((stress, tangent, energy)) => Ok(PointResponse {
                        stress,
                        tangent,
                        energy,
                    }),
                    Err(e) => Err(PointFailure::NonPositiveJacobian(e.j)),
                }
            }
            Model::MooneyRivlin(m) => finite(h, |f| m.evaluate(f)),
            Model::Ogden(m) => finite(h, |f| m.evaluate(f)),
            Model::MohrCoulomb(m) => {
                let eps = small_strain(h);
                let mut ep = [0.0; 6];
                ep.copy_from_slice(&state_n[..6]);
                let up = m.update(&eps, &ep);
                state_new[..6].copy_from_slice(&up.plastic_strain);
                state_new[6] = state_n[6] + up.eq_plastic_increment;
                state_new[7] = if up.kind == Return::Elastic { 0.0 } else { 1.0 };
                // stored energy ½ σ:εᵉ = ½ (s:s / 2G + p² / K)
                let s = up.stress;
                let p = (s[0] + s[1] + s[2]) / 3.0;
                let dev = [s[0] - p, s[1] - p, s[2] - p, s[3], s[4], s[5]];
                let energy = 0.5 * (double_contract(&dev, &dev) / (2.0 * m.shear) + p * p / m.bulk);
                let mut tangent = up.tangent;
                if matches!(
                    up.kind,
                    Return::EdgeCompression | Return::EdgeExtension | Return::Apex
                ) {
                    // perfect plasticity leaves the consistent tangent singular on an edge
                    // (rank 1 in principal space: the two lateral strains of a triaxial test are
                    // not separated) and zero at the apex; a trace of the elastic stiffness keeps
                    // the Newton system solvable and changes the iterations, not the solution
                    tangent += EDGE_REGULARISATION
                        * isotropic_tangent(m.bulk - 2.0 / 3.0 * m.shear, m.shear);
                }
                Ok(PointResponse {
                    stress: s,
                    tangent,
                    energy,
                })
            }
        }
    }
}

fn finite<E>(
    h: &[[f64; 3]; 3],
    eval: impl FnOnce(&Matrix3<f64>) -> Result<([f64; 6], Tangent, f64), E>,
) -> Result<PointResponse, PointFailure> {
    let f = deformation_gradient(h);
    match eval(&f) {
        Ok((stress, tangent, energy)) => Ok(PointResponse {
            stress,
            tangent,
            energy,
        }),
        Err(_) => Err(PointFailure::NonPositiveJacobian(f.determinant())),
    }
}

/// F = I + H.
#[inline]
pub fn deformation_gradient(h: &[[f64; 3]; 3]) -> Matrix3<f64> {
    Matrix3::new(
        1.0 + h[0][0],
        h[0][1],
        h[0][2],
        h[1][0],
        1.0 + h[1][1],
        h[1][2],
        h[2][0],
        h[2][1],
        1.0 + h[2][2],
    )
}

/// ε = ½(H + Hᵀ), Voigt tensor components.
#[inline]
pub fn small_strain(h: &[[f64; 3]; 3]) -> [f64; 6] {
    crate::element::strain_from_gradient(h)
}

/// A : B for Voigt tensor components (shear counted twice).
#[inline]
pub fn double_contract(a: &[f64; 6], b: &[f64; 6]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + 2.0 * (a[3] * b[3] + a[4] * b[4] + a[5] * b[5])
}

/// The isotropic elasticity matrix on engineering strains (Ullrich (2.35)–(2.37)).
pub fn isotropic_tangent(lambda: f64, mu: f64) -> Tangent {
    let mut d = Tangent::zeros();
    for i in 0..3 {
        for j in 0..3 {
            d[(i, j)] = lambda;
        }
        d[(i, i)] += 2.0 * mu;
        d[(i + 3, i + 3)] = mu;
    }
    d
}

/// Cauchy stress σ = J⁻¹ F S Fᵀ from the second Piola–Kirchhoff stress (finite strain), or
/// σ itself (small strain).
pub fn cauchy(model: &Model, h: &[[f64; 3]; 3], stress: &[f64; 6]) -> [f64; 6] {
    if model.finite_strain() {
        hyperelastic::cauchy_from_pk2(&deformation_gradient(h), stress)
    } else {
        *stress
    }
}

/// Spectral decomposition of a symmetric 3×3 matrix by cyclic Jacobi
/// rotations. Eigenvalues sorted descending, eigenvectors are the columns of
/// the returned orthogonal matrix. Bounded number of sweeps, no allocation,
/// no panic (NaN in gives NaN out). A diagonal input is returned exactly.
pub(crate) fn sym_eigen(m: &Matrix3<f64>) -> ([f64; 3], Matrix3<f64>) {
    let mut a = *m;
    let mut v = Matrix3::identity();
    for _ in 0..32 {
        let off = a[(0, 1)].abs() + a[(0, 2)].abs() + a[(1, 2)].abs();
        let diag = a[(0, 0)].abs() + a[(1, 1)].abs() + a[(2, 2)].abs();
        if off == 0.0 || off <= 1e-20 * diag {
            break;
        }
        for &(p, q) in &[(0usize, 1usize), (0, 2), (1, 2)] {
            let apq = a[(p, q)];
            if apq == 0.0 {
                continue;
            }
            // Numerical Recipes: θ = cot 2φ, t = tan φ (smaller root).
            let theta = (a[(q, q)] - a[(p, p)]) / (2.0 * apq);
            let t = if theta.abs() > 1e150 {
                0.5 / theta
            } else {
                theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt())
            };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            let mut j = Matrix3::identity();
            j[(p, p)] = c;
            j[(q, q)] = c;
            j[(p, q)] = s;
            j[(q, p)] = -s;
            a = j.transpose() * a * j;
            a[(p, q)] = 0.0;
            a[(q, p)] = 0.0;
            v *= j;
        }
    }
    let mut w = [a[(0, 0)], a[(1, 1)], a[(2, 2)]];
    let mut idx = [0usize, 1, 2];
    for &(i, j) in &[(0usize, 1usize), (1, 2), (0, 1)] {
        if w[i] < w[j] {
            w.swap(i, j);
            idx.swap(i, j);
        }
    }
    let q = Matrix3::from_columns(&[
        v.column(idx[0]).into_owned(),
        v.column(idx[1]).into_owned(),
        v.column(idx[2]).into_owned(),
    ]);
    (w, q)
}
