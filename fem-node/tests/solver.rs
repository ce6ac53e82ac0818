//! `[fem] solver`: the mixed-precision static solver (f32 Cholesky factor preconditioning f64
//! conjugate gradients) gives the f64 factor's answer, and falls back to it where single
//! precision cannot carry the problem.
mod common;
use common::*;

fn with_solver(scene: &str, solver: &str) -> String {
    scene.replacen("[fem]\n", &format!("[fem]\nsolver = \"{solver}\"\n"), 1)
}

/// Every free displacement component of a static solve, node-major.
fn solve(scene: &str) -> (Vec<f64>, Option<fem::assembly::RefinedSolve>) {
    let mut m = model(scene);
    m.solve_static().unwrap();
    (m.displacements().to_vec(), m.last_mixed_solve())
}

fn max_rel_diff(a: &[f64], b: &[f64]) -> f64 {
    let scale = b.iter().fold(0.0f64, |s, v| s.max(v.abs()));
    a.iter()
        .zip(b)
        .fold(0.0f64, |s, (x, y)| s.max((x - y).abs()))
        / scale
}

#[test]
fn mixed_precision_solve_gives_the_f64_answer_on_the_a3_beam() {
    let beam = a3_beam("hex8", 0.025);
    let (direct, none) = solve(&with_solver(&beam, "direct"));
    assert!(none.is_none());
    let (mixed, info) = solve(&with_solver(&beam, "mixed"));
    let info = info.expect("the mixed solver was used");
    let d = max_rel_diff(&mixed, &direct);
    println!(
        "hex8 25 mm: {} PCG iterations, relative residual {:.1e}, max difference {d:.1e} of the \
         largest displacement",
        info.iterations, info.relative_residual
    );
    assert!(info.iterations <= 20, "{info:?}");
    assert!(info.relative_residual <= 1e-9, "{info:?}");
    assert!(d < 1e-9, "{d:e}");
    // `auto` keeps the f64 factor for small systems
    let (auto, none) = solve(&beam);
    assert!(none.is_none());
    assert_eq!(auto, direct);
}

/// A 1 m × 2 mm × 2 mm cantilever (κ(K) ~ (L/t)⁴): single precision cannot factor or
/// precondition it: the solver falls back to the f64 factor and gives its answer exactly.
#[test]
fn mixed_precision_solve_falls_back_to_f64_on_an_ill_conditioned_cantilever() {
    let scene = format!(
        r#"
[fem]
mesh = {{ size = [1.0, 0.002, 0.002], element_size = 0.002, element = "hex8i" }}
{STEEL}
[[fem.supports]]
on = {{ set = "xmin" }}
[[fem.loads]]
type = "gravity"
acceleration = [0.0, 0.0, -9.81]
"#
    );
    let (direct, _) = solve(&with_solver(&scene, "direct"));
    let (mixed, info) = solve(&with_solver(&scene, "mixed"));
    let d = max_rel_diff(&mixed, &direct);
    println!("thin cantilever: mixed path {info:?}, max difference {d:.1e}");
    assert!(info.is_none(), "fell back to the f64 factor: {info:?}");
    assert_eq!(d, 0.0);
}

#[test]
fn an_unknown_solver_is_a_scene_error_naming_the_choices() {
    let err = fem::parse_scene_section(&with_solver(&a3_beam("hex8", 0.05), "lu"))
        .unwrap_err()
        .to_string();
    println!("{err}");
    assert!(err.contains("solver") || err.contains("`lu`"), "{err}");
    assert!(err.contains("direct") && err.contains("mixed"), "{err}");
}
