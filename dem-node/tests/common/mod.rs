#![allow(dead_code)]
use dem::{parse_scene_section, Engine};

pub fn engine(toml: &str) -> Engine {
    let cfg = parse_scene_section(toml)
        .expect("valid scene")
        .expect("has [dem]");
    Engine::from_config(&cfg, std::path::Path::new(".")).expect("engine builds")
}

/// A soft test grain (E = 10 MPa, ρ = 1000) as a `[dem.materials.grain]` table.
pub const GRAIN: &str = r#"
[dem.materials.grain]
youngs_modulus = 1e7
poisson_ratio = 0.3
density = 1000.0
restitution = 0.5
friction = 0.5
"#;

/// A wall material as soft as [`GRAIN`] (`[dem.materials.steel]`, ρ = 7800).
pub const STEEL: &str = r#"
[dem.materials.steel]
youngs_modulus = 1e7
poisson_ratio = 0.3
density = 7800.0
restitution = 0.5
friction = 0.5
"#;

/// The engine's result `key` (panics naming it when absent).
pub fn result(e: &Engine, key: &str) -> f64 {
    e.results()
        .into_iter()
        .find(|(k, _)| k == key)
        .unwrap_or_else(|| panic!("no result {key}"))
        .1
}

/// Position and velocity of the particle with identity `id`.
pub fn state_of(e: &Engine, id: u32) -> ([f64; 3], [f64; 3]) {
    let p = e.particles();
    let k = p.id.iter().position(|&i| i == id).expect("particle exists");
    let (x, v) = (p.position[k], p.velocity[k]);
    ([x.x, x.y, x.z], [v.x, v.y, v.z])
}

/// ∫_0^1 dx / √(1 − x^{5/2}) (Hertz contact duration integral), via x = 1 − u².
pub fn hertz_duration_integral() -> f64 {
    let n = 200_000;
    let f = |u: f64| {
        if u == 0.0 {
            2.0 / 2.5f64.sqrt()
        } else {
            2.0 * u / (1.0 - (1.0 - u * u).powf(2.5)).sqrt()
        }
    };
    let h = 1.0 / n as f64;
    let mut s = f(0.0) + f(1.0);
    for k in 1..n {
        s += f(k as f64 * h) * if k % 2 == 1 { 4.0 } else { 2.0 };
    }
    s * h / 3.0
}
