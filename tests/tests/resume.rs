//! Checkpoint and resume: a run killed in the middle and resumed ends in the same final state,
//! bit for bit, as a run that was never interrupted.

use std::path::Path;

use cosim_tests::{cosim, root, run, summary, write_scene};

fn plate_scene(dir: &Path, schedule: &str, tables: &str) -> std::path::PathBuf {
    let text = std::fs::read_to_string(root().join("scenes/plate.toml"))
        .unwrap()
        .replace(
            "schedule = \"predictive\"",
            // JIT's window limit here is 14 µs: this test is about resuming, at 100 µs
            &format!(
                "schedule = \"{schedule}\"\nforce_averaging = true\nallow_beyond_limits = true"
            ),
        )
        .replace(
            "end_time = \"30 ms\"",
            "end_time = \"12 ms\"\n[output]\ncheckpoint_every = 10\nfinal_state = true",
        )
        + "\n"
        + tables;
    // adaptive windows start on their ladder (10 µs × 2^3)
    let text = if tables.contains("adaptive") {
        text.replace("window = \"0.1 ms\"", "window = \"0.08 ms\"")
    } else {
        text
    };
    write_scene(dir, "plate.toml", &text)
}

fn read(p: &Path) -> Vec<u8> {
    std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Runs the scene, kills `victim` (`dem`, `fem` or `cosim`) once the checkpoint after window
/// 49 exists, resumes, and compares the final states with an uninterrupted run.
fn killed_and_resumed_equals_uninterrupted(schedule: &str, victim: &str) {
    killed_and_resumed_equals_uninterrupted_with(schedule, "", victim)
}

/// As [`killed_and_resumed_equals_uninterrupted`], with `tables` appended to the scene.
fn killed_and_resumed_equals_uninterrupted_with(schedule: &str, tables: &str, victim: &str) {
    let dir = tempfile::tempdir().unwrap();
    let scene = plate_scene(dir.path(), schedule, tables);

    let (whole, broken, _) =
        cosim_tests::whole_and_resumed(dir.path(), &scene, "resume", 49, victim);
    let s = summary(&broken);
    assert_eq!(s["status"], "completed");
    // fixed windows: 120; adaptive: as many as the uninterrupted run had
    let windows_done = summary(&whole)["windows_done"].as_u64().unwrap();
    assert!(tables.contains("adaptive") || windows_done == 120);
    assert_eq!(s["windows_done"], windows_done);
    let resumed_after = s["resumed_after_window"].as_u64().unwrap();
    assert!(resumed_after >= 49, "{s}");
    for node in ["dem", "fem"] {
        let a = read(&whole.join(format!("final/{node}.state")));
        let b = read(&broken.join(format!("final/{node}.state")));
        assert!(
            a == b,
            "{node}: the resumed final state differs from the uninterrupted run ({} vs {} bytes)",
            a.len(),
            b.len()
        );
    }
    let csv = std::fs::read_to_string(broken.join("windows.csv")).unwrap();
    let windows: Vec<u64> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap().parse().unwrap())
        .collect();
    assert_eq!(
        windows,
        (0..windows_done).collect::<Vec<_>>(),
        "one row per window, none twice"
    );
    assert_eq!(
        summary(&whole)["results"]["fem.probe.centre.uz"],
        s["results"]["fem.probe.centre.uz"]
    );
    // the nodes' time series continue from the checkpoint: the rows the interrupted run wrote
    // after it are not there twice, so the files equal the uninterrupted run's
    for csv in ["dem/dem_timeseries.csv", "fem/fem_probes.csv"] {
        let a = String::from_utf8(read(&whole.join(csv))).unwrap();
        let b = String::from_utf8(read(&broken.join(csv))).unwrap();
        // a header and a row per window (an implicit scheme's abandoned iterations leave none
        // and take none away)
        assert_eq!(a.lines().count() as u64, windows_done + 1, "{csv}");
        assert!(
            a == b,
            "{csv}: the resumed run's rows differ from the uninterrupted run's"
        );
    }
}

#[test]
fn predictive_run_with_dem_killed_resumes_bitwise_equal() {
    killed_and_resumed_equals_uninterrupted("predictive", "dem");
}

#[test]
fn jit_run_with_fem_killed_resumes_bitwise_equal() {
    killed_and_resumed_equals_uninterrupted("jit", "fem");
}

#[test]
fn implicit_run_with_fem_killed_resumes_bitwise_equal() {
    // the acceleration's state (the next window's force estimate) is in the coordinator's
    // checkpoint, the nodes' window checkpoints are not needed across a restart
    killed_and_resumed_equals_uninterrupted("implicit", "fem");
}

#[test]
fn concurrent_run_with_dem_killed_resumes_bitwise_equal() {
    // the DEM's forces of the window before and the FEM's end state are both in flight at a
    // checkpoint: the restored nodes publish both again
    killed_and_resumed_equals_uninterrupted("concurrent", "dem");
}

