//! Contact law of two smooth convex bodies touching in an elliptic contact area (Wellmann 2011,
//! ch. 3.2, eqs. 3.13–3.31; SEED-SPEC §1.7): Hertz's normal force for an elliptic contact,
//! Mindlin's elliptic no-slip tangential compliances and a Coulomb cap.
//!
//! Pure math, no engine state: the caller supplies the curvature tensors of both surfaces at the
//! contact points, the overlap δ, its rate and the relative velocity of the contact points.
//!
//! Corrections to the printed thesis (SEED-SPEC §7):
//! - W3: (3.17) is used as B/A = (κ²E(e) − K(e))/(K(e) − E(e)); the printed numerator
//!   (1/κ)²E − K is negative for κ ≥ 1.
//! - W4: E and K in (3.19) are functions of the eccentricity e, not of κ.
//!
//! Not in the thesis (each said so where it is used): the complete elliptic integrals by the
//! arithmetic–geometric mean (the thesis approximates them, [1, 7]); κ by a safeguarded Newton
//! iteration on (3.17) (the thesis uses the approximation of Antoine et al., rel. error
//! 5.86e-6); the relative curvatures as eigenvalues of the mean curvature tensor (equivalent to
//! (3.15)–(3.16)); the rotation of the stored tangential force into the current tangent plane;
//! the guards on degenerate input.
//!
//! Notation: `A ≤ B` are the relative principal curvatures (3.15)–(3.16); `B(e)`, `D(e)` are
//! the functions (3.20) of the eccentricity (fields `b_e`, `d_e`); `K`, `E` the complete
//! elliptic integrals of modulus e (fields `k`, `ee`).

use crate::hertz_mindlin::V3;
use crate::shape::superquadric::hypot_fast;
use nalgebra::Matrix3;
use std::f64::consts::{FRAC_PI_2, PI};

/// Largest ratio B/A of the relative curvatures used (*not in thesis*: larger ratios, also
/// A ≤ 0 — a flat direction — are clamped to it; the range of the thesis' approximation).
pub const MAX_CURVATURE_RATIO: f64 = 1e10;

/// Complete elliptic integrals `(K(e), E(e))` of the first and second kind, modulus `e` (not the
/// parameter m = e²), by the arithmetic–geometric mean to machine precision (*not in thesis*).
///
/// `|e|` is used; `|e| ≥ 1` gives `(∞, 1)`, NaN gives NaN.
pub fn complete_elliptic_integrals(e: f64) -> (f64, f64) {
    let e = e.abs();
    if e.is_nan() {
        return (f64::NAN, f64::NAN);
    }
    if e >= 1.0 {
        return (f64::INFINITY, 1.0);
    }
    let p = Elliptic::new(e * e, ((1.0 - e) * (1.0 + e)).sqrt());
    (p.k, p.ee)
}

/// The functions `(B(e), D(e))` of (3.20), without cancellation also for e → 0 (both → π/4).
/// `|e| ≥ 1` gives `(1, ∞)`.
pub fn mindlin_b_d(e: f64) -> (f64, f64) {
    let e = e.abs();
    if e.is_nan() {
        return (f64::NAN, f64::NAN);
    }
    if e >= 1.0 {
        return (1.0, f64::INFINITY);
    }
    let p = Elliptic::new(e * e, ((1.0 - e) * (1.0 + e)).sqrt());
    (p.b, p.d)
}

/// The corrected (3.17) forward: B/A as a function of κ = a/b ≥ 1 (erratum W3). Evaluated as
/// κ² B(e)/D(e), an identity of (κ²E − K)/(K − E) that stays well conditioned at κ → 1.
/// `κ < 1` is read as 1/κ (the same ellipse turned by 90°).
pub fn ratio_from_kappa(kappa: f64) -> f64 {
    let s = kappa.ln().abs();
    let p = Elliptic::from_log_kappa(s);
    (2.0 * s + p.ln_b_over_d()).exp()
}

/// κ = a/b ≥ 1 of the contact ellipse from the ratio B/A of the relative curvatures: the root of
/// the corrected (3.17) (erratum W3), e = √(1 − 1/κ²).
///
/// *Not in thesis*: solved by a bracketed Newton iteration in ln κ on ln(B/A) with the AGM-based
/// K, E, to ≈ 1e-15 relative (the thesis uses the approximation of Antoine et al., 5.86e-6).
/// `B/A = 1` gives κ = 1 exactly. Guards (*not in thesis*): a ratio in (0, 1) is read as its
/// inverse (the same ellipse turned by 90°); ratios above [`MAX_CURVATURE_RATIO`], +∞ and
/// ratios ≤ 0 (a flat or concave direction) are clamped to it; NaN gives NaN.
pub fn kappa_from_ratio(b_over_a: f64) -> f64 {
    if b_over_a.is_nan() {
        return f64::NAN;
    }
    solve_kappa(clamp_ratio(b_over_a)).0.exp()
}

/// Shape and size of a Hertzian elliptic contact for given relative curvatures; constant while
/// the contact points and the relative orientation of the bodies are constant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HertzEllipse {
    /// κ = a/b ≥ 1, ratio of the semi-axes, root of (3.17).
    pub kappa: f64,
    /// Eccentricity e = √(1 − 1/κ²).
    pub e: f64,
    /// K(e), complete elliptic integral of the first kind.
    pub k: f64,
    /// E(e), complete elliptic integral of the second kind.
    pub ee: f64,
    /// B(e) of (3.20).
    pub b_e: f64,
    /// D(e) of (3.20).
    pub d_e: f64,
    /// γ of (3.19): f_N,el = γ E* δ^{3/2} (unit m^{1/2}).
    pub gamma: f64,
    /// √(D(e)/(A K(e))) of (3.21): the major semi-axis is a = `axis_coef` √δ.
    pub axis_coef: f64,
    /// A + B of (3.15) as given.
    pub sum_ab: f64,
    /// The smaller relative curvature A used (after the ratio guard: (A+B)/(1 + B/A)).
    pub curv_a: f64,
    /// The larger relative curvature B used (after the ratio guard).
    pub curv_b: f64,
}

/// The Hertzian ellipse for relative principal curvatures `a_curv`, `b_curv` (order free; the
/// smaller is A), see (3.15)–(3.21) with errata W3, W4.
///
/// Returns `None` unless both are finite and A + B > 0 (*not in thesis*). B/A is clamped to
/// [`MAX_CURVATURE_RATIO`] (also for A ≤ 0), keeping A + B (*not in thesis*); no NaN and no
/// infinity result for valid input. Sphere pair: A = B = 1/(2R*) gives κ = 1, γ = (4/3)√R*.
pub fn hertz_ellipse(a_curv: f64, b_curv: f64) -> Option<HertzEllipse> {
    let sum = a_curv + b_curv;
    if !(a_curv.is_finite() && b_curv.is_finite() && sum > 0.0 && sum.is_finite()) {
        return None;
    }
    let (lo, hi) = if a_curv <= b_curv {
        (a_curv, b_curv)
    } else {
        (b_curv, a_curv)
    };
    let ratio = if lo > 0.0 {
        (hi / lo).min(MAX_CURVATURE_RATIO)
    } else {
        MAX_CURVATURE_RATIO
    };
    let (_, p) = fitted_kappa(ratio);
    let root_sum = sum.sqrt();
    // (3.19) with E(e), K(e) (W4): γ = (2/3) π κ √(E/(K³ (A+B)))
    let kappa = p.kappa;
    let gamma = 2.0 / 3.0 * PI * kappa * (p.ee / (p.k * p.k * p.k)).sqrt() / root_sum;
    // (3.21) with A = (A+B)/(1 + B/A), written to stay finite for tiny A + B
    let axis_coef = (p.d * (1.0 + ratio) / p.k).sqrt() / root_sum;
    let curv_a = sum / (1.0 + ratio);
    Some(HertzEllipse {
        kappa,
        e: p.m.sqrt(),
        k: p.k,
        ee: p.ee,
        b_e: p.b,
        d_e: p.d,
        gamma,
        axis_coef,
        sum_ab: sum,
        curv_a,
        curv_b: sum - curv_a,
    })
}

