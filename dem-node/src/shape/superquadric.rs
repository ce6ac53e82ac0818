//! Superquadric particles (Wellmann 2011, §3.1 and App. A): shape (3.1), mass and inertia
//! (3.4)–(3.8), bounding radius (A.8)–(A.14), surface point from a normal (A.39)–(A.48) with
//! its Jacobian, and the principal curvatures.
//!
//! Everything is in the particle's principal (body) frame, origin at the centre.
//!
//! **Point from a normal in log space** (*not in thesis*, algebraically the same as
//! (A.44)–(A.48)). The printed formulas multiply ratios like (n2/n1)^(2/(2−ε1)); with the
//! guard |n_i| ≥ 1e-20 of (A.43) and ε near 0.3 or 1.7 these overflow a double. Written for the
//! logarithms u_i = ln n_i they become sums and log-sum-exps, which neither overflow nor lose
//! digits, and their derivatives by u give the Jacobian ∂X/∂n in the same pass: with
//! ℓ_i = ln X_i, ∂X_i/∂n_j = X_i ∂ℓ_i/∂u_j / n_j. This replaces the trigonometric route of
//! (A.25)–(A.34) and the explicit derivatives (A.54)–(A.61); the tests check (A.49)
//! n·∂X/∂n = 0, the symmetry (A.53) and F(X(n)) = 1, ∇F(X(n)) ∥ n in all octants.
//!
//! **Curvatures from the Jacobian** (*not in thesis*, equivalent to (A.15)–(A.24) with the
//! erratum W5 corrected): for a unit normal the map n ↦ X(n) has the inverse shape operator as
//! its derivative on the tangent plane, so the eigenvalues of the 2×2 tangent block of ∂X/∂n
//! are the principal radii of curvature and its eigenvectors the principal directions.

use crate::hertz_mindlin::V3;
use nalgebra::Matrix3;
use serde::{Deserialize, Serialize};

/// Smallest |n_i| used in the point-from-normal map (Wellmann A.43: TOL = 1e-20).
const NORMAL_FLOOR: f64 = 1e-20;

/// Smallest and largest exponent accepted: ε ∈ (0, 2) gives a smooth convex body (W §3.1);
/// the limits 0 (cuboid) and 2 (octahedron) have edges where the normal is undefined.
pub const EXPONENT_MIN: f64 = 0.1;
pub const EXPONENT_MAX: f64 = 1.9;

/// A superquadric (3.1): F(X) = (|X1/r1|^(2/ε1) + |X2/r2|^(2/ε1))^(ε1/ε2) + |X3/r3|^(2/ε2).
/// Half-extents r_i along the body axes E_i; ε1 is the angularity in the X1–X2 plane, ε2
/// towards X3 (ε → 0 cuboid, ε = 1 ellipsoid, ε → 2 octahedron).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(into = "SuperquadricParams", try_from = "SuperquadricParams")]
pub struct Superquadric {
    pub radii: V3,
    pub eps1: f64,
    pub eps2: f64,
    // constants of the point-from-normal map (A.44)–(A.47) in log form
    ln_r: [f64; 3],
    /// ε1/(2 − ε1), ε2/(2 − ε2)
    a1: f64,
    a2: f64,
    /// ln of (r2/r1)^(2/(2−ε1))
    c21: f64,
    /// 2/ε1, 2/ε2, ε1/ε2
    two_e1: f64,
    two_e2: f64,
    e1_e2: f64,
    /// Bounding and inscribed radii (computed once: they take trigonometry).
    bounding: f64,
    inscribed: f64,
}

/// The five parameters of a superquadric as stored (the derived constants are rebuilt).
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct SuperquadricParams {
    pub radii: [f64; 3],
    pub eps1: f64,
    pub eps2: f64,
}

