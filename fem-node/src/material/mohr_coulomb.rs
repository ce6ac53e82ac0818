//! Small-strain, perfectly plastic, non-associative Mohr–Coulomb material.
//!
//! Model: Wellmann (thesis), §2.1.5, eqs. (2.31)–(2.37), tension positive:
//!
//! * elasticity `σ = K tr εᵉ 1 + 2G dev εᵉ`, additive split `ε = εᵉ + εᵖ`;
//! * principal stresses ordered `σ1 ≥ σ2 ≥ σ3`;
//! * yield function (eq. (2.32), **sign of the cohesion term corrected**)
//!   `Φ = σ1 − σ3 + (σ1 + σ3) sin φ − 2c cos φ ≤ 0`.
//!   The thesis prints `+ 2c cos φ`; with that sign the stress-free state has
//!   `Φ(0) = 2c cos φ > 0`, i.e. lies outside the elastic domain (erratum);
//! * plastic potential `Ψ = σ1 − σ3 + (σ1 + σ3) sin ψ`, flow `ε̇ᵖ = γ̇ ∂Ψ/∂σ`;
//! * perfect plasticity (no hardening).
//!
//! Algorithm: elastic predictor / return mapping in principal stress space of
//! de Souza Neto, Perić & Owen, *Computational Methods for Plasticity* (Wiley
//! 2008), ch. 8 (§8.2, the Mohr–Coulomb return-mapping boxes, Box 8.4 ff.):
//! one-vector return to the main plane, two-vector return to the
//! compression (`σ1 = σ2`) or extension (`σ2 = σ3`) edge, return to the apex.
//! The consistent tangent is the derivative of that isotropic tensor function
//! of the trial elastic strain (de Souza Neto et al. 2008, Appendix A).
//!
//! Conventions: symmetric tensors as `[f64; 6]` in Voigt order
//! (11, 22, 33, 12, 23, 31) with *tensor* shear components (stress and
//! strain). [`Tangent`] maps *engineering* strain increments
//! (ε11, ε22, ε33, 2ε12, 2ε23, 2ε31) to stress increments.

use super::sym_eigen;
use nalgebra::{Matrix2, Matrix3, SMatrix, Vector3};

/// 6×6 tangent acting on engineering Voigt strain increments:
/// `δσ_I = Σ_J D_IJ δε̂_J`, `ε̂ = (ε11, ε22, ε33, 2ε12, 2ε23, 2ε31)`.
pub type Tangent = SMatrix<f64, 6, 6>;

/// Voigt index pairs (11, 22, 33, 12, 23, 31).
const VOIGT: [(usize, usize); 6] = [(0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (2, 0)];

/// Material parameters (derived quantities stored for the hot loop).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MohrCoulomb {
    /// Bulk modulus K.
    pub bulk: f64,
    /// Shear modulus G.
    pub shear: f64,
    /// sin φ (friction angle).
    pub sin_phi: f64,
    /// cos φ.
    pub cos_phi: f64,
    /// sin ψ (dilation angle).
    pub sin_psi: f64,
    /// Cohesion c.
    pub cohesion: f64,
}

/// Which branch of the return mapping produced the stress.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Return {
    /// Trial state admissible.
    Elastic,
    /// One-vector return to the main plane Φ₁₃ = 0.
    Plane,
    /// Two-vector return to the edge σ1 = σ2 (planes (1,3) and (2,3));
    /// reached in triaxial compression.
    EdgeCompression,
    /// Two-vector return to the edge σ2 = σ3 (planes (1,3) and (1,2));
    /// reached in triaxial extension.
    EdgeExtension,
    /// Return to the apex σ = c cot φ 1 (only for φ > 0).
    Apex,
}

/// Result of a stress update at one integration point.
#[derive(Clone, Copy, Debug)]
pub struct Update {
    /// σ_{n+1}, Voigt, tensor components.
    pub stress: [f64; 6],
    /// εᵖ_{n+1}, Voigt, tensor components.
    pub plastic_strain: [f64; 6],
    /// Δε̄ᵖ = √(2/3 Δεᵖ:Δεᵖ).
    pub eq_plastic_increment: f64,
    /// Consistent tangent ∂σ_{n+1}/∂ε̂_{n+1} (non-symmetric if ψ ≠ φ).
    pub tangent: Tangent,
    /// Branch of the return mapping.
    pub kind: Return,
}

/// Return mapping in principal space (internal).
#[derive(Clone, Copy, Debug)]
struct Principal {
    kind: Return,
    /// Principal stresses in the order of the trial principal strains.
    sigma: [f64; 3],
    /// ∂σ_a/∂εᵗʳ_b.
    dsde: Matrix3<f64>,
}

fn tensor(v: &[f64; 6]) -> Matrix3<f64> {
    Matrix3::new(v[0], v[3], v[5], v[3], v[1], v[4], v[5], v[4], v[2])
}

fn voigt(m: &Matrix3<f64>) -> [f64; 6] {
    let mut v = [0.0; 6];
    for (vk, &(i, j)) in v.iter_mut().zip(VOIGT.iter()) {
        *vk = 0.5 * (m[(i, j)] + m[(j, i)]);
    }
    v
}

/// `Q diag(d) Qᵀ` as Voigt vector.
fn from_principal(q: &Matrix3<f64>, d: &[f64; 3]) -> [f64; 6] {
    voigt(&(q * Matrix3::from_diagonal(&Vector3::new(d[0], d[1], d[2])) * q.transpose()))
}

