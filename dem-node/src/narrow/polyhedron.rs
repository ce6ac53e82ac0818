//! Narrow phase of the dilated polyhedra (U (2.5), SEED-SPEC §6.1): the distance Δ between the
//! two convex cores by parry's GJK (its EPA when they interpenetrate), the gap between the
//! dilated bodies δ = Δ − r_ds,1 − r_ds,2 and the overlap δ_d = −δ along the cores' closest-
//! point direction. The thesis leaves the narrow phase open; GJK on the cores is what its
//! "distance between the two core polyhedra" asks for.
//!
//! One contact point per pair, halfway between the two dilated surfaces on the segment of the
//! cores' closest points. The overlap δ_d(x, θ) is a continuous function of the poses (the
//! distance of two convex sets is), and the normal force F(δ_d) c applied at the closest
//! points is −∇W(δ_d) wherever those points are unique: the field is conservative (elastic
//! impacts conserve energy) and the force has no jump when the closest features change
//! between face, edge and vertex. Where two faces are parallel the closest points are not
//! unique (the force is then a subgradient): the force is the same but its point may jump
//! within the common area, as for any single-point model of flat contacts.
//!
//! A sphere takes part as a dilated point (core = its centre, dilation = its radius), so a
//! sphere–polyhedron pair is exact; a superquadric as its own support map (point from a
//! normal, W A.2) with no dilation.
//!
//! The cores must never interpenetrate (δ_d < r_ds,1 + r_ds,2, the model's validity limit,
//! U §6.1): when they do, the detection says so ([`PolyDetection::CoresIntersect`]) and the
//! engine stops with an error naming the pair.

use crate::hertz_mindlin::V3;
use crate::particles::Orientation;
use crate::shape::polyhedron::{support_index, Adjacency};
use crate::shape::Superquadric;
use nalgebra::Matrix3;
use parry3d_f64::math::{Pose, Rotation, Vector};
use parry3d_f64::query::details::contact_support_map_support_map_with_params;
use parry3d_f64::query::epa::EPA;
use parry3d_f64::query::gjk::{self, CsoPoint, GJKResult, VoronoiSimplex};
use parry3d_f64::shape::{SupportMap, Triangle};

#[inline]
fn to_parry(x: &V3) -> Vector {
    Vector::new(x.x, x.y, x.z)
}

#[inline]
fn from_parry(x: Vector) -> V3 {
    V3::new(x.x, x.y, x.z)
}

/// The convex core of a body in its own frame, as GJK sees it.
#[derive(Clone, Copy)]
pub enum Core<'a> {
    /// The hull of `vertices` × `scale` (a stone; a sphere is the single vertex 0).
    Points { vertices: &'a [V3], scale: f64 },
    /// A superquadric (no dilation): its support point is its surface point of that normal.
    Superquadric(&'a Superquadric),
}

impl SupportMap for Core<'_> {
    #[inline]
    fn local_support_point(&self, dir: Vector) -> Vector {
        match self {
            Core::Points { vertices, scale } => {
                let best = vertices[support_index(vertices, &from_parry(dir))];
                to_parry(&(best * *scale))
            }
            Core::Superquadric(s) => {
                let d = from_parry(dir);
                if d.norm_squared() == 0.0 {
                    return Vector::ZERO;
                }
                to_parry(&s.point_from_normal(&d).x)
            }
        }
    }
}

/// A body as the polyhedral narrow phase sees it.
#[derive(Clone, Copy)]
pub struct PolyBody<'a> {
    pub core: Core<'a>,
    /// Dilation radius r_ds (m); a sphere's radius, 0 for a superquadric.
    pub dilation: f64,
    pub position: V3,
    pub orientation: Orientation,
}

/// The single vertex of a sphere's core.
pub const POINT_CORE: [V3; 1] = [V3::new(0.0, 0.0, 0.0)];

/// Result of a polyhedral detection.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PolyDetection {
    /// The dilated bodies are apart, separated by the plane of normal `normal` (from the first
    /// body to the second) with `gap` between them: the cores' closest-point direction and
    /// the distance of the dilated surfaces when GJK found them within its reach, else GJK's
    /// separating direction and the gap along it (a lower bound; NaN if none was proved).
    Separated { normal: V3, gap: f64 },
    /// Overlap δ_d > 0 along `normal` (unit, from the first body to the second), contact
    /// `point` halfway between the dilated surfaces; `core_point` is the second's core point
    /// (on a triangle: where the force acts on the wall).
    Contact {
        normal: V3,
        overlap: f64,
        point: V3,
        core_point: V3,
    },
    /// The cores interpenetrate by `depth` (the dilation no longer covers the overlap).
    CoresIntersect { depth: f64 },
}

