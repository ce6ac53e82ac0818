//! Stage "resolve and accumulate (contact) forces" (Ullrich Algorithm 1, line 4).
//!
//! The particles are split into force blocks of [`BLOCK`] consecutive (spatially sorted)
//! particles, processed in parallel. Within a block one pass over its particles i sets the
//! force to gravity, evaluates i's pairs (i, j > i) and adds the force to i and the reaction
//! to j (Newton's third law, one evaluation per pair), then i's wall contacts. A reaction on a
//! particle of a later block (a "cross pair") is written to a buffer instead, and each block
//! gathers its incoming cross reactions afterwards in a fixed order. Block boundaries do not
//! depend on the thread count, and no sum depends on the scheduling (no atomics), so the
//! result is bitwise identical for any number of threads.

use crate::broad_phase::{NeighbourLists, WallContact, BLOCK};
use crate::hertz_mindlin::{contact_force, rolling_torque, V3};
use crate::materials::MaterialTable;
use crate::particles::Particles;
use crate::walls::{Mesh, Plane};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// A force on a wall, stored per wall candidate group (valid while the group's contact is
/// touching) when a coupled mesh or a loaded wall needs it: on a coupled mesh at the point of
/// triangle `triangle` with barycentric weights `bary` (zero on other walls).
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
pub struct MeshForceRecord {
    pub triangle: u32,
    pub bary: [f64; 3],
    /// Force exerted by the particle on the mesh.
    pub force: V3,
}

pub struct ForceContext<'a> {
    pub materials: &'a MaterialTable,
    pub planes: &'a [Plane],
    pub meshes: &'a [Mesh],
    pub gravity: V3,
    /// Hold the elliptic Hertz stiffness of a shaped contact from its first touch
    /// ([`crate::config::StiffnessUpdate::FirstTouch`]).
    pub hold_stiffness: bool,
    /// `dem.superquadric_surface_budget` ([`crate::narrow::superquadric::SearchSettings`]).
    pub surface_budget: f64,
    /// Tangential history increment time (Δt, or 0 for a pure evaluation).
    pub dt: f64,
    /// A periodic cell: its edges L and their rates L̇ (an image s of a body is shifted by
    /// s∘L and moves with s∘L̇ besides the body's own velocity).
    pub cell: Option<(V3, V3)>,
    /// Arlequin weights of the bodies (an overlap with a continuum, [`crate::volume_coupling`]):
    /// each contact force and torque is weighted at its contact point (6.29).
    pub weights: Option<&'a crate::volume_coupling::SlotWeights>,
}

/// The mutable data a run of consecutive blocks writes: its particles' forces, its pairs'
/// histories and cross reactions, its wall contacts and mesh records.
struct BlockSlices<'a> {
    /// First block, first particle, pair, cross pair and wall candidate of the slices.
    block: usize,
    particle: usize,
    pair: usize,
    cross: usize,
    wall: usize,
    force: &'a mut [V3],
    torque: &'a mut [V3],
    shear: &'a mut [V3],
    cross_force: &'a mut [[V3; 2]],
    wall_contacts: &'a mut [WallContact],
    records: &'a mut [MeshForceRecord],
}

