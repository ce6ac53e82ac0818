//! Cost of dilated-polyhedron DEM (issue 20: target ≤ 1 core-µs per particle-step; Ullrich's
//! Table 6.2: Demify on a V100 + 8 cores, 83,000 polyhedra, 25 min for the coupled run).
//!
//! A bed of Ullrich's ballast (SEED-SPEC §6.3: size normal 40 mm ± 10 mm, truncated to
//! [20, 80] mm; random convex stones of PB_TRIANGLES core triangles (default 30), dilation
//! 10 %; μ = 0.6, e = 0.2), PB_COUNT stones (default 5,000) dropped into a plane box and
//! settled under gravity, then PB_STEPS timed steps (default 1000): core-µs per
//! particle-step, and the share of the narrow phase (timed on its own on the settled state:
//! parry's GJK on every listed pair; on the touching pairs GJK against the engine's path —
//! the closest-feature tracker, GJK where it declines — with the fraction the tracker
//! answers). The stones are softened (E = 300 MPa instead of 10 GPa,
//! Δt = 30 µs: the cost per step does not depend on it, the number of steps to settle does;
//! the cores still do not meet below 11 m/s). PB_THREADS (default: all), PB_SETTLE (settling
//! steps, default 40,000 = 1.2 s), PB_CACHE (file: the settled state is restored from it when
//! it holds a snapshot of this engine version and size, else written there after settling),
//! PB_NARROW (0: skip the narrow-phase timing).

mod common;
use common::env;
use dem::narrow::polyhedron::{detect_pair_warm, track_pair, Core, PolyBody, Simplex};
use dem::{parse_scene_section, Engine};
use std::time::Instant;

