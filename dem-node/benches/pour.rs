//! Polydisperse pour (issue 25), the peer case of `bench/liggghts/pour.in`: the spheres of a
//! LIGGGHTS data file written by `bench/liggghts/pour_gen.py` (d uniform in [3, 5] mm, random
//! non-overlapping start up to 0.4 m, at rest) fall into a 0.1 × 0.1 m box open at the top and
//! settle; wheat material (A4), Hertz–Mindlin, Δt = 8e-6 s (0.28 of the smallest sphere's Rayleigh step), skin 0.5 mm (as LIGGGHTS'
//! `neighbor 0.0005 bin`). All steps are timed: unlike the dense bed, the case is the fall,
//! the impacts and the settling (frequent list rebuilds, a growing contact count).
//!
//! Both codes read the same file: this bench parses the data file's `Atoms` lines
//! (`id type diameter density x y z`) into the engine's `list` particle source (Rust's and
//! LIGGGHTS' number parsers both round correctly, so the two start from the same doubles).
//!
//! With POUR_GEOMETRY=hopper the same spheres (a start file from `pour_gen.py N seed 0.16
//! 0.45`) flow instead through the hopper of `bench/liggghts/hopper.in`: the STL of
//! `hopper_stl.py` (POUR_STL, default `hopper.stl` beside the data file: a 0.1 m square shaft
//! and a pyramidal funnel to a 30 mm outlet at z = 0.1 m) and a sink below z = 0, where
//! LIGGGHTS' domain ends; the discharged count is printed with the other answers.
//!
//! Environment: POUR_DATA (data file, default `pour.data` in the working folder), POUR_STEPS
//! (default 50000 = 0.4 s), POUR_THREADS (default: all), POUR_EVERY (steps between progress
//! lines, default 10000: time, KE, contacts, highest centre, like LIGGGHTS' thermo).

mod common;
use common::cpu_seconds;
use common::env;
use dem::config::{ParticleSource, SphereConfig};
use dem::{parse_scene_section, Engine};
use std::time::Instant;

/// The spheres of a LIGGGHTS data file's `Atoms` section (radius = half the diameter, exact
/// in binary) and their density (all must agree).
fn read_data(path: &str) -> Result<(Vec<SphereConfig>, f64), String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{path}: {e}"))?;
    let mut spheres = Vec::new();
    let mut density: Option<f64> = None;
    let mut in_atoms = false;
    for (i, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        if line == "Atoms" {
            in_atoms = true;
            continue;
        }
        if !in_atoms {
            continue;
        }
        let f: Vec<&str> = line.split_whitespace().collect();
        if f.len() < 7 {
            if f[0].chars().all(|c| c.is_ascii_alphabetic()) {
                break; // the next section (Velocities, ...)
            }
            return Err(format!(
                "{path}:{}: an Atoms line needs `id type diameter density x y z`",
                i + 1
            ));
        }
        let num = |k: usize, what: &str| {
            f[k].parse::<f64>()
                .map_err(|_| format!("{path}:{}: {what} `{}` is not a number", i + 1, f[k]))
        };
        let rho = num(3, "density")?;
        match density {
            None => density = Some(rho),
            Some(r0) if r0 != rho => {
                return Err(format!(
                    "{path}:{}: density {rho} differs from the first atom's {r0}",
                    i + 1
                ))
            }
            _ => {}
        }
        spheres.push(SphereConfig {
            position: [num(4, "x")?, num(5, "y")?, num(6, "z")?],
            radius: 0.5 * num(2, "diameter")?,
            velocity: [0.0; 3],
            angular_velocity: [0.0; 3],
            orientation: None,
        });
    }
    let density = density.ok_or_else(|| format!("{path}: no Atoms section"))?;
    Ok((spheres, density))
}

fn z_max(e: &Engine) -> f64 {
    e.particles()
        .position
        .iter()
        .map(|p| p.z)
        .fold(f64::NEG_INFINITY, f64::max)
}

/// Spheres removed by the sink (the hopper's discharge; 0 in the box).
fn discharged(e: &Engine) -> usize {
    e.results()
        .iter()
        .find(|(k, _)| k == "removed_particles")
        .map_or(0, |(_, v)| *v as usize)
}

