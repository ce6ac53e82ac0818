//! Local contact detection of two superquadrics: the common normal by minimisation over the
//! contact direction (Wellmann 2011 §3.4.2, eqs. 3.51–3.61).
//!
//! For a direction c the contact points are p1(c) = x1 + T1 X1(T1ᵀc) and
//! p2(c) = x2 + T2 X2(−T2ᵀc) (A.2 point from normal), so the normals are anti-parallel by
//! construction (3.51); d = p2 − p1 (3.54) and f = |d|² (3.55) is minimised over c. At the
//! solution d ∥ c (3.52) and δ = −d·c is the penetration.
//!
//! **Local parameters** (*not in thesis*, equivalent to (3.53)–(3.58)): every iteration
//! re-centres the angles α on the current c with tangents (t1, t2), so the iterate is never
//! near the poles of (3.53) and c_i = t_i, c_ij = −c δ_ij. With G = T1 J1 T1ᵀ + T2 J2 T2ᵀ
//! (J = ∂X/∂n of the point-from-normal map; G c = 0), d_i = −G t_i, so the gradient is
//! f_i = −2 (G d)·t_i and, dropping only the third-derivative term that vanishes with the
//! tangential part d_t of d, the Hessian is f_ij = 2 G_t (G_t + (d·c) I). The Newton step is
//! then Δα = (G_t + (d·c) I)⁻¹ d_t — which is also exactly the Newton step of the parallel
//! condition d·c_i = 0 (3.60)–(3.61), the temporal-coherence update: the same iteration
//! serves both, warm-started from the last step's normal for a tracked pair. A
//! Levenberg–Marquardt shift μI keeps the step a descent step where G_t + (d·c) I is not
//! positive definite or f does not decrease.
//!
//! Early exit (3.59): as soon as an iterate has c·d > 0 the tangent plane at p1 separates the
//! bodies (P1 lies behind it, P2 — whose support point in −c is p2 — in front), no contact.
//! Acceptance: a converged penetration is the global minimum only if p1 ∈ P2 and p2 ∈ P1;
//! otherwise (a local minimum, Fig. 3.10) or without convergence the search restarts from the
//! best of a set of fixed directions around the centre line (*not in thesis*: W uses random
//! search + Nelder–Mead; fixed directions keep the result deterministic).

use crate::hertz_mindlin::V3;
use crate::shape::superquadric::{hypot_fast, sym2_eigen, tangent_basis, Superquadric};
use nalgebra::Matrix3;
use serde::{Deserialize, Serialize};

/// A superquadric body placed in space: centre and rotation T (body → global).
#[derive(Debug, Clone, Copy)]
pub struct SqBody<'a> {
    pub shape: &'a Superquadric,
    pub position: V3,
    pub rotation: Matrix3<f64>,
}

/// Settings of the search.
#[derive(Debug, Clone, Copy)]
pub struct SearchSettings {
    /// Converged when |d_t| ≤ `tolerance` × the length scale (mean bounding radius).
    pub tolerance: f64,
    /// Newton iterations per start (W: 50).
    pub max_iterations: u32,
    /// Restarts after a local minimum or no convergence.
    pub max_restarts: u32,
    /// A tracked pair's linearised surfaces may err by this multiple of a quarter of the
    /// tolerance before they are evaluated exactly again (`dem.superquadric_surface_budget`;
    /// 1: the search's own accuracy).
    pub surface_budget: f64,
}

impl Default for SearchSettings {
    fn default() -> Self {
        SearchSettings {
            tolerance: 1e-10,
            max_iterations: 50,
            max_restarts: 16,
            surface_budget: 1.0,
        }
    }
}

/// The geometry of a penetrating pair.
#[derive(Debug, Clone, Copy)]
pub struct SqContact {
    /// Unit contact normal c: outward normal of body 1 at p1, pointing from body 1 to body 2.
    pub normal: V3,
    /// Contact points on the surfaces of bodies 1 and 2.
    pub p1: V3,
    pub p2: V3,
    /// Penetration δ = −d·c > 0.
    pub overlap: f64,
    /// Tangent basis (t1, t2) of the normal in which the radius tensors are given.
    pub t1: V3,
    pub t2: V3,
    /// Tangent blocks [a, b, c] = [[a, b], [b, c]] of the inverse curvature tensors (principal
    /// radii as eigenvalues) of bodies 1 and 2 at their contact points.
    pub radii1: [f64; 3],
    pub radii2: [f64; 3],
}

