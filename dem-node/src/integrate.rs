//! Stage "update particle states" (Ullrich Algorithm 1, line 5): velocity Verlet for
//! translation (second order, symplectic: with e = 1 the rebound error of fig. 2.5 falls as
//! Δt²) and the same kick–drift–kick for rotation with an exact quaternion update.

use crate::hertz_mindlin::V3;
use crate::particles::Particles;
use nalgebra::{Quaternion, UnitQuaternion};
use rayon::prelude::*;

const MIN_LEN: usize = 2048;

/// First half kick and drift: v ← v + ½Δt F/m, x ← x + Δt v (same for ω and orientation).
pub fn kick_drift(p: &mut Particles, dt: f64, rotation: bool) {
    p.position
        .par_iter_mut()
        .zip(p.velocity.par_iter_mut())
        .zip(p.force.par_iter())
        .zip(p.mass.par_iter())
        .with_min_len(MIN_LEN)
        .for_each(|(((x, v), f), m)| {
            *v += f * (0.5 * dt / m);
            *x += *v * dt;
        });
    if rotation {
        p.orientation
            .par_iter_mut()
            .zip(p.angular_velocity.par_iter_mut())
            .zip(p.torque.par_iter())
            .zip(p.inertia.par_iter())
            .with_min_len(MIN_LEN)
            .for_each(|(((q, w), t), inertia)| {
                *w += t * (0.5 * dt / inertia);
                *q = rotate(q, w, dt);
            });
    }
}

/// Second half kick with the new forces.
pub fn kick(p: &mut Particles, dt: f64, rotation: bool) {
    p.velocity
        .par_iter_mut()
        .zip(p.force.par_iter())
        .zip(p.mass.par_iter())
        .with_min_len(MIN_LEN)
        .for_each(|((v, f), m)| {
            *v += f * (0.5 * dt / m);
        });
    if rotation {
        p.angular_velocity
            .par_iter_mut()
            .zip(p.torque.par_iter())
            .zip(p.inertia.par_iter())
            .with_min_len(MIN_LEN)
            .for_each(|((w, t), inertia)| {
                *w += t * (0.5 * dt / inertia);
            });
    }
}

/// Orientation after rotating by the world-frame angular velocity ω over Δt.
#[inline]
fn rotate(q: &Quaternion<f64>, w: &V3, dt: f64) -> Quaternion<f64> {
    let angle = w.norm() * dt;
    if angle == 0.0 {
        return *q;
    }
    let dq = UnitQuaternion::from_scaled_axis(w * dt);
    let r = dq.into_inner() * q;
    r / r.norm()
}