impl From<Superquadric> for SuperquadricParams {
    fn from(s: Superquadric) -> Self {
        SuperquadricParams {
            radii: [s.radii.x, s.radii.y, s.radii.z],
            eps1: s.eps1,
            eps2: s.eps2,
        }
    }
}

impl TryFrom<SuperquadricParams> for Superquadric {
    type Error = String;
    fn try_from(p: SuperquadricParams) -> Result<Self, String> {
        Superquadric::new(V3::from(p.radii), p.eps1, p.eps2).ok_or_else(|| {
            format!(
                "not a convex superquadric: semi-axes {:?}, exponents {} and {}",
                p.radii, p.eps1, p.eps2
            )
        })
    }
}

/// Surface point X(n) of a body-frame normal n and its Jacobian J = ∂X/∂n (symmetric,
/// J n = 0: X is homogeneous of degree 0 in n).
#[derive(Debug, Clone, Copy)]
pub struct SurfacePoint {
    pub x: V3,
    pub jacobian: Matrix3<f64>,
}

#[inline(always)]
fn log_sum_exp(a: f64, b: f64) -> (f64, f64, f64) {
    // returns (ln(e^a + e^b), weight of a, weight of b); the larger term's exponential is 1,
    // so one exp and one ln
    let (m, small) = if a >= b { (a, b) } else { (b, a) };
    let e = (small - m).exp();
    let w_small = e / (1.0 + e);
    let w_large = 1.0 - w_small;
    // ln(1 + e) by ln: its absolute error (~1e-16) is that of m itself, and ln is cheaper
    let l = m + (1.0 + e).ln();
    if a >= b {
        (l, w_large, w_small)
    } else {
        (l, w_small, w_large)
    }
}

/// √(a² + b²) without `hypot`'s guard against overflow (libm's is several times slower); for
/// the curvature and angle values of the contact geometry, far inside ±1e150.
#[inline(always)]
pub fn hypot_fast(a: f64, b: f64) -> f64 {
    (a * a + b * b).sqrt()
}

impl Superquadric {
    /// The shape with half-extents `radii` and exponents ε1, ε2; `None` if a value is not
    /// finite, a radius not positive, or an exponent outside [`EXPONENT_MIN`, `EXPONENT_MAX`].
    pub fn new(radii: V3, eps1: f64, eps2: f64) -> Option<Superquadric> {
        let ok_eps = |e: f64| (EXPONENT_MIN..=EXPONENT_MAX).contains(&e);
        if !(radii.iter().all(|r| r.is_finite() && *r > 0.0) && ok_eps(eps1) && ok_eps(eps2)) {
            return None;
        }
        let ln_r = [radii.x.ln(), radii.y.ln(), radii.z.ln()];
        let (r12_max, _) = extreme_radius_2d(radii.x, radii.y, eps1, true);
        let (r12_min, _) = extreme_radius_2d(radii.x, radii.y, eps1, false);
        Some(Superquadric {
            bounding: extreme_radius_2d(r12_max, radii.z, eps2, true).0,
            inscribed: extreme_radius_2d(r12_min, radii.z, eps2, false).0,
            radii,
            eps1,
            eps2,
            ln_r,
            a1: eps1 / (2.0 - eps1),
            a2: eps2 / (2.0 - eps2),
            c21: 2.0 / (2.0 - eps1) * (ln_r[1] - ln_r[0]),
            two_e1: 2.0 / eps1,
            two_e2: 2.0 / eps2,
            e1_e2: eps1 / eps2,
        })
    }

    /// Inside–outside function (3.1): < 1 inside, 1 on the surface, > 1 outside.
    #[inline]
    pub fn inside_outside(&self, x: &V3) -> f64 {
        let r = &self.radii;
        let a = (x.x / r.x).abs().powf(self.two_e1) + (x.y / r.y).abs().powf(self.two_e1);
        a.powf(self.e1_e2) + (x.z / r.z).abs().powf(self.two_e2)
    }

