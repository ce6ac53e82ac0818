//! What impact refinement costs on a dense packing: a settled lattice bed (the REFERENCE D
//! scene, reduced to 21 × 21 × 12 spheres) stepped with and without `impact_substeps`;
//! prints the fraction of refined steps and the time ratio.
//!
//! ```text
//! cargo run --release -p dem-node --example impact_refinement_cost -- [N] [STEPS]
//! ```

use std::time::Instant;

fn scene(impact_substeps: usize) -> String {
    format!(
        r#"[dem]
time_step = 1e-5
impact_substeps = {impact_substeps}
[dem.materials.wheat]
youngs_modulus = 1e8
poisson_ratio = 0.3
density = 1242.0
restitution = 0.4
friction = 1.0
[[dem.walls]]
kind = "box"
material = "wheat"
min = [0.0, 0.0, 0.0]
max = [0.1, 0.1, 0.26]
open = ["+z"]
[[dem.particles]]
kind = "lattice"
material = "wheat"
radius = 0.002
first = [0.00425, 0.00425, 0.00425]
spacing = 0.0045
count = [21, 21, 12]
"#
    )
}

fn engine(n: usize) -> dem::Engine {
    let cfg = dem::parse_scene_section(&scene(n))
        .expect("scene")
        .expect("[dem]");
    dem::Engine::from_config(&cfg, std::path::Path::new(".")).expect("engine")
}

fn main() {
    let arg = |k: usize, d: usize| {
        std::env::args()
            .nth(k)
            .and_then(|v| v.parse().ok())
            .unwrap_or(d)
    };
    let (n, steps) = (arg(1, 16), arg(2, 1000));
    let mut plain = engine(1);
    // falls 2.25 mm onto the floor, then settles
    plain.advance(20_000).expect("settles");
    let snap = plain.snapshot();
    println!(
        "{} particles, {} contacts, {} wall contacts after settling 0.2 s",
        plain.num_particles(),
        plain.num_contacts(),
        plain.num_wall_contacts()
    );
    let t = Instant::now();
    plain.advance(steps).expect("runs");
    let t_plain = t.elapsed().as_secs_f64();
    let mut refined = engine(n);
    refined.restore(&snap).expect("restores");
    let t = Instant::now();
    refined.advance(steps).expect("runs");
    let t_ref = t.elapsed().as_secs_f64();
    println!(
        "{steps} steps: plain {t_plain:.3} s, impact_substeps = {n}: {t_ref:.3} s ({:.1}x); refined steps {} of {steps} ({:.1} %)",
        t_ref / t_plain,
        refined.refined_steps(),
        100.0 * refined.refined_steps() as f64 / steps as f64
    );
}