/// Distance query between two cores placed by `pos12` (second in the first's frame, both
/// cores in their own frames), reach `reach`: (closest point on the first, on the second,
/// normal from first to second, all in the first's frame) or the separating direction.
fn closest<G1: SupportMap, G2: SupportMap>(
    pos12: &Pose,
    g1: &G1,
    g2: &G2,
    reach: f64,
    warm: Option<Vector>,
) -> GJKResult {
    let mut simplex = VoronoiSimplex::new();
    contact_support_map_support_map_with_params(pos12, g1, g2, reach, &mut simplex, warm)
}

/// Classifies the GJK result of two bodies of dilations summing to `reach` (`r1` the
/// first's); `to_global` maps the first body's frame to the global one.
fn classify(
    result: GJKResult,
    reach: f64,
    r1: f64,
    to_global: impl Fn(V3) -> V3,
    x1: &V3,
) -> PolyDetection {
    match result {
        GJKResult::ClosestPoints(p1, p2, n1) => {
            let dist = (p2 - p1).dot(n1);
            let normal = to_global(from_parry(n1)).normalize();
            if dist <= 0.0 {
                return PolyDetection::CoresIntersect { depth: -dist };
            }
            if dist >= reach {
                return PolyDetection::Separated {
                    normal,
                    gap: dist - reach,
                };
            }
            let c1 = x1 + to_global(from_parry(p1));
            let c2 = x1 + to_global(from_parry(p2));
            // halfway between the dilated surfaces c1 + r1 n and c2 − r2 n
            let overlap = reach - dist;
            let point = c1 + normal * (r1 - 0.5 * overlap);
            PolyDetection::Contact {
                normal,
                overlap,
                point,
                core_point: c2,
            }
        }
        GJKResult::NoIntersection(dir) => PolyDetection::Separated {
            normal: to_global(from_parry(dir))
                .try_normalize(0.0)
                .unwrap_or_else(V3::z),
            gap: f64::NAN,
        },
        // not returned by the contact query (EPA answers an intersection)
        GJKResult::Intersection | GJKResult::Proximity(_) => {
            PolyDetection::CoresIntersect { depth: 0.0 }
        }
    }
}

fn rotation(q: &Orientation) -> Rotation {
    let c = q.quaternion().coords; // [i, j, k, w]
    Rotation::from_xyzw(c.x, c.y, c.z, c.w)
}

/// A GJK simplex as vertex indices of the two cores, (first, second) × 3; `u16::MAX` unused.
pub type Simplex = [u16; 6];

/// The vertex lists and scales of two point cores (stones or spheres); `None` if either is a
/// superquadric.
#[allow(clippy::type_complexity)] // two lists and two scales
fn point_cores<'a>(a: &PolyBody<'a>, b: &PolyBody<'a>) -> Option<([&'a [V3]; 2], [f64; 2])> {
    match (a.core, b.core) {
        (
            Core::Points {
                vertices: va,
                scale: sa,
            },
            Core::Points {
                vertices: vb,
                scale: sb,
            },
        ) => Some(([va, vb], [sa, sb])),
        _ => None,
    }
}

/// No simplex.
pub const NO_SIMPLEX: Simplex = [u16::MAX; 6];

/// Contact of two bodies; `warm` is the last normal (the GJK start direction).
pub fn detect_pair(a: &PolyBody, b: &PolyBody, warm: Option<V3>) -> PolyDetection {
    detect_pair_warm(a, b, warm, &NO_SIMPLEX).0
}

/// The index of the vertex of `vertices` × `scale` at `x` (a support point GJK kept): one of
/// the `hints` (the last simplex's, usually still the closest features) or any.
fn vertex_at(vertices: &[V3], scale: f64, x: &V3, hints: [u16; 3]) -> Option<u16> {
    let tolerance = 1e-20 * scale * scale;
    for h in hints {
        if let Some(v) = vertices.get(h as usize) {
            if (v * scale - x).norm_squared() <= tolerance {
                return Some(h);
            }
        }
    }
    let (mut best, mut d) = (0, f64::INFINITY);
    for (i, v) in vertices.iter().enumerate() {
        let e = (v * scale - x).norm_squared();
        if e < d {
            (best, d) = (i, e);
        }
    }
    (d <= tolerance && best < u16::MAX as usize).then_some(best as u16)
}