/// Outcome of one detection.
#[derive(Debug, Clone, Copy)]
pub enum Detection {
    /// A separating plane was found; `normal` is its direction (the warm start for the next
    /// step) and `gap` = c·d > 0 the distance of the two tangent planes of normal c (NaN when
    /// the search gave up without one).
    Separated {
        normal: V3,
        gap: f64,
    },
    Contact(SqContact),
}

/// What the search did (for the validation statistics and the cost figures).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SearchStats {
    /// Newton iterations summed over all starts (0: decided at the initial guess).
    pub iterations: u32,
    pub restarts: u32,
    /// Starts that converged to a rejected (local) minimum, starts that did not converge.
    pub local_minima: u32,
    pub not_converged: u32,
    /// No start converged to an accepted minimum: the best iterate was returned.
    pub failed: bool,
    /// Evaluations on the exact surfaces with the Jacobian (the others of a tracked pair were
    /// on its linearised surfaces, [`Linearised`]; the restarts' samples are not counted).
    pub exact_evaluations: u32,
}

/// The two surfaces of a tracked pair linearised about their last exact evaluation (*not in
/// thesis*; a temporal coherence of the surface points, beside W's of the normal, 3.60–3.61).
///
/// In its body frame each surface point is X(n) for the body-frame normal n, and the exact
/// evaluation gives X(n_b) and the Jacobian J = ∂X/∂n there (symmetric, J n_b = 0). For unit
/// n near n_b, X(n) ≈ X(n_b) + J (n − n_b), with an error ≈ C |n − n_b|². While the bodies turn and the
/// normal moves by less than `reach` in both body frames, the search evaluates this linear map
/// (a few products instead of ten `exp`/`ln` per body); beyond it, or where the linear surfaces
/// separate (a separation must be proven on the exact ones), it evaluates exactly and
/// linearises anew. Each re-linearisation measures the old map's error at the new normal, so
/// C is known and `reach` = |n − n_b| √(tol/(4 err)) keeps the error below a quarter of the
/// search tolerance (at most 4× the last reach; the first from the largest principal radius
/// ρ of the tangent block, whose term is ½ ρ θ² for a sphere).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Linearised {
    /// Body-frame unit normals n_b of bodies 1 and 2 at the last exact evaluation.
    pub normals: [V3; 2],
    /// The maps' constant terms X(n_b) − J n_b (X(n_b) itself but for round-off: J n_b = 0).
    pub points: [V3; 2],
    /// J = ∂X/∂n at n_b (symmetrised), as its six entries xx, yy, zz, xy, xz, yz.
    pub jacobians: [[f64; 6]; 2],
    /// Largest |n − n_b| (both bodies) at which the linear map is used; 0: none.
    pub reach: f64,
}

impl Linearised {
    pub const NONE: Linearised = Linearised {
        normals: [V3::new(0.0, 0.0, 0.0); 2],
        points: [V3::new(0.0, 0.0, 0.0); 2],
        jacobians: [[0.0; 6]; 2],
        reach: 0.0,
    };

    /// The same linearisation with the bodies swapped.
    pub fn swapped(&self) -> Linearised {
        Linearised {
            normals: [self.normals[1], self.normals[0]],
            points: [self.points[1], self.points[0]],
            jacobians: [self.jacobians[1], self.jacobians[0]],
            reach: self.reach,
        }
    }

    /// J n of body k.
    #[inline]
    fn jacobian_times(&self, k: usize, n: &V3) -> V3 {
        let j = &self.jacobians[k];
        V3::new(
            j[0] * n.x + j[3] * n.y + j[4] * n.z,
            j[3] * n.x + j[1] * n.y + j[5] * n.z,
            j[4] * n.x + j[5] * n.y + j[2] * n.z,
        )
    }

    /// Body k's linearised surface point of the body-frame normal n.
    #[inline]
    fn point(&self, k: usize, n: &V3) -> V3 {
        self.points[k] + self.jacobian_times(k, n)
    }

    /// The tangent block of J_k in the body-frame tangents (u, v).
    #[inline]
    fn block_in(&self, k: usize, u: &V3, v: &V3) -> [f64; 3] {
        let (ju, jv) = (self.jacobian_times(k, u), self.jacobian_times(k, v));
        [u.dot(&ju), 0.5 * (u.dot(&jv) + v.dot(&ju)), v.dot(&jv)]
    }
}