impl HertzEllipse {
    /// Major semi-axis a = √(δ D(e)/(A K(e))) (3.21), along e_x; δ < 0 counts as 0.
    #[inline]
    pub fn major_semi_axis(&self, delta: f64) -> f64 {
        self.axis_coef * delta.max(0.0).sqrt()
    }

    /// Semi-axes (a, b = a/κ) of the contact ellipse at overlap δ (3.21).
    #[inline]
    pub fn semi_axes(&self, delta: f64) -> (f64, f64) {
        let a = self.major_semi_axis(delta);
        (a, a / self.kappa)
    }

    /// Elastic normal force f_N,el = γ E* δ^{3/2} (3.19); δ < 0 counts as 0.
    #[inline]
    pub fn elastic_normal_force(&self, e_star: f64, delta: f64) -> f64 {
        let d = delta.max(0.0);
        self.gamma * e_star * d * d.sqrt()
    }

    /// Normal contact stiffness c^N = ∂f_N,el/∂δ = (3/2) γ E* √δ (3.28); δ < 0 counts as 0.
    /// (Equals π a E*/K(e), *derived*.)
    #[inline]
    pub fn normal_stiffness(&self, e_star: f64, delta: f64) -> f64 {
        1.5 * self.gamma * e_star * delta.max(0.0).sqrt()
    }

    /// Mindlin's no-slip compliances (C_x, C_y) along the major and minor semi-axes at overlap
    /// δ (3.23): C_x = (K λ1 − B(e) λ2)/(π a), C_y = (K λ1 − D(e) λ2)/(π a). Infinite at δ = 0.
    pub fn tangential_compliances(&self, lambda: &MindlinConstants, delta: f64) -> (f64, f64) {
        let pa = PI * self.major_semi_axis(delta);
        (
            (self.k * lambda.lambda1 - self.b_e * lambda.lambda2) / pa,
            (self.k * lambda.lambda1 - self.d_e * lambda.lambda2) / pa,
        )
    }

    /// The stiffnesses (1/C_x, 1/C_y) of (3.23)–(3.24) at overlap δ, zero at δ ≤ 0 (no
    /// division by a vanishing semi-axis).
    #[inline]
    pub fn tangential_stiffnesses(&self, lambda: &MindlinConstants, delta: f64) -> (f64, f64) {
        let pa = PI * self.major_semi_axis(delta);
        (
            pa / (self.k * lambda.lambda1 - self.b_e * lambda.lambda2),
            pa / (self.k * lambda.lambda1 - self.d_e * lambda.lambda2),
        )
    }
}

/// Effective modulus E* of (3.18): 1/E* = (1 − ν1²)/E1 + (1 − ν2²)/E2.
#[inline]
pub fn effective_modulus(e1: f64, nu1: f64, e2: f64, nu2: f64) -> f64 {
    1.0 / ((1.0 - nu1 * nu1) / e1 + (1.0 - nu2 * nu2) / e2)
}

/// Mindlin's material constants λ1, λ2 of (3.22).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MindlinConstants {
    /// λ1 = (1+ν1)/E1 + (1+ν2)/E2.
    pub lambda1: f64,
    /// λ2 = ν1(1+ν1)/E1 + ν2(1+ν2)/E2.
    pub lambda2: f64,
}

impl MindlinConstants {
    /// λ1, λ2 of (3.22) from Young's moduli and Poisson's ratios of both bodies.
    pub fn new(e1: f64, nu1: f64, e2: f64, nu2: f64) -> Self {
        let (w1, w2) = ((1.0 + nu1) / e1, (1.0 + nu2) / e2);
        MindlinConstants {
            lambda1: w1 + w2,
            lambda2: nu1 * w1 + nu2 * w2,
        }
    }
}

/// Relative curvatures and ellipse axes in the tangent plane of the contact.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RelativeCurvature {
    /// Smaller relative curvature A.
    pub a: f64,
    /// Larger relative curvature B.
    pub b: f64,
    /// Unit eigenvector of A: direction of the major semi-axis a (e_x of (3.24)).
    pub e_x: [f64; 2],
    /// Unit eigenvector of B: direction of the minor semi-axis (e_y of (3.24)); e_y is e_x
    /// turned by +90° in the given basis.
    pub e_y: [f64; 2],
}

/// Relative principal curvatures A ≤ B and their directions from the 2×2 curvature tensors of
/// both surfaces at the contact points, both expressed in ONE orthonormal basis of the tangent
/// plane (each surface's curvature positive where it is convex; a plane is the zero tensor).
///
/// *Not in thesis* (SEED-SPEC §1.7): A, B are the eigenvalues of S = ½(K1 + K2), equivalent to
/// (3.15)–(3.16), which also gives the ellipse axes e_x (of A, major semi-axis) and e_y (of B)
/// needed in (3.24). The off-diagonal entry is symmetrised. Isotropic S (A = B exactly): e_x,
/// e_y are the basis vectors (1, 0), (0, 1).
pub fn relative_curvature(k1: [[f64; 2]; 2], k2: [[f64; 2]; 2]) -> RelativeCurvature {
    let p = 0.5 * (k1[0][0] + k2[0][0]);
    let r = 0.5 * (k1[1][1] + k2[1][1]);
    let q = 0.25 * (k1[0][1] + k1[1][0] + k2[0][1] + k2[1][0]);
    let mean = 0.5 * (p + r);
    let u = 0.5 * (p - r);
    let h = hypot_fast(u, q);
    if h == 0.0 {
        return RelativeCurvature {
            a: mean,
            b: mean,
            e_x: [1.0, 0.0],
            e_y: [0.0, 1.0],
        };
    }
    // eigenvector of the larger eigenvalue: (u + h, q) or (q, h − u), whichever has no
    // cancellation (both ∝ (cos θ, sin θ), tan 2θ = q/u)
    let (vx, vy) = if u >= 0.0 { (u + h, q) } else { (q, h - u) };
    let len = hypot_fast(vx, vy);
    let e_y = [vx / len, vy / len];
    RelativeCurvature {
        a: mean - h,
        b: mean + h,
        e_x: [e_y[1], -e_y[0]],
        e_y,
    }
}

/// The vector of tangent-plane coordinates `v` in 3-D: `t1 v[0] + t2 v[1]` (the basis in which
/// the curvature tensors of [`relative_curvature`] were given).
#[inline]
pub fn lift(t1: &V3, t2: &V3, v: [f64; 2]) -> V3 {
    t1 * v[0] + t2 * v[1]
}

/// Tangential stiffness tensor K^T = e_x⊗e_x/C_x + e_y⊗e_y/C_y of (3.24), kept as its axes and
/// stiffnesses (applying it costs two dot products).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TangentialStiffness {
    /// Unit direction of the major semi-axis.
    pub e_x: V3,
    /// Unit direction of the minor semi-axis.
    pub e_y: V3,
    /// 1/C_x.
    pub k_x: f64,
    /// 1/C_y.
    pub k_y: f64,
}

impl TangentialStiffness {
    /// K^T of (3.24) at overlap δ: stiffnesses from (3.21)–(3.23), `e_x`, `e_y` the 3-D unit
    /// directions of the ellipse's axes (e.g. [`lift`] of [`RelativeCurvature::e_x`], `e_y`).
    pub fn new(
        ell: &HertzEllipse,
        lambda: &MindlinConstants,
        delta: f64,
        e_x: V3,
        e_y: V3,
    ) -> Self {
        let (k_x, k_y) = ell.tangential_stiffnesses(lambda, delta);
        TangentialStiffness { e_x, e_y, k_x, k_y }
    }