    /// Gradient of the inside–outside function (A.40) (zero at the centre).
    pub fn gradient(&self, x: &V3) -> V3 {
        let r = &self.radii;
        let (a1, a2, a3) = (
            (x.x / r.x).abs().powf(self.two_e1),
            (x.y / r.y).abs().powf(self.two_e1),
            (x.z / r.z).abs().powf(self.two_e2),
        );
        let s = a1 + a2;
        let outer = if s > 0.0 {
            self.e1_e2 * s.powf(self.e1_e2 - 1.0) * self.two_e1
        } else {
            0.0
        };
        let d = |a: f64, xi: f64| if xi != 0.0 { a / xi } else { 0.0 };
        V3::new(
            outer * d(a1, x.x),
            outer * d(a2, x.y),
            self.two_e2 * d(a3, x.z),
        )
    }

    /// Surface point whose outward normal is parallel to `n` (body frame, any length > 0),
    /// (A.39)–(A.48), with the Jacobian ∂X/∂n. Mapped from the first octant by
    /// X_i(n) = sign(n_i) X_i(|n|) (A.42) and ∂X_i/∂n_j = s_i s_j ∂X_i/∂|n_j| (A.62).
    #[inline]
    pub fn point_from_normal(&self, n: &V3) -> SurfacePoint {
        let s = [sign(n.x), sign(n.y), sign(n.z)];
        let m = [
            n.x.abs().max(NORMAL_FLOOR),
            n.y.abs().max(NORMAL_FLOOR),
            n.z.abs().max(NORMAL_FLOOR),
        ];
        // only the differences of ln n_i enter: two logarithms of ratios (m_i ∈ [1e-20, 1])
        let (u10, u20) = ((m[1] / m[0]).ln(), (m[2] / m[0]).ln());
        let (a1, a2, t1, t2, e12) = (self.a1, self.a2, self.two_e1, self.two_e2, self.e1_e2);
        let ln_r = &self.ln_r;
        // (A.44) γ21 = X2/X1
        let l21 = self.c21 + a1 * u10;
        let d21 = [-a1, a1, 0.0];
        // (A.45) s12 = (1/r1)^(2/ε1) + (γ21/r2)^(2/ε1)
        let (ls12, _, wq) = log_sum_exp(-t1 * ln_r[0], t1 * (l21 - ln_r[1]));
        let ds12 = d21.map(|d| wq * t1 * d);
        // (A.46) γ31 = X3/X1
        let l31 = a2 * (u20 + t2 * ln_r[2] - t1 * ln_r[0] + (e12 - 1.0) * ls12);
        let d31 = [
            a2 * (-1.0 + (e12 - 1.0) * ds12[0]),
            a2 * ((e12 - 1.0) * ds12[1]),
            a2 * (1.0 + (e12 - 1.0) * ds12[2]),
        ];
        // (A.47) X1 = (s12^(ε1/ε2) + (γ31/r3)^(2/ε2))^(−ε2/2)
        let (lse, wp, wqq) = log_sum_exp(e12 * ls12, t2 * (l31 - ln_r[2]));
        let half = 0.5 * self.eps2;
        let l1 = -half * lse;
        let d1: [f64; 3] =
            std::array::from_fn(|j| -half * (wp * e12 * ds12[j] + wqq * t2 * d31[j]));
        // (A.48) X = X1 (1, γ21, γ31)
        let lx = [l1, l1 + l21, l1 + l31];
        let dl = [
            d1,
            std::array::from_fn(|j| d1[j] + d21[j]),
            std::array::from_fn(|j| d1[j] + d31[j]),
        ];
        let xa = lx.map(f64::exp);
        let x = V3::new(s[0] * xa[0], s[1] * xa[1], s[2] * xa[2]);
        let inv_m = m.map(|v| 1.0 / v);
        let jacobian = Matrix3::from_fn(|i, j| s[i] * s[j] * xa[i] * dl[i][j] * inv_m[j]);
        SurfacePoint { x, jacobian }
    }

