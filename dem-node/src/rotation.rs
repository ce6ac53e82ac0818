//! Rotation of a rigid non-spherical body: the modified Munjiza RK4 update in
//! angular-momentum form (Wellmann 2011 §3.3, eqs. 3.35–3.46).
//!
//! State: the orientation `q`, a unit quaternion mapping the body (principal) frame to the
//! global frame (`T = q.to_rotation_matrix()`, a body point `P` sits at `p = x + T P`, eq.
//! 3.11), and the angular momentum `H`, a global vector. The principal moments of inertia
//! `(I1, I2, I3)` are given as a [`V3`]; `Ĩ = diag(I1, I2, I3)` (3.36). The angular velocity
//! `ω`, also global, is not state: it follows from `q` and `H` by (3.38).
//!
//! Wellmann stores the 9 numbers of `T` and never re-orthonormalises it; here `q` is a
//! quaternion, renormalised after every update (*not in thesis*, one cheap step).
//!
//! # Use in a velocity-Verlet engine
//!
//! Wellmann's (3.35) adds the whole kick `Δt Mⁿ` before the orientation update. A
//! velocity-Verlet engine splits it into two half kicks around [`rotate`], which holds `H`
//! constant over the step:
//!
//! ```text
//! H += ½Δt M                         // half kick with the torque of the old orientation
//! (q, ω) = rotate(q, H, I, Δt)       // (3.39)–(3.46) at constant H
//! … contact detection, forces and torques M at the new orientation …
//! H += ½Δt M                         // second half kick
//! ω = angular_velocity(q, H, I)      // (3.38), for the contact laws and output
//! ```
//!
//! Accuracy (measured, see the tests): the update is **second order** in `Δt` for the
//! orientation and the kinetic energy of a torque-free asymmetric top, not fourth order: the
//! stages `R(ωᵢ, τ) qⁿ` and the final `R(ω̄, Δt) qⁿ` compose rotations about different axes
//! without the commutator corrections a fourth-order Lie-group RK4 (Munthe-Kaas) needs (with
//! them, `−⅛ k1×k2` in the third stage and `−1/12 k1×k4` in the mean, the test
//! `commutator_corrected_stages_reach_fourth_order` measures order 4; *not in thesis*). For a
//! body with `I1 = I2 = I3` every stage has the same `ω` and the update is exact. `H` is kept
//! exactly (it is an input), so the torque-free angular momentum has no drift at all.

use crate::hertz_mindlin::V3;
use nalgebra::{Quaternion, UnitQuaternion};

/// `ω = T Ĩ⁻¹ Tᵀ H`, Wellmann (3.38): the global angular velocity of a body with orientation
/// `q` (body → global), global angular momentum `h` and principal inertia `inertia`.
#[inline]
pub fn angular_velocity(q: &UnitQuaternion<f64>, h: &V3, inertia: &V3) -> V3 {
    let h_body = q.inverse_transform_vector(h);
    q * h_body.component_div(inertia)
}

/// `H = T Ĩ Tᵀ ω`, Wellmann (3.37): the global angular momentum of a body with orientation
/// `q` (body → global), global angular velocity `omega` and principal inertia `inertia`.
#[inline]
pub fn angular_momentum(q: &UnitQuaternion<f64>, omega: &V3, inertia: &V3) -> V3 {
    let omega_body = q.inverse_transform_vector(omega);
    q * omega_body.component_mul(inertia)
}

/// `R(ω, τ)` of (3.39): the rotation by the angle `|ω|τ` about `ω/|ω|` (the identity for
/// `ω = 0`), as the quaternion `(cos(θ/2), (τ/2) · sin(θ/2)/(θ/2) · ω)` with `θ = |ω|τ`; the
/// `sin(x)/x` factor is evaluated by its Taylor series for small `x`, so no division by a
/// tiny `|ω|` occurs.
#[inline]
fn rotation(omega: &V3, tau: f64) -> Quaternion<f64> {
    let x2 = omega.norm_squared() * (0.25 * tau * tau);
    let (sinc, cos) = if x2 < 1e-6 {
        // sin(x)/x and cos x to their x⁶ terms: the next terms are below 1e-24 here (products
        // by the reciprocals and no square root: this is on the turn's critical path)
        (
            1.0 - x2 * (1.0 / 6.0) * (1.0 - x2 * (1.0 / 20.0) * (1.0 - x2 * (1.0 / 42.0))),
            1.0 - x2 * 0.5 * (1.0 - x2 * (1.0 / 12.0) * (1.0 - x2 * (1.0 / 30.0))),
        )
    } else {
        let x = x2.sqrt();
        (x.sin() / x, x.cos())
    };
    let s = 0.5 * tau * sinc;
    Quaternion::new(cos, s * omega.x, s * omega.y, s * omega.z)
}

