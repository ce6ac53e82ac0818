//! Stage "resolve forces", shaped bucket: the contacts of non-spherical bodies (with each
//! other, with spheres, with planes). Each listed contact is evaluated on its own — narrow
//! phase ([`crate::narrow::superquadric`], warm-started from the last normal: Wellmann's
//! temporal coherence) then the elliptic Hertz–Mindlin–Coulomb law
//! ([`crate::elliptic_hertz`], W 3.13–3.31) — and stored in its [`ShapedContact`] record;
//! then every body gathers the forces and torques of its records in list order. No sum
//! depends on the scheduling, so results are bitwise the same for any thread count.

use crate::broad_phase::{NeighbourLists, ShapedContact, WallCandidate};
use crate::elliptic_hertz::{
    hertz_ellipse, lift, relative_curvature, tangential_force, MindlinConstants,
    TangentialStiffness,
};
use crate::hertz_mindlin;
use crate::hertz_mindlin::V3;
use crate::materials::{PairParams, ShapedDamping};
use crate::narrow::polyhedron::{
    detect_pair_warm, detect_plane, detect_triangle, track_pair, Core, PolyBody, PolyDetection,
    POINT_CORE,
};
use crate::narrow::superquadric::{search, track, Detection, SearchSettings, SearchStats, SqBody};
use crate::narrow::superquadric_patch::patch_contact;
use crate::particles::{Particles, Shape};
use crate::resolve_forces::ForceContext;
use crate::resolve_forces::MeshForceRecord;
use crate::shape::polyhedron::Adjacency;
use crate::shape::superquadric::{sym2_eigen, tangent_basis};
use crate::shape::Superquadric;
use nalgebra::Matrix3;
use rayon::prelude::*;

/// Contacts per parallel work item (fixed: the result does not depend on it).
const CHUNK: usize = 256;

/// Bounds of the principal radii of curvature used by the law, relative to the body
/// (*not in thesis*): a flat point of an ε < 1 face has an infinite radius and a tip of an
/// ε > 1 body a zero one, where Hertz (3.19) degenerates (SEED-SPEC §1.1). Radii are kept
/// within [1e-2 × the smallest semi-axis, 10 × the bounding radius].
const RADIUS_FLOOR: f64 = 1e-2;
const RADIUS_CEILING: f64 = 10.0;

/// A body as the narrow phase and the law see it.
struct BodyView<'a> {
    /// Its template's superquadric, or a sphere's (made in the caller's slot).
    shape: &'a Superquadric,
    position: V3,
    rotation: Matrix3<f64>,
    velocity: V3,
    omega: V3,
    mass: f64,
    /// Radius bounds of the law.
    radius_range: (f64, f64),
}

/// Body `k` as the narrow phase sees it; a sphere's superquadric is made in `slot`.
fn body<'a>(p: &'a Particles, k: usize, slot: &'a mut Option<Superquadric>) -> BodyView<'a> {
    body_turned(
        p,
        k,
        slot,
        p.orientation[k].to_rotation_matrix().into_inner(),
    )
}

/// [`body`] with its rotation matrix formed already (once per body and step for the pairs).
fn body_turned<'a>(
    p: &'a Particles,
    k: usize,
    slot: &'a mut Option<Superquadric>,
    rotation: Matrix3<f64>,
) -> BodyView<'a> {
    let shape = match p.template(k).and_then(|t| t.superquadric()) {
        Some(s) => s,
        // a sphere is the superquadric with equal semi-axes and ε = 1 (exact in the search);
        // polyhedra never come here (`pair_contact` sends them to `poly_pair_contact`)
        None => slot.insert(
            Superquadric::new(V3::repeat(p.radius[k]), 1.0, 1.0)
                .expect("a particle radius is positive"),
        ),
    };
    let smallest = shape.radii.min();
    BodyView {
        radius_range: (
            RADIUS_FLOOR * smallest,
            RADIUS_CEILING * shape.bounding_radius(),
        ),
        shape,
        position: p.position[k],
        rotation,
        velocity: p.velocity[k],
        omega: p.angular_velocity[k],
        mass: p.mass[k],
    }
}

/// Curvature tensor (2×2, tangent basis) from a radius tensor [a, b, c] with the principal
/// radii clamped to `range`.
fn curvature(radii: [f64; 3], range: (f64, f64)) -> [[f64; 2]; 2] {
    let (r_lo, r_hi, v_lo, v_hi) = sym2_eigen(radii[0], radii[1], radii[2]);
    let (k_lo, k_hi) = (
        1.0 / r_lo.clamp(range.0, range.1),
        1.0 / r_hi.clamp(range.0, range.1),
    );
    let m = |a: usize, b: usize| k_lo * v_lo[a] * v_lo[b] + k_hi * v_hi[a] * v_hi[b];
    [[m(0, 0), m(0, 1)], [m(1, 0), m(1, 1)]]
}

/// The contact geometry the law needs.
struct Geometry {
    /// Unit normal from body 1 towards body 2 (or the wall).
    normal: V3,
    overlap: f64,
    point: V3,
    t1: V3,
    t2: V3,
    k1: [[f64; 2]; 2],
    k2: [[f64; 2]; 2],
}

