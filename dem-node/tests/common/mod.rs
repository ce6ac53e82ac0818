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

/// A 2-D disc engine (`model = "discs-2d"`) of a scene text; files relative to `base`.
pub fn disc_engine(text: &str, base: &std::path::Path) -> dem::discs::DiscEngine {
    let cfg = dem::discs::parse_scene_table(text, "dem")
        .unwrap_or_else(|e| panic!("{e}"))
        .expect("[dem]");
    dem::discs::DiscEngine::from_config(&cfg, base).unwrap_or_else(|e| panic!("{e}"))
}

/// The value of `name` in a list of results or limits.
pub fn value(list: &[(String, f64)], name: &str) -> f64 {
    list.iter()
        .find(|(k, _)| k == name)
        .unwrap_or_else(|| panic!("no {name}"))
        .1
}

/// A rigid plate of a disc scene touching the sample at t = 0, moving into it at `speed`
/// along its `normal`.
pub fn disc_plate(name: &str, normal: [f64; 2], speed: f64) -> String {
    format!(
        "[[dem.walls]]\nname = \"{name}\"\npoint = [{}, {}]\nnormal = [{}, {}]\nvelocity = [{}, {}]\ntouch = true\n",
        -normal[0],
        -normal[1],
        normal[0],
        normal[1],
        speed * normal[0],
        speed * normal[1]
    )
}