/// An exact evaluation's linearisation (reach not set yet) and the tangent blocks of its
/// Jacobians in the global frame (for the first reach).
#[derive(Clone, Copy)]
struct Sample {
    lin: Linearised,
    blocks: [[f64; 3]; 2],
}

impl Sample {
    /// X(n) ≈ X(n_b) + J (n − n_b) = (X(n_b) − J n_b) + J n with J symmetrised (J n_b = 0
    /// holds only to round-off, amplified for exponents near 2: the constant term keeps the
    /// map exact at n_b whatever it is).
    fn new(n: [V3; 2], x: [V3; 2], j: [&Matrix3<f64>; 2], blocks: [[f64; 3]; 2]) -> Sample {
        let sym = |j: &Matrix3<f64>| {
            [
                j[(0, 0)],
                j[(1, 1)],
                j[(2, 2)],
                0.5 * (j[(0, 1)] + j[(1, 0)]),
                0.5 * (j[(0, 2)] + j[(2, 0)]),
                0.5 * (j[(1, 2)] + j[(2, 1)]),
            ]
        };
        let mut lin = Linearised {
            normals: n,
            points: x,
            jacobians: [sym(j[0]), sym(j[1])],
            reach: 0.0,
        };
        lin.points = [
            x[0] - lin.jacobian_times(0, &n[0]),
            x[1] - lin.jacobian_times(1, &n[1]),
        ];
        Sample { lin, blocks }
    }
}

/// One evaluation at direction c, relative to x1 (no loss of digits far from the origin).
struct Eval {
    c: V3,
    d: V3,
    p1: V3,
    p2: V3,
    /// t1, t2 and the tangent blocks of T_β J_β T_βᵀ.
    t: (V3, V3),
    g1: [f64; 3],
    g2: [f64; 3],
}

impl Eval {
    fn f(&self) -> f64 {
        self.d.norm_squared()
    }
    fn s(&self) -> f64 {
        self.d.dot(&self.c)
    }
    /// |d_t|: the residual of the parallel condition (3.52).
    fn residual(&self) -> f64 {
        (self.d - self.c * self.s()).norm()
    }
}

#[inline]
fn evaluate(b1: &SqBody, b2: &SqBody, x21: &V3, c: V3, with_jacobian: bool) -> Eval {
    sampled(b1, b2, x21, c, with_jacobian).0
}

/// [`evaluate`], with the body-frame data of an exact evaluation with the Jacobian.
#[inline]
fn sampled(
    b1: &SqBody,
    b2: &SqBody,
    x21: &V3,
    c: V3,
    with_jacobian: bool,
) -> (Eval, Option<Sample>) {
    let n1 = b1.rotation.tr_mul(&c);
    let n2 = -b2.rotation.tr_mul(&c);
    let (t1, t2) = tangent_basis(&c);
    let block = |rot: &Matrix3<f64>, j: &Matrix3<f64>| {
        let (u, v) = (rot.tr_mul(&t1), rot.tr_mul(&t2));
        let (ju, jv) = (j * u, j * v);
        [u.dot(&ju), 0.5 * (u.dot(&jv) + v.dot(&ju)), v.dot(&jv)]
    };
    let (x1, x2, g1, g2, sample) = if with_jacobian {
        let s1 = b1.shape.point_from_normal(&n1);
        let s2 = b2.shape.point_from_normal(&n2);
        let (g1, g2) = (
            block(&b1.rotation, &s1.jacobian),
            block(&b2.rotation, &s2.jacobian),
        );
        (
            s1.x,
            s2.x,
            g1,
            g2,
            Some(Sample::new(
                [n1, n2],
                [s1.x, s2.x],
                [&s1.jacobian, &s2.jacobian],
                [g1, g2],
            )),
        )
    } else {
        (
            b1.shape.point(&n1),
            b2.shape.point(&n2),
            [0.0; 3],
            [0.0; 3],
            None,
        )
    };
    let p1 = b1.rotation * x1;
    let p2 = x21 + b2.rotation * x2;
    (
        Eval {
            c,
            d: p2 - p1,
            p1,
            p2,
            t: (t1, t2),
            g1,
            g2,
        },
        sample,
    )
}

