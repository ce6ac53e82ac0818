//! Adaptive coupling windows end to end (issue 19): the window chosen after each window from
//! the nodes' numbers, on a ladder, logged, ending on the end time.

use cosim_tests::run_scene;

/// The plate, predictive with force averaging, adaptive `tables`.
fn plate(tables: &str, window: &str) -> String {
    cosim_tests::plate_with("predictive", window, tables)
}

#[test]
fn adaptive_plate_grows_the_window_in_free_flight_and_shrinks_it_at_the_impacts() {
    let dir = tempfile::tempdir().unwrap();
    let s = run_scene(
        dir.path(),
        "plate.toml",
        &plate(
            "[coupling.adaptive]\nmin_window = \"10 us\"\nmax_window = \"0.32 ms\"",
            "0.08 ms",
        ),
    );
    assert_eq!(s["status"], "completed", "{s}");
    let a = &s["adaptive_windows"];
    let (shortest, longest) = (
        a["shortest_s"].as_f64().unwrap(),
        a["longest_s"].as_f64().unwrap(),
    );
    eprintln!(
        "adaptive plate: {} windows, {} changes, {shortest:.3e}–{longest:.3e} s",
        s["windows_done"], a["changes"]
    );
    // the beads fly for 7 ms: the window grows to the longest; the impacts load the interface
    // and the energy mismatch shrinks it
    assert!((longest - 3.2e-4).abs() < 1e-12, "{a}");
    assert!(shortest < 1e-4, "{a}");
    assert!(a["changes"].as_u64().unwrap() >= 4, "{a}");
    // every window is on the ladder, and they add up to the end time
    let csv = std::fs::read_to_string(dir.path().join("out-plate.toml/windows.csv")).unwrap();
    let lengths: Vec<f64> = cosim_tests::csv_column(&csv, "window_s")
        .iter()
        .map(|v| v.parse().unwrap())
        .collect();
    assert_eq!(lengths.len() as u64, s["windows_done"].as_u64().unwrap());
    for l in &lengths {
        let n = l / 1e-5;
        assert!(
            (n.round() - n).abs() < 1e-6 && (n.round() as u64).is_power_of_two(),
            "{l}"
        );
    }
    let total: f64 = lengths.iter().sum();
    assert!((total - 0.03).abs() < 1e-9, "{total}");
    assert!(
        (s["simulated_time_s"].as_f64().unwrap() - 0.03).abs() < 1e-9,
        "{s}"
    );
}

#[test]
fn adaptive_settings_that_cannot_work_are_refused_with_the_field() {
    let dir = tempfile::tempdir().unwrap();
    for (tables, window, field, words) in [
        (
            "[coupling.adaptive]\nmin_window = \"10 us\"\nmax_window = \"0.32 ms\"",
            "0.1 ms",
            "coupling.window",
            "min_window × 2^i",
        ),
        (
            "[coupling.adaptive]\nmin_window = \"0.4 ms\"\nmax_window = \"0.32 ms\"",
            "0.08 ms",
            "coupling.adaptive.min_window",
            "at most max_window",
        ),
        (
            "[coupling.adaptive]\nmin_window = \"7 ms\"\nmax_window = \"14 ms\"",
            "7 ms",
            "coupling.adaptive.min_window",
            "not a whole number",
        ),
        (
            "[coupling.adaptive]\nmin_window = \"10 us\"\nmax_window = \"0.32 ms\"\ntolerance = 2",
            "0.08 ms",
            "coupling.adaptive.tolerance",
            "(0, 1)",
        ),
    ] {
        let scene = cosim_tests::write_scene(dir.path(), "plate.toml", &plate(tables, window));
        let mut c = cosim_tests::cosim();
        c.arg("check").arg(&scene);
        let o = cosim_tests::run(c);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{tables}");
        assert!(
            err.contains(field) && err.contains(words),
            "{tables}: {err}"
        );
    }
}

#[test]
fn adaptive_implicit_windows_follow_the_iterations_serial_and_concurrent() {
    for (name, extra) in [("serial", ""), ("concurrent", "concurrent = true\n")] {
        let dir = tempfile::tempdir().unwrap();
        // 12 ms: the fall and the first impacts
        let text = cosim_tests::plate_with(
            "implicit",
            "0.08 ms",
            &format!(
                "[coupling.implicit]\n{extra}[coupling.adaptive]\nmin_window = \"10 us\"\nmax_window = \"0.32 ms\"\niterations = 4\n"
            ),
        )
        .replace("end_time = \"30 ms\"", "end_time = \"12 ms\"");
        let s = run_scene(dir.path(), "plate.toml", &text);
        assert_eq!(s["status"], "completed", "{name}: {s}");
        let csv = std::fs::read_to_string(dir.path().join("out-plate.toml/windows.csv")).unwrap();
        let column = |c: &str| -> Vec<f64> {
            cosim_tests::csv_column(&csv, c)
                .iter()
                .map(|v| v.parse().unwrap())
                .collect()
        };
        let (lengths, iterations, residuals) =
            (column("window_s"), column("iterations"), column("residual"));
        assert!(
            residuals.iter().all(|r| *r <= 1e-3),
            "{name}: {residuals:?}"
        );
        // free flight converges at once: the windows grow to the longest; the impacts need
        // iterations, and a window above the aim halves the next
        assert!(lengths.iter().any(|l| (l - 3.2e-4).abs() < 1e-12), "{name}");
        for k in 1..lengths.len() {
            if iterations[k - 1] > 4.0 {
                assert!(
                    lengths[k] <= 0.5 * lengths[k - 1] + 1e-12 || lengths[k] == 1e-5,
                    "{name}: window {k}"
                );
            }
        }
        let total: f64 = lengths.iter().sum();
        assert!((total - 0.012).abs() < 1e-9, "{name}: {total}");
        eprintln!(
            "adaptive implicit ({name}): {} windows, {} iterations",
            lengths.len(),
            s["coupling_iterations"]
        );
    }
}
