//! Progress of a DEM programme (a periodic cell's stages, Wellmann ch. 5) for the run's
//! progress bar. Such a run ends when the programme does, not at the scene's `end_time`, so
//! the bar counts stages instead of windows: each stage is a hundredth-steps segment, filled
//! by the fraction the DEM reports in its `window_done` monitor (proto/PROTOCOL.md), with the
//! time left in a strain-driven stage estimated from its rate so far.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

/// Steps of the bar per stage.
pub const STEPS_PER_STAGE: u64 = 100;

/// Where a programme stands, as the coordinator learns it window by window.
#[derive(Debug, Clone)]
pub struct ProgrammeProgress {
    names: Vec<String>,
    /// The stage first seen with a strain fraction: (stage, when, fraction then).
    seen: Option<(usize, Instant, f64)>,
}

/// One update of the display.
#[derive(Debug, Clone, PartialEq)]
pub struct ProgressLine {
    /// Bar position out of `stages × STEPS_PER_STAGE`.
    pub position: u64,
    pub message: String,
}

impl ProgrammeProgress {
    /// `stages` from the DEM's `ready` limits (`programme_stages`); the names from the
    /// scene's `[[dem.periodic.stages]]` (`name`, else `stage<k>` as the DEM calls them).
    pub fn new(scene_text: &str, stages: usize) -> Self {
        let table: Option<toml::Table> = scene_text.parse().ok();
        let listed = table
            .as_ref()
            .and_then(|t| t.get("dem"))
            .and_then(|d| d.get("periodic"))
            .and_then(|p| p.get("stages"))
            .and_then(|s| s.as_array());
        let names = (0..stages)
            .map(|k| {
                listed
                    .and_then(|l| l.get(k))
                    .and_then(|s| s.get("name"))
                    .and_then(|n| n.as_str())
                    .map_or_else(|| format!("stage{k}"), str::to_string)
            })
            .collect();
        ProgrammeProgress { names, seen: None }
    }

    /// The bar's length.
    pub fn length(&self) -> u64 {
        self.names.len() as u64 * STEPS_PER_STAGE
    }

    /// The display after a DEM `window_done` with `values` (its monitor) at `now`; `None`
    /// when the monitor has no `programme_stage` (an older DEM, or another node).
    pub fn update(&mut self, values: &BTreeMap<String, f64>, now: Instant) -> Option<ProgressLine> {
        let n = self.names.len();
        let stage = *values.get("programme_stage")?;
        if !(stage.is_finite() && stage >= 0.0) {
            return None;
        }
        let stage = stage as usize;
        if stage >= n {
            self.seen = None;
            return Some(ProgressLine {
                position: self.length(),
                message: format!("programme done ({n} stages)"),
            });
        }
        let head = format!("stage {}/{n} `{}`", stage + 1, self.names[stage]);
        let base = stage as u64 * STEPS_PER_STAGE;
        let step = |f: f64| (f.clamp(0.0, 1.0) * (STEPS_PER_STAGE - 1) as f64) as u64;
        if let Some(&f) = values.get("programme_strain_fraction") {
            let f = f.clamp(0.0, 1.0);
            let left = match self.seen {
                Some((s, t0, f0)) if s == stage && f > f0 + 1e-3 => {
                    let spent = now.duration_since(t0).as_secs_f64();
                    Some(Duration::from_secs_f64(spent * (1.0 - f) / (f - f0)))
                }
                Some((s, ..)) if s == stage => None,
                _ => {
                    self.seen = Some((stage, now, f));
                    None
                }
            };
            let mut message = format!("{head}: {:.1} % of its strain", 100.0 * f);
            if let Some(left) = left {
                message += &format!(", {} left in it", about(left));
            }
            return Some(ProgressLine {
                position: base + step(f),
                message,
            });
        }
        self.seen = None;
        let message = match values.get("programme_stress_fraction") {
            Some(&f) => format!("{head}: stress at {:.0} % of its target", 100.0 * f),
            None => head,
        };
        let f = values
            .get("programme_stress_fraction")
            .copied()
            .unwrap_or(0.0);
        Some(ProgressLine {
            position: base + step(f),
            message,
        })
    }
}