/// The evaluations of one search: exact, or on the linearised surfaces of [`Linearised`]
/// where they are within reach.
struct Surfaces<'a, 'b> {
    b1: &'b SqBody<'a>,
    b2: &'b SqBody<'a>,
    x21: V3,
    lin: &'b mut Linearised,
    /// The search tolerance (a length) times [`SearchSettings::surface_budget`]: the
    /// linearisation keeps its error below a quarter of it.
    tol: f64,
    /// The count of exact evaluations ([`SearchStats::exact_evaluations`]).
    exact: &'b mut u32,
}

impl Surfaces<'_, '_> {
    /// The evaluation at c: linearised if within reach and not separating, else exact (and
    /// the surfaces are linearised anew about it).
    fn eval(&mut self, c: V3) -> Eval {
        if self.lin.reach > 0.0 {
            if let Some(e) = self.linear(c) {
                if e.s() <= 0.0 {
                    return e;
                }
            }
        }
        *self.exact += 1;
        let (e, sample) = sampled(self.b1, self.b2, &self.x21, c, true);
        if let Some(sample) = &sample {
            self.relinearise(sample);
        }
        e
    }

    fn linear(&self, c: V3) -> Option<Eval> {
        let (b1, b2, lin) = (self.b1, self.b2, &*self.lin);
        let n1 = b1.rotation.tr_mul(&c);
        let n2 = -b2.rotation.tr_mul(&c);
        let r2 = lin.reach * lin.reach;
        if (n1 - lin.normals[0]).norm_squared() > r2 || (n2 - lin.normals[1]).norm_squared() > r2 {
            return None;
        }
        let (x1, x2) = (lin.point(0, &n1), lin.point(1, &n2));
        let (t1, t2) = tangent_basis(&c);
        let g = |k: usize, rot: &Matrix3<f64>| lin.block_in(k, &rot.tr_mul(&t1), &rot.tr_mul(&t2));
        let p1 = b1.rotation * x1;
        let p2 = self.x21 + b2.rotation * x2;
        Some(Eval {
            c,
            d: p2 - p1,
            p1,
            p2,
            t: (t1, t2),
            g1: g(0, &b1.rotation),
            g2: g(1, &b2.rotation),
        })
    }

    /// Linearises about an exact sample; the reach from the old map's measured error at the
    /// sample's normals, or, without one, from the largest principal radius.
    fn relinearise(&mut self, s: &Sample) {
        let (old, new) = (*self.lin, &s.lin);
        let mut reach = f64::INFINITY;
        // no old map, or one linearised far away (a restart, a jump): C is not known
        let mut unknown = old.reach <= 0.0;
        let mut measured = false;
        if !unknown {
            for k in 0..2 {
                let n = &new.normals[k];
                let theta = (n - old.normals[k]).norm();
                // only a move well inside the quadratic range measures C; round-off makes
                // the estimate of a tiny move larger (a smaller reach: on the safe side)
                if theta >= 0.1 {
                    unknown = true;
                } else if theta > 0.0 {
                    // the old map against the exact point (the new map at its own normal)
                    let err = (new.point(k, n) - old.point(k, n)).norm();
                    if err > 0.0 {
                        reach = reach.min(theta * (self.tol / (4.0 * err)).sqrt());
                    }
                    measured = true;
                }
            }
        }
        if unknown {
            reach = f64::INFINITY;
            for b in &s.blocks {
                let (_, hi, ..) = sym2_eigen(b[0], b[1], b[2]);
                if hi > 0.0 {
                    reach = reach.min((self.tol / (2.0 * hi)).sqrt());
                }
            }
        } else if measured {
            reach = reach.min(4.0 * old.reach);
        } else {
            // re-evaluated where it was linearised (a separation to prove): nothing learnt
            reach = old.reach;
        }
        *self.lin = Linearised {
            reach: if reach.is_finite() {
                reach.min(1e-2)
            } else {
                0.0
            },
            ..*new
        };
    }
}

/// c rotated by the tangent step (Δα1, Δα2): the exponential map on the unit sphere.
#[inline]
pub(crate) fn rotate_normal(c: &V3, t: &(V3, V3), da: [f64; 2]) -> V3 {
    let angle = hypot_fast(da[0], da[1]);
    if angle == 0.0 {
        return *c;
    }
    let dir = (t.0 * da[0] + t.1 * da[1]) / angle;
    // a tracked contact turns by ~1e-6 rad a step: the series are exact to round-off there
    // and cheaper than the library's sin and cos
    let (sin, cos) = if angle < 1e-3 {
        let a2 = angle * angle;
        (
            angle * (1.0 - a2 / 6.0 * (1.0 - a2 / 20.0)),
            1.0 - a2 / 2.0 * (1.0 - a2 / 12.0),
        )
    } else {
        angle.sin_cos()
    };
    (c * cos + dir * sin).normalize()
}

