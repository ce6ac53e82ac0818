//! The `[fem]` scene table: errors name line, column and field; histories.
#![allow(
    clippy::neg_cmp_op_on_partial_ord,
    clippy::needless_range_loop,
    clippy::nonminimal_bool
)]

mod common;
use common::*;
use fem::history::History;

const BEAM: &str = r#"[scene]
name = "beam"

[dem]
anything = "ignored"

[fem]
mesh = { size = [1.0, 0.1, 0.1], element_size = 0.05, element = "hex8" }
analysis = "static"

[fem.material]
youngs_modulus = 210e9
poisson_ratio = 0.3
density = 7800.0

[[fem.supports]]
on = { set = "xmin" }
"#;

#[test]
fn other_tables_are_ignored_and_missing_fem_is_none() {
    assert!(fem::parse_scene_section(BEAM).unwrap().is_some());
    assert!(fem::parse_scene_section("[scene]\nname = \"dem only\"\n")
        .unwrap()
        .is_none());
}

#[test]
fn invalid_poisson_ratio_names_field_and_line() {
    let text = BEAM.replace("poisson_ratio = 0.3", "poisson_ratio = 0.5");
    let e = fem::parse_scene_section(&text).unwrap_err();
    println!("{e}");
    assert_eq!(e.line, 13);
    assert!(e.message.contains("fem.material.poisson_ratio"), "{e}");
    assert!(e.to_string().starts_with("line 13, column "));
}

/// ν ≥ ½ (incompressible: λ infinite) and ν ≤ −1 (G infinite or negative) are refused with the
/// field and its line; ν = 0.499 is accepted.
#[test]
fn poisson_ratio_outside_open_interval_is_refused_with_its_line() {
    for bad in ["0.5", "0.7", "-1.0", "-1.5"] {
        let text = BEAM.replace("poisson_ratio = 0.3", &format!("poisson_ratio = {bad}"));
        let e = fem::parse_scene_section(&text).unwrap_err();
        assert!(
            e.message.contains("fem.material.poisson_ratio")
                && e.message
                    .contains(&format!("got {}", bad.parse::<f64>().unwrap())),
            "{e}"
        );
        assert_eq!(e.line, 13, "{e}");
    }
    let text = BEAM.replace("poisson_ratio = 0.3", "poisson_ratio = 0.499");
    assert!(fem::parse_scene_section(&text).unwrap().is_some());
}

#[test]
fn unknown_field_is_reported_at_its_line() {
    let text = BEAM.replace("density = 7800.0", "density = 7800.0\ndensty = 1.0");
    let e = fem::parse_scene_section(&text).unwrap_err();
    println!("{e}");
    assert_eq!(e.line, 15);
    assert!(e.message.contains("densty"), "{e}");
}

#[test]
fn wrong_type_names_the_field() {
    let text = BEAM.replace("youngs_modulus = 210e9", "youngs_modulus = \"stiff\"");
    let e = fem::parse_scene_section(&text).unwrap_err();
    println!("{e}");
    assert_eq!(e.line, 12);
    assert!(e.message.contains("youngs_modulus"), "{e}");
}

#[test]
fn bad_selector_in_array_of_tables_is_located() {
    let text = format!(
        "{BEAM}[[fem.supports]]\non = {{ set = \"a\", plane = {{ axis = \"x\", value = 0.0 }} }}\n"
    );
    let e = fem::parse_scene_section(&text).unwrap_err();
    println!("{e}");
    assert!(e.message.contains("fem.supports[1].on"), "{e}");
    assert_eq!(e.line, 19);
}

#[test]
fn bossak_alpha_out_of_range_is_rejected() {
    let text = BEAM.replace(
        "analysis = \"static\"",
        "analysis = { type = \"dynamic\", alpha_b = 0.1 }",
    );
    let e = fem::parse_scene_section(&text).unwrap_err();
    println!("{e}");
    assert!(e.message.contains("fem.analysis.alpha_b"), "{e}");
    assert_eq!(e.line, 9);
}

#[test]
fn unknown_node_set_is_named_when_building() {
    let text = BEAM.replace("set = \"xmin\"", "set = \"left_end\"");
    let cfg = config(&text);
    let err = fem::Model::from_config(&cfg, std::path::Path::new("."))
        .err()
        .unwrap()
        .to_string();
    println!("{err}");
    assert!(err.contains("left_end") && err.contains("fem.supports[0].on") && err.contains("xmin"));
}

/// REFERENCE A5: ramp 0→220 kN, cycles 4.4–44 kN at 2 Hz, ramp again (times scaled here to
/// 1 s ramps and 2 s of cycling).
#[test]
fn sleeper_load_pattern_is_expressible() {
    let text = r#"
[fem]
mesh = { size = [2.5, 0.2, 0.18], element_size = 0.09, element = "hex8" }
[fem.material]
youngs_modulus = 9e9
poisson_ratio = 0.3
density = 800.0
[[fem.supports]]
on = { set = "zmin" }
[fem.histories.sleeper]
type = "sum"
of = [
  { type = "table", points = [[0.0, 0.0], [1.0, 220e3], [1.0, 0.0], [3.0, 0.0], [3.0, 0.0], [4.0, 220e3], [4.0, 0.0]] },
  { type = "window", start = 1.0, end = 3.0, of = { type = "sine", amplitude = 19.8e3, offset = 24.2e3, frequency = 2.0, start = 1.0, phase = -1.5707963267948966 } },
]
[[fem.loads]]
type = "force"
on = { box = { min = [0.8075, 0.0, 0.18], max = [0.9575, 0.2, 0.18] } }
total = [0.0, 0.0, -1.0]
history = "sleeper"
"#;
    let cfg = config(text);
    let h = &cfg.histories["sleeper"];
    let v = |t: f64| h.eval(t, &cfg.histories);
    assert!((v(0.5) - 110e3).abs() < 1e-6);
    assert!((v(1.0) - 4.4e3).abs() < 1e-6, "{}", v(1.0)); // cycling starts at the minimum
    assert!((v(1.25) - 44e3).abs() < 1e-6, "{}", v(1.25)); // peak a quarter period later... 2 Hz
    assert!((v(1.5) - 4.4e3).abs() < 1e-6);
    assert!((v(3.5) - 110e3).abs() < 1e-6);
    assert_eq!(v(5.0), 0.0);
    let m = fem::Model::from_config(&cfg, std::path::Path::new(".")).unwrap();
    let f = m.external_forces(0.5);
    let fz: f64 = f.iter().skip(2).step_by(3).sum();
    assert!((fz + 110e3).abs() < 1e-6, "{fz}");
    let _ = History::Constant { value: 1.0 };
}