#[test]
fn concurrent_implicit_run_with_dem_killed_resumes_bitwise_equal() {
    // the position estimate and the acceleration's scales are in the coordinator's checkpoint
    killed_and_resumed_equals_uninterrupted_with(
        "implicit",
        "[coupling.implicit]\nconcurrent = true",
        "dem",
    );
}

#[test]
fn adaptive_run_with_fem_killed_resumes_bitwise_equal() {
    // the clock, the controller and the window being observed are in the coordinator's
    // checkpoint: the resumed run chooses the same windows
    killed_and_resumed_equals_uninterrupted_with(
        "predictive",
        "[coupling.adaptive]\nmin_window = \"10 us\"\nmax_window = \"0.08 ms\"",
        "fem",
    );
}

#[test]
fn run_with_the_coordinator_killed_resumes_bitwise_equal() {
    killed_and_resumed_equals_uninterrupted("predictive", "cosim");
}

/// `checkpoint_wall`: checkpoints by wall time alone (no window count), taken while windows
/// are announced ahead (the predictive schedule holds them, checkpoints, and goes on); a run
/// killed after one resumes bitwise.
#[test]
fn wall_time_checkpoints_resume_bitwise_equal() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(plate_scene(dir.path(), "predictive", ""))
        .unwrap()
        .replace("checkpoint_every = 10", "checkpoint_wall = \"0.05 s\"")
        .replace("end_time = \"12 ms\"", "end_time = \"30 ms\"");
    assert!(text.contains("checkpoint_wall") && !text.contains("checkpoint_every"));
    let scene = write_scene(dir.path(), "plate.toml", &text);
    let (whole, broken, _) = cosim_tests::whole_and_resumed(dir.path(), &scene, "wall", 1, "dem");
    let checkpoints = std::fs::read_dir(whole.join("checkpoints"))
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with('w'))
        .count();
    assert!(
        checkpoints >= 2,
        "{checkpoints} checkpoints in the whole run"
    );
    let s = summary(&broken);
    assert_eq!(s["status"], "completed");
    let resumed_after = s["resumed_after_window"].as_u64().unwrap();
    let windows = s["windows_done"].as_u64().unwrap();
    assert!(resumed_after >= 1 && resumed_after + 10 < windows, "{s}");
    assert!(
        s["windows_announced_ahead"].as_u64().unwrap() > 0,
        "the predictive schedule announced windows ahead: {s}"
    );
    assert_eq!(s["windows_done"], summary(&whole)["windows_done"]);
    for node in ["dem", "fem"] {
        let a = read(&whole.join(format!("final/{node}.state")));
        let b = read(&broken.join(format!("final/{node}.state")));
        assert!(a == b, "{node}: the resumed final state differs");
    }
}

#[test]
fn resume_without_a_checkpoint_says_how_to_get_one() {
    let dir = tempfile::tempdir().unwrap();
    let mut c = cosim();
    c.args(["run", "scenes/minimal.toml", "--no-progress", "--out"])
        .arg(dir.path());
    assert!(run(c).status.success());
    let mut c = cosim();
    c.arg("resume").arg(dir.path());
    let o = run(c);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("checkpoint_every"));
}

/// A periodic RVE (a DEM-only run whose programme of stages ends it) killed in the middle and
/// resumed from its checkpoint ends as the uninterrupted run: the same final state, the same
/// curves in dem/periodic.csv, the same number of windows — so long ensembles (`cosim study`
/// of seeded RVEs, hours each) continue where they stopped.
#[test]
fn a_periodic_rve_killed_in_its_programme_resumes_bitwise_equal() {
    let dir = tempfile::tempdir().unwrap();
    // the shear cut to 3 % (640 windows instead of 869): the checkpoint at window 299 is in
    // the middle of the programme's stages either way
    let text = std::fs::read_to_string(root().join("scenes/rve-triaxial-ci.toml"))
        .unwrap()
        .replace("strain = { z = -0.1 }", "strain = { z = -0.03 }")
        + "\n[output]\ncheckpoint_every = 100\nfinal_state = true\n";
    assert!(text.contains("z = -0.03"));
    let scene = write_scene(dir.path(), "rve.toml", &text);
    let (whole, broken, _) =
        cosim_tests::whole_and_resumed(dir.path(), &scene, "resume-rve", 299, "dem");
    let s = summary(&broken);
    assert_eq!(s["status"], "completed");
    assert!(s["resumed_after_window"].as_u64().unwrap() >= 299, "{s}");
    assert_eq!(s["windows_done"], summary(&whole)["windows_done"]);
    assert!(
        read(&whole.join("final/dem.state")) == read(&broken.join("final/dem.state")),
        "the resumed final state differs from the uninterrupted run's"
    );
    let a = String::from_utf8(read(&whole.join("dem/periodic.csv"))).unwrap();
    let b = String::from_utf8(read(&broken.join("dem/periodic.csv"))).unwrap();
    assert!(a.lines().count() > 300);
    assert!(a == b, "dem/periodic.csv: the resumed run's rows differ");
}