/// The step Δα = (G_t + sI)⁻¹ d_t of the common-normal iteration, G_t = [[g0, g1], [g1, g2]],
/// turned by at most 0.5 rad; `None` where the matrix is singular.
#[inline]
pub(crate) fn shifted_newton_step(g: [f64; 3], s: f64, dt: [f64; 2]) -> Option<[f64; 2]> {
    let (a, b, c) = (g[0] + s, g[1], g[2] + s);
    let det = a * c - b * b;
    if !(det.abs() > 1e-300 && det.is_finite()) {
        return None;
    }
    let da = [(c * dt[0] - b * dt[1]) / det, (a * dt[1] - b * dt[0]) / det];
    let len = hypot_fast(da[0], da[1]);
    Some(if len > 0.5 {
        [da[0] * 0.5 / len, da[1] * 0.5 / len]
    } else {
        da
    })
}

/// Result of one Newton run from a start direction.
enum Run {
    Separated(V3, f64),
    Converged(Eval),
    NotConverged(Eval),
}

fn newton(surf: &mut Surfaces, c0: V3, tol: f64, max_iter: u32, iterations: &mut u32) -> Run {
    // one evaluation with the Jacobian blocks: they cost arithmetic only, the surface points
    // cost the transcendental functions, which a separate test would pay twice
    let mut e = surf.eval(c0);
    if e.s() > 0.0 {
        return Run::Separated(e.c, e.s());
    }
    let mut mu = 0.0f64;
    for _ in 0..max_iter {
        let (t1, t2) = e.t;
        let dt = [e.d.dot(&t1), e.d.dot(&t2)];
        if hypot_fast(dt[0], dt[1]) <= tol {
            return Run::Converged(e);
        }
        *iterations += 1;
        let s = e.s();
        let g = [e.g1[0] + e.g2[0], e.g1[1] + e.g2[1], e.g1[2] + e.g2[2]];
        let floor = 1e-3 * (0.5 * (g[0] + g[2])).abs().max(tol);
        // First the plain Newton step (shift 0, or the last successful shift): it also solves
        // the parallel condition where f is flat (two sharp tips: the points hardly move
        // with c, so only the direction of c is found, and G_t + sI is indefinite). If it
        // neither lowers f nor the residual, shift to a positive definite matrix (a descent
        // step of f) and grow the shift (Levenberg–Marquardt).
        // formed only when the plain step fails (a tracked pair's step hardly ever does)
        let pd_shift = || (floor - (sym2_eigen(g[0], g[1], g[2]).0 + s)).max(0.0);
        let mut shift = mu;
        let mut tries = 0;
        loop {
            tries += 1;
            let step = shifted_newton_step(g, s + shift, dt);
            let ok = step.is_some();
            let da = step.unwrap_or([0.0, 0.0]);
            let cn = rotate_normal(&e.c, &e.t, da);
            let trial = surf.eval(cn);
            if trial.s() > 0.0 {
                return Run::Separated(cn, trial.s());
            }
            // near the solution f changes by less than its round-off (|d_t|² ≪ ε|d|²): then
            // the decrease of the residual |d_t| decides
            // (f must not grow beyond round-off: an indefinite step that lowers the residual
            // while f grows heads for another stationary point, e.g. the far side)
            let better = ok
                && (trial.f() < e.f()
                    || (trial.residual() < e.residual() && trial.f() <= e.f() * (1.0 + 1e-9)));
            if better || tries > 40 {
                e = trial;
                mu *= 0.25;
                if mu < 1e-6 * floor {
                    mu = 0.0;
                }
                break;
            }
            let pd_shift = pd_shift();
            mu = if shift < pd_shift {
                pd_shift + floor
            } else {
                4.0 * shift.max(floor)
            };
            shift = mu;
        }
    }
    let (t1, t2) = e.t;
    if hypot_fast(e.d.dot(&t1), e.d.dot(&t2)) <= tol {
        Run::Converged(e)
    } else {
        Run::NotConverged(e)
    }
}

