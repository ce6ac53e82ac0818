//! The `limits` a FEM node reports for the coordinator's up-front checks: interface node
//! masses, structure mass, lowest and highest natural frequency; and the locking warnings.
#![allow(
    clippy::neg_cmp_op_on_partial_ord,
    clippy::needless_range_loop,
    clippy::nonminimal_bool
)]

mod common;
use common::*;
use nalgebra::DMatrix;

fn limit(l: &std::collections::BTreeMap<String, f64>, key: &str) -> f64 {
    *l.get(key)
        .unwrap_or_else(|| panic!("{key} missing in {l:?}"))
}

/// Steel cantilever 1 m × 50 mm × 50 mm (L/H = 20), hex20 20 × 1 × 1.
fn cantilever(analysis: &str) -> String {
    format!(
        r#"
[fem]
mesh = {{ size = [1.0, 0.05, 0.05], divisions = [20, 1, 1], element = "hex20" }}
analysis = {analysis}
{STEEL}
[[fem.supports]]
on = {{ set = "xmin" }}
[fem.interface]
on = {{ set = "zmax" }}
"#
    )
}

/// Generalised eigenvalues of K φ = λ M φ (dense, ascending) via the Cholesky factor of M.
fn dense_eigenvalues(m: &fem::Model) -> Vec<f64> {
    let (n, k, mm) = m.dense_free_matrices();
    let k = DMatrix::from_row_slice(n, n, &k);
    let l = DMatrix::from_row_slice(n, n, &mm).cholesky().unwrap().l();
    let li = l.try_inverse().unwrap();
    let a = &li * k * li.transpose();
    let a = (&a + a.transpose()) * 0.5;
    let mut ev: Vec<f64> = a.symmetric_eigenvalues().iter().copied().collect();
    ev.sort_by(f64::total_cmp);
    ev
}

/// f₁ of a clamped-free beam: (1.8751²/2π) √(EI/(ρAL⁴)) (Euler–Bernoulli). At L/H = 20 shear
/// and rotary inertia lower it by ~0.3 %, the fully clamped 3-D root raises it by about as
/// much; measured +0.5 %. The Lanczos value must match the dense eigensolve of the same model.
#[test]
fn cantilever_lowest_frequency_matches_beam_theory_and_dense_eigensolve() {
    let mut m = model(&cantilever("\"dynamic\""));
    let l = m.limits().unwrap();
    let f1 = limit(&l, "lowest_frequency_hz");
    let fmax = limit(&l, "highest_frequency_hz");
    let (e, rho, b, len) = (210e9, 7800.0, 0.05f64, 1.0f64);
    let i = b.powi(4) / 12.0;
    let euler_bernoulli = 1.875_104_f64.powi(2) / (2.0 * std::f64::consts::PI)
        * (e * i / (rho * b * b * len.powi(4))).sqrt();
    println!("f1 = {f1:.4} Hz, Euler–Bernoulli {euler_bernoulli:.4} Hz, f_max = {fmax:.4e} Hz");
    assert!(
        (f1 / euler_bernoulli - 1.0).abs() < 0.01,
        "{f1} vs {euler_bernoulli}"
    );
    // the same model's spectrum, dense
    let ev = dense_eigenvalues(&m);
    let two_pi = 2.0 * std::f64::consts::PI;
    let (f_lo, f_hi) = (ev[0].sqrt() / two_pi, ev[ev.len() - 1].sqrt() / two_pi);
    assert!((f1 / f_lo - 1.0).abs() < 1e-6, "{f1} vs dense {f_lo}");
    assert!((fmax / f_hi - 1.0).abs() < 1e-4, "{fmax} vs dense {f_hi}");
}

/// With the lumped mass the highest frequency is the one behind the explicit critical step,
/// Δt_crit = 2/ω_max.
#[test]
fn explicit_highest_frequency_is_the_critical_time_step_one() {
    let mut m = model(&cantilever("\"explicit\""));
    let l = m.limits().unwrap();
    let fmax = limit(&l, "highest_frequency_hz");
    let dt = limit(&l, "critical_time_step");
    assert!(
        (fmax * std::f64::consts::PI * dt - 1.0).abs() < 1e-12,
        "{fmax} {dt}"
    );
    let ev = dense_eigenvalues(&m);
    let two_pi = 2.0 * std::f64::consts::PI;
    let f_lo = ev[0].sqrt() / two_pi;
    let f_hi = ev[ev.len() - 1].sqrt() / two_pi;
    assert!((limit(&l, "lowest_frequency_hz") / f_lo - 1.0).abs() < 1e-6);
    assert!((fmax / f_hi - 1.0).abs() < 1e-6, "{fmax} vs {f_hi}");
}

/// hex8 lumped masses are ρV_e/8 per corner: on the top face a corner node carries ρh³/8,
/// and the face's nodes together half of the top element layer.
#[test]
fn interface_node_masses_and_structure_mass_of_a_hex8_block() {
    let text = r#"
[fem]
mesh = { size = [0.4, 0.3, 0.2], element_size = 0.1, element = "hex8" }
[fem.material]
E = 1e9
nu = 0.3
rho = 1000.0
[[fem.supports]]
on = { set = "zmin" }
[fem.interface]
on = { set = "zmax" }
"#;
    let mut m = model(text);
    let l = m.limits().unwrap();
    let h3 = 1e-3;
    assert!((limit(&l, "structure_mass") - 1000.0 * 0.4 * 0.3 * 0.2).abs() < 1e-9);
    assert_eq!(limit(&l, "interface_nodes"), 5.0 * 4.0);
    assert!((limit(&l, "interface_node_mass_min") - 1000.0 * h3 / 8.0).abs() < 1e-12);
    let mean = 4.0 * 3.0 * 1000.0 * h3 / 2.0 / 20.0;
    assert!((limit(&l, "interface_node_mass_mean") - mean).abs() < 1e-12);
    assert!((limit(&l, "dofs") - 3.0 * 5.0 * 4.0 * 3.0).abs() < 0.5);
    // static analysis: no frequencies
    assert!(!l.contains_key("lowest_frequency_hz") && !l.contains_key("highest_frequency_hz"));
}

#[test]
fn locking_elements_draw_a_warning_above_nu_045() {
    let scene = |el: &str, nu: f64| {
        format!(
            "[fem]\nmesh = {{ size = [1.0, 0.1, 0.1], element_size = 0.05, element = \"{el}\" }}\n\
             [fem.material]\nE = 1e9\nnu = {nu}\nrho = 1000.0\n[[fem.supports]]\non = {{ set = \"xmin\" }}\n"
        )
    };
    let w = model(&scene("tet4", 0.49)).warnings();
    assert!(
        w.len() == 1 && w[0].contains("tet4") && w[0].contains("use tet10"),
        "{w:?}"
    );
    assert!(w[0].contains("fem.material.poisson_ratio"), "{w:?}");
    let w = model(&scene("hex8", 0.499)).warnings();
    assert!(w.len() == 1 && w[0].contains("hex8i"), "{w:?}");
    for (el, nu) in [
        ("hex8", 0.45),
        ("tet4", 0.3),
        ("hex8i", 0.499),
        ("tet10", 0.499),
        ("hex20", 0.499),
    ] {
        assert!(model(&scene(el, nu)).warnings().is_empty(), "{el} at {nu}");
    }
}