/// The orientation update over `dt` at constant angular momentum `h` (global), Wellmann
/// (3.39)–(3.46):
///
/// ```text
/// ω1 = ω(qⁿ, H)                                        (3.40)
/// ω2 = ω(R(ω1, Δt/2) qⁿ, H)                            (3.41)
/// ω3 = ω(R(ω2, Δt/2) qⁿ, H)                            (3.42)
/// ω4 = ω(R(ω3, Δt) qⁿ, H)                              (3.43)
/// ω̄ = (ω1 + 2ω2 + 2ω3 + ω4)/6                          (3.44)
/// qⁿ⁺¹ = R(ω̄, Δt) qⁿ                                   (3.45)
/// ```
///
/// Returns `(qⁿ⁺¹, ωⁿ⁺¹ = ω(qⁿ⁺¹, H))` (3.46). The momentum kicks (3.35) are the caller's
/// (see the module documentation). Unlike (3.40), `ω1` is evaluated with the same `H` as the
/// other stages rather than taken over from the previous step.
#[inline]
pub fn rotate(q: &UnitQuaternion<f64>, h: &V3, inertia: &V3, dt: f64) -> (UnitQuaternion<f64>, V3) {
    rotate_body(q, &q.inverse_transform_vector(h), inertia, dt)
}