/// Evaluates all contact forces and gravity into `p.force` and `p.torque`: pair forces
/// (Hertz–Mindlin, eqs. 2.6–2.19) and wall contacts, with history updates when `ctx.dt` > 0.
/// `records` (one per wall candidate, or empty without coupled meshes and loaded walls)
/// receive the forces on the walls.
pub fn contact_forces(
    lists: &mut NeighbourLists,
    p: &mut Particles,
    records: &mut [MeshForceRecord],
    ctx: &ForceContext,
) {
    let n = p.len();
    let blocks = n.div_ceil(BLOCK);
    let NeighbourLists {
        first_pair,
        partner,
        shear,
        wall_start,
        walls,
        wall_contacts,
        cross,
        ..
    } = lists;
    let slices = BlockSlices {
        block: 0,
        particle: 0,
        pair: 0,
        cross: 0,
        wall: 0,
        force: &mut p.force,
        torque: &mut p.torque,
        shear: &mut shear[..],
        cross_force: &mut cross.force,
        wall_contacts: &mut wall_contacts[..],
        records,
    };
    let view = ListsView {
        first_pair: &first_pair[..],
        partner: &partner[..],
        wall_start: &wall_start[..],
        walls: &walls[..],
        block_start: &cross.block_start,
    };
    // field by field: `force` and `torque` are borrowed mutably above
    let kin = Kinematics {
        pos: &p.position,
        vel: &p.velocity,
        omega: &p.angular_velocity,
        rad: &p.radius,
        mass: &p.mass,
        inertia: &p.inertia,
        mat: &p.material,
    };
    for_blocks_view(0..blocks, slices, &view, &|b, s| {
        block_forces(b, s, &view, &kin, ctx)
    });

    // incoming cross-pair reactions, per block in receiver order
    let c = &lists.cross;
    p.force
        .par_chunks_mut(BLOCK)
        .zip(p.torque.par_chunks_mut(BLOCK))
        .enumerate()
        .for_each(|(b, (f, t))| {
            let lo = b * BLOCK;
            for r in c.block_receivers[b] as usize..c.block_receivers[b + 1] as usize {
                let j = c.receivers[r] as usize - lo;
                let (mut fj, mut tj) = (f[j], t[j]);
                for &o in
                    &c.incoming[c.receiver_start[r] as usize..c.receiver_start[r + 1] as usize]
                {
                    let [df, dt] = c.force[o as usize];
                    fj += df;
                    tj += dt;
                }
                f[j] = fj;
                t[j] = tj;
            }
        });
}

/// Read-only parts of the lists during the force pass.
struct ListsView<'a> {
    first_pair: &'a [u32],
    partner: &'a [u32],
    wall_start: &'a [u32],
    walls: &'a [crate::broad_phase::WallCandidate],
    block_start: &'a [u32],
}

/// Read-only particle state of the force pass.
pub(crate) struct Kinematics<'a> {
    pos: &'a [V3],
    vel: &'a [V3],
    omega: &'a [V3],
    rad: &'a [f64],
    mass: &'a [f64],
    inertia: &'a [f64],
    mat: &'a [u16],
}

