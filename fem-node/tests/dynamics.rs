//! Time integration: Bossak–Newmark (REFERENCE A6) energy conservation and numerical damping,
//! explicit central differences at the stability limit.
#![allow(
    clippy::neg_cmp_op_on_partial_ord,
    clippy::needless_range_loop,
    clippy::nonminimal_bool
)]

mod common;
use common::*;
use nalgebra::{DMatrix, DVector};

/// A small clamped steel cantilever, 0.8 × 0.1 × 0.1 m, hex8 at 0.1 m.
fn small_cantilever(analysis: &str) -> fem::Model {
    model(&format!(
        r#"
[fem]
mesh = {{ size = [0.8, 0.1, 0.1], element_size = 0.1, element = "hex8" }}
{STEEL}
{analysis}
[[fem.supports]]
on = {{ set = "xmin" }}
"#
    ))
}

/// Generalised eigenpairs K x = λ M x (ascending), x M-normalised.
fn modes(m: &fem::Model) -> (Vec<f64>, Vec<DVector<f64>>) {
    let (n, k, mm) = m.dense_free_matrices();
    let k = DMatrix::from_row_slice(n, n, &k);
    let mm = DMatrix::from_row_slice(n, n, &mm);
    let l = mm.cholesky().expect("M SPD").l();
    let linv = l.clone().try_inverse().unwrap();
    let a = &linv * k * linv.transpose();
    let a = (&a + a.transpose()) * 0.5;
    let eig = a.symmetric_eigen();
    let mut idx: Vec<usize> = (0..n).collect();
    idx.sort_by(|&i, &j| eig.eigenvalues[i].partial_cmp(&eig.eigenvalues[j]).unwrap());
    let vals = idx.iter().map(|&i| eig.eigenvalues[i]).collect();
    let vecs = idx
        .iter()
        .map(|&i| linv.transpose() * eig.eigenvectors.column(i))
        .collect();
    (vals, vecs)
}

fn energy(m: &fem::Model) -> f64 {
    m.kinetic_energy() + m.strain_energy()
}

/// α_B = 0 is the trapezoidal rule: the energy of a free vibration is conserved.
#[test]
fn bossak_alpha_zero_conserves_energy() {
    let mut m = small_cantilever("[fem.analysis]\ntype = \"dynamic\"\nalpha_b = 0.0");
    let (vals, _) = modes(&m);
    let period = 2.0 * std::f64::consts::PI / vals[0].sqrt();
    // random initial displacement: all modes excited
    let mut rng = Rng(42);
    let u0: Vec<f64> = (0..m.num_dofs()).map(|_| 1e-5 * rng.next()).collect();
    m.set_initial_conditions(&u0, &vec![0.0; u0.len()]).unwrap();
    let e0 = energy(&m);
    let periods = 10;
    let mut worst: f64 = 0.0;
    for _ in 0..periods * 40 {
        m.advance(period / 40.0).unwrap();
        worst = worst.max((energy(&m) - e0).abs() / e0);
    }
    println!("max relative energy drift over {periods} periods: {worst:.2e}");
    assert!(worst / periods as f64 <= 1e-6, "{worst:e}");
}

/// Modal free vibration with α_B = −0.1 over the same 40 steps (one period of mode 1): the
/// highest mode loses > 99.9 % of its energy, the first mode < 1 %.
#[test]
fn bossak_damps_highest_mode_not_first() {
    let run = |alpha: f64, mode_hi: bool, steps: usize| -> f64 {
        let mut m = small_cantilever(&format!(
            "[fem.analysis]\ntype = \"dynamic\"\nalpha_b = {alpha}"
        ));
        let (vals, vecs) = modes(&m);
        let dt = 2.0 * std::f64::consts::PI / vals[0].sqrt() / 40.0;
        let shape = if mode_hi {
            vecs.last().unwrap()
        } else {
            &vecs[0]
        };
        let scale = 1e-5 / shape.amax();
        let u0 = m.free_to_full((shape * scale).as_slice());
        m.set_initial_conditions(&u0, &vec![0.0; u0.len()]).unwrap();
        let e0 = energy(&m);
        for _ in 0..steps {
            m.advance(dt).unwrap();
        }
        energy(&m) / e0
    };
    let first = run(-0.1, false, 40); // one period of mode 1
    let highest = run(-0.1, true, 40);
    let highest_undamped = run(0.0, true, 40);
    println!("energy ratio: mode 1 after 1 period {first:.6}, highest after 40 steps {highest:.2e} (α_B = 0: {highest_undamped:.6})");
    assert!(first > 0.99, "first mode damped too much: {first}");
    assert!(highest < 1e-3, "highest mode not damped: {highest:e}");
    assert!((highest_undamped - 1.0).abs() < 1e-6);
}

