//! REFERENCE D dense bed: 24,696 spheres d = 4 mm on a simple-cubic lattice (spacing 4.5 mm)
//! in a 0.1 × 0.1 × 0.26 m box open at the top, wheat material (A4), settled, then timed steps
//! of Δt = 1e-5 s. Prints particle-steps per second and bytes per particle, then a scaling run
//! at 1e3, 1e4, 1e5 particles.
//!
//! Environment: DENSE_BED_STEPS (default 10000), DENSE_BED_SETTLE (settling steps, default
//! 40000 = 0.4 s), DENSE_BED_SCALING_STEPS (default 1000), DENSE_BED_THREADS (default: all),
//! DENSE_BED_CACHE (file: the settled state is restored from it when it holds a snapshot of
//! this engine version, else written there after settling), DENSE_BED_SCALING_MAX (largest
//! scaling size exponent: 5 (default) runs 1e3, 1e4, 1e5; 6 adds 1e6; 0 skips the scaling),
//! DENSE_BED_SCALING_SPACING (lattice spacing of the scaling runs, default 0.004 m: resting),
//! DENSE_BED_JITTER (m, default 0: REFERENCE D's exact lattice): the dense bed's lattice sites
//! displaced at random by up to this much in x and y, as LIGGGHTS' `displace_atoms random`
//! in bench/liggghts/dense_bed.in; any jitter turns the lattice into a random packing.

mod common;
use common::cpu_seconds;
use common::env;
use dem::{parse_scene_section, Engine};
use std::time::Instant;

/// Lattice of `n` spheres (r = 2 mm) with `spacing`, the first centre at 4.25 mm from the
/// walls and at `z0` above the floor, in a box of at least 0.1 × 0.1 × 0.26 m.
fn scene(n: [usize; 3], spacing: f64, z0: f64, jitter: f64) -> String {
    let s = spacing;
    let (lx, ly, lz) = (
        0.1f64.max(n[0] as f64 * s + 0.0055),
        0.1f64.max(n[1] as f64 * s + 0.0055),
        0.26f64.max(n[2] as f64 * s + 0.01),
    );
    format!(
        r#"
[dem]
time_step = 1e-5
gravity = [0.0, 0.0, -9.81]
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
max = [{lx}, {ly}, {lz}]
open = ["+z"]
[[dem.particles]]
kind = "lattice"
material = "wheat"
radius = 0.002
first = [0.00425, 0.00425, {z0}]
spacing = {s}
count = [{}, {}, {}]
jitter = {jitter}
"#,
        n[0], n[1], n[2]
    )
}

fn build(n: [usize; 3], spacing: f64, z0: f64, jitter: f64) -> Engine {
    let cfg = parse_scene_section(&scene(n, spacing, z0, jitter))
        .expect("scene")
        .expect("dem table");
    Engine::from_config(&cfg, std::path::Path::new(".")).expect("engine")
}

fn timed(e: &mut Engine, steps: usize) -> f64 {
    let t = Instant::now();
    e.advance(steps).expect("advance");
    t.elapsed().as_secs_f64()
}

fn main() {
    let threads = env("DENSE_BED_THREADS", 0);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("pool");
    pool.install(|| {
        let steps = env("DENSE_BED_STEPS", 10_000);
        let settle = env("DENSE_BED_SETTLE", 40_000);
        let jitter: f64 = std::env::var("DENSE_BED_JITTER")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(0.0);
        let mut e = build([21, 21, 56], 0.0045, 0.00425, jitter);
        let n = e.num_particles();
        println!("dense bed: {n} particles, {} threads, dt = {} s (Rayleigh {:.3e} s), lattice jitter {jitter} m", rayon::current_num_threads(), e.time_step(), e.rayleigh_time_step());
        let cache = std::env::var("DENSE_BED_CACHE").ok();
        let cached = cache
            .as_ref()
            .and_then(|path| std::fs::read(path).ok())
            .is_some_and(|bytes| e.restore(&bytes).is_ok());
        if cached {
            println!("settled state restored from {}", cache.as_deref().unwrap_or(""));
        } else {
            let ts = timed(&mut e, settle);
            println!("settling {settle} steps ({:.2} s simulated): {ts:.2} s wall, KE = {:.3e} J", settle as f64 * 1e-5, e.kinetic_energy());
            if let Some(path) = &cache {
                std::fs::write(path, e.snapshot()).expect("write the settled-state cache");
            }
        }
        let builds0 = e.neighbour_list_builds();
        let cpu0 = cpu_seconds();
        let t = timed(&mut e, steps);
        let cpu = cpu_seconds() - cpu0;
        let snap = e.snapshot().len();
        println!(
            "timed {steps} steps: {t:.3} s wall, {:.3e} particle-steps/s, {:.1} ns per particle-step \
             ({:.1} CPU-ns); contacts {}, wall contacts {}, list builds {}, KE {:.3e} J",
            (n * steps) as f64 / t,
            t * 1e9 / (n * steps) as f64,
            cpu * 1e9 / (n * steps) as f64,
            e.num_contacts(),
            e.num_wall_contacts(),
            e.neighbour_list_builds() - builds0,
            e.kinetic_energy()
        );
        println!(
            "extrapolated to 10,000 steps: {:.2} s; state in memory {:.0} bytes/particle (particles, \
             neighbour lists, histories), snapshot {:.0} bytes/particle, core SoA {} bytes/particle",
            t * 10_000.0 / steps as f64,
            e.memory_bytes() as f64 / n as f64,
            snap as f64 / n as f64,
            dem::particles::Particles::bytes_per_particle()
        );
        for (k, r) in e.results() {
            println!("  {k} = {r:.6e}");
        }

        let scaling_steps = env("DENSE_BED_SCALING_STEPS", 1000);
        let sizes: &[[usize; 3]] = match env("DENSE_BED_SCALING_MAX", 5) {
            0 => &[],
            6 => &[[10, 10, 10], [21, 21, 23], [46, 46, 48], [100, 100, 100]],
            _ => &[[10, 10, 10], [21, 21, 23], [46, 46, 48]],
        };
        // default: a resting lattice (touching neighbours, bottom layer on the floor), which
        // gravity compresses into about one contact per particle, like the dense bed; 0.0045
        // gives the dense bed's lattice, which is still falling (no contacts, frequent rebuilds)
        let spacing: f64 = std::env::var("DENSE_BED_SCALING_SPACING")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(0.004);
        let z0 = if spacing <= 0.004 { 0.002 } else { 0.00425 };
        for &dims in sizes {
            let mut e = build(dims, spacing, z0, 0.0);
            e.advance(200).expect("advance");
            let n = e.num_particles();
            let cpu0 = cpu_seconds();
            let t = timed(&mut e, scaling_steps);
            let cpu = cpu_seconds() - cpu0;
            println!(
                "scaling: {n:>7} particles, {scaling_steps} steps: {t:.3} s, {:.3e} particle-steps/s, \
                 {:.1} ns per particle-step ({:.1} CPU-ns), {} contacts, {} wall contacts, \
                 {:.0} bytes/particle",
                (n * scaling_steps) as f64 / t,
                t * 1e9 / (n * scaling_steps) as f64,
                cpu * 1e9 / (n * scaling_steps) as f64,
                e.num_contacts(),
                e.num_wall_contacts(),
                e.memory_bytes() as f64 / n as f64
            );
        }
    });
}
