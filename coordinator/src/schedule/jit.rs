//! Just-in-time (Ullrich ch. 3.3): in window k the DEM moves every mesh by the kinematics of
//! its provider at the window start, x = P + Vτ + ½Aτ², and publishes forces k; every FEM node
//! reads its forces k, steps, and publishes its end state as kinematics k + 1. Before window 0
//! the FEM nodes publish their initial state as kinematics 0.

use proto::{CommandBody, Label, MotionRule};

use super::{Scheme, Sends, Topology, Windows};

#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct Jit;

impl Scheme for Jit {
    fn pipelines(&self) -> bool {
        true
    }

    fn prologue(&self, t: &Topology) -> Sends {
        // every FEM node's initial state is kinematics 0
        self.replay(t, 0)
    }

    fn window(&self, t: &Topology, w: &Windows, k: u64) -> Sends {
        let mut out = Vec::new();
        if let Some(d) = &t.dem {
            out.push((
                d.clone(),
                w.advance(k, MotionRule::Quadratic, Some(k), Some(k), false),
            ));
        }
        for f in &t.fems {
            out.push((
                f.clone(),
                w.advance(
                    k,
                    MotionRule::Quadratic,
                    Some(k),
                    (!w.is_last(k)).then_some(k + 1),
                    false,
                ),
            ));
        }
        out
    }

    fn replay(&self, t: &Topology, k: u64) -> Sends {
        // each FEM node's state at the end of window k − 1 is kinematics k
        t.fems
            .iter()
            .map(|f| {
                (
                    f.clone(),
                    CommandBody::Publish {
                        label: Label::window(k),
                    },
                )
            })
            .collect()
    }
}
