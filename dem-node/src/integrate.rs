//! Stage "update particle states" (Ullrich Algorithm 1, line 5): velocity Verlet for
//! translation (second order, symplectic: with e = 1 the rebound error of fig. 2.5 falls as
//! Δt²) and the same kick–drift–kick for the angular velocity (spheres carry no orientation:
//! it would change none of their contacts). A non-spherical body kicks its angular momentum
//! H = T Ĩ Tᵀ ω by half steps of the torque and turns between the kicks by Wellmann's
//! scheme (3.35)–(3.46) ([`crate::rotation`]); the sphere-only pass is compiled without that
//! branch.
//!
//! Each half of the update is one pass over the particles that also does the bookkeeping
//! needing the same data: the drift checks the Verlet-skin displacement (Wellmann B4), the
//! second kick checks that the state is finite.

use crate::hertz_mindlin::V3;
use crate::particles::{Orientation, Particles, ShapeTemplate, SPHERE};
use crate::rotation;
use rayon::prelude::*;

/// Particles per parallel chunk (the passes are element-wise: the result does not depend on
/// it); a shaped body's turn costs about a hundred times a sphere's update, so beds with
/// shapes are cut finer.
const CHUNK: usize = 2048;
const SHAPED_CHUNK: usize = 128;

/// What a pass over the particles does.
const DRIFT: u8 = 1; // first half kick and drift (x), skin check
const KICK: u8 = 2; // second half kick, finiteness check
const KICK_DRIFT: u8 = 3; // second half kick of one step, then first half kick and drift of the next

/// First half kick and drift: v ← v + ½Δt F/m, x ← x + Δt v, ω ← ω + ½Δt T/I.
/// Returns true if some particle is now farther than `half_skin` from `position_at_build`
/// (or the lengths differ).
pub fn kick_drift(
    p: &mut Particles,
    position_at_build: &[V3],
    half_skin: f64,
    dt: f64,
    rotation: bool,
) -> bool {
    pass::<DRIFT>(p, position_at_build, half_skin, dt, rotation).1
}

/// Second half kick with the new forces. Returns false if a position, velocity or angular
/// velocity is not finite.
pub fn kick(p: &mut Particles, dt: f64, rotation: bool) -> bool {
    pass::<KICK>(p, &[], 0.0, dt, rotation).0
}

/// [`kick`] of one step followed by [`kick_drift`] of the next, in one pass (the same
/// operations on each particle in the same order, so bitwise the same result).
/// Returns (finite after the kick, moved after the drift).
pub fn kick_then_kick_drift(
    p: &mut Particles,
    position_at_build: &[V3],
    half_skin: f64,
    dt: f64,
    rotation: bool,
) -> (bool, bool) {
    pass::<KICK_DRIFT>(p, position_at_build, half_skin, dt, rotation)
}

fn pass<const MODE: u8>(
    p: &mut Particles,
    position_at_build: &[V3],
    half_skin: f64,
    dt: f64,
    rotation: bool,
) -> (bool, bool) {
    if p.has_shapes() {
        pass_with::<MODE, true>(p, position_at_build, half_skin, dt, rotation)
    } else {
        pass_with::<MODE, false>(p, position_at_build, half_skin, dt, rotation)
    }
}

fn pass_with<const MODE: u8, const SHAPES: bool>(
    p: &mut Particles,
    position_at_build: &[V3],
    half_skin: f64,
    dt: f64,
    rotation: bool,
) -> (bool, bool) {
    let half2 = half_skin * half_skin;
    let check = position_at_build.len() == p.len();
    let build: &[V3] = if check { position_at_build } else { &[] };
    let templates: &[ShapeTemplate] = &p.templates;
    let per_chunk = if SHAPES { SHAPED_CHUNK } else { CHUNK };
    let (finite, moved) = (
        p.position.par_chunks_mut(per_chunk),
        p.velocity.par_chunks_mut(per_chunk),
        p.force.par_chunks(per_chunk),
        p.mass.par_chunks(per_chunk),
        p.angular_velocity.par_chunks_mut(per_chunk),
        p.torque.par_chunks(per_chunk),
        p.inertia.par_chunks(per_chunk),
        p.orientation.par_chunks_mut(per_chunk),
        p.shape.par_chunks(per_chunk),
    )
        .into_par_iter()
        .enumerate()
        .map(|(c, (x, v, f, m, w, t, inertia, q, shape))| {
            let x0 = build
                .get(c * per_chunk..c * per_chunk + x.len())
                .unwrap_or(&[]);
            let s = Chunk {
                x,
                v,
                f,
                m,
                w,
                t,
                inertia,
                x0,
                q,
                shape,
                templates,
            };
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                // SAFETY: the CPU supports AVX2 and FMA (checked above)
                return unsafe { chunk_avx2::<MODE, SHAPES>(s, dt, half2, rotation) };
            }
            chunk::<MODE, SHAPES>(s, dt, half2, rotation)
        })
        .reduce(|| (true, false), |a, b| (a.0 && b.0, a.1 || b.1));
    (finite, moved || (MODE & DRIFT != 0 && !check))
}