/// What the law gives for a touching contact.
struct Response {
    /// Tangential force and total force on body 1.
    tangential: V3,
    force: V3,
    /// γ of (3.19) used.
    stiffness: f64,
}

impl Response {
    /// Writes the touching contact of geometry `g` into `c` (the fields a touching record
    /// has; the others, such as a pair's linearised surfaces, are left as they are).
    fn write(self, g: &Geometry, c: &mut ShapedContact) {
        c.normal = g.normal;
        c.tangential = self.tangential;
        c.overlap = g.overlap;
        c.point = g.point;
        c.force = self.force;
        c.stiffness = self.stiffness;
        c.support = f64::NAN;
    }

    /// The record of a touching contact of geometry `g`.
    fn record(self, g: &Geometry) -> ShapedContact {
        let mut c = ShapedContact::NONE;
        self.write(g, &mut c);
        c
    }
}

/// Elliptic Hertz + Mindlin + Coulomb (W 3.13–3.31) on body 1; `d_dot` is the velocity of
/// body 2's contact point relative to body 1's, `m_eff` the effective mass. `None` where the
/// surfaces have no curvature at all (unreachable with the radius bounds).
fn law(
    g: &Geometry,
    params: &PairParams,
    d_dot: &V3,
    m_eff: f64,
    old: &ShapedContact,
    dt: f64,
    hold: bool,
) -> Option<Response> {
    let rel = relative_curvature(g.k1, g.k2);
    let mut ell = hertz_ellipse(rel.a, rel.b)?;
    if hold && old.touching() {
        // γ from the first touch (StiffnessUpdate::FirstTouch): f = −∂W/∂x exactly
        ell.gamma = old.stiffness;
    }
    let delta = g.overlap;
    let e_star = params.e_star;
    let f_el = ell.elastic_normal_force(e_star, delta); // (3.19)
    let c_n = ell.normal_stiffness(e_star, delta); // (3.28)
                                                   // approach rate δ̇ = −ḋ·c
    let delta_dot = -d_dot.dot(&g.normal);
    let f_dis = match params.shaped_damping {
        // calibrated like the sphere law (Tsuji, coefficient from the restitution):
        // F_d = −2√(5/6) β √(c_N m*) δ̇, c_N = ∂f_el/∂δ; for a sphere pair it is that law's
        ShapedDamping::Restitution => params.damping_factor * (c_n * m_eff).sqrt() * delta_dot,
        // (3.29): ζ × the critical damping 2√(c_N m*)
        ShapedDamping::QuasiStatic(zeta) => zeta * 2.0 * (c_n * m_eff).sqrt() * delta_dot,
        // (3.30): (3/2)γE*√δ A δ̇ = c_N A δ̇
        ShapedDamping::Viscoelastic(a) => c_n * a * delta_dot,
    };
    let f_n = (f_el + f_dis).max(0.0); // (3.31)
    let mindlin = MindlinConstants {
        lambda1: params.mindlin_lambda1,
        lambda2: params.mindlin_lambda2,
    };
    let kt = TangentialStiffness::new(
        &ell,
        &mindlin,
        delta,
        lift(&g.t1, &g.t2, rel.e_x),
        lift(&g.t1, &g.t2, rel.e_y),
    );
    // a pure evaluation (dt = 0) keeps the history: turned into the tangent plane, capped
    let ft = tangential_force(
        &old.tangential,
        &g.normal,
        &kt,
        d_dot,
        dt,
        params.friction,
        f_n,
    )
    .force;
    Some(Response {
        tangential: ft,
        force: -g.normal * f_n + ft, // (3.13)
        stiffness: ell.gamma,
    })
}

/// True if the separating plane of the pair's last evaluation still separates it (*not in
/// thesis*; the temporal coherence of a separated pair). With the normal c and the support
/// sum H = h1(c) + h2(−c) of that evaluation, the gap now is c·(x2 − x1) − H′, and H′ differs
/// from H by at most the distance the bodies' surface points have turned: for a rotation of
/// angle θ a point at distance ≤ R (the bounding radius) moves by at most 2 sin(θ/2) R, and
/// 2 sin(θ/2) = 2 |vec(q q_thenᵀ)|. The translation enters exactly. A positive bound is a
/// proof of separation, so the pair needs no search this step.
#[inline]
fn still_separated(p: &Particles, i: usize, j: usize, x21: &V3, old: &ShapedContact) -> bool {
    if old.touching() || !old.support.is_finite() {
        return false;
    }
    let chord = |k: usize, then: &crate::particles::Orientation| {
        2.0 * (p.orientation[k] * then.inverse())
            .quaternion()
            .imag()
            .norm()
            * p.radius[k]
    };
    let bound =
        old.normal.dot(x21) - old.support - chord(i, &old.frames[0]) - chord(j, &old.frames[1]);
    // a margin for the round-off of H and the dot product
    bound > 1e-12 * (p.radius[i] + p.radius[j])
}