    /// K^T v.
    #[inline]
    pub fn apply(&self, v: &V3) -> V3 {
        self.e_x * (self.k_x * self.e_x.dot(v)) + self.e_y * (self.k_y * self.e_y.dot(v))
    }

    /// K^T as a 3×3 matrix (3.24).
    pub fn matrix(&self) -> Matrix3<f64> {
        self.e_x * self.e_x.transpose() * self.k_x + self.e_y * self.e_y.transpose() * self.k_y
    }
}

/// Result of the tangential update (3.25)–(3.26).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TangentialForce {
    /// f^{T,n}, tangential force on body 1 (3.13).
    pub force: V3,
    /// The Coulomb cap was active (sliding).
    pub sliding: bool,
}

/// Incremental tangential force with Coulomb cap, (3.25)–(3.26):
/// f^{T,tr} = f^{T,n−1} + K^T Δt ḋ, capped at μ|f^N|.
///
/// `f_old` is f^{T,n−1}; it is first turned into the current tangent plane (normal `n`, unit)
/// keeping its length (*not in thesis*, standard). `d_dot` is the relative velocity of the
/// contact points, body 2's minus body 1's, so that f^T, the force on body 1 of (3.13), drags
/// body 1 along with body 2; only its tangential part is used. `f_n` is the normal force f^N.
/// Never NaN for finite input (a zero cap gives a zero force).
#[inline]
pub fn tangential_force(
    f_old: &V3,
    n: &V3,
    stiffness: &TangentialStiffness,
    d_dot: &V3,
    dt: f64,
    mu: f64,
    f_n: f64,
) -> TangentialForce {
    let old_len2 = f_old.norm_squared();
    let mut trial = V3::zeros();
    if old_len2 > 0.0 {
        let rotated = f_old - n * f_old.dot(n);
        let new_len2 = rotated.norm_squared();
        if new_len2 > 0.0 {
            trial = rotated * (old_len2 / new_len2).sqrt();
        }
    }
    let v_t = d_dot - n * d_dot.dot(n);
    trial += stiffness.apply(&v_t) * dt;
    let cap = mu * f_n.abs();
    let len2 = trial.norm_squared();
    if len2 > cap * cap {
        TangentialForce {
            force: trial * (cap / len2.sqrt()),
            sliding: true,
        }
    } else {
        TangentialForce {
            force: trial,
            sliding: false,
        }
    }
}

/// Critical damping constant d = 2√(c^N m1 m2/(m1 + m2)) (3.29); the reduced mass is formed as
/// 1/(1/m1 + 1/m2) so that an infinite mass (a wall) gives m1 (*not in thesis*).
#[inline]
pub fn critical_damping(c_n: f64, m1: f64, m2: f64) -> f64 {
    2.0 * (c_n / (1.0 / m1 + 1.0 / m2)).sqrt()
}

/// Quasi-static dissipative normal force f_N,dis = ζ d δ̇ (3.27), d of (3.29), c^N of (3.28);
/// ζ = 1 is critical (W uses 0.9). δ̇ > 0 while the overlap grows.
#[inline]
pub fn quasi_static_damping_force(
    ell: &HertzEllipse,
    e_star: f64,
    delta: f64,
    delta_dot: f64,
    zeta: f64,
    m1: f64,
    m2: f64,
) -> f64 {
    zeta * critical_damping(ell.normal_stiffness(e_star, delta), m1, m2) * delta_dot
}

/// Viscoelastic (Brilliantov) dissipative normal force f_N,dis = γ E* (3/2) A √δ δ̇ (3.30),
/// `a_visc` = A [s]; δ < 0 counts as 0.
#[inline]
pub fn viscoelastic_damping_force(
    ell: &HertzEllipse,
    e_star: f64,
    a_visc: f64,
    delta: f64,
    delta_dot: f64,
) -> f64 {
    ell.normal_stiffness(e_star, delta) * a_visc * delta_dot
}

/// Total normal force without attraction, f^N = max(f_N,el + f_N,dis, 0) (3.31).
#[inline]
pub fn normal_force(f_el: f64, f_dis: f64) -> f64 {
    (f_el + f_dis).max(0.0)
}

// ---------------------------------------------------------------------------------------------
// internals

/// Clamps a curvature ratio into [1, MAX_CURVATURE_RATIO] (see [`kappa_from_ratio`]).
fn clamp_ratio(r: f64) -> f64 {
    if r >= 1.0 {
        r.min(MAX_CURVATURE_RATIO)
    } else if r > 0.0 {
        (1.0 / r).min(MAX_CURVATURE_RATIO)
    } else {
        MAX_CURVATURE_RATIO
    }
}

/// K, E, B, D at one eccentricity, from the AGM, and Q used by the κ solver.
#[derive(Debug, Clone, Copy)]
struct Elliptic {
    /// m = e².
    m: f64,
    /// k' = √(1 − m) = 1/κ.
    kp: f64,
    k: f64,
    ee: f64,
    b: f64,
    d: f64,
    /// Q = Σ_{n≥1} 2^{n−1} (c_n/m)² of the AGM (K − E = K m (½ + m Q)); 1/16 at m = 0.
    q: f64,
}

impl Elliptic {
    /// From m = e² and k' = √(1 − m), both given accurately by the caller.
    ///
    /// AGM a_0 = 1, g_0 = k', c_0 = e: K = π/(2 a_N), K − E = K Σ_{n≥0} 2^{n−1} c_n². The c_n
    /// are formed as c_{n+1} = c_n²/(4 a_{n+1}) (no difference a_n − g_n), and the sum is
    /// carried divided by m, so D = (K − E)/m = K(½ + m Q) has no cancellation at m → 0.
    #[inline]
    fn new(m: f64, kp: f64) -> Self {
        let mut a = 0.5 * (1.0 + kp);
        let mut g = kp.sqrt();
        let mut q = 0.5 / (1.0 + kp); // q_1 = c_1/m, c_1 = (1 − k')/2 = m/(2(1 + k'))
        let mut c = m * q;
        let mut weight = 1.0; // 2^{n−1}
        let mut sum = q * q;
        // ≈ log2(ln(4/k')) + 4 rounds: 4 at k' = 0.5, 7 at k' = 3e-6 (B/A = 1e10), 12 at 1e-200
        for _ in 0..64 {
            if c <= f64::EPSILON * a {
                break;
            }
            let a_next = 0.5 * (a + g);
            g = (a * g).sqrt();
            a = a_next;
            let f = c / (4.0 * a);
            q *= f;
            c *= f;
            weight *= 2.0;
            sum += weight * q * q;
        }
        let k = FRAC_PI_2 / a;
        let t = m * sum;
        let d = k * (0.5 + t);
        let ee = k - m * d;
        // B = K − D = K(½ − T) cancels as m → 1; there (E − k'²K)/m does not
        let b = if m <= 0.5 {
            k * (0.5 - t)
        } else {
            (ee - kp * kp * k) / m
        };
        Elliptic {
            m,
            kp,
            k,
            ee,
            b,
            d,
            q: sum,
        }
    }

    /// At s = ln κ ≥ 0: k' = e^{−s}, m = −expm1(−2s) (accurate also for κ → 1).
    #[inline]
    fn from_log_kappa(s: f64) -> Self {
        Elliptic::new(-(-2.0 * s).exp_m1(), (-s).exp())
    }

    /// ln(B(e)/D(e)) ≤ 0; for m ≤ ½ as ln((1 − 2T)/(1 + 2T)), T = mQ, accurate as m → 0.
    #[inline]
    fn ln_b_over_d(&self) -> f64 {
        if self.m <= 0.5 {
            let t2 = 2.0 * self.m * self.q;
            (-t2).ln_1p() - t2.ln_1p()
        } else {
            (self.b / self.d).ln()
        }
    }