/// [`detect_pair`] warm-started from the last step's simplex too (temporal coherence, *not in
/// thesis*): GJK begins with the CSO points of the vertex pairs that formed its last simplex,
/// evaluated at the current poses — for a resting contact the closest features of the last
/// step, so it converges in an iteration or two instead of building the simplex up again.
/// Any simplex of CSO points is a valid start, so the answer is GJK's as from scratch (up to
/// its tolerance). Returns the detection and the simplex to keep.
pub fn detect_pair_warm(
    a: &PolyBody,
    b: &PolyBody,
    warm: Option<V3>,
    last: &Simplex,
) -> (PolyDetection, Simplex) {
    let q1 = a.orientation;
    let t = q1.inverse_transform_vector(&(b.position - a.position));
    let pos12 = Pose::from_parts(to_parry(&t), rotation(&(q1.inverse() * b.orientation)));
    let reach = a.dilation + b.dilation;
    let warm = warm.map(|n| to_parry(&q1.inverse_transform_vector(&n)));
    let Some(([va, vb], [sa, sb])) = point_cores(a, b) else {
        let result = closest(&pos12, &a.core, &b.core, reach, warm);
        return (finish(result, reach, a, b, &q1), NO_SIMPLEX);
    };
    let mut simplex = VoronoiSimplex::new();
    let mut seeded = 0;
    for k in 0..3 {
        let (i, j) = (last[2 * k] as usize, last[2 * k + 1] as usize);
        if i >= va.len() || j >= vb.len() {
            break;
        }
        let point = CsoPoint::new(to_parry(&(va[i] * sa)), pos12 * to_parry(&(vb[j] * sb)));
        if seeded == 0 {
            simplex.reset(point);
            seeded = 1;
        } else if simplex.add_point(point) {
            seeded += 1;
        }
    }
    let result = if seeded == 0 {
        let dir = warm
            .or_else(|| pos12.translation.try_normalize())
            .unwrap_or(Vector::X);
        simplex.reset(CsoPoint::from_shapes(&pos12, &a.core, &b.core, dir));
        gjk::closest_points(&pos12, &a.core, &b.core, reach, true, &mut simplex)
    } else {
        gjk::closest_points(&pos12, &a.core, &b.core, reach, true, &mut simplex)
    };
    let result = match result {
        GJKResult::Intersection => {
            match EPA::new().closest_points(&pos12, &a.core, &b.core, &simplex) {
                Some((p1, p2, n)) => GJKResult::ClosestPoints(p1, p2, n),
                None => GJKResult::NoIntersection(Vector::X),
            }
        }
        other => other,
    };
    // the simplex to keep: its points' vertex indices on each core
    let mut keep = NO_SIMPLEX;
    let inverse = pos12.inverse();
    for k in 0..=simplex.dimension().min(2) {
        let c = simplex.point(k);
        let (Some(i), Some(j)) = (
            vertex_at(va, sa, &from_parry(c.orig1), [last[0], last[2], last[4]]),
            vertex_at(
                vb,
                sb,
                &from_parry(inverse * c.orig2),
                [last[1], last[3], last[5]],
            ),
        ) else {
            break;
        };
        keep[2 * k] = i;
        keep[2 * k + 1] = j;
    }
    (finish(result, reach, a, b, &q1), keep)
}

/// The point of the simplex `w[..n]` (1–3 points) closest to the origin, as convex weights
/// over its points (zero for the points its closest feature does not use; Ericson, *Real-Time
/// Collision Detection* 5.1.5 for the triangle). `None` for a degenerate simplex.
///
/// The triangle case is `triangle_contact::closest_point_on_triangle` at p = 0 with a guard for
/// flat triangles; calling that instead changes the tracker's round-off, and with it the CI
/// polyhedral sleeper chain turns unstable at 19.4 ms (tests/tests/polyhedra.rs) — that chain
/// sits at the edge of stability and must be made robust before the two are merged.
fn closest_weights(w: &[V3; 3], n: usize) -> Option<[f64; 3]> {
    match n {
        1 => Some([1.0, 0.0, 0.0]),
        2 => {
            let ab = w[1] - w[0];
            let l2 = ab.norm_squared();
            if l2 <= 0.0 || l2.is_nan() {
                return None;
            }
            let t = (-w[0].dot(&ab) / l2).clamp(0.0, 1.0);
            Some([1.0 - t, t, 0.0])
        }
        3 => {
            let (a, b, c) = (w[0], w[1], w[2]);
            let (ab, ac) = (b - a, c - a);
            let (d1, d2) = (-ab.dot(&a), -ac.dot(&a));
            if d1 <= 0.0 && d2 <= 0.0 {
                return Some([1.0, 0.0, 0.0]);
            }
            let (d3, d4) = (-ab.dot(&b), -ac.dot(&b));
            if d3 >= 0.0 && d4 <= d3 {
                return Some([0.0, 1.0, 0.0]);
            }
            let vc = d1 * d4 - d3 * d2;
            if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
                let v = d1 / (d1 - d3);
                return Some([1.0 - v, v, 0.0]);
            }
            let (d5, d6) = (-ab.dot(&c), -ac.dot(&c));
            if d6 >= 0.0 && d5 <= d6 {
                return Some([0.0, 0.0, 1.0]);
            }
            let vb = d5 * d2 - d1 * d6;
            if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
                let t = d2 / (d2 - d6);
                return Some([1.0 - t, 0.0, t]);
            }
            let va = d3 * d6 - d5 * d4;
            if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
                let t = (d4 - d3) / ((d4 - d3) + (d5 - d6));
                return Some([0.0, 1.0 - t, t]);
            }
            let sum = va + vb + vc;
            if sum <= 0.0 || sum.is_nan() {
                return None;
            }
            let (v, t) = (vb / sum, vc / sum);
            // a nearly flat triangle's round-off can leave a weight just below zero
            (v >= 0.0 && t >= 0.0 && v + t <= 1.0).then_some([1.0 - v - t, v, t])
        }
        _ => None,
    }
}

