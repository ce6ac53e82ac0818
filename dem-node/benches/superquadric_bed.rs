//! Cost of superquadric DEM (issue 16; REFERENCE B4: Wellmann's code ≈ 20 core-µs per
//! particle-step).
//!
//! 1. Contact detection accuracy and cost with Wellmann's validation protocol (Table 3.1),
//!    SQ_PROTOCOL_PAIRS pairs per angularity class (default 1e6).
//! 2. A dense bed of Wellmann's sand (SEED-SPEC §3.4: semi-axes Gaussian 0.57 / 0.395 /
//!    0.305 mm ± 20 %, truncated to 0.25–0.75 mm, ε uniform in [0.6, 1.2]), SQ_BED_COUNT
//!    grains (default 5,000) thrown down (0.5 m/s) into a square plane box and settled under
//!    gravity, then
//!    SQ_BED_STEPS timed steps (default 2000): core-µs per particle-step, and the share of the
//!    exact narrow phase (every listed pair's detection on the exact surfaces, timed on its own
//!    on the settled state: what a step would pay without the linearised surfaces of tracked
//!    pairs, `Linearised`, which the engine evaluates instead while the normals stay in reach).
//!    The material is softened (E = 10 MPa instead of 50 GPa, Δt = 4 µs: the cost per step does not
//!    depend on it, the number of steps to settle does). SQ_BED_WARMUP (untimed steps before
//!    the timed ones, default 100), SQ_BED_THREADS (default: all),
//!    SQ_BED_SETTLE (settling steps, default 40,000 = 0.16 s), SQ_BED_CACHE (file: the settled
//!    state is restored from it when it holds a snapshot of this engine version, else written
//!    there after settling; one file per SQ_BED_COUNT), SQ_BED_NARROW (0: skip the narrow-phase
//!    timing).

mod common;
use common::env;
use dem::hertz_mindlin::V3;
use dem::narrow::superquadric::{detect, detect_tracked, SearchSettings, SearchStats, SqBody};
use dem::{parse_scene_section, Engine};
use std::time::Instant;

fn protocol(pairs: u64) {
    println!("contact detection, Wellmann's protocol, {pairs} pairs per class and test");
    let table = [
        (2.34e-6, 4.34e-8, 4.21e-3),
        (2.40e-6, 4.40e-8, 5.05e-3),
        (32.1e-6, 37.2e-8, 18.2e-3),
    ];
    for class in 1..=3 {
        let t = Instant::now();
        let st = dem::narrow::protocol::run(class, pairs, 2011, &SearchSettings::default());
        let secs = t.elapsed().as_secs_f64();
        let (de, pe, ae) = table[class as usize - 1];
        println!(
            "  class {class}: δ error {:.2e} (W {de:.2e}), point error {:.2e} (W {pe:.2e}), \
             angle {:.2e}° (W {ae:.2e}°), max δ error {:.2e}",
            st.mean_overlap_error, st.mean_point_error, st.mean_angle_deg, st.max_overlap_error
        );
        println!(
            "           wrong answers {} + {} (separated), ≥20 iterations {:.3} %, local minima \
             {} + not converged {} per {pairs}, most restarts {}, mean iterations {:.2}; \
             separated: excluded at start {:.1} %, ≥5 iterations {:.3} %; {:.2} µs per pair",
            st.wrong,
            st.separation_wrong,
            100.0 * st.at_least_20_iterations as f64 / pairs as f64,
            st.local_minima,
            st.not_converged,
            st.max_restarts,
            st.mean_iterations,
            100.0 * st.excluded_at_start as f64 / pairs as f64,
            100.0 * st.separation_at_least_5 as f64 / pairs as f64,
            secs * 1e6 / (2 * pairs) as f64
        );
    }
}

