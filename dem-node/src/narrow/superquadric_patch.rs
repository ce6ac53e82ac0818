//! Contact of a superquadric body with a convex patch of triangles: one contact per patch,
//! conservative by construction (the superquadric counterpart of `triangle_contact`).
//!
//! **Definition.** For a unit direction c (from the wall towards the body) the body's lowest
//! point along c is p*(c) = x + T X(−Tᵀc) (point from normal, the surface point with outward
//! normal −c) and φ(c) = p*(c)·c; the patch's highest point along c is h(c) = max_v v·c over
//! the patch vertices (the support function of its convex hull). The overlap along c is
//! o(c) = h(c) − φ(c), and
//!
//! ```text
//! δ = min over c ∈ F of o(c),        F = the front directions of the patch (below)
//! ```
//!
//! F does not depend on the pose, so δ is continuous in the pose, and where the minimiser is
//! unique (Danskin / envelope theorem) ∂δ/∂x = −c and ∂δ/∂θ = −(p* − x) × c: the force
//! F(δ) c applied at p* is −∇W(δ), energy is conserved exactly (Wellmann's condition III), the
//! force has no jump (II), and inside a face region c is the face normal and δ the plane
//! penetration (I). δ is the minimum translation that moves the body out of the solid
//! "patch hull extended to infinity behind the patch" (for a flat patch: the prism under it).
//!
//! **Front directions** F (*not in thesis*) are the union of the normal cones of the hull
//! features, cut off at the back of the patch:
//! - a face (a coplanar, edge-connected group of triangles with normal n): c = n;
//! - an edge between two faces f, g (convex): the arc from n_f to n_g about the edge;
//! - a boundary edge of face f: the arc from n_f to its in-plane outward normal m (c·n_f ≥ 0);
//! - a vertex: the directions in which it is a highest vertex, with c·n_f ≥ 0 for one of its
//!   triangles; at a boundary vertex also the arc from m₁ to m₂ of its two boundary edges.
//!
//! **The minimiser, by features** (an active-set classification, like the closest-point
//! regions of a triangle); every candidate is valid only inside its feature's region, and the
//! smallest valid o wins:
//! 1. face: c = n, valid iff the projection q = p* + o n of p* lies in the group (and no
//!    patch vertex lies above the face plane);
//! 2. edge (a, b): c(θ) on its arc, the 1-D minimum of g(θ) = (a − p*)·c, g′ = (a − p*)·c′,
//!    g″ = c′·G c′ − (a − p*)·c with G = T J Tᵀ (J = ∂X/∂n, its tangent block holds the radii
//!    of curvature); safeguarded Newton inside the bracket given by the signs of g′ at the
//!    arc ends (which are the face evaluations); valid iff the foot q = p* + o c lies on [a, b];
//! 3. vertex v: 2-D Newton for (v − p*) ∥ c, the superquadric–superquadric search of
//!    `narrow::superquadric` with a point as second body: Δα = (G_t − o I)⁻¹ d_t, d = p* − v,
//!    with the same Levenberg–Marquardt safeguard; valid iff v is a highest vertex at c;
//! 4. the clamped ends at the back (body reaching behind the patch plane): a boundary edge at
//!    c = m (the "wall" below the edge: valid iff p*(m) lies below the face plane and its foot
//!    on the edge) and a boundary vertex on its arc m₁ → m₂ (the "ray" below the vertex).
//!
//! Any evaluated direction c ∈ F with o(c) < 0 is a separating plane: no contact (early exit,
//! as W §3.4.2 step 3). The features are pruned cheaply: an edge is searched only if g′ < 0
//! at its face end (the face's support point lies beyond the edge) or the body's bounding
//! sphere reaches it (or the wall below it); a vertex only if it lies inside the body, or an
//! edge's foot or a face's projection points at it (then one run, for a separating plane).
//!
//! **Several local minima** (*not in thesis*). Where the body's radii of curvature are below
//! the overlap — near the tips of a pointed body (ε → 2, the radius is 0 at a tip) or the
//! rounded corners of a boxy one (ε → 0), or for deep overlaps — o has several local minima
//! on an edge arc and in a vertex region. Near the body an arc is therefore sampled (3 even
//! points and the body's flat-ish directions −T N, N = the axes and the diagonals
//! (±1/r₁, ±1/r₂, ±1/r₃)), each interval judged by the cubic Hermite model of g′ from g′, g″
//! at its ends and bisected where the model hides a minimum; a vertex is searched from the
//! last normal, the direction that pointed to it, its exit direction −∇F, the two lowest
//! samples of its region and all of the body's flat-ish directions in its region, and the
//! lowest minimum is kept. δ stays the global minimum (checked against a brute force), but
//! where two minima tie the minimiser — the normal and p* — switches between them: δ is
//! continuous there (energy is still conserved) but the force turns by the angle between the
//! two normals (condition II holds only where the minimiser is unique). The sweeps of the
//! tests meet such ties with pointed bodies (ε = 1.7) at edges and corners, never with the
//! round or boxy ones.
//!
//! **Non-convex patches** (*not in thesis*). `walls::compute_patches` also joins edges that are
//! concave by less than 1°, and a flat patch may have a non-convex outline. The triangles are
//! therefore first split into convex pieces (joined across convex or coplanar edges; a piece is
//! convex when no vertex lies above a face plane or beyond a boundary wall), and δ is the
//! largest of the pieces' values — a maximum of continuous, conservative overlaps, so still
//! continuous and conservative, and across coplanar splits still exactly the plane value (a
//! sphere's closest point over a union is the same maximum).
//!
//! **Nodal forces.** The contact point on the wall is q = p* + δ c (on the face, on the edge,
//! or the vertex); `triangle` and `bary` give q as N₁x₁ + N₂x₂ + N₃x₃, so f_K = −N_K f keeps
//! the total force and the moment about any point on the line of action. For the clamped
//! back contacts (4.) q lies below the edge/vertex; there the weights are those of the foot on
//! the edge / of the vertex (the moment is then not exactly kept).
//!
//! **Limitations.** The patch is one-sided: it is taken as the top of a solid (its hull
//! extended behind it), so a body that reaches behind the patch plane is pushed to the front
//! — right for the surface of a solid wall, not for a thin open plate hit from behind (the
//! sphere contact of `triangle_contact` is two-sided there). Behind a non-flat boundary
//! vertex only the arc m₁ → m₂ is searched, not the whole border of F. Deep overlaps (δ
//! beyond ~0.3 of the smallest semi-axis) are searched with the same starts and may, rarely,
//! return a non-global minimum.

use crate::hertz_mindlin::V3;
use crate::narrow::superquadric::rotate_normal;
use crate::narrow::superquadric::shifted_newton_step;
use crate::shape::superquadric::{sym2_eigen, tangent_basis, Superquadric};
use crate::triangle_contact::closest_point_on_triangle;
use nalgebra::Matrix3;

/// Two triangles sharing an edge are coplanar (one face) when their normals differ by less
/// than this angle (rad).
const COPLANAR_SIN: f64 = 1e-8;
/// Tolerance of the region tests (inside a face, foot on an edge, highest vertex), relative to
/// the body size.
const REGION_TOL: f64 = 1e-9;
/// Newton convergence: tangential residual relative to the body size.
const NEWTON_TOL: f64 = 1e-12;
/// A Newton run that stops above NEWTON_TOL is still used below this residual (relative).
const ACCEPT_TOL: f64 = 1e-9;
const MAX_ITERATIONS: u32 = 100;

/// Which feature of the patch carries the contact.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Feature {
    /// A face: c is its normal.
    Face,
    /// An edge (or the wall below a boundary edge): c ⊥ edge.
    Edge,
    /// A vertex (or the ray below a boundary vertex).
    Vertex,
}

/// The contact of a superquadric with one patch.
#[derive(Debug, Clone, Copy)]
pub struct PatchContact {
    /// Unit contact normal c, from the wall towards the body.
    pub normal: V3,
    /// δ > 0.
    pub overlap: f64,
    /// Contact point on the body: p* = x + T X(−Tᵀc), the body's lowest point along c.
    pub point: V3,
    /// Index (into the given `triangles`) of the triangle that holds the wall point
    /// q = p* + δ c (see `bary`).
    pub triangle: usize,
    /// Barycentric weights of q in `triangle` (each in [0, 1], sum 1): nodal forces
    /// f_K = −N_K f.
    pub bary: [f64; 3],
    /// The body's radius tensor at p* (principal radii of curvature as eigenvalues):
    /// [a, b, c] = [[a, b], [b, c]], the tangent block of G = T J Tᵀ in the basis
    /// (t1, t2) = `tangent_basis(&-normal)` (the basis of the body's outward normal at p*).
    pub radii: [f64; 3],
    pub feature: Feature,
}

/// What the search did (for statistics and the tests).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PatchStats {
    /// Point-from-normal evaluations.
    pub evaluations: u32,
    /// Newton iterations (1-D and 2-D).
    pub iterations: u32,
    /// Newton runs that ended above the convergence tolerance.
    pub not_converged: u32,
    /// Convex pieces the triangles were split into.
    pub pieces: u32,
    /// A contact piece had no valid feature candidate: the smallest evaluated o was returned
    /// (an upper bound of δ; should not happen).
    pub fallback: bool,
}

/// Contact of the superquadric `shape` at `position` with orientation `rotation` (body →
/// global) against the triangles of one patch (`triangles` index `vertices`; normals
/// (b − a) × (c − a) point to the front side). `warm` is the last step's normal of this pair
/// (used as the first separating-plane test and Newton start). `None`: no contact (δ ≤ 0).
pub fn patch_contact(
    shape: &Superquadric,
    position: V3,
    rotation: &Matrix3<f64>,
    vertices: &[V3],
    triangles: &[[usize; 3]],
    warm: Option<V3>,
) -> Option<PatchContact> {
    patch_contact_with_stats(
        shape,
        position,
        rotation,
        vertices,
        triangles,
        warm,
        &mut PatchStats::default(),
    )
}

/// [`patch_contact`] with the search statistics.
pub fn patch_contact_with_stats(
    shape: &Superquadric,
    position: V3,
    rotation: &Matrix3<f64>,
    vertices: &[V3],
    triangles: &[[usize; 3]],
    warm: Option<V3>,
    stats: &mut PatchStats,
) -> Option<PatchContact> {
    let mesh = Mesh::new(vertices, triangles, position);
    if mesh.tris.is_empty() {
        return None;
    }
    let scale = shape.radii.max();
    let mut ctx = Ctx {
        shape,
        rot: *rotation,
        rot_t: rotation.transpose(),
        mesh: &mesh,
        scale,
        tol: REGION_TOL * scale,
        bound: shape.bounding_radius(),
        body_dirs: None,
        stats,
    };
    let warm = warm
        .filter(|w| w.iter().all(|c| c.is_finite()))
        .and_then(|w| w.try_normalize(1e-300));
    let mut best: Option<Cand> = None;
    for piece in mesh.pieces(ctx.tol) {
        ctx.stats.pieces += 1;
        if let Some(c) = ctx.solve_piece(&piece, warm) {
            if best.as_ref().is_none_or(|b| c.delta > b.delta) {
                best = Some(c);
            }
        }
    }
    let c = best.filter(|c| c.delta > 0.0 && c.delta.is_finite())?;
    let (t1, t2) = tangent_basis(&-c.eval.c);
    let (gt1, gt2) = (c.eval.g * t1, c.eval.g * t2);
    Some(PatchContact {
        normal: c.eval.c,
        overlap: c.delta,
        point: position + c.eval.r,
        triangle: mesh.tris[c.tri].index,
        bary: c.bary,
        radii: [
            t1.dot(&gt1),
            0.5 * (t1.dot(&gt2) + t2.dot(&gt1)),
            t2.dot(&gt2),
        ],
        feature: c.feature,
    })
}

// ---------------------------------------------------------------------------------------------
// topology

