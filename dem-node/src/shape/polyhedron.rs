//! Dilated convex polyhedra (sphero-polyhedra): Ullrich's ballast (U §2.1.1, (2.4)–(2.5);
//! SEED-SPEC §6.1). A body is a convex core (a closed triangle mesh, the convex hull of its
//! vertices) Minkowski-summed with a ball of radius r_ds: its surface is the core faces offset
//! by r_ds, cylinders along the edges and sphere caps at the vertices.
//!
//! A [`Stone`] is one such shape at unit size, in the principal frame of the dilated body
//! (origin at its centre of mass); a particle is a scaled, rotated copy. The size measure
//! (the thesis's undefined "characteristic length", SEED-SPEC §6.1) is here the
//! **equivalent-volume diameter of the dilated body**, so a stone of size L has the volume of
//! a sphere of diameter L, and r_ds = `dilation` × L (U: 10 %). The particle sources' radius
//! is then L/2, as for spheres and superquadrics.
//!
//! Mass properties (*not in thesis*): the dilated body is the disjoint union of the core,
//! one prism over every face (height r_ds), one cylinder wedge along every edge (angle
//! π − θ_e, θ_e the interior dihedral angle) and one ball sector at every vertex (its normal
//! cone). The volume is Steiner's formula
//!
//! ```text
//! V = V_core + S_core r + ½ Σ_edges ℓ_e (π − θ_e) r² + 4/3 π r³
//! ```
//!
//! and the first and second moments are summed over the same pieces: core tetrahedra and
//! prisms exactly (their integrands are polynomials), wedges in closed form, the vertex
//! sectors by Gauss quadrature over the spherical polygons of their normal cones (the cones
//! tile the sphere: Σ Ω = 4π is checked to round-off in the tests).

use crate::generate::{random_unit_vector, SplitMix64};
use crate::hertz_mindlin::V3;
use nalgebra::{Matrix3, SymmetricEigen};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::f64::consts::PI;

/// Largest dilation ratio r_ds / L accepted (a ball of diameter L has r = L/2; U uses 0.1,
/// shows 0.2).
pub const DILATION_MAX: f64 = 0.3;

/// A dilated convex polyhedron at unit size (equivalent-volume diameter 1) in the principal
/// frame of the dilated body.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(from = "StoneRecord")]
pub struct Stone {
    /// Core vertices (body frame, unit size).
    pub vertices: Vec<V3>,
    /// Core triangles, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
    /// Dilation radius r_ds at unit size (= the ratio r_ds / L).
    pub dilation: f64,
    /// Volume of the dilated body at unit size (π/6 by construction).
    pub volume: f64,
    /// Principal moments of inertia of the dilated body per unit density at unit size
    /// (they scale with ρ L⁵).
    pub inertia: V3,
    /// max |vertex| + dilation: the bounding radius at unit size.
    pub circumradius: f64,
    /// The core's edges as each vertex's neighbours (derived from `triangles`, not stored).
    #[serde(skip_serializing)]
    pub adjacency: Adjacency,
}

/// A [`Stone`] as stored: its adjacency is rebuilt on reading.
#[derive(Deserialize)]
struct StoneRecord {
    vertices: Vec<V3>,
    triangles: Vec<[u32; 3]>,
    dilation: f64,
    volume: f64,
    inertia: V3,
    circumradius: f64,
}

impl From<StoneRecord> for Stone {
    fn from(r: StoneRecord) -> Stone {
        Stone {
            adjacency: Adjacency::of(r.vertices.len(), &r.triangles),
            vertices: r.vertices,
            triangles: r.triangles,
            dilation: r.dilation,
            volume: r.volume,
            inertia: r.inertia,
            circumradius: r.circumradius,
        }
    }
}

/// The vertex graph of a triangulated convex core: each vertex's neighbours, in compressed
/// rows.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Adjacency {
    start: Vec<u16>,
    next: Vec<u16>,
}

impl Adjacency {
    /// The graph of the edges of `triangles` over `vertices` vertices.
    pub fn of(vertices: usize, triangles: &[[u32; 3]]) -> Adjacency {
        let mut lists: Vec<Vec<u16>> = vec![Vec::new(); vertices];
        for t in triangles {
            for e in 0..3 {
                let (i, j) = (t[e] as usize, t[(e + 1) % 3] as usize);
                if i < vertices && j < vertices {
                    lists[i].push(j as u16);
                    lists[j].push(i as u16);
                }
            }
        }
        let mut start = vec![0u16];
        let mut next = Vec::new();
        for mut l in lists {
            l.sort_unstable();
            l.dedup();
            next.extend(l);
            start.push(next.len() as u16);
        }
        Adjacency { start, next }
    }

    /// The neighbours of vertex `i`.
    #[inline]
    pub fn neighbours(&self, i: usize) -> &[u16] {
        &self.next[self.start[i] as usize..self.start[i + 1] as usize]
    }

    /// The vertex furthest along `d` and its height, by climbing the graph from `from`: on a
    /// convex core a vertex no neighbour of which is higher is the highest (the height grows
    /// strictly at each move, so the climb ends). `None` without a graph.
    #[inline]
    pub fn climb(&self, vertices: &[V3], from: usize, d: &V3) -> Option<(usize, f64)> {
        if self.start.len() != vertices.len() + 1 || from >= vertices.len() {
            return None;
        }
        let (mut at, mut h) = (from, vertices[from].dot(d));
        loop {
            let mut moved = false;
            for &k in self.neighbours(at) {
                let x = vertices[k as usize].dot(d);
                if x > h {
                    (at, h, moved) = (k as usize, x, true);
                }
            }
            if !moved {
                return Some((at, h));
            }
        }
    }
}