/// Evaluates one shaped pair into its record `c` (which holds the last step's); the second
/// body is seen at its image across a periodic cell's faces shifted by `image` = (d, ḋ)
/// (zero inside the cell). In place: a record is several hundred bytes, most of which a
/// touching pair's step leaves as they are.
fn pair_contact(
    p: &Particles,
    ctx: &ForceContext,
    rotations: &[Matrix3<f64>],
    [i, j]: [u32; 2],
    image: (V3, V3),
    c: &mut ShapedContact,
) {
    let (i, j) = (i as usize, j as usize);
    let x21 = p.position[j] + image.0 - p.position[i];
    // bounding spheres apart: no contact, and nothing to evaluate (the last normal stays
    // the warm start)
    let reach = p.radius[i] + p.radius[j];
    if x21.norm_squared() >= reach * reach {
        *c = ShapedContact {
            normal: c.normal,
            ..ShapedContact::NONE
        };
        return;
    }
    if still_separated(p, i, j, &x21, c) {
        return;
    }
    if p.polyhedron(i).is_some() || p.polyhedron(j).is_some() {
        poly_pair_contact(
            p,
            ctx,
            [&rotations[i], &rotations[j]],
            [i, j],
            image,
            &x21,
            c,
        );
        return;
    }
    let (mut slot_a, mut slot_b) = (None, None);
    let (a, mut b) = (
        body_turned(p, i, &mut slot_a, rotations[i]),
        body_turned(p, j, &mut slot_b, rotations[j]),
    );
    b.position += image.0;
    b.velocity += image.1;
    let (ba, bb) = (
        SqBody {
            shape: a.shape,
            position: a.position,
            rotation: a.rotation,
        },
        SqBody {
            shape: b.shape,
            position: b.position,
            rotation: b.rotation,
        },
    );
    let mut stats = SearchStats::default();
    let settings = SearchSettings {
        surface_budget: ctx.surface_budget,
        ..SearchSettings::default()
    };
    // the search updates the record's linearised surfaces in place
    let (normal, overlap) = (c.normal, c.overlap);
    let found = if c.touching() {
        track(
            &ba,
            &bb,
            normal,
            overlap,
            &mut c.linear,
            &settings,
            &mut stats,
        )
    } else {
        let guess = (normal != V3::zeros()).then_some(normal);
        search(&ba, &bb, guess, &settings, &mut stats, &mut c.linear)
    };
    let sq = match found {
        Detection::Separated { normal, gap } => {
            *c = ShapedContact {
                normal,
                support: normal.dot(&x21) - gap,
                frames: [p.orientation[i], p.orientation[j]],
                ..ShapedContact::NONE
            };
            return;
        }
        Detection::Contact(sq) => sq,
    };
    let point = (sq.p1 + sq.p2) * 0.5;
    let g = Geometry {
        normal: sq.normal,
        overlap: sq.overlap,
        point,
        t1: sq.t1,
        t2: sq.t2,
        k1: curvature(sq.radii1, a.radius_range),
        k2: curvature(sq.radii2, b.radius_range),
    };
    let d_dot = (b.velocity + b.omega.cross(&(point - b.position)))
        - (a.velocity + a.omega.cross(&(point - a.position)));
    let params = ctx.materials.pair(p.material[i], p.material[j]);
    let m_eff = a.mass * b.mass / (a.mass + b.mass);
    match law(&g, params, &d_dot, m_eff, c, ctx.dt, ctx.hold_stiffness) {
        Some(r) => r.write(&g, c),
        None => *c = ShapedContact::NONE,
    }
}

/// Evaluates a shaped body's contact with plane `w`: the deepest point of the body is its
/// surface point of outward normal −n (A.2), the plane has no curvature.
fn plane_contact(
    p: &Particles,
    ctx: &ForceContext,
    [k, w]: [u32; 2],
    old: &ShapedContact,
) -> ShapedContact {
    let (k, w) = (k as usize, w as usize);
    let pl = &ctx.planes[w];
    if p.polyhedron(k).is_some() {
        return poly_plane_contact(p, ctx, k, pl, old);
    }
    let mut slot = None;
    let a = body(p, k, &mut slot);
    let c = -pl.normal;
    let n_body = a.rotation.tr_mul(&c);
    let sp = a.shape.point_from_normal(&n_body);
    let p1 = a.position + a.rotation * sp.x;
    let delta = (pl.point - p1).dot(&pl.normal);
    if !pl.active || delta < 0.0 {
        return ShapedContact {
            normal: c,
            ..ShapedContact::NONE
        };
    }
    let (t1, t2) = tangent_basis(&c);
    let (u, v) = (a.rotation.tr_mul(&t1), a.rotation.tr_mul(&t2));
    let (ju, jv) = (sp.jacobian * u, sp.jacobian * v);
    let radii = [u.dot(&ju), 0.5 * (u.dot(&jv) + v.dot(&ju)), v.dot(&jv)];
    let point = p1 + pl.normal * (0.5 * delta);
    let g = Geometry {
        normal: c,
        overlap: delta,
        point,
        t1,
        t2,
        k1: curvature(radii, a.radius_range),
        k2: [[0.0; 2]; 2],
    };
    let d_dot = pl.velocity - (a.velocity + a.omega.cross(&(point - a.position)));
    let params = ctx.materials.pair(p.material[k], pl.material);
    law(&g, params, &d_dot, a.mass, old, ctx.dt, ctx.hold_stiffness)
        .map_or(ShapedContact::NONE, |r| r.record(&g))
}