/// p1 ∈ P2 and p2 ∈ P1 (the acceptance test of W §3.4.2, step 5), up to the penetration
/// itself (*not in thesis*): near a sharp tip (ε near 2) the body is thinner than δ a little
/// behind its surface, and the inner point of a true contact lies just outside the other
/// body; a local minimum (W Fig. 3.10) has its points outside by a distance of the order of
/// the particle size. The distance outside is estimated as (F − 1)/|∇F|.
fn accepted(b1: &SqBody, b2: &SqBody, x21: &V3, e: &Eval) -> bool {
    let size = b1.shape.inscribed_radius().min(b2.shape.inscribed_radius());
    let margin = (-e.s()).clamp(0.0, 0.05 * size) + 1e-12 * size;
    let outside = |shape: &Superquadric, x: V3| {
        let f = shape.inside_outside(&x);
        f <= 1.0 || (f - 1.0) <= margin * shape.gradient(&x).norm()
    };
    outside(b2.shape, b2.rotation.tr_mul(&(e.p1 - x21)))
        && outside(b1.shape, b1.rotation.tr_mul(&e.p2))
}

/// Restart directions (deterministic): restart k takes 32 points of a spherical Fibonacci
/// set turned by the golden angle per restart, in the frame of the centre line (its pole
/// first), so successive restarts cover the whole sphere of directions ever more densely.
fn restart_directions(axis: &V3, restart: u32) -> impl Iterator<Item = V3> {
    const N: u32 = 32;
    let (t1, t2) = tangent_basis(axis);
    let axis = *axis;
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let turn = golden * restart as f64 * 0.618;
    (0..N).map(move |k| {
        let z = 1.0 - (k as f64 + 0.5) / N as f64 * 2.0;
        let r = (1.0 - z * z).sqrt();
        let az = golden * k as f64 + turn;
        (axis * z + (t1 * az.cos() + t2 * az.sin()) * r).normalize()
    })
}

/// The contact of a converged evaluation, in global coordinates.
fn finish(b1: &SqBody, e: Eval) -> SqContact {
    let (t1, t2) = e.t;
    SqContact {
        normal: e.c,
        p1: e.p1 + b1.position,
        p2: e.p2 + b1.position,
        overlap: -e.s(),
        t1,
        t2,
        radii1: e.g1,
        radii2: e.g2,
    }
}

/// Wellmann's temporal-coherence update (SEED-SPEC §1.6, W 3.60–3.61) for a pair that
/// touched in the last step with `normal` and `overlap`: Newton from that normal, and a
/// converged root is taken without the acceptance test (the minimum condition is dropped),
/// unless the overlap jumped (more than twice the last one plus 1 % of the smaller body's
/// inscribed radius: a sign of a wrong root, SEED-SPEC §1.6), in which case, as on
/// non-convergence, the full search [`detect`] decides. A separating iterate ends it as in the full search
/// (3.59: a separating plane is a proof).
pub fn detect_tracked(
    b1: &SqBody,
    b2: &SqBody,
    normal: V3,
    overlap: f64,
    settings: &SearchSettings,
    stats: &mut SearchStats,
) -> Detection {
    track(
        b1,
        b2,
        normal,
        overlap,
        &mut Linearised::default(),
        settings,
        stats,
    )
}

/// [`detect_tracked`] on the pair's linearised surfaces (see [`Linearised`]): `lin` is the
/// map of the last step (`Linearised::NONE` for none) and, on return, the one to keep for the
/// next (`NONE` when the pair separated).
pub fn track(
    b1: &SqBody,
    b2: &SqBody,
    normal: V3,
    overlap: f64,
    lin: &mut Linearised,
    settings: &SearchSettings,
    stats: &mut SearchStats,
) -> Detection {
    let x21 = b2.position - b1.position;
    let scale = 0.5 * (b1.shape.bounding_radius() + b2.shape.bounding_radius());
    let tol = settings.tolerance * scale;
    let size = b1.shape.inscribed_radius().min(b2.shape.inscribed_radius());
    let mut surf = Surfaces {
        b1,
        b2,
        x21,
        lin: &mut *lin,
        tol: settings.surface_budget * tol,
        exact: &mut stats.exact_evaluations,
    };
    let run = newton(
        &mut surf,
        normal,
        tol,
        settings.max_iterations,
        &mut stats.iterations,
    );
    match run {
        Run::Separated(normal, gap) => {
            *lin = Linearised::NONE;
            Detection::Separated { normal, gap }
        }
        Run::Converged(e) if -e.s() <= 2.0 * overlap.max(0.0) + 0.01 * size => {
            Detection::Contact(finish(b1, e))
        }
        _ => search(b1, b2, Some(normal), settings, stats, lin),
    }
}

