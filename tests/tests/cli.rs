//! `cosim run` and `cosim check` as a user runs them: real processes, real zenoh sessions on
//! loopback, real files.

use cosim_tests::{cosim, root, run, summary, write_scene};

#[test]
fn cosim_run_minimal_scene_launches_the_dem_node_and_writes_a_summary() {
    let out = tempfile::tempdir().unwrap();
    let mut c = cosim();
    c.args(["run", "scenes/minimal.toml", "--no-progress", "--out"])
        .arg(out.path());
    let o = run(c);
    assert!(o.status.success());
    let s = summary(out.path());
    assert_eq!(s["status"], "completed");
    assert_eq!(s["windows_done"], 20);
    assert_eq!(s["dem_substeps"], 1000);
    assert_eq!(s["results"]["dem.particles"], 27.0);
    assert!((s["simulated_time_s"].as_f64().unwrap() - 0.2).abs() < 1e-9);
    // the beads have landed and settle on the floor
    assert!(
        s["results"]["dem.wall_contacts"].as_f64().unwrap() >= 9.0,
        "{s}"
    );
    let csv = std::fs::read_to_string(out.path().join("windows.csv")).unwrap();
    assert_eq!(csv.lines().count(), 21, "header + one row per window");
    assert!(out.path().join("logs/dem.log").exists());
}

#[test]
fn cosim_check_names_line_and_field_of_a_coordinator_error() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(root().join("scenes/minimal.toml"))
        .unwrap()
        .replace("window = \"10 ms\"", "window = \"10 ms\"\nwindoe = 3");
    let scene = write_scene(dir.path(), "broken.toml", &text);
    let mut c = cosim();
    c.arg("check").arg(&scene);
    let o = run(c);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    let line = text.lines().position(|l| l.starts_with("windoe")).unwrap() + 1;
    assert!(err.contains(&format!("broken.toml:{line}:")), "{err}");
    assert!(err.contains("unknown field `windoe`"), "{err}");
}

#[test]
fn cosim_check_names_line_and_field_of_an_error_in_the_dem_table() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(root().join("scenes/minimal.toml"))
        .unwrap()
        .replace("poisson_ratio = 0.3", "poisson_ratio = 0.7");
    let scene = write_scene(dir.path(), "bad-dem.toml", &text);
    let mut c = cosim();
    c.arg("check").arg(&scene);
    let o = run(c);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    let line = text
        .lines()
        .position(|l| l.starts_with("poisson_ratio"))
        .unwrap()
        + 1;
    assert!(err.contains("bad-dem.toml"), "{err}");
    assert!(err.contains(&format!("line {line}")), "{err}");
    assert!(err.contains("poisson_ratio"), "{err}");
}

#[test]
fn cosim_check_accepts_the_minimal_scene_and_reports_the_dem_limits() {
    let mut c = cosim();
    c.args(["check", "scenes/minimal.toml"]);
    let o = run(c);
    assert!(o.status.success());
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("dem.rayleigh_time_step"), "{text}");
    assert!(text.contains("dem.time_step = 1.0"), "{text}");
}

#[test]
fn a_missing_scene_file_is_named() {
    let mut c = cosim();
    c.args(["run", "scenes/does-not-exist.toml"]);
    let o = run(c);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("scenes/does-not-exist.toml"));
}
