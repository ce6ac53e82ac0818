//! The headline of Ullrich ch. 6 (REFERENCE A5): on the sleeper scene the predictive schedule
//! stays stable with a coupling window at least 10× longer than the just-in-time schedule's
//! (seed: 1e-4 s vs 1e-5 s). `cosim study` sweeps the window for both schedules on the CI variant
//! (scenes/sleeper-ci.toml) and the largest stable window of each is read from study.csv.

use cosim_tests::{cosim, run};

/// Largest window whose run completed, per schedule, from study.csv.
fn largest_stable(csv: &str, schedule: &str) -> Option<f64> {
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (w, s, st) = (
        col("coupling.window"),
        col("coupling.schedule"),
        col("status"),
    );
    lines
        .map(|l| l.split(',').collect::<Vec<_>>())
        .filter(|r| r[s] == schedule && r[st] == "completed")
        .map(|r| r[w].parse::<f64>().unwrap())
        .fold(None, |a: Option<f64>, x| Some(a.map_or(x, |a| a.max(x))))
}

#[test]
fn predictive_allows_a_coupling_window_ten_times_the_just_in_time_one() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("study");
    let mut c = cosim();
    c.args([
        "study",
        "scenes/sleeper-ci.toml",
        "--vary",
        "coupling.window=5e-6,1e-5,5e-5,1e-4,2e-4",
        "--vary",
        "coupling.schedule=jit,predictive",
        "--series",
        "fem/fem_probes.csv:probe.seat.uz",
        "--jobs",
        "1",
        "--out",
    ])
    .arg(&out);
    assert!(run(c).status.success());
    let csv = std::fs::read_to_string(out.join("study.csv")).unwrap();
    let jit = largest_stable(&csv, "jit").expect("some JIT window is stable");
    let predictive = largest_stable(&csv, "predictive").expect("some predictive window is stable");
    eprintln!("largest stable window: JIT {jit:e} s, predictive {predictive:e} s");
    assert!(
        predictive >= 10.0 * jit,
        "predictive {predictive:e} s vs JIT {jit:e} s\n{csv}"
    );
    // every unstable run was stopped by the monitor with its cause, none ran on with NaNs
    for l in csv.lines().skip(1).filter(|l| l.contains(",unstable,")) {
        let run = l.split(',').next().unwrap();
        let s = std::fs::read_to_string(out.join(run).join("summary.json")).unwrap();
        assert!(s.contains("unstable at window"), "{s}");
    }
    // the sweep found the limits rather than stopping short of them: the next window of each
    // schedule is not a stable run
    let status = |schedule: &str, window: &str| -> String {
        csv.lines()
            .map(|l| l.split(',').collect::<Vec<_>>())
            .find(|r| r[1] == window && r[2] == schedule)
            .map(|r| r[3].to_string())
            .unwrap()
    };
    assert_ne!(status("jit", "1e-5"), "completed", "{csv}");
    assert_ne!(status("predictive", "2e-4"), "completed", "{csv}");
    for plot in ["error_vs_wall.png", "stability.png"] {
        assert!(out.join(plot).exists(), "{plot}");
    }
}
