//! Materials and per-pair contact parameters (Ullrich eqs. 2.7, 2.17; REFERENCE A1).

use crate::config::DemConfig;
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Material {
    pub name: String,
    pub youngs_modulus: f64,
    pub poisson_ratio: f64,
    pub density: f64,
    pub restitution: f64,
    pub friction: f64,
    pub rolling_friction: f64,
    /// This material's half of a linear contact spring (N/m), `None` for Hertz–Mindlin.
    #[serde(default)]
    pub normal_stiffness: Option<f64>,
}

impl Material {
    pub fn shear_modulus(&self) -> f64 {
        self.youngs_modulus / (2.0 * (1.0 + self.poisson_ratio))
    }
}

/// Contact parameters of one (ordered-insensitive) material pair.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct PairParams {
    /// Effective modulus, eq. (2.7): 1/E* = (1−ν_i²)/E_i + (1−ν_j²)/E_j.
    pub e_star: f64,
    /// Effective shear modulus. Erratum to eq. (2.17): Mindlin's form is
    /// 1/G* = (2−ν_i)/G_i + (2−ν_j)/G_j (as in LIGGGHTS); the printed (1−ν²)/G is not.
    pub g_star: f64,
    pub friction: f64,
    pub restitution: f64,
    pub rolling_friction: f64,
    /// Damping factor β (≤ 0) of F_d = −2√(5/6) β √(S m*) v, calibrated so that the Hertz
    /// contact with this damping rebounds with exactly `restitution` (see `hertz_mindlin`).
    pub beta: f64,
    /// √(S_t/S_n) = √(4G*/E*) (eqs. 2.12, 2.16): ratio of the tangential to the normal damping.
    pub sqrt_stiffness_ratio: f64,
    /// Constant factors of `hertz_mindlin::contact_force`: 2E*, 8G*, 4/3 E*, and the dashpot's
    /// γ_n/√(S_n m*): −2√(5/6)β (restitution-calibrated), 2ζ (a pair's `damping_ratio`,
    /// W 3.29), 0 with `viscoelastic_time`.
    pub two_e_star: f64,
    pub eight_g_star: f64,
    pub four_thirds_e_star: f64,
    pub damping_factor: f64,
    /// λ1, λ2 of Mindlin's elliptic compliance (Wellmann 3.22), for shaped contacts.
    #[serde(default)]
    pub mindlin_lambda1: f64,
    #[serde(default)]
    pub mindlin_lambda2: f64,
    /// The pair's dashpot (every shape; the superquadric law reads it here, the sphere kernel
    /// through `damping_factor`, `viscoelastic_time` and `no_tangential_dashpot`).
    #[serde(default)]
    pub shaped_damping: ShapedDamping,
    /// Linear spring-dashpot law (both materials' `normal_stiffness` in series), N/m; 0 for
    /// Hertz–Mindlin. `damping_factor` is then 2ζ of the exact restitution.
    #[serde(default)]
    pub linear_normal: f64,
    /// Its tangential spring k_t = k_n · 4G*/E*, N/m.
    #[serde(default)]
    pub linear_tangential: f64,
    /// A of Brilliantov's viscoelastic dashpot γ_n = S_n A (W 3.30) where the pair has
    /// `viscoelastic_time`; 0 otherwise (γ_n = `damping_factor` √(S_n m*)).
    #[serde(default)]
    pub viscoelastic_time: f64,
    /// The pair's law has no tangential dashpot (Wellmann's laws (3.29)/(3.30) damp the normal
    /// direction only); the restitution-calibrated law (Ullrich 2.18, LIGGGHTS) has one.
    #[serde(default)]
    pub no_tangential_dashpot: bool,
}

