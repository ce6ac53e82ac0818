//! One-way (Ullrich ch. 4): the DEM runs windows against the fixed meshes until its kinetic
//! energy stays below the threshold for a number of windows (or the end time comes), then
//! publishes its forces once, and every FEM node solves statically with them.

use proto::{CommandBody, Label, MotionRule};

use super::{Next, Scheme, Sends, Topology, Windows};

#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct OneWay {
    /// Kinetic energy (J) below which the DEM is steady ...
    pub steady_kinetic_energy: Option<f64>,
    /// ... for this many consecutive windows.
    pub steady_windows: u32,
    /// Consecutive windows with the DEM below the steady kinetic energy.
    calm_windows: u32,
    /// The DEM was still moving when the end time forced the static solve (its kinetic
    /// energy then, J): the run says so instead of passing the forces off as settled.
    pub unsettled_kinetic_energy: Option<f64>,
}

impl OneWay {
    pub fn new(steady_kinetic_energy: Option<f64>, steady_windows: u32) -> Self {
        OneWay {
            steady_kinetic_energy,
            steady_windows,
            ..Default::default()
        }
    }
}

impl Scheme for OneWay {
    fn window(&self, t: &Topology, w: &Windows, k: u64) -> Sends {
        t.dem
            .iter()
            .map(|d| {
                (
                    d.clone(),
                    w.advance(k, MotionRule::Fixed, None, None, false),
                )
            })
            .collect()
    }

    fn after_window(
        &mut self,
        t: &Topology,
        w: &Windows,
        k: u64,
        kinetic_energy: Option<f64>,
    ) -> Next {
        let calm = match (kinetic_energy, self.steady_kinetic_energy) {
            (Some(e), Some(limit)) => e < limit,
            _ => false,
        };
        self.calm_windows = if calm { self.calm_windows + 1 } else { 0 };
        let steady = self.calm_windows >= self.steady_windows;
        if !steady && !w.is_last(k) {
            return Next::Continue;
        }
        if !steady && self.steady_kinetic_energy.is_some() {
            self.unsettled_kinetic_energy = Some(kinetic_energy.unwrap_or(f64::NAN));
        }
        // Ullrich ch. 4: the settled DEM forces load a static FEM solve.
        let mut sends: Sends = t
            .dem
            .iter()
            .map(|d| {
                (
                    d.clone(),
                    CommandBody::Publish {
                        label: Label::window(k),
                    },
                )
            })
            .collect();
        sends.extend(t.fems.iter().map(|f| {
            (
                f.clone(),
                w.advance(k, MotionRule::Fixed, Some(k), None, true),
            )
        }));
        Next::Final {
            sends,
            reason: format!("static FEM solve with the DEM forces of window {k} done"),
        }
    }

    fn unsettled_kinetic_energy(&self) -> Option<f64> {
        self.unsettled_kinetic_energy
    }
}