    /// Surface point only (no Jacobian), for the cheap evaluations of a search.
    #[inline]
    pub fn point(&self, n: &V3) -> V3 {
        self.point_from_normal(n).x
    }

    /// Radius of the smallest centred sphere containing the body, (A.8)–(A.14) (exact: the
    /// farthest point in the plane φ2 = 0 stays the farthest for every φ2).
    #[inline]
    pub fn bounding_radius(&self) -> f64 {
        self.bounding
    }

    /// Radius of the largest centred sphere inside the body (the other extreme of (A.11)).
    #[inline]
    pub fn inscribed_radius(&self) -> f64 {
        self.inscribed
    }

    /// Volume per unit density and principal moments per unit density, (3.4)–(3.7)
    /// (Jaklič et al.), with Γ from libm.
    pub fn mass_properties(&self, density: f64) -> (f64, V3) {
        let g = libm::tgamma;
        let (e1, e2) = (self.eps1, self.eps2);
        let g11 = g(e1 / 2.0).powi(2) / g(e1);
        let g12 = g(e1 / 2.0) * g(1.5 * e1) / g(2.0 * e1);
        let g21 = g(e2 / 2.0) * g(e2 + 1.0) / g(1.5 * e2 + 1.0);
        let g22 = g(e2 / 2.0) * g(2.0 * e2 + 1.0) / g(2.5 * e2 + 1.0);
        let g23 = g(1.5 * e2) * g(e2 + 1.0) / g(2.5 * e2 + 1.0);
        let r = &self.radii;
        let base = density * r.x * r.y * r.z * e1 * e2;
        let mass = base * g11 * g21; // (3.4)
        let inertia = V3::new(
            0.5 * base * (r.y * r.y * g12 * g22 + 2.0 * r.z * r.z * g11 * g23), // (3.5)
            0.5 * base * (r.x * r.x * g12 * g22 + 2.0 * r.z * r.z * g11 * g23), // (3.6)
            0.5 * base * (r.x * r.x + r.y * r.y) * g12 * g22,                   // (3.7)
        );
        (mass, inertia)
    }

    /// Volume (3.4) with ρ = 1.
    pub fn volume(&self) -> f64 {
        self.mass_properties(1.0).0
    }

    /// Principal curvatures at the surface point of unit normal `n` (body frame) with their
    /// directions: (ρ_I, ρ_II, e_I, e_II), ρ_I ≥ ρ_II ≥ 0 (an infinite radius, i.e. a flat
    /// point of an ε < 1 face, gives ρ = 0; a tip of an ε > 1 body gives ρ = ∞).
    pub fn principal_curvatures(&self, n: &V3) -> (f64, f64, V3, V3) {
        let n = n.normalize();
        let j = self.point_from_normal(&n).jacobian;
        let (t1, t2) = tangent_basis(&n);
        let (a, b, c) = (
            t1.dot(&(j * t1)),
            0.5 * (t1.dot(&(j * t2)) + t2.dot(&(j * t1))),
            t2.dot(&(j * t2)),
        );
        let (r_small, r_large, v_small, v_large) = sym2_eigen(a, b, c);
        let e_small = t1 * v_small[0] + t2 * v_small[1];
        let e_large = t1 * v_large[0] + t2 * v_large[1];
        let curv = |r: f64| if r > 0.0 { 1.0 / r } else { f64::INFINITY };
        (curv(r_small), curv(r_large), e_small, e_large)
    }
}

#[inline(always)]
fn sign(x: f64) -> f64 {
    if x < 0.0 {
        -1.0
    } else {
        1.0
    }
}