impl<'a> Kinematics<'a> {
    pub(crate) fn of(p: &'a Particles) -> Kinematics<'a> {
        Kinematics {
            pos: &p.position,
            vel: &p.velocity,
            omega: &p.angular_velocity,
            rad: &p.radius,
            mass: &p.mass,
            inertia: &p.inertia,
            mat: &p.material,
        }
    }
}

/// A touching particle pair (i, j): the force on i and what the torques need.
pub(crate) struct PairContact {
    pub cf: crate::hertz_mindlin::ContactForce,
    /// Unit normal towards i.
    pub nrm: V3,
    /// Lever arms r − δ/2 of i and j.
    pub ai: f64,
    pub aj: f64,
    pub r_eff: f64,
}

/// Hertz–Mindlin force on i of the touching pair (i, j) with `d` = x_i − x_j,
/// `dist2` = |d|² < `sum`² = (r_i + r_j)² (eqs. 2.6–2.19); `shear` is the pair's history.
/// `vj` is j's velocity (of its image across a periodic cell's face: with the image's).
#[inline(always)]
#[allow(clippy::too_many_arguments)] // the hot loop's unbundled inputs
pub(crate) fn pair_contact(
    k: &Kinematics,
    ctx: &ForceContext,
    (i, j): (usize, usize),
    d: V3,
    dist2: f64,
    vj: V3,
    shear: &mut V3,
) -> PairContact {
    let (ri, rj) = (k.rad[i], k.rad[j]);
    let sum = ri + rj;
    let dist = dist2.sqrt();
    let delta = sum - dist; // (2.9)
    let nrm = if dist > 0.0 {
        d * (1.0 / dist)
    } else {
        V3::z()
    };
    let params = ctx.materials.pair(k.mat[i], k.mat[j]);
    let r_eff = ri * rj / sum; // (2.8)
    let (mi, mj) = (k.mass[i], k.mass[j]);
    let m_eff = mi * mj / (mi + mj); // (2.11)
    let (ai, aj) = (ri - 0.5 * delta, rj - 0.5 * delta);
    let v_c = k.vel[i] - vj - (k.omega[i] * ai + k.omega[j] * aj).cross(&nrm);
    let cf = contact_force(params, delta, r_eff, m_eff, &nrm, &v_c, shear, ctx.dt);
    PairContact {
        cf,
        nrm,
        ai,
        aj,
        r_eff,
    }
}

/// The force on i of the touching sphere pair (i, j) (see [`pair_contact`]) with the
/// torques on i and j (tangential force and rolling resistance).
#[inline(always)]
#[allow(clippy::too_many_arguments)] // the hot loop's unbundled inputs
pub(crate) fn pair_force_torques(
    k: &Kinematics,
    ctx: &ForceContext,
    (i, j): (usize, usize),
    d: V3,
    dist2: f64,
    vj: V3,
    shear: &mut V3,
) -> (V3, V3, V3) {
    let PairContact {
        cf,
        nrm,
        ai,
        aj,
        r_eff,
    } = pair_contact(k, ctx, (i, j), d, dist2, vj, shear);
    let nxt = nrm.cross(&cf.tangential);
    let params = ctx.materials.pair(k.mat[i], k.mat[j]);
    let roll = if params.rolling_friction > 0.0 {
        let (ii, ij) = (k.inertia[i], k.inertia[j]);
        let i_eff = ii * ij / (ii + ij);
        rolling_torque(
            params.rolling_friction,
            r_eff,
            cf.normal,
            &(k.omega[i] - k.omega[j]),
            i_eff,
            ctx.dt,
        )
    } else {
        V3::zeros()
    };
    (cf.force, nxt * (-ai) + roll, nxt * (-aj) - roll)
}

impl<'a> BlockSlices<'a> {
    fn split_view(self, b: usize, v: &ListsView) -> (BlockSlices<'a>, BlockSlices<'a>) {
        let particle = b * BLOCK;
        let pair = v.first_pair[particle] as usize;
        let cross = v.block_start[b] as usize;
        let wall = v.wall_start[particle] as usize;
        let (f0, f1) = self.force.split_at_mut(particle - self.particle);
        let (t0, t1) = self.torque.split_at_mut(particle - self.particle);
        let (s0, s1) = self.shear.split_at_mut(pair - self.pair);
        let (c0, c1) = self.cross_force.split_at_mut(cross - self.cross);
        let (w0, w1) = self.wall_contacts.split_at_mut(wall - self.wall);
        let (r0, r1) = if self.records.is_empty() {
            (self.records, <&mut [MeshForceRecord]>::default())
        } else {
            self.records.split_at_mut(wall - self.wall)
        };
        (
            BlockSlices {
                block: self.block,
                particle: self.particle,
                pair: self.pair,
                cross: self.cross,
                wall: self.wall,
                force: f0,
                torque: t0,
                shear: s0,
                cross_force: c0,
                wall_contacts: w0,
                records: r0,
            },
            BlockSlices {
                block: b,
                particle,
                pair,
                cross,
                wall,
                force: f1,
                torque: t1,
                shear: s1,
                cross_force: c1,
                wall_contacts: w1,
                records: r1,
            },
        )
    }
}

fn for_blocks_view<F>(blocks: std::ops::Range<usize>, s: BlockSlices, v: &ListsView, f: &F)
where
    F: Fn(usize, BlockSlices) + Sync,
{
    if blocks.len() <= 1 {
        if !blocks.is_empty() {
            f(blocks.start, s);
        }
        return;
    }
    let mid = blocks.start + blocks.len() / 2;
    let (a, b) = s.split_view(mid, v);
    rayon::join(
        || for_blocks_view(blocks.start..mid, a, v, f),
        || for_blocks_view(mid..blocks.end, b, v, f),
    );
}

/// Geometry of the contact of a particle with one wall (plane, or a mesh patch at its
/// closest point).
pub(crate) struct WallGeom {
    /// Unit normal towards the particle.
    pub n: V3,
    pub delta: f64,
    /// Distance from the centre to the contact point (≥ 0).
    pub lever: f64,
    /// Contact point on the wall.
    pub point: V3,
    pub wall_velocity: V3,
    pub material: u16,
    /// (triangle, barycentric weights) of the contact point on a coupled mesh.
    pub mesh_ref: Option<(u32, [f64; 3])>,
}

/// The wall group (same wall and patch) of `cands` starting at `g`: its contact geometry when
/// the particle (centre `x`, radius `r`) touches it, and the start of the next group.
#[inline(always)]
pub(crate) fn wall_group(
    x: V3,
    r: f64,
    cands: &[crate::broad_phase::WallCandidate],
    mut g: usize,
    ctx: &ForceContext,
) -> (Option<WallGeom>, usize) {
    let n_planes = ctx.planes.len() as u32;
    let (w, patch) = (cands[g].wall, cands[g].patch);
    let mut geo = None;
    if w < n_planes {
        let pl = &ctx.planes[w as usize];
        let d = (x - pl.point).dot(&pl.normal);
        if d < r {
            geo = Some(WallGeom {
                n: pl.normal,
                delta: r - d,
                lever: d.max(0.0),
                point: x - pl.normal * d,
                wall_velocity: pl.velocity,
                material: pl.material,
                mesh_ref: None,
            });
        }
        g += 1;
    } else {
        let mesh = &ctx.meshes[(w - n_planes) as usize];
        let mut best: Option<(f64, V3, [f64; 3], u32)> = None;
        while g < cands.len() && cands[g].wall == w && cands[g].patch == patch {
            let tri = cands[g].triangle;
            let [a, b, c] = mesh.corners(tri as usize);
            let (q, bary) = crate::triangle_contact::closest_point_on_triangle(&x, &a, &b, &c);
            let d2 = (x - q).norm_squared();
            if best.is_none_or(|(bd, ..)| d2 < bd) {
                best = Some((d2, q, bary, tri));
            }
            g += 1;
        }
        if let Some((d2, q, bary, tri)) = best {
            if d2 < r * r {
                let d = d2.sqrt();
                let nrm = if d > 0.0 {
                    (x - q) / d
                } else {
                    let [a, b, c] = mesh.corners(tri as usize);
                    (b - a).cross(&(c - a)).normalize()
                };
                let [na, nb, nc] = mesh.triangles[tri as usize];
                let wv = mesh.velocities[na as usize] * bary[0]
                    + mesh.velocities[nb as usize] * bary[1]
                    + mesh.velocities[nc as usize] * bary[2];
                geo = Some(WallGeom {
                    n: nrm,
                    delta: r - d,
                    lever: d,
                    point: q,
                    wall_velocity: wv,
                    material: mesh.material,
                    mesh_ref: mesh.coupled.then_some((tri, bary)),
                });
            }
        }
    }
    (geo, g)
}

/// Hertz–Mindlin force on particle i of its wall contact `geo`; the relative velocity is
/// that of i's contact point against the wall's (moving walls, coupled meshes).
#[inline(always)]
pub(crate) fn wall_contact(
    k: &Kinematics,
    ctx: &ForceContext,
    i: usize,
    geo: &WallGeom,
    shear: &mut V3,
) -> crate::hertz_mindlin::ContactForce {
    let params = ctx.materials.pair(k.mat[i], geo.material);
    let v_c = k.vel[i] - (k.omega[i] * geo.lever).cross(&geo.n) - geo.wall_velocity;
    contact_force(
        params, geo.delta, k.rad[i], k.mass[i], &geo.n, &v_c, shear, ctx.dt,
    )
}

/// One force block: gravity, pairs with reactions, wall contacts.
fn block_forces(b: usize, s: BlockSlices, v: &ListsView, k: &Kinematics, ctx: &ForceContext) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
        // SAFETY: the CPU supports AVX2 and FMA (checked above)
        return unsafe {
            if ctx.weights.is_some() {
                block_forces_avx2::<true>(b, s, v, k, ctx)
            } else {
                block_forces_avx2::<false>(b, s, v, k, ctx)
            }
        };
    }
    if ctx.weights.is_some() {
        block_forces_generic::<true>(b, s, v, k, ctx)
    } else {
        block_forces_generic::<false>(b, s, v, k, ctx)
    }
}

