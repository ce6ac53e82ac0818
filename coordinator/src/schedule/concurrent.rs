//! Concurrent (explicit Jacobi): both solvers compute window k at the same time, each from the
//! other's data of the window before. The DEM moves every mesh by its provider's kinematics at
//! the window start extrapolated, x = P + Vτ + ½Aτ² (as just-in-time), and publishes forces k;
//! every FEM node steps with the DEM's forces of window k − 1 (none in window 0; as
//! predictive) and publishes its end state as kinematics k + 1. Neither waits for the other
//! within a window, so a window costs max(DEM, FEM) instead of their sum; the price is that
//! both sides lag (the limit of `cosim check`, docs/speed-accuracy.md). Before window 0 the
//! FEM nodes publish their initial state as kinematics 0.

use proto::{CommandBody, Label, MotionRule};

use super::{Scheme, Sends, Topology, Windows};

#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct Concurrent;

impl Scheme for Concurrent {
    fn pipelines(&self) -> bool {
        true
    }

    fn prologue(&self, t: &Topology) -> Sends {
        // every FEM node's initial state is kinematics 0
        publish(t.fems.iter(), 0)
    }

    fn window(&self, t: &Topology, w: &Windows, k: u64) -> Sends {
        let last = w.is_last(k);
        let mut out = Vec::new();
        if let Some(d) = &t.dem {
            // the forces of the last window would load no FEM window
            out.push((
                d.clone(),
                w.advance(
                    k,
                    MotionRule::Quadratic,
                    Some(k),
                    (!last).then_some(k),
                    false,
                ),
            ));
        }
        for f in &t.fems {
            out.push((
                f.clone(),
                w.advance(
                    k,
                    MotionRule::Quadratic,
                    k.checked_sub(1),
                    (!last).then_some(k + 1),
                    false,
                ),
            ));
        }
        out
    }

    fn replay(&self, t: &Topology, k: u64) -> Sends {
        // in flight between window k − 1 and k: each FEM node's end state (kinematics k) and
        // the DEM's forces of window k − 1
        let mut out = publish(t.fems.iter(), k);
        out.extend(publish(t.dem.iter(), k - 1));
        out
    }
}

/// `publish` of window `k`'s label to each node.
fn publish<'a>(nodes: impl Iterator<Item = &'a String>, k: u64) -> Sends {
    nodes
        .map(|n| {
            (
                n.clone(),
                CommandBody::Publish {
                    label: Label::window(k),
                },
            )
        })
        .collect()
}