/// The closest-feature tracker of a polyhedral pair (temporal coherence, *not in thesis*):
/// the vertex pairs of the last step's simplex (`last`, the closest features: vertex–face,
/// edge–edge, …) are placed at the current poses, the point of their simplex closest to the
/// origin gives the distance and the direction n, and the two support scans along n check
/// that no other vertex comes closer (the features' Voronoi regions still hold). That check
/// is GJK's own termination test (parry's relative tolerance, √(10 ε)), so an accepted answer
/// is the one GJK gives from this simplex; the tracker only saves the set-up of a GJK run.
/// `None` when the features changed (or the simplex is degenerate, or the cores meet):
/// then [`detect_pair_warm`] answers. `ra`, `rb` are the bodies' rotation matrices; with
/// their cores' vertex graphs (`graphs`) the support scans climb from the simplex's vertices
/// (a few neighbours instead of every vertex).
pub fn track_pair(
    a: &PolyBody,
    b: &PolyBody,
    ra: &Matrix3<f64>,
    rb: &Matrix3<f64>,
    last: &Simplex,
    graphs: [Option<&Adjacency>; 2],
) -> Option<(PolyDetection, Simplex)> {
    let ([va, vb], [sa, sb]) = point_cores(a, b)?;
    // the second body in the first's frame: x ↦ r12 x + t
    let r12 = ra.tr_mul(rb);
    let t = ra.tr_mul(&(b.position - a.position));
    // the simplex of the configuration space obstacle B − A, w = b − a
    let mut w = [V3::zeros(); 3];
    let mut pa = [V3::zeros(); 3];
    let mut n = 0;
    for k in 0..3 {
        let (i, j) = (last[2 * k] as usize, last[2 * k + 1] as usize);
        if i >= va.len() || j >= vb.len() {
            break;
        }
        pa[n] = va[i] * sa;
        w[n] = r12 * (vb[j] * sb) + t - pa[n];
        n += 1;
    }
    if n == 0 {
        return None;
    }
    let lambda = closest_weights(&w, n)?;
    let v = w[0] * lambda[0] + w[1] * lambda[1] + w[2] * lambda[2];
    let dist = v.norm();
    if dist <= 10.0 * f64::EPSILON || dist.is_nan() {
        return None; // the cores touch or meet: EPA's case
    }
    let normal = v / dist;
    // the support scans: all of A below p_A·n, all of B above p_B·n (within the tolerance)
    let m = -r12.tr_mul(&normal);
    let (ha, hb) = match graphs {
        [Some(ga), Some(gb)] => {
            // climb from the simplex's highest vertex of each core
            let from = |core: &[V3], d: &V3, side: usize| {
                let mut at = last[side] as usize;
                let mut h = core[at].dot(d);
                for k in 1..n {
                    let i = last[2 * k + side] as usize;
                    let x = core[i].dot(d);
                    if x > h {
                        (at, h) = (i, x);
                    }
                }
                at
            };
            let (_, ha) = ga.climb(va, from(va, &normal, 0), &normal)?;
            let (_, hb) = gb.climb(vb, from(vb, &m, 1), &m)?;
            (ha, hb)
        }
        _ => (
            va[support_index(va, &normal)].dot(&normal),
            vb[support_index(vb, &m)].dot(&m),
        ),
    };
    let lower = t.dot(&normal) - sb * hb - sa * ha;
    if dist - lower > (10.0 * f64::EPSILON).sqrt() * dist {
        return None;
    }
    let mut keep = NO_SIMPLEX;
    let mut kept = 0;
    for k in 0..n {
        if lambda[k] > 0.0 {
            keep[2 * kept] = last[2 * k];
            keep[2 * kept + 1] = last[2 * k + 1];
            kept += 1;
        }
    }
    let reach = a.dilation + b.dilation;
    let global = ra * normal;
    if dist >= reach {
        // the lower bound: a proof of the gap
        return Some((
            PolyDetection::Separated {
                normal: global,
                gap: (lower - reach).max(0.0),
            },
            keep,
        ));
    }
    let p1 = pa[0] * lambda[0] + pa[1] * lambda[1] + pa[2] * lambda[2];
    let c1 = a.position + ra * p1;
    let c2 = c1 + global * dist;
    let overlap = reach - dist;
    Some((
        PolyDetection::Contact {
            normal: global,
            overlap,
            point: c1 + global * (a.dilation - 0.5 * overlap),
            core_point: c2,
        },
        keep,
    ))
}