/// Assemble the 6×6 tangent (engineering-strain Voigt form) of an isotropic
/// tensor function σ(εᵗʳ) = Σ σ_a(εᵗʳ_1..3) e_a⊗e_a from the principal
/// derivatives `dsde[a][b] = ∂σ_a/∂εᵗʳ_b` and the spin coefficients
/// `theta = [θ₁₂, θ₁₃, θ₂₃]`, θ_ab = (σ_a − σ_b)/(εᵗʳ_a − εᵗʳ_b)
/// (de Souza Neto et al. 2008, Appendix A):
/// `δσ = Σ_ab (∂σ_a/∂ε_b) δε_bb E_a + Σ_{a<b} θ_ab δε_ab (e_a⊗e_b + e_b⊗e_a)`
/// with δε_ab = e_a·δε e_b. Column J is the response to a unit engineering
/// strain component (tensor shear ½ for J ≥ 3).
fn assemble(q: &Matrix3<f64>, dsde: &Matrix3<f64>, theta: &[f64; 3]) -> Tangent {
    let mut t = Tangent::zeros();
    for (col, &(i, j)) in VOIGT.iter().enumerate() {
        let mut de = Matrix3::zeros();
        if i == j {
            de[(i, i)] = 1.0;
        } else {
            de[(i, j)] = 0.5;
            de[(j, i)] = 0.5;
        }
        let dp = q.transpose() * de * q;
        let dd = dsde * Vector3::new(dp[(0, 0)], dp[(1, 1)], dp[(2, 2)]);
        let s01 = theta[0] * dp[(0, 1)];
        let s02 = theta[1] * dp[(0, 2)];
        let s12 = theta[2] * dp[(1, 2)];
        let ds = Matrix3::new(dd[0], s01, s02, s01, dd[1], s12, s02, s12, dd[2]);
        let s = voigt(&(q * ds * q.transpose()));
        for (row, sv) in s.iter().enumerate() {
            t[(row, col)] = *sv;
        }
    }
    t
}

impl MohrCoulomb {
    /// Build from E, ν, φ, ψ (radians) and c. Never panics; call
    /// [`MohrCoulomb::check`] on the same arguments first.
    pub fn new(
        youngs_modulus: f64,
        poisson_ratio: f64,
        friction_angle: f64,
        dilation_angle: f64,
        cohesion: f64,
    ) -> MohrCoulomb {
        MohrCoulomb {
            bulk: youngs_modulus / (3.0 * (1.0 - 2.0 * poisson_ratio)),
            shear: youngs_modulus / (2.0 * (1.0 + poisson_ratio)),
            sin_phi: friction_angle.sin(),
            cos_phi: friction_angle.cos(),
            sin_psi: dilation_angle.sin(),
            cohesion,
        }
    }

    /// Validate the arguments of [`MohrCoulomb::new`] (angles in radians; messages in degrees).
    /// On failure returns the offending field name and a message.
    pub fn check(
        youngs_modulus: f64,
        poisson_ratio: f64,
        friction_angle: f64,
        dilation_angle: f64,
        cohesion: f64,
    ) -> Result<(), (&'static str, String)> {
        let (phi, psi) = (friction_angle, dilation_angle);
        if !youngs_modulus.is_finite() || youngs_modulus <= 0.0 {
            return Err((
                "youngs_modulus",
                format!("Young's modulus must be finite and > 0 Pa, got {youngs_modulus}"),
            ));
        }
        if !poisson_ratio.is_finite() || poisson_ratio <= -1.0 || poisson_ratio >= 0.5 {
            return Err((
                "poisson_ratio",
                format!(
                    "Poisson's ratio must satisfy −1 < ν < 0.5 (ν = 0.5 is incompressible: \
                     infinite bulk modulus), got {poisson_ratio}"
                ),
            ));
        }
        if !(0.0..std::f64::consts::FRAC_PI_2).contains(&phi) {
            return Err((
                "friction_angle",
                format!(
                    "friction angle must satisfy 0° ≤ φ < 90°, got {}°",
                    degrees(phi)
                ),
            ));
        }
        if !psi.is_finite() || psi < 0.0 {
            return Err((
                "dilation_angle",
                format!(
                    "dilation angle must be finite and ≥ 0°, got {}°",
                    degrees(psi)
                ),
            ));
        }
        if psi > phi {
            return Err((
                "dilation_angle",
                format!(
                    "dilation angle ψ = {}° exceeds the friction angle φ = {}°; ψ > φ is \
                     non-physical: the plastic dissipation σ:ε̇ᵖ = γ̇ [(σ1 + σ3)(sin ψ − sin φ) \
                     + 2c cos φ] becomes negative under enough confinement",
                    degrees(psi),
                    degrees(phi)
                ),
            ));
        }
        if !cohesion.is_finite() || cohesion < 0.0 {
            return Err((
                "cohesion",
                format!("cohesion must be finite and ≥ 0 Pa, got {cohesion}"),
            ));
        }
        if cohesion == 0.0 && phi == 0.0 {
            return Err((
                "cohesion",
                "cohesion = 0 together with friction angle = 0 gives a material of zero strength"
                    .to_string(),
            ));
        }
        Ok(())
    }

    /// Yield function Φ(σ) = σ1 − σ3 + (σ1 + σ3) sin φ − 2c cos φ
    /// (Wellmann eq. (2.32) with the corrected sign of the cohesion term).
    pub fn yield_value(&self, stress: &[f64; 6]) -> f64 {
        let (s, _) = sym_eigen(&tensor(stress));
        self.phi13(&s)
    }

    fn phi13(&self, s: &[f64; 3]) -> f64 {
        (1.0 + self.sin_phi) * s[0]
            - (1.0 - self.sin_phi) * s[2]
            - 2.0 * self.cohesion * self.cos_phi
    }

    /// Isotropic elastic tangent D (engineering-strain Voigt form).
    pub fn elastic_tangent(&self) -> Tangent {
        let (k, g) = (self.bulk, self.shear);
        let mut d = Tangent::zeros();
        for i in 0..3 {
            for j in 0..3 {
                d[(i, j)] = k - 2.0 * g / 3.0;
            }
            d[(i, i)] = k + 4.0 * g / 3.0;
            d[(i + 3, i + 3)] = g;
        }
        d
    }

    /// Elastic matrix in principal space: dσ_a = Σ_b Dp_ab dε_b.
    fn principal_elastic(&self) -> Matrix3<f64> {
        let d = self.bulk + 4.0 * self.shear / 3.0;
        let o = self.bulk - 2.0 * self.shear / 3.0;
        Matrix3::new(d, o, o, o, d, o, o, o, d)
    }