struct Tri {
    /// local vertex ids
    v: [usize; 3],
    /// unit normal and (b − a) × (c − a)
    n: V3,
    cross: V3,
    /// index in the caller's list
    index: usize,
}

/// The non-degenerate triangles with their vertices relative to the body centre, and who
/// is joined to whom across which edge.
struct Mesh {
    pos: Vec<V3>,
    tris: Vec<Tri>,
    /// per triangle and edge slot k (edge v[k] → v[k+1]): the neighbour (triangle, its slot)
    /// if exactly one triangle shares the edge, and how they are joined
    nbr: Vec<[Option<(usize, usize, Join)>; 3]>,
}

fn find(parent: &mut [usize], mut x: usize) -> usize {
    while parent[x] != x {
        parent[x] = parent[parent[x]];
        x = parent[x];
    }
    x
}

fn union(parent: &mut [usize], a: usize, b: usize) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        parent[ra.max(rb)] = ra.min(rb);
    }
}

/// How two triangles sharing an edge are joined.
#[derive(PartialEq, Eq, Clone, Copy, PartialOrd, Ord, Debug)]
enum Join {
    Coplanar,
    Convex,
    Apart,
}

impl Mesh {
    fn new(vertices: &[V3], triangles: &[[usize; 3]], x: V3) -> Mesh {
        let mut ids: Vec<usize> = triangles
            .iter()
            .flatten()
            .copied()
            .filter(|&i| i < vertices.len())
            .collect();
        ids.sort_unstable();
        ids.dedup();
        let pos: Vec<V3> = ids.iter().map(|&i| vertices[i] - x).collect();
        let mut tris = Vec::with_capacity(triangles.len());
        for (index, t) in triangles.iter().enumerate() {
            if t.iter().any(|&i| i >= vertices.len()) {
                continue;
            }
            let v = t.map(|g| ids.binary_search(&g).unwrap_or(0));
            if v[0] == v[1] || v[1] == v[2] || v[0] == v[2] {
                continue;
            }
            let (a, b, c) = (pos[v[0]], pos[v[1]], pos[v[2]]);
            let cross = (b - a).cross(&(c - a));
            let size2 = (b - a)
                .norm_squared()
                .max((c - a).norm_squared())
                .max((c - b).norm_squared());
            let area2 = cross.norm();
            if area2 <= 1e-12 * size2 || !area2.is_finite() {
                continue; // degenerate (or not finite): no normal
            }
            tris.push(Tri {
                v,
                n: cross / area2,
                cross,
                index,
            });
        }
        // adjacency: (lo vertex, hi vertex, triangle, slot) sorted
        let mut edges: Vec<(usize, usize, usize, usize)> = Vec::with_capacity(3 * tris.len());
        for (t, tri) in tris.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (tri.v[k], tri.v[(k + 1) % 3]);
                edges.push((a.min(b), a.max(b), t, k));
            }
        }
        edges.sort_unstable_by_key(|e| ((e.0 as u64) << 32) | e.1 as u64);
        let mut mesh = Mesh {
            pos,
            nbr: vec![[None; 3]; tris.len()],
            tris,
        };
        let mut k = 0;
        while k < edges.len() {
            let mut m = k + 1;
            while m < edges.len() && edges[m].0 == edges[k].0 && edges[m].1 == edges[k].1 {
                m += 1;
            }
            if m - k == 2 {
                let (e, f) = (edges[k], edges[k + 1]);
                let j = mesh.join(e.2, e.3, f.2, f.3);
                mesh.nbr[e.2][e.3] = Some((f.2, f.3, j));
                mesh.nbr[f.2][f.3] = Some((e.2, e.3, j));
            }
            k = m;
        }
        mesh
    }

    /// How the triangles ta (edge at slot ka) and tb (slot kb) are joined across their
    /// common edge.
    fn join(&self, ta: usize, ka: usize, tb: usize, kb: usize) -> Join {
        let (a, b) = (&self.tris[ta], &self.tris[tb]);
        // consistent orientation: the shared edge is traversed in opposite directions
        if a.v[ka] != b.v[(kb + 1) % 3] {
            return Join::Apart;
        }
        let sin = a.n.cross(&b.n).norm();
        if sin <= COPLANAR_SIN && a.n.dot(&b.n) > 0.0 {
            return Join::Coplanar;
        }
        let opposite = b.v[(kb + 2) % 3];
        if (self.pos[opposite] - self.pos[a.v[ka]]).dot(&a.n) < 0.0 {
            Join::Convex
        } else {
            Join::Apart
        }
    }

    /// The convex pieces: components joined across convex or coplanar edges, split greedily
    /// where a component is not convex.
    fn pieces(&self, tol: f64) -> Vec<Piece> {
        let nt = self.tris.len();
        let mut parent: Vec<usize> = (0..nt).collect();
        for t in 0..nt {
            for (u, _, j) in self.nbr[t].iter().flatten() {
                if *j != Join::Apart && t < *u {
                    union(&mut parent, t, *u);
                }
            }
        }
        let mut comp_of = vec![usize::MAX; nt];
        let mut comps: Vec<Vec<usize>> = Vec::new();
        for t in 0..nt {
            let r = find(&mut parent, t);
            if comp_of[r] == usize::MAX {
                comp_of[r] = comps.len();
                comps.push(Vec::new());
            }
            comps[comp_of[r]].push(t);
        }
        let mut out = Vec::with_capacity(comps.len());
        for comp in comps {
            let piece = Piece::new(self, comp);
            if piece.is_convex(self, tol) {
                out.push(piece);
                continue;
            }
            // greedy: coplanar joins first, then convex ones, each kept only if the merged
            // piece stays convex
            let mut joins: Vec<(Join, usize, usize)> = Vec::new();
            for &t in &piece.tris {
                for (u, _, j) in self.nbr[t].iter().flatten() {
                    if *j != Join::Apart && t < *u {
                        joins.push((*j, t, *u));
                    }
                }
            }
            joins.sort();
            let mut sets: Vec<Vec<usize>> = piece.tris.iter().map(|&t| vec![t]).collect();
            for (_, ta, tb) in joins {
                let sa = sets.iter().position(|s| s.contains(&ta));
                let sb = sets.iter().position(|s| s.contains(&tb));
                let (Some(sa), Some(sb)) = (sa, sb) else {
                    continue;
                };
                if sa == sb {
                    continue;
                }
                let mut merged = sets[sa].clone();
                merged.extend_from_slice(&sets[sb]);
                if Piece::new(self, merged.clone()).is_convex(self, tol) {
                    let (lo, hi) = (sa.min(sb), sa.max(sb));
                    sets.swap_remove(hi);
                    sets[lo] = merged;
                }
            }
            out.extend(sets.into_iter().map(|s| Piece::new(self, s)));
        }
        out
    }
}

/// A face: coplanar, edge-connected triangles.
struct Group {
    n: V3,
    level: f64,
    tris: Vec<usize>,
}

/// A hull edge of a piece, seen from its triangle f (a → b in f's order).
struct HullEdge {
    a: usize,
    b: usize,
    f: usize,
    /// the triangle on the other side (an edge between two faces), or none (boundary)
    g: Option<usize>,
    /// unit direction and length of b − a
    e: V3,
    len: f64,
    /// arc c(θ) = cos θ u + sin θ w, θ ∈ [0, th1]: u = n_f, w = outward in-plane normal of f
    u: V3,
    w: V3,
    th1: f64,
}

/// The clamped arc m₁ → m₂ at a boundary vertex (the ray below it).
struct Ray {
    u: V3,
    w: V3,
    th1: f64,
    /// the ray direction (behind the patch)
    down: V3,
    /// the two boundary edges
    e1: usize,
    e2: usize,
}

struct HullVertex {
    v: usize,
    /// its triangles: `Piece::vtris[range]`
    range: (usize, usize),
    ray: Option<Ray>,
}

struct Piece {
    tris: Vec<usize>,
    /// piece-local index of each mesh triangle (usize::MAX: not in the piece)
    local: Vec<usize>,
    verts: Vec<usize>,
    groups: Vec<Group>,
    /// group of each triangle (parallel to `tris`)
    group_of: Vec<usize>,
    edges: Vec<HullEdge>,
    hverts: Vec<HullVertex>,
    vtris: Vec<usize>,
}

impl Piece {
    fn new(mesh: &Mesh, tris: Vec<usize>) -> Piece {
        let mut local = vec![usize::MAX; mesh.tris.len()];
        for (i, &t) in tris.iter().enumerate() {
            local[t] = i;
        }
        let mut parent: Vec<usize> = (0..tris.len()).collect();
        // (triangle, slot, other side) of the hull edges
        let mut hull: Vec<(usize, usize, Option<usize>)> = Vec::with_capacity(3 * tris.len());
        for (i, &t) in tris.iter().enumerate() {
            for k in 0..3 {
                match mesh.nbr[t][k] {
                    Some((u, _, j)) if local[u] != usize::MAX => match j {
                        Join::Coplanar => union(&mut parent, i, local[u]),
                        Join::Convex if t < u => hull.push((t, k, Some(u))),
                        Join::Convex => {}
                        Join::Apart => hull.push((t, k, None)),
                    },
                    _ => hull.push((t, k, None)),
                }
            }
        }
        // faces
        let mut groups: Vec<Group> = Vec::with_capacity(4);
        let mut group_of = vec![usize::MAX; tris.len()];
        let mut group_of_root = vec![usize::MAX; tris.len()];
        for i in 0..tris.len() {
            let r = find(&mut parent, i);
            if group_of_root[r] == usize::MAX {
                group_of_root[r] = groups.len();
                groups.push(Group {
                    n: V3::zeros(),
                    level: f64::NEG_INFINITY,
                    tris: Vec::new(),
                });
            }
            let gi = group_of_root[r];
            group_of[i] = gi;
            groups[gi].n += mesh.tris[tris[i]].cross;
            groups[gi].tris.push(tris[i]);
        }
        for g in &mut groups {
            g.n =
                g.n.try_normalize(0.0)
                    .unwrap_or_else(|| mesh.tris[g.tris[0]].n);
            g.level = g
                .tris
                .iter()
                .flat_map(|&t| mesh.tris[t].v)
                .map(|v| mesh.pos[v].dot(&g.n))
                .fold(f64::NEG_INFINITY, f64::max);
        }
        let mut mark = vec![false; mesh.pos.len()];
        let mut verts = Vec::with_capacity(tris.len() + 2);
        for &t in &tris {
            for v in mesh.tris[t].v {
                if !mark[v] {
                    mark[v] = true;
                    verts.push(v);
                }
            }
        }
        // hull edges
        let mut edges = Vec::with_capacity(hull.len());
        for (t, k, other) in hull {
            let tri = &mesh.tris[t];
            let (a, b, third) = (tri.v[k], tri.v[(k + 1) % 3], tri.v[(k + 2) % 3]);
            let ev = mesh.pos[b] - mesh.pos[a];
            let len = ev.norm();
            if len <= 0.0 || !len.is_finite() {
                continue;
            }
            let e = ev / len;
            let nf = groups[group_of[local[t]]].n;
            let Some(u) = (nf - e * nf.dot(&e)).try_normalize(1e-12) else {
                continue;
            };
            let mut w = e.cross(&u);
            if (mesh.pos[third] - mesh.pos[a]).dot(&w) > 0.0 {
                w = -w;
            }
            let th1 = match other {
                Some(g) => {
                    let ng = groups[group_of[local[g]]].n;
                    ng.dot(&w).atan2(ng.dot(&u))
                }
                None => std::f64::consts::FRAC_PI_2,
            };
            if !(th1 > 0.0 && th1 < std::f64::consts::PI) {
                continue;
            }
            edges.push(HullEdge {
                a,
                b,
                f: t,
                g: other,
                e,
                len,
                u,
                w,
                th1,
            });
        }
        // hull vertices (on a hull edge), their triangles, their boundary edges
        let mut hv_of = vec![usize::MAX; mesh.pos.len()];
        let mut hvs: Vec<(usize, [usize; 2], usize)> = Vec::with_capacity(edges.len() + 1);
        for (i, ed) in edges.iter().enumerate() {
            for v in [ed.a, ed.b] {
                if hv_of[v] == usize::MAX {
                    hv_of[v] = hvs.len();
                    hvs.push((v, [usize::MAX; 2], 0));
                }
                if ed.g.is_none() {
                    let h = &mut hvs[hv_of[v]];
                    if h.2 < 2 {
                        h.1[h.2] = i;
                    }
                    h.2 += 1;
                }
            }
        }
        let mut pairs: Vec<(usize, usize)> = Vec::with_capacity(3 * tris.len());
        for &t in &tris {
            for v in mesh.tris[t].v {
                if hv_of[v] != usize::MAX {
                    pairs.push((hv_of[v], t));
                }
            }
        }
        pairs.sort_unstable_by_key(|p| p.0);
        let vtris: Vec<usize> = pairs.iter().map(|p| p.1).collect();
        let mut hverts = Vec::with_capacity(hvs.len());
        let mut at = 0;
        for (h, (v, bnd, nb)) in hvs.into_iter().enumerate() {
            let start = at;
            while at < pairs.len() && pairs[at].0 == h {
                at += 1;
            }
            let ray = if nb == 2 {
                let (e1, e2) = (bnd[0], bnd[1]);
                let (m1, m2) = (edges[e1].w, edges[e2].w);
                let axis = m1.cross(&m2);
                let s = axis.norm();
                if s > 1e-9 {
                    let axis = axis / s;
                    let w = axis.cross(&m1).normalize();
                    let th1 = m2.dot(&w).atan2(m2.dot(&m1));
                    let nsum: V3 = vtris[start..at].iter().map(|&t| mesh.tris[t].n).sum();
                    let down = if axis.dot(&nsum) > 0.0 { -axis } else { axis };
                    (th1 > 0.0).then_some(Ray {
                        u: m1,
                        w,
                        th1,
                        down,
                        e1,
                        e2,
                    })
                } else {
                    None
                }
            } else {
                None
            };
            hverts.push(HullVertex {
                v,
                range: (start, at),
                ray,
            });
        }
        Piece {
            tris,
            local,
            verts,
            groups,
            group_of,
            edges,
            hverts,
            vtris,
        }
    }