fn sand_scene(count: usize, side: f64, threads: Option<usize>) -> String {
    let axis = |mean: f64| {
        format!(
            "{{ kind = \"normal\", mean = {:e}, std_dev = {:e}, min = 0.25e-3, max = 0.75e-3 }}",
            mean * 1e-3,
            0.2 * mean * 1e-3
        )
    };
    let t = threads
        .map(|n| format!("threads = {n}\n"))
        .unwrap_or_default();
    // a loose fill (solid fraction ≈ 0.15) of the box up to `height`
    let volume = count as f64 * 0.335e-9;
    let height = volume / 0.15 / (side * side);
    let wall = |point: [f64; 3], normal: [f64; 3]| {
        format!(
            "[[dem.walls]]\nkind = \"plane\"\nmaterial = \"sand\"\npoint = {point:?}\nnormal = {normal:?}\n"
        )
    };
    format!(
        r#"
[dem]
time_step = 4e-6
{t}
[dem.materials.sand]
youngs_modulus = 1e7
poisson_ratio = 0.2
density = 2650.0
restitution = 0.3
friction = 0.24
{}{}{}{}{}
[[dem.particles]]
kind = "fill"
material = "sand"
min = [0.0, 0.0, 0.0]
max = [{side}, {side}, {height}]
count = {count}
seed = 5
velocity = [0.0, 0.0, -0.5]
shape = {{ kind = "superquadric", semi_axes = [{}, {}, {}], exponent_range = [0.6, 1.2] }}
"#,
        wall([0.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
        wall([0.0, 0.0, 0.0], [1.0, 0.0, 0.0]),
        wall([side, 0.0, 0.0], [-1.0, 0.0, 0.0]),
        wall([0.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
        wall([0.0, side, 0.0], [0.0, -1.0, 0.0]),
        axis(0.57),
        axis(0.395),
        axis(0.305)
    )
}

fn bed(count: usize) {
    let threads = std::env::var("SQ_BED_THREADS")
        .ok()
        .and_then(|v| v.parse().ok());
    let cores = threads.unwrap_or_else(rayon::current_num_threads);
    let steps = env("SQ_BED_STEPS", 2000);
    let settle = env("SQ_BED_SETTLE", 40_000);
    // box side for a bed ~ as deep as wide
    let side = (count as f64 * 0.335e-9 / 0.6).cbrt();
    let cfg = parse_scene_section(&sand_scene(count, side, threads))
        .expect("scene")
        .expect("[dem]");
    let mut e = Engine::from_config(&cfg, std::path::Path::new(".")).expect("engine");
    println!(
        "\nsand bed: {} superquadrics in a {:.1} mm box, Δt = {:e} s, {cores} threads",
        e.num_particles(),
        side * 1e3,
        e.time_step()
    );
    let t = Instant::now();
    let cache = std::env::var("SQ_BED_CACHE").ok();
    let n0 = e.num_particles();
    let cached = cache
        .as_ref()
        .and_then(|path| std::fs::read(path).ok())
        .is_some_and(|bytes| e.restore(&bytes).is_ok());
    if cached {
        assert_eq!(
            e.num_particles(),
            n0,
            "SQ_BED_CACHE holds a bed of another size: one file per SQ_BED_COUNT"
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
    println!(
        "  settled {settle} steps in {:.1} s: kinetic energy {:.3e} J, {} contacts, {} wall \
         contacts, packing fraction {}",
        t.elapsed().as_secs_f64(),
        e.kinetic_energy(),
        e.num_contacts(),
        e.num_wall_contacts(),
        packing(&e, side)
    );
    // untimed steps first: a restored state (or one written by an older build) starts its
    // tracked pairs without linearised surfaces
    e.advance(env("SQ_BED_WARMUP", 100)).expect("warm-up steps");
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
    if env("SQ_BED_NARROW", 1) == 0 {
        return;
    }
    // the narrow phase alone: every listed pair, warm-started as in the step
    let p = e.particles();
    let idx: std::collections::HashMap<u32, usize> =
        p.id.iter().enumerate().map(|(k, &i)| (i, k)).collect();
    let mut jobs = Vec::new();
    for (ids, c) in e.shaped_pair_contacts() {
        jobs.push((
            idx[&ids[0]],
            idx[&ids[1]],
            c.normal,
            c.touching().then_some(c.overlap),
        ));
    }
    let body = |k: usize| {
        let s = p
            .template(k)
            .expect("superquadric")
            .superquadric()
            .copied()
            .unwrap();
        (
            s,
            p.position[k],
            p.orientation[k].to_rotation_matrix().into_inner(),
        )
    };
    let bodies: Vec<_> = (0..p.len()).map(body).collect();
    let rounds = 5;
    let t = Instant::now();
    let mut iterations = 0u64;
    for _ in 0..rounds {
        for &(a, b, guess, tracked) in &jobs {
            let mk = |k: usize| SqBody {
                shape: &bodies[k].0,
                position: bodies[k].1,
                rotation: bodies[k].2,
            };
            let mut st = SearchStats::default();
            let settings = SearchSettings::default();
            // as the engine does: the temporal-coherence update for pairs that touched
            std::hint::black_box(match tracked {
                Some(overlap) => detect_tracked(&mk(a), &mk(b), guess, overlap, &settings, &mut st),
                None => {
                    let g = (guess != V3::zeros()).then_some(guess);
                    detect(&mk(a), &mk(b), g, &settings, &mut st)
                }
            });
            iterations += st.iterations as u64;
        }
    }
    let narrow = t.elapsed().as_secs_f64() / rounds as f64;
    let step_serial = per * 1e-6 * e.num_particles() as f64; // core-seconds per step
    println!(
        "  exact narrow phase: {} listed pairs, {:.3} µs per pair ({:.2} iterations), {:.1} % \
         of a step's core time",
        jobs.len(),
        narrow * 1e6 / jobs.len().max(1) as f64,
        iterations as f64 / (rounds * jobs.len().max(1)) as f64,
        100.0 * narrow / step_serial
    );
}

fn packing(e: &Engine, side: f64) -> String {
    let p = e.particles();
    let top = (0..p.len()).map(|k| p.position[k].z).fold(0.0f64, f64::max);
    let vol: f64 = (0..p.len())
        .map(|k| {
            p.template(k)
                .map_or(0.0, |t| t.superquadric().unwrap().volume())
        })
        .sum();
    // below the highest centre, a little under the bed's true fraction
    format!(
        "{:.3} (below the highest centre)",
        vol / (side * side * top)
    )
}

fn main() {
    let pairs = env("SQ_PROTOCOL_PAIRS", 1_000_000) as u64;
    if pairs > 0 {
        protocol(pairs);
    }
    let count = env("SQ_BED_COUNT", 5_000);
    if count > 0 {
        bed(count);
    }
}