    /// Return mapping in principal space for the ordered trial principal
    /// elastic strains `e[0] ≥ e[1] ≥ e[2]` (de Souza Neto et al. 2008, §8.2).
    ///
    /// With Dp the principal elastic matrix, `F_ij = ∂Φ_ij/∂σ` and
    /// `N_ij = ∂Ψ_ij/∂σ` for the plane with σ_i largest and σ_j smallest
    /// (`F_13 = (1 + s_φ, 0, −(1 − s_φ))`, `N_13 = (1 + s_ψ, 0, −(1 − s_ψ))`):
    ///
    /// * plane: `Δγ = Φᵗʳ/a`, `a = F_13·Dp N_13 = 4G(1 + s_φ s_ψ/3) + 4K s_φ s_ψ`,
    ///   `σ = σᵗʳ − Δγ Dp N_13` with
    ///   `Dp N_13 = (2G(1 + s_ψ/3) + 2K s_ψ, (2K − 4G/3) s_ψ, −2G(1 − s_ψ/3) + 2K s_ψ)`;
    ///   valid if the ordering survives;
    /// * edge (chosen by `(1 − s_ψ)σ1ᵗʳ − 2σ2ᵗʳ + (1 + s_ψ)σ3ᵗʳ > 0` →
    ///   σ2 = σ3, otherwise σ1 = σ2): `[a b; b a] Δγ = Φᵗʳ`,
    ///   `b = 2G(1 − s_φ − s_ψ − s_φ s_ψ/3) + 4K s_φ s_ψ` (σ1 = σ2, planes (1,3),(2,3)),
    ///   `b = 2G(1 + s_φ + s_ψ − s_φ s_ψ/3) + 4K s_φ s_ψ` (σ2 = σ3, planes (1,3),(1,2));
    /// * apex: `σ = c cot φ 1`, zero tangent (perfect plasticity).
    ///
    /// Linearisation: `∂σ/∂εᵗʳ = Dp − Σ_ij (Dp N_i) (A⁻¹)_ij (F_jᵀ Dp)`.
    fn principal_return(&self, e: &[f64; 3]) -> Principal {
        let dp = self.principal_elastic();
        let st = dp * Vector3::new(e[0], e[1], e[2]);
        let (sf, sp) = (self.sin_phi, self.sin_psi);
        let k = 2.0 * self.cohesion * self.cos_phi;

        // 1. elastic predictor
        let fa = Vector3::new(1.0 + sf, 0.0, -(1.0 - sf));
        let na = Vector3::new(1.0 + sp, 0.0, -(1.0 - sp));
        let phia = fa.dot(&st) - k;
        if phia <= 1e-12 * (st[0].abs() + st[2].abs() + k) {
            return Principal {
                kind: Return::Elastic,
                sigma: [st[0], st[1], st[2]],
                dsde: dp,
            };
        }

        // 2. one-vector return to the main plane
        let dna = dp * na;
        let ra = (dp * fa).transpose(); // Fᵀ Dp (Dp symmetric)
        let a = fa.dot(&dna);
        let dg = phia / a;
        let s = st - dg * dna;
        if s[0] >= s[1] && s[1] >= s[2] {
            return Principal {
                kind: Return::Plane,
                sigma: [s[0], s[1], s[2]],
                dsde: dp - dna * ra / a,
            };
        }

        // 3. two-vector return to an edge
        let q = (1.0 - sp) * st[0] - 2.0 * st[1] + (1.0 + sp) * st[2];
        let (kind, fb, nb) = if q > 0.0 {
            (
                Return::EdgeExtension,
                Vector3::new(1.0 + sf, -(1.0 - sf), 0.0),
                Vector3::new(1.0 + sp, -(1.0 - sp), 0.0),
            )
        } else {
            (
                Return::EdgeCompression,
                Vector3::new(0.0, 1.0 + sf, -(1.0 - sf)),
                Vector3::new(0.0, 1.0 + sp, -(1.0 - sp)),
            )
        };
        let dnb = dp * nb;
        let rb = (dp * fb).transpose();
        let phib = fb.dot(&st) - k;
        let m = Matrix2::new(a, fa.dot(&dnb), fb.dot(&dna), fb.dot(&dnb));
        let det = m[(0, 0)] * m[(1, 1)] - m[(0, 1)] * m[(1, 0)];
        let mi = Matrix2::new(m[(1, 1)], -m[(0, 1)], -m[(1, 0)], m[(0, 0)]) / det;
        let dga = mi[(0, 0)] * phia + mi[(0, 1)] * phib;
        let dgb = mi[(1, 0)] * phia + mi[(1, 1)] * phib;
        let mut s = st - dga * dna - dgb * dnb;
        let ordered = if kind == Return::EdgeCompression {
            let mean = 0.5 * (s[0] + s[1]);
            s[0] = mean;
            s[1] = mean;
            s[1] >= s[2]
        } else {
            let mean = 0.5 * (s[1] + s[2]);
            s[1] = mean;
            s[2] = mean;
            s[0] >= s[1]
        };
        // For φ = 0 (Tresca) there is no apex and the edge return is always
        // admissible (c > 0); accept it to avoid c cot φ = c/0.
        if (ordered && dga >= 0.0 && dgb >= 0.0) || sf <= 0.0 {
            let dsde = dp
                - dna * (mi[(0, 0)] * ra + mi[(0, 1)] * rb)
                - dnb * (mi[(1, 0)] * ra + mi[(1, 1)] * rb);
            return Principal {
                kind,
                sigma: [s[0], s[1], s[2]],
                dsde,
            };
        }

        // 4. apex
        let p = self.cohesion * self.cos_phi / sf;
        Principal {
            kind: Return::Apex,
            sigma: [p, p, p],
            dsde: Matrix3::zeros(),
        }
    }

    /// Spin coefficients θ_ab = (σ_a − σ_b)/(εᵗʳ_a − εᵗʳ_b) for the pairs
    /// (1,2), (1,3), (2,3); for coincident trial principal strains the limit
    /// ∂σ_a/∂ε_a − ∂σ_a/∂ε_b. On an edge the two equal principal stresses
    /// stay equal for any trial state in the edge region, so θ = 0 there
    /// exactly (the limit formula gives the same).
    fn spin(&self, pr: &Principal, e: &[f64; 3]) -> [f64; 3] {
        let scale = e[0].abs().max(e[2].abs());
        let mut th = [0.0; 3];
        for (t, &(a, b)) in th.iter_mut().zip(&[(0usize, 1usize), (0, 2), (1, 2)]) {
            let d = e[a] - e[b];
            *t = match (pr.kind, a, b) {
                (Return::EdgeCompression, 0, 1) | (Return::EdgeExtension, 1, 2) => 0.0,
                _ if d.abs() > 1e-12 * scale => (pr.sigma[a] - pr.sigma[b]) / d,
                _ => pr.dsde[(a, a)] - pr.dsde[(a, b)],
            };
        }
        th
    }