/// [`rotate`] with the angular momentum given in the body frame of `q`, `h_body = qⁿᵀ H`,
/// and every stage evaluated in that frame (*not in thesis*; the same algebra, fewer
/// products): a trial orientation R(ω, τ) qⁿ equals qⁿ R(qⁿᵀω, τ), so with
/// `ω_b = qⁿᵀω` each stage (3.41)–(3.43) is `ω_b′ = R_b (Ĩ⁻¹ R_bᵀ h_body)`, R_b = R(ω_b, τ),
/// (3.40) is `Ĩ⁻¹ h_body`, and (3.45) is qⁿ⁺¹ = qⁿ R(ω̄_b, Δt): two vector rotations per
/// stage and no quaternion product, where the global form needs four and one.
#[inline]
pub fn rotate_body(
    q: &UnitQuaternion<f64>,
    h_body: &V3,
    inertia: &V3,
    dt: f64,
) -> (UnitQuaternion<f64>, V3) {
    let inverse = inertia.map(|i| 1.0 / i);
    let stage = |omega: &V3, tau: f64| {
        let r = UnitQuaternion::new_unchecked(rotation(omega, tau));
        r * r.inverse_transform_vector(h_body).component_mul(&inverse)
    };
    let w1 = h_body.component_mul(&inverse);
    let w2 = stage(&w1, 0.5 * dt);
    let w3 = stage(&w2, 0.5 * dt);
    let w4 = stage(&w3, dt);
    let w_bar = (w1 + 2.0 * (w2 + w3) + w4) / 6.0;
    let r = UnitQuaternion::new_unchecked(rotation(&w_bar, dt));
    // Renormalised after the product (*not in thesis*: Wellmann's matrix T is never
    // re-orthonormalised); this keeps |q| = 1 to round-off over any number of steps.
    let q_next = UnitQuaternion::new_normalize(q.quaternion() * r.quaternion());
    // (3.46): ω = qⁿ⁺¹ Ĩ⁻¹ qⁿ⁺¹ᵀ H with qⁿ⁺¹ᵀ H = Rᵀ h_body
    let w_next = q_next * r.inverse_transform_vector(h_body).component_mul(&inverse);
    (q_next, w_next)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::generate::SplitMix64;
    use nalgebra::{Matrix3, Unit};

    fn random_orientation(rng: &mut SplitMix64) -> UnitQuaternion<f64> {
        let axis = Unit::new_normalize(crate::generate::random_unit_vector(rng));
        UnitQuaternion::from_axis_angle(&axis, std::f64::consts::PI * rng.uniform())
    }

    fn kinetic_energy(q: &UnitQuaternion<f64>, h: &V3, inertia: &V3) -> f64 {
        0.5 * angular_velocity(q, h, inertia).dot(h)
    }

    /// Torque-free top: `n` steps of `rotate` from `q0` with momentum `h`.
    fn run(
        q0: UnitQuaternion<f64>,
        h: &V3,
        inertia: &V3,
        dt: f64,
        n: usize,
    ) -> UnitQuaternion<f64> {
        let mut q = q0;
        for _ in 0..n {
            q = rotate(&q, h, inertia, dt).0;
        }
        q
    }

    /// Reference: Euler's equations in the body frame, `I ω̇ + ω × Iω = 0`, with the
    /// quaternion kinematics `q̇ = ½ q ⊗ (0, ω_body)`, classical RK4 at step `dt`.
    fn reference(
        q0: UnitQuaternion<f64>,
        omega_body: V3,
        inertia: &V3,
        t_end: f64,
        dt: f64,
    ) -> UnitQuaternion<f64> {
        let rhs = |q: &Quaternion<f64>, w: &V3| {
            let iw = w.component_mul(inertia);
            let w_dot = -w.cross(&iw).component_div(inertia);
            let q_dot = q * Quaternion::new(0.0, w.x, w.y, w.z) * 0.5;
            (q_dot, w_dot)
        };
        let n = (t_end / dt).round() as usize;
        let (mut q, mut w) = (q0.into_inner(), omega_body);
        for _ in 0..n {
            let (k1q, k1w) = rhs(&q, &w);
            let (k2q, k2w) = rhs(&(q + k1q * (0.5 * dt)), &(w + k1w * (0.5 * dt)));
            let (k3q, k3w) = rhs(&(q + k2q * (0.5 * dt)), &(w + k2w * (0.5 * dt)));
            let (k4q, k4w) = rhs(&(q + k3q * dt), &(w + k3w * dt));
            q += (k1q + k2q * 2.0 + k3q * 2.0 + k4q) * (dt / 6.0);
            w += (k1w + 2.0 * k2w + 2.0 * k3w + k4w) * (dt / 6.0);
        }
        UnitQuaternion::new_normalize(q)
    }

    #[test]
    fn omega_and_momentum_match_the_matrix_form_and_invert() {
        let mut rng = SplitMix64::new(7);
        for _ in 0..100 {
            let q = random_orientation(&mut rng);
            let inertia = V3::new(
                0.5 + rng.uniform(),
                0.5 + rng.uniform(),
                0.5 + rng.uniform(),
            );
            let h = crate::generate::random_unit_vector(&mut rng) * 3.0;
            let t = q.to_rotation_matrix().into_inner();
            let inv = Matrix3::from_diagonal(&inertia.map(|i| 1.0 / i));
            let omega_matrix = t * inv * t.transpose() * h;
            let omega = angular_velocity(&q, &h, &inertia);
            assert!((omega - omega_matrix).norm() <= 1e-14 * omega.norm());
            let back = angular_momentum(&q, &omega, &inertia);
            assert!((back - h).norm() <= 1e-14 * h.norm());
        }
    }

    #[test]
    fn rotation_is_exact_for_small_and_zero_angles() {
        let q = rotation(&V3::zeros(), 1.0);
        assert_eq!(q, Quaternion::identity());
        for &w in &[1e-300, 1e-12, 1e-4, 1e-3 * 1.999, 2.1e-3, 0.3, 5.0] {
            let omega = V3::new(1.0, -2.0, 0.5).normalize() * w;
            let tau = 1.0;
            let expect = UnitQuaternion::from_scaled_axis(omega * tau).into_inner();
            let got = rotation(&omega, tau);
            assert!(
                (got - expect).norm() <= 2e-16,
                "|ω| = {w}: {got:?} vs {expect:?}"
            );
            assert!((got.norm() - 1.0).abs() <= 2e-16);
        }
        // zero momentum: the orientation stays
        let q0 = UnitQuaternion::from_euler_angles(0.1, 0.2, 0.3);
        let (q1, w1) = rotate(&q0, &V3::zeros(), &V3::new(1.0, 2.0, 3.0), 0.1);
        assert!(q1.angle_to(&q0) <= 1e-15 && w1 == V3::zeros());
    }

    #[test]
    fn sphere_like_inertia_is_exact() {
        let inertia = V3::new(2.5, 2.5, 2.5);
        let omega = V3::new(0.3, -1.2, 0.7);
        let q0 = UnitQuaternion::from_euler_angles(0.4, -0.3, 1.1);
        let h = angular_momentum(&q0, &omega, &inertia);
        let (dt, n) = (1e-2, 1000);
        let q = run(q0, &h, &inertia, dt, n);
        let exact = UnitQuaternion::from_scaled_axis(omega * (dt * n as f64)) * q0;
        let err = q.angle_to(&exact);
        eprintln!("sphere-like inertia, 1000 steps: angle error {err:e} rad");
        assert!(err <= 1e-12, "angle error {err:e}");
        let (_, w) = rotate(&q, &h, &inertia, dt);
        assert!((w - omega).norm() <= 1e-14);
    }

    /// The asymmetric top of the energy and reference tests.
    fn top() -> (UnitQuaternion<f64>, V3, V3) {
        let inertia = V3::new(1.0, 2.0, 3.0);
        let q0 = UnitQuaternion::from_euler_angles(0.3, -0.7, 1.2);
        let omega0 = q0 * V3::new(1.0, 2.0, 1.5);
        (q0, angular_momentum(&q0, &omega0, &inertia), inertia)
    }

    #[test]
    fn torque_free_top_keeps_momentum_and_energy_converges_second_order() {
        let (q0, h, inertia) = top();
        let e0 = kinetic_energy(&q0, &h, &inertia);
        let t_end = 2.0;
        let mut errors = Vec::new();
        for k in 0..3 {
            let dt = 1e-2 / f64::powi(2.0, k);
            let n = (t_end / dt).round() as usize;
            let mut q = q0;
            for _ in 0..n {
                let (q1, w1) = rotate(&q, &h, &inertia, dt);
                q = q1;
                let back = angular_momentum(&q, &w1, &inertia);
                assert!((back - h).norm() <= 1e-13 * h.norm());
            }
            let err = (kinetic_energy(&q, &h, &inertia) - e0).abs() / e0;
            errors.push(err);
        }
        let orders: Vec<f64> = errors.windows(2).map(|e| (e[0] / e[1]).log2()).collect();
        eprintln!("relative energy error at t = 2 s, dt = 1e-2, 5e-3, 2.5e-3: {errors:?}, orders {orders:.3?}");
        assert!(errors[0] < 1e-3, "{errors:?}");
        for p in orders {
            assert!((1.5..=2.5).contains(&p), "observed order {p}");
        }
    }

    #[test]
    fn orientation_matches_euler_equations_reference() {
        let (q0, h, inertia) = top();
        let t_end = 2.0;
        let omega_body = q0.inverse_transform_vector(&angular_velocity(&q0, &h, &inertia));
        let q_ref = reference(q0, omega_body, &inertia, t_end, 1e-5);
        // the reference itself: halving its step changes it by round-off only
        let q_ref2 = reference(q0, omega_body, &inertia, t_end, 2e-5);
        assert!(q_ref.angle_to(&q_ref2) < 1e-12);
        let mut errors = Vec::new();
        for k in 0..3 {
            let dt = 1e-3 * f64::powi(2.0, k);
            let q = run(q0, &h, &inertia, dt, (t_end / dt).round() as usize);
            errors.push(q.angle_to(&q_ref));
        }
        let orders: Vec<f64> = errors.windows(2).map(|e| (e[1] / e[0]).log2()).collect();
        eprintln!("orientation error (rad) at t = 2 s, dt = 1e-3, 2e-3, 4e-3: {errors:?}, orders {orders:.3?}");
        assert!(errors[0] < 1e-5, "{errors:?}");
        for p in orders {
            assert!((1.5..=2.5).contains(&p), "observed order {p}");
        }
    }

    /// The same stages with the commutator corrections of the Runge–Kutta–Munthe-Kaas RK4
    /// (Iserles et al., Acta Numerica 2000; `[a, b] = a × b` in so(3)): fourth order. Shows
    /// that the second order of [`rotate`] belongs to the scheme (3.39)–(3.45), not to this
    /// implementation of it.
    fn rotate_rkmk4(q: &UnitQuaternion<f64>, h: &V3, inertia: &V3, dt: f64) -> UnitQuaternion<f64> {
        let qn = q.quaternion();
        let at = |u: V3| {
            angular_velocity(
                &UnitQuaternion::new_unchecked(rotation(&u, 1.0) * qn),
                h,
                inertia,
            ) * dt
        };
        let k1 = angular_velocity(q, h, inertia) * dt;
        let k2 = at(0.5 * k1);
        let k3 = at(0.5 * k2 - k1.cross(&k2) / 8.0);
        let k4 = at(k3);
        let v = (k1 + 2.0 * (k2 + k3) + k4) / 6.0 - k1.cross(&k4) / 12.0;
        UnitQuaternion::new_normalize(rotation(&v, 1.0) * qn)
    }

    #[test]
    fn commutator_corrected_stages_reach_fourth_order() {
        let (q0, h, inertia) = top();
        let t_end = 2.0;
        let omega_body = q0.inverse_transform_vector(&angular_velocity(&q0, &h, &inertia));
        let q_ref = reference(q0, omega_body, &inertia, t_end, 1e-5);
        let mut errors = Vec::new();
        for k in 0..3 {
            let dt = 1e-2 * f64::powi(2.0, k);
            let mut q = q0;
            for _ in 0..(t_end / dt).round() as usize {
                q = rotate_rkmk4(&q, &h, &inertia, dt);
            }
            errors.push(q.angle_to(&q_ref));
        }
        let orders: Vec<f64> = errors.windows(2).map(|e| (e[1] / e[0]).log2()).collect();
        eprintln!(
            "RKMK4 orientation error (rad), dt = 1e-2, 2e-2, 4e-2: {errors:?}, orders {orders:.3?}"
        );
        for p in orders {
            assert!((3.5..=4.5).contains(&p), "observed order {p}");
        }
    }

    #[test]
    fn orthonormality_after_many_random_updates() {
        let mut rng = SplitMix64::new(42);
        let mut q = random_orientation(&mut rng);
        let dt = 1e-2;
        let mut worst = 0.0f64;
        for k in 0..1_000_000 {
            if k % 1000 == 0 {
                let t = q.to_rotation_matrix().into_inner();
                worst = worst.max((t.transpose() * t - Matrix3::identity()).amax());
            }
            let inertia = V3::new(
                0.2 + rng.uniform(),
                0.2 + rng.uniform(),
                0.2 + rng.uniform(),
            );
            // |ω| Δt up to about 0.5 rad per update
            let omega = crate::generate::random_unit_vector(&mut rng) * (50.0 * rng.uniform());
            let h = angular_momentum(&q, &omega, &inertia);
            q = rotate(&q, &h, &inertia, dt).0;
        }
        let t = q.to_rotation_matrix().into_inner();
        worst = worst.max((t.transpose() * t - Matrix3::identity()).amax());
        eprintln!("max |TᵀT − 1| over 1e6 random updates: {worst:e}");
        assert!(worst <= 1e-12, "{worst:e}");
        assert!((q.quaternion().norm() - 1.0).abs() <= 1e-15);
    }

    /// Spin about a principal axis with a tiny perturbation; the smallest cosine between that
    /// body axis and `H` over `t_end`.
    fn min_axis_alignment(axis: usize, t_end: f64) -> f64 {
        let inertia = V3::new(1.0, 2.0, 3.0);
        let q0 = UnitQuaternion::from_euler_angles(0.2, 0.5, -0.4);
        let mut omega_body = V3::repeat(1e-4);
        omega_body[axis] = 10.0;
        let h = angular_momentum(&q0, &(q0 * omega_body), &inertia);
        let h_dir = h.normalize();
        let mut e = V3::zeros();
        e[axis] = 1.0;
        let dt = 1e-3;
        let mut q = q0;
        let mut min_cos = f64::INFINITY;
        for _ in 0..(t_end / dt).round() as usize {
            q = rotate(&q, &h, &inertia, dt).0;
            min_cos = min_cos.min((q * e).dot(&h_dir));
        }
        min_cos
    }

    #[test]
    fn intermediate_axis_flips_major_and_minor_axes_stay() {
        let intermediate = min_axis_alignment(1, 5.0);
        let major = min_axis_alignment(2, 5.0);
        let minor = min_axis_alignment(0, 5.0);
        eprintln!(
            "min cos(axis, H): intermediate {intermediate:.4}, major {major:.6}, minor {minor:.6}"
        );
        assert!(
            intermediate < -0.99,
            "intermediate axis did not flip: {intermediate}"
        );
        assert!(major > 0.9999, "major axis left H: {major}");
        assert!(minor > 0.9999, "minor axis left H: {minor}");
    }
}