/// Evaluates a shaped body's contact with one (mesh, patch) group of triangle candidates:
/// the minimum translation of the body out of the patch's convex hull
/// ([`crate::narrow::superquadric_patch`]) — face, edge or vertex without a force jump, and
/// conservative — with the elliptic law against a flat surface. Returns the contact and, on
/// a coupled mesh, where its force acts (triangle, barycentric weights).
fn mesh_contact(
    p: &Particles,
    ctx: &ForceContext,
    group: &[(u32, WallCandidate)],
    old: &ShapedContact,
) -> (ShapedContact, MeshForceRecord) {
    let none = (
        ShapedContact {
            normal: old.normal,
            ..ShapedContact::NONE
        },
        MeshForceRecord::default(),
    );
    let (k, first) = group[0];
    let k = k as usize;
    let mesh = &ctx.meshes[(first.wall as usize) - ctx.planes.len()];
    if !mesh.active {
        return none;
    }
    // the group's triangles with local vertex numbers (a handful: linear search)
    let mut nodes: Vec<u32> = Vec::with_capacity(3 * group.len());
    let mut tris: Vec<[usize; 3]> = Vec::with_capacity(group.len());
    for (_, c) in group {
        let t = mesh.triangles[c.triangle as usize];
        tris.push(t.map(|n| match nodes.iter().position(|&m| m == n) {
            Some(i) => i,
            None => {
                nodes.push(n);
                nodes.len() - 1
            }
        }));
    }
    if p.polyhedron(k).is_some() {
        return poly_mesh_contact(p, ctx, group, old);
    }
    let vertices: Vec<V3> = nodes.iter().map(|&n| mesh.positions[n as usize]).collect();
    let mut slot = None;
    let a = body(p, k, &mut slot);
    // Walls are two-sided (as for spheres): the patch's front is the side of the body's
    // centre, judged at the nearest triangle; seen from behind, its triangles turn over.
    let nearest = tris
        .iter()
        .map(|t| {
            let [u, v, w] = t.map(|i| vertices[i]);
            let (q, _) =
                crate::triangle_contact::closest_point_on_triangle(&a.position, &u, &v, &w);
            (
                (a.position - q).norm_squared(),
                (a.position - u).dot(&(v - u).cross(&(w - u))),
            )
        })
        .fold(
            (f64::INFINITY, 0.0),
            |best, c| if c.0 < best.0 { c } else { best },
        );
    let flipped = nearest.1 < 0.0;
    if flipped {
        for t in tris.iter_mut() {
            t.swap(1, 2);
        }
    }
    // the stored normal points from the body to the wall, the search's from the wall
    let warm = (old.normal != V3::zeros()).then_some(-old.normal);
    let Some(pc) = patch_contact(a.shape, a.position, &a.rotation, &vertices, &tris, warm) else {
        return none;
    };
    let c = -pc.normal;
    let point = pc.point + pc.normal * (0.5 * pc.overlap);
    let (t1, t2) = tangent_basis(&c);
    let g = Geometry {
        normal: c,
        overlap: pc.overlap,
        point,
        t1,
        t2,
        k1: curvature(pc.radii, a.radius_range),
        k2: [[0.0; 2]; 2],
    };
    let tri = group[pc.triangle].1.triangle;
    // weights in the mesh's own corner order
    let mut bary = pc.bary;
    if flipped {
        bary.swap(1, 2);
    }
    let corner = mesh.triangles[tri as usize];
    let wall_velocity = corner.iter().zip(&bary).fold(V3::zeros(), |v, (&n, &w)| {
        v + mesh.velocities[n as usize] * w
    });
    let d_dot = wall_velocity - (a.velocity + a.omega.cross(&(point - a.position)));
    let params = ctx.materials.pair(p.material[k], mesh.material);
    let contact = law(&g, params, &d_dot, a.mass, old, ctx.dt, ctx.hold_stiffness)
        .map_or(ShapedContact::NONE, |r| r.record(&g));
    let record = MeshForceRecord {
        triangle: tri,
        bary,
        force: -contact.force,
    };
    (contact, record)
}

/// A body as the polyhedral narrow phase sees it: a stone, a sphere (a dilated point) or a
/// superquadric (its support map, no dilation).
fn poly_view(p: &Particles, k: usize) -> PolyBody<'_> {
    poly_view_and_graph(p, k).0
}

/// [`poly_view`] and, for a stone, its core's vertex graph (the tracker's support climb).
fn poly_view_and_graph(p: &Particles, k: usize) -> (PolyBody<'_>, Option<&Adjacency>) {
    let (core, dilation, graph) = match p.template(k).map(|t| &t.shape) {
        None => (
            Core::Points {
                vertices: &POINT_CORE,
                scale: 1.0,
            },
            p.radius[k],
            None,
        ),
        Some(Shape::Polyhedron { stone, scale }) => {
            let s = &p.stones[*stone as usize];
            (
                Core::Points {
                    vertices: &s.vertices,
                    scale: *scale,
                },
                s.dilation * scale,
                Some(&s.adjacency),
            )
        }
        Some(Shape::Superquadric(s)) => (Core::Superquadric(s), 0.0, None),
    };
    let body = PolyBody {
        core,
        dilation,
        position: p.position[k],
        orientation: p.orientation[k],
    };
    (body, graph)
}