    /// Stress update at one integration point: total strain ε_{n+1} and
    /// plastic strain εᵖ_n (tensor Voigt components) give σ_{n+1}, εᵖ_{n+1},
    /// Δε̄ᵖ and the consistent tangent. No allocation, no panic.
    ///
    /// εᵖ_{n+1} = ε_{n+1} − D⁻¹σ_{n+1} (exact for every branch, apex included).
    pub fn update(&self, strain: &[f64; 6], plastic_strain_n: &[f64; 6]) -> Update {
        let mut etr = [0.0; 6];
        for ((t, e), p) in etr.iter_mut().zip(strain).zip(plastic_strain_n) {
            *t = e - p;
        }
        let (e, q) = sym_eigen(&tensor(&etr));
        let pr = self.principal_return(&e);
        let (k, g) = (self.bulk, self.shear);

        if pr.kind == Return::Elastic {
            let tr = etr[0] + etr[1] + etr[2];
            let mut stress = [0.0; 6];
            for (i, s) in stress.iter_mut().enumerate() {
                *s = if i < 3 {
                    k * tr + 2.0 * g * (etr[i] - tr / 3.0)
                } else {
                    2.0 * g * etr[i]
                };
            }
            return Update {
                stress,
                plastic_strain: *plastic_strain_n,
                eq_plastic_increment: 0.0,
                tangent: self.elastic_tangent(),
                kind: Return::Elastic,
            };
        }

        // Δεᵖ in the trial eigenbasis: εᵗʳ_a − (Dp⁻¹σ)_a.
        let s = pr.sigma;
        let trs = s[0] + s[1] + s[2];
        let mut dep = [0.0; 3];
        for ((d, ea), sa) in dep.iter_mut().zip(&e).zip(&s) {
            *d = ea - (trs / (9.0 * k) + (sa - trs / 3.0) / (2.0 * g));
        }
        let eq = (2.0 / 3.0 * (dep[0] * dep[0] + dep[1] * dep[1] + dep[2] * dep[2])).sqrt();
        let dep_v = from_principal(&q, &dep);
        let mut plastic_strain = *plastic_strain_n;
        for (p, d) in plastic_strain.iter_mut().zip(&dep_v) {
            *p += d;
        }
        let tangent = if pr.kind == Return::Apex {
            // the exact tangent is zero; a body whose points all sit at the apex would have
            // a singular Newton matrix: keep a vanishing share of the elastic one (the stress
            // stays exact, Newton converges linearly through such states)
            let mut t = self.elastic_tangent();
            t.iter_mut().for_each(|x| *x *= APEX_TANGENT_SHARE);
            t
        } else {
            assemble(&q, &pr.dsde, &self.spin(&pr, &e))
        };
        Update {
            stress: from_principal(&q, &s),
            plastic_strain,
            eq_plastic_increment: eq,
            tangent,
            kind: pr.kind,
        }
    }
}

/// The share of the elastic tangent a point at the apex keeps in the Newton matrix.
pub const APEX_TANGENT_SHARE: f64 = 1e-6;

