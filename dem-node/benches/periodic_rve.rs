//! Cost of Wellmann's periodic RVE (issue 22, W ch. 5; his L = 30 mm test took 132 h on 4
//! cores): the scene's grains through its programme up to the stage RVE_STAGE (default the
//! last, the shear), then RVE_STEPS timed steps (default 2000) in it: core-µs per
//! particle-step (wall × threads, and the process's CPU time, steadier on a shared machine),
//! list builds and contacts, and from the axial strain those steps made, the steps and the
//! wall time the whole stage takes at this cost.
//!
//! RVE_SCENE (default ../scenes/rve-triaxial.toml, the L = 10 mm cell of 1,642 superquadrics),
//! RVE_CACHE (file: the state at the start of the stage is restored from it when it holds a
//! snapshot of this engine with the scene's particle count at that stage, else written there — the first run pays the
//! generation, minutes for the L = 10 mm cell), RVE_THREADS (default: the scene's, else all), RVE_WARMUP
//! (untimed steps in the stage first, default 200).
//!
//! `cargo bench -p dem-node --bench periodic_rve`

mod common;
use common::{cpu_seconds, env};
use dem::{parse_scene_section, Engine};
use std::time::Instant;

fn main() {
    let path = std::env::var("RVE_SCENE").unwrap_or_else(|_| "../scenes/rve-triaxial.toml".into());
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("RVE_SCENE {path}: {e} (run from dem-node/ or set RVE_SCENE)"));
    let parse = |text: &str| {
        parse_scene_section(text)
            .unwrap_or_else(|e| panic!("{path}: {e}"))
            .unwrap_or_else(|| panic!("{path}: no [dem] section"))
    };
    let mut cfg = parse(&text);
    if let Ok(n) = std::env::var("RVE_THREADS") {
        cfg.threads = Some(n.parse().expect("RVE_THREADS: a number of threads"));
    }
    let cores = cfg.threads.unwrap_or_else(rayon::current_num_threads);
    let base = std::path::Path::new(&path)
        .parent()
        .unwrap_or(std::path::Path::new("."));
    let engine = || Engine::from_config(&cfg, base).expect("engine");
    let mut e = engine();
    let stages = cfg.periodic.as_ref().map_or(0, |p| p.stages.len());
    assert!(stages > 0, "{path}: no [[dem.periodic.stages]] programme");
    let stage = env("RVE_STAGE", stages - 1);
    assert!(
        stage < stages,
        "RVE_STAGE {stage}: the programme has {stages} stages"
    );
    println!(
        "{path}: {} particles, Δt = {:e} s, {cores} threads; timing stage {stage} of {stages}",
        e.num_particles(),
        e.time_step()
    );
    let cache = std::env::var("RVE_CACHE").ok();
    // a cache of another scene or stage (the engine checks only the snapshot's structure) is
    // not used: generated again and overwritten
    let n0 = e.num_particles();
    let restored = cache
        .as_ref()
        .and_then(|p| std::fs::read(p).ok())
        .is_some_and(|bytes| e.restore(&bytes).is_ok())
        && e.num_particles() == n0
        && e.cell().is_some_and(|c| c.stage == stage);
    if !restored {
        e = engine();
    }
    if restored {
        println!(
            "  state at the stage's start restored from {}",
            cache.as_deref().unwrap_or("")
        );
    } else {
        let (t, c) = (Instant::now(), cpu_seconds());
        let mut steps = 0usize;
        // in steps of 100: the timing starts at most 99 + RVE_WARMUP steps into the stage
        while e.cell().expect("a periodic cell").stage < stage {
            e.advance(100).expect("generation");
            steps += 100;
            assert!(
                !e.programme_finished(),
                "the programme ended before stage {stage}"
            );
        }
        println!(
            "  generation to stage {stage}: {steps} steps in {:.1} s ({:.1} CPU s)",
            t.elapsed().as_secs_f64(),
            cpu_seconds() - c
        );
        if let Some(p) = &cache {
            std::fs::write(p, e.snapshot()).expect("write RVE_CACHE");
        }
    }
    e.advance(env("RVE_WARMUP", 200)).expect("warm-up steps");
    let steps = env("RVE_STEPS", 2000);
    let cell = e.cell().unwrap();
    let (l0, z0) = (cell.stage_size0.z, cell.size.z);
    let builds = e.neighbour_list_builds();
    let (t, c) = (Instant::now(), cpu_seconds());
    e.advance(steps).expect("timed steps");
    let (secs, cpu) = (t.elapsed().as_secs_f64(), cpu_seconds() - c);
    let n = (e.num_particles() * steps) as f64;
    println!(
        "  {steps} steps: {secs:.2} s = {:.3} core-µs per particle-step (CPU time {:.3}); {} list \
         builds, {} contacts",
        secs * cores as f64 * 1e6 / n,
        cpu * 1e6 / n,
        e.neighbour_list_builds() - builds,
        e.num_contacts()
    );
    let cell = e.cell().unwrap();
    let strain_per_step = (z0 - cell.size.z).abs() / l0 / steps as f64;
    if let Some(target) = cfg
        .periodic
        .as_ref()
        .and_then(|p| p.stages[stage].strain.get(2))
    {
        if strain_per_step > 0.0 {
            let total = target.abs() / strain_per_step;
            println!(
                "  the stage's {:.0} % axial strain at this rate: {total:.3e} steps, {:.0} s wall at \
                 this cost",
                100.0 * target.abs(),
                total * secs / steps as f64
            );
        }
    }
}