/// Extreme distance from the centre of the 2-D superquadric (a cos^ε φ, b sin^ε φ), (A.11):
/// candidates φ = 0, π/2 and tan φ = (a/b)^(1/(ε−1)). Returns (radius, φ) of the largest
/// (`largest`) or smallest one.
fn extreme_radius_2d(a: f64, b: f64, eps: f64, largest: bool) -> (f64, f64) {
    let mut best = (a, 0.0);
    let better = |r: f64, best: f64| if largest { r > best } else { r < best };
    if better(b, best.0) {
        best = (b, std::f64::consts::FRAC_PI_2);
    }
    if (eps - 1.0).abs() > 1e-12 {
        let phi = ((a / b).powf(1.0 / (eps - 1.0))).atan();
        let (c, s) = (phi.cos(), phi.sin());
        let r = (a * c.powf(eps)).hypot(b * s.powf(eps));
        if better(r, best.0) {
            best = (r, phi);
        }
    }
    best
}

/// An orthonormal pair (t1, t2) completing the unit vector n to a right-handed basis
/// (n, t1, t2) without a division by a small number (Duff et al. 2017; the basis jumps
/// where n_z changes sign, which only the choice of tangents sees).
#[inline]
pub fn tangent_basis(n: &V3) -> (V3, V3) {
    let sign = if n.z >= 0.0 { 1.0 } else { -1.0 };
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    let t1 = V3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
    let t2 = V3::new(b, sign + n.y * n.y * a, -n.y);
    (t1, t2)
}

