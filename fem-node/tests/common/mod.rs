#![allow(dead_code)]
//! Shared helpers for the integration tests.

pub mod footing;

use fem::config::FemConfig;
use fem::Model;
use std::path::Path;

pub fn config(toml_text: &str) -> FemConfig {
    match fem::parse_scene_section(toml_text) {
        Ok(Some(c)) => c,
        Ok(None) => panic!("no [fem] table"),
        Err(e) => panic!("config error: {e}"),
    }
}

pub fn model(toml_text: &str) -> Model {
    let cfg = config(toml_text);
    Model::from_config(&cfg, Path::new(".")).unwrap_or_else(|e| panic!("model: {e}"))
}

/// Small deterministic xorshift generator in [-0.5, 0.5).
pub struct Rng(pub u64);
impl Rng {
    pub fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    }
}

/// Steel of Ullrich table 4.1.
pub const STEEL: &str =
    "[fem.material]\nyoungs_modulus = 210e9\npoisson_ratio = 0.3\ndensity = 7800.0\n";

/// The fixed-fixed beam of REFERENCE A3 with a generated mesh.
pub fn a3_beam(element: &str, h: f64) -> String {
    format!(
        r#"
[fem]
mesh = {{ size = [1.0, 0.1, 0.1], element_size = {h}, element = "{element}" }}
{STEEL}
[[fem.supports]]
on = {{ set = "xmin" }}
[[fem.supports]]
on = {{ set = "xmax" }}
[[fem.loads]]
type = "pressure"
on = {{ set = "zmax" }}
value = 5000.0
[[fem.probes]]
name = "midspan"
point = [0.5, 0.05, 0.05]
[[fem.probes]]
name = "midspan_top"
point = [0.5, 0.05, 0.1]
[[fem.probes]]
name = "midspan_bottom"
point = [0.5, 0.05, 0.0]
"#
    )
}
