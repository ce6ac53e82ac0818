//! Impact refinement (`[dem] impact_substeps = N`, off by default): a step during which any
//! contact is touching — or starts or ends — is integrated as N sub-steps of Δt/N.
//!
//! Why: with ~8 steps per contact (Ullrich fig. 2.5, REFERENCE A2: 0.1 m/s at the Rayleigh
//! step) velocity Verlet's rebound error is up to 5.6e-3 depending on where in a step the
//! contact begins. Refining only the steps in which a contact opens or closes does not help
//! (worst 7e-3 with N = 16): the F ∝ δ^{3/2} boundary layer, where Verlet's error expansion
//! fails, spans δ ≲ vΔt, at Δt_R nearly the whole contact; and a change of step size inside a
//! contact breaks the cancellation between onset and separation errors that the symmetric
//! integrator otherwise gets (its modified energy equals the energy at δ = 0 only). Refining
//! the whole contact, free flight at Δt, gives exactly the error of Δt/N at the cost of
//! Δt/N during contacts only: 4.9e-6 (N = 16) and 9.4e-7 (N = 32) at Δt_R, worst over onset
//! phases. In a dense packing some contact is always touching, so every step is refined
//! (cost ≈ N×): an option for dilute, impact-dominated scenes.
//!
//! The prediction uses the positions the unrefined step would reach, x + Δt(v + ½Δt F/m)
//! (exactly what the drift computes): a pair or wall group touching now or then, or a pair
//! whose straight relative path passes through contact in between (a glancing touch within
//! one step), triggers refinement. Walls are moved by their current velocity. When the step
//! would rebuild the neighbour lists (a particle, coupled-mesh node or moving wall passes d_V/2
//! from where it was at the last build, or the lists are invalid) the lists cannot show new
//! pairs, and the step is refined conservatively.
//!
//! The whole system is sub-stepped, so pair forces stay symmetric; the decision is a boolean
//! over a fixed set, so it and hence the results do not depend on the thread count.

use crate::broad_phase::{NeighbourLists, WallCandidate};
use crate::hertz_mindlin::V3;
use crate::particles::Particles;
use crate::walls::{Mesh, Plane};
use rayon::prelude::*;

/// Particles per parallel chunk of the prediction (element-wise: no effect on the result).
const CHUNK: usize = 2048;

/// The walls as the prediction sees them.
pub struct WallsView<'a> {
    pub planes: &'a [Plane],
    pub meshes: &'a [Mesh],
    /// Largest displacement of a prescribed-motion wall since the last list build at the end
    /// of this step (m).
    pub wall_shift_at_step_end: f64,
}

/// True when a contact is predicted to touch at some time of the next step of `dt`, or the
/// step would rebuild the neighbour lists (see the module docs). `predicted` is scratch space
/// (the predicted end positions).
pub fn contact_during_step(
    lists: &NeighbourLists,
    p: &Particles,
    walls: &WallsView,
    dt: f64,
    predicted: &mut Vec<V3>,
) -> bool {
    let n = p.len();
    if n == 0 {
        return false;
    }
    if !lists.valid || lists.position_at_build.len() != n {
        return true;
    }
    let half_skin = 0.5 * lists.skin;
    if walls.wall_shift_at_step_end > half_skin
        || walls.meshes.iter().any(|m| {
            m.coupled && m.active && {
                let vmax = m.velocities.iter().map(|v| v.norm()).fold(0.0, f64::max);
                m.max_displacement_since_build() + vmax * dt > half_skin
            }
        })
    {
        return true;
    }
    predicted.resize(n, V3::zeros());
    let half2 = half_skin * half_skin;
    let moved = predicted
        .par_chunks_mut(CHUNK)
        .enumerate()
        .map(|(c, out)| {
            let lo = c * CHUNK;
            let mut moved = false;
            for (k, x1) in out.iter_mut().enumerate() {
                let i = lo + k;
                // the drift's own operations (integrate.rs), so x1 is where the step puts i
                let v = p.velocity[i] + p.force[i] * (0.5 * dt / p.mass[i]);
                *x1 = p.position[i] + v * dt;
                moved |= (*x1 - lists.position_at_build[i]).norm_squared() > half2;
            }
            moved
        })
        .reduce(|| false, |a, b| a || b);
    if moved {
        return true;
    }
    let x1 = &predicted[..];
    (0..n).into_par_iter().with_min_len(256).any(|i| {
        let (xi, yi, ri) = (p.position[i], x1[i], p.radius[i]);
        let pairs = lists.first_pair[i] as usize..lists.first_pair[i + 1] as usize;
        let pair_touches = lists.partner[pairs].iter().any(|&j| {
            let j = j as usize;
            pair_touches(xi - p.position[j], yi - x1[j], ri + p.radius[j])
        });
        pair_touches || {
            let ws = lists.wall_start[i] as usize..lists.wall_start[i + 1] as usize;
            !ws.is_empty() && walls_touch(xi, yi, ri, &lists.walls[ws], walls, dt)
        }
    })
}