/// The record of a pair whose cores interpenetrate: a non-finite force, which stops the run
/// with [`crate::DemError::CoresIntersect`] naming the pair (the model's validity limit).
fn cores_intersect(normal: V3, overlap: f64) -> ShapedContact {
    ShapedContact {
        normal,
        overlap,
        force: V3::repeat(f64::NAN),
        ..ShapedContact::NONE
    }
}

/// Ullrich's dilated-polyhedron law (2.20)–(2.24), corrected (SEED-SPEC §6.2): Hertz between
/// the dilation spheres, F_n = 4/3 E* √R δ^{3/2} with R = r_ds,1 r_ds,2/(r_ds,1 + r_ds,2)
/// (r_ds against a wall; (2.20) is the equal-sphere case), Mindlin's k_t = 8G*√(Rδ) ((2.22)
/// with its missing factor 3), the relative velocity of (2.23) with ω × r, Coulomb's cap
/// (2.24), and the restitution damping of the sphere law (the thesis writes none; Table 6.1
/// sets e = 0.2). It is [`hertz_mindlin::contact_force`] itself. `normal` points from body 1
/// to body 2, `d_dot` is the velocity of 2's contact point relative to 1's; `tangential`
/// of the record holds the tangential displacement history.
#[allow(clippy::too_many_arguments)] // the physical inputs of one contact
fn dilated_law(
    params: &PairParams,
    overlap: f64,
    r_eff: f64,
    m_eff: f64,
    normal: V3,
    d_dot: &V3,
    point: V3,
    old: &ShapedContact,
    dt: f64,
) -> ShapedContact {
    let mut shear = if old.touching() {
        old.tangential
    } else {
        V3::zeros()
    };
    let cf = hertz_mindlin::contact_force(
        params, overlap, r_eff, m_eff, &-normal, &-d_dot, &mut shear, dt,
    );
    ShapedContact {
        normal,
        tangential: shear,
        overlap,
        point,
        force: cf.force,
        ..ShapedContact::NONE
    }
}

/// Velocity of body k's material point at `point`.
#[inline]
fn point_velocity(p: &Particles, k: usize, point: &V3) -> V3 {
    p.velocity[k] + p.angular_velocity[k].cross(&(point - p.position[k]))
}

/// A pair with a dilated polyhedron (the other a polyhedron, a sphere or a superquadric),
/// evaluated into its record `c` (the last step's): the closest-feature tracker where the
/// last simplex still holds, else GJK warm-started from it. `rotations` are the bodies'.
#[allow(clippy::too_many_arguments)] // the pair, its image and its record
fn poly_pair_contact(
    p: &Particles,
    ctx: &ForceContext,
    rotations: [&Matrix3<f64>; 2],
    [i, j]: [usize; 2],
    image: (V3, V3),
    x21: &V3,
    c: &mut ShapedContact,
) {
    let ((a, graph_a), (mut b, graph_b)) = (poly_view_and_graph(p, i), poly_view_and_graph(p, j));
    b.position += image.0;
    let graphs = [graph_a, graph_b];
    let (found, simplex) = track_pair(&a, &b, rotations[0], rotations[1], &c.simplex, graphs)
        .unwrap_or_else(|| {
            let warm = (c.normal != V3::zeros()).then_some(c.normal);
            detect_pair_warm(&a, &b, warm, &c.simplex)
        });
    let old = &*c;
    let new = match found {
        PolyDetection::Separated { normal, gap } => ShapedContact {
            normal,
            support: normal.dot(x21) - gap, // NaN when no plane was proved
            frames: [p.orientation[i], p.orientation[j]],
            ..ShapedContact::NONE
        },
        PolyDetection::CoresIntersect { depth } => {
            cores_intersect(old.normal, depth + a.dilation + b.dilation)
        }
        PolyDetection::Contact {
            normal,
            overlap,
            point,
            ..
        } => {
            let (ra, rb) = (a.dilation, b.dilation);
            // a superquadric has no dilation: the polyhedron's sphere against a surface
            let r_eff = if ra > 0.0 && rb > 0.0 {
                ra * rb / (ra + rb)
            } else {
                ra.max(rb)
            };
            let m_eff = p.mass[i] * p.mass[j] / (p.mass[i] + p.mass[j]);
            let d_dot =
                point_velocity(p, j, &(point - image.0)) + image.1 - point_velocity(p, i, &point);
            let params = ctx.materials.pair(p.material[i], p.material[j]);
            dilated_law(
                params, overlap, r_eff, m_eff, normal, &d_dot, point, old, ctx.dt,
            )
        }
    };
    // the fields a polyhedral record uses (its superquadric linearisation stays `NONE`:
    // the record is a few hundred bytes, most of them that)
    c.normal = new.normal;
    c.tangential = new.tangential;
    c.overlap = new.overlap;
    c.point = new.point;
    c.force = new.force;
    c.stiffness = new.stiffness;
    c.support = new.support;
    c.frames = new.frames;
    c.simplex = simplex;
}