/// Δt_crit = 2/ω_max from Lanczos equals the dense eigenvalue bound.
#[test]
fn critical_time_step_matches_dense_eigenvalue() {
    let m = small_cantilever("[fem.analysis]\ntype = \"explicit\"");
    let (vals, _) = modes(&m); // lumped mass for explicit
    let exact = 2.0 / vals.last().unwrap().sqrt();
    let est = m.critical_time_step().unwrap();
    println!("Δt_crit Lanczos {est:.6e}, dense {exact:.6e}");
    assert!((est / exact - 1.0).abs() < 1e-6);
}

fn explicit_growth(factor: f64) -> f64 {
    let mut m = small_cantilever("[fem.analysis]\ntype = \"explicit\"");
    let mut rng = Rng(7);
    let u0: Vec<f64> = (0..m.num_dofs()).map(|_| 1e-6 * rng.next()).collect();
    m.set_initial_conditions(&u0, &vec![0.0; u0.len()]).unwrap();
    let amp0 = m.displacements().iter().fold(0.0f64, |a, b| a.max(b.abs()));
    let h = factor * m.critical_time_step().unwrap();
    let mut amp: f64 = 0.0;
    for _ in 0..400 {
        m.explicit_step(h).unwrap();
        amp = amp.max(m.displacements().iter().fold(0.0f64, |a, b| a.max(b.abs())));
        if !amp.is_finite() {
            break;
        }
    }
    amp / amp0
}

/// Central differences are stable just below Δt_crit and blow up just above it.
#[test]
fn explicit_central_difference_stable_below_critical_step_unstable_above() {
    let below = explicit_growth(0.98);
    let above = explicit_growth(1.05);
    println!(
        "amplitude growth over 400 steps: 0.98 Δt_crit → {below:.2}, 1.05 Δt_crit → {above:.2e}"
    );
    assert!(below < 20.0, "unstable below the limit: {below}");
    assert!(!(above < 1e6), "stable above the limit: {above}");
}

/// `advance` in explicit mode substeps automatically and stays stable for a large window.
#[test]
fn explicit_advance_substeps_within_limit() {
    let mut m = small_cantilever(
        "[fem.analysis]\ntype = \"explicit\"\nsafety = 0.9\n[[fem.loads]]\ntype = \"force\"\non = { set = \"xmax\" }\ntotal = [0.0, 0.0, -1000.0]",
    );
    let crit = m.critical_time_step().unwrap();
    let mut s = small_cantilever(
        "[fem.analysis]\ntype = \"static\"\n[[fem.loads]]\ntype = \"force\"\non = { set = \"xmax\" }\ntotal = [0.0, 0.0, -1000.0]",
    );
    s.solve_static().unwrap();
    let w_static = s.displacements().iter().fold(0.0f64, |a, b| a.min(*b));
    // step load: the dynamic response oscillates between 0 and ~2× the static deflection
    let mut w_min: f64 = 0.0;
    for _ in 0..200 {
        m.advance(50.0 * crit).unwrap();
        w_min = w_min.min(m.displacements().iter().fold(0.0f64, |a, b| a.min(*b)));
    }
    println!("explicit min {w_min:.4e}, static {w_static:.4e}");
    assert!(
        w_min < 1.5 * w_static && w_min > 2.1 * w_static,
        "{w_min:e} vs {w_static:e}"
    );
}

/// `max_step`: a long window is stepped in equal substeps, so a window of 8 h equals 8 windows
/// of h (to the round-off of the substep times), and a too-long window alone would not.
#[test]
fn max_step_makes_the_structure_independent_of_the_window() {
    let h = 1e-5;
    let run = |analysis: &str, windows: &[f64]| -> Vec<f64> {
        let mut m = small_cantilever(analysis);
        let mut rng = Rng(7);
        let u0: Vec<f64> = (0..m.num_dofs()).map(|_| 1e-5 * rng.next()).collect();
        m.set_initial_conditions(&u0, &vec![0.0; u0.len()]).unwrap();
        for &w in windows {
            m.advance(w).unwrap();
        }
        m.interface_kinematics().0
    };
    let fine = run("[fem.analysis]\ntype = \"dynamic\"", &[h; 16]);
    let sub = run(
        "[fem.analysis]\ntype = \"dynamic\"\nmax_step = 1e-5",
        &[8.0 * h, 4.0 * h, 2.0 * h, h, h],
    );
    let coarse = run(
        "[fem.analysis]\ntype = \"dynamic\"",
        &[8.0 * h, 4.0 * h, 2.0 * h, h, h],
    );
    let diff = |a: &[f64], b: &[f64]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f64, f64::max)
    };
    let (d_sub, d_coarse) = (diff(&fine, &sub), diff(&fine, &coarse));
    println!("max_step: {d_sub:.2e} m from 16 steps of h; one step per window: {d_coarse:.2e} m");
    assert!(d_sub < 1e-15, "{d_sub:e}");
    assert!(d_coarse > 1e3 * d_sub.max(1e-18), "{d_coarse:e}");
}