    /// d ln(B/A)/d ln κ of (3.17), from dK/dm = B/(2k'²), dE/dm = −D/2 (*derived*):
    /// 2 + 2k'²(K Q/B − D'/D); 3/2 at κ = 1, → 2 as κ → ∞.
    #[inline]
    fn slope(&self) -> f64 {
        let kp2 = self.kp * self.kp;
        // 2k'² D'/D: D' = (D − 2KQ)/(2k'²) = (B − k'²D)/(2mk'²), the form without cancellation
        let dd = if self.m <= 0.5 {
            (self.d - 2.0 * self.k * self.q) / self.d
        } else {
            (self.b - kp2 * self.d) / (self.m * self.d)
        };
        2.0 + 2.0 * kp2 * self.k * self.q / self.b - dd
    }
}

/// Solves the corrected (3.17) for s = ln κ at ratio r ∈ [1, MAX_CURVATURE_RATIO]; returns s and
/// K, E, B, D at exactly that s.
///
/// f(s) = ln(κ² B(e)/D(e)) − ln r is increasing with slope in [3/2, 2), so the root lies in
/// [ln r/2, ln r/1.5]; Newton from a fitted start, bisection when a step leaves the bracket.
fn solve_kappa(r: f64) -> (f64, Elliptic) {
    let target = (r - 1.0).ln_1p();
    if target <= 0.0 {
        return (0.0, Elliptic::new(0.0, 1.0));
    }
    let mut lo = 0.5 * target;
    let mut hi = target / 1.45;
    // start: ln r/ln κ ≈ 3/2 + L²/(2(L² + 14L + 35.5)), L = ln r (fitted, within 0.005)
    let mut s = target / (1.5 + 0.5 * target * target / (target * (target + 14.0) + 35.5));
    for _ in 0..60 {
        let p = Elliptic::from_log_kappa(s);
        let f = 2.0 * s + p.ln_b_over_d() - target;
        if f == 0.0 {
            return (s, p);
        }
        if f < 0.0 {
            lo = lo.max(s);
        } else {
            hi = hi.min(s);
        }
        let step = f / p.slope();
        // converged to rounding: s is the root
        if step.abs() <= 4.0 * f64::EPSILON * s {
            return (s, p);
        }
        let next = s - step;
        let inside = next > lo && next < hi;
        // quadratic convergence: after a step this small the next iterate is exact to rounding
        if inside && step.abs() <= 1e-8 * s {
            return (next, Elliptic::from_log_kappa(next));
        }
        s = if inside { next } else { 0.5 * (lo + hi) };
    }
    (s, Elliptic::from_log_kappa(s))
}

/// Breaks of the pieces of [`KappaFit`] in L = ln(B/A) (the last is ln [`MAX_CURVATURE_RATIO`]
/// with a margin).
const FIT_BREAKS: [f64; 20] = [
    0.0, 0.1, 0.25, 0.45, 0.7, 1.0, 1.4, 1.9, 2.5, 3.2, 4.0, 5.0, 6.2, 7.6, 9.2, 11.0, 13.2, 15.8,
    18.8, 23.1,
];
/// Chebyshev terms per piece.
const FIT_TERMS: usize = 10;

/// ln κ, B(e) and D(e) as functions of L = ln(B/A), fitted once (*not in thesis*): on each
/// piece of [`FIT_BREAKS`] Chebyshev series of ln κ / L (smooth, from 2/3 at L → 0 to ½ at
/// L → ∞), B and D interpolating the Newton solution [`solve_kappa`] at the Chebyshev nodes.
/// The contact law evaluates them instead of iterating: no AGM (K = B + D and E = B + k'² D,
/// identities of (3.20)); the test bounds the relative error of κ at 1e-14 × max(1, ln κ) and
/// of B, D, K, E at 3e-14 (the bodies' curvatures are not known to that).
struct KappaFit {
    /// Per piece, the series of ln κ / L, B and D.
    coef: [[[f64; FIT_TERMS]; 3]; FIT_BREAKS.len() - 1],
}

impl KappaFit {
    fn new() -> KappaFit {
        let n = FIT_TERMS;
        let mut coef = [[[0.0; FIT_TERMS]; 3]; FIT_BREAKS.len() - 1];
        for (piece, c) in coef.iter_mut().enumerate() {
            let (lo, hi) = (FIT_BREAKS[piece], FIT_BREAKS[piece + 1]);
            // values at the Chebyshev nodes x_k = cos(π(k + ½)/n), then the discrete
            // cosine transform
            let values: Vec<[f64; 3]> = (0..n)
                .map(|k| {
                    let x = (PI * (k as f64 + 0.5) / n as f64).cos();
                    let l = 0.5 * (lo + hi) + 0.5 * (hi - lo) * x;
                    let (s, p) = solve_kappa(l.exp());
                    [s / l, p.b, p.d]
                })
                .collect();
            for (f, cf) in c.iter_mut().enumerate() {
                for (j, cj) in cf.iter_mut().enumerate() {
                    let sum: f64 = (0..n)
                        .map(|k| values[k][f] * (PI * j as f64 * (k as f64 + 0.5) / n as f64).cos())
                        .sum();
                    *cj = 2.0 / n as f64 * sum;
                }
                cf[0] *= 0.5;
            }
        }
        KappaFit { coef }
    }

    /// (ln κ, B, D) at L = ln(B/A) ∈ (0, ln MAX_CURVATURE_RATIO].
    #[inline]
    fn eval(&self, l: f64) -> (f64, f64, f64) {
        let piece = FIT_BREAKS[1..FIT_BREAKS.len() - 1].partition_point(|&b| b <= l);
        let (lo, hi) = (FIT_BREAKS[piece], FIT_BREAKS[piece + 1]);
        let x = (2.0 * l - lo - hi) / (hi - lo);
        // Clenshaw, the three series side by side
        let c = &self.coef[piece];
        let (mut b1, mut b2) = ([0.0; 3], [0.0; 3]);
        for j in (1..FIT_TERMS).rev() {
            for f in 0..3 {
                let b0 = 2.0 * x * b1[f] - b2[f] + c[f][j];
                b2[f] = b1[f];
                b1[f] = b0;
            }
        }
        let v: [f64; 3] = std::array::from_fn(|f| x * b1[f] - b2[f] + c[f][0]);
        (l * v[0], v[1], v[2])
    }
}

/// What the law needs of the ellipse at ratio r: κ, m = e², K, E, B, D.
#[derive(Debug, Clone, Copy)]
struct Fitted {
    kappa: f64,
    m: f64,
    k: f64,
    ee: f64,
    b: f64,
    d: f64,
}