struct Chunk<'a> {
    x: &'a mut [V3],
    v: &'a mut [V3],
    f: &'a [V3],
    m: &'a [f64],
    w: &'a mut [V3],
    t: &'a [V3],
    inertia: &'a [f64],
    x0: &'a [V3],
    q: &'a mut [Orientation],
    shape: &'a [u32],
    templates: &'a [ShapeTemplate],
}

/// [`chunk`] compiled for AVX2 (no FMA contraction happens without explicit `mul_add`, so
/// the results are bitwise those of the baseline build).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn chunk_avx2<const MODE: u8, const SHAPES: bool>(
    s: Chunk,
    dt: f64,
    half2: f64,
    rotation: bool,
) -> (bool, bool) {
    chunk::<MODE, SHAPES>(s, dt, half2, rotation)
}

#[inline(always)]
fn chunk<const MODE: u8, const SHAPES: bool>(
    s: Chunk,
    dt: f64,
    half2: f64,
    rotation: bool,
) -> (bool, bool) {
    let Chunk {
        x,
        v,
        f,
        m,
        w,
        t,
        inertia,
        x0,
        q,
        shape,
        templates,
    } = s;
    let mut ok = true;
    let mut moved = false;
    for k in 0..x.len() {
        if SHAPES && shape[k] != SPHERE {
            let principal = &templates[shape[k] as usize].principal_inertia;
            let half_kick = f[k] * (0.5 * dt / m[k]);
            // the half kick of H (3.35) in the body frame: ½Δt Tᵀ M (a kick and the drift
            // that follows it in one pass see the same orientation and torque)
            let turn = if rotation {
                q[k].inverse_transform_vector(&t[k]) * (0.5 * dt)
            } else {
                V3::zeros()
            };
            if MODE & KICK != 0 {
                v[k] += half_kick;
                if rotation {
                    // ω(T, H + ½Δt M) (3.37) = T (Tᵀω + Ĩ⁻¹ ½Δt Tᵀ M)
                    let wb = q[k].inverse_transform_vector(&w[k]) + turn.component_div(principal);
                    w[k] = q[k] * wb;
                }
                let (a, b, c) = (x[k], v[k], w[k]);
                ok &= (a.x + a.y + a.z + b.x + b.y + b.z + c.x + c.y + c.z).is_finite();
            }
            if MODE & DRIFT != 0 {
                v[k] += half_kick;
                x[k] += v[k] * dt;
                if let Some(x0) = x0.get(k) {
                    moved |= (x[k] - x0).norm_squared() > half2;
                }
                if rotation {
                    // Tᵀ H after the half kick, then the turn (3.39)–(3.46) in the body frame
                    let h = q[k]
                        .inverse_transform_vector(&w[k])
                        .component_mul(principal)
                        + turn;
                    let (qn, wn) = rotation::rotate_body(&q[k], &h, principal, dt);
                    q[k] = qn;
                    w[k] = wn;
                }
            }
            continue;
        }
        let half_kick = f[k] * (0.5 * dt / m[k]);
        let half_turn = t[k] * (0.5 * dt / inertia[k]);
        if MODE & KICK != 0 {
            v[k] += half_kick;
            if rotation {
                w[k] += half_turn;
            }
            // non-finite iff a component is (or |component| > 1e307, equally unstable)
            let (a, b, c) = (x[k], v[k], w[k]);
            ok &= (a.x + a.y + a.z + b.x + b.y + b.z + c.x + c.y + c.z).is_finite();
        }
        if MODE & DRIFT != 0 {
            v[k] += half_kick;
            x[k] += v[k] * dt;
            if let Some(x0) = x0.get(k) {
                moved |= (x[k] - x0).norm_squared() > half2;
            }
            if rotation {
                w[k] += half_turn;
            }
        }
    }
    (ok, moved)
}