/// An angle in degrees for messages (radians → degrees round-off removed).
fn degrees(rad: f64) -> f64 {
    (rad.to_degrees() * 1e9).round() / 1e9
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    const ZERO: [f64; 6] = [0.0; 6];

    fn mat() -> MohrCoulomb {
        MohrCoulomb::new(30e6, 0.25, 30f64.to_radians(), 10f64.to_radians(), 10e3)
    }

    fn rot() -> Matrix3<f64> {
        Rotation3::from_euler_angles(0.3, -0.7, 1.1).into_inner()
    }

    fn norm6(v: &[f64; 6]) -> f64 {
        tensor(v).norm()
    }

    /// Strain whose trial stress has principal values `s` (descending) in the
    /// eigenbasis given by the columns of `r`.
    fn strain_for(m: &MohrCoulomb, s: [f64; 3], r: &Matrix3<f64>) -> [f64; 6] {
        let tr = s[0] + s[1] + s[2];
        let e = s.map(|si| tr / (9.0 * m.bulk) + (si - tr / 3.0) / (2.0 * m.shear));
        from_principal(r, &e)
    }

    fn principal_stress(m: &MohrCoulomb, strain: &[f64; 6], r: &Matrix3<f64>) -> [f64; 3] {
        let dp = m.principal_elastic();
        let e = r.transpose() * tensor(strain) * r;
        let s = dp * Vector3::new(e[(0, 0)], e[(1, 1)], e[(2, 2)]);
        [s[0], s[1], s[2]]
    }

    fn fd_tangent(m: &MohrCoulomb, eps: &[f64; 6], ep: &[f64; 6]) -> Tangent {
        let h = 1e-7 * eps.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        let mut t = Tangent::zeros();
        for j in 0..6 {
            // engineering perturbation h ⇔ tensor shear h/2
            let dt = if j < 3 { h } else { 0.5 * h };
            let (mut p, mut n) = (*eps, *eps);
            p[j] += dt;
            n[j] -= dt;
            let (sp, sn) = (m.update(&p, ep).stress, m.update(&n, ep).stress);
            for i in 0..6 {
                t[(i, j)] = (sp[i] - sn[i]) / (2.0 * h);
            }
        }
        t
    }

    /// Relative Frobenius error of the algorithmic tangent versus central
    /// finite differences (absolute, relative to ‖D‖, if the FD matrix is 0).
    fn tangent_error(m: &MohrCoulomb, eps: &[f64; 6]) -> (Return, f64) {
        let u = m.update(eps, &ZERO);
        let fd = fd_tangent(m, eps, &ZERO);
        let scale = if fd.norm() > 1e-8 * m.elastic_tangent().norm() {
            fd.norm()
        } else {
            m.elastic_tangent().norm()
        };
        let err = (u.tangent - fd).norm() / scale;
        assert!(err.is_finite());
        (u.kind, err)
    }

    /// Checks after a plastic return for a strain built with `strain_for`
    /// (trial eigenbasis = columns of `r`): consistency, ordering, coaxiality,
    /// flow direction, Δγ ≥ 0, Δε̄ᵖ; returns (Δγ_a, Δγ_b).
    fn check_plastic(m: &MohrCoulomb, eps: &[f64; 6], r: &Matrix3<f64>, kind: Return) -> [f64; 2] {
        let u = m.update(eps, &ZERO);
        assert_eq!(u.kind, kind);
        let (sf, sp, c) = (m.sin_phi, m.sin_psi, m.cohesion);
        let sig = r.transpose() * tensor(&u.stress) * r;
        let s = [sig[(0, 0)], sig[(1, 1)], sig[(2, 2)]];
        let tol = 1e-10 * (norm6(&u.stress) + c);
        // coaxial with the trial state, ordered, on the yield surface
        assert!(sig[(0, 1)].abs() + sig[(0, 2)].abs() + sig[(1, 2)].abs() <= tol);
        assert!(s[0] >= s[1] - tol && s[1] >= s[2] - tol, "{s:?}");
        let phi = m.yield_value(&u.stress);
        assert!(phi.abs() <= tol, "Phi = {phi}");
        let plane =
            |i: usize, j: usize| (1.0 + sf) * s[i] - (1.0 - sf) * s[j] - 2.0 * c * m.cos_phi;
        // plastic strain increment in the trial eigenbasis
        let de = r.transpose() * tensor(&u.plastic_strain) * r;
        let d = [de[(0, 0)], de[(1, 1)], de[(2, 2)]];
        let dn = de.norm();
        assert!(de[(0, 1)].abs() + de[(0, 2)].abs() + de[(1, 2)].abs() <= 1e-9 * dn);
        let eq = (2.0 / 3.0 * de.norm_squared()).sqrt();
        assert!((u.eq_plastic_increment - eq).abs() <= 1e-12 * eq);
        let (ga, gb, n_expect) = match kind {
            Return::Plane => {
                let g = d[0] / (1.0 + sp);
                (g, 0.0, [(1.0 + sp) * g, 0.0, -(1.0 - sp) * g])
            }
            Return::EdgeCompression => {
                assert!(plane(1, 2).abs() <= tol, "Phi_23");
                assert!((s[0] - s[1]).abs() <= tol);
                let (ga, gb) = (d[0] / (1.0 + sp), d[1] / (1.0 + sp));
                (ga, gb, [d[0], d[1], -(1.0 - sp) * (ga + gb)])
            }
            Return::EdgeExtension => {
                assert!(plane(0, 1).abs() <= tol, "Phi_12");
                assert!((s[1] - s[2]).abs() <= tol);
                let (ga, gb) = (-d[2] / (1.0 - sp), -d[1] / (1.0 - sp));
                (ga, gb, [(1.0 + sp) * (ga + gb), d[1], d[2]])
            }
            _ => unreachable!(),
        };
        assert!(ga >= 0.0 && gb >= 0.0);
        let flow_err = (0..3).map(|i| (d[i] - n_expect[i]).abs()).sum::<f64>() / dn;
        assert!(flow_err <= 1e-9, "flow direction error {flow_err}");
        println!(
            "{kind:?}: |Phi|/(|s|+c) = {:.2e}, flow err = {flow_err:.2e}",
            phi.abs() / (norm6(&u.stress) + c)
        );
        [ga, gb]
    }

    #[test]
    fn eigen_decomposition() {
        let r = rot();
        let v = from_principal(&r, &[3.0, -1.0, -2.5]);
        let (w, q) = sym_eigen(&tensor(&v));
        assert!((w[0] - 3.0).abs() + (w[1] + 1.0).abs() + (w[2] + 2.5).abs() < 1e-14);
        let back = from_principal(&q, &w);
        assert!((0..6).all(|i| (back[i] - v[i]).abs() < 1e-14));
        assert!((q.transpose() * q - Matrix3::identity()).norm() < 1e-15);
        // diagonal input is returned exactly (triaxial states)
        let (w, _) = sym_eigen(&tensor(&[-1.0, 2.0, 2.0, 0.0, 0.0, 0.0]));
        assert_eq!(w, [2.0, 2.0, -1.0]);
    }

    /// Verify the closed-form coefficients of the brief (de Souza Neto's
    /// expressions) against the vector derivation used in the code.
    #[test]
    fn closed_form_coefficients() {
        for &(phi, psi) in &[(30.0f64, 10.0f64), (23.15, 5.17), (40.0, 40.0), (0.0, 0.0)] {
            let m = MohrCoulomb::new(30e6, 0.3, phi.to_radians(), psi.to_radians(), 1.0);
            let (k, g, sf, sp) = (m.bulk, m.shear, m.sin_phi, m.sin_psi);
            let dp = m.principal_elastic();
            let unit = |i: usize, j: usize, x: f64| {
                Vector3::from_fn(|r, _| {
                    [0.0, 1.0 + x, -(1.0 - x)][(r == i) as usize + 2 * (r == j) as usize]
                })
            };
            let (f, n) = (|i, j| unit(i, j, sf), |i, j| unit(i, j, sp));
            let tol = 1e-9 * g;
            let dn = dp * n(0, 2);
            assert!((dn[0] - (2.0 * g * (1.0 + sp / 3.0) + 2.0 * k * sp)).abs() < tol);
            assert!((dn[1] - (2.0 * k - 4.0 * g / 3.0) * sp).abs() < tol);
            assert!((dn[2] + (2.0 * g * (1.0 - sp / 3.0) - 2.0 * k * sp)).abs() < tol);
            let a = 4.0 * g * (1.0 + sf * sp / 3.0) + 4.0 * k * sf * sp;
            assert!((f(0, 2).dot(&dn) - a).abs() < tol);
            let b_comp = 2.0 * g * (1.0 - sf - sp - sf * sp / 3.0) + 4.0 * k * sf * sp;
            let b_ext = 2.0 * g * (1.0 + sf + sp - sf * sp / 3.0) + 4.0 * k * sf * sp;
            assert!((f(0, 2).dot(&(dp * n(1, 2))) - b_comp).abs() < tol);
            assert!((f(1, 2).dot(&dn) - b_comp).abs() < tol);
            assert!((f(0, 2).dot(&(dp * n(0, 1))) - b_ext).abs() < tol);
            assert!((f(0, 1).dot(&dn) - b_ext).abs() < tol);
        }
    }

    #[test]
    fn elastic_state() {
        let m = mat();
        let eps = [1e-4, -2e-4, 0.5e-4, 0.7e-4, -0.3e-4, 0.2e-4];
        let ep = [1e-5, 2e-5, -3e-5, 1e-6, 0.0, -2e-6];
        let u = m.update(&eps, &ep);
        assert_eq!(u.kind, Return::Elastic);
        let d = m.elastic_tangent();
        let mut eng = [0.0; 6];
        for i in 0..6 {
            eng[i] = (eps[i] - ep[i]) * if i < 3 { 1.0 } else { 2.0 };
        }
        let s = d * SMatrix::<f64, 6, 1>::from_column_slice(&eng);
        let err = (0..6)
            .map(|i| (s[i] - u.stress[i]).abs())
            .fold(0.0, f64::max);
        assert!(err <= 1e-14 * norm6(&u.stress), "{err}");
        assert_eq!(u.tangent, d);
        assert_eq!(u.plastic_strain, ep);
        assert_eq!(u.eq_plastic_increment, 0.0);
        // the spectral assembly reproduces D for the elastic principal map
        let dd = assemble(&rot(), &m.principal_elastic(), &[2.0 * m.shear; 3]);
        assert!((dd - d).norm() <= 1e-14 * d.norm());
        // stress-free state is elastic (sign erratum of eq. (2.32))
        assert!(m.yield_value(&ZERO) < 0.0);
        println!("elastic: stress err = {:.2e}", err / norm6(&u.stress));
    }

    #[test]
    fn plane_return() {
        let m = mat();
        let r = rot();
        let eps = strain_for(&m, [-50e3, -100e3, -250e3], &r);
        let [g, _] = check_plastic(&m, &eps, &r, Return::Plane);
        // Δγ and σ against the closed form of de Souza Neto
        let (k, gm, sf, sp) = (m.bulk, m.shear, m.sin_phi, m.sin_psi);
        let st = principal_stress(&m, &eps, &r);
        let a = 4.0 * gm * (1.0 + sf * sp / 3.0) + 4.0 * k * sf * sp;
        let dg = m.phi13(&st) / a;
        assert!((g - dg).abs() <= 1e-10 * dg);
        let s = [
            st[0] - dg * (2.0 * gm * (1.0 + sp / 3.0) + 2.0 * k * sp),
            st[1] - dg * (2.0 * k - 4.0 * gm / 3.0) * sp,
            st[2] + dg * (2.0 * gm * (1.0 - sp / 3.0) - 2.0 * k * sp),
        ];
        let u = m.update(&eps, &ZERO);
        let v = from_principal(&r, &s);
        assert!((0..6).all(|i| (v[i] - u.stress[i]).abs() <= 1e-9 * norm6(&v)));
    }

    fn edge_case(s: [f64; 3], kind: Return) {
        let m = mat();
        let r = rot();
        let eps = strain_for(&m, s, &r);
        let [ga, gb] = check_plastic(&m, &eps, &r, kind);
        let (k, g, sf, sp) = (m.bulk, m.shear, m.sin_phi, m.sin_psi);
        let a = 4.0 * g * (1.0 + sf * sp / 3.0) + 4.0 * k * sf * sp;
        let st = principal_stress(&m, &eps, &r);
        let (b, phib) = if kind == Return::EdgeCompression {
            let b = 2.0 * g * (1.0 - sf - sp - sf * sp / 3.0) + 4.0 * k * sf * sp;
            (b, m.phi13(&[st[1], 0.0, st[2]]))
        } else {
            let b = 2.0 * g * (1.0 + sf + sp - sf * sp / 3.0) + 4.0 * k * sf * sp;
            (b, m.phi13(&[st[0], 0.0, st[1]]))
        };
        let phia = m.phi13(&st);
        let det = a * a - b * b;
        let (ea, eb) = ((a * phia - b * phib) / det, (a * phib - b * phia) / det);
        assert!(
            (ga - ea).abs() + (gb - eb).abs() <= 1e-9 * (ea + eb),
            "{ga} {ea} {gb} {eb}"
        );
        assert!(ga > 0.0 && gb > 0.0, "both planes active");
    }

    #[test]
    fn edge_compression_return() {
        edge_case([-95e3, -100e3, -400e3], Return::EdgeCompression);
    }

    #[test]
    fn edge_extension_return() {
        edge_case([0.0, -197e3, -200e3], Return::EdgeExtension);
    }

    #[test]
    fn apex_return() {
        let m = mat();
        let eps = strain_for(&m, [40e3, 30e3, 20e3], &rot());
        let u = m.update(&eps, &ZERO);
        assert_eq!(u.kind, Return::Apex);
        let p = m.cohesion * m.cos_phi / m.sin_phi;
        let err = (0..6)
            .map(|i| (u.stress[i] - if i < 3 { p } else { 0.0 }).abs())
            .fold(0.0, f64::max);
        assert!(err <= 1e-12 * p, "{err}");
        assert!(m.yield_value(&u.stress).abs() <= 1e-10 * (p + m.cohesion));
        // the exact tangent is zero: a vanishing share of the elastic one keeps Newton going
        assert_eq!(u.tangent, m.elastic_tangent() * APEX_TANGENT_SHARE);
        // εᵖ = ε − D⁻¹σ with hydrostatic σ: εᵖ = ε − p/(3K) 1
        let e_el = p / (3.0 * m.bulk);
        assert!((0..6).all(
            |i| (u.plastic_strain[i] - eps[i] + if i < 3 { e_el } else { 0.0 }).abs()
                < 1e-14 * norm6(&eps)
        ));
        assert!(u.eq_plastic_increment > 0.0);
    }

    #[test]
    fn consistent_tangent_generic() {
        let m = mat();
        let r = rot();
        let mut worst: f64 = 0.0;
        for (s, kind) in [
            ([-50e3, -60e3, -80e3], Return::Elastic),
            ([-50e3, -100e3, -250e3], Return::Plane),
            ([-95e3, -100e3, -400e3], Return::EdgeCompression),
            ([0.0, -197e3, -200e3], Return::EdgeExtension),
            ([40e3, 30e3, 20e3], Return::Apex),
        ] {
            let (k, err) = tangent_error(&m, &strain_for(&m, s, &r));
            println!("generic {k:?}: tangent rel err = {err:.2e}");
            assert_eq!(k, kind);
            // at the apex the tangent keeps APEX_TANGENT_SHARE of the elastic one
            let tol = if kind == Return::Apex {
                2.0 * APEX_TANGENT_SHARE
            } else {
                1e-6
            };
            assert!(err <= tol, "{kind:?}: {err}");
            worst = worst.max(err);
        }
        // associative flow (ψ = φ) gives a symmetric tangent
        let ma = MohrCoulomb::new(30e6, 0.25, 30f64.to_radians(), 30f64.to_radians(), 10e3);
        for s in [
            [-50e3, -100e3, -250e3],
            [-95e3, -100e3, -400e3],
            [0.0, -197e3, -200e3],
        ] {
            let t = ma.update(&strain_for(&ma, s, &r), &ZERO).tangent;
            assert!((t - t.transpose()).norm() <= 1e-12 * t.norm());
        }
        // non-associative flow: non-symmetric
        let t = m
            .update(&strain_for(&m, [-50e3, -100e3, -250e3], &r), &ZERO)
            .tangent;
        assert!((t - t.transpose()).norm() > 1e-3 * t.norm());
        println!("generic worst = {worst:.2e}");
    }

    #[test]
    fn consistent_tangent_coincident() {
        let m = mat();
        let r = rot();
        for (s, kind) in [
            ([-50e3, -50e3, -80e3], Return::Elastic),
            ([-100e3, -100e3, -400e3], Return::EdgeCompression),
            ([0.0, -200e3, -200e3], Return::EdgeExtension),
            ([40e3, 40e3, 40e3], Return::Apex),
        ] {
            let eps = strain_for(&m, s, &r);
            let (k, err) = tangent_error(&m, &eps);
            println!("coincident {k:?}: tangent rel err = {err:.2e}");
            assert_eq!(k, kind);
            assert!(err <= 1e-6, "{kind:?}: {err}");
            // the generic limit ∂σ_a/∂ε_a − ∂σ_a/∂ε_b agrees with θ = 0 on edges
            let (e, _) = sym_eigen(&tensor(&eps));
            let pr = m.principal_return(&e);
            let lim = match kind {
                Return::EdgeCompression => pr.dsde[(0, 0)] - pr.dsde[(0, 1)],
                Return::EdgeExtension => pr.dsde[(1, 1)] - pr.dsde[(1, 2)],
                _ => 0.0,
            };
            assert!(lim.abs() <= 1e-9 * m.shear, "{lim}");
        }
    }

    /// Limit of the spin coefficient for coincident trial principal strains:
    /// for the elastic principal map ∂σ_a/∂ε_a − ∂σ_a/∂ε_b = 2G.
    #[test]
    fn spin_limit_coincident() {
        let m = mat();
        let e = [1e-3, 1e-3, -2e-3];
        let dp = m.principal_elastic();
        let s = dp * Vector3::new(e[0], e[1], e[2]);
        let pr = Principal {
            kind: Return::Plane,
            sigma: [s[0], s[1], s[2]],
            dsde: dp,
        };
        let th = m.spin(&pr, &e);
        assert!(
            th.iter().all(|t| (t / (2.0 * m.shear) - 1.0).abs() < 1e-12),
            "{th:?}"
        );
    }

    /// Drained triaxial compression, lateral stress held at −100 kPa by
    /// Newton iterations on the lateral strain, axial strain driven.
    #[test]
    fn drained_triaxial_compression() {
        let (e_mod, nu, c) = (60e6, 0.145, 15.0);
        let (phi, psi) = (23.15f64.to_radians(), 5.17f64.to_radians());
        MohrCoulomb::check(e_mod, nu, phi, psi, c).unwrap();
        let m = MohrCoulomb::new(e_mod, nu, phi, psi, c);
        let (sf, sp) = (m.sin_phi, m.sin_psi);
        let lat = -100e3;
        let e0 = lat / (3.0 * m.bulk);
        let (mut ax, mut el) = (e0, e0);
        let mut ep = ZERO;
        let de = -1e-5;
        // (axial strain, lateral strain, axial stress, kind)
        let mut hist = vec![(ax, el, lat, Return::Elastic)];
        for _ in 0..400 {
            ax += de;
            let mut u = m.update(&[ax, el, el, 0.0, 0.0, 0.0], &ep);
            let mut it = 0;
            while (u.stress[1] - lat).abs() > 1e-8 || (u.stress[2] - lat).abs() > 1e-8 {
                let slope = u.tangent[(1, 1)] + u.tangent[(1, 2)];
                el -= (u.stress[1] - lat) / slope;
                u = m.update(&[ax, el, el, 0.0, 0.0, 0.0], &ep);
                it += 1;
                assert!(it < 50, "Newton failed");
            }
            ep = u.plastic_strain;
            hist.push((ax, el, u.stress[0], u.kind));
        }
        let vol = |h: &(f64, f64, f64, Return)| h.0 + 2.0 * h.1;
        // elastic phase
        let slope = (hist[1].2 - hist[0].2) / (hist[1].0 - hist[0].0);
        let slope_err = (slope / e_mod - 1.0).abs();
        assert!(slope_err <= 1e-9, "{slope}");
        let vr = (vol(&hist[1]) - vol(&hist[0])) / (hist[1].0 - hist[0].0);
        let vr_err = (vr - (1.0 - 2.0 * nu)).abs() / (1.0 - 2.0 * nu);
        assert!(vr_err <= 1e-9, "{vr}");
        // yield: Φ = 0 with σ1 = σ2 = lat, σ3 = axial
        let s_y = ((1.0 + sf) * lat - 2.0 * c * m.cos_phi) / (1.0 - sf);
        let k = hist.iter().position(|h| h.3 != Return::Elastic).unwrap();
        assert!(hist[k..].iter().all(|h| h.3 == Return::EdgeCompression));
        let plateau_err = hist[k..]
            .iter()
            .map(|h| (h.2 / s_y - 1.0).abs())
            .fold(0.0, f64::max);
        assert!(plateau_err <= 1e-9, "{plateau_err}");
        let eps_y = hist[k - 1].0 + (s_y - hist[k - 1].2) / e_mod - e0;
        let eps_y_exact = (s_y - lat) / e_mod;
        assert!((eps_y / eps_y_exact - 1.0).abs() <= 1e-9);
        assert!(hist[k - 1].0 - e0 >= eps_y && eps_y >= hist[k].0 - e0);
        assert!((eps_y * 100.0 + 0.216).abs() < 5e-4, "{}", eps_y * 100.0);
        // post-yield dilatancy −Δε_V/Δε_axial = 2 s_ψ/(1 − s_ψ)
        let dil = 2.0 * sp / (1.0 - sp);
        let mut dil_err: f64 = 0.0;
        for w in hist[k..].windows(2) {
            let r = -(vol(&w[1]) - vol(&w[0])) / (w[1].0 - w[0].0);
            dil_err = dil_err.max((r / dil - 1.0).abs());
        }
        assert!(dil_err <= 1e-8, "{dil_err}");
        println!(
            "triaxial: slope err {slope_err:.2e}, vol ratio err {vr_err:.2e}, ratio {:.4}, \
             yield axial strain {:.5} %, plateau err {plateau_err:.2e}, dilatancy {dil:.5} err \
             {dil_err:.2e}, first plastic step {k}, kind {:?}",
            s_y / lat,
            eps_y * 100.0,
            hist[k].3
        );
    }

    #[test]
    fn tresca_limit() {
        let c = 50e3;
        MohrCoulomb::check(30e6, 0.3, 0.0, 0.0, c).unwrap();
        let m = MohrCoulomb::new(30e6, 0.3, 0.0, 0.0, c);
        let r = rot();
        for (s, kind) in [
            ([150e3, 0.0, -150e3], Return::Plane),
            ([-95e3, -100e3, -300e3], Return::EdgeCompression),
            ([-100e3, -100e3, -300e3], Return::EdgeCompression),
            ([300e3, 100e3, 95e3], Return::EdgeExtension),
            ([1e9, 1e9 - 50e3, 1e9 - 60e3], Return::Elastic),
        ] {
            let eps = strain_for(&m, s, &r);
            let u = m.update(&eps, &ZERO);
            assert_eq!(u.kind, kind);
            assert!(u
                .stress
                .iter()
                .chain(u.tangent.iter())
                .all(|x| x.is_finite()));
            assert!(u.eq_plastic_increment.is_finite());
            let (w, _) = sym_eigen(&tensor(&u.stress));
            if kind != Return::Elastic {
                // Tresca: σ1 − σ3 = 2c on yield whatever σ2 is (pure shear and
                // triaxial alike, unlike von Mises)
                assert!((w[0] - w[2] - 2.0 * c).abs() <= 1e-9 * c, "{w:?}");
                check_plastic(&m, &eps, &r, kind);
                let (_, err) = tangent_error(&m, &eps);
                assert!(err <= 1e-6, "{kind:?} {err}");
            }
        }
        // pure shear: σ2 = 0 stays, τ_max = c
        let u = m.update(&strain_for(&m, [150e3, 0.0, -150e3], &r), &ZERO);
        let (w, _) = sym_eigen(&tensor(&u.stress));
        assert!((w[0] - c).abs() + w[1].abs() + (w[2] + c).abs() <= 1e-9 * c);
    }

    #[test]
    fn cohesionless_isotropic_tension_apex() {
        let m = MohrCoulomb::new(30e6, 0.25, 30f64.to_radians(), 10f64.to_radians(), 0.0);
        MohrCoulomb::check(30e6, 0.25, 30f64.to_radians(), 10f64.to_radians(), 0.0).unwrap();
        let eps = [1e-3, 1e-3, 1e-3, 0.0, 0.0, 0.0];
        let u = m.update(&eps, &ZERO);
        assert_eq!(u.kind, Return::Apex);
        assert_eq!(u.stress, ZERO);
        assert_eq!(u.plastic_strain, eps);
        // the exact tangent is zero: a vanishing share of the elastic one keeps Newton going
        assert_eq!(u.tangent, m.elastic_tangent() * APEX_TANGENT_SHARE);
        assert!(u.eq_plastic_increment.is_finite());
        // zero strain is elastic, not NaN
        let u0 = m.update(&ZERO, &ZERO);
        assert_eq!(u0.kind, Return::Elastic);
        assert_eq!(u0.stress, ZERO);
    }

    #[test]
    fn bad_parameters() {
        let (e, nu, phi, psi, c) = (60e6, 0.3, 0.5, 0.1, 10.0);
        assert!(MohrCoulomb::check(e, nu, phi, psi, c).is_ok());
        let right = std::f64::consts::FRAC_PI_2;
        for (args, name) in [
            ((e, nu, phi, 0.6, c), "dilation_angle"),
            ((e, 0.5, phi, psi, c), "poisson_ratio"),
            ((e, -1.0, phi, psi, c), "poisson_ratio"),
            ((e, nu, phi, psi, -1.0), "cohesion"),
            ((e, nu, 0.0, 0.0, 0.0), "cohesion"),
            ((e, nu, right, psi, c), "friction_angle"),
            ((e, nu, -0.1, 0.0, c), "friction_angle"),
            ((0.0, nu, phi, psi, c), "youngs_modulus"),
            ((f64::NAN, nu, phi, psi, c), "youngs_modulus"),
        ] {
            let (e, nu, phi, psi, c) = args;
            assert_eq!(MohrCoulomb::check(e, nu, phi, psi, c).unwrap_err().0, name);
        }
        assert!(MohrCoulomb::check(e, nu, phi, 0.6, c)
            .unwrap_err()
            .1
            .contains("non-physical"));
        // new() does not panic on bad input
        let m = MohrCoulomb::new(e, 0.5, phi, psi, c);
        assert!(m.bulk.is_infinite());
    }
}