/// A pair with separation `d0` now and `d1` at the step end (straight relative path) and
/// radius sum `s` touches (|d| < s, as the force stage tests) at some time of the step.
#[inline]
fn pair_touches(d0: V3, d1: V3, s: f64) -> bool {
    let s2 = s * s;
    if d0.norm_squared() < s2 || d1.norm_squared() < s2 {
        return true;
    }
    // both ends apart: does the path pass through contact (a glancing touch)?
    let e = d1 - d0;
    let e2 = e.norm_squared();
    if e2 == 0.0 {
        return false;
    }
    let t = -d0.dot(&e) / e2;
    t > 0.0 && t < 1.0 && (d0 + e * t).norm_squared() < s2
}

/// The particle (centre `x0` now, `x1` at the step end, radius `r`) touches one of its wall
/// groups now or at the step end (walls moved by their current velocity; a glancing touch in
/// between is not detected for walls).
fn walls_touch(x0: V3, x1: V3, r: f64, cands: &[WallCandidate], w: &WallsView, dt: f64) -> bool {
    let n_planes = w.planes.len() as u32;
    let r2 = r * r;
    let mut g = 0;
    while g < cands.len() {
        let (wall, patch) = (cands[g].wall, cands[g].patch);
        if wall < n_planes {
            let pl = &w.planes[wall as usize];
            g += 1;
            let d0 = (x0 - pl.point).dot(&pl.normal);
            let d1 = (x1 - pl.point - pl.velocity * dt).dot(&pl.normal);
            if pl.active && (d0 < r || d1 < r) {
                return true;
            }
            continue;
        }
        let mesh = &w.meshes[(wall - n_planes) as usize];
        while g < cands.len() && cands[g].wall == wall && cands[g].patch == patch {
            let t = cands[g].triangle as usize;
            g += 1;
            if !mesh.active {
                continue;
            }
            let [a, b, c] = mesh.corners(t);
            if crate::triangle_contact::distance_squared(&x0, &a, &b, &c) < r2 {
                return true;
            }
            let [ia, ib, ic] = mesh.triangles[t];
            let moved = |k: u32, x: V3| x + mesh.velocities[k as usize] * dt;
            let (a1, b1, c1) = (moved(ia, a), moved(ib, b), moved(ic, c));
            if crate::triangle_contact::distance_squared(&x1, &a1, &b1, &c1) < r2 {
                return true;
            }
        }
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pair_touch_covers_onset_contact_separation_and_glancing() {
        let s = 1.0;
        let x = |a: f64, b: f64| V3::new(a, b, 0.0);
        assert!(pair_touches(x(1.1, 0.0), x(0.9, 0.0), s), "onset");
        assert!(pair_touches(x(0.9, 0.0), x(1.1, 0.0), s), "separation");
        assert!(
            pair_touches(x(0.9, 0.0), x(0.8, 0.0), s),
            "stays in contact"
        );
        assert!(!pair_touches(x(1.3, 0.0), x(1.2, 0.0), s), "stays apart");
        assert!(pair_touches(x(-2.0, 0.5), x(2.0, 0.5), s), "glancing pass");
        assert!(!pair_touches(x(-2.0, 1.5), x(2.0, 1.5), s), "passes by");
    }
}