/// [`block_forces`] compiled for AVX2 (no FMA contraction happens without explicit
/// `mul_add`, so the results are bitwise those of the baseline build).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn block_forces_avx2<const WEIGHTED: bool>(
    b: usize,
    s: BlockSlices,
    v: &ListsView,
    k: &Kinematics,
    ctx: &ForceContext,
) {
    block_forces_generic::<WEIGHTED>(b, s, v, k, ctx)
}

/// One force block; `WEIGHTED`: scale each pair's force and torques by its Arlequin
/// contact-point weight (6.29) (compiled out of unweighted runs).
#[inline(always)]
fn block_forces_generic<const WEIGHTED: bool>(
    b: usize,
    s: BlockSlices,
    v: &ListsView,
    k: &Kinematics,
    ctx: &ForceContext,
) {
    let n = k.pos.len();
    let (lo, hi) = (b * BLOCK, ((b + 1) * BLOCK).min(n));
    let BlockSlices {
        pair: pair0,
        cross: cross0,
        wall: wall0,
        force,
        torque,
        shear,
        cross_force,
        wall_contacts,
        records,
        ..
    } = s;
    for i in lo..hi {
        force[i - lo] = ctx.gravity * k.mass[i];
        torque[i - lo] = V3::zeros();
    }
    let mut cross = 0usize;
    debug_assert_eq!(cross0, v.block_start[b] as usize);
    for i in lo..hi {
        let xi = k.pos[i];
        let ri = k.rad[i];
        let mut fi = force[i - lo];
        let mut ti = torque[i - lo];
        for pk in v.first_pair[i] as usize..v.first_pair[i + 1] as usize {
            let j = v.partner[pk] as usize;
            let local = j < hi;
            let d = xi - k.pos[j];
            let rj = k.rad[j];
            let dist2 = d.norm_squared();
            let sum = ri + rj;
            if dist2 >= sum * sum {
                let h = &mut shear[pk - pair0];
                if *h != V3::zeros() {
                    *h = V3::zeros();
                }
                if !local {
                    cross_force[cross] = [V3::zeros(); 2];
                    cross += 1;
                }
                continue;
            }
            let (mut f, mut t, mut tj) =
                pair_force_torques(k, ctx, (i, j), d, dist2, k.vel[j], &mut shear[pk - pair0]);
            if WEIGHTED {
                // the weight at the contact point on the line of centres, r_i − δ/2 from c_i
                // (`SlotWeights::pair`, our form of 6.29); 1 away from every overlap, where
                // the contact point is not needed
                if let Some(ws) = ctx.weights.filter(|ws| !(ws.outside(i) && ws.outside(j))) {
                    let dist = dist2.sqrt();
                    let at = ((dist + ri - rj) / (2.0 * dist)).clamp(0.0, 1.0);
                    let w = ws.pair(i, j, xi, k.pos[j], xi - d * at);
                    f *= w;
                    t *= w;
                    tj *= w;
                }
            }
            fi += f;
            ti += t;
            if local {
                force[j - lo] -= f;
                torque[j - lo] += tj;
            } else {
                cross_force[cross] = [-f, tj];
                cross += 1;
            }
        }
        let ws = v.wall_start[i] as usize..v.wall_start[i + 1] as usize;
        if !ws.is_empty() {
            let (df, dtq) = wall_forces(
                i,
                &v.walls[ws.clone()],
                &mut wall_contacts[ws.start - wall0..ws.end - wall0],
                if records.is_empty() {
                    None
                } else {
                    Some(&mut records[ws.start - wall0..ws.end - wall0])
                },
                k,
                ctx,
            );
            fi += df;
            ti += dtq;
        }
        force[i - lo] = fi;
        torque[i - lo] = ti;
    }
    debug_assert_eq!(cross, cross_force.len());
}