/// Classifies a pair's GJK result, and proves a separation beyond GJK's reach with the
/// support functions along its separating direction.
fn finish(
    result: GJKResult,
    reach: f64,
    a: &PolyBody,
    b: &PolyBody,
    q1: &Orientation,
) -> PolyDetection {
    match classify(result, reach, a.dilation, |v| q1 * v, &a.position) {
        // beyond GJK's reach: the gap along its separating direction (a proof of
        // separation the next steps can reuse, as for the pairs within reach)
        PolyDetection::Separated { normal, gap } if gap.is_nan() => {
            let x21 = b.position - a.position;
            let h = |body: &PolyBody, c: &V3| {
                let local = body.orientation.inverse_transform_vector(c);
                let v = from_parry(body.core.local_support_point(to_parry(&local)));
                (body.orientation * v).dot(c) + body.dilation
            };
            for c in [normal, -normal] {
                let g = c.dot(&x21) - h(a, &c) - h(b, &-c);
                if g > 0.0 {
                    return PolyDetection::Separated { normal: c, gap: g };
                }
            }
            PolyDetection::Separated { normal, gap }
        }
        found => found,
    }
}

/// Contact of a body with triangle `tri` (global corners; walls have no dilation). The
/// normal points from the body to the triangle; `core_point` is the triangle's closest point.
pub fn detect_triangle(a: &PolyBody, tri: &[V3; 3], warm: Option<V3>) -> PolyDetection {
    let q1 = a.orientation;
    let local = tri.map(|v| to_parry(&q1.inverse_transform_vector(&(v - a.position))));
    let triangle = Triangle::new(local[0], local[1], local[2]);
    let warm = warm.map(|n| to_parry(&q1.inverse_transform_vector(&n)));
    let result = closest(&Pose::IDENTITY, &a.core, &triangle, a.dilation, warm);
    classify(result, a.dilation, a.dilation, |v| q1 * v, &a.position)
}