/// A duration as people say it: `< 1 min`, `about 7 min`, `about 2 h 05 min`.
pub fn about(d: Duration) -> String {
    let min = (d.as_secs_f64() / 60.0).round() as u64;
    match min {
        0 => "< 1 min".into(),
        1..=59 => format!("about {min} min"),
        _ => format!("about {} h {:02} min", min / 60, min % 60),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SCENE: &str = r#"
[dem.periodic]
size = 0.01
[[dem.periodic.stages]]
name = "consolidate"
stress = { x = -1e3, y = -1e3, z = -1e3 }
[[dem.periodic.stages]]
strain = { z = -0.2 }
"#;

    fn monitor(pairs: &[(&str, f64)]) -> BTreeMap<String, f64> {
        pairs.iter().map(|(k, v)| (k.to_string(), *v)).collect()
    }

    #[test]
    fn stages_are_named_from_the_scene_or_numbered_like_the_dem_does() {
        let p = ProgrammeProgress::new(SCENE, 2);
        assert_eq!(p.names, ["consolidate", "stage1"]);
        assert_eq!(p.length(), 200);
        // a scene that does not parse still gets a display
        assert_eq!(ProgrammeProgress::new("not toml [", 1).names, ["stage0"]);
    }

    #[test]
    fn a_strain_stage_fills_its_segment_and_estimates_the_time_left_from_its_rate() {
        let mut p = ProgrammeProgress::new(SCENE, 2);
        let t0 = Instant::now();
        let first = p
            .update(
                &monitor(&[("programme_stage", 1.0), ("programme_strain_fraction", 0.1)]),
                t0,
            )
            .unwrap();
        assert_eq!(first.position, 100 + 9);
        assert_eq!(first.message, "stage 2/2 `stage1`: 10.0 % of its strain");
        // 0.1 → 0.3 in 10 min: the remaining 0.7 takes 35 min
        let later = p
            .update(
                &monitor(&[("programme_stage", 1.0), ("programme_strain_fraction", 0.3)]),
                t0 + Duration::from_secs(600),
            )
            .unwrap();
        assert_eq!(later.position, 100 + 29);
        assert_eq!(
            later.message,
            "stage 2/2 `stage1`: 30.0 % of its strain, about 35 min left in it"
        );
        let done = p
            .update(
                &monitor(&[("programme_stage", 2.0), ("programme_finished", 1.0)]),
                t0,
            )
            .unwrap();
        assert_eq!(done.position, 200);
        assert_eq!(done.message, "programme done (2 stages)");
    }

    #[test]
    fn a_stress_stage_shows_how_close_its_stress_is_and_no_monitor_no_display() {
        let mut p = ProgrammeProgress::new(SCENE, 2);
        let now = Instant::now();
        let l = p
            .update(
                &monitor(&[
                    ("programme_stage", 0.0),
                    ("programme_stress_fraction", 0.434),
                ]),
                now,
            )
            .unwrap();
        assert_eq!(l.position, 42);
        assert_eq!(
            l.message,
            "stage 1/2 `consolidate`: stress at 43 % of its target"
        );
        // overshoot while the servo settles: the segment stays short of the next stage
        let l = p
            .update(
                &monitor(&[("programme_stage", 0.0), ("programme_stress_fraction", 1.3)]),
                now,
            )
            .unwrap();
        assert_eq!(l.position, 99);
        assert!(p
            .update(&monitor(&[("kinetic_energy", 1.0)]), now)
            .is_none());
        assert!(p
            .update(&monitor(&[("programme_stage", f64::NAN)]), now)
            .is_none());
    }

    #[test]
    fn durations_read_like_speech() {
        assert_eq!(about(Duration::from_secs(20)), "< 1 min");
        assert_eq!(about(Duration::from_secs(7 * 60 + 10)), "about 7 min");
        assert_eq!(
            about(Duration::from_secs(2 * 3600 + 5 * 60)),
            "about 2 h 05 min"
        );
    }
}