/// [`solve_kappa`] by the fit: s = ln κ at ratio r and m, K, E, B, D there.
#[inline]
fn fitted_kappa(r: f64) -> (f64, Fitted) {
    static FIT: std::sync::OnceLock<KappaFit> = std::sync::OnceLock::new();
    let target = (r - 1.0).ln_1p();
    if target <= 0.0 {
        // a circle: K = E = π/2, B = D = π/4 exactly
        return (
            0.0,
            Fitted {
                kappa: 1.0,
                m: 0.0,
                k: FRAC_PI_2,
                ee: FRAC_PI_2,
                b: 0.5 * FRAC_PI_2,
                d: 0.5 * FRAC_PI_2,
            },
        );
    }
    let (s, b, d) = FIT.get_or_init(KappaFit::new).eval(target);
    // one transcendental either way, each accurate where it is used: near κ = 1,
    // k' = e^{−s} = 1 + x and m = 1 − k'² = −x(2 + x) from x = expm1(−s); for long ellipses
    // κ = e^s (1/(1 + x) would lose the digits of a small k')
    let (kappa, kp, m) = if s < 0.5 {
        let x = (-s).exp_m1();
        (1.0 / (1.0 + x), 1.0 + x, -x * (2.0 + x))
    } else {
        let kappa = s.exp();
        let kp = 1.0 / kappa;
        (kappa, kp, 1.0 - kp * kp)
    };
    let kp2 = kp * kp;
    (
        s,
        Fitted {
            kappa,
            m,
            k: b + d,
            ee: b + kp2 * d,
            b,
            d,
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::generate::SplitMix64;

    #[test]
    fn the_kappa_fit_matches_the_newton_root() {
        let mut rng = SplitMix64::new(7);
        let mut worst: f64 = 0.0;
        let mut at = 0.0;
        let mut worst_integrals = (0.0f64, "", 0.0);
        for k in 0..200_000 {
            // uniform in ln r, plus the region near r = 1
            let l = if k % 4 == 0 {
                1e-6 * 10f64.powf(6.0 * rng.uniform())
            } else {
                MAX_CURVATURE_RATIO.ln() * rng.uniform()
            };
            let r = l.exp();
            let (exact, p) = solve_kappa(r);
            let (fit, q) = fitted_kappa(r);
            // |Δ ln κ| is the relative error of κ; ln κ itself is known to a few ulps
            // and of κ itself (formed from s by one exp or expm1), in the same measure
            let e = ((fit - exact).abs() / exact.max(1.0))
                .max(((q.kappa - exact.exp()) / exact.exp()).abs() / exact.max(1.0));
            if e > worst {
                worst = e;
                at = l;
            }
            for (name, x, y) in [
                ("B", q.b, p.b),
                ("D", q.d, p.d),
                ("K", q.k, p.k),
                ("E", q.ee, p.ee),
            ] {
                let e = ((x - y) / y).abs();
                if e > worst_integrals.0 {
                    worst_integrals = (e, name, l);
                }
            }
        }
        println!("worst |Δ ln κ|, |Δκ/κ| / max(1, ln κ): {worst:.2e} at ln(B/A) = {at}");
        println!(
            "worst relative error of B, D, K, E: {:.2e} ({} at ln(B/A) = {})",
            worst_integrals.0, worst_integrals.1, worst_integrals.2
        );
        assert!(worst < 1e-14, "{worst:e} at ln(B/A) = {at}");
        // B, D, K, E at large κ: the reference's own ln κ (a few ulps of s ≈ 11) moves them
        // by ~1e-14, a finer fit does not change it
        assert!(worst_integrals.0 < 3e-14, "{worst_integrals:?}");
    }

    fn rel(x: f64, y: f64) -> f64 {
        ((x - y) / y).abs()
    }

    #[test]
    fn elliptic_integrals_known_values() {
        let (k, e) = complete_elliptic_integrals(0.0);
        assert_eq!((k, e), (FRAC_PI_2, FRAC_PI_2));
        // (e, K, E), mpmath at 40 digits at the exact double e
        #[allow(clippy::excessive_precision)]
        let refs = [
            (
                std::f64::consts::FRAC_1_SQRT_2,
                1.854_074_677_301_371_8,
                1.350_643_881_047_675_5,
            ),
            (1e-5, 1.570_796_326_834_166_5, 1.570_796_326_755_626_7),
            (0.1, 1.574_745_561_517_356, 1.566_861_942_021_668_3),
            (0.3, 1.608_048_619_930_512_8, 1.534_833_464_923_249),
            (0.5, 1.685_750_354_812_596, 1.467_462_209_339_427_2),
            (0.9, 2.280_549_138_422_770_3, 1.171_697_052_781_614_1),
            (0.99, 3.356_600_523_361_192, 1.028_475_809_028_804),
            (0.999999, 7.947_479_773_547_967, 1.000_007_447_477_724_4),
        ];
        let mut worst: f64 = 0.0;
        for (x, kr, er) in refs {
            let (k, e) = complete_elliptic_integrals(x);
            worst = worst.max(rel(k, kr)).max(rel(e, er));
            assert!(rel(k, kr) < 1e-14 && rel(e, er) < 1e-14, "e={x}: {k} {e}");
        }
        println!("elliptic integrals: worst rel. error {worst:.2e}");
        // Legendre's relation E K' + E' K − K K' = π/2 (k' = √(1−k²))
        for x in [0.05, 0.3, 0.6, 0.8, 0.95] {
            let xp = (1.0 - x) * (1.0 + x);
            let (k, e) = complete_elliptic_integrals(x);
            let (kc, ec) = complete_elliptic_integrals(xp.sqrt());
            assert!((e * kc + ec * k - k * kc - FRAC_PI_2).abs() < 1e-14);
        }
    }

    /// SEED-SPEC §1.7 table: B/A, κ, e, K, E, γ√(A+B), a√(A/δ), B(e), D(e).
    const TABLE: [[f64; 9]; 6] = [
        [
            1.5, 1.310103, 0.646046, 1.789765, 1.391138, 1.351621, 0.730504, 0.834683, 0.955083,
        ],
        [
            2.0, 1.585802, 0.776112, 1.952114, 1.297152, 1.386901, 0.746331, 0.864768, 1.087346,
        ],
        [
            5.0, 2.890181, 0.938235, 2.493744, 1.120520, 1.627105, 0.790921, 0.933766, 1.559978,
        ],
        [
            10.0, 4.499447, 0.974990, 2.914203, 1.059884, 1.950147, 0.818149, 0.963531, 1.950671,
        ],
        [
            100.0, 18.187103, 0.998487, 4.289495, 1.005730, 4.299852, 0.876275, 0.995772, 3.293723,
        ],
        [
            1000.0, 67.872475, 0.999891, 5.604175, 1.000554, 10.717785, 0.906444, 0.999554,
            4.604620,
        ],
    ];

    /// The same quantities from mpmath at 40 digits (κ by findroot on the corrected (3.17)).
    #[allow(clippy::excessive_precision)] // mpmath's 17 digits as printed
    const TABLE_HP: [[f64; 9]; 10] = [
        [
            1.5,
            1.310_102_962_112_750_4,
            0.646_045_636_075_197_5,
            1.789_765_095_042_285_8,
            1.391_137_541_920_845_8,
            1.351_621_298_515_782_2,
            0.730_503_738_175_431_6,
            0.834_682_525_152_507_5,
            0.955_082_569_889_778_3,
        ],
        [
            2.0,
            1.585_802_119_702_555,
            0.776_111_500_585_066,
            1.952_113_839_156_846_9,
            1.297_152_156_388_730_9,
            1.386_900_670_669_977_6,
            0.746_330_615_760_754,
            0.864_768_104_259_154,
            1.087_345_734_897_692_9,
        ],
        [
            5.0,
            2.890_181_039_836_407_3,
            0.938_234_849_089_563_3,
            2.493_743_994_668_252,
            1.120_519_724_084_932_4,
            1.627_105_126_268_197_2,
            0.790_921_245_690_149_4,
            0.933_766_436_737_443_6,
            1.559_977_557_930_808_2,
        ],
        [
            10.0,
            4.499_447_303_155_423,
            0.974_989_821_072_416_9,
            2.914_202_688_667_258,
            1.059_884_343_939_357,
            1.950_147_183_575_478,
            0.818_148_594_138_860_8,
            0.963_531_221_763_051_8,
            1.950_671_466_904_206_3,
        ],
        [
            100.0,
            18.187_103_004_388_933,
            0.998_487_234_649_644_6,
            4.289_495_451_406_563,
            1.005_730_020_193_789_8,
            4.299_852_217_519_402,
            0.876_275_038_491_880_5,
            0.995_772_297_221_574_1,
            3.293_723_154_184_989,
        ],
        [
            1000.0,
            67.872_474_777_969_3,
            0.999_891_455_904_146_1,
            5.604_174_814_956_239,
            1.000_554_010_797_12,
            10.717_785_373_379_068,
            0.906_444_206_684_955,
            0.999_554_456_340_779_2,
            4.604_620_358_615_46,
        ],
        [
            1e4,
            242.432_625_692_389_5,
            0.999_991_492_739_699_8,
            6.877_043_199_486_528,
            1.000_054_251_037_491_7,
            28.155_213_846_989_717,
            0.924_443_249_462_473_5,
            0.999_954_255_611_930_6,
            5.877_088_943_874_597,
        ],
        [
            1e6,
            2_890.590_804_634_543,
            0.999_999_940_159_283_7,
            9.355_510_802_002_536,
            1.000_000_529_920_101_4,
            211.565_129_754_584_54,
            0.945_045_595_663_983,
            0.999_999_529_920_571_4,
            8.355_511_272_081_965,
        ],
        [
            1e8,
            32_841.661_939_164_44,
            0.999_999_999_536_425_3,
            11.785_747_533_066_671,
            1.000_000_005_231_787_3,
            1_699.996_552_159_333_7,
            0.956_635_643_759_904_8,
            0.999_999_995_231_787_4,
            10.785_747_537_834_883,
        ],
        [
            1e10,
            363_165.360_545_882_3,
            0.999_999_999_996_208_9,
            14.188_907_909_359_518,
            1.000_000_000_051_895_5,
            14_231.136_247_791_744,
            0.964_117_426_671_962_9,
            0.999_999_999_951_895_5,
            13.188_907_909_407_622,
        ],
    ];

    fn row_of(r: f64) -> [f64; 9] {
        // A = 1, B = r
        let h = hertz_ellipse(1.0, r).unwrap();
        [
            r,
            h.kappa,
            h.e,
            h.k,
            h.ee,
            h.gamma * (1.0 + r).sqrt(),
            h.axis_coef,
            h.b_e,
            h.d_e,
        ]
    }

    #[test]
    fn hertz_kappa_table() {
        let names = [
            "B/A",
            "κ",
            "e",
            "K",
            "E",
            "γ√(A+B)",
            "a√(A/δ)",
            "B(e)",
            "D(e)",
        ];
        let mut worst: f64 = 0.0;
        for t in TABLE {
            let got = row_of(t[0]);
            for j in 1..9 {
                let err = rel(got[j], t[j]);
                worst = worst.max(err);
                assert!(
                    err < 1e-6,
                    "B/A={} {}: {} vs {}",
                    t[0],
                    names[j],
                    got[j],
                    t[j]
                );
            }
        }
        println!("SEED-SPEC table (6 decimals): worst rel. deviation {worst:.2e}");
        let mut worst: f64 = 0.0;
        for t in TABLE_HP {
            let got = row_of(t[0]);
            // the Newton root to round-off; the law's fitted κ to 1e-14 × max(1, ln κ) (so
            // the values derived from it to 1e-13)
            assert!(rel(kappa_from_ratio(t[0]), t[1]) < 2e-14, "B/A = {}", t[0]);
            for j in 1..9 {
                let err = rel(got[j], t[j]);
                worst = worst.max(err);
                assert!(
                    err < 1e-13,
                    "B/A={} {}: {} vs {}",
                    t[0],
                    names[j],
                    got[j],
                    t[j]
                );
            }
        }
        println!("mpmath table up to B/A = 1e10: worst rel. error {worst:.2e}");
        // B/A = 1: the sphere row, exactly
        let one = row_of(1.0);
        assert_eq!(one[1], 1.0);
        assert_eq!(one[2], 0.0);
        assert_eq!((one[3], one[4]), (FRAC_PI_2, FRAC_PI_2));
        assert!((one[5] - 4.0 / 3.0).abs() < 1e-15);
        assert!((one[6] - std::f64::consts::FRAC_1_SQRT_2).abs() < 1e-15);
        assert!((one[7] - PI / 4.0).abs() < 1e-15 && (one[8] - PI / 4.0).abs() < 1e-15);
        // the identity γ = (2/3)π √(D/(A K³)) of SEED-SPEC §1.7
        for t in TABLE_HP {
            let h = hertz_ellipse(1.0, t[0]).unwrap();
            let g = 2.0 / 3.0 * PI * (h.d_e / (h.curv_a * h.k.powi(3))).sqrt();
            // (an identity at the root of (3.17): to the fitted κ's 1e-14 × ln κ)
            assert!(rel(g, h.gamma) < 1e-13);
        }
    }

    #[test]
    fn kappa_round_trip() {
        let mut rng = SplitMix64::new(7);
        let mut worst: f64 = 0.0;
        for i in 0..20_000 {
            // half uniform in [1, 1e4], half log-uniform (many near 1)
            let kappa = if i % 2 == 0 {
                1.0 + (1e4 - 1.0) * rng.uniform()
            } else {
                (rng.uniform() * 1e4f64.ln()).exp()
            };
            let back = kappa_from_ratio(ratio_from_kappa(kappa));
            worst = worst.max(rel(back, kappa));
        }
        println!("round trip κ → B/A → κ, κ in [1, 1e4]: worst rel. error {worst:.2e}");
        assert!(worst < 1e-10);
        // forward: mpmath values of the corrected (3.17) (κ²E − K)/(K − E) at 40 digits
        for (kappa, r) in [
            (1.2, 1.314_658_367_684_155_7),
            (2.0, 2.842_753_308_670_996),
            (7.0, 20.335_828_680_747_207),
            (50.0, 581.020_054_348_079_5),
            (1e3, 137_097.488_581_680_75),
        ] {
            let err = rel(ratio_from_kappa(kappa), r);
            assert!(
                err < 1e-14,
                "κ={kappa}: {} vs {r} ({err:.1e})",
                ratio_from_kappa(kappa)
            );
            // the literal form through e = √(1 − 1/κ²) agrees as far as its conditioning allows
            // (1 − e² loses digits as κ grows: 4e-12 at κ = 1000)
            let e = (1.0 - 1.0 / (kappa * kappa)).sqrt();
            let (k, ee) = complete_elliptic_integrals(e);
            let lit = (kappa * kappa * ee - k) / (k - ee);
            assert!(rel(lit, r) < 1e-15 * kappa * kappa);
        }
        // guards: inverse ratio, flat direction, clamp, never NaN
        assert_eq!(kappa_from_ratio(1.0), 1.0);
        assert!(rel(kappa_from_ratio(0.1), kappa_from_ratio(10.0)) < 1e-15);
        let kmax = kappa_from_ratio(MAX_CURVATURE_RATIO);
        for r in [0.0, -3.0, f64::INFINITY, 1e300] {
            assert_eq!(kappa_from_ratio(r), kmax);
        }
        assert!(kappa_from_ratio(f64::NAN).is_nan());
        assert!(rel(ratio_from_kappa(kmax), MAX_CURVATURE_RATIO) < 1e-13);
    }

    #[test]
    fn hertz_reduces_to_sphere_and_is_continuous() {
        for r_star in [1e-4, 0.3, 1.0, 7.5] {
            let c = 0.5 / r_star;
            let h = hertz_ellipse(c, c).unwrap();
            assert_eq!(h.kappa, 1.0);
            assert!(rel(h.gamma, 4.0 / 3.0 * r_star.sqrt()) < 1e-12);
            // a = √(R* δ), f = (4/3) E* √R* δ^{3/2}
            assert!(rel(h.major_semi_axis(1e-6), (r_star * 1e-6).sqrt()) < 1e-12);
        }
        let sphere = hertz_ellipse(1.0, 1.0).unwrap();
        for eps in [1e-12, 1e-8] {
            let h = hertz_ellipse(1.0, 1.0 + eps).unwrap();
            // γ√(A+B) and a√(A/δ) move by O(eps); κ − 1 = (B/A − 1)/1.5 to first order
            let g0 = sphere.gamma * 2f64.sqrt();
            let g1 = h.gamma * (2.0 + eps).sqrt();
            assert!((g1 - g0).abs() < eps, "γ jumps: {g0} {g1}");
            assert!((h.axis_coef - sphere.axis_coef).abs() < eps);
            assert!(
                rel(h.kappa - 1.0, eps / 1.5) < 1e-3,
                "κ−1 = {}",
                h.kappa - 1.0
            );
            assert!((h.b_e - PI / 4.0).abs() < eps && (h.d_e - PI / 4.0).abs() < eps);
            assert!(h.e > 0.0 && h.e < 1e-3);
        }
        // B(e), D(e) near e = 0 have no cancellation: series π/4 (1 + e²/8), π/4 (1 + 3e²/8)
        for e in [1e-9, 1e-6, 1e-3] {
            let (b, d) = mindlin_b_d(e);
            assert!(rel(b, PI / 4.0 * (1.0 + e * e / 8.0)) < 1e-14 + e.powi(4));
            assert!(rel(d, PI / 4.0 * (1.0 + 3.0 * e * e / 8.0)) < 1e-14 + e.powi(4));
        }
    }

    #[test]
    fn hertz_guards() {
        assert!(hertz_ellipse(0.0, 0.0).is_none());
        assert!(hertz_ellipse(-1.0, 1.0).is_none());
        assert!(hertz_ellipse(f64::NAN, 1.0).is_none());
        assert!(hertz_ellipse(1.0, f64::INFINITY).is_none());
        // a flat direction (A = 0), a slightly concave one, swapped order, tiny curvatures
        let flat = hertz_ellipse(0.0, 2.0).unwrap();
        let concave = hertz_ellipse(-0.5, 2.0).unwrap();
        let swapped = hertz_ellipse(2.0, 0.5).unwrap();
        assert_eq!(swapped, hertz_ellipse(0.5, 2.0).unwrap());
        let tiny = hertz_ellipse(1e-320, 1e-310).unwrap();
        let huge = hertz_ellipse(1e300, 1e300).unwrap();
        for h in [flat, concave, swapped, tiny, huge] {
            let v = [
                h.kappa,
                h.e,
                h.k,
                h.ee,
                h.b_e,
                h.d_e,
                h.gamma,
                h.axis_coef,
                h.curv_a,
                h.curv_b,
            ];
            assert!(v.iter().all(|x| x.is_finite()), "{h:?}");
            assert!(h.curv_a > 0.0 && h.curv_a <= h.curv_b);
        }
        assert!(rel(flat.kappa, kappa_from_ratio(MAX_CURVATURE_RATIO)) < 1e-13);
        assert_eq!(flat.sum_ab, 2.0);
        // δ ≤ 0: no force, no stiffness, no NaN
        let lam = MindlinConstants::new(1e9, 0.3, 2e9, 0.25);
        for d in [0.0, -1e-6] {
            assert_eq!(flat.elastic_normal_force(1e9, d), 0.0);
            assert_eq!(flat.normal_stiffness(1e9, d), 0.0);
            assert_eq!(flat.tangential_stiffnesses(&lam, d), (0.0, 0.0));
        }
    }

    #[test]
    fn normal_force_helpers() {
        let e_star = effective_modulus(7e10, 0.22, 2e11, 0.3);
        assert!(rel(1.0 / e_star, (1.0 - 0.0484) / 7e10 + 0.91 / 2e11) < 1e-15);
        for r in [1.0, 3.0, 300.0] {
            let h = hertz_ellipse(50.0, 50.0 * r).unwrap();
            for delta in [1e-7, 1e-5] {
                // c^N = ∂f/∂δ (3.28), by a central difference
                let dd = delta * 1e-4;
                let num = (h.elastic_normal_force(e_star, delta + dd)
                    - h.elastic_normal_force(e_star, delta - dd))
                    / (2.0 * dd);
                let c_n = h.normal_stiffness(e_star, delta);
                assert!(rel(num, c_n) < 1e-7);
                // c^N = π a E*/K(e) (derived)
                assert!(rel(c_n, PI * h.major_semi_axis(delta) * e_star / h.k) < 1e-13);
                // (3.29): an infinite mass gives the other one
                let d = critical_damping(c_n, 2e-3, f64::INFINITY);
                assert!(rel(d, 2.0 * (c_n * 2e-3).sqrt()) < 1e-15);
                let d2 = critical_damping(c_n, 2e-3, 3e-3);
                assert!(rel(d2, 2.0 * (c_n * 6e-6 / 5e-3).sqrt()) < 1e-14);
                let fq = quasi_static_damping_force(&h, e_star, delta, 0.1, 0.9, 2e-3, 3e-3);
                assert!(rel(fq, 0.9 * d2 * 0.1) < 1e-15);
                // (3.30)
                let fv = viscoelastic_damping_force(&h, e_star, 5e-8, delta, 0.2);
                assert!(rel(fv, h.gamma * e_star * 1.5 * 5e-8 * delta.sqrt() * 0.2) < 1e-14);
            }
        }
        // (3.31)
        assert_eq!(normal_force(1.0, -3.0), 0.0);
        assert_eq!(normal_force(1.0, 0.5), 1.5);
    }

    #[test]
    fn mindlin_compliance_limits() {
        let delta = 1e-6;
        // e = 0: C_x = C_y = (λ1 − λ2/2)/(2a)
        let lam = MindlinConstants::new(7e10, 0.22, 2e11, 0.3);
        let s = hertz_ellipse(40.0, 40.0).unwrap();
        let a = s.major_semi_axis(delta);
        let (cx, cy) = s.tangential_compliances(&lam, delta);
        let c0 = (lam.lambda1 - lam.lambda2 / 2.0) / (2.0 * a);
        assert!(rel(cx, c0) < 1e-15 && rel(cy, c0) < 1e-15);
        // identical materials, sphere: C = (2 − ν)/(4 G a); C_x/C_z = (2 − ν)/(2(1 − ν))
        for nu in [0.0, 0.1, 0.25, 0.3, 0.5] {
            let e = 5e9;
            let g = e / (2.0 * (1.0 + nu));
            let lam = MindlinConstants::new(e, nu, e, nu);
            let (cx, cy) = s.tangential_compliances(&lam, delta);
            assert!(rel(cx, (2.0 - nu) / (4.0 * g * a)) < 1e-14);
            assert!(rel(cy, cx) < 1e-15);
            let cz = 1.0 / s.normal_stiffness(effective_modulus(e, nu, e, nu), delta);
            assert!(rel(cx / cz, (2.0 - nu) / (2.0 * (1.0 - nu))) < 1e-14);
        }
        for r in [1.5, 2.0, 5.0, 10.0, 100.0, 1e4, 1e10] {
            let h = hertz_ellipse(1.0, r).unwrap();
            // ν1 = ν2 = 0: isotropic
            let lam0 = MindlinConstants::new(3e9, 0.0, 8e9, 0.0);
            let (cx, cy) = h.tangential_compliances(&lam0, delta);
            assert!(rel(cx, cy) < 1e-15);
            for nu in [0.05, 0.2, 0.3, 0.45, 0.5] {
                let e = 5e9;
                let lam = MindlinConstants::new(e, nu, e, nu);
                let (cx, cy) = h.tangential_compliances(&lam, delta);
                assert!(cx > cy, "B/A={r} ν={nu}");
                // C_z ≤ C_y < C_x ≤ 2 C_z (Mindlin, here for every e, not only spheres)
                let cz = 1.0 / h.normal_stiffness(effective_modulus(e, nu, e, nu), delta);
                assert!(cz <= cy && cx <= 2.0 * cz, "B/A={r} ν={nu}: {}", cx / cz);
                // stiffnesses are the inverse compliances
                let (kx, ky) = h.tangential_stiffnesses(&lam, delta);
                assert!(rel(kx * cx, 1.0) < 1e-15 && rel(ky * cy, 1.0) < 1e-15);
            }
        }
        // SEED-SPEC example: ν1 = ν2 = 0.3, B/A = 10 → C_x/C_y = 1.12715 (mpmath 1.127154107)
        let h = hertz_ellipse(1.0, 10.0).unwrap();
        let lam = MindlinConstants::new(1e9, 0.3, 3e9, 0.3);
        let (cx, cy) = h.tangential_compliances(&lam, delta);
        println!("C_x/C_y (ν = 0.3, B/A = 10) = {:.9}", cx / cy);
        assert!((cx / cy - 1.12715).abs() < 1e-5);
        assert!((cx / cy - 1.127_154_107).abs() < 1e-9);
    }

    fn rand_tensor(rng: &mut SplitMix64, scale: f64) -> [[f64; 2]; 2] {
        let o = scale * rng.normal();
        [[scale * rng.uniform(), o], [o, scale * rng.uniform()]]
    }

    #[test]
    fn relative_curvature_eigen() {
        let mut rng = SplitMix64::new(3);
        for _ in 0..10_000 {
            let scale = 10f64.powf(4.0 * rng.uniform() - 2.0);
            let k1 = rand_tensor(&mut rng, scale);
            let k2 = rand_tensor(&mut rng, scale);
            let rc = relative_curvature(k1, k2);
            assert!(rc.a <= rc.b);
            let (x, y) = (rc.e_x, rc.e_y);
            assert!((x[0] * x[0] + x[1] * x[1] - 1.0).abs() < 1e-15);
            assert!((y[0] * y[0] + y[1] * y[1] - 1.0).abs() < 1e-15);
            assert!((x[0] * y[0] + x[1] * y[1]).abs() < 1e-15);
            // e_y = e_x turned by +90°
            assert_eq!((y[0], y[1]), (-x[1], x[0]));
            // S = A e_x e_xᵀ + B e_y e_yᵀ
            let norm = rc.a.abs().max(rc.b.abs());
            for i in 0..2 {
                for j in 0..2 {
                    let s = 0.5 * (k1[i][j] + k2[i][j]);
                    let rebuilt = rc.a * x[i] * x[j] + rc.b * y[i] * y[j];
                    assert!((s - rebuilt).abs() < 4e-15 * norm, "{s} {rebuilt}");
                }
            }
            // plane (K2 = 0): S = K1/2, the halved principal curvatures of K1, same axes
            let p = relative_curvature(k1, [[0.0; 2]; 2]);
            let full = relative_curvature(k1, k1);
            assert_eq!((p.a, p.b), (0.5 * full.a, 0.5 * full.b));
            assert_eq!((p.e_x, p.e_y), (full.e_x, full.e_y));
        }
        // (3.15)–(3.16) from principal curvatures and the angle α between the ρ^I directions
        for _ in 0..1000 {
            let (r1i, r1ii, r2i, r2ii) =
                (rng.uniform(), rng.uniform(), rng.uniform(), rng.uniform());
            let alpha = PI * rng.uniform();
            let k1 = [[r1i, 0.0], [0.0, r1ii]];
            let (c, s) = (alpha.cos(), alpha.sin());
            // surface 2: ρ^I along (cos α, sin α)
            let k2 = [
                [r2i * c * c + r2ii * s * s, (r2i - r2ii) * c * s],
                [(r2i - r2ii) * c * s, r2i * s * s + r2ii * c * c],
            ];
            let rc = relative_curvature(k1, k2);
            let sum = 0.5 * (r1i + r1ii + r2i + r2ii);
            let (d1, d2) = (r1i - r1ii, r2i - r2ii);
            let diff = 0.5 * (d1 * d1 + d2 * d2 + 2.0 * d1 * d2 * (2.0 * alpha).cos()).sqrt();
            assert!((rc.a + rc.b - sum).abs() < 1e-14);
            assert!((rc.b - rc.a - diff).abs() < 1e-14);
        }
        // isotropic: deterministic basis; a sphere on a plane: A = B = 1/(2R)
        let rc = relative_curvature([[0.5, 0.0], [0.0, 0.5]], [[0.0; 2]; 2]);
        assert_eq!(rc.e_x, [1.0, 0.0]);
        assert_eq!(rc.e_y, [0.0, 1.0]);
        assert_eq!((rc.a, rc.b), (0.25, 0.25));
        // a cylinder along t2 on a plane: major axis along the cylinder
        let rc = relative_curvature([[2.0, 0.0], [0.0, 0.0]], [[0.0; 2]; 2]);
        assert_eq!((rc.a, rc.b), (0.0, 1.0));
        assert!((rc.e_x[0].abs() < 1e-15) && (rc.e_x[1].abs() - 1.0).abs() < 1e-15);
        let t1 = V3::new(0.0, 1.0, 0.0);
        let t2 = V3::new(0.0, 0.0, 1.0);
        assert_eq!(lift(&t1, &t2, [0.5, 2.0]), V3::new(0.0, 0.5, 2.0));
    }

    fn stiffness_for(r: f64, nu: f64, delta: f64) -> TangentialStiffness {
        let h = hertz_ellipse(100.0, 100.0 * r).unwrap();
        let lam = MindlinConstants::new(1e9, nu, 1e9, nu);
        TangentialStiffness::new(&h, &lam, delta, V3::x(), V3::y())
    }

    #[test]
    fn tangential_stick_and_coulomb_cap() {
        let n = V3::new(0.0, 0.0, 1.0);
        let kt = stiffness_for(10.0, 0.3, 1e-6);
        assert!(kt.k_y > kt.k_x);
        // matrix form = apply
        let v = V3::new(0.3, -0.7, 0.2);
        assert!((kt.matrix() * v - kt.apply(&v)).norm() < 1e-15 * kt.k_y);
        // stick: the force grows by K^T Δt ḋ (tangential ḋ), not parallel to ḋ
        let f_old = V3::new(0.01, 0.02, 0.0);
        let d_dot = V3::new(1e-4, 1e-4, 5.0);
        let dt = 1e-6;
        let t = tangential_force(&f_old, &n, &kt, &d_dot, dt, 0.5, 100.0);
        assert!(!t.sliding);
        let inc = t.force - f_old;
        let expect = V3::new(kt.k_x * 1e-4 * dt, kt.k_y * 1e-4 * dt, 0.0);
        assert!((inc - expect).norm() < 1e-12 * expect.norm());
        assert!(inc.normalize().dot(&V3::new(1.0, 1.0, 0.0).normalize()) < 1.0 - 1e-4);
        // the old force is turned into the tangent plane keeping its length
        let tilted = V3::new(3.0, 0.0, 4.0);
        let t = tangential_force(&tilted, &n, &kt, &V3::zeros(), dt, 1.0, 100.0);
        assert!((t.force - V3::new(5.0, 0.0, 0.0)).norm() < 1e-14);
        // along the normal it cannot be turned: dropped
        let t = tangential_force(&(n * 2.0), &n, &kt, &V3::zeros(), dt, 1.0, 100.0);
        assert_eq!(t.force, V3::zeros());
        // random: ‖f^T‖ ≤ μ|f^N| always; the cap keeps the trial direction
        let mut rng = SplitMix64::new(11);
        let mut f = V3::zeros();
        let mut slides = 0;
        for _ in 0..20_000 {
            let nn = V3::new(rng.normal(), rng.normal(), rng.normal()).normalize();
            let mu = rng.uniform();
            let f_n = 10.0 * rng.normal();
            let d_dot = V3::new(rng.normal(), rng.normal(), rng.normal()) * 0.05;
            let kt = stiffness_for(1.0 + 50.0 * rng.uniform(), 0.5 * rng.uniform(), 1e-6);
            let t = tangential_force(&f, &nn, &kt, &d_dot, 1e-5, mu, f_n);
            let cap = mu * f_n.abs();
            assert!(
                t.force.norm() <= cap * (1.0 + 1e-15),
                "{} > {cap}",
                t.force.norm()
            );
            assert!(t.force.iter().all(|x| x.is_finite()));
            slides += t.sliding as u32;
            f = t.force;
        }
        assert!(slides > 100 && slides < 19_900, "{slides}");
        // zero cap: zero force, no NaN
        let t = tangential_force(&V3::zeros(), &n, &kt, &V3::zeros(), dt, 0.0, 0.0);
        assert_eq!(t.force, V3::zeros());
    }
}