    fn group_of_tri(&self, t: usize) -> usize {
        self.group_of[self.local[t]]
    }

    /// The triangles of hull vertex `h`.
    fn vtris(&self, h: &HullVertex) -> &[usize] {
        &self.vtris[h.range.0..h.range.1]
    }

    /// No vertex above a face plane or beyond a boundary wall.
    fn is_convex(&self, mesh: &Mesh, tol: f64) -> bool {
        let above =
            |n: &V3, level: f64| self.verts.iter().any(|&v| mesh.pos[v].dot(n) > level + tol);
        !self.groups.iter().any(|g| above(&g.n, g.level))
            && !self
                .edges
                .iter()
                .any(|e| e.g.is_none() && above(&e.w, mesh.pos[e.a].dot(&e.w)))
    }
}

// ---------------------------------------------------------------------------------------------
// search

/// One evaluation at direction c: p* − x and G = T J Tᵀ.
#[derive(Clone, Copy)]
struct Eval {
    c: V3,
    r: V3,
    g: Matrix3<f64>,
}

/// A candidate contact: the evaluation, δ = o(c), the triangle (mesh-local) and weights.
#[derive(Clone, Copy)]
struct Cand {
    eval: Eval,
    delta: f64,
    tri: usize,
    bary: [f64; 3],
    feature: Feature,
}

struct Ctx<'a> {
    shape: &'a Superquadric,
    rot: Matrix3<f64>,
    rot_t: Matrix3<f64>,
    mesh: &'a Mesh,
    scale: f64,
    tol: f64,
    bound: f64,
    /// directions −T N of the body's flat-ish parts (lazy, see `body_directions`)
    body_dirs: Option<Vec<V3>>,
    stats: &'a mut PatchStats,
}

/// Result of a 1-D arc search: converged (or bracketed to round-off), or separated.
enum ArcMin {
    Min(Eval),
    Separated,
}

