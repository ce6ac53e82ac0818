//! Cost of the nonlinear path (issue 17): on the REFERENCE A3 beam with hex8 at 10 mm
//! (36,663 dof), a static solve and Bossak steps with Neo-Hooke (small loads: the answer is
//! the linear one) against the linear elastic material (cached factor); Newton iterations per
//! increment; and the wall time of the plastic strip footing (Tresca clay, hex8b) at h = 0.5,
//! 0.25 and 0.125 m with its collapse pressure against Prandtl's (2 + π) c.
//! Run with `cargo bench -p fem-node --no-default-features --bench nonlinear [-- 10]` (beam
//! element size in mm).

#[path = "../tests/common/footing.rs"]
mod footing;

use std::path::Path;
use std::time::Instant;

fn beam(h_mm: f64, material: &str, dynamic: bool) -> String {
    let analysis = if dynamic {
        "[fem.analysis]\ntype = \"dynamic\"\nalpha_b = -0.1\n"
    } else {
        ""
    };
    format!(
        "[fem]\nmesh = {{ size = [1.0, 0.1, 0.1], element_size = {h}, element = \"hex8\" }}\n\
         {material}\n{analysis}\
         [[fem.supports]]\non = {{ set = \"xmin\" }}\n[[fem.supports]]\non = {{ set = \"xmax\" }}\n\
         [[fem.loads]]\ntype = \"pressure\"\non = {{ set = \"zmax\" }}\nvalue = 5000.0\n\
         [[fem.probes]]\nname = \"midspan\"\npoint = [0.5, 0.05, 0.05]\n",
        h = h_mm / 1000.0
    )
}

const LINEAR: &str =
    "[fem.material]\nyoungs_modulus = 210e9\npoisson_ratio = 0.3\ndensity = 7800.0";
const NEO_HOOKE: &str = "[fem.materials.steel]\nmodel = \"neo_hooke\"\nyoungs_modulus = 210e9\n\
                         poisson_ratio = 0.3\ndensity = 7800.0\n\
                         [[fem.sections]]\nelements = \"all\"\nmaterial = \"steel\"";

fn build(text: &str) -> fem::Model {
    let cfg = fem::parse_scene_section(text).unwrap().unwrap();
    fem::Model::from_config(&cfg, Path::new(".")).unwrap()
}

fn main() {
    if std::env::var_os("RUST_LOG").is_some() {
        tracing_subscriber::fmt()
            .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
            .with_writer(std::io::stderr)
            .init();
    }
    let args: Vec<f64> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let h = args.first().copied().unwrap_or(10.0);
    println!("threads: {}", rayon::current_num_threads());
    let mut static_times = Vec::new();
    let modified = format!("{NEO_HOOKE}\n[fem.newton]\ntangent = \"modified\"");
    for (name, material) in [
        ("linear", LINEAR),
        ("neo-Hooke", NEO_HOOKE),
        ("neo-Hooke, modified Newton", modified.as_str()),
    ] {
        let t0 = Instant::now();
        let mut m = build(&beam(h, material, false));
        let t_build = t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        m.solve_static().unwrap();
        let t_solve = t0.elapsed().as_secs_f64();
        let its: Vec<usize> = m
            .last_newton_residuals()
            .iter()
            .map(|r| r.len() - 1)
            .collect();
        println!(
            "beam {h} mm, {name}: {} dof, build {t_build:.2} s, static solve {t_solve:.2} s, \
             midspan w = {:.6e} m, Newton iterations per increment {its:?}",
            m.num_dofs(),
            m.probe_displacement("midspan").unwrap()[2]
        );
        static_times.push(t_solve);
        // Bossak steps
        let mut d = build(&beam(h, material, true));
        d.advance(1e-5).unwrap();
        let t0 = Instant::now();
        let steps = 5;
        for _ in 0..steps {
            d.advance(1e-5).unwrap();
        }
        let per = t0.elapsed().as_secs_f64() / steps as f64;
        let its: usize = d.last_newton_residuals().iter().map(|r| r.len() - 1).sum();
        println!("  Bossak step {per:.3} s (last step: {its} Newton iterations)");
    }
    println!(
        "nonlinear / linear static solve: {:.1}×",
        static_times[1] / static_times[0]
    );
    let prandtl = 2.0 + std::f64::consts::PI;
    for h in [0.5, 0.25, 0.125] {
        let (curve, iterations, wall) = footing::strip_footing(h, 18);
        let q = curve.last().unwrap().1 / 1e4;
        println!(
            "strip footing h = {h} m: collapse pressure {q:.3} c (Prandtl {prandtl:.3}, {:+.1} %), \
             {iterations} Newton iterations in {} steps, {wall:.2} s",
            100.0 * (q / prandtl - 1.0),
            curve.len()
        );
    }
}