/// Contact of a body with the plane through `point` of unit `normal` (pointing to the side
/// the body belongs to): the core's deepest vertex against the plane.
pub fn detect_plane(a: &PolyBody, point: &V3, normal: &V3) -> PolyDetection {
    let c = -normal; // from the body to the wall
    let local = a.orientation.inverse_transform_vector(&c);
    let deepest =
        a.position + a.orientation * from_parry(a.core.local_support_point(to_parry(&local)));
    let dist = (deepest - point).dot(normal);
    if dist <= 0.0 {
        return PolyDetection::CoresIntersect { depth: -dist };
    }
    if dist >= a.dilation {
        return PolyDetection::Separated {
            normal: c,
            gap: dist - a.dilation,
        };
    }
    let foot = deepest - normal * dist;
    PolyDetection::Contact {
        normal: c,
        overlap: a.dilation - dist,
        point: (deepest + foot) * 0.5,
        core_point: foot,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::generate::{random_orientation, random_unit_vector, SplitMix64};
    use crate::shape::Stone;

    fn body<'a>(s: &'a Stone, scale: f64, x: V3, q: Orientation) -> PolyBody<'a> {
        PolyBody {
            core: Core::Points {
                vertices: &s.vertices,
                scale,
            },
            dilation: s.dilation * scale,
            position: x,
            orientation: q,
        }
    }

    /// Two detections agree: contacts with overlaps within `overlap` and normals within
    /// `normal`, both separated, or core intersections of depths within `overlap`.
    fn assert_same(x: PolyDetection, y: PolyDetection, overlap: f64, normal: f64) {
        match (x, y) {
            (
                PolyDetection::Contact {
                    overlap: o1,
                    normal: n1,
                    ..
                },
                PolyDetection::Contact {
                    overlap: o2,
                    normal: n2,
                    ..
                },
            ) => {
                assert!((o1 - o2).abs() < overlap, "{o1} vs {o2}");
                assert!((n1 - n2).norm() < normal, "{n1} vs {n2}");
            }
            (PolyDetection::Separated { .. }, PolyDetection::Separated { .. }) => {}
            (
                PolyDetection::CoresIntersect { depth: d1 },
                PolyDetection::CoresIntersect { depth: d2 },
            ) => assert!((d1 - d2).abs() < overlap.max(1e-9), "{d1} {d2}"),
            other => panic!("{other:?}"),
        }
    }

    fn world(p: &PolyBody, s: &Stone) -> Vec<V3> {
        let Core::Points { scale, .. } = p.core else {
            unreachable!()
        };
        s.vertices
            .iter()
            .map(|v| p.position + p.orientation * (v * scale))
            .collect()
    }

    /// The separating-axis test of two convex polytopes (face normals and edge crossings):
    /// true iff their cores are disjoint.
    fn separated_by_an_axis(a: &PolyBody, sa: &Stone, b: &PolyBody, sb: &Stone) -> bool {
        let (va, vb) = (world(a, sa), world(b, sb));
        let edges = |v: &[V3], s: &Stone| -> Vec<V3> {
            s.triangles
                .iter()
                .flat_map(|t| (0..3).map(move |e| (t[e], t[(e + 1) % 3])))
                .map(|(i, j)| v[j as usize] - v[i as usize])
                .collect()
        };
        let normals = |v: &[V3], s: &Stone| -> Vec<V3> {
            s.triangles
                .iter()
                .map(|t| {
                    (v[t[1] as usize] - v[t[0] as usize])
                        .cross(&(v[t[2] as usize] - v[t[0] as usize]))
                })
                .collect()
        };
        let mut axes = normals(&va, sa);
        axes.extend(normals(&vb, sb));
        for e in edges(&va, sa) {
            for f in edges(&vb, sb) {
                axes.push(e.cross(&f));
            }
        }
        axes.iter().filter(|n| n.norm() > 1e-12).any(|n| {
            let n = n.normalize();
            let range = |v: &[V3]| {
                v.iter().fold((f64::MAX, f64::MIN), |(lo, hi), x| {
                    (lo.min(x.dot(&n)), hi.max(x.dot(&n)))
                })
            };
            let (ra, rb) = (range(&va), range(&vb));
            ra.1 < rb.0 || rb.1 < ra.0
        })
    }

    /// Brute-force core distance: the minimum over vertex–triangle and edge–edge pairs.
    fn brute_distance(a: &PolyBody, sa: &Stone, b: &PolyBody, sb: &Stone) -> f64 {
        let world = |p: &PolyBody, s: &Stone, scale: f64| -> Vec<V3> {
            s.vertices
                .iter()
                .map(|v| p.position + p.orientation * (v * scale))
                .collect()
        };
        let (Core::Points { scale: ka, .. }, Core::Points { scale: kb, .. }) = (a.core, b.core)
        else {
            unreachable!()
        };
        let (va, vb) = (world(a, sa, ka), world(b, sb, kb));
        let mut d = f64::INFINITY;
        for (vs, other, tris) in [(&va, &vb, &sb.triangles), (&vb, &va, &sa.triangles)] {
            for v in vs.iter() {
                for t in tris.iter() {
                    let [p, q, r] = t.map(|k| other[k as usize]);
                    d = d.min(crate::triangle_contact::distance_squared(v, &p, &q, &r).sqrt());
                }
            }
        }
        // exact segment–segment distance (Ericson, Real-Time Collision Detection 5.1.9)
        let seg = |p1: V3, q1: V3, p2: V3, q2: V3| -> f64 {
            let (d1, d2, r) = (q1 - p1, q2 - p2, p1 - p2);
            let (a, e, f) = (d1.dot(&d1), d2.dot(&d2), d2.dot(&r));
            let (c, b) = (d1.dot(&r), d1.dot(&d2));
            let denom = a * e - b * b;
            let mut s = if denom > 1e-300 {
                ((b * f - c * e) / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let mut t = (b * s + f) / e;
            if t < 0.0 {
                t = 0.0;
                s = (-c / a).clamp(0.0, 1.0);
            } else if t > 1.0 {
                t = 1.0;
                s = ((b - c) / a).clamp(0.0, 1.0);
            }
            ((p1 + d1 * s) - (p2 + d2 * t)).norm()
        };
        for ta in &sa.triangles {
            for tb in &sb.triangles {
                for e in 0..3 {
                    for f in 0..3 {
                        d = d.min(seg(
                            va[ta[e] as usize],
                            va[ta[(e + 1) % 3] as usize],
                            vb[tb[f] as usize],
                            vb[tb[(f + 1) % 3] as usize],
                        ));
                    }
                }
            }
        }
        d
    }

    /// GJK's overlap agrees with a brute-force distance of the cores on random pairs.
    #[test]
    fn pair_overlap_matches_a_brute_force_distance() {
        let mut rng = SplitMix64::new(9);
        let sa = Stone::random(30, 1.6, 0.1, &mut rng).unwrap();
        let sb = Stone::random(10, 1.3, 0.1, &mut rng).unwrap();
        let (mut contacts, mut intersections) = (0, 0);
        for _ in 0..400 {
            let a = body(&sa, 1.0, V3::zeros(), random_orientation(&mut rng));
            let dir = random_unit_vector(&mut rng);
            let x = dir * (0.75 + 0.3 * rng.uniform());
            let b = body(&sb, 0.8, x, random_orientation(&mut rng));
            let d = brute_distance(&a, &sa, &b, &sb);
            match detect_pair(&a, &b, None) {
                PolyDetection::Contact {
                    overlap, normal, ..
                } => {
                    contacts += 1;
                    let expected = a.dilation + b.dilation - d;
                    assert!(
                        (overlap - expected).abs() < 1e-10,
                        "{overlap} vs {expected}"
                    );
                    assert!((normal.norm() - 1.0).abs() < 1e-12);
                }
                PolyDetection::Separated { gap, .. } => {
                    assert!(separated_by_an_axis(&a, &sa, &b, &sb));
                    assert!(d >= a.dilation + b.dilation - 2e-5, "missed: {d}");
                    // the distance within GJK's reach, a lower bound beyond it
                    assert!(gap > 0.0 && gap <= d - a.dilation - b.dilation + 1e-10);
                }
                PolyDetection::CoresIntersect { depth } => {
                    assert!(
                        !separated_by_an_axis(&a, &sa, &b, &sb),
                        "cores {d} apart but said to intersect by {depth}"
                    );
                    intersections += 1;
                }
            }
        }
        println!("{contacts} contacts, {intersections} core intersections");
        assert!(
            contacts > 20 && intersections > 5,
            "{contacts} {intersections}"
        );
    }

    /// Warm-started from the last step's simplex, GJK gives the answer it gives from scratch
    /// (overlap to 1e-12 of the size) after the bodies moved and turned a little; the kept
    /// simplex names real vertices.
    #[test]
    fn a_warm_simplex_gives_the_cold_answer() {
        let mut rng = SplitMix64::new(31);
        let sa = Stone::random(30, 1.6, 0.1, &mut rng).unwrap();
        let sb = Stone::random(40, 1.3, 0.1, &mut rng).unwrap();
        let mut warm_used = 0;
        for _ in 0..500 {
            let (qa, qb) = (random_orientation(&mut rng), random_orientation(&mut rng));
            let x = random_unit_vector(&mut rng) * (0.85 + 0.25 * rng.uniform());
            let a = body(&sa, 1.0, V3::zeros(), qa);
            let b = body(&sb, 1.0, x, qb);
            let (first, simplex) = detect_pair_warm(&a, &b, None, &NO_SIMPLEX);
            assert!(simplex.iter().all(|&i| i == u16::MAX || (i as usize) < 22));
            // a small motion and turn
            let turn = crate::particles::Orientation::from_axis_angle(
                &nalgebra::Unit::new_normalize(random_unit_vector(&mut rng)),
                0.02 * rng.uniform(),
            );
            let b2 = body(
                &sb,
                1.0,
                x + random_unit_vector(&mut rng) * 0.003,
                turn * qb,
            );
            let normal = match first {
                PolyDetection::Contact { normal, .. } | PolyDetection::Separated { normal, .. } => {
                    Some(normal)
                }
                PolyDetection::CoresIntersect { .. } => None,
            };
            let (cold, _) = detect_pair_warm(&a, &b2, normal, &NO_SIMPLEX);
            let (warm, _) = detect_pair_warm(&a, &b2, normal, &simplex);
            if simplex[0] != u16::MAX {
                warm_used += 1;
            }
            assert_same(cold, warm, 1e-12, 1e-6);
        }
        assert!(warm_used > 300, "{warm_used}");
    }

    /// The closest-feature tracker, after a small motion and turn from a GJK answer: where it
    /// answers, its overlap (or proven gap) agrees with a brute-force distance of the cores to
    /// GJK's tolerance, and its normal and kept simplex with GJK's from scratch; it answers for
    /// most pairs (the closest features rarely change in a small motion); its simplex is
    /// tracked again at the next motion.
    /// With the vertex graphs (the support by climbing) and without (full scans).
    #[test]
    fn the_tracker_gives_the_brute_force_distance() {
        tracker_against_brute_force(true);
        tracker_against_brute_force(false);
    }

    fn tracker_against_brute_force(graphs: bool) {
        let mut rng = SplitMix64::new(77);
        let sa = Stone::random(30, 1.6, 0.1, &mut rng).unwrap();
        let sb = Stone::random(40, 1.3, 0.1, &mut rng).unwrap();
        let (graph_a, graph_b) = if graphs {
            (Some(&sa.adjacency), Some(&sb.adjacency))
        } else {
            (None, None)
        };
        let (mut answered, mut contacts, mut separated, mut tries) = (0, 0, 0, 0);
        // after a contact (GJK converged within its reach: the simplex names the features)
        let (mut after_contact, mut tracked_after_contact) = (0, 0);
        let rot = |b: &PolyBody| b.orientation.to_rotation_matrix().into_inner();
        for _ in 0..400 {
            let (qa, qb) = (random_orientation(&mut rng), random_orientation(&mut rng));
            let x = random_unit_vector(&mut rng) * (0.85 + 0.3 * rng.uniform());
            let a = body(&sa, 1.0, V3::new(0.1, -0.2, 0.3), qa);
            let mut b = body(&sb, 0.9, a.position + x, qb);
            let (first, mut simplex) = detect_pair_warm(&a, &b, None, &NO_SIMPLEX);
            let mut touching = matches!(first, PolyDetection::Contact { .. });
            for _ in 0..3 {
                let turn = Orientation::from_axis_angle(
                    &nalgebra::Unit::new_normalize(random_unit_vector(&mut rng)),
                    0.003 * rng.uniform(),
                );
                b.orientation = turn * b.orientation;
                b.position += random_unit_vector(&mut rng) * 0.001;
                tries += 1;
                let cold = detect_pair_warm(&a, &b, None, &NO_SIMPLEX).0;
                let was_touching = touching;
                after_contact += usize::from(was_touching);
                touching = matches!(cold, PolyDetection::Contact { .. });
                let Some((tracked, keep)) =
                    track_pair(&a, &b, &rot(&a), &rot(&b), &simplex, [graph_a, graph_b])
                else {
                    simplex = detect_pair_warm(&a, &b, None, &simplex).1;
                    continue;
                };
                answered += 1;
                tracked_after_contact += usize::from(was_touching);
                assert!(keep[0] != u16::MAX);
                let reach = a.dilation + b.dilation;
                let d = brute_distance(&a, &sa, &b, &sb);
                match tracked {
                    PolyDetection::Contact {
                        overlap,
                        normal,
                        point,
                        core_point,
                    } => {
                        contacts += 1;
                        assert!(
                            (overlap - (reach - d)).abs() < 1e-8 * d,
                            "{overlap} vs {}",
                            reach - d
                        );
                        assert!((normal.norm() - 1.0).abs() < 1e-12);
                        // the core point of b lies at the distance from a's core point
                        let c1 = point - normal * (a.dilation - 0.5 * overlap);
                        assert!(((core_point - c1).norm() - d).abs() < 1e-8 * d);
                        let PolyDetection::Contact { normal: n0, .. } = cold else {
                            panic!("GJK from scratch: {cold:?}")
                        };
                        assert!((normal - n0).norm() < 1e-4, "{normal} vs {n0}");
                    }
                    PolyDetection::Separated { gap, .. } => {
                        separated += 1;
                        assert!(d >= reach - 1e-8 * d, "{d} < {reach}");
                        assert!(gap >= 0.0 && gap <= d - reach + 1e-12, "{gap} {d} {reach}");
                        assert!(matches!(cold, PolyDetection::Separated { .. }), "{cold:?}");
                    }
                    PolyDetection::CoresIntersect { .. } => panic!("tracker: cores meet"),
                }
                simplex = keep;
            }
        }
        println!(
            "{answered} of {tries} tracked: {contacts} contacts, {separated} separated; \
             {tracked_after_contact} of {after_contact} after a contact"
        );
        assert!(
            contacts > 100 && separated > 20 && tracked_after_contact * 10 > after_contact * 8,
            "{answered} {tries} {contacts} {separated}"
        );
    }

    /// A sphere is a dilated point: sphere–sphere gives the exact overlap r1 + r2 − |x2 − x1|
    /// and the point halfway between the surfaces.
    #[test]
    fn spheres_as_dilated_points_are_exact() {
        let q = Orientation::identity();
        let a = PolyBody {
            core: Core::Points {
                vertices: &POINT_CORE,
                scale: 1.0,
            },
            dilation: 1.0,
            position: V3::zeros(),
            orientation: q,
        };
        let b = PolyBody {
            dilation: 0.5,
            position: V3::new(0.3, 1.2, 0.4),
            ..a
        };
        let d = b.position.norm();
        let PolyDetection::Contact {
            overlap,
            normal,
            point,
            ..
        } = detect_pair(&a, &b, None)
        else {
            panic!()
        };
        assert!((overlap - (1.5 - d)).abs() < 1e-14);
        assert!((normal - b.position / d).norm() < 1e-14);
        let mid = normal * (0.5 * (1.0 + d - 0.5));
        assert!((point - mid).norm() < 1e-14, "{point} vs {mid}");
    }

    /// Body against a plane and against a triangle of that plane give the same overlap where
    /// the body is over the triangle's interior.
    #[test]
    fn plane_and_triangle_agree() {
        let mut rng = SplitMix64::new(2);
        let s = Stone::random(30, 1.5, 0.1, &mut rng).unwrap();
        for _ in 0..50 {
            let q = random_orientation(&mut rng);
            let h = s.circumradius * (0.75 + 0.3 * rng.uniform());
            let a = body(&s, 1.0, V3::new(0.0, 0.0, h), q);
            let tri = [
                V3::new(-10.0, -10.0, 0.0),
                V3::new(10.0, -10.0, 0.0),
                V3::new(0.0, 10.0, 0.0),
            ];
            let p = detect_plane(&a, &V3::zeros(), &V3::z());
            let t = detect_triangle(&a, &tri, None);
            assert_same(p, t, 1e-10, 1e-8);
            if let PolyDetection::Contact { normal, .. } = p {
                assert!((normal + V3::z()).norm() < 1e-8);
            }
        }
    }
}