impl Ctx<'_> {
    fn eval(&mut self, c: V3) -> Eval {
        self.stats.evaluations += 1;
        let n = -(self.rot_t * c);
        let sp = self.shape.point_from_normal(&n);
        Eval {
            c,
            r: self.rot * sp.x,
            g: self.rot * sp.jacobian * self.rot_t,
        }
    }

    fn h(&self, p: &Piece, c: &V3) -> f64 {
        p.verts
            .iter()
            .map(|&v| self.mesh.pos[v].dot(c))
            .fold(f64::NEG_INFINITY, f64::max)
    }

    /// o(c) = h(c) − φ(c) (relative to the centre).
    fn overlap(&self, p: &Piece, e: &Eval) -> f64 {
        self.h(p, &e.c) - e.r.dot(&e.c)
    }

    /// c ∈ F: a highest vertex at c has a triangle facing c (c·n ≥ 0).
    fn in_front(&self, p: &Piece, c: &V3) -> bool {
        let h = self.h(p, c);
        p.tris.iter().any(|&t| {
            let tri = &self.mesh.tris[t];
            tri.n.dot(c) >= -1e-12
                && tri
                    .v
                    .iter()
                    .any(|&v| self.mesh.pos[v].dot(c) >= h - self.tol)
        })
    }

    fn highest(&self, p: &Piece, v: usize, c: &V3) -> bool {
        self.h(p, c) <= self.mesh.pos[v].dot(c) + self.tol
    }

    fn inside_body(&self, q: &V3) -> bool {
        self.shape.inside_outside(&(self.rot_t * q)) < 1.0
    }

    /// Weights of the vertex v in triangle t.
    fn vertex_bary(&self, t: usize, v: usize) -> [f64; 3] {
        let tv = self.mesh.tris[t].v;
        std::array::from_fn(|k| if tv[k] == v { 1.0 } else { 0.0 })
    }

    /// Weights of a + s (b − a) in triangle t (s clamped to [0, 1]).
    fn edge_bary(&self, t: usize, a: usize, b: usize, s: f64) -> [f64; 3] {
        let s = s.clamp(0.0, 1.0);
        let tv = self.mesh.tris[t].v;
        std::array::from_fn(|k| {
            if tv[k] == a {
                1.0 - s
            } else if tv[k] == b {
                s
            } else {
                0.0
            }
        })
    }

    /// The closest triangle of a face to a point q of its plane: (distance, triangle,
    /// weights).
    fn in_face(&self, g: &Group, q: &V3) -> (f64, usize, [f64; 3]) {
        let mut best = (f64::INFINITY, g.tris[0], [1.0, 0.0, 0.0]);
        for &t in &g.tris {
            let v = self.mesh.tris[t].v;
            let (cp, bary) = closest_point_on_triangle(
                q,
                &self.mesh.pos[v[0]],
                &self.mesh.pos[v[1]],
                &self.mesh.pos[v[2]],
            );
            let d = (q - cp).norm();
            if d < best.0 {
                best = (d, t, bary);
            }
        }
        best
    }

    /// Minimum of g(θ) = (a − p*(c(θ)))·c(θ), c(θ) = cos θ u + sin θ w on (lo, hi), given
    /// g′(lo) < 0 < g′(hi): safeguarded Newton in the bracket. Early exit when an iterate
    /// separates (o < 0; the arc lies in F).
    #[allow(clippy::too_many_arguments)]
    fn solve_arc(
        &mut self,
        p: &Piece,
        a: V3,
        u: V3,
        w: V3,
        (mut lo, gp0): (f64, f64),
        (mut hi, gp1): (f64, f64),
        warm: Option<V3>,
    ) -> ArcMin {
        let axis = u.cross(&w);
        let th1 = hi;
        let mut th = warm
            .filter(|c| c.dot(&axis).abs() < 0.3)
            .map(|c| c.dot(&w).atan2(c.dot(&u)))
            .filter(|t| *t > lo && *t < hi)
            .unwrap_or_else(|| {
                let f = (gp0 / (gp0 - gp1)).clamp(0.05, 0.95);
                lo + f * (hi - lo)
            });
        let ntol = NEWTON_TOL * self.scale;
        // a bracket end that already solves g′ = 0 (to the tolerance)
        if gp0.abs() <= ntol || gp1.abs() <= ntol {
            th = if gp0.abs() <= gp1.abs() { lo } else { hi };
        }
        let mut last: Option<Eval> = None;
        for _ in 0..MAX_ITERATIONS {
            self.stats.iterations += 1;
            let (s, co) = th.sin_cos();
            let c = u * co + w * s;
            let cp = w * co - u * s;
            let e = self.eval(c);
            if self.overlap(p, &e) < 0.0 {
                return ArcMin::Separated;
            }
            let ar = a - e.r;
            let gp = ar.dot(&cp);
            last = Some(e);
            if gp.abs() <= ntol {
                return ArcMin::Min(e);
            }
            if gp < 0.0 {
                lo = th;
            } else {
                hi = th;
            }
            if hi - lo <= 1e-15 * th1.max(1.0) {
                break;
            }
            let gpp = cp.dot(&(e.g * cp)) - ar.dot(&c);
            let newton = th - gp / gpp;
            th = if gpp > 0.0 && newton >= lo && newton <= hi && newton != th {
                newton
            } else {
                0.5 * (lo + hi)
            };
        }
        let e = last.expect("at least one iteration");
        let cp = e.c.cross(&axis);
        if (a - e.r).dot(&cp).abs() > ACCEPT_TOL * self.scale {
            self.stats.not_converged += 1;
        }
        ArcMin::Min(e)
    }

    /// Directions c = −T N for the normals N of the body's flat-ish parts: the axes (the
    /// faces of a boxy body, ε → 0) and the diagonals (±1/r1, ±1/r2, ±1/r3) with one or no
    /// zero (the faces of a pointed body, ε → 2). Near those directions o has its separate
    /// local minima; they seed the searches of vertices and the samples of near arcs. Empty
    /// for a near-ellipsoid (both exponents within 0.25 of 1), whose o is unimodal at
    /// moderate overlaps.
    fn body_directions(&mut self) -> &[V3] {
        if self.body_dirs.is_none() {
            let mut dirs = Vec::new();
            if (self.shape.eps1 - 1.0).abs() > 0.25 || (self.shape.eps2 - 1.0).abs() > 0.25 {
                let inv = self.shape.radii.map(|r| 1.0 / r);
                for code in 1..27 {
                    let s = [code % 3, code / 3 % 3, code / 9].map(|k| k as f64 - 1.0);
                    let n = V3::new(s[0] * inv.x, s[1] * inv.y, s[2] * inv.z).normalize();
                    dirs.push(-(self.rot * n));
                }
            }
            self.body_dirs = Some(dirs);
        }
        self.body_dirs.as_deref().unwrap_or(&[])
    }

    /// The local minima of g(θ) = (a − p*)·c on the arc c(θ) = cos θ u + sin θ w, θ ∈
    /// [0, th1] (the arc lies in F), given the evaluations at its ends. For a feature near
    /// the body, interior samples are added (3 even ones and the body's flat-ish directions
    /// on the arc). Each interval is then judged by the cubic Hermite model of g′ from g′, g″
    /// at its ends (g″ = c′·G c′ − (a − p*)·c): a clean bracket g′ < 0 < g′ is solved by
    /// Newton, an interval where the model hides a minimum (g″ < 0 near the sharp parts of
    /// a body: radii of curvature below the overlap) is bisected, up to 6 times. `None`:
    /// separated.
    #[allow(clippy::too_many_arguments)]
    fn scan_arc(
        &mut self,
        p: &Piece,
        a: V3,
        u: V3,
        w: V3,
        th1: f64,
        ends: (&Eval, &Eval),
        near: bool,
        warm: Option<V3>,
        out: &mut Vec<Eval>,
    ) -> Option<()> {
        // (θ, g′, g″)
        let deriv = |th: f64, e: &Eval| -> (f64, f64, f64) {
            let (s, co) = th.sin_cos();
            let (c, cp) = (u * co + w * s, w * co - u * s);
            let ar = a - e.r;
            (th, ar.dot(&cp), cp.dot(&(e.g * cp)) - ar.dot(&c))
        };
        let mut angles: Vec<f64> = Vec::new();
        if near {
            angles.extend((1..=3).map(|j| th1 * j as f64 / 4.0));
            let axis = u.cross(&w);
            let extra: Vec<f64> = self
                .body_directions()
                .iter()
                .filter(|d| d.dot(&axis).abs() < 0.5)
                .map(|d| d.dot(&w).atan2(d.dot(&u)))
                .filter(|t| *t > 0.01 * th1 && *t < 0.99 * th1)
                .collect();
            angles.extend(extra);
            angles.sort_by(f64::total_cmp);
            angles.dedup_by(|a, b| (*a - *b).abs() < 0.02 * th1);
        }
        let mut pts = Vec::with_capacity(angles.len() + 2);
        pts.push(deriv(0.0, ends.0));
        for th in angles {
            let (s, co) = th.sin_cos();
            let e = self.eval(u * co + w * s);
            if self.overlap(p, &e) < 0.0 {
                return None;
            }
            pts.push(deriv(th, &e));
        }
        pts.push(deriv(th1, ends.1));
        let mut stack: Vec<_> = pts.windows(2).map(|q| (q[0], q[1], 0u32)).collect();
        while let Some((pa, pb, depth)) = stack.pop() {
            let h = pb.0 - pa.0;
            // the Hermite cubic of g′ on the interval, sampled at 9 points
            let (p0, p1, m0, m1) = (pa.1, pb.1, pa.2 * h, pb.2 * h);
            let model = |t: f64| {
                let (t2, t3) = (t * t, t * t * t);
                (2.0 * t3 - 3.0 * t2 + 1.0) * p0
                    + (t3 - 2.0 * t2 + t) * m0
                    + (-2.0 * t3 + 3.0 * t2) * p1
                    + (t3 - t2) * m1
            };
            let vals: [f64; 9] = std::array::from_fn(|k| model(k as f64 / 8.0));
            let changes = vals
                .windows(2)
                .filter(|q| (q[0] < 0.0) != (q[1] < 0.0))
                .count();
            let hidden = vals.windows(2).any(|q| q[0] < 0.0 && q[1] > 0.0);
            let bracket = p0 < 0.0 && p1 > 0.0;
            if !(bracket || hidden) {
                continue;
            }
            if !(bracket && changes == 1) && depth < 6 && h > 1e-4 {
                let tm = pa.0 + 0.5 * h;
                let (s, co) = tm.sin_cos();
                let e = self.eval(u * co + w * s);
                if self.overlap(p, &e) < 0.0 {
                    return None;
                }
                let pm = deriv(tm, &e);
                stack.push((pa, pm, depth + 1));
                stack.push((pm, pb, depth + 1));
                continue;
            }
            if bracket {
                match self.solve_arc(p, a, u, w, (pa.0, pa.1), (pb.0, pb.1), warm) {
                    ArcMin::Separated => return None,
                    ArcMin::Min(e) => out.push(e),
                }
            }
        }
        Some(())
    }

    /// The 2-D Newton for the vertex v: minimise o_v(c) = (v − p*(c))·c over the sphere
    /// (the superquadric–superquadric search with a point as the second body). Returns the
    /// last evaluation and whether it converged.
    fn solve_vertex(&mut self, v: V3, c0: V3) -> (Eval, bool) {
        let ntol = NEWTON_TOL * self.scale;
        let mut e = self.eval(c0);
        let mut mu = 0.0f64;
        let ov = |e: &Eval| (v - e.r).dot(&e.c);
        let resid = |e: &Eval| {
            let d = e.r - v;
            (d - e.c * d.dot(&e.c)).norm()
        };
        for _ in 0..MAX_ITERATIONS {
            let t = tangent_basis(&e.c);
            let d = e.r - v;
            let dt = [d.dot(&t.0), d.dot(&t.1)];
            let res = crate::shape::superquadric::hypot_fast(dt[0], dt[1]);
            if res <= ntol {
                return (e, true);
            }
            self.stats.iterations += 1;
            let s = d.dot(&e.c); // = −o_v
            let (gt0, gt1) = (e.g * t.0, e.g * t.1);
            let g = [
                t.0.dot(&gt0),
                0.5 * (t.0.dot(&gt1) + t.1.dot(&gt0)),
                t.1.dot(&gt1),
            ];
            let (low, ..) = sym2_eigen(g[0], g[1], g[2]);
            let floor = 1e-3 * (0.5 * (g[0] + g[2])).abs().max(ntol);
            let pd_shift = (floor - (low + s)).max(0.0);
            let (o_cur, r_cur) = (ov(&e), res);
            let mut shift = mu;
            let mut tries = 0;
            loop {
                tries += 1;
                let step = shifted_newton_step(g, s + shift, dt);
                let ok = step.is_some();
                let da = step.unwrap_or([0.0, 0.0]);
                let cn = rotate_normal(&e.c, &t, da);
                let trial = self.eval(cn);
                let (o_t, r_t) = (ov(&trial), resid(&trial));
                // o_v is minimised; near the solution its change is below round-off and the
                // residual decides (o must not grow beyond round-off)
                let better = ok
                    && o_t.is_finite()
                    && (o_t < o_cur || (r_t < r_cur && o_t <= o_cur + 1e-13 * self.scale));
                if better || tries > 40 {
                    e = trial;
                    mu *= 0.25;
                    if mu < 1e-6 * floor {
                        mu = 0.0;
                    }
                    break;
                }
                mu = if shift < pd_shift {
                    pd_shift + floor
                } else {
                    4.0 * shift.max(floor)
                };
                shift = mu;
            }
        }
        let ok = resid(&e) <= ACCEPT_TOL * self.scale;
        if !ok {
            self.stats.not_converged += 1;
        }
        (e, ok)
    }

    /// The contact of one convex piece: `None` if a separating direction was found.
    fn solve_piece(&mut self, p: &Piece, warm: Option<V3>) -> Option<Cand> {
        let tol = self.tol;
        let mut best: Option<Cand> = None;
        let mut upper: Option<Cand> = None;
        let keep = |slot: &mut Option<Cand>, c: Cand| {
            if slot.as_ref().is_none_or(|b| c.delta < b.delta) {
                *slot = Some(c);
            }
        };
        // the last normal: a separating plane ends the search
        if let Some(wc) = warm {
            if self.in_front(p, &wc) {
                let e = self.eval(wc);
                if self.overlap(p, &e) < 0.0 {
                    return None;
                }
            }
        }
        // faces
        let mut requests: Vec<Option<V3>> = vec![None; p.hverts.len()];
        let request = |requests: &mut Vec<Option<V3>>, v: usize, c: V3| {
            if let Some(i) = p.hverts.iter().position(|h| h.v == v) {
                requests[i].get_or_insert(c);
            }
        };
        let mut face_eval = Vec::with_capacity(p.groups.len());
        for g in &p.groups {
            let e = self.eval(g.n);
            let o = self.overlap(p, &e);
            if o < 0.0 {
                return None;
            }
            face_eval.push(e);
            let q = e.r + g.n * o;
            let (dist, t, bary) = self.in_face(g, &q);
            let cand = Cand {
                eval: e,
                delta: o,
                tri: t,
                bary,
                feature: Feature::Face,
            };
            keep(&mut upper, cand);
            if self.h(p, &g.n) > g.level + tol {
                continue; // not a face of the hull
            }
            if dist <= tol {
                keep(&mut best, cand);
            } else if let Some(k) = bary.iter().position(|&b| b == 1.0) {
                request(&mut requests, self.mesh.tris[t].v[k], g.n);
            }
        }
        // edges and the walls below the boundary edges
        let mut wall: Vec<Option<Eval>> = vec![None; p.edges.len()];
        let mut mins: Vec<Eval> = Vec::new();
        for (i, ed) in p.edges.iter().enumerate() {
            let a = self.mesh.pos[ed.a];
            let rf = face_eval[p.group_of_tri(ed.f)].r;
            let gp0 = (a - rf).dot(&ed.w);
            // near: the bounding sphere meets the edge, or the wall below a boundary edge
            let along = (-a).dot(&ed.e).clamp(0.0, ed.len);
            let down = if ed.g.is_none() {
                a.dot(&ed.u).max(0.0)
            } else {
                0.0
            };
            let near = (a + ed.e * along - ed.u * down).norm() <= self.bound;
            if !(gp0 < 0.0 || near) {
                continue; // the face f side is lower
            }
            let end = match ed.g {
                Some(g) => face_eval[p.group_of_tri(g)],
                None => {
                    let we = self.eval(ed.w);
                    let o = self.overlap(p, &we);
                    if o < 0.0 {
                        return None;
                    }
                    wall[i] = Some(we);
                    let gp1 = (we.r - a).dot(&ed.u);
                    let s = (we.r + ed.w * o - a).dot(&ed.e) / ed.len;
                    let cand = Cand {
                        eval: we,
                        delta: o,
                        tri: ed.f,
                        bary: self.edge_bary(ed.f, ed.a, ed.b, s),
                        feature: Feature::Edge,
                    };
                    keep(&mut upper, cand);
                    if gp1 <= 0.0 {
                        let stol = tol / ed.len;
                        if (-stol..=1.0 + stol).contains(&s)
                            && self.highest(p, ed.a, &ed.w)
                            && self.highest(p, ed.b, &ed.w)
                        {
                            keep(&mut best, cand);
                        } else if s < 0.0 {
                            request(&mut requests, ed.a, ed.w);
                        } else if s > 1.0 {
                            request(&mut requests, ed.b, ed.w);
                        }
                    }
                    we
                }
            };
            mins.clear();
            let start = face_eval[p.group_of_tri(ed.f)];
            self.scan_arc(
                p,
                a,
                ed.u,
                ed.w,
                ed.th1,
                (&start, &end),
                near,
                warm,
                &mut mins,
            )?;
            for &e in &mins {
                let o = self.overlap(p, &e);
                let s = (e.r + e.c * o - a).dot(&ed.e) / ed.len;
                let stol = tol / ed.len;
                if (-stol..=1.0 + stol).contains(&s)
                    && self.highest(p, ed.a, &e.c)
                    && self.highest(p, ed.b, &e.c)
                {
                    keep(
                        &mut best,
                        Cand {
                            eval: e,
                            delta: o,
                            tri: ed.f,
                            bary: self.edge_bary(ed.f, ed.a, ed.b, s),
                            feature: Feature::Edge,
                        },
                    );
                } else if s < 0.0 {
                    request(&mut requests, ed.a, e.c);
                } else if s > 1.0 {
                    request(&mut requests, ed.b, e.c);
                }
            }
        }
        // vertices, and the rays below the boundary vertices
        for (i, hv) in p.hverts.iter().enumerate() {
            let v = self.mesh.pos[hv.v];
            let inside = v.norm() <= self.bound && self.inside_body(&v);
            if requests[i].is_some() || inside {
                // starts: the last normal (if v is about highest there), the direction that
                // pointed here, the exit direction of v (−∇F), the two lowest of o_v sampled
                // over v's region (its face normals, the outward normals of its boundary
                // edges, their pairwise means and the mean of all), and the body's flat-ish
                // directions in the region. All are run and the lowest valid minimum kept:
                // o_v has several local minima where v lies near a sharp or flat part of the
                // body (ε near 2 or 0) or deep inside it.
                // a vertex outside the body cannot carry a positive minimum (that has v =
                // p* + δ c inside the body); it is only run once, from the direction that
                // pointed to it, for a separating plane
                let mut all_starts: Vec<V3> = Vec::new();
                if !inside {
                    all_starts.extend(requests[i]);
                } else {
                    let mut gens: Vec<V3> = Vec::new();
                    let edge_normals = p
                        .edges
                        .iter()
                        .filter(|e| e.g.is_none() && (e.a == hv.v || e.b == hv.v))
                        .map(|e| e.w);
                    for g in p
                        .vtris(hv)
                        .iter()
                        .map(|&t| self.mesh.tris[t].n)
                        .chain(edge_normals)
                    {
                        if !gens.iter().any(|h| h.dot(&g) > 1.0 - 1e-9) {
                            gens.push(g);
                        }
                    }
                    let mut sample_dirs: Vec<V3> = gens.clone();
                    for a in 0..gens.len() {
                        for b in a + 1..gens.len() {
                            if let Some(c) = (gens[a] + gens[b]).try_normalize(1e-6) {
                                sample_dirs.push(c);
                            }
                        }
                    }
                    if let Some(c) = gens.iter().sum::<V3>().try_normalize(1e-6) {
                        sample_dirs.push(c);
                    }
                    // a body with flat or sharp parts has a local minimum near each of their
                    // directions that lies in v's region: all are starts
                    let body: Vec<V3> = self
                        .body_directions()
                        .to_vec()
                        .into_iter()
                        .filter(|d| {
                            self.highest(p, hv.v, d) && gens.iter().any(|g| g.dot(d) >= 0.0)
                        })
                        .collect();
                    let mut sampled: Vec<(f64, V3)> = Vec::with_capacity(sample_dirs.len());
                    for c in sample_dirs {
                        let e = self.eval(c);
                        if self.in_front(p, &c) && self.overlap(p, &e) < 0.0 {
                            return None;
                        }
                        sampled.push(((v - e.r).dot(&c), c));
                    }
                    sampled.sort_by(|a, b| a.0.total_cmp(&b.0));
                    let starts = [
                        warm.filter(|w| self.h(p, w) - v.dot(w) <= 0.1 * self.scale),
                        requests[i],
                        (-(self.rot * self.shape.gradient(&(self.rot_t * v))))
                            .try_normalize(1e-300),
                    ];
                    let faces = sampled
                        .iter()
                        .take(2)
                        .map(|s| Some(s.1))
                        .chain(body.into_iter().map(Some));
                    all_starts.extend(starts.into_iter().chain(faces).flatten());
                }
                let mut tried: Vec<V3> = Vec::new();
                let mut found: Vec<V3> = Vec::new();
                for start in all_starts {
                    if tried.iter().any(|t| t.dot(&start) > 1.0 - 1e-9) {
                        continue;
                    }
                    tried.push(start);
                    let (e, converged) = self.solve_vertex(v, start);
                    let front = self.highest(p, hv.v, &e.c)
                        && p.vtris(hv)
                            .iter()
                            .any(|&t| self.mesh.tris[t].n.dot(&e.c) >= -1e-12);
                    if !front {
                        continue;
                    }
                    let o = self.overlap(p, &e);
                    if o < 0.0 {
                        return None;
                    }
                    if converged && !found.iter().any(|f| f.dot(&e.c) > 1.0 - 1e-12) {
                        found.push(e.c);
                        keep(
                            &mut best,
                            Cand {
                                eval: e,
                                delta: o,
                                tri: p.vtris(hv)[0],
                                bary: self.vertex_bary(p.vtris(hv)[0], hv.v),
                                feature: Feature::Vertex,
                            },
                        );
                    }
                }
            }
            let Some(ray) = &hv.ray else { continue };
            let foot = (-v.dot(&ray.down)).max(0.0);
            let near = (v + ray.down * foot).norm() <= self.bound;
            if !(requests[i].is_some() || inside || near) {
                continue;
            }
            let mut ends = Vec::with_capacity(2);
            for ei in [ray.e1, ray.e2] {
                let we = match wall[ei] {
                    Some(we) => we,
                    None => {
                        let we = self.eval(p.edges[ei].w);
                        if self.overlap(p, &we) < 0.0 {
                            return None;
                        }
                        wall[ei] = Some(we);
                        we
                    }
                };
                ends.push(we);
            }
            mins.clear();
            self.scan_arc(
                p,
                v,
                ray.u,
                ray.w,
                ray.th1,
                (&ends[0], &ends[1]),
                near,
                warm,
                &mut mins,
            )?;
            for &e in &mins {
                let o = self.overlap(p, &e);
                let depth = (e.r + e.c * o - v).dot(&ray.down);
                if depth >= -tol && self.highest(p, hv.v, &e.c) {
                    keep(
                        &mut best,
                        Cand {
                            eval: e,
                            delta: o,
                            tri: p.vtris(hv)[0],
                            bary: self.vertex_bary(p.vtris(hv)[0], hv.v),
                            feature: Feature::Vertex,
                        },
                    );
                }
            }
        }
        if best.is_none() {
            self.stats.fallback = true;
            return upper;
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::generate::{random_orientation, SplitMix64};
    use crate::rotation::{angular_momentum, angular_velocity, rotate};
    use nalgebra::UnitQuaternion;

    /// The outer corner of the cube [−l, 0]³: its three faces at the origin, outward x, y, z.
    fn cube_corner(l: f64) -> MeshB {
        let mut m = MeshB::default();
        let o = V3::zeros();
        let (x, y, z) = (
            V3::new(-l, 0.0, 0.0),
            V3::new(0.0, -l, 0.0),
            V3::new(0.0, 0.0, -l),
        );
        m.quad([o, y, y + z, z], V3::x());
        m.quad([o, x, x + z, z], V3::y());
        m.quad([o, x, x + y, y], V3::z());
        m
    }

    fn sq(r: [f64; 3], e1: f64, e2: f64) -> Superquadric {
        Superquadric::new(V3::new(r[0], r[1], r[2]), e1, e2).unwrap()
    }

    /// A triangle list with shared vertices (exact position match).
    #[derive(Default, Clone)]
    struct MeshB {
        v: Vec<V3>,
        t: Vec<[usize; 3]>,
    }

    impl MeshB {
        fn vid(&mut self, p: V3) -> usize {
            match self.v.iter().position(|q| (q - p).norm() < 1e-12) {
                Some(i) => i,
                None => {
                    self.v.push(p);
                    self.v.len() - 1
                }
            }
        }
        /// Triangle oriented so that its normal points to `front`.
        fn tri(&mut self, a: V3, b: V3, c: V3, front: V3) {
            let (ia, ib, ic) = (self.vid(a), self.vid(b), self.vid(c));
            if (b - a).cross(&(c - a)).dot(&front) >= 0.0 {
                self.t.push([ia, ib, ic]);
            } else {
                self.t.push([ia, ic, ib]);
            }
        }
        fn quad(&mut self, p: [V3; 4], front: V3) {
            self.tri(p[0], p[1], p[2], front);
            self.tri(p[0], p[2], p[3], front);
        }
        fn contact(
            &self,
            s: &Superquadric,
            x: V3,
            rot: &Matrix3<f64>,
            warm: Option<V3>,
        ) -> Option<PatchContact> {
            let mut st = PatchStats::default();
            let c = patch_contact_with_stats(s, x, rot, &self.v, &self.t, warm, &mut st);
            assert!(!st.fallback, "fallback at x = {x}");
            c
        }
    }

    /// p* − x of the body for the direction c (the lowest point along c).
    fn low(s: &Superquadric, rot: &Matrix3<f64>, c: &V3) -> V3 {
        rot * s.point(&-(rot.transpose() * c))
    }

    fn shapes() -> Vec<Superquadric> {
        vec![
            sq([0.5, 0.3, 0.2], 0.3, 0.3),
            sq([0.5, 0.25, 0.2], 1.0, 0.5),
            sq([0.45, 0.3, 0.15], 1.7, 1.2),
            sq([0.5, 0.2, 0.3], 0.5, 1.7),
        ]
    }

    /// Body over a large tilted 2-triangle square, sliding across the diagonal: δ, point and
    /// normal are the body–plane values (support point along −n) to 1e-12, and constant.
    #[test]
    fn plane_limit_and_coplanar_diagonal() {
        let mut rng = SplitMix64::new(1);
        let r0 = *random_orientation(&mut rng).to_rotation_matrix().matrix();
        let off = V3::new(3.0, -2.0, 7.0);
        let n = r0 * V3::z();
        let mut m = MeshB::default();
        let p = [(-5.0, -5.0), (5.0, -5.0), (5.0, 5.0), (-5.0, 5.0)]
            .map(|(a, b)| off + r0 * V3::new(a, b, 0.0));
        m.quad(p, n); // the diagonal joins (−5, −5) and (5, 5)
        for s in shapes() {
            let rot = *random_orientation(&mut rng).to_rotation_matrix().matrix();
            let r = low(&s, &rot, &n);
            let height = -r.dot(&n) - 0.03;
            let mut deltas = Vec::new();
            let mut warm = None;
            for k in 0..=200 {
                let t = -1.0 + 2.0 * k as f64 / 200.0;
                // crosses the diagonal y = x at t = 0
                let x = off + r0 * V3::new(t + 0.3, -t + 0.3, 0.0) + n * height;
                let c = m.contact(&s, x, &rot, warm).expect("contact");
                warm = Some(c.normal);
                let pstar = x + r;
                let plane = (off - pstar).dot(&n);
                assert_eq!(c.feature, Feature::Face);
                assert!((c.normal - n).norm() < 1e-12, "{} vs {n}", c.normal);
                assert!(
                    (c.overlap - plane).abs() < 1e-12,
                    "{} vs {plane}",
                    c.overlap
                );
                assert!((c.point - pstar).norm() < 1e-12);
                let q: V3 = (0..3).map(|i| m.v[m.t[c.triangle][i]] * c.bary[i]).sum();
                assert!((q - (pstar + n * c.overlap)).norm() < 1e-11);
                deltas.push(c.overlap);
            }
            let (lo, hi) = deltas
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &d| {
                    (a.min(d), b.max(d))
                });
            assert!(
                hi - lo < 1e-12,
                "δ varies by {} across the diagonal",
                hi - lo
            );
            assert!((hi - 0.03).abs() < 1e-12);
        }
    }

    /// A sweep of the body centre along `path(s)`, s ∈ [0, 1], with warm starts (each sample
    /// also cold, the same result): checks that δ is 1-Lipschitz in the translation (|Δδ| ≤
    /// |Δx|, as ∂δ/∂x = −c) and bisects every normal change above 0.02 (and the 4 largest)
    /// 40 times: a jump that survives must be a verified tie of two minima (same δ, each
    /// normal optimal on both sides). Returns the features met (in order, None = no contact)
    /// and the number of ties.
    fn sweep(
        s: &Superquadric,
        rot: &Matrix3<f64>,
        m: &MeshB,
        path: &dyn Fn(f64) -> V3,
        n: usize,
        label: &str,
    ) -> (Vec<Option<Feature>>, usize) {
        sweep_with(s, rot, m, path, n, label, 0.0)
    }

    /// [`sweep`] allowing normal jumps up to `allowed` (rad; the switch between the pieces
    /// of a concave fold).
    fn sweep_with(
        s: &Superquadric,
        rot: &Matrix3<f64>,
        m: &MeshB,
        path: &dyn Fn(f64) -> V3,
        n: usize,
        label: &str,
        allowed: f64,
    ) -> (Vec<Option<Feature>>, usize) {
        let at = |t: f64, warm: Option<V3>| m.contact(s, path(t), rot, warm);
        let mut samples = Vec::with_capacity(n + 1);
        let mut warm = None;
        for k in 0..=n {
            let t = k as f64 / n as f64;
            let c = at(t, warm);
            // warm and cold starts agree
            let cold = at(t, None);
            match (&c, &cold) {
                (Some(a), Some(b)) => {
                    assert!(
                        (a.overlap - b.overlap).abs() < 1e-11
                            && (a.normal - b.normal).norm() < 1e-8,
                        "{label}: warm {a:?} vs cold {b:?} at x = {:?}, rot {:?}, warm {:?}",
                        path(t).as_slice(),
                        rot.as_slice(),
                        warm.map(|w| w.as_slice().to_vec())
                    )
                }
                (None, None) => {}
                _ => panic!("{label}: warm {c:?} vs cold {cold:?}"),
            }
            warm = c.map(|c| c.normal);
            samples.push((t, c));
        }
        let mut feats: Vec<Option<Feature>> = Vec::new();
        let mut jumps: Vec<(f64, f64, f64)> = Vec::new();
        for w in samples.windows(2) {
            let ((t0, c0), (t1, c1)) = (&w[0], &w[1]);
            let dx = (path(*t1) - path(*t0)).norm();
            let (d0, d1) = (c0.map_or(0.0, |c| c.overlap), c1.map_or(0.0, |c| c.overlap));
            assert!(
                (d1 - d0).abs() <= dx * (1.0 + 1e-9) + 1e-10,
                "{label}: δ jumps by {} over a step of {dx} at s = {t0}: {c0:?} → {c1:?}",
                d1 - d0
            );
            if let (Some(a), Some(b)) = (c0, c1) {
                jumps.push(((a.normal - b.normal).norm(), *t0, *t1));
            }
        }
        for (_, c) in &samples {
            let f = c.map(|c| c.feature);
            if feats.last() != Some(&f) {
                feats.push(f);
            }
        }
        jumps.sort_by(|a, b| b.0.total_cmp(&a.0));
        let mut ties = 0;
        let big = jumps.iter().filter(|j| j.0 > 0.02).count().max(4);
        for &(j, mut t0, mut t1) in jumps.iter().take(big) {
            let mut jump = j;
            for _ in 0..40 {
                let tm = 0.5 * (t0 + t1);
                let (Some(a), Some(b), Some(c)) = (at(t0, None), at(tm, None), at(t1, None)) else {
                    break;
                };
                let (j0, j1) = ((a.normal - b.normal).norm(), (b.normal - c.normal).norm());
                if j0 >= j1 {
                    t1 = tm;
                    jump = j0;
                } else {
                    t0 = tm;
                    jump = j1;
                }
            }
            if jump < 1e-6 || jump <= 2.0 * (0.5 * allowed).sin() {
                continue;
            }
            // a jump that survives the bisection must be a tie of two minima: the same δ on
            // both sides, and each side's normal gives that δ at the other side's pose too
            let (a, b) = (at(t0, None).unwrap(), at(t1, None).unwrap());
            let o_at = |x: V3, c: &V3| {
                m.v.iter()
                    .map(|v| v.dot(c))
                    .fold(f64::NEG_INFINITY, f64::max)
                    - (x + low(s, rot, c)).dot(c)
            };
            let (x0, x1) = (path(t0), path(t1));
            // (to 1e-6 relative, the accuracy asserted against the brute force)
            let eq = |x: f64, y: f64| (x - y).abs() <= 1e-6 * x.abs().max(y.abs());
            let tie = eq(a.overlap, b.overlap)
                && eq(o_at(x0, &b.normal), a.overlap)
                && eq(o_at(x1, &a.normal), b.overlap);
            assert!(
                tie,
                "{label}: the normal jumps by {jump} at s = {t0} (was {j}): {a:?} → {b:?}"
            );
            println!(
                "{label}: tie of two minima at s = {t0}: the normal turns by {jump:.3} at δ = {:.9} | {:.9}",
                a.overlap, b.overlap
            );
            ties += 1;
        }
        (feats, ties)
    }

    /// Across the boundary edge of a flat patch, a convex box edge (90° and 150°) and over a
    /// box corner (3 faces): δ and the normal are continuous and the features go
    /// Face → Edge (→ Vertex) → ….
    #[test]
    fn continuity_across_edges_and_corner() {
        let mut rng = SplitMix64::new(2);
        let (mut sweeps, mut total_ties) = (0, 0);
        for (si, s) in shapes().into_iter().enumerate() {
            for _ in 0..2 {
                let rot = *random_orientation(&mut rng).to_rotation_matrix().matrix();
                // the body placed so that its lowest point along c lies 0.03 below the point
                // q of the patch (along c)
                let place = |q: V3, c: V3| q - c * 0.03 - low(&s, &rot, &c);
                let height = |c: V3| -low(&s, &rot, &c).dot(&c) - 0.03;
                // (a) the boundary edge x = 0 of a flat patch
                let mut flat = MeshB::default();
                flat.quad(
                    [
                        V3::new(-3.0, -2.0, 0.0),
                        V3::new(0.0, -2.0, 0.0),
                        V3::new(0.0, 2.0, 0.0),
                        V3::new(-3.0, 2.0, 0.0),
                    ],
                    V3::z(),
                );
                let hz = height(V3::z());
                let path = |t: f64| V3::new(-0.8 + 1.6 * t, 0.1, hz);
                let (f, ties) = sweep(
                    &s,
                    &rot,
                    &flat,
                    &path,
                    400,
                    &format!("flat edge, shape {si}"),
                );
                assert_eq!(f[0], Some(Feature::Face), "{f:?}");
                assert_eq!(*f.last().unwrap(), None, "{f:?}");
                if ties == 0 {
                    assert!(f.contains(&Some(Feature::Edge)), "{f:?}");
                }
                total_ties += ties;
                sweeps += 1;
                // (b) convex edges: face A z = 0 (x ≤ 0), face B turned down by τ
                for alpha in [90.0f64, 150.0] {
                    let tau = (180.0 - alpha).to_radians();
                    let db = V3::new(tau.cos(), 0.0, -tau.sin());
                    let nb = V3::new(tau.sin(), 0.0, tau.cos());
                    let mut m = MeshB::default();
                    let (e0, e1) = (V3::new(0.0, -2.0, 0.0), V3::new(0.0, 2.0, 0.0));
                    m.quad(
                        [V3::new(-3.0, -2.0, 0.0), e0, e1, V3::new(-3.0, 2.0, 0.0)],
                        V3::z(),
                    );
                    m.quad([e0, e0 + db * 3.0, e1 + db * 3.0, e1], nb);
                    let ep = V3::new(0.0, 0.1, 0.0);
                    let path = |t: f64| {
                        let phi = -0.8 + (tau + 1.6) * t;
                        if phi < 0.0 {
                            place(ep + V3::x() * (1.5 * phi), V3::z())
                        } else if phi > tau {
                            place(ep + db * (1.5 * (phi - tau)), nb)
                        } else {
                            place(ep, V3::new(phi.sin(), 0.0, phi.cos()))
                        }
                    };
                    let (f, ties) = sweep(
                        &s,
                        &rot,
                        &m,
                        &path,
                        600,
                        &format!("{alpha}° edge, shape {si}"),
                    );
                    assert_eq!(f.first(), Some(&Some(Feature::Face)), "{f:?}");
                    assert_eq!(f.last(), Some(&Some(Feature::Face)), "{f:?}");
                    assert!(!f.contains(&None), "{f:?}");
                    if ties == 0 {
                        assert_eq!(
                            f,
                            [
                                Some(Feature::Face),
                                Some(Feature::Edge),
                                Some(Feature::Face)
                            ]
                        );
                    }
                    total_ties += ties;
                    sweeps += 1;
                }
                // (c) the corner of the cube [−2, 0]³
                let m = cube_corner(2.0);
                let o = V3::zeros();
                // the target point q and direction c: along face z to the edge (z, x), around
                // it, along it to the corner, into the corner's cone, out onto face x
                let lerp = |a: V3, b: V3, t: f64| a * (1.0 - t) + b * t;
                let (e_pt, bis, diag) = (
                    V3::new(0.0, -0.6, 0.0),
                    V3::new(1.0, 0.0, 1.0).normalize(),
                    V3::new(1.0, 1.0, 1.0).normalize(),
                );
                let path = |t: f64| {
                    let u = 6.0 * t;
                    let (k, f) = ((u.floor() as usize).min(5), u - (u.floor()).min(5.0));
                    let (q, c) = match k {
                        0 => (lerp(V3::new(-0.6, -0.6, 0.0), e_pt, f), V3::z()),
                        1 => (e_pt, lerp(V3::z(), bis, f)),
                        2 => (lerp(e_pt, o, f), bis),
                        3 => (o, lerp(bis, diag, f)),
                        4 => (o, lerp(diag, V3::x(), f)),
                        _ => (lerp(o, V3::new(0.0, -0.6, -0.6), f), V3::x()),
                    };
                    place(q, c.normalize())
                };
                let (f, ties) = sweep(&s, &rot, &m, &path, 800, &format!("corner, shape {si}"));
                assert_eq!(f.first(), Some(&Some(Feature::Face)), "{f:?}");
                assert_eq!(f.last(), Some(&Some(Feature::Face)), "{f:?}");
                assert!(!f.contains(&None), "{f:?}");
                if ties == 0 {
                    let iv = f.iter().position(|x| *x == Some(Feature::Vertex));
                    let ie = f.iter().position(|x| *x == Some(Feature::Edge));
                    assert!(iv.is_some() && ie.is_some() && ie < iv, "{f:?}");
                } else {
                    assert!(f.contains(&Some(Feature::Vertex)), "{f:?}");
                }
                total_ties += ties;
                sweeps += 1;
            }
        }
        println!("{sweeps} sweeps, {total_ties} ties of two minima (normal jumps at equal δ)");
    }

    /// Frictionless elastic impact, integrated by velocity Verlet with the rotation update of
    /// `rotation::rotate` (angular-momentum half kicks): force k δ^{3/2} c at `point`.
    /// Returns (energy before, energy after, features met, contact steps).
    #[allow(clippy::too_many_arguments)]
    fn impact(
        s: &Superquadric,
        m: &MeshB,
        x0: V3,
        v0: V3,
        q0: UnitQuaternion<f64>,
        w0: V3,
        k: f64,
        dt: f64,
    ) -> (f64, f64, Vec<Feature>, usize) {
        let (mass, inertia) = s.mass_properties(1.0);
        let (mut x, mut v, mut q) = (x0, v0, q0);
        let mut h = angular_momentum(&q, &w0, &inertia);
        let mut warm = None;
        let mut feats: Vec<Feature> = Vec::new();
        let mut force = |x: V3, q: &UnitQuaternion<f64>, warm: &mut Option<V3>| -> (V3, V3, f64) {
            let rot = *q.to_rotation_matrix().matrix();
            match m.contact(s, x, &rot, *warm) {
                Some(c) => {
                    *warm = Some(c.normal);
                    if feats.last() != Some(&c.feature) {
                        feats.push(c.feature);
                    }
                    // the barycentric split: Σ N = 1 and Σ N x = q = p* + δ c
                    let sum: f64 = c.bary.iter().sum();
                    assert!(
                        (sum - 1.0).abs() < 1e-12 && c.bary.iter().all(|b| (0.0..=1.0).contains(b))
                    );
                    let qw: V3 = (0..3).map(|i| m.v[m.t[c.triangle][i]] * c.bary[i]).sum();
                    let qc = c.point + c.normal * c.overlap;
                    assert!(
                        (qw - qc).norm() < 1e-9,
                        "Σ N x = {qw} vs {qc} ({:?})",
                        c.feature
                    );
                    let f = c.normal * (k * c.overlap.powf(1.5));
                    (f, (c.point - x).cross(&f), 0.4 * k * c.overlap.powf(2.5))
                }
                None => {
                    *warm = None;
                    (V3::zeros(), V3::zeros(), 0.0)
                }
            }
        };
        let energy = |v: &V3, q: &UnitQuaternion<f64>, h: &V3, w: f64| {
            0.5 * mass * v.norm_squared() + 0.5 * angular_velocity(q, h, &inertia).dot(h) + w
        };
        let (mut f, mut tq, mut w) = force(x, &q, &mut warm);
        assert_eq!(w, 0.0, "starts in contact");
        let e0 = energy(&v, &q, &h, w);
        let (mut steps, mut in_contact, mut after) = (0, 0, 0);
        for _ in 0..200_000 {
            v += f * (0.5 * dt / mass);
            h += tq * (0.5 * dt);
            x += v * dt;
            q = rotate(&q, &h, &inertia, dt).0;
            (f, tq, w) = force(x, &q, &mut warm);
            v += f * (0.5 * dt / mass);
            h += tq * (0.5 * dt);
            steps += 1;
            if w > 0.0 {
                in_contact += 1;
            } else if in_contact > 0 {
                after += 1;
                if after > 20 {
                    break;
                }
            }
        }
        assert!(
            in_contact > 0 && after > 20,
            "no complete impact in {steps} steps"
        );
        (e0, energy(&v, &q, &h, w), feats, in_contact)
    }

    /// The key test: a spinning, elongated, angular superquadric hits a face, a box edge, a
    /// box corner, and slides over a convex edge: the total energy is kept to 1e-5.
    #[test]
    fn frictionless_impacts_conserve_energy() {
        // angular (the brief's body) and pointed (ε near 2: several minima of o, ties)
        impacts_of(&sq([0.5, 0.25, 0.2], 0.4, 0.6), true);
        impacts_of(&sq([0.5, 0.3, 0.2], 1.7, 1.2), false);
    }

    fn impacts_of(s: &Superquadric, check_features: bool) {
        let s = *s;
        let (mass, _) = s.mass_properties(1.0);
        let k = 1.25 * mass / 0.01f64.powf(2.5); // δ_max ≈ 0.01 at 1 m/s
        let dt = 1e-5;
        let mut rng = SplitMix64::new(3);
        let q0 = random_orientation(&mut rng);
        let rot0 = *q0.to_rotation_matrix().matrix();
        let w0 = V3::new(3.0, -5.0, 8.0);
        let gap = |c: V3| -low(&s, &rot0, &c).dot(&c) + 0.003;
        // (a) a face
        let mut face = MeshB::default();
        face.quad(
            [
                V3::new(-3.0, -3.0, 0.0),
                V3::new(3.0, -3.0, 0.0),
                V3::new(3.0, 3.0, 0.0),
                V3::new(-3.0, 3.0, 0.0),
            ],
            V3::z(),
        );
        // (b) a 90° box edge along y
        let box_edge = |tau: f64| {
            let db = V3::new(tau.cos(), 0.0, -tau.sin());
            let nb = V3::new(tau.sin(), 0.0, tau.cos());
            let mut m = MeshB::default();
            let (e0, e1) = (V3::new(0.0, -2.0, 0.0), V3::new(0.0, 2.0, 0.0));
            m.quad(
                [V3::new(-3.0, -2.0, 0.0), e0, e1, V3::new(-3.0, 2.0, 0.0)],
                V3::z(),
            );
            m.quad([e0, e0 + db * 3.0, e1 + db * 3.0, e1], nb);
            m
        };
        // (c) a cube corner
        let corner = cube_corner(2.0);
        let d2 = V3::new(1.0, 0.0, 1.0).normalize();
        let d3 = V3::new(1.0, 1.0, 1.0).normalize();
        let cases: Vec<(&str, MeshB, V3, V3)> = vec![
            (
                "face",
                face,
                V3::new(0.1, -0.2, 0.0) + V3::z() * gap(V3::z()),
                V3::new(0.2, 0.1, -1.0),
            ),
            (
                "90° edge",
                box_edge(std::f64::consts::FRAC_PI_2),
                V3::new(0.0, 0.1, 0.0) + d2 * gap(d2),
                -d2 + V3::new(0.05, 0.1, 0.0),
            ),
            (
                "corner",
                corner,
                d3 * gap(d3),
                -d3 + V3::new(0.03, -0.05, 0.02),
            ),
            (
                "sliding over a 150° edge",
                box_edge(30f64.to_radians()),
                V3::new(-0.06, 0.1, 0.002) - low(&s, &rot0, &V3::z()),
                V3::new(3.0, 0.2, -0.3),
            ),
        ];
        for (label, m, x0, v0) in cases {
            let (e0, e1, feats, n) = impact(&s, &m, x0, v0, q0, w0, k, dt);
            let err = (e1 - e0).abs() / e0;
            println!(
                "ε = ({}, {}), {label}: {n} contact steps, features {feats:?}, energy {e0:.9} → {e1:.9}, relative error {err:.2e}",
                s.eps1, s.eps2
            );
            assert!(err < 1e-5, "{label}: energy error {err:.2e}");
            match label {
                _ if !check_features => {}
                "face" => assert_eq!(feats, vec![Feature::Face]),
                "90° edge" => assert!(feats.contains(&Feature::Edge), "{feats:?}"),
                "corner" => assert!(feats.contains(&Feature::Vertex), "{feats:?}"),
                _ => assert!(
                    feats.contains(&Feature::Face) && feats.contains(&Feature::Edge),
                    "{feats:?}"
                ),
            }
        }
    }

    /// δ by brute force: the minimum of o(c) = h(c) − φ(c) over the front directions F,
    /// from (i) a spherical Fibonacci grid refined by zooming tangent-plane grids (a smooth
    /// interior minimum), (ii) zooming 1-D grids along every great circle on which o may have
    /// a kink or F a border — c ⊥ (v_i − v_j) for every vertex pair (two vertices tie) and
    /// c ⊥ n for every triangle normal — and (iii) the intersections of any two of those
    /// circles. No use of the patch's edges or faces as such.
    fn brute_force(s: &Superquadric, x: V3, rot: &Matrix3<f64>, m: &MeshB) -> (f64, V3) {
        let normals: Vec<V3> =
            m.t.iter()
                .map(|t| {
                    (m.v[t[1]] - m.v[t[0]])
                        .cross(&(m.v[t[2]] - m.v[t[0]]))
                        .normalize()
                })
                .collect();
        let o = |c: &V3| -> Option<f64> {
            let h =
                m.v.iter()
                    .map(|v| v.dot(c))
                    .fold(f64::NEG_INFINITY, f64::max);
            let front =
                m.t.iter().zip(&normals).any(|(t, n)| {
                    n.dot(c) >= -1e-13 && t.iter().any(|&i| m.v[i].dot(c) >= h - 1e-12)
                });
            front.then(|| h - (x + low(s, rot, c)).dot(c))
        };
        let mut best = (f64::INFINITY, V3::z());
        let try_c = |c: V3, best: &mut (f64, V3)| -> bool {
            match o(&c) {
                Some(v) if v < best.0 => {
                    *best = (v, c);
                    true
                }
                _ => false,
            }
        };
        // (i)
        let n = 40_000;
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        for k in 0..n {
            let z = 1.0 - (k as f64 + 0.5) / n as f64 * 2.0;
            let r = (1.0 - z * z).sqrt();
            try_c(
                V3::new(
                    r * (golden * k as f64).cos(),
                    r * (golden * k as f64).sin(),
                    z,
                ),
                &mut best,
            );
        }
        let mut w = 0.05;
        for _ in 0..30 {
            let (t1, t2) = tangent_basis(&best.1);
            let c0 = best.1;
            for i in -10..=10 {
                for j in -10..=10 {
                    try_c(
                        (c0 + t1 * (w * i as f64 / 10.0) + t2 * (w * j as f64 / 10.0)).normalize(),
                        &mut best,
                    );
                }
            }
            w *= 0.25;
        }
        // (ii) circles
        let mut axes: Vec<V3> = normals.clone();
        for i in 0..m.v.len() {
            for j in i + 1..m.v.len() {
                if let Some(a) = (m.v[j] - m.v[i]).try_normalize(1e-12) {
                    axes.push(a);
                }
            }
        }
        for a in &axes {
            let (u, w1) = tangent_basis(a);
            let at = |t: f64| u * t.cos() + w1 * t.sin();
            let mut cb = (f64::INFINITY, 0.0);
            for k in 0..3600 {
                let t = k as f64 * std::f64::consts::TAU / 3600.0;
                if let Some(v) = o(&at(t)) {
                    if v < cb.0 {
                        cb = (v, t);
                    }
                }
            }
            if !cb.0.is_finite() {
                continue;
            }
            let mut w = std::f64::consts::TAU / 3600.0;
            for _ in 0..200 {
                let t0 = cb.1;
                let mut rim = false;
                for k in -20i32..=20 {
                    let t = t0 + w * k as f64 / 20.0;
                    if let Some(v) = o(&at(t)) {
                        if v < cb.0 {
                            cb = (v, t);
                            rim = k.abs() == 20;
                        }
                    }
                }
                if !rim {
                    w *= 0.25;
                    if w < 1e-13 {
                        break;
                    }
                }
            }
            try_c(at(cb.1), &mut best);
        }
        // (iii) points
        for i in 0..axes.len() {
            for j in i + 1..axes.len() {
                if let Some(c) = axes[i].cross(&axes[j]).try_normalize(1e-9) {
                    try_c(c, &mut best);
                    try_c(-c, &mut best);
                }
            }
        }
        best
    }

    /// Random poses near three small convex patches (a pyramid cap, a cube corner, a flat
    /// square): δ equals the brute-force minimum to 1e-6 relative.
    #[test]
    fn overlap_matches_brute_force() {
        let mut rng = SplitMix64::new(4);
        let mut cap = MeshB::default();
        let apex = V3::new(0.0, 0.0, 0.12);
        let base =
            [(0.4, 0.4), (-0.4, 0.4), (-0.4, -0.4), (0.4, -0.4)].map(|(a, b)| V3::new(a, b, 0.0));
        for i in 0..4 {
            let (a, b) = (base[i], base[(i + 1) % 4]);
            let n = (a - apex).cross(&(b - apex));
            cap.tri(apex, a, b, if n.z > 0.0 { n } else { -n });
        }
        let corner = cube_corner(0.5);
        let mut flat = MeshB::default();
        flat.quad(
            [
                V3::new(-0.3, -0.3, 0.0),
                V3::new(0.3, -0.3, 0.0),
                V3::new(0.3, 0.3, 0.0),
                V3::new(-0.3, 0.3, 0.0),
            ],
            V3::z(),
        );
        let mut counts = std::collections::BTreeMap::new();
        let mut worst: f64 = 0.0;
        let mut deep = (0, 0);
        // "behind": the flat square with directions around its plane (bodies reaching
        // behind it at the border: the walls below its edges, the rays below its corners)
        for (name, m) in [
            ("cap", &cap),
            ("corner", &corner),
            ("flat", &flat),
            ("behind", &flat),
        ] {
            let mut done = 0;
            while done < 60 {
                let s = sq(
                    [
                        0.1 + 0.25 * rng.uniform(),
                        0.1 + 0.25 * rng.uniform(),
                        0.1 + 0.25 * rng.uniform(),
                    ],
                    0.3 + 1.4 * rng.uniform(),
                    0.3 + 1.4 * rng.uniform(),
                );
                let rot = *random_orientation(&mut rng).to_rotation_matrix().matrix();
                // a target point on a random triangle (a third of them at a vertex, a third
                // on an edge), a direction around its normal
                let t = m.t[(rng.uniform() * m.t.len() as f64) as usize];
                let (a, b) = (rng.uniform(), rng.uniform());
                let (a, b) = if a + b > 1.0 {
                    (1.0 - a, 1.0 - b)
                } else {
                    (a, b)
                };
                let (a, b) = match done % 3 {
                    0 => (0.0, 0.0),
                    1 => (a, 0.0),
                    _ => (a, b),
                };
                let q0 = m.v[t[0]] + (m.v[t[1]] - m.v[t[0]]) * a + (m.v[t[2]] - m.v[t[0]]) * b;
                let nt = (m.v[t[1]] - m.v[t[0]])
                    .cross(&(m.v[t[2]] - m.v[t[0]]))
                    .normalize();
                let c0 = (nt + V3::new(rng.normal(), rng.normal(), rng.normal()) * 0.5).normalize();
                let c0 = if name == "behind" {
                    // outward in the plane, tilted by at most ±0.3
                    let out = V3::new(q0.x, q0.y, 0.0).normalize();
                    (out + nt * (0.6 * rng.uniform() - 0.3)).normalize()
                } else {
                    c0
                };
                if name != "behind" && c0.dot(&nt) < 0.7 {
                    continue;
                }
                let pen = 0.003 + 0.04 * rng.uniform();
                let x = q0 - c0 * pen - low(&s, &rot, &c0);
                let (bf, bc) = brute_force(&s, x, &rot, m);
                if bf > 0.3 * s.radii.min() {
                    // deep (δ > 0.3 × the smallest semi-axis): counted, not asserted
                    let got = m.contact(&s, x, &rot, None).map_or(0.0, |c| c.overlap);
                    deep.0 += 1;
                    if (got - bf).abs() <= 1e-6 * bf {
                        deep.1 += 1;
                    }
                    continue;
                }
                let got = m.contact(&s, x, &rot, None);
                if bf <= 1e-9 {
                    assert!(
                        got.is_none_or(|c| c.overlap < 1e-8),
                        "{name}: brute force {bf}, got {got:?}"
                    );
                    continue;
                }
                let c = got.unwrap_or_else(|| panic!("{name}: brute force δ = {bf}, no contact"));
                let rel = (c.overlap - bf).abs() / bf;
                worst = worst.max(rel);
                assert!(
                    rel < 1e-6,
                    "{name}: δ = {} vs brute force {bf} (rel {rel:.1e}), normal {} vs {bc}, {:?}",
                    c.overlap,
                    c.normal,
                    c.feature
                );
                // a warm start from a nearby direction gives the same contact
                let warm = (c.normal + V3::new(0.01, -0.02, 0.015)).normalize();
                let w = m.contact(&s, x, &rot, Some(warm)).expect("warm");
                assert!((w.overlap - c.overlap).abs() < 1e-11 * bf.max(1.0));
                let back = if c.normal.z.abs() < 1e-9 && name != "corner" {
                    " (back)"
                } else {
                    ""
                };
                *counts
                    .entry(format!("{name} {:?}{back}", c.feature))
                    .or_insert(0) += 1;
                done += 1;
            }
        }
        println!("brute force: worst relative δ difference {worst:.2e}; {counts:?}; deeper poses (δ > 0.3 r_min, not asserted): {} of {} agree", deep.1, deep.0);
        for f in ["Face", "Edge", "Vertex"] {
            assert!(
                counts.keys().any(|k| k.ends_with(f)),
                "{f} never met: {counts:?}"
            );
        }
    }

    /// A patch joined across a 0.5° concave fold and a flat L-shaped patch are split into
    /// convex pieces; δ stays 1-Lipschitz and is the plane value inside the faces.
    #[test]
    fn concave_fold_and_non_convex_outline() {
        let mut rng = SplitMix64::new(5);
        let s = sq([0.5, 0.25, 0.2], 0.6, 1.2);
        let rot = *random_orientation(&mut rng).to_rotation_matrix().matrix();
        let height = |c: V3| -low(&s, &rot, &c).dot(&c) - 0.03;
        let a = 0.5f64.to_radians();
        let mut fold = MeshB::default();
        let (e0, e1) = (V3::new(0.0, -2.0, 0.0), V3::new(0.0, 2.0, 0.0));
        fold.quad(
            [V3::new(-3.0, -2.0, 0.0), e0, e1, V3::new(-3.0, 2.0, 0.0)],
            V3::z(),
        );
        let up = V3::new(a.cos(), 0.0, a.sin()) * 3.0;
        fold.quad([e0, e0 + up, e1 + up, e1], V3::new(-a.sin(), 0.0, a.cos()));
        let mut st = PatchStats::default();
        patch_contact_with_stats(
            &s,
            V3::new(0.0, 0.0, height(V3::z())),
            &rot,
            &fold.v,
            &fold.t,
            None,
            &mut st,
        );
        assert_eq!(st.pieces, 2);
        let hz = height(V3::z());
        let path = |t: f64| V3::new(-1.0 + 2.0 * t, 0.1, hz);
        let (f, _) = sweep_with(&s, &rot, &fold, &path, 400, "0.5° concave fold", 1.001 * a);
        assert!(!f.contains(&None), "{f:?}");
        // the L: three unit squares, the quadrant x, y > 0 missing
        let mut l = MeshB::default();
        for (x0, y0) in [(-2.0, -2.0), (0.0, -2.0), (-2.0, 0.0)] {
            l.quad(
                [
                    V3::new(x0, y0, 0.0),
                    V3::new(x0 + 2.0, y0, 0.0),
                    V3::new(x0 + 2.0, y0 + 2.0, 0.0),
                    V3::new(x0, y0 + 2.0, 0.0),
                ],
                V3::z(),
            );
        }
        let path = |t: f64| V3::new(-1.0 + 2.5 * t, -0.9 + 2.5 * t, hz);
        let (f, _) = sweep_with(&s, &rot, &l, &path, 500, "L-shaped patch", 0.0);
        assert_eq!(f.first(), Some(&Some(Feature::Face)));
        let r = low(&s, &rot, &V3::z());
        for k in 0..=100 {
            let x = path(k as f64 / 100.0);
            let p = x + r;
            // the plane value wherever p* lies in the L (off its border)
            if p.x.min(p.y) < -1e-6 && p.x.max(p.y) < 2.0 && p.x.min(p.y) > -2.0 {
                let c = l.contact(&s, x, &rot, None).expect("contact");
                assert!(
                    (c.overlap - 0.03).abs() < 1e-12 && (c.normal - V3::z()).norm() < 1e-12,
                    "{c:?}"
                );
            }
        }
    }

    /// Degenerate triangles, out-of-range indices, a NaN warm start, the centre exactly on an
    /// edge or a vertex: no NaN, no panic.
    #[test]
    fn degenerate_input_is_guarded() {
        let s = sq([0.5, 0.25, 0.2], 0.4, 1.6);
        let m = cube_corner(1.0);
        let o = V3::zeros();
        let mut bad = m.clone();
        let (i, j) = (
            bad.vid(V3::new(-0.5, 0.0, 0.0)),
            bad.vid(V3::new(-0.25, 0.0, 0.0)),
        );
        bad.t.push([0, i, j]); // collinear
        bad.t.push([0, 0, 1]); // repeated vertex
        bad.t.push([0, 1, 999]); // out of range
        bad.t.push(m.t[0]); // duplicate
        let rot = Matrix3::identity();
        for x in [
            V3::zeros(),
            V3::new(0.0, 0.0, -0.3),
            V3::new(-0.5, 0.0, 0.0),
            V3::new(0.3, 0.3, 0.3),
            V3::new(0.05, 0.05, 0.05),
        ] {
            for warm in [
                None,
                Some(V3::new(f64::NAN, 0.0, 1.0)),
                Some(V3::zeros()),
                Some(-V3::z()),
            ] {
                for mesh in [&m, &bad] {
                    if let Some(c) = patch_contact(&s, x, &rot, &mesh.v, &mesh.t, warm) {
                        assert!(
                            c.overlap.is_finite()
                                && c.normal.iter().all(|v| v.is_finite())
                                && c.point.iter().all(|v| v.is_finite())
                                && c.radii.iter().all(|v| !v.is_nan())
                                && c.bary.iter().all(|v| v.is_finite()),
                            "{c:?}"
                        );
                        assert!((c.normal.norm() - 1.0).abs() < 1e-12);
                    }
                }
            }
        }
        assert!(patch_contact(&s, o, &rot, &m.v, &[], None).is_none());
        assert!(patch_contact(&s, o, &rot, &m.v, &[[0, 0, 0]], None).is_none());
    }

    /// The radius tensor: for an ellipsoid at the tip of its x axis on a plane, the principal
    /// radii are b²/a and c²/a.
    #[test]
    fn radii_on_a_plane() {
        let s = sq([1.0, 1.5, 2.0], 1.0, 1.0);
        let mut m = MeshB::default();
        m.quad(
            [
                V3::new(-5.0, -5.0, 0.0),
                V3::new(5.0, -5.0, 0.0),
                V3::new(5.0, 5.0, 0.0),
                V3::new(-5.0, 5.0, 0.0),
            ],
            V3::z(),
        );
        // body x axis along −z: the tip (1, 0, 0) is the lowest point
        let rot = Matrix3::new(0.0, 0.0, 1.0, 0.0, 1.0, 0.0, -1.0, 0.0, 0.0);
        let c = patch_contact(&s, V3::new(0.2, 0.1, 0.99), &rot, &m.v, &m.t, None).unwrap();
        assert!((c.overlap - 0.01).abs() < 1e-12);
        let (lo, hi, ..) = sym2_eigen(c.radii[0], c.radii[1], c.radii[2]);
        assert!(
            (lo - 2.25).abs() < 1e-9 && (hi - 4.0).abs() < 1e-9,
            "{lo} {hi}"
        );
    }

    /// Cost per call (run with --release --ignored --nocapture for meaningful figures).
    #[test]
    #[ignore]
    fn timing() {
        let mut rng = SplitMix64::new(6);
        let s = sq([0.5, 0.25, 0.2], 0.4, 0.6);
        let rot = *random_orientation(&mut rng).to_rotation_matrix().matrix();
        let height = |c: V3| -low(&s, &rot, &c).dot(&c) - 0.01;
        let place = |q: V3, c: V3| q - c * 0.01 - low(&s, &rot, &c);
        let corner = cube_corner(2.0);
        let mut grid = MeshB::default();
        for i in 0..3 {
            for j in 0..3 {
                let (x0, y0) = (-1.5 + i as f64, -1.5 + j as f64);
                grid.quad(
                    [
                        V3::new(x0, y0, 0.0),
                        V3::new(x0 + 1.0, y0, 0.0),
                        V3::new(x0 + 1.0, y0 + 1.0, 0.0),
                        V3::new(x0, y0 + 1.0, 0.0),
                    ],
                    V3::z(),
                );
            }
        }
        let d2 = V3::new(1.0, 0.0, 1.0).normalize();
        let d3 = V3::new(1.0, 1.0, 1.0).normalize();
        let cases: Vec<(&str, &MeshB, V3)> = vec![
            (
                "face, flat 18 triangles",
                &grid,
                V3::new(0.1, 0.2, height(V3::z())),
            ),
            (
                "separated, flat 18 triangles",
                &grid,
                V3::new(0.1, 0.2, height(V3::z()) + 0.05),
            ),
            (
                "face, corner 6 triangles",
                &corner,
                V3::new(-1.0, -1.0, height(V3::z())),
            ),
            ("edge, corner", &corner, place(V3::new(0.0, -1.0, 0.0), d2)),
            ("vertex, corner", &corner, place(V3::zeros(), d3)),
        ];
        let only = std::env::var("PATCH_TIMING_CASE").ok();
        let t0 = std::time::Instant::now();
        let mut acc = V3::zeros();
        for k in 0..100_000 {
            let n = V3::new(0.3, -0.5 + 1e-6 * k as f64, 0.8);
            acc += s.point_from_normal(std::hint::black_box(&n)).x;
        }
        println!(
            "point_from_normal: {:.3} µs/call ({})",
            t0.elapsed().as_secs_f64() * 1e6 / 100_000.0,
            acc.x
        );
        for (label, m, x) in cases {
            if only
                .as_ref()
                .is_some_and(|o| !label.starts_with(o.as_str()))
            {
                continue;
            }
            let first = m.contact(&s, x, &rot, None);
            let warm = first.map(|c| c.normal);
            let n = 20_000;
            let mut st = PatchStats::default();
            let t0 = std::time::Instant::now();
            for _ in 0..n {
                std::hint::black_box(patch_contact_with_stats(
                    &s,
                    std::hint::black_box(x),
                    &rot,
                    &m.v,
                    &m.t,
                    warm,
                    &mut st,
                ));
            }
            let us = t0.elapsed().as_secs_f64() * 1e6 / n as f64;
            println!(
                "{label}: {:?}, {us:.2} µs/call, {:.1} evaluations, {:.1} iterations per call",
                first.map(|c| c.feature),
                st.evaluations as f64 / n as f64,
                st.iterations as f64 / n as f64
            );
        }
    }
}