/// Volume, centre of mass and inertia tensor (about the centre of mass) at unit density.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MassProperties {
    pub volume: f64,
    pub centroid: V3,
    pub inertia: Matrix3<f64>,
}

/// Mass, first and second moments ∫1, ∫x, ∫x⊗x of a body at unit density.
#[derive(Debug, Clone, Copy)]
struct Moments {
    m: f64,
    s: V3,
    j: Matrix3<f64>,
}

impl Moments {
    fn zero() -> Moments {
        Moments {
            m: 0.0,
            s: V3::zeros(),
            j: Matrix3::zeros(),
        }
    }

    fn properties(&self) -> MassProperties {
        let c = self.s / self.m;
        let jc = self.j - c * c.transpose() * self.m;
        MassProperties {
            volume: self.m,
            centroid: c,
            inertia: Matrix3::identity() * jc.trace() - jc,
        }
    }
}

/// Gauss–Legendre nodes and weights on [0, 1].
fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        // Newton on P_n from the Chebyshev guess
        let mut x = (PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut dp = 1.0;
        for _ in 0..100 {
            let (mut p0, mut p1) = (1.0, x);
            for k in 2..=n {
                let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                p0 = p1;
                p1 = p2;
            }
            dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
            let dx = p1 / dp;
            x -= dx;
            if dx.abs() < 1e-16 {
                break;
            }
        }
        let w = 2.0 / ((1.0 - x * x) * dp * dp);
        out.push((0.5 * (1.0 - x), 0.5 * w));
    }
    out
}

/// ∫ dΩ, ∫ u dΩ and ∫ u⊗u dΩ over the spherical triangle (a, b, c) (unit vectors, smaller
/// than a hemisphere): the planar triangle p(s, t) = a + s(b − a) + t(c − a) maps to it by
/// u = p/|p| with dΩ = |det[a, b, c]| / |p|³ ds dt; collapsed (Duffy) Gauss product rule.
/// Triangles wider than 0.5 rad are split in four at their (normalised) edge midpoints first.
fn spherical_triangle(a: &V3, b: &V3, c: &V3, rule: &[(f64, f64)]) -> (f64, V3, Matrix3<f64>) {
    let cos_max = 0.5f64.cos();
    if a.dot(b).min(b.dot(c)).min(c.dot(a)) < cos_max {
        let (ab, bc, ca) = (
            (a + b).normalize(),
            (b + c).normalize(),
            (c + a).normalize(),
        );
        let mut sum = (0.0, V3::zeros(), Matrix3::zeros());
        for [p, q, r] in [[a, &ab, &ca], [&ab, b, &bc], [&ca, &bc, c], [&ab, &bc, &ca]] {
            let (w0, w1, w2) = spherical_triangle(p, q, r, rule);
            sum.0 += w0;
            sum.1 += w1;
            sum.2 += w2;
        }
        return sum;
    }
    let det = a.dot(&b.cross(c)).abs();
    let (mut w0, mut w1, mut w2) = (0.0, V3::zeros(), Matrix3::zeros());
    if det == 0.0 {
        return (w0, w1, w2);
    }
    for &(x, wx) in rule {
        for &(y, wy) in rule {
            let (s, t) = (x * (1.0 - y), x * y);
            let p = a + (b - a) * s + (c - a) * t;
            let len = p.norm();
            let u = p / len;
            let w = wx * wy * x * det / (len * len * len);
            w0 += w;
            w1 += u * w;
            w2 += u * u.transpose() * w;
        }
    }
    (w0, w1, w2)
}

/// The edges of a closed triangle mesh with their two triangles: (a, b) → [t1, t2] for a < b.
type EdgeFaces = Vec<([u32; 2], [usize; 2])>;

fn edge_faces(triangles: &[[u32; 3]]) -> Result<EdgeFaces, String> {
    let mut map: HashMap<[u32; 2], Vec<usize>> = HashMap::new();
    for (t, tri) in triangles.iter().enumerate() {
        for e in 0..3 {
            let (a, b) = (tri[e], tri[(e + 1) % 3]);
            map.entry([a.min(b), a.max(b)]).or_default().push(t);
        }
    }
    let mut edges: EdgeFaces = Vec::with_capacity(map.len());
    for (e, faces) in map {
        if faces.len() != 2 {
            return Err(format!(
                "edge {:?} belongs to {} triangles: the core is not a closed surface",
                e,
                faces.len()
            ));
        }
        edges.push((e, [faces[0], faces[1]]));
    }
    edges.sort_unstable();
    Ok(edges)
}

