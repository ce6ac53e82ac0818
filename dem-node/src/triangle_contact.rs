//! Particle–triangle contact geometry (Wellmann ch. 4).
//!
//! Wellmann's conditions for non-smooth contact are: (I) exact Hertz–Mindlin for a plane
//! contact, (II) no force jump at face/edge/vertex transitions, (III) energy conservation in a
//! frictionless elastic impact, i.e. a curl-free force field (ch. 4.1.1). His interpolated force
//! (4.6) meets I–II and reduces the curl of per-triangle weighting (4.5) twentyfold, but it is
//! not curl-free, and its ε-term does not keep the normal force exactly constant while a sphere
//! crosses coplanar triangles.
//!
//! We use an equivalent scheme that meets I–III exactly for spheres: triangles are grouped into
//! patches joined across convex or coplanar edges (`walls::compute_patches`), and a sphere
//! makes ONE contact per patch, at the closest point c of the patch, with overlap
//! δ = r − |x − c| and normal (x − c)/|x − c|. Then
//! - I: in the interior of a face this is the plane contact;
//! - III: the normal force is −∇W(d(x)) with the Hertz potential W(δ) = 8/15 E*√r δ^{5/2} and
//!   d the distance to the patch — a gradient field, so conservative;
//! - II: across a convex edge the closest point moves continuously from the face onto the
//!   edge and its normal turns continuously from the face normal, so the force has no jump;
//!   across coplanar triangles the closest point and δ do not change at all (constant normal
//!   force, no double counting). Concave edges bound patches: a sphere in a corner touches
//!   both faces, each with its own continuous contact. Edges that are concave by less than
//!   1° stay in one patch (d is still continuous, the normal turns by < 1° at the bisector).
//!
//! The contact point c lies on a triangle with barycentric weights (N_1, N_2, N_3) (4.3);
//! forces on a coupled mesh go to its nodes as f_K = −N_K f (4.4), which conserves the total
//! force and the moment about any point.

use crate::hertz_mindlin::V3;

/// Closest point of triangle (a, b, c) to p, with its barycentric coordinates
/// (Ericson, Real-Time Collision Detection, 5.1.5).
#[inline]
pub fn closest_point_on_triangle(p: &V3, a: &V3, b: &V3, c: &V3) -> (V3, [f64; 3]) {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(&ap);
    let d2 = ac.dot(&ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return (*a, [1.0, 0.0, 0.0]);
    }
    let bp = p - b;
    let d3 = ab.dot(&bp);
    let d4 = ac.dot(&bp);
    if d3 >= 0.0 && d4 <= d3 {
        return (*b, [0.0, 1.0, 0.0]);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (a + ab * v, [1.0 - v, v, 0.0]);
    }
    let cp = p - c;
    let d5 = ab.dot(&cp);
    let d6 = ac.dot(&cp);
    if d6 >= 0.0 && d5 <= d6 {
        return (*c, [0.0, 0.0, 1.0]);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (a + ac * w, [1.0 - w, 0.0, w]);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + (c - b) * w, [0.0, 1.0 - w, w]);
    }
    let denom = 1.0 / (va + vb + vc);
    let v = vb * denom;
    let w = vc * denom;
    (a + ab * v + ac * w, [1.0 - v - w, v, w])
}

/// Squared distance of p to triangle (a, b, c).
#[inline]
pub fn distance_squared(p: &V3, a: &V3, b: &V3, c: &V3) -> f64 {
    let (q, _) = closest_point_on_triangle(p, a, b, c);
    (p - q).norm_squared()
}
