//! Beams: the fixed-fixed steel beam of Ullrich ch. 4 (REFERENCE A3) and a cantilever against
//! Timoshenko / Euler–Bernoulli theory.
#![allow(
    clippy::neg_cmp_op_on_partial_ord,
    clippy::needless_range_loop,
    clippy::nonminimal_bool
)]

mod common;
use common::*;

fn midspan_deflection(element: &str, h: f64) -> f64 {
    let mut m = model(&a3_beam(element, h));
    m.solve_static().unwrap();
    m.probe_displacement("midspan").unwrap()[2]
}

/// REFERENCE A3: full-integration hexes at 50 mm give −7.05e-7 m at midspan (CalculiX 2.20 on
/// the deck of `benches/ccx/beam_deck.py 50`: −7.049743e-7 m at the centre node).
#[test]
fn fixed_beam_hex8_50mm_matches_reference() {
    let w = midspan_deflection("hex8", 0.05);
    println!("hex8 50 mm: {w:.5e} m");
    assert!((w / -7.05e-7 - 1.0).abs() < 0.005, "{w:e}");
}

/// Refinement and locking-free elements converge to the shear-corrected value (~ −8.2e-7 m),
/// below Euler–Bernoulli's ωL⁴/(384EI) = 7.44e-7 m (4.3) because shear deformation matters
/// at L/H = 10.
#[test]
fn fixed_beam_converges_to_timoshenko_value() {
    let hex8_25 = midspan_deflection("hex8", 0.025);
    let hex8i_50 = midspan_deflection("hex8i", 0.05);
    let hex8i_25 = midspan_deflection("hex8i", 0.025);
    let hex20_50 = midspan_deflection("hex20", 0.05);
    let hex20_25 = midspan_deflection("hex20", 0.025);
    println!("hex8 25: {hex8_25:.4e}, hex8i 50/25: {hex8i_50:.4e} {hex8i_25:.4e}, hex20 50/25: {hex20_50:.4e} {hex20_25:.4e}");
    let euler_bernoulli = -500.0 / (384.0 * 210e9 * (0.1f64.powi(4) / 12.0));
    // monotone convergence from the stiff side, all beyond Euler–Bernoulli after refinement
    assert!(hex8_25 < -7.05e-7 && hex8_25 > hex8i_25);
    assert!(hex8i_50 < euler_bernoulli && hex20_50 < euler_bernoulli);
    assert!(hex20_25 < hex20_50 && hex8i_25 < hex8i_50);
    // converged value ≈ −8.2e-7 m within 1 %
    assert!((hex20_25 / -8.2e-7 - 1.0).abs() < 0.01, "{hex20_25:e}");
    // locking-free hexes at 25 mm and hex20 agree within 1.5 %
    assert!((hex8i_25 / hex20_25 - 1.0).abs() < 0.015);
}

fn cantilever(element: &str, h: f64, length: f64, depth: f64, extra: &str) -> String {
    format!(
        r#"
[fem]
mesh = {{ size = [{length}, {depth}, {depth}], element_size = {h}, element = "{element}" }}
{STEEL}
[[fem.supports]]
on = {{ plane = {{ axis = "x", value = 0.0 }} }}
[[fem.probes]]
name = "tip"
point = [{length}, {half}, {half}]
{extra}
"#,
        half = depth / 2.0
    )
}

/// Tip deflection of a clamped cantilever under an end shear P: δ = PL³/(3EI) + PL/(κGA).
#[test]
fn cantilever_tip_deflection_matches_timoshenko() {
    let p = 1000.0;
    let load = format!(
        "[[fem.loads]]\ntype = \"force\"\non = {{ set = \"xmax\" }}\ntotal = [0.0, 0.0, -{p}]\n"
    );
    let mut m = model(&cantilever("hex20", 0.025, 1.0, 0.1, &load));
    m.solve_static().unwrap();
    let tip = m.probe_displacement("tip").unwrap()[2];
    let (e, nu, b) = (210e9, 0.3, 0.1f64);
    let i = b.powi(4) / 12.0;
    let g = e / (2.0 * (1.0 + nu));
    let timoshenko = -(p / (3.0 * e * i) + p / (5.0 / 6.0 * g * b * b));
    println!(
        "tip {tip:.5e}, Timoshenko {timoshenko:.5e}, ratio {:.4}",
        tip / timoshenko
    );
    assert!(
        (tip / timoshenko - 1.0).abs() < 0.01,
        "{tip:e} vs {timoshenko:e}"
    );
}

/// First bending frequency of a slender cantilever (L/h = 20) from a free-vibration Bossak run
/// (α_B = 0) vs Euler–Bernoulli f₁ = 1.8751²/(2π) √(EI/(ρAL⁴)).
#[test]
fn cantilever_first_bending_frequency_matches_euler_bernoulli() {
    let (l, h): (f64, f64) = (1.0, 0.05);
    let (e, rho): (f64, f64) = (210e9, 7800.0);
    let f_eb = 1.875104f64.powi(2) / (2.0 * std::f64::consts::PI)
        * (e * h * h / (12.0 * rho * l.powi(4))).sqrt();
    let extra = r#"
[fem.analysis]
type = "dynamic"
alpha_b = 0.0
[fem.histories.release]
type = "table"
points = [[0.0, 1.0], [1e-12, 0.0]]
[[fem.loads]]
type = "force"
on = { set = "xmax" }
total = [0.0, 0.0, -100.0]
history = "release"
"#;
    let mut m = model(&cantilever("hex20", 0.025, l, h, extra));
    m.solve_static().unwrap(); // static deflection at t = 0, released for t > 0
    let period = 1.0 / f_eb;
    let dt = period / 80.0;
    let mut prev = m.probe_displacement("tip").unwrap()[2];
    let mut crossings = Vec::new();
    for _ in 0..(3.3 * 80.0) as usize {
        m.advance(dt).unwrap();
        let w = m.probe_displacement("tip").unwrap()[2];
        if prev.signum() != w.signum() && w != 0.0 {
            // linear interpolation of the zero crossing
            crossings.push(m.time() - dt * w / (w - prev));
        }
        prev = w;
    }
    assert!(crossings.len() >= 5, "{crossings:?}");
    let half_periods = (crossings.len() - 1) as f64;
    let t_fe = 2.0 * (crossings[crossings.len() - 1] - crossings[0]) / half_periods;
    let f_fe = 1.0 / t_fe;
    println!(
        "f_FE = {f_fe:.3} Hz, f_EB = {f_eb:.3} Hz, ratio {:.4}",
        f_fe / f_eb
    );
    assert!((f_fe / f_eb - 1.0).abs() < 0.02);
}