/// Mass properties (unit density) of the convex core `vertices`/`triangles` (closed,
/// counter-clockwise seen from outside) dilated by `r` ≥ 0.
pub fn dilated_mass_properties(
    vertices: &[V3],
    triangles: &[[u32; 3]],
    r: f64,
) -> Result<MassProperties, String> {
    let mut mo = Moments::zero();
    let v = |k: u32| vertices[k as usize];
    let origin = vertices.iter().sum::<V3>() / vertices.len() as f64;
    let normals: Vec<V3> = triangles
        .iter()
        .map(|t| (v(t[1]) - v(t[0])).cross(&(v(t[2]) - v(t[0]))))
        .collect();
    // core: tetrahedra (origin, a, b, c); ∫x⊗x = V/20 (Σ p pᵀ + s sᵀ)
    for t in triangles {
        let p = [origin, v(t[0]), v(t[1]), v(t[2])];
        let vol = (p[1] - p[0]).dot(&(p[2] - p[0]).cross(&(p[3] - p[0]))) / 6.0;
        let s: V3 = p.iter().sum();
        let pp: Matrix3<f64> = p.iter().map(|q| q * q.transpose()).sum();
        mo.m += vol;
        mo.s += s * (vol / 4.0);
        mo.j += (pp + s * s.transpose()) * (vol / 20.0);
    }
    if mo.m <= 0.0 {
        return Err(format!(
            "the core has volume {:e}: its triangles must be counter-clockwise seen from outside",
            mo.m
        ));
    }
    if r > 0.0 {
        // face prisms {y + t n}: degree-2 integrands, 3-point triangle rule × 2-point Gauss
        let tri_rule = [
            (1.0 / 6.0, 1.0 / 6.0),
            (2.0 / 3.0, 1.0 / 6.0),
            (1.0 / 6.0, 2.0 / 3.0),
        ];
        let g = 0.5 / 3f64.sqrt();
        for (t, n2) in triangles.iter().zip(&normals) {
            let area = 0.5 * n2.norm();
            if area == 0.0 {
                continue;
            }
            let n = n2 / (2.0 * area);
            let (a, b, c) = (v(t[0]), v(t[1]), v(t[2]));
            for (u, w) in tri_rule {
                let y = a + (b - a) * u + (c - a) * w;
                for h in [0.5 - g, 0.5 + g] {
                    let x = y + n * (h * r);
                    let weight = area / 3.0 * r * 0.5;
                    mo.m += weight;
                    mo.s += x * weight;
                    mo.j += x * x.transpose() * weight;
                }
            }
        }
        // edge wedges x = p + s e + ρ (cos φ n1 + sin φ w), s ∈ [0, ℓ], ρ ∈ [0, r], φ ∈ [0, α]
        for ([i, j], [f1, f2]) in edge_faces(triangles)? {
            let (p, q) = (v(i), v(j));
            let (n1, n2) = (normals[f1].normalize(), normals[f2].normalize());
            let alpha = n1.dot(&n2).clamp(-1.0, 1.0).acos();
            if alpha < 1e-12 {
                continue; // coplanar triangles: no wedge
            }
            let w = (n2 - n1 * n1.dot(&n2)).normalize();
            let len = (q - p).norm();
            let e = (q - p) / len;
            let (a0, a1, a2) = (r * r / 2.0, r.powi(3) / 3.0, r.powi(4) / 4.0);
            let (s0, s1, s2) = (len, len * len / 2.0, len.powi(3) / 3.0);
            let (sa, ca) = alpha.sin_cos();
            let d1 = n1 * sa + w * (1.0 - ca);
            let (icc, iss, ics) = (
                alpha / 2.0 + (2.0 * alpha).sin() / 4.0,
                alpha / 2.0 - (2.0 * alpha).sin() / 4.0,
                sa * sa / 2.0,
            );
            let d2 = n1 * n1.transpose() * icc
                + w * w.transpose() * iss
                + (n1 * w.transpose() + w * n1.transpose()) * ics;
            let sym = |a: &V3, b: &V3| a * b.transpose() + b * a.transpose();
            mo.m += a0 * s0 * alpha;
            mo.s += (p * s0 + e * s1) * (a0 * alpha) + d1 * (a1 * s0);
            mo.j += (p * p.transpose() * s0 + sym(&p, &e) * s1 + e * e.transpose() * s2)
                * (a0 * alpha)
                + (sym(&p, &d1) * s0 + sym(&e, &d1) * s1) * a1
                + d2 * (a2 * s0);
        }
        // vertex sectors {v + ρ u}, u in the normal cone of v (a convex spherical polygon
        // of the incident face normals in cyclic order), fanned from its mean direction
        let rule = gauss_legendre(16);
        for (k, cone) in normal_cones(vertices.len(), triangles, &normals)?
            .iter()
            .enumerate()
        {
            let mean = cone.iter().sum::<V3>().normalize();
            let (mut om, mut u1, mut u2) = (0.0, V3::zeros(), Matrix3::zeros());
            for i in 0..cone.len() {
                let (a, b) = (cone[i], cone[(i + 1) % cone.len()]);
                let (w0, w1, w2) = spherical_triangle(&mean, &a, &b, &rule);
                om += w0;
                u1 += w1;
                u2 += w2;
            }
            let x = vertices[k];
            let m = r.powi(3) / 3.0 * om;
            let r4 = r.powi(4) / 4.0;
            mo.m += m;
            mo.s += x * m + u1 * r4;
            mo.j += x * x.transpose() * m
                + (x * u1.transpose() + u1 * x.transpose()) * r4
                + u2 * (r.powi(5) / 5.0);
        }
    }
    Ok(mo.properties())
}

