//! Hertz–Mindlin–Deresiewicz contact law (Ullrich eqs. 2.6–2.19, REFERENCE A1) in the form of
//! LIGGGHTS' `hertz/mindlin` with tangential history, a Coulomb cap and optional rolling
//! resistance (constant directional torque).

use crate::materials::PairParams;
use nalgebra::Vector3;

pub type V3 = Vector3<f64>;

/// √(5/6) of the Tsuji mapping F_d = −2√(5/6) β √(S m*) v.
pub const SQRT_5_6: f64 = 0.912_870_929_175_276_8;

/// Result of one contact evaluation, forces acting on body i.
#[derive(Debug, Clone, Copy)]
pub struct ContactForce {
    pub force: V3,
    pub tangential: V3,
    /// Normal force magnitude (≥ 0) after clamping.
    pub normal: f64,
}

/// Evaluates one contact.
///
/// `n` is the unit normal pointing towards body i, `delta > 0` the overlap, `r_eff` and
/// `m_eff` the effective radius (2.8) and mass (2.11), `v_c` the velocity of i's contact point
/// relative to j's, `shear` the tangential displacement history ξ of this contact (updated in
/// place), `dt` the increment time (0 for a force evaluation without history increment).
#[inline(always)]
#[allow(clippy::too_many_arguments)] // the physical inputs of one contact, kept unbundled for the hot loop
pub fn contact_force(
    p: &PairParams,
    delta: f64,
    r_eff: f64,
    m_eff: f64,
    n: &V3,
    v_c: &V3,
    shear: &mut V3,
    dt: f64,
) -> ContactForce {
    let (s_n, s_t, f_elastic) = if p.linear_normal > 0.0 {
        // the linear spring-dashpot law (`MaterialConfig::normal_stiffness`)
        (
            p.linear_normal,
            p.linear_tangential,
            p.linear_normal * delta,
        )
    } else {
        let sqrt_rd = (r_eff * delta).sqrt();
        // (2.12) S_n = k_n = 2E*√(Rδ); (2.16) S_t = k_t = 8G*√(Rδ); (2.6) F_n,e = 4/3 E* √R δ^{3/2}
        (
            p.two_e_star * sqrt_rd,
            p.eight_g_star * sqrt_rd,
            p.four_thirds_e_star * sqrt_rd * delta,
        )
    };
    let v_n = v_c.dot(n);
    let (gamma_n, gamma_t) = p.dashpots(s_n, m_eff);
    // (2.13), no attraction: the total normal force is clamped at zero.
    let normal = (f_elastic - gamma_n * v_n).max(0.0);
    let v_t = v_c - n * v_n;
    // Tangential spring: rotate the history into the current tangent plane, keeping its length,
    // then add the increment v_t Δt (incremental form of eq. 2.15).
    let old_len2 = shear.norm_squared();
    if old_len2 > 0.0 {
        let rotated = *shear - n * shear.dot(n);
        let new_len2 = rotated.norm_squared();
        *shear = if new_len2 > 0.0 {
            rotated * (old_len2 / new_len2).sqrt()
        } else {
            V3::zeros()
        };
    }
    *shear += v_t * dt;
    // (2.18) with Coulomb cap μF_n
    let f_spring = *shear * (-s_t);
    let f_cap = p.friction * normal;
    let tangential = if f_spring.norm_squared() > f_cap * f_cap {
        let len = f_spring.norm();
        let capped = f_spring * (f_cap / len);
        *shear = capped * (-1.0 / s_t);
        capped
    } else {
        f_spring - v_t * gamma_t
    };
    ContactForce {
        force: n * normal + tangential,
        tangential,
        normal,
    }
}

/// Rolling resistance, constant directional torque: M_r = −μ_r R* F_n ω_rel/|ω_rel| (on i),
/// limited to the torque that stops the relative rolling within one step, |M_r| ≤ I* |ω_rel|/Δt
/// (I* the effective moment of inertia). Without that limit the constant torque overshoots
/// and reverses ω_rel every step near rest, which feeds a permanent jitter through the
/// tangential springs; the limit is what the elastic part of EPSD models achieves.
#[inline(always)]
pub fn rolling_torque(
    mu_r: f64,
    r_eff: f64,
    normal: f64,
    omega_rel: &V3,
    inertia_eff: f64,
    dt: f64,
) -> V3 {
    let w = omega_rel.norm();
    if mu_r <= 0.0 || w < 1e-12 {
        return V3::zeros();
    }
    let mut m = mu_r * r_eff * normal;
    if dt > 0.0 {
        m = m.min(inertia_eff * w / dt);
    }
    omega_rel * (-m / w)
}

/// Rebound coefficient of the dimensionless Hertz impact y'' = −y^{3/2} − b y^{1/4} y'
/// (force clamped ≥ 0), y(0) = 0, y'(0) = 1. With the damping of [`contact_force`] the impact
/// of any mass, radius, modulus and speed reduces to this equation with b = −√5 β, so the
/// restitution depends on β only.
pub fn restitution_of_damping(b: f64) -> f64 {
    let accel = |y: f64, v: f64| -> f64 {
        if y <= 0.0 {
            return 0.0;
        }
        let f = y * y.sqrt() + b * y.sqrt().sqrt() * v;
        -f.max(0.0)
    };
    let h = 2e-4;
    let (mut y, mut v) = (0.0f64, 1.0f64);
    for _ in 0..2_000_000 {
        // classical RK4
        let (k1y, k1v) = (v, accel(y, v));
        let (k2y, k2v) = (
            v + 0.5 * h * k1v,
            accel(y + 0.5 * h * k1y, v + 0.5 * h * k1v),
        );
        let (k3y, k3v) = (
            v + 0.5 * h * k2v,
            accel(y + 0.5 * h * k2y, v + 0.5 * h * k2v),
        );
        let (k4y, k4v) = (v + h * k3v, accel(y + h * k3y, v + h * k3v));
        let ny = y + h / 6.0 * (k1y + 2.0 * k2y + 2.0 * k3y + k4y);
        let nv = v + h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v);
        if ny <= 0.0 && nv < 0.0 {
            // left the contact within this step; the force vanishes at y = 0
            let frac = y / (y - ny);
            return -(v + frac * (nv - v));
        }
        if nv.abs() < 1e-9 && ny > 0.0 && accel(ny, 0.0).abs() < 1e-12 {
            return 0.0;
        }
        y = ny;
        v = nv;
    }
    0.0
}

/// β of the Tsuji mapping, calibrated so that the clamped Hertz impact rebounds with
/// restitution `e`. The textbook value β = ln e/√(ln²e + π²) is exact for a linear
/// spring-dashpot only; for Hertz it misses e by several percent, so we solve e(β) = e by
/// bisection on the dimensionless impact (see [`restitution_of_damping`]).
pub fn damping_beta(e: f64) -> f64 {
    if e >= 1.0 {
        return 0.0;
    }
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    while restitution_of_damping(hi) > e && hi < 1e6 {
        hi *= 2.0;
    }
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if restitution_of_damping(mid) > e {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    -0.5 * (lo + hi) / 5f64.sqrt()
}

/// β = ln e / √(ln²e + π²), the uncalibrated textbook mapping (reported for comparison).
pub fn textbook_beta(e: f64) -> f64 {
    let l = e.ln();
    l / (l * l + std::f64::consts::PI.powi(2)).sqrt()
}