fn main() {
    let data = std::env::var("POUR_DATA").unwrap_or_else(|_| "pour.data".into());
    let (spheres, density) = match read_data(&data) {
        Ok(r) => r,
        Err(e) => {
            eprintln!(
                "pour: {e} (write one with `python3 bench/liggghts/pour_gen.py > pour.data`)"
            );
            std::process::exit(2);
        }
    };
    let n_file = spheres.len();
    let hopper = match std::env::var("POUR_GEOMETRY").as_deref() {
        Err(_) | Ok("box") => false,
        Ok("hopper") => true,
        Ok(other) => {
            eprintln!("pour: POUR_GEOMETRY must be `box` or `hopper`, not `{other}`");
            std::process::exit(2);
        }
    };
    let walls = if hopper {
        let stl = std::env::var("POUR_STL")
            .map(std::path::PathBuf::from)
            .unwrap_or_else(|_| std::path::Path::new(&data).with_file_name("hopper.stl"));
        let stl = std::fs::canonicalize(&stl).unwrap_or_else(|e| {
            eprintln!(
                "pour: hopper STL {}: {e} (write one with `python3 bench/liggghts/hopper_stl.py > hopper.stl`)",
                stl.display()
            );
            std::process::exit(2);
        });
        format!(
            r#"
[[dem.walls]]
kind = "stl"
material = "wheat"
path = {:?}
[[dem.sinks]]
max = [1.0, 1.0, 0.0]
"#,
            stl.display().to_string()
        )
    } else {
        r#"
[[dem.walls]]
kind = "box"
material = "wheat"
min = [0.0, 0.0, 0.0]
max = [0.1, 0.1, 0.5]
open = ["+z"]
"#
        .to_string()
    };
    let scene = format!(
        r#"
[dem]
time_step = 8e-6
skin = 0.0005
gravity = [0.0, 0.0, -9.81]
[dem.materials.wheat]
youngs_modulus = 1e8
poisson_ratio = 0.3
density = {density:?}
restitution = 0.4
friction = 1.0
{walls}"#
    );
    let mut cfg = parse_scene_section(&scene)
        .expect("scene")
        .expect("dem table");
    cfg.particles.push(ParticleSource::List {
        material: "wheat".into(),
        spheres,
        shape: Default::default(),
    });
    let threads = env("POUR_THREADS", 0);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("pool");
    pool.install(|| {
        let mut e = Engine::from_config(&cfg, std::path::Path::new(".")).expect("engine");
        let n = e.num_particles();
        assert_eq!(n, n_file, "particles read");
        let steps = env("POUR_STEPS", 50_000);
        let every = env("POUR_EVERY", 10_000).max(1);
        println!(
            "pour: {n} particles from {data} into {}, {} threads, dt = {} s (Rayleigh {:.3e} s)",
            if hopper { "the hopper" } else { "the box" },
            rayon::current_num_threads(),
            e.time_step(),
            e.rayleigh_time_step()
        );
        let cpu0 = cpu_seconds();
        let t0 = Instant::now();
        let mut done = 0;
        while done < steps {
            let k = every.min(steps - done);
            e.advance(k).expect("advance");
            done += k;
            println!(
                "  step {done}: {:.1} s wall, KE {:.4e} J, contacts {}, wall contacts {}, highest centre {:.4} m, discharged {}",
                t0.elapsed().as_secs_f64(),
                e.kinetic_energy(),
                e.num_contacts(),
                e.num_wall_contacts(),
                z_max(&e),
                discharged(&e)
            );
        }
        let t = t0.elapsed().as_secs_f64();
        let cpu = cpu_seconds() - cpu0;
        println!(
            "timed {steps} steps: {t:.3} s wall, {:.3e} particle-steps/s, {:.1} ns per particle-step \
             ({:.1} CPU-ns); contacts {}, wall contacts {}, list builds {}, KE {:.3e} J, highest centre {:.4} m, \
             discharged {}",
            (n * steps) as f64 / t,
            t * 1e9 / (n * steps) as f64,
            cpu * 1e9 / (n * steps) as f64,
            e.num_contacts(),
            e.num_wall_contacts(),
            e.neighbour_list_builds(),
            e.kinetic_energy(),
            z_max(&e),
            discharged(&e)
        );
        println!(
            "state in memory {:.0} bytes/particle",
            e.memory_bytes() as f64 / n as f64
        );
    });
}