/// Steiner's coefficients of a convex core: its volume, its area and ½ Σ_edges ℓ_e (π − θ_e).
fn steiner_coefficients(
    vertices: &[V3],
    triangles: &[[u32; 3]],
) -> Result<(f64, f64, f64), String> {
    let v = |k: u32| vertices[k as usize];
    let normals: Vec<V3> = triangles
        .iter()
        .map(|t| (v(t[1]) - v(t[0])).cross(&(v(t[2]) - v(t[0]))))
        .collect();
    let volume = triangles
        .iter()
        .map(|t| v(t[0]).dot(&v(t[1]).cross(&v(t[2]))) / 6.0)
        .sum();
    let area = normals.iter().map(|n| 0.5 * n.norm()).sum();
    let mut edges = 0.0;
    for ([i, j], [f1, f2]) in edge_faces(triangles)? {
        let alpha = normals[f1]
            .normalize()
            .dot(&normals[f2].normalize())
            .clamp(-1.0, 1.0)
            .acos();
        edges += 0.5 * (v(j) - v(i)).norm() * alpha;
    }
    Ok((volume, area, edges))
}

/// For every vertex, the unit normals of its triangles in cyclic order around it.
fn normal_cones(
    n_vertices: usize,
    triangles: &[[u32; 3]],
    normals: &[V3],
) -> Result<Vec<Vec<V3>>, String> {
    // around vertex v, triangle (v, a, b) is followed by the triangle (v, b, c)
    let mut next: Vec<Vec<(u32, u32, usize)>> = vec![Vec::new(); n_vertices];
    for (t, tri) in triangles.iter().enumerate() {
        for e in 0..3 {
            next[tri[e] as usize].push((tri[(e + 1) % 3], tri[(e + 2) % 3], t));
        }
    }
    next.iter()
        .enumerate()
        .map(|(v, fan)| {
            if fan.len() < 3 {
                return Err(format!(
                    "vertex {v} has {} triangles (at least 3)",
                    fan.len()
                ));
            }
            let mut cone = Vec::with_capacity(fan.len());
            let mut at = 0;
            for _ in 0..fan.len() {
                cone.push(normals[fan[at].2].normalize());
                let b = fan[at].1;
                at = fan
                    .iter()
                    .position(|f| f.0 == b)
                    .ok_or_else(|| format!("the triangles around vertex {v} do not close"))?;
            }
            if at != 0 {
                return Err(format!("the triangles around vertex {v} do not close"));
            }
            Ok(cone)
        })
        .collect()
}

fn to_parry(x: &V3) -> parry3d_f64::math::Vector {
    parry3d_f64::math::Vector::new(x.x, x.y, x.z)
}

/// The convex hull of `points` (outward triangles), refusing degenerate point sets.
fn hull(points: &[V3]) -> Result<(Vec<V3>, Vec<[u32; 3]>), String> {
    if points.len() < 4 {
        return Err(format!(
            "{} points: a core needs at least 4 that are not coplanar",
            points.len()
        ));
    }
    if let Some(k) = points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        return Err(format!("point {k} is not finite: {:?}", points[k]));
    }
    let pts: Vec<_> = points.iter().map(to_parry).collect();
    let (hv, ht) = parry3d_f64::transformation::try_convex_hull(&pts)
        .map_err(|e| format!("no convex hull of the points ({e:?}): are they coplanar?"))?;
    let vertices: Vec<V3> = hv.iter().map(|p| V3::new(p.x, p.y, p.z)).collect();
    let mut triangles = ht;
    let signed: f64 = triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|k| vertices[k as usize]);
            a.dot(&b.cross(&c))
        })
        .sum();
    let extent = vertices
        .iter()
        .map(|v| v.norm())
        .fold(0.0, f64::max)
        .max(1e-300);
    if signed.abs() < 1e-9 * extent.powi(3) {
        return Err("the points are (nearly) coplanar: the core has no volume".into());
    }
    if signed < 0.0 {
        for t in triangles.iter_mut() {
            t.swap(1, 2);
        }
    }
    Ok((vertices, triangles))
}

/// Index of the vertex furthest along `d` (the first of equals): the hot loop of GJK. Four
/// independent lanes without branches, so the comparisons neither mispredict nor wait on
/// each other.
#[inline]
pub fn support_index(vertices: &[V3], d: &V3) -> usize {
    let n = vertices.len();
    let dot = |v: &V3| v.x * d.x + v.y * d.y + v.z * d.z;
    if n < 8 {
        let (mut best, mut h) = (0, dot(&vertices[0]));
        for (i, v) in vertices.iter().enumerate().skip(1) {
            let x = dot(v);
            if x > h {
                (best, h) = (i, x);
            }
        }
        return best;
    }
    let mut h = [f64::NEG_INFINITY; 4];
    let mut at = [0usize; 4];
    let chunks = n / 4;
    for c in 0..chunks {
        for l in 0..4 {
            let i = 4 * c + l;
            let x = dot(&vertices[i]);
            let better = x > h[l];
            h[l] = if better { x } else { h[l] };
            at[l] = if better { i } else { at[l] };
        }
    }
    for (l, v) in vertices[4 * chunks..].iter().enumerate() {
        let x = dot(v);
        if x > h[l] {
            (h[l], at[l]) = (x, 4 * chunks + l);
        }
    }
    // the largest value, the smallest index among equals
    let mut best = 0;
    for l in 1..4 {
        if h[l] > h[best] || (h[l] == h[best] && at[l] < at[best]) {
            best = l;
        }
    }
    at[best]
}

