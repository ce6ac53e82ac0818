//! The schedule's kinematic maths, in one place (PROTOCOL.md §6): how a user of a surface
//! interface moves the coupled mesh during a window from the provider's kinematics. Providers
//! (FEM nodes in any language) publish only their own state; they never compute a
//! schedule-specific velocity.
//!
//! Within the window, τ ∈ [0, Δt^C] from its start, the mesh follows x(τ) = P + Vτ + ½Aτ²
//! with P, V, A chosen by the window's [`MotionRule`] (Ullrich ch. 3.3):
//! - `quadratic` (just-in-time): the provider's state at the window start, extrapolated;
//! - `linear` (predictive, (3.4)–(3.7)): P = P₀, the provider's previous end position (the
//!   mesh's reference position before the first window), V = (P_end − P₀)/Δt^C, A = 0, so the
//!   mesh lands exactly on the provider's end position P_end;
//! - `fixed`: P = the provider's position, V = A = 0.

use crate::messages::{InterfaceKinematics, MotionRule};

/// Substeps of length `step` in a window of length `window` (Δt^C = n^D Δt^D, Ullrich ch. 3.3):
/// the nearest whole number when the ratio is whole to 1e-6 relative, else `Err(ratio)`. The
/// coordinator checks a scene with it; a DEM node derives its substeps from the window with it.
pub fn whole_substeps(window: f64, step: f64) -> Result<u32, f64> {
    let ratio = window / step;
    let n = ratio.round();
    if !(step > 0.0 && step.is_finite())
        || n < 1.0
        || n > u32::MAX as f64
        || (ratio - n).abs() > 1e-6 * ratio.max(1.0)
    {
        return Err(ratio);
    }
    Ok(n as u32)
}

/// The mesh's motion during one window: x(τ) = P + Vτ + ½Aτ² (node-major xyz).
#[derive(Debug, Clone, PartialEq)]
pub struct MeshMotion {
    pub positions: Vec<f64>,
    pub velocities: Vec<f64>,
    pub accelerations: Vec<f64>,
}

/// The motion of a window of length `dt` under `rule`, from the provider's kinematics `k` and
/// its previous end position `start` (same length as `k`'s arrays; checked by the caller).
pub fn mesh_motion(
    rule: MotionRule,
    start: &[f64],
    k: &InterfaceKinematics,
    dt: f64,
) -> MeshMotion {
    let p = k.positions.as_slice();
    match rule {
        MotionRule::Quadratic => MeshMotion {
            positions: p.to_vec(),
            velocities: k.velocities.0.clone(),
            accelerations: k.accelerations.0.clone(),
        },
        MotionRule::Linear => MeshMotion {
            positions: start.to_vec(),
            // Ullrich (3.4): the predictive velocity
            velocities: p.iter().zip(start).map(|(e, s)| (e - s) / dt).collect(),
            accelerations: vec![0.0; p.len()],
        },
        MotionRule::Fixed => MeshMotion {
            positions: p.to_vec(),
            velocities: vec![0.0; p.len()],
            accelerations: vec![0.0; p.len()],
        },
    }
}

impl MeshMotion {
    /// Position at τ from the window start.
    pub fn at(&self, tau: f64) -> Vec<f64> {
        (0..self.positions.len())
            .map(|i| {
                self.positions[i]
                    + self.velocities[i] * tau
                    + 0.5 * self.accelerations[i] * tau * tau
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::messages::F64Array;

    fn kin(p: Vec<f64>, v: Vec<f64>, a: Vec<f64>) -> InterfaceKinematics {
        InterfaceKinematics {
            version: crate::PROTOCOL_VERSION,
            run_id: "r".into(),
            interface: "i".into(),
            window: 1,
            iteration: 0,
            time: 2e-4,
            positions: F64Array(p),
            velocities: F64Array(v),
            accelerations: F64Array(a),
        }
    }

    #[test]
    fn substeps_are_whole_or_refused_with_the_ratio() {
        assert_eq!(whole_substeps(1e-4, 1e-6), Ok(100));
        assert_eq!(whole_substeps(1e-5, 1e-6), Ok(10));
        assert!(whole_substeps(1e-4, 3e-6).is_err_and(|r| (r - 33.3333).abs() < 1e-3));
        assert!(whole_substeps(1e-4, 0.0).is_err());
        assert!(whole_substeps(1e-7, 1e-6).is_err());
    }

    #[test]
    fn predictive_motion_lands_on_the_providers_end_position() {
        let start = [0.0, 1.0, 2.0, -1.0, 0.5, 3.0];
        let end = vec![0.1, 0.9, 2.5, -1.25, 0.5, 2.0];
        let k = kin(end.clone(), vec![7.0; 6], vec![9.0; 6]);
        let m = mesh_motion(MotionRule::Linear, &start, &k, 1e-4);
        assert_eq!(m.positions, start.to_vec());
        assert!(m.accelerations.iter().all(|&a| a == 0.0));
        for (x, e) in m.at(1e-4).iter().zip(&end) {
            assert!((x - e).abs() <= 1e-15 * e.abs().max(1.0), "{x} vs {e}");
        }
        // the provider's own velocity plays no part: the motion is the secant (3.4)
        assert!((m.velocities[2] - 5000.0).abs() < 1e-9);
    }

    #[test]
    fn just_in_time_extrapolates_the_providers_state() {
        let k = kin(
            vec![1.0, 2.0, 3.0],
            vec![0.5, 0.0, -1.0],
            vec![2.0, 0.0, 4.0],
        );
        let m = mesh_motion(MotionRule::Quadratic, &[0.0; 3], &k, 1e-3);
        assert_eq!(m.at(0.5), vec![1.0 + 0.25 + 0.25, 2.0, 3.0 - 0.5 + 0.5]);
        let f = mesh_motion(MotionRule::Fixed, &[0.0; 3], &k, 1e-3);
        assert_eq!(f.at(0.5), vec![1.0, 2.0, 3.0]);
    }
}
