//! `cosim study`: a sweep writes its table and plots, names a failing combination, and a second
//! call reuses the runs it already has.

use std::path::Path;
use std::process::Output;

use cosim_tests::{cosim, run};

/// `cosim study scenes/minimal.toml --vary dem.time_step=<steps>` comparing the kinetic
/// energy, into `out`.
fn study_of_minimal(out: &Path, steps: &str) -> Output {
    let mut c = cosim();
    c.args([
        "study",
        "scenes/minimal.toml",
        "--vary",
        &format!("dem.time_step={steps}"),
        "--metric",
        "dem.kinetic_energy",
        "--out",
    ])
    .arg(out);
    run(c)
}

/// The data rows of a study.csv, split into cells.
fn rows(csv: &str) -> Vec<Vec<&str>> {
    csv.lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect()
}

#[test]
fn study_sweeps_marks_failures_and_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("study");
    let study = || study_of_minimal(&out, "1e-5,2e-5,3e-5");
    assert!(study().status.success());
    let csv = std::fs::read_to_string(out.join("study.csv")).unwrap();
    let rows = rows(&csv);
    assert_eq!(rows.len(), 3);
    // header: run,dem.time_step,status,...
    assert_eq!(rows[0][2], "completed");
    assert_eq!(rows[1][2], "completed");
    // 10 ms windows are not a whole number of 3e-5 s steps: that run fails, named as such
    assert_eq!(rows[2][2], "failed");
    let err = std::fs::read_to_string(out.join("run002/summary.json")).unwrap();
    assert!(err.contains("not a whole multiple"), "{err}");
    assert_eq!(
        rows[0].last(),
        Some(&"true"),
        "the finest completed run is the reference"
    );
    for plot in ["error_vs_wall.svg", "stability.svg"] {
        assert!(std::fs::read_to_string(out.join(plot))
            .unwrap()
            .starts_with("<svg"));
    }
    // a second call finds every run done and does not run it again
    let before = std::fs::metadata(out.join("run000/summary.json"))
        .unwrap()
        .modified()
        .unwrap();
    assert!(study().status.success());
    let after = std::fs::metadata(out.join("run000/summary.json"))
        .unwrap()
        .modified()
        .unwrap();
    assert_eq!(before, after);
}

#[test]
fn a_study_where_no_run_completes_still_writes_its_table_and_stability_map() {
    // 10 ms windows are not whole multiples of 3e-5 s or 7e-5 s DEM steps: both runs fail
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("study");
    let o = study_of_minimal(&out, "3e-5,7e-5");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(stderr.contains("no run of the study completed"), "{stderr}");
    let csv = std::fs::read_to_string(out.join("study.csv")).unwrap();
    let rows = rows(&csv);
    assert_eq!(rows.len(), 2);
    for r in &rows {
        assert_eq!(r[2], "failed", "{csv}");
        assert_eq!(r.last(), Some(&"false"), "no reference: {csv}");
    }
    assert!(std::fs::read_to_string(out.join("stability.svg"))
        .unwrap()
        .starts_with("<svg"));
}
