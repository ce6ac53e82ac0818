//! Stage "resolve and accumulate (contact) forces" (Ullrich Algorithm 1, line 4).
//!
//! Pair forces are computed in parallel into the pair list; each particle then gathers its
//! pairs, wall contacts and gravity in a fixed order (no atomics, no order-dependent
//! reductions), so the result is bitwise identical for any number of threads.

use crate::broad_phase::NeighbourLists;
use crate::hertz_mindlin::{contact_force, rolling_torque, V3};
use crate::materials::MaterialTable;
use crate::particles::Particles;
use crate::walls::{Mesh, Plane};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Wall contacts remembered per particle (history slots); more simultaneous wall contacts are
/// still resolved, without tangential history.
pub const WALL_SLOTS: usize = 4;

#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
pub struct WallSlot {
    /// Contact identity: (wall index << 32) | patch; walls are planes then meshes.
    pub key: u64,
    pub shear: V3,
    pub overlap: f64,
}

#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
pub struct WallState {
    pub count: u32,
    pub slots: [WallSlot; WALL_SLOTS],
}

/// A force on a coupled mesh at a point of triangle `triangle` with barycentric weights.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
pub struct MeshForceRecord {
    pub mesh: u32,
    pub triangle: u32,
    pub bary: [f64; 3],
    /// Force exerted by the particle on the mesh.
    pub force: V3,
    /// Contact point (for moment checks).
    pub point: V3,
}

#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
pub struct MeshRecords {
    pub count: u32,
    pub recs: [MeshForceRecord; WALL_SLOTS],
}

pub struct ForceContext<'a> {
    pub materials: &'a MaterialTable,
    pub planes: &'a [Plane],
    pub meshes: &'a [Mesh],
    pub gravity: V3,
    /// Tangential history increment time (Δt, or 0 for a pure evaluation).
    pub dt: f64,
}

/// Pair forces (Hertz–Mindlin, eqs. 2.6–2.19) into the pair list.
pub fn pair_forces(lists: &mut NeighbourLists, p: &Particles, ctx: &ForceContext) {
    let dt = ctx.dt;
    lists
        .pairs
        .par_iter_mut()
        .with_min_len(1024)
        .for_each(|pair| {
            let (i, j) = (pair.i as usize, pair.j as usize);
            let d = p.position[i] - p.position[j];
            let (ri, rj) = (p.radius[i], p.radius[j]);
            let dist2 = d.norm_squared();
            let sum = ri + rj;
            if dist2 >= sum * sum {
                pair.shear = V3::zeros();
                pair.force = V3::zeros();
                pair.torque_i = V3::zeros();
                pair.torque_j = V3::zeros();
                pair.overlap = sum - dist2.sqrt();
                return;
            }
            let dist = dist2.sqrt();
            let delta = sum - dist; // (2.9)
            let n = if dist > 0.0 { d / dist } else { V3::z() };
            let params = ctx.materials.pair(p.material[i], p.material[j]);
            let r_eff = ri * rj / sum; // (2.8)
            let m_eff = p.mass[i] * p.mass[j] / (p.mass[i] + p.mass[j]); // (2.11)
            let (ai, aj) = (ri - 0.5 * delta, rj - 0.5 * delta);
            let (wi, wj) = (p.angular_velocity[i], p.angular_velocity[j]);
            let v_c = p.velocity[i] - p.velocity[j] - (wi * ai + wj * aj).cross(&n);
            let cf = contact_force(params, delta, r_eff, m_eff, &n, &v_c, &mut pair.shear, dt);
            let nxt = n.cross(&cf.tangential);
            let i_eff = p.inertia[i] * p.inertia[j] / (p.inertia[i] + p.inertia[j]);
            let roll = rolling_torque(
                params.rolling_friction,
                r_eff,
                cf.normal,
                &(wi - wj),
                i_eff,
                dt,
            );
            pair.force = cf.force;
            pair.torque_i = nxt * (-ai) + roll;
            pair.torque_j = nxt * (-aj) - roll;
            pair.overlap = delta;
        });
}

struct WallContactGeom {
    key: u64,
    n: V3,
    delta: f64,
    lever: f64,
    point: V3,
    wall_velocity: V3,
    material: u16,
    mesh_ref: Option<(u32, u32, [f64; 3])>,
}

