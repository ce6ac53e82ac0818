//! `none`: a single solver runs its windows alone (the window is the reporting interval).

use proto::MotionRule;

use super::{Next, Scheme, Sends, Topology, Windows};

#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct Alone;

impl Scheme for Alone {
    fn prologue(&self, _: &Topology) -> Sends {
        Vec::new()
    }

    fn window(&self, t: &Topology, w: &Windows, k: u64) -> Sends {
        t.all()
            .map(|n| {
                (
                    n.to_string(),
                    w.advance(k, MotionRule::Fixed, None, None, false),
                )
            })
            .collect()
    }

    fn replay(&self, _: &Topology, _: u64) -> Sends {
        Vec::new()
    }

    fn after_window(&mut self, _: &Topology, _: &Windows, _: u64, _: Option<f64>) -> Next {
        Next::Continue
    }
}