/// A dilated polyhedron against a plane (a flat wall: R = r_ds).
fn poly_plane_contact(
    p: &Particles,
    ctx: &ForceContext,
    k: usize,
    pl: &crate::walls::Plane,
    old: &ShapedContact,
) -> ShapedContact {
    let none = ShapedContact {
        normal: -pl.normal,
        ..ShapedContact::NONE
    };
    if !pl.active {
        return none;
    }
    let a = poly_view(p, k);
    match detect_plane(&a, &pl.point, &pl.normal) {
        PolyDetection::Separated { .. } => none,
        PolyDetection::CoresIntersect { depth } => cores_intersect(-pl.normal, depth + a.dilation),
        PolyDetection::Contact {
            normal,
            overlap,
            point,
            ..
        } => {
            let d_dot = pl.velocity - point_velocity(p, k, &point);
            let params = ctx.materials.pair(p.material[k], pl.material);
            dilated_law(
                params, overlap, a.dilation, p.mass[k], normal, &d_dot, point, old, ctx.dt,
            )
        }
    }
}

/// A dilated polyhedron against one (mesh, patch) group of triangles: the closest triangle
/// of the patch (the distance of the core to the patch, continuous across its edges, as for
/// spheres in [`crate::triangle_contact`]), a flat wall (R = r_ds); the force acts on the
/// mesh at the triangle's closest point.
fn poly_mesh_contact(
    p: &Particles,
    ctx: &ForceContext,
    group: &[(u32, WallCandidate)],
    old: &ShapedContact,
) -> (ShapedContact, MeshForceRecord) {
    let (k, first) = group[0];
    let k = k as usize;
    let mesh = &ctx.meshes[(first.wall as usize) - ctx.planes.len()];
    let none = (
        ShapedContact {
            normal: old.normal,
            ..ShapedContact::NONE
        },
        MeshForceRecord::default(),
    );
    if !mesh.active {
        return none;
    }
    let a = poly_view(p, k);
    let warm = (old.normal != V3::zeros()).then_some(old.normal);
    // the deepest contact of the patch (one per patch), or the first core intersection
    let mut best: Option<(f64, V3, V3, V3, u32)> = None;
    for (_, c) in group {
        let corner = mesh.triangles[c.triangle as usize].map(|n| mesh.positions[n as usize]);
        match detect_triangle(&a, &corner, warm) {
            PolyDetection::Separated { .. } => {}
            PolyDetection::CoresIntersect { depth } => {
                return (
                    cores_intersect(old.normal, depth + a.dilation),
                    MeshForceRecord::default(),
                )
            }
            PolyDetection::Contact {
                normal,
                overlap,
                point,
                core_point,
            } => {
                if best.is_none_or(|b| overlap > b.0) {
                    best = Some((overlap, normal, point, core_point, c.triangle));
                }
            }
        }
    }
    let Some((overlap, normal, point, on_wall, tri)) = best else {
        return none;
    };
    let corner = mesh.triangles[tri as usize];
    let [u, v, w] = corner.map(|n| mesh.positions[n as usize]);
    let (_, bary) = crate::triangle_contact::closest_point_on_triangle(&on_wall, &u, &v, &w);
    let wall_velocity = corner.iter().zip(&bary).fold(V3::zeros(), |s, (&n, &b)| {
        s + mesh.velocities[n as usize] * b
    });
    let d_dot = wall_velocity - point_velocity(p, k, &point);
    let params = ctx.materials.pair(p.material[k], mesh.material);
    let contact = dilated_law(
        params, overlap, a.dilation, p.mass[k], normal, &d_dot, point, old, ctx.dt,
    );
    let record = MeshForceRecord {
        triangle: tri,
        bary,
        force: -contact.force,
    };
    (contact, record)
}

/// Evaluates every shaped contact and adds the forces and torques to the bodies (after the
/// sphere stage has set gravity and the sphere contacts).
/// The shift d = s∘L and its rate of shaped pair k's second body (zero inside the cell).
#[inline]
fn image_of(ctx: &ForceContext, images: &[[i8; 3]], k: usize) -> (V3, V3) {
    match (ctx.cell, images.get(k)) {
        (Some((size, rate)), Some(&s)) if s != [0; 3] => (
            crate::broad_phase::image_shift(&size, s),
            crate::broad_phase::image_shift(&rate, s),
        ),
        _ => (V3::zeros(), V3::zeros()),
    }
}

