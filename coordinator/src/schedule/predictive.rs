//! Predictive (Ullrich (3.4)–(3.7)): in window k every FEM node reads the DEM forces of window
//! k − 1 (none in window 0), steps from P_k to P_{k+1} and publishes its end state as
//! kinematics k; the DEM moves each mesh linearly from P_k to that end state
//! (proto::motion) — so it lands exactly on P_{k+1} — and publishes forces k (none in the
//! last window).

use proto::{CommandBody, Label, MotionRule};

use super::{Scheme, Sends, Topology, Windows};

#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct Predictive;

impl Scheme for Predictive {
    fn pipelines(&self) -> bool {
        true
    }

    fn window(&self, t: &Topology, w: &Windows, k: u64) -> Sends {
        let mut out = Vec::new();
        for f in &t.fems {
            out.push((
                f.clone(),
                w.advance(k, MotionRule::Linear, k.checked_sub(1), Some(k), false),
            ));
        }
        if let Some(d) = &t.dem {
            out.push((
                d.clone(),
                w.advance(
                    k,
                    MotionRule::Linear,
                    Some(k),
                    (!w.is_last(k)).then_some(k),
                    false,
                ),
            ));
        }
        out
    }

    fn replay(&self, t: &Topology, k: u64) -> Sends {
        // the DEM's forces of window k − 1 load the FEM nodes in window k
        t.dem
            .iter()
            .map(|d| {
                (
                    d.clone(),
                    CommandBody::Publish {
                        label: Label::window(k - 1),
                    },
                )
            })
            .collect()
    }
}