impl Stone {
    /// The stone whose core is the convex hull of `points`, dilated by `dilation` × its size
    /// (equivalent-volume diameter of the dilated body), scaled to unit size and turned into
    /// its principal frame.
    pub fn from_points(points: &[V3], dilation: f64) -> Result<Stone, String> {
        if !(dilation > 0.0 && dilation <= DILATION_MAX) {
            return Err(format!(
                "dilation {dilation} of the size: must be in (0, {DILATION_MAX}] (Ullrich: 0.1)"
            ));
        }
        let (vertices, triangles) = hull(points)?;
        // scale s of the core so that V(s) = V_c s³ + S s² r + E s r² + 4/3π r³ = π/6 with
        // r = dilation (Steiner; increasing in s)
        let (vc, area, e) = steiner_coefficients(&vertices, &triangles)?;
        let r = dilation;
        let vol = |s: f64| ((vc * s + area * r) * s + e * r * r) * s + 4.0 / 3.0 * PI * r.powi(3);
        let target = PI / 6.0;
        let (mut lo, mut hi) = (
            0.0,
            1.0 / vertices.iter().map(|v| v.norm()).fold(0.0, f64::max),
        );
        while vol(hi) < target {
            hi *= 2.0;
        }
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if vol(mid) < target {
                lo = mid;
            } else {
                hi = mid;
            }
            if hi - lo <= 1e-15 * hi {
                break;
            }
        }
        let s = 0.5 * (lo + hi);
        let scaled: Vec<V3> = vertices.iter().map(|v| v * s).collect();
        let mp = dilated_mass_properties(&scaled, &triangles, dilation)?;
        let eig = SymmetricEigen::new(mp.inertia);
        let mut q = eig.eigenvectors;
        if q.determinant() < 0.0 {
            q.set_column(2, &(-q.column(2)));
        }
        let vertices: Vec<V3> = scaled
            .iter()
            .map(|v| q.tr_mul(&(v - mp.centroid)))
            .collect();
        let circumradius = vertices.iter().map(|v| v.norm()).fold(0.0, f64::max) + dilation;
        Ok(Stone {
            adjacency: Adjacency::of(vertices.len(), &triangles),
            vertices,
            triangles,
            dilation,
            volume: mp.volume,
            inertia: eig.eigenvalues,
            circumradius,
        })
    }

    /// A stone from a closed triangle mesh (an STL of a scanned stone): its convex hull,
    /// refused if the mesh is not convex (a vertex or a triangle centre inside the hull by
    /// more than 1e-6 of the stone's extent).
    pub fn from_mesh(
        vertices: &[V3],
        triangles: &[[u32; 3]],
        dilation: f64,
    ) -> Result<Stone, String> {
        let (hv, ht) = hull(vertices)?;
        let planes: Vec<(V3, f64)> = ht
            .iter()
            .filter_map(|t| {
                let [a, b, c] = t.map(|k| hv[k as usize]);
                let n = (b - a).cross(&(c - a));
                (n.norm() > 0.0).then(|| {
                    let n = n.normalize();
                    (n, n.dot(&a))
                })
            })
            .collect();
        let centre = hv.iter().sum::<V3>() / hv.len() as f64;
        let extent = hv.iter().map(|v| (v - centre).norm()).fold(0.0, f64::max);
        let depth = |p: &V3| {
            -planes
                .iter()
                .map(|(n, d)| n.dot(p) - d)
                .fold(f64::MIN, f64::max)
        };
        for (k, p) in vertices.iter().enumerate() {
            if depth(p) > 1e-6 * extent {
                return Err(format!(
                    "not convex: vertex {k} at {:?} lies {:.3e} inside the convex hull",
                    [p.x, p.y, p.z],
                    depth(p)
                ));
            }
        }
        for (k, t) in triangles.iter().enumerate() {
            let c = t.iter().map(|&i| vertices[i as usize]).sum::<V3>() / 3.0;
            if depth(&c) > 1e-6 * extent {
                return Err(format!(
                    "not convex: triangle {k} lies {:.3e} inside the convex hull",
                    depth(&c)
                ));
            }
        }
        Stone::from_points(&hv, dilation)
    }

    /// A random convex stone with `triangles` core triangles (even, ≥ 4; F = 2V − 4, so
    /// 10 / 30 / 40 triangles have 7 / 17 / 22 vertices): vertices on an ellipsoid of axes
    /// 1 ≥ b ≥ c, each of b, c uniform in [1/`elongation`, 1], at random directions kept at
    /// least half the mean spacing apart (no slivers).
    pub fn random(
        triangles: usize,
        elongation: f64,
        dilation: f64,
        rng: &mut SplitMix64,
    ) -> Result<Stone, String> {
        if triangles < 4 || triangles % 2 != 0 || triangles > 1000 {
            return Err(format!(
                "{triangles} triangles: a closed convex core has an even number ≥ 4 (≤ 1000)"
            ));
        }
        if !(elongation >= 1.0 && elongation.is_finite()) {
            return Err(format!("elongation {elongation}: must be ≥ 1"));
        }
        let n = (triangles + 4) / 2;
        let axes = {
            let mut b = [
                1.0,
                1.0 / elongation + (1.0 - 1.0 / elongation) * rng.uniform(),
                0.0,
            ];
            b[2] = 1.0 / elongation + (1.0 - 1.0 / elongation) * rng.uniform();
            V3::new(b[0], b[1].max(b[2]), b[1].min(b[2]))
        };
        let min_angle = 0.5 * (4.0 * PI / n as f64).sqrt();
        for _attempt in 0..1000 {
            let mut dirs: Vec<V3> = Vec::with_capacity(n);
            let mut tries = 0;
            while dirs.len() < n && tries < 100_000 {
                tries += 1;
                let d = random_unit_vector(rng);
                if dirs.iter().all(|e| e.dot(&d) < min_angle.cos()) {
                    dirs.push(d);
                }
            }
            if dirs.len() < n {
                continue;
            }
            let points: Vec<V3> = dirs.iter().map(|d| d.component_mul(&axes)).collect();
            if let Ok((hv, ht)) = hull(&points) {
                if hv.len() == n && ht.len() == triangles {
                    return Stone::from_points(&hv, dilation);
                }
            }
        }
        Err(format!(
            "no random stone with {triangles} triangles in 1000 attempts"
        ))
    }

    /// Checks a stone read from a file: finite values, triangles naming existing vertices,
    /// the dilation in range, positive volume and moments, and the bounding radius it
    /// claims.
    pub fn check(&self) -> Result<(), String> {
        if self.vertices.len() < 4 || self.triangles.len() < 4 {
            return Err(format!(
                "{} vertices and {} triangles: a core has at least 4 of each",
                self.vertices.len(),
                self.triangles.len()
            ));
        }
        if let Some(k) = self
            .vertices
            .iter()
            .position(|v| !v.iter().all(|c| c.is_finite()))
        {
            return Err(format!("vertex {k} is not finite"));
        }
        let n = self.vertices.len() as u32;
        if let Some(k) = self
            .triangles
            .iter()
            .position(|t| t.iter().any(|&i| i >= n))
        {
            return Err(format!(
                "triangle {k} names a vertex beyond the {n} there are"
            ));
        }
        if !(self.dilation > 0.0 && self.dilation <= DILATION_MAX) {
            return Err(format!(
                "dilation {} outside (0, {DILATION_MAX}]",
                self.dilation
            ));
        }
        if !(self.volume > 0.0 && self.inertia.iter().all(|i| *i > 0.0 && i.is_finite())) {
            return Err(format!(
                "volume {} and moments {:?} must be positive",
                self.volume,
                self.inertia.as_slice()
            ));
        }
        let reach = self.vertices.iter().map(|v| v.norm()).fold(0.0, f64::max) + self.dilation;
        if (reach - self.circumradius).abs() > 1e-12 * reach {
            return Err(format!(
                "bounding radius {} but the vertices reach {reach}",
                self.circumradius
            ));
        }
        Ok(())
    }

    /// Support point of the core at unit size: the vertex furthest along `dir`.
    #[inline]
    pub fn support(&self, dir: &V3) -> V3 {
        self.vertices[support_index(&self.vertices, dir)]
    }

    /// The dilated surface at unit size for drawing: the convex hull of points on the exact
    /// surface — every core vertex offset by the dilation along the normals of its faces,
    /// along 3 directions on the arc of each of its edges, and along those of `directions`
    /// Fibonacci-sphere directions that lie in its normal cone (it is their support vertex).
    /// Faces stay flat; edges and vertex caps come out faceted.
    pub fn surface(&self, directions: usize) -> (Vec<V3>, Vec<[u32; 3]>) {
        let r = self.dilation;
        let v = |k: u32| self.vertices[k as usize];
        let normal = |t: &[u32; 3]| (v(t[1]) - v(t[0])).cross(&(v(t[2]) - v(t[0]))).normalize();
        let mut points = Vec::new();
        for t in &self.triangles {
            let n = normal(t);
            points.extend(t.iter().map(|&k| v(k) + n * r));
        }
        if let Ok(edges) = edge_faces(&self.triangles) {
            for ([i, j], [f1, f2]) in edges {
                let (n1, n2) = (normal(&self.triangles[f1]), normal(&self.triangles[f2]));
                for w in [0.25, 0.5, 0.75] {
                    // normalised linear blend: on the arc between the two face normals
                    let d = (n1 * (1.0 - w) + n2 * w).normalize();
                    points.extend([v(i) + d * r, v(j) + d * r]);
                }
            }
        }
        let n = directions.max(4);
        let golden = PI * (3.0 - 5f64.sqrt());
        for i in 0..n {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let rho = (1.0 - z * z).sqrt();
            let phi = golden * i as f64;
            let d = V3::new(rho * phi.cos(), rho * phi.sin(), z);
            points.push(self.support(&d) + d * r);
        }
        // a stone's dilated points are never coplanar: the hull exists
        hull(&points).unwrap_or_else(|_| (self.vertices.clone(), self.triangles.clone()))
    }

    /// Volume of the core at unit size.
    pub fn core_volume(&self) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|k| self.vertices[k as usize]);
                a.dot(&b.cross(&c)) / 6.0
            })
            .sum()
    }

    /// Radius of the largest ball about the centre inside the dilated body, at unit size.
    pub fn inradius(&self) -> f64 {
        self.triangles
            .iter()
            .filter_map(|t| {
                let [a, b, c] = t.map(|k| self.vertices[k as usize]);
                let n = (b - a).cross(&(c - a));
                (n.norm() > 0.0).then(|| n.normalize().dot(&a))
            })
            .fold(f64::INFINITY, f64::min)
            + self.dilation
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube(a: f64) -> (Vec<V3>, Vec<[u32; 3]>) {
        let mut pts = Vec::new();
        for k in 0..8 {
            pts.push(V3::new(
                a * (k & 1) as f64,
                a * ((k >> 1) & 1) as f64,
                a * ((k >> 2) & 1) as f64,
            ));
        }
        hull(&pts).unwrap()
    }

    /// Steiner's formula for a dilated cube is exact: a³ + 6a²r + 3πar² + 4/3πr³ (12 edges of
    /// right dihedral angle, each a quarter cylinder); the centre is the cube's, the inertia
    /// isotropic.
    #[test]
    fn a_dilated_cube_has_the_steiner_volume() {
        let (a, r) = (1.3, 0.27);
        let (v, t) = cube(a);
        let mp = dilated_mass_properties(&v, &t, r).unwrap();
        let exact = a.powi(3) + 6.0 * a * a * r + 3.0 * PI * a * r * r + 4.0 / 3.0 * PI * r.powi(3);
        assert!(
            (mp.volume - exact).abs() < 1e-13 * exact,
            "{} vs {exact}",
            mp.volume
        );
        assert!((mp.centroid - V3::repeat(a / 2.0)).norm() < 1e-13);
        let i = mp.inertia;
        for k in 0..3 {
            assert!((i[(k, k)] - i[(0, 0)]).abs() < 1e-12 * i[(0, 0)]);
            for l in 0..3 {
                if k != l {
                    assert!(i[(k, l)].abs() < 1e-12 * i[(0, 0)]);
                }
            }
        }
        // without dilation: the cube's own a⁵/6
        let core = dilated_mass_properties(&v, &t, 0.0).unwrap();
        assert!((core.inertia[(0, 0)] - a.powi(5) / 6.0).abs() < 1e-13);
    }

    /// The vertex normal cones tile the sphere: Σ Ω = 4π, Σ ∫u dΩ = 0, Σ ∫u⊗u dΩ = 4π/3 1 —
    /// the quadrature of the vertex sectors is exact to round-off.
    #[test]
    fn the_vertex_cones_tile_the_sphere() {
        let mut rng = SplitMix64::new(3);
        for tris in [4, 10, 30, 40] {
            let s = Stone::random(tris, 2.0, 0.1, &mut rng).unwrap();
            let normals: Vec<V3> = s
                .triangles
                .iter()
                .map(|t| {
                    let [a, b, c] = t.map(|k| s.vertices[k as usize]);
                    (b - a).cross(&(c - a))
                })
                .collect();
            let rule = gauss_legendre(16);
            let (mut om, mut u1, mut u2) = (0.0, V3::zeros(), Matrix3::zeros());
            for cone in normal_cones(s.vertices.len(), &s.triangles, &normals).unwrap() {
                let mean = cone.iter().sum::<V3>().normalize();
                for i in 0..cone.len() {
                    let (w0, w1, w2) =
                        spherical_triangle(&mean, &cone[i], &cone[(i + 1) % cone.len()], &rule);
                    om += w0;
                    u1 += w1;
                    u2 += w2;
                }
            }
            assert!((om - 4.0 * PI).abs() < 1e-11, "{tris}: Ω = {om}");
            assert!(u1.norm() < 1e-11, "{tris}: {u1}");
            assert!(
                (u2 - Matrix3::identity() * (4.0 * PI / 3.0)).norm() < 1e-11,
                "{tris}"
            );
        }
    }

    /// A core shrunk to (nearly) a point is a ball: volume 4/3πr³, inertia 2/5 m r².
    #[test]
    fn a_tiny_core_dilates_to_a_ball() {
        let (v, t) = cube(1e-7);
        let r = 1.0;
        let mp = dilated_mass_properties(&v, &t, r).unwrap();
        let m = 4.0 / 3.0 * PI;
        assert!((mp.volume - m).abs() < 1e-6);
        for k in 0..3 {
            assert!((mp.inertia[(k, k)] - 0.4 * m).abs() < 1e-6);
        }
    }

    /// Inertia of random dilated stones against a brute-force quadrature of the body (a fine
    /// grid with the inside test dist(x, core) ≤ r).
    #[test]
    fn stone_inertia_matches_quadrature() {
        let mut rng = SplitMix64::new(17);
        for tris in [10, 30] {
            let s = Stone::random(tris, 1.8, 0.12, &mut rng).unwrap();
            assert!((s.volume - PI / 6.0).abs() < 1e-12);
            // the principal frame: centre at the origin, moments by a grid sum
            let h = 2.0 * s.circumradius / 160.0;
            let (mut m, mut c, mut j) = (0.0, V3::zeros(), Matrix3::zeros());
            let inside = |x: &V3| {
                let mut d2 = f64::INFINITY;
                let mut outside_any = false;
                for t in &s.triangles {
                    let [a, b, cc] = t.map(|k| s.vertices[k as usize]);
                    let n = (b - a).cross(&(cc - a));
                    if n.dot(&(x - a)) > 0.0 {
                        outside_any = true;
                    }
                    d2 = d2.min(crate::triangle_contact::distance_squared(x, &a, &b, &cc));
                }
                !outside_any || d2 <= s.dilation * s.dilation
            };
            for i in 0..160 {
                for k in 0..160 {
                    for l in 0..160 {
                        let x = V3::new(
                            -s.circumradius + (i as f64 + 0.5) * h,
                            -s.circumradius + (k as f64 + 0.5) * h,
                            -s.circumradius + (l as f64 + 0.5) * h,
                        );
                        if inside(&x) {
                            m += h.powi(3);
                            c += x * h.powi(3);
                            j += x * x.transpose() * h.powi(3);
                        }
                    }
                }
            }
            let c = c / m;
            let jc = j - c * c.transpose() * m;
            let inertia = Matrix3::identity() * jc.trace() - jc;
            let scale = s.inertia.max();
            assert!(
                (m - s.volume).abs() < 3e-3 * s.volume,
                "{tris}: volume {m} vs {}",
                s.volume
            );
            assert!(c.norm() < 3e-3 * s.circumradius, "{tris}: centre {c}");
            for k in 0..3 {
                for l in 0..3 {
                    let exact = if k == l { s.inertia[k] } else { 0.0 };
                    assert!(
                        (inertia[(k, l)] - exact).abs() < 5e-3 * scale,
                        "{tris}: I[{k}{l}] = {} vs {exact}",
                        inertia[(k, l)]
                    );
                }
            }
        }
    }

    /// The branch-free support scan finds the first furthest vertex, as a plain scan does.
    #[test]
    fn support_index_is_the_first_furthest_vertex() {
        let mut rng = SplitMix64::new(8);
        for n in 1..40 {
            let mut v: Vec<V3> = (0..n).map(|_| random_unit_vector(&mut rng)).collect();
            if n > 5 {
                v[n - 1] = v[2]; // a tie: the first wins
            }
            for _ in 0..50 {
                let d = random_unit_vector(&mut rng);
                let mut plain = 0;
                for i in 1..n {
                    if v[i].dot(&d) > v[plain].dot(&d) {
                        plain = i;
                    }
                }
                assert_eq!(support_index(&v, &d), plain, "{n}");
            }
        }
    }

    /// Climbing the vertex graph from any vertex ends at the height of the full scan's
    /// support vertex; a stored stone reads back with its graph.
    #[test]
    fn climbing_the_vertex_graph_finds_the_support() {
        let mut rng = SplitMix64::new(12);
        for tris in [10, 30, 40] {
            let s = Stone::random(tris, 1.6, 0.1, &mut rng).unwrap();
            for _ in 0..300 {
                let d = random_unit_vector(&mut rng);
                let from = (rng.uniform() * s.vertices.len() as f64) as usize;
                let (_, h) = s.adjacency.climb(&s.vertices, from, &d).unwrap();
                let best = s.vertices[support_index(&s.vertices, &d)].dot(&d);
                assert_eq!(h, best, "{tris} triangles");
            }
            let bytes = rmp_serde::to_vec(&s).unwrap();
            let back: Stone = rmp_serde::from_slice(&bytes).unwrap();
            assert_eq!(back, s);
        }
        assert!(Adjacency::default()
            .climb(&[V3::zeros()], 0, &V3::x())
            .is_none());
    }

    #[test]
    fn random_stones_have_the_asked_triangle_counts() {
        let mut rng = SplitMix64::new(5);
        for (tris, verts) in [(10, 7), (30, 17), (40, 22)] {
            let s = Stone::random(tris, 1.5, 0.1, &mut rng).unwrap();
            assert_eq!((s.triangles.len(), s.vertices.len()), (tris, verts));
            assert!(s.inradius() > 0.0 && s.inradius() < 0.5 && s.circumradius > 0.5);
        }
        assert!(Stone::random(11, 1.5, 0.1, &mut rng).is_err());
        assert!(Stone::random(10, 0.5, 0.1, &mut rng).is_err());
        assert!(Stone::random(10, 1.5, 0.6, &mut rng).is_err());
    }

    /// A non-convex mesh (a cube with one face pushed in) is refused, naming the vertex.
    #[test]
    fn a_non_convex_mesh_is_refused() {
        let (v, t) = cube(1.0);
        Stone::from_mesh(&v, &t, 0.1).unwrap();
        // a dent: the top face's centre pushed inwards, fanned
        let mut v2 = v.clone();
        let top: Vec<usize> = (0..v.len()).filter(|&k| v[k].z == 1.0).collect();
        v2.push(V3::new(0.5, 0.5, 0.7));
        let dent = (v2.len() - 1) as u32;
        let mut t2: Vec<[u32; 3]> = t
            .iter()
            .filter(|tri| !tri.iter().all(|&k| top.contains(&(k as usize))))
            .cloned()
            .collect();
        t2.push([top[0] as u32, top[1] as u32, dent]);
        let err = Stone::from_mesh(&v2, &t2, 0.1).unwrap_err();
        assert!(
            err.contains("not convex") && err.contains("vertex 8"),
            "{err}"
        );
    }
}