/// Wall contacts of particle i: planes, then one contact per (mesh, patch) at its closest
/// point (see `triangle_contact`). Returns the force and torque on i.
#[inline(always)]
fn wall_forces(
    i: usize,
    cands: &[crate::broad_phase::WallCandidate],
    contacts: &mut [WallContact],
    mut records: Option<&mut [MeshForceRecord]>,
    k: &Kinematics,
    ctx: &ForceContext,
) -> (V3, V3) {
    let x = k.pos[i];
    let r = k.rad[i];
    let mut f = V3::zeros();
    let mut t = V3::zeros();
    let mut g = 0;
    while g < cands.len() {
        let first = g;
        let (geo, next) = wall_group(x, r, cands, g, ctx);
        g = next;
        let slot = &mut contacts[first];
        let Some(geo) = geo else {
            if *slot != WallContact::NONE {
                *slot = WallContact::NONE;
            }
            continue;
        };
        // the history of a contact that did not exist in the last evaluation is zero
        let mut shear = slot.shear;
        let cf = wall_contact(k, ctx, i, &geo, &mut shear);
        let params = ctx.materials.pair(k.mat[i], geo.material);
        let w = k.omega[i];
        // the weight of the contact point (1 without volume interfaces: the sums keep the
        // order of unweighted runs, bitwise)
        let s = ctx.weights.map_or(1.0, |ws| ws.at(i, x, geo.point));
        let fc = cf.force * s;
        f += fc;
        t += geo.n.cross(&cf.tangential) * (-geo.lever * s);
        if params.rolling_friction > 0.0 {
            t += rolling_torque(
                params.rolling_friction,
                r,
                cf.normal,
                &w,
                k.inertia[i],
                ctx.dt,
            ) * s;
        }
        *slot = WallContact {
            shear,
            overlap: geo.delta,
        };
        if let Some(rec) = records.as_deref_mut() {
            let (tri, bary) = geo.mesh_ref.unwrap_or_default();
            rec[first] = MeshForceRecord {
                triangle: tri,
                bary,
                force: -fc,
            };
        }
    }
    (f, t)
}