/// Detects the contact of two superquadrics. `guess` is the last step's normal of this pair
/// (temporal coherence), else the centre line x2 − x1 is the start (exact for spheres).
pub fn detect(
    b1: &SqBody,
    b2: &SqBody,
    guess: Option<V3>,
    settings: &SearchSettings,
    stats: &mut SearchStats,
) -> Detection {
    search(b1, b2, guess, settings, stats, &mut Linearised::default())
}

/// [`detect`], with the linearised surfaces of a found contact left in `lin` for [`track`]
/// (`NONE` when separated or when no start was accepted).
pub fn search(
    b1: &SqBody,
    b2: &SqBody,
    guess: Option<V3>,
    settings: &SearchSettings,
    stats: &mut SearchStats,
    lin: &mut Linearised,
) -> Detection {
    *lin = Linearised::NONE;
    let x21 = b2.position - b1.position;
    let centre = if x21.norm_squared() > 0.0 {
        x21.normalize()
    } else {
        V3::z()
    };
    let scale = 0.5 * (b1.shape.bounding_radius() + b2.shape.bounding_radius());
    let tol = settings.tolerance * scale;
    let mut surf = Surfaces {
        b1,
        b2,
        x21,
        lin,
        tol: settings.surface_budget * tol,
        exact: &mut stats.exact_evaluations,
    };
    let finish = |e: Eval| finish(b1, e);
    let start = guess.filter(|g| g.norm_squared() > 0.0).unwrap_or(centre);
    let mut best: Option<Eval> = None;
    let keep = |e: Eval, best: &mut Option<Eval>| {
        if best.as_ref().is_none_or(|b| e.f() < b.f()) {
            *best = Some(e);
        }
    };
    match newton(
        &mut surf,
        start,
        tol,
        settings.max_iterations,
        &mut stats.iterations,
    ) {
        Run::Separated(normal, gap) => {
            *surf.lin = Linearised::NONE;
            return Detection::Separated { normal, gap };
        }
        Run::Converged(e) if accepted(b1, b2, &x21, &e) => return Detection::Contact(finish(e)),
        Run::Converged(e) => {
            stats.local_minima += 1;
            keep(e, &mut best)
        }
        Run::NotConverged(e) => {
            stats.not_converged += 1;
            keep(e, &mut best)
        }
    }
    for ring in 0..settings.max_restarts {
        stats.restarts += 1;
        // the best sampled direction (a separating one ends the search): mutually inside
        // contact points first (the acceptance test), then the smallest |d|
        let mut pick: Option<((bool, f64), V3)> = None;
        for c in restart_directions(&centre, ring) {
            let e = evaluate(b1, b2, &x21, c, false);
            if e.s() > 0.0 {
                *surf.lin = Linearised::NONE;
                return Detection::Separated {
                    normal: c,
                    gap: e.s(),
                };
            }
            let key = (!accepted(b1, b2, &x21, &e), e.f());
            if pick.is_none_or(|(k, _)| key < k) {
                pick = Some((key, c));
            }
        }
        let Some((_, c)) = pick else { break };
        match newton(
            &mut surf,
            c,
            tol,
            settings.max_iterations,
            &mut stats.iterations,
        ) {
            Run::Separated(normal, gap) => {
                *surf.lin = Linearised::NONE;
                return Detection::Separated { normal, gap };
            }
            Run::Converged(e) if accepted(b1, b2, &x21, &e) => {
                return Detection::Contact(finish(e))
            }
            Run::Converged(e) => {
                stats.local_minima += 1;
                keep(e, &mut best)
            }
            Run::NotConverged(e) => {
                stats.not_converged += 1;
                keep(e, &mut best)
            }
        }
    }
    stats.failed = true;
    *surf.lin = Linearised::NONE;
    match best {
        Some(e) => Detection::Contact(finish(e)),
        None => Detection::Separated {
            normal: centre,
            gap: f64::NAN,
        },
    }
}