pub fn shaped_forces(lists: &mut NeighbourLists, p: &mut Particles, ctx: &ForceContext) {
    if lists.shaped_pairs.is_empty()
        && lists.shaped_walls.is_empty()
        && lists.shaped_mesh.is_empty()
    {
        return;
    }
    {
        let pv: &Particles = p;
        let images = &lists.shaped_pair_image;
        // the rotation matrices of the bodies in shaped pairs, once per step (a body is in
        // several pairs; a bed of spheres with a few shaped bodies forms only theirs)
        let starts = &lists.shaped_incidence.pair_start;
        let rotations = &mut lists.shaped_rotations;
        if !starts.is_empty() {
            rotations.resize(pv.len(), Matrix3::identity());
            rotations
                .par_iter_mut()
                .with_min_len(1024)
                .enumerate()
                .filter(|(k, _)| starts[k + 1] > starts[*k])
                .for_each(|(k, r)| *r = pv.orientation[k].to_rotation_matrix().into_inner());
        }
        let rotations = &lists.shaped_rotations;
        lists
            .shaped_pair_contacts
            .par_iter_mut()
            .with_min_len(CHUNK)
            .zip(lists.shaped_pairs.par_iter())
            .enumerate()
            .for_each(|(k, (c, &pair))| {
                let image = image_of(ctx, images, k);
                pair_contact(pv, ctx, rotations, pair, image, c)
            });
        lists
            .shaped_wall_contacts
            .par_iter_mut()
            .with_min_len(CHUNK)
            .zip(lists.shaped_walls.par_iter())
            .for_each(|(c, &cand)| *c = plane_contact(pv, ctx, cand, c));
        let groups = &lists.shaped_incidence.mesh_groups;
        let cands = &lists.shaped_mesh;
        let olds = &lists.shaped_mesh_contacts;
        let results: Vec<(ShapedContact, MeshForceRecord)> = (0..groups.len().saturating_sub(1))
            .into_par_iter()
            .with_min_len(CHUNK)
            .map(|g| {
                let (lo, hi) = (groups[g] as usize, groups[g + 1] as usize);
                mesh_contact(pv, ctx, &cands[lo..hi], &olds[lo])
            })
            .collect();
        lists
            .shaped_mesh_records
            .resize(lists.shaped_mesh.len(), MeshForceRecord::default());
        for (g, (c, r)) in results.into_iter().enumerate() {
            let at = groups[g] as usize;
            lists.shaped_mesh_contacts[at] = c;
            lists.shaped_mesh_records[at] = r;
        }
    }
    let inc = &lists.shaped_incidence;
    let images = &lists.shaped_pair_image;
    let pair_bodies = &lists.shaped_pairs;
    let pairs = &lists.shaped_pair_contacts;
    let walls = &lists.shaped_wall_contacts;
    let meshes = &lists.shaped_mesh_contacts;
    let pos = &p.position;
    p.force
        .par_iter_mut()
        .zip(p.torque.par_iter_mut())
        .enumerate()
        .with_min_len(1024)
        .for_each(|(k, (f, t))| {
            let x = pos[k];
            if !inc.pair_start.is_empty() {
                for &e in
                    &inc.pair_entries[inc.pair_start[k] as usize..inc.pair_start[k + 1] as usize]
                {
                    let c = &pairs[(e >> 1) as usize];
                    if c.touching() {
                        let (mut fk, at) = if e & 1 == 0 {
                            (c.force, x)
                        } else {
                            // the second body acts at its image
                            (-c.force, x + image_of(ctx, images, (e >> 1) as usize).0)
                        };
                        if let Some(ws) = ctx.weights {
                            // the weight at the contact point, the same for both bodies of the
                            // pair (`SlotWeights::pair`, our form of 6.29)
                            let [a, b] = pair_bodies[(e >> 1) as usize].map(|i| i as usize);
                            fk *= ws.pair(a, b, pos[a], pos[b], c.point);
                        }
                        *f += fk;
                        *t += (c.point - at).cross(&fk);
                    }
                }
            }
            if !inc.wall_start.is_empty() {
                for c in &walls[inc.wall_start[k] as usize..inc.wall_start[k + 1] as usize] {
                    if c.touching() {
                        let fc = ctx
                            .weights
                            .map_or(c.force, |ws| c.force * ws.at(k, x, c.point));
                        *f += fc;
                        *t += (c.point - x).cross(&fc);
                    }
                }
            }
            if !inc.mesh_group_start.is_empty() {
                let groups = inc.mesh_group_start[k] as usize..inc.mesh_group_start[k + 1] as usize;
                for g in groups {
                    let c = &meshes[inc.mesh_groups[g] as usize];
                    if c.touching() {
                        let fc = ctx
                            .weights
                            .map_or(c.force, |ws| c.force * ws.at(k, x, c.point));
                        *f += fc;
                        *t += (c.point - x).cross(&fc);
                    }
                }
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::generate::{random_orientation, random_unit_vector, SplitMix64};

    /// The dilated-polyhedron law with Ullrich's corrected constants (SEED-SPEC §6.2): for two
    /// bodies of dilation r of one material, F_n = 2√2 G/(3(1 − ν)) √r δ^{3/2} (2.20) and the
    /// tangential stiffness k_t = 2 (3 G² (1 − ν) |F_n| r)^{1/3}/(2 − ν) (2.22 with its factor
    /// 3); the tangential force drags body 1 along with body 2 (the sign of (2.23)).
    #[test]
    fn dilated_law_is_ullrichs_corrected_2_20_to_2_24() {
        let cfg = crate::config::parse_scene_section(
            "[dem]\ntime_step = 1e-6\n[dem.materials.rock]\nyoungs_modulus = 1e10\npoisson_ratio = 0.27\ndensity = 2600.0\nrestitution = 1.0\nfriction = 10.0\n",
        )
        .unwrap()
        .unwrap();
        let table = crate::materials::MaterialTable::from_config(&cfg);
        let params = table.pair(0, 0);
        let (e, nu) = (1e10, 0.27);
        let g = e / (2.0 * (1.0 + nu));
        let (r, delta, v, dt) = (4e-3, 2e-5, 0.01, 1e-6);
        let old = ShapedContact::NONE;
        let c = dilated_law(
            params,
            delta,
            r / 2.0,
            0.1,
            V3::x(),
            &(V3::y() * v),
            V3::zeros(),
            &old,
            dt,
        );
        let f_n = 2.0 * 2f64.sqrt() * g / (3.0 * (1.0 - nu)) * r.sqrt() * delta.powf(1.5);
        let k_t = 2.0 * (3.0 * g * g * (1.0 - nu) * f_n * r).cbrt() / (2.0 - nu);
        // normal: pushes body 1 away from body 2 (−x)
        assert!(
            (c.force.x + f_n).abs() < 1e-12 * f_n,
            "{} vs {f_n}",
            c.force.x
        );
        // tangential: one step of relative sliding v dt, along body 2's motion (+y)
        let f_t = k_t * v * dt;
        assert!(
            (c.force.y - f_t).abs() < 1e-12 * f_t,
            "{} vs {f_t}",
            c.force.y
        );
        assert!(c.force.z.abs() < 1e-20);
        // the printed (2.22) without the 3 is 3^{1/3} too small
        let printed = 2.0 * (g * g * (1.0 - nu) * f_n * r).cbrt() / (2.0 - nu);
        assert!((k_t / printed - 3f64.cbrt()).abs() < 1e-12);
    }

    /// The skip of a separated pair is a proof: whenever `still_separated` says so after the
    /// bodies moved and turned, the full search finds them separated too; and it does skip
    /// small motions (else it would be useless).
    #[test]
    fn a_skipped_pair_is_separated() {
        let mut rng = SplitMix64::new(11);
        let (mut skipped, mut trials) = (0, 0);
        for _ in 0..20_000 {
            let mut p = Particles::default();
            let mut shape = || {
                let r = V3::new(
                    0.5 + rng.uniform(),
                    0.5 + rng.uniform(),
                    0.5 + rng.uniform(),
                );
                Superquadric::new(r, 0.3 + 1.4 * rng.uniform(), 0.3 + 1.4 * rng.uniform()).unwrap()
            };
            let (s1, s2) = (shape(), shape());
            let reach = s1.bounding_radius() + s2.bounding_radius();
            let x2 = random_unit_vector(&mut rng) * reach * (0.6 + 0.4 * rng.uniform());
            for (x, s) in [(V3::zeros(), s1), (x2, s2)] {
                let q = random_orientation(&mut rng);
                p.push_superquadric(x, V3::zeros(), V3::zeros(), q, s, 1000.0, 0);
            }
            fn view(p: &Particles, k: usize) -> SqBody<'_> {
                SqBody {
                    shape: p.templates[k].superquadric().unwrap(),
                    position: p.position[k],
                    rotation: p.orientation[k].to_rotation_matrix().into_inner(),
                }
            }
            let detect_now = |p: &Particles| {
                let mut st = SearchStats::default();
                crate::narrow::superquadric::detect(
                    &view(p, 0),
                    &view(p, 1),
                    None,
                    &SearchSettings::default(),
                    &mut st,
                )
            };
            let Detection::Separated { normal, gap } = detect_now(&p) else {
                continue;
            };
            let x21 = p.position[1] - p.position[0];
            let old = ShapedContact {
                normal,
                support: normal.dot(&x21) - gap,
                frames: [p.orientation[0], p.orientation[1]],
                ..ShapedContact::NONE
            };
            // a random motion from far below to beyond what the bound allows: up to the gap,
            // rotations up to 0.3 rad
            let scale = 10f64.powf(-4.0 * rng.uniform());
            for k in 0..2 {
                p.position[k] += random_unit_vector(&mut rng) * (gap * scale);
                let axis = nalgebra::Unit::new_normalize(random_unit_vector(&mut rng));
                let turn = crate::particles::Orientation::from_axis_angle(
                    &axis,
                    0.3 * scale * rng.uniform(),
                );
                p.orientation[k] = turn * p.orientation[k];
            }
            trials += 1;
            let x21 = p.position[1] - p.position[0];
            if still_separated(&p, 0, 1, &x21, &old) {
                skipped += 1;
                match detect_now(&p) {
                    Detection::Separated { gap, .. } => assert!(gap > 0.0),
                    Detection::Contact(c) => panic!("skipped a pair in contact: {c:?}"),
                }
            }
        }
        println!("{skipped} of {trials} moved separated pairs skipped");
        assert!(
            trials > 5_000 && skipped > trials / 4 && skipped < trials * 95 / 100,
            "{skipped} of {trials}"
        );
    }
}
