//! Static solve of the REFERENCE A3 / D beam (1000 × 100 × 100 mm, clamped ends, 5 kPa on top)
//! with 8-node hexes at 10 mm (36,663 dof) and 5 mm (265,923 dof): wall time of model build
//! (assembly) and solve, peak memory (VmHWM), and time per Bossak step at 10 mm.
//! CalculiX 2.20 reference on this machine: ~1.5 s and ~45 s (2.35 GB). Run with
//! `cargo bench -p fem-node --no-default-features --bench static_beam [-- 10]` (sizes in mm).
//! STATIC_BEAM_SOLVER = auto (default) | direct | mixed sets `[fem] solver` (auto: the f32
//! factor with f64 conjugate gradients from 100k equations, the f64 factor below).
//! With a scene file as argument (`-- bench/gmsh/bracket.toml`) it solves that scene's `[fem]`
//! section once instead (the unstructured tet10 peer case; compare.sh case tet10).
//! `RUST_LOG=fem=debug` adds the cost split: element matrices vs scatter, ordering fill
//! (nnz of L), symbolic vs numeric factorisation.

use std::path::Path;
use std::time::Instant;

fn vm_hwm_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| {
                l.split_whitespace()
                    .nth(1)
                    .and_then(|v| v.parse::<f64>().ok())
            })
        })
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

fn scene(h_mm: f64, dynamic: bool) -> String {
    let analysis = if dynamic {
        "[fem.analysis]\ntype = \"dynamic\"\nalpha_b = -0.1\n"
    } else {
        ""
    };
    let solver = std::env::var("STATIC_BEAM_SOLVER").unwrap_or_else(|_| "auto".into());
    format!(
        r#"
[fem]
solver = "{solver}"
mesh = {{ size = [1.0, 0.1, 0.1], element_size = {h}, element = "hex8" }}
[fem.material]
youngs_modulus = 210e9
poisson_ratio = 0.3
density = 7800.0
{analysis}
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
"#,
        h = h_mm / 1000.0
    )
}

/// Which factor the last static solve used.
fn solver_label(m: &fem::Model) -> String {
    match m.last_mixed_solve() {
        Some(s) => format!(
            "f32 factor + f64 CG, {} iterations, relative residual {:.1e}",
            s.iterations, s.relative_residual
        ),
        None => "f64 factor".into(),
    }
}

/// One static solve of the `[fem]` section of a scene file (its mesh path relative to the
/// file), timed like the beam: the unstructured peer cases (bench/gmsh/bracket.toml).
fn static_scene(path: &Path) {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    let cfg = fem::parse_scene_section(&text)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .unwrap_or_else(|| panic!("{}: no [fem] section", path.display()));
    let dir = path.parent().unwrap_or(Path::new("."));
    let t0 = Instant::now();
    let mut m = fem::Model::from_config(&cfg, dir).unwrap_or_else(|e| panic!("{e}"));
    let t_build = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    m.solve_static().unwrap_or_else(|e| panic!("{e}"));
    let t_solve = t1.elapsed().as_secs_f64();
    let solver = solver_label(&m);
    let probes: Vec<String> = cfg
        .probes
        .iter()
        .map(|p| {
            let u = m.probe_displacement(&p.name).unwrap();
            format!("{} u {:.7e} {:.7e} {:.7e} m", p.name, u[0], u[1], u[2])
        })
        .collect();
    println!(
        "static {}: {} dof, read+build+assembly {t_build:.3} s, factorise+solve {t_solve:.3} s, total {:.3} s, \
         {}, VmHWM {:.0} MB, solver: {solver}",
        path.display(),
        m.num_dofs(),
        t_build + t_solve,
        probes.join(", "),
        vm_hwm_mb()
    );
}

fn main() {
    if std::env::var_os("RUST_LOG").is_some() {
        tracing_subscriber::fmt()
            .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
            .with_writer(std::io::stderr)
            .init();
    }
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with('-'))
        .collect();
    if let Some(path) = args.iter().find(|a| a.ends_with(".toml")) {
        static_scene(Path::new(path));
        return;
    }
    let sizes: Vec<f64> = if args.is_empty() {
        vec![10.0, 5.0]
    } else {
        args.iter().filter_map(|a| a.parse().ok()).collect()
    };
    println!("threads: {}", rayon::current_num_threads());
    for &h in &sizes {
        let cfg = fem::parse_scene_section(&scene(h, false)).unwrap().unwrap();
        let t0 = Instant::now();
        let mut m = fem::Model::from_config(&cfg, Path::new(".")).unwrap();
        let t_build = t0.elapsed().as_secs_f64();
        let t1 = Instant::now();
        m.solve_static().unwrap();
        let t_solve = t1.elapsed().as_secs_f64();
        let t2 = Instant::now();
        m.solve_static().unwrap();
        let t_resolve = t2.elapsed().as_secs_f64();
        let solver = solver_label(&m);
        println!(
            "static hex8 {h} mm: {} dof, build+assembly {t_build:.3} s, factorise+solve {t_solve:.3} s, total {:.3} s, \
             re-solve with cached factor {t_resolve:.3} s, midspan uz {:.7e} m, VmHWM {:.0} MB, solver: {solver}",
            m.num_dofs(),
            t_build + t_solve,
            m.probe_displacement("midspan").unwrap()[2],
            vm_hwm_mb()
        );
    }
    // time per dynamic (Bossak) step at the coarsest requested size
    let h = sizes.iter().cloned().fold(0.0, f64::max);
    let cfg = fem::parse_scene_section(&scene(h, true)).unwrap().unwrap();
    let mut m = fem::Model::from_config(&cfg, Path::new(".")).unwrap();
    let t0 = Instant::now();
    m.advance(1e-4).unwrap(); // initial acceleration + factorisation of the effective matrix
    let t_first = t0.elapsed().as_secs_f64();
    let steps = 20;
    let t1 = Instant::now();
    for _ in 0..steps {
        m.advance(1e-4).unwrap();
    }
    let per = t1.elapsed().as_secs_f64() / steps as f64;
    println!(
        "dynamic Bossak hex8 {h} mm: first step (M and effective-matrix factorisations) {t_first:.3} s, then {:.2} ms per step",
        per * 1e3
    );
}
