//! The concurrent explicit schedule end to end (issue 19): both solvers compute a window at
//! once from the other's data of the window before (the concurrent implicit scheme is tested
//! with the serial one in implicit.rs).

use cosim_tests::run_scene;

fn plate(schedule: &str, window: &str, tables: &str) -> String {
    cosim_tests::plate_with(schedule, window, tables)
}

fn column(csv: &str, name: &str) -> Vec<f64> {
    cosim_tests::csv_column(csv, name)
        .iter()
        .map(|v| v.parse().unwrap())
        .collect()
}

#[test]
fn concurrent_plate_runs_with_the_critical_path_of_the_slower_solver() {
    let dir = tempfile::tempdir().unwrap();
    // 10 µs = one DEM step: just above the concurrent limit 0.025 T_c = 8.7 µs (a warning)
    let s = run_scene(
        dir.path(),
        "plate.toml",
        &plate("concurrent", "0.01 ms", ""),
    );
    assert_eq!(s["status"], "completed", "{s}");
    assert_eq!(s["windows_done"], 3000);
    let warnings = s["warnings"].to_string();
    assert!(warnings.contains("concurrent limit"), "{warnings}");
    // a window's critical path is the slower solver's compute, not the sum of both (each
    // node's next window waits for its own outputs too: the whole compute counts)
    let csv = std::fs::read_to_string(dir.path().join("out-plate.toml/windows.csv")).unwrap();
    let (dem, fem) = (column(&csv, "dem_compute_s"), column(&csv, "fem_compute_s"));
    let critical: f64 = dem.iter().zip(&fem).map(|(d, f)| d.max(*f)).sum();
    let t = &s["timing"];
    let recorded = t["critical_path_s"].as_f64().unwrap();
    assert!(
        (recorded - critical).abs() <= 1e-6 * critical + 1e-5,
        "{recorded} vs {critical}"
    );
    assert!(recorded < t["dem_compute_s"].as_f64().unwrap() + t["fem_compute_s"].as_f64().unwrap());
    // the energy audit sees both solvers' lag: the DEM's work and the FEM's differ
    let w = &s["interface_work"]["top"];
    let (d, f) = (w["dem_j"].as_f64().unwrap(), w["fem_j"].as_f64().unwrap());
    eprintln!("concurrent plate at 10 µs: DEM work {d:.4e} J, FEM {f:.4e} J");
    assert!(d > 0.0 && f > 0.0);
}
