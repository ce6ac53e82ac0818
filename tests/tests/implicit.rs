//! The implicit schedule end to end (issue 19): each window iterated with rollbacks until the
//! interface forces are a fixed point, the acceleration in the coordinator; serial and
//! concurrent.

use cosim_tests::{csv_column, run_scene};

fn plate(schedule: &str, window: &str, tables: &str) -> String {
    cosim_tests::plate_with(schedule, window, tables)
}

#[test]
fn implicit_plate_converges_every_window_and_closes_the_energy_gap() {
    // serial (FEM first, Aitken) and concurrent (both at once on the coordinator's estimates of
    // forces and positions, IQN-ILS by default)
    for (name, tables) in [
        ("serial", "acceleration = \"aitken\""),
        ("concurrent", "concurrent = true"),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let s = run_scene(
            dir.path(),
            "plate.toml",
            &plate(
                "implicit",
                "0.1 ms",
                &format!("[coupling.implicit]\ntolerance = 1e-4\n{tables}"),
            ),
        );
        assert_eq!(s["status"], "completed", "{name}: {s}");
        let csv = std::fs::read_to_string(dir.path().join("out-plate.toml/windows.csv")).unwrap();
        let iterations: Vec<u32> = csv_column(&csv, "iterations")
            .iter()
            .map(|v| v.parse().unwrap())
            .collect();
        let residuals: Vec<f64> = csv_column(&csv, "residual")
            .iter()
            .map(|v| v.parse().unwrap())
            .collect();
        assert_eq!(iterations.len(), 300);
        assert!(
            residuals.iter().all(|r| *r <= 1e-4),
            "{name}: {residuals:?}"
        );
        let total: u32 = iterations.iter().sum();
        assert_eq!(s["coupling_iterations"].as_u64().unwrap(), total as u64);
        // serial: free fall needs one iteration a window (nothing touches the plate)
        if name == "serial" {
            assert_eq!(iterations[0], 1);
        }
        // impacts need more
        let most = *iterations.iter().max().unwrap();
        assert!(most > 1 && most <= 30, "{name}: {iterations:?}");
        assert_eq!(s["max_window_iterations"].as_u64().unwrap(), most as u64);
        // converged, the DEM's work and the FEM's agree window by window to the tolerance:
        // the energy error of the explicit lag is gone
        let t = &s["interface_work"]["top"];
        let (d, f) = (t["dem_j"].as_f64().unwrap(), t["fem_j"].as_f64().unwrap());
        let exchanged: f64 = csv_column(&csv, "interface_work_dem.top_j")
            .iter()
            .map(|v| v.parse::<f64>().unwrap().abs())
            .sum();
        eprintln!(
            "implicit plate ({name}): {total} iterations in 300 windows (at most {most}); DEM {d:.4e} J, FEM {f:.4e} J, error {:.2e} J of {exchanged:.3e} J exchanged",
            d - f
        );
        assert!((d - f).abs() < 0.01 * exchanged, "{name}: {d} vs {f}");
    }
}

#[test]
fn iqn_ils_converges_the_plate_and_constant_relaxation_says_when_it_cannot() {
    let run = |acceleration: &str, extra: &str| {
        let dir = tempfile::tempdir().unwrap();
        let text = plate(
            "implicit",
            "0.1 ms",
            &format!(
                "[coupling.implicit]\ntolerance = 1e-4\nacceleration = \"{acceleration}\"\n{extra}"
            ),
        );
        let scene = cosim_tests::write_scene(dir.path(), "plate.toml", &text);
        let out = dir.path().join("out");
        let mut c = cosim_tests::cosim();
        c.arg("run")
            .arg(&scene)
            .arg("--no-progress")
            .arg("--out")
            .arg(&out);
        let o = cosim_tests::run(c);
        (o, cosim_tests::summary(&out))
    };
    let (_, iqn) = run("iqn-ils", "");
    assert_eq!(iqn["status"], "completed", "{iqn}");
    let (_, aitken) = run("aitken", "");
    eprintln!(
        "plate, tolerance 1e-4: IQN-ILS {} iterations (at most {} in a window), Aitken {} (at most {})",
        iqn["coupling_iterations"],
        iqn["max_window_iterations"],
        aitken["coupling_iterations"],
        aitken["max_window_iterations"]
    );
    assert!(iqn["coupling_iterations"].as_u64().unwrap() < 2 * 300);
    // a fixed relaxation of 0.5 is too large for this interface: the iteration diverges at the
    // first impacts, and the run says so with the window's residual history
    let (o, constant) = run("constant", "max_iterations = 20");
    assert!(!o.status.success());
    assert_eq!(constant["status"], "failed");
    let e = constant["error"].as_str().unwrap();
    eprintln!("{e}");
    assert!(e.contains("did not converge in 20 iterations"), "{e}");
    assert!(e.matches("e").count() >= 20, "the residual history: {e}");
}

#[test]
fn cosim_check_and_study_take_the_implicit_keys() {
    // a check starts the nodes too: the DEM's forces must find the coordinator's tap, or it
    // would never report `ready`
    let dir = tempfile::tempdir().unwrap();
    let text =
        plate("implicit", "0.1 ms", "").replace("end_time = \"30 ms\"", "end_time = \"8 ms\"");
    let scene = cosim_tests::write_scene(dir.path(), "plate.toml", &text);
    let mut c = cosim_tests::cosim();
    c.arg("check").arg(&scene);
    let o = cosim_tests::run(c);
    assert!(o.status.success());
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("implicit: no window limit"), "{stdout}");
    // a study varies them like any other key
    let out = dir.path().join("study");
    let mut c = cosim_tests::cosim();
    c.arg("study")
        .arg(&scene)
        .args([
            "--vary",
            "coupling.implicit.acceleration=aitken,iqn-ils",
            "--series",
            "fem/fem_probes.csv:probe.centre.uz",
            "--jobs",
            "1",
            "--out",
        ])
        .arg(&out);
    assert!(cosim_tests::run(c).status.success());
    let csv = std::fs::read_to_string(out.join("study.csv")).unwrap();
    assert_eq!(csv.matches(",completed,").count(), 2, "{csv}");
}