/// The dashpot of a material pair's contacts (Wellmann 3.27–3.30), for every shape: spheres
/// and dilated polyhedra take the same choice in `hertz_mindlin::contact_force`.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Default)]
pub enum ShapedDamping {
    /// −2√(5/6)β√(c_N m*) δ̇ with β from the pair's restitution, as for spheres.
    #[default]
    Restitution,
    /// ζ · 2√(c_N m*) δ̇ (W 3.29).
    QuasiStatic(f64),
    /// (3/2)γE*A√δ δ̇ = c_N A δ̇ (W 3.30).
    Viscoelastic(f64),
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MaterialTable {
    pub materials: Vec<Material>,
    /// Row-major n×n table.
    pub pairs: Vec<PairParams>,
}

impl PairParams {
    /// The normal and tangential dashpot coefficients γ_n, γ_t (N s/m) of a contact of normal
    /// stiffness `s_n` and effective mass `m_eff`: Tsuji/LIGGGHTS (replacing the schematic
    /// U 2.10), γ_n = `damping_factor` √(S_n m*) and γ_t = γ_n √(S_t/S_n); a pair
    /// with Wellmann's dashpot: ζ 2√(S_n m*) (W 3.29, `damping_factor` = 2ζ) or S_n A (W 3.30),
    /// and no tangential one.
    #[inline(always)]
    pub fn dashpots(&self, s_n: f64, m_eff: f64) -> (f64, f64) {
        let gamma_n = if self.viscoelastic_time > 0.0 {
            s_n * self.viscoelastic_time
        } else {
            self.damping_factor * (s_n * m_eff).sqrt()
        };
        let gamma_t = if self.no_tangential_dashpot {
            0.0
        } else {
            gamma_n * self.sqrt_stiffness_ratio
        };
        (gamma_n, gamma_t)
    }
}

impl MaterialTable {
    pub fn from_config(cfg: &DemConfig) -> MaterialTable {
        let materials: Vec<Material> = cfg
            .materials
            .iter()
            .map(|(name, m)| Material {
                name: name.clone(),
                youngs_modulus: m.youngs_modulus,
                poisson_ratio: m.poisson_ratio,
                density: m.density,
                restitution: m.restitution,
                friction: m.friction,
                rolling_friction: m.rolling_friction,
                normal_stiffness: m.normal_stiffness,
            })
            .collect();
        let n = materials.len();
        let mut pairs = Vec::with_capacity(n * n);
        for a in &materials {
            for b in &materials {
                let mut friction = 0.5 * (a.friction + b.friction);
                let mut restitution = 0.5 * (a.restitution + b.restitution);
                let mut rolling_friction = 0.5 * (a.rolling_friction + b.rolling_friction);
                let mut shaped_damping = ShapedDamping::Restitution;
                for ia in &cfg.interactions {
                    let [x, y] = &ia.materials;
                    if (x == &a.name && y == &b.name) || (x == &b.name && y == &a.name) {
                        friction = ia.friction.unwrap_or(friction);
                        restitution = ia.restitution.unwrap_or(restitution);
                        rolling_friction = ia.rolling_friction.unwrap_or(rolling_friction);
                        if let Some(z) = ia.damping_ratio {
                            shaped_damping = ShapedDamping::QuasiStatic(z);
                        }
                        if let Some(a) = ia.viscoelastic_time {
                            shaped_damping = ShapedDamping::Viscoelastic(a);
                        }
                    }
                }
                let e_star = 1.0
                    / ((1.0 - a.poisson_ratio.powi(2)) / a.youngs_modulus
                        + (1.0 - b.poisson_ratio.powi(2)) / b.youngs_modulus);
                let g_star = 1.0
                    / ((2.0 - a.poisson_ratio) / a.shear_modulus()
                        + (2.0 - b.poisson_ratio) / b.shear_modulus());
                // the linear law where both halves of the spring are given (config checks that
                // a scene's materials all have one or none)
                let linear_normal = match (a.normal_stiffness, b.normal_stiffness) {
                    (Some(ka), Some(kb)) => 1.0 / (1.0 / ka + 1.0 / kb),
                    _ => 0.0,
                };
                let sqrt_stiffness_ratio = (4.0 * g_star / e_star).sqrt();
                let beta = if linear_normal > 0.0 {
                    crate::hertz_mindlin::textbook_beta(restitution)
                } else {
                    crate::hertz_mindlin::damping_beta(restitution)
                };
                // F_d = −γ v, γ = damping_factor √(S_n m*): −2√(5/6)β for Hertz (Tsuji), −2β
                // = 2ζ for the linear spring (exact restitution of the unclamped law)
                let restitution_factor = if linear_normal > 0.0 {
                    -2.0 * beta
                } else {
                    -2.0 * crate::hertz_mindlin::SQRT_5_6 * beta
                };
                // Wellmann's dashpots act on the normal direction only (W 3.29–3.31): ζ of
                // the critical 2√(S_n m*), or S_n A
                let (damping_factor, viscoelastic_time, no_tangential_dashpot) =
                    match shaped_damping {
                        ShapedDamping::Restitution => (restitution_factor, 0.0, false),
                        ShapedDamping::QuasiStatic(zeta) => (2.0 * zeta, 0.0, true),
                        ShapedDamping::Viscoelastic(a) => (0.0, a, true),
                    };
                let mindlin = crate::elliptic_hertz::MindlinConstants::new(
                    a.youngs_modulus,
                    a.poisson_ratio,
                    b.youngs_modulus,
                    b.poisson_ratio,
                );
                pairs.push(PairParams {
                    e_star,
                    g_star,
                    friction,
                    restitution,
                    rolling_friction,
                    beta,
                    two_e_star: 2.0 * e_star,
                    eight_g_star: 8.0 * g_star,
                    four_thirds_e_star: 4.0 / 3.0 * e_star,
                    damping_factor,
                    sqrt_stiffness_ratio,
                    mindlin_lambda1: mindlin.lambda1,
                    mindlin_lambda2: mindlin.lambda2,
                    shaped_damping,
                    linear_normal,
                    linear_tangential: linear_normal * sqrt_stiffness_ratio.powi(2),
                    viscoelastic_time,
                    no_tangential_dashpot,
                });
            }
        }
        MaterialTable { materials, pairs }
    }

    pub fn index(&self, name: &str) -> Option<u16> {
        self.materials
            .iter()
            .position(|m| m.name == name)
            .map(|i| i as u16)
    }

    #[inline]
    pub fn pair(&self, a: u16, b: u16) -> &PairParams {
        &self.pairs[a as usize * self.materials.len() + b as usize]
    }
}