/// Gathers pair forces, resolves wall contacts and adds gravity, per particle.
pub fn gather_and_walls(
    lists: &NeighbourLists,
    p: &mut Particles,
    wall_state: &mut [WallState],
    records: &mut [MeshRecords],
    ctx: &ForceContext,
) {
    let pairs = &lists.pairs;
    let (pos, vel, omega, rad, mass, mat, inertia) = (
        &p.position,
        &p.velocity,
        &p.angular_velocity,
        &p.radius,
        &p.mass,
        &p.material,
        &p.inertia,
    );
    let with_records = !records.is_empty();
    let n_planes = ctx.planes.len() as u64;
    let body = |i: usize, ws: &mut WallState, mut rec: Option<&mut MeshRecords>| -> (V3, V3) {
        let mut f = gravity_force(mass[i], &ctx.gravity);
        let mut t = V3::zeros();
        for k in lists.first_pair[i]..lists.first_pair[i + 1] {
            let pr = &pairs[k as usize];
            f += pr.force;
            t += pr.torque_i;
        }
        for k in lists.as_j_start[i]..lists.as_j_start[i + 1] {
            let pr = &pairs[lists.as_j[k as usize] as usize];
            f -= pr.force;
            t += pr.torque_j;
        }

        // wall contacts: planes, then one contact per (mesh, patch) at its closest point
        let x = pos[i];
        let r = rad[i];
        let mut found: [Option<WallContactGeom>; 2 * WALL_SLOTS] = Default::default();
        let mut nfound = 0usize;
        let mut extra: Vec<WallContactGeom> = Vec::new();
        let mut push = |g: WallContactGeom, nfound: &mut usize| {
            if *nfound < found.len() {
                found[*nfound] = Some(g);
                *nfound += 1;
            } else {
                extra.push(g);
            }
        };
        for (k, pl) in ctx.planes.iter().enumerate() {
            let d = (x - pl.point).dot(&pl.normal);
            if d < r {
                push(
                    WallContactGeom {
                        key: (k as u64) << 32,
                        n: pl.normal,
                        delta: r - d,
                        lever: d.max(0.0),
                        point: x - pl.normal * d,
                        wall_velocity: V3::zeros(),
                        material: pl.material,
                        mesh_ref: None,
                    },
                    &mut nfound,
                );
            }
        }
        let cands = &lists.tri[lists.tri_start[i] as usize..lists.tri_start[i + 1] as usize];
        let mut g = 0;
        while g < cands.len() {
            let (m, patch) = (cands[g].mesh, cands[g].patch);
            let mesh = &ctx.meshes[m as usize];
            let mut best: Option<(f64, V3, [f64; 3], u32)> = None;
            while g < cands.len() && cands[g].mesh == m && cands[g].patch == patch {
                let tri = cands[g].triangle;
                let [a, b, c] = mesh.corners(tri as usize);
                let (q, bary) = crate::triangle_contact::closest_point_on_triangle(&x, &a, &b, &c);
                let d2 = (x - q).norm_squared();
                if best.map_or(true, |(bd, ..)| d2 < bd) {
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
                    push(
                        WallContactGeom {
                            key: ((n_planes + m as u64) << 32) | patch as u64,
                            n: nrm,
                            delta: r - d,
                            lever: d,
                            point: q,
                            wall_velocity: wv,
                            material: mesh.material,
                            mesh_ref: if mesh.coupled {
                                Some((m, tri, bary))
                            } else {
                                None
                            },
                        },
                        &mut nfound,
                    );
                }
            }
        }

        let old = *ws;
        let mut new_state = WallState::default();
        if let Some(rec) = rec.as_deref_mut() {
            rec.count = 0;
        }
        let all = found[..nfound]
            .iter()
            .map(|o| o.as_ref().unwrap())
            .chain(extra.iter());
        for geo in all {
            let params = ctx.materials.pair(mat[i], geo.material);
            let mut shear = old.slots[..old.count as usize]
                .iter()
                .find(|s| s.key == geo.key)
                .map_or(V3::zeros(), |s| s.shear);
            let w = omega[i];
            let v_c = vel[i] - (w * geo.lever).cross(&geo.n) - geo.wall_velocity;
            let cf = contact_force(
                params, geo.delta, r, mass[i], &geo.n, &v_c, &mut shear, ctx.dt,
            );
            f += cf.force;
            t += geo.n.cross(&cf.tangential) * (-geo.lever)
                + rolling_torque(
                    params.rolling_friction,
                    r,
                    cf.normal,
                    &w,
                    inertia[i],
                    ctx.dt,
                );
            if (new_state.count as usize) < WALL_SLOTS {
                new_state.slots[new_state.count as usize] = WallSlot {
                    key: geo.key,
                    shear,
                    overlap: geo.delta,
                };
                new_state.count += 1;
            }
            if let (Some((m, tri, bary)), Some(rec)) = (geo.mesh_ref, rec.as_deref_mut()) {
                if (rec.count as usize) < WALL_SLOTS {
                    rec.recs[rec.count as usize] = MeshForceRecord {
                        mesh: m,
                        triangle: tri,
                        bary,
                        force: -cf.force,
                        point: geo.point,
                    };
                    rec.count += 1;
                }
            }
        }
        *ws = new_state;
        (f, t)
    };
    let forces = p
        .force
        .par_iter_mut()
        .zip(p.torque.par_iter_mut())
        .zip(wall_state.par_iter_mut());
    if with_records {
        forces
            .zip(records.par_iter_mut())
            .enumerate()
            .with_min_len(512)
            .for_each(|(i, (((f_out, t_out), ws), rec))| {
                (*f_out, *t_out) = body(i, ws, Some(rec));
            });
    } else {
        forces
            .enumerate()
            .with_min_len(512)
            .for_each(|(i, ((f_out, t_out), ws))| {
                (*f_out, *t_out) = body(i, ws, None);
            });
    }
}

#[inline]
fn gravity_force(m: f64, g: &V3) -> V3 {
    g * m
}

/// Distributes the recorded forces on coupled meshes to their nodes, f_K = N_K f
/// (Wellmann eqs. 4.3–4.4), in particle order, and updates the window accumulators.
pub fn accumulate_nodal_forces(meshes: &mut [Mesh], records: &[MeshRecords], count_step: bool) {
    for m in meshes.iter_mut().filter(|m| m.coupled) {
        m.nodal_force_step.iter_mut().for_each(|f| *f = V3::zeros());
    }
    for r in records {
        for rec in &r.recs[..r.count as usize] {
            let mesh = &mut meshes[rec.mesh as usize];
            let tri = mesh.triangles[rec.triangle as usize];
            for k in 0..3 {
                mesh.nodal_force_step[tri[k] as usize] += rec.force * rec.bary[k];
            }
        }
    }
    for m in meshes.iter_mut().filter(|m| m.coupled) {
        m.nodal_force_last.clone_from(&m.nodal_force_step);
        if count_step {
            for (s, f) in m.nodal_force_sum.iter_mut().zip(&m.nodal_force_step) {
                *s += f;
            }
            m.window_substeps += 1;
        }
    }
}