/// Distributes the recorded forces on coupled meshes to their nodes, f_K = N_K f
/// (Wellmann eqs. 4.3–4.4), in particle order, and updates the window accumulators: the
/// nodal forces are added to the window sum with `weight` (1 per step; 1/N per impact
/// sub-step; 0 for a pure evaluation), `count_step` counts one more window substep, and the
/// forces' power on the moving nodes times `dt` (the step's length; 0 for an evaluation) is
/// added to the window's interface work.
pub fn accumulate_nodal_forces(
    meshes: &mut [Mesh],
    lists: &NeighbourLists,
    n_planes: usize,
    records: &[MeshForceRecord],
    weight: f64,
    count_step: bool,
    dt: f64,
) {
    for m in meshes.iter_mut().filter(|m| m.coupled) {
        m.nodal_force_step.iter_mut().for_each(|f| *f = V3::zeros());
    }
    for (k, rec) in records.iter().enumerate() {
        let w = lists.walls[k].wall as usize;
        if w < n_planes || !lists.wall_contacts[k].touching() {
            continue;
        }
        let mesh = &mut meshes[w - n_planes];
        if !mesh.coupled {
            continue;
        }
        let tri = mesh.triangles[rec.triangle as usize];
        for (&node, &weight) in tri.iter().zip(&rec.bary) {
            mesh.nodal_force_step[node as usize] += rec.force * weight;
        }
    }
    // then the shaped bodies' contacts, group by group in list order
    let inc = &lists.shaped_incidence;
    for g in 0..inc.mesh_groups.len().saturating_sub(1) {
        let at = inc.mesh_groups[g] as usize;
        if !lists.shaped_mesh_contacts[at].touching() {
            continue;
        }
        let mesh = &mut meshes[lists.shaped_mesh[at].1.wall as usize - n_planes];
        if !mesh.coupled {
            continue;
        }
        let rec = &lists.shaped_mesh_records[at];
        let tri = mesh.triangles[rec.triangle as usize];
        for (&node, &weight) in tri.iter().zip(&rec.bary) {
            mesh.nodal_force_step[node as usize] += rec.force * weight;
        }
    }
    for m in meshes.iter_mut().filter(|m| m.coupled) {
        m.nodal_force_last.clone_from(&m.nodal_force_step);
        if weight != 0.0 {
            // weight 1 adds f exactly (x · 1 = x), as before impact sub-steps existed
            for (s, f) in m.nodal_force_sum.iter_mut().zip(&m.nodal_force_step) {
                *s += f * weight;
            }
        }
        if count_step {
            m.window_substeps += 1;
        }
        if dt > 0.0 {
            let power: f64 = m
                .nodal_force_step
                .iter()
                .zip(&m.velocities)
                .map(|(f, v)| f.dot(v))
                .sum();
            m.window_work += dt * power;
        }
    }
}
