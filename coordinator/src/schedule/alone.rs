//! `none`: a single solver runs its windows alone (the window is the reporting interval).

use proto::MotionRule;

use super::{Scheme, Sends, Topology, Windows};

#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct Alone;

impl Scheme for Alone {
    fn pipelines(&self) -> bool {
        true
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
}