/// Eigen-decomposition of the symmetric 2×2 matrix [[a, b], [b, c]]:
/// (λ_small, λ_large, v_small, v_large) with unit eigenvectors.
#[inline]
pub fn sym2_eigen(a: f64, b: f64, c: f64) -> (f64, f64, [f64; 2], [f64; 2]) {
    let mean = 0.5 * (a + c);
    let half_diff = 0.5 * (a - c);
    let rad = hypot_fast(half_diff, b);
    let (lo, hi) = (mean - rad, mean + rad);
    if rad == 0.0 {
        return (lo, hi, [1.0, 0.0], [0.0, 1.0]);
    }
    // eigenvector of the larger eigenvalue, by the better-conditioned of the two rows
    let v = if half_diff >= 0.0 {
        [half_diff + rad, b]
    } else {
        [b, rad - half_diff]
    };
    let norm = hypot_fast(v[0], v[1]);
    let v_large = [v[0] / norm, v[1] / norm];
    let v_small = [-v_large[1], v_large[0]];
    (lo, hi, v_small, v_large)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::generate::SplitMix64;

    fn sq(r: [f64; 3], e1: f64, e2: f64) -> Superquadric {
        Superquadric::new(V3::new(r[0], r[1], r[2]), e1, e2).unwrap()
    }

    /// W §1.2 table (r = (1, 1.5, 2), ρ = 1): the closed forms (3.4)–(3.7) against the values
    /// the SEED-SPEC obtained by quadrature (6 digits), and the ellipsoid exactly.
    #[test]
    fn superquadric_mass_inertia_match_gamma_formulas() {
        let pi = std::f64::consts::PI;
        let (m, i) = sq([1.0, 1.5, 2.0], 1.0, 1.0).mass_properties(1.0);
        // ellipsoid: m = 4/3 π abc, I1 = m/5 (b² + c²), ...
        let close = |a: f64, b: f64, tol: f64| (a - b).abs() <= tol * b.abs();
        assert!(close(m, 4.0 * pi, 1e-13), "{m}");
        let m5 = m / 5.0;
        assert!(close(i.x, m5 * (2.25 + 4.0), 1e-13));
        assert!(close(i.y, m5 * (1.0 + 4.0), 1e-13));
        assert!(close(i.z, m5 * (1.0 + 2.25), 1e-13));
        for ((e1, e2), want) in [
            ((0.5, 1.5), [10.6629, 11.0463, 8.2768, 7.2009]),
            ((1.5, 0.5), [13.3286, 20.2402, 17.1163, 8.1221]),
            ((0.3, 1.2), [13.6709, 16.9468, 12.8409, 10.6754]),
        ] {
            let (m, i) = sq([1.0, 1.5, 2.0], e1, e2).mass_properties(1.0);
            for (got, want) in [m, i.x, i.y, i.z].into_iter().zip(want) {
                assert!(close(got, want, 1e-5), "ε = ({e1}, {e2}): {got} vs {want}");
            }
        }
    }

    /// Volume and inertia by direct quadrature of the inside–outside function (3.1) on a
    /// grid (midpoint rule, 1e-4 relative at this resolution) agree with (3.4)–(3.7).
    #[test]
    fn mass_inertia_match_quadrature() {
        let s = sq([1.0, 1.5, 2.0], 0.7, 1.3);
        let (m, i) = s.mass_properties(1.0);
        // first octant, symmetric: integrate over [0, r1]×[0, r2]×[0, r3], times 8
        let n = 160;
        let h = [1.0 / n as f64, 1.5 / n as f64, 2.0 / n as f64];
        let (mut vol, mut ix, mut iy, mut iz) = (0.0, 0.0, 0.0, 0.0);
        let sub = 4; // sub-cells near the surface
        for a in 0..n {
            for b in 0..n {
                for c in 0..n {
                    let lo = V3::new(a as f64 * h[0], b as f64 * h[1], c as f64 * h[2]);
                    let hi = lo + V3::new(h[0], h[1], h[2]);
                    let (fl, fh) = (s.inside_outside(&lo), s.inside_outside(&hi));
                    if fl >= 1.0 {
                        continue;
                    }
                    let cells = if fh <= 1.0 { 1 } else { sub };
                    let dv = h[0] * h[1] * h[2] / (cells * cells * cells) as f64;
                    for p in 0..cells {
                        for q in 0..cells {
                            for r in 0..cells {
                                let x = lo
                                    + V3::new(
                                        (p as f64 + 0.5) * h[0] / cells as f64,
                                        (q as f64 + 0.5) * h[1] / cells as f64,
                                        (r as f64 + 0.5) * h[2] / cells as f64,
                                    );
                                if s.inside_outside(&x) < 1.0 {
                                    vol += dv;
                                    ix += dv * (x.y * x.y + x.z * x.z);
                                    iy += dv * (x.x * x.x + x.z * x.z);
                                    iz += dv * (x.x * x.x + x.y * x.y);
                                }
                            }
                        }
                    }
                }
            }
        }
        for (q, c) in [
            (8.0 * vol, m),
            (8.0 * ix, i.x),
            (8.0 * iy, i.y),
            (8.0 * iz, i.z),
        ] {
            assert!(
                (q - c).abs() < 2e-3 * c,
                "quadrature {q} vs closed form {c}"
            );
        }
    }

    /// Fig. 3.2: the cube (ε → 0) and octahedron (ε = 2) limits: m = 24 and 4, I = (50, 40,
    /// 26) and (2.5, 2.0, 1.3); max/min ratios 6 (mass) and 20 (moments). The constructor
    /// refuses those exponents, so the formula is evaluated at ε = 1e-7 and 2 directly.
    #[test]
    fn superquadric_limits_cube_ellipsoid_octahedron() {
        let raw = |e: f64| Superquadric {
            eps1: e,
            eps2: e,
            ..sq([1.0, 1.5, 2.0], 1.0, 1.0)
        };
        let (mc, ic) = raw(1e-7).mass_properties(1.0);
        let (mo, io) = raw(2.0).mass_properties(1.0);
        let close = |a: f64, b: f64, tol: f64| (a - b).abs() <= tol * b.abs();
        assert!(close(mc, 24.0, 1e-6), "{mc}");
        for (a, b) in [(ic.x, 50.0), (ic.y, 40.0), (ic.z, 26.0)] {
            assert!(close(a, b, 1e-6), "{a} vs {b}");
        }
        assert!(close(mo, 4.0, 1e-12), "{mo}");
        for (a, b) in [(io.x, 2.5), (io.y, 2.0), (io.z, 1.3)] {
            assert!(close(a, b, 1e-12), "{a} vs {b}");
        }
        assert!(close(mc / mo, 6.0, 1e-6));
        for (a, b) in [(ic.x, io.x), (ic.y, io.y), (ic.z, io.z)] {
            assert!(close(a / b, 20.0, 1e-6));
        }
    }

    /// F(X(n)) = 1 and ∇F(X(n)) ∥ n (A.39) in all octants, ε ∈ [0.3, 1.7], 1e-12.
    #[test]
    fn point_from_normal_satisfies_surface_and_gradient() {
        let mut rng = SplitMix64::new(7);
        for _ in 0..20_000 {
            let r = [
                0.5 + 2.5 * rng.uniform(),
                0.5 + 2.5 * rng.uniform(),
                0.5 + 2.5 * rng.uniform(),
            ];
            let s = sq(r, 0.3 + 1.4 * rng.uniform(), 0.3 + 1.4 * rng.uniform());
            let n = crate::generate::random_unit_vector(&mut rng);
            let x = s.point(&n);
            let f = s.inside_outside(&x);
            assert!((f - 1.0).abs() < 1e-12, "F = {f} for {s:?}, n = {n}");
            let g = s.gradient(&x).normalize();
            assert!(
                g.dot(&n) > 1.0 - 1e-12,
                "∇F·n = {} for {s:?}, n = {n}",
                g.dot(&n)
            );
        }
    }

    /// (A.49) n·∂X/∂n_i = 0, (A.53) symmetry, and the Jacobian against central differences.
    #[test]
    fn point_from_normal_jacobian_symmetric_and_tangent() {
        let mut rng = SplitMix64::new(11);
        for _ in 0..5_000 {
            let r = [
                0.5 + 2.5 * rng.uniform(),
                0.5 + 2.5 * rng.uniform(),
                0.5 + 2.5 * rng.uniform(),
            ];
            let s = sq(r, 0.3 + 1.4 * rng.uniform(), 0.3 + 1.4 * rng.uniform());
            let n = crate::generate::random_unit_vector(&mut rng);
            if n.iter().any(|c| c.abs() < 0.05) {
                continue; // the derivative is singular on the principal planes for ε ≠ 1
            }
            let p = s.point_from_normal(&n);
            let j = p.jacobian;
            let scale = j.abs().max();
            assert!(
                (j.transpose() * n).norm() < 1e-10 * scale,
                "n·J = {} ≠ 0 for {s:?} n = {n}: {j}",
                (j.transpose() * n).norm()
            );
            assert!(
                (j - j.transpose()).abs().max() < 1e-10 * scale,
                "J not symmetric: {j}"
            );
            let h = 1e-6;
            for k in 0..3 {
                let mut e = V3::zeros();
                e[k] = h;
                let fd = (s.point(&(n + e)) - s.point(&(n - e))) / (2.0 * h);
                let col = j.column(k).into_owned();
                assert!(
                    (fd - col).norm() < 1e-6 * scale.max(1.0),
                    "column {k}: {fd} vs {col}"
                );
            }
        }
    }

    /// Closed form for ε1 = ε2 = ε: r_ext = (Σ r_i^(2/(1−ε)))^((1−ε)/2); r = (1, 1.5, 2):
    /// ε = 0.5 → r_max = 2.16729, ε = 1.5 → r_min = 0.94385 (SEED-SPEC §1.4).
    #[test]
    fn bounding_radius_closed_form_equal_exponents() {
        let closed = |e: f64| {
            let p = 2.0 / (1.0 - e);
            (1f64.powf(p) + 1.5f64.powf(p) + 2f64.powf(p)).powf((1.0 - e) / 2.0)
        };
        let a = sq([1.0, 1.5, 2.0], 0.5, 0.5);
        assert!((a.bounding_radius() - closed(0.5)).abs() < 1e-12);
        // SEED-SPEC prints 2.16729; 22.0625^¼ = 2.1672733
        assert!((a.bounding_radius() - 2.16727).abs() < 1e-5);
        assert!((a.inscribed_radius() - 1.0).abs() < 1e-12);
        let b = sq([1.0, 1.5, 2.0], 1.5, 1.5);
        assert!((b.inscribed_radius() - closed(1.5)).abs() < 1e-12);
        assert!((b.inscribed_radius() - 0.94385).abs() < 1e-5);
        assert!((b.bounding_radius() - 2.0).abs() < 1e-12);
        // and in general no surface point lies farther (random normals)
        let mut rng = SplitMix64::new(3);
        for _ in 0..200 {
            let s = sq(
                [0.5 + rng.uniform(), 1.0 + rng.uniform(), 0.7],
                0.3 + 1.4 * rng.uniform(),
                0.3 + 1.4 * rng.uniform(),
            );
            let (rb, ri) = (s.bounding_radius(), s.inscribed_radius());
            for _ in 0..200 {
                let d = s
                    .point(&crate::generate::random_unit_vector(&mut rng))
                    .norm();
                assert!(
                    d <= rb * (1.0 + 1e-12) && d >= ri * (1.0 - 1e-12),
                    "{d} outside [{ri}, {rb}]"
                );
            }
        }
    }

    /// Ellipsoid (1, 1.5, 2) at (1, 0, 0): ρ = 1/1.5² = 0.4444 and 1/2² = 0.25 (the radius of
    /// curvature b²/a); a sphere: 1/R twice.
    #[test]
    fn principal_curvatures_ellipsoid_tip() {
        let e = sq([1.0, 1.5, 2.0], 1.0, 1.0);
        let (k1, k2, d1, d2) = e.principal_curvatures(&V3::x());
        assert!((k1 - 1.0 / 2.25).abs() < 1e-12, "{k1}");
        assert!((k2 - 0.25).abs() < 1e-12, "{k2}");
        assert!(d1.y.abs() > 1.0 - 1e-12 && d2.z.abs() > 1.0 - 1e-12);
        let s = sq([0.7, 0.7, 0.7], 1.0, 1.0);
        let mut rng = SplitMix64::new(5);
        for _ in 0..100 {
            let (k1, k2, ..) =
                s.principal_curvatures(&crate::generate::random_unit_vector(&mut rng));
            assert!((k1 - 1.0 / 0.7).abs() < 1e-10 && (k2 - 1.0 / 0.7).abs() < 1e-10);
        }
        // a general ellipsoid point against the closed form of the Gaussian curvature
        // K = 1 / (a²b²c² (x²/a⁴ + y²/b⁴ + z²/c⁴)²)
        for _ in 0..100 {
            let n = crate::generate::random_unit_vector(&mut rng);
            let x = e.point(&n);
            let (k1, k2, ..) = e.principal_curvatures(&n);
            let q = x.x * x.x + x.y * x.y / 1.5f64.powi(4) + x.z * x.z / 16.0;
            let gauss = 1.0 / (2.25 * 4.0 * q * q);
            assert!(
                (k1 * k2 - gauss).abs() < 1e-10 * gauss,
                "{} vs {gauss}",
                k1 * k2
            );
        }
    }

    #[test]
    fn exponents_outside_the_convex_range_are_refused() {
        assert!(Superquadric::new(V3::repeat(1.0), 0.05, 1.0).is_none());
        assert!(Superquadric::new(V3::repeat(1.0), 1.0, 1.95).is_none());
        assert!(Superquadric::new(V3::new(1.0, 0.0, 1.0), 1.0, 1.0).is_none());
        assert!(Superquadric::new(V3::new(1.0, f64::NAN, 1.0), 1.0, 1.0).is_none());
    }
}