fn ballast_scene(count: usize, side: f64, triangles: usize, threads: Option<usize>) -> String {
    let t = threads
        .map(|n| format!("threads = {n}\n"))
        .unwrap_or_default();
    // a loose fill (solid fraction ≈ 0.15) up to `height`
    let volume = count as f64 * std::f64::consts::PI / 6.0 * 0.042f64.powi(3);
    let height = volume / 0.15 / (side * side);
    let wall = |point: [f64; 3], normal: [f64; 3]| {
        format!(
            "[[dem.walls]]\nkind = \"plane\"\nmaterial = \"ballast\"\npoint = {point:?}\nnormal = {normal:?}\n"
        )
    };
    format!(
        r#"
[dem]
time_step = 3e-5
{t}
[dem.materials.ballast]
youngs_modulus = 3e8
poisson_ratio = 0.27
density = 2600.0
restitution = 0.2
friction = 0.6
{}{}{}{}{}
[[dem.particles]]
kind = "fill"
material = "ballast"
min = [0.0, 0.0, 0.0]
max = [{side}, {side}, {height}]
count = {count}
seed = 5
distribution = {{ kind = "normal", mean = 0.02, std_dev = 0.005, min = 0.01, max = 0.04 }}
shape = {{ kind = "polyhedron", triangles = {triangles}, dilation = 0.1, stones = 100 }}
"#,
        wall([0.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
        wall([0.0, 0.0, 0.0], [1.0, 0.0, 0.0]),
        wall([side, 0.0, 0.0], [-1.0, 0.0, 0.0]),
        wall([0.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
        wall([0.0, side, 0.0], [0.0, -1.0, 0.0]),
    )
}

fn main() {
    let count = env("PB_COUNT", 5000);
    let triangles = env("PB_TRIANGLES", 30);
    let threads = std::env::var("PB_THREADS")
        .ok()
        .and_then(|v| v.parse().ok());
    let cores = threads.unwrap_or_else(rayon::current_num_threads);
    let steps = env("PB_STEPS", 1000);
    let settle = env("PB_SETTLE", 40_000);
    // a bed about as deep as wide at a packing fraction of 0.6
    let side = (count as f64 * std::f64::consts::PI / 6.0 * 0.042f64.powi(3) / 0.6).cbrt();
    let cfg = parse_scene_section(&ballast_scene(count, side, triangles, threads))
        .expect("scene")
        .expect("[dem]");
    let mut e = Engine::from_config(&cfg, std::path::Path::new(".")).expect("engine");
    println!(
        "ballast bed: {} stones of {triangles} triangles in a {:.2} m box, Δt = {:e} s, {cores} \
         threads",
        e.num_particles(),
        side,
        e.time_step()
    );
    let t = Instant::now();
    let cache = std::env::var("PB_CACHE").ok();
    let n0 = e.num_particles();
    let cached = cache
        .as_ref()
        .and_then(|path| std::fs::read(path).ok())
        .is_some_and(|bytes| e.restore(&bytes).is_ok());
    if cached {
        assert_eq!(
            e.num_particles(),
            n0,
            "PB_CACHE holds a bed of another size"
        );
        println!(
            "  settled state restored from {}",
            cache.as_deref().unwrap_or("")
        );
    } else {
        e.advance(settle).expect("settling");
        if let Some(path) = &cache {
            std::fs::write(path, e.snapshot()).expect("write the settled-state cache");
        }
    }
    let p = e.particles();
    let top = (0..p.len()).map(|k| p.position[k].z).fold(0.0f64, f64::max);
    let vol: f64 = (0..p.len()).map(|k| p.volume(k)).sum();
    println!(
        "  settled {settle} steps in {:.1} s: kinetic energy {:.3e} J, {} contacts, {} wall \
         contacts, packing fraction {:.3} (below the highest centre)",
        t.elapsed().as_secs_f64(),
        e.kinetic_energy(),
        e.num_contacts(),
        e.num_wall_contacts(),
        vol / (side * side * top)
    );
    let builds0 = e.neighbour_list_builds();
    let t = Instant::now();
    e.advance(steps).expect("timed steps");
    let secs = t.elapsed().as_secs_f64();
    let per = secs * cores as f64 * 1e6 / (e.num_particles() * steps) as f64;
    println!(
        "  {steps} timed steps: {secs:.2} s = {per:.3} core-µs per particle-step ({} list \
         builds), {} contacts",
        e.neighbour_list_builds() - builds0,
        e.num_contacts()
    );
    if env("PB_NARROW", 1) == 0 {
        return;
    }
    // the narrow phase alone: every listed pair, warm-started from its last normal and simplex
    let p = e.particles();
    let idx: std::collections::HashMap<u32, usize> =
        p.id.iter().enumerate().map(|(k, &i)| (i, k)).collect();
    let jobs: Vec<(usize, usize, dem::hertz_mindlin::V3, Simplex)> = e
        .shaped_pair_contacts()
        .map(|(ids, c)| (idx[&ids[0]], idx[&ids[1]], c.normal, c.simplex))
        .collect();
    let body = |k: usize| {
        let (s, scale) = p.polyhedron(k).expect("a stone");
        PolyBody {
            core: Core::Points {
                vertices: &s.vertices,
                scale,
            },
            dilation: s.dilation * scale,
            position: p.position[k],
            orientation: p.orientation[k],
        }
    };
    let rounds = 5;
    let t = Instant::now();
    for _ in 0..rounds {
        for (a, b, warm, simplex) in &jobs {
            let w = (*warm != dem::hertz_mindlin::V3::zeros()).then_some(*warm);
            std::hint::black_box(detect_pair_warm(&body(*a), &body(*b), w, simplex));
        }
    }
    let narrow = t.elapsed().as_secs_f64() / rounds as f64;
    let step_serial = per * 1e-6 * e.num_particles() as f64; // core-seconds per step
    println!(
        "  narrow phase, GJK on every listed pair: {} listed pairs, {:.3} µs per pair, {:.1} % of \
         a step's core time (without the separated pairs the step skips)",
        jobs.len(),
        narrow * 1e6 / jobs.len().max(1) as f64,
        100.0 * narrow / step_serial
    );
    // the engine's path on the touching pairs (most separated ones skip the narrow phase on
    // their proof of separation): the closest-feature tracker, GJK where it declines
    let jobs: Vec<_> = e
        .shaped_pair_contacts()
        .filter(|(_, c)| c.touching())
        .map(|(ids, c)| (idx[&ids[0]], idx[&ids[1]], c.normal, c.simplex))
        .collect();
    let gjk = {
        let t = Instant::now();
        for _ in 0..rounds {
            for (a, b, warm, simplex) in &jobs {
                let w = (*warm != dem::hertz_mindlin::V3::zeros()).then_some(*warm);
                std::hint::black_box(detect_pair_warm(&body(*a), &body(*b), w, simplex));
            }
        }
        t.elapsed().as_secs_f64() / rounds as f64
    };
    let rotation = |k: usize| p.orientation[k].to_rotation_matrix().into_inner();
    let graph = |k: usize| p.polyhedron(k).map(|(s, _)| &s.adjacency);
    let tracked = jobs
        .iter()
        .filter(|(a, b, _, simplex)| {
            track_pair(
                &body(*a),
                &body(*b),
                &rotation(*a),
                &rotation(*b),
                simplex,
                [graph(*a), graph(*b)],
            )
            .is_some()
        })
        .count();
    let t = Instant::now();
    for _ in 0..rounds {
        for (a, b, warm, simplex) in &jobs {
            let (ba, bb) = (body(*a), body(*b));
            let found = track_pair(
                &ba,
                &bb,
                &rotation(*a),
                &rotation(*b),
                simplex,
                [graph(*a), graph(*b)],
            )
            .unwrap_or_else(|| {
                let w = (*warm != dem::hertz_mindlin::V3::zeros()).then_some(*warm);
                detect_pair_warm(&ba, &bb, w, simplex)
            });
            std::hint::black_box(found);
        }
    }
    let engine_path = t.elapsed().as_secs_f64() / rounds as f64;
    let per_pair = |secs: f64| secs * 1e6 / jobs.len().max(1) as f64;
    println!(
        "  touching pairs ({}): GJK warm-started {:.3} µs per pair ({:.1} % of a step's core \
         time); tracker first {:.3} µs per pair ({:.1} %; rotation matrices included), the \
         tracker answering {:.1} % of them",
        jobs.len(),
        per_pair(gjk),
        100.0 * gjk / step_serial,
        per_pair(engine_path),
        100.0 * engine_path / step_serial,
        100.0 * tracked as f64 / jobs.len().max(1) as f64,
    );
}
