//! `cosim study`: a sweep writes its table and plots, names a failing combination, and a second
//! call reuses the runs it already has.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Output;

use cosim_tests::{cosim, run};

/// `cosim study scenes/minimal.toml <args>` comparing the kinetic energy, into `out`.
fn study_minimal(out: &Path, args: &[&str]) -> Output {
    let mut c = cosim();
    c.args(["study", "scenes/minimal.toml"])
        .args(args)
        .args(["--metric", "dem.kinetic_energy", "--out"])
        .arg(out);
    run(c)
}

/// `cosim study scenes/minimal.toml --vary dem.time_step=<steps>` comparing the kinetic
/// energy, into `out`.
fn study_of_minimal(out: &Path, steps: &str) -> Output {
    study_minimal(out, &["--vary", &format!("dem.time_step={steps}")])
}

/// The data rows of a study.csv, split into cells.
fn rows(csv: &str) -> Vec<Vec<&str>> {
    csv.lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect()
}

#[test]
fn study_sweeps_and_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("study");
    let study = || study_of_minimal(&out, "1e-5,2e-5");
    assert!(study().status.success());
    let csv = std::fs::read_to_string(out.join("study.csv")).unwrap();
    let rows = rows(&csv);
    assert_eq!(rows.len(), 2);
    // header: run,dem.time_step,status,...
    assert_eq!(rows[0][2], "completed");
    assert_eq!(rows[1][2], "completed");
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
    // a run left `interrupted` (or `running`: it died with the study) is run again
    let s = out.join("run001/summary.json");
    let text = std::fs::read_to_string(&s).unwrap();
    std::fs::write(&s, text.replace("\"completed\"", "\"interrupted\"")).unwrap();
    assert!(study().status.success());
    assert!(std::fs::read_to_string(&s)
        .unwrap()
        .contains("\"completed\""));
}

/// Seeds varied: the runs of each case form an ensemble; `ensembles.csv` and the printed
/// summary give the metric's mean and spread over the seeds.
#[test]
fn a_study_over_seeds_reports_each_cases_mean_and_spread() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("seeds");
    let o = study_minimal(
        &out,
        &[
            "--vary",
            "dem.particles.0.jitter=1e-3",
            "--vary",
            "dem.time_step=1e-5,2e-5",
            "--vary",
            "dem.particles.0.seed=1,2,3",
            "--jobs",
            "2",
        ],
    );
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // the per-run values, by case
    let study = std::fs::read_to_string(out.join("study.csv")).unwrap();
    let header: Vec<&str> = study.lines().next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let mut by_step: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    for r in rows(&study) {
        assert_eq!(r[col("status")], "completed", "{r:?}");
        by_step
            .entry(r[col("dem.time_step")].to_string())
            .or_default()
            .push(r[col("dem.kinetic_energy")].parse().unwrap());
    }
    let ens = std::fs::read_to_string(out.join("ensembles.csv")).unwrap();
    let eh: Vec<&str> = ens.lines().next().unwrap().split(',').collect();
    assert_eq!(
        eh,
        [
            "dem.particles.0.jitter",
            "dem.time_step",
            "runs",
            "completed",
            "dem.kinetic_energy_mean",
            "dem.kinetic_energy_std_dev",
            "dem.kinetic_energy_min",
            "dem.kinetic_energy_max",
            "wall_mean_s"
        ]
    );
    let ens_rows = rows(&ens);
    assert_eq!(ens_rows.len(), 2);
    for r in ens_rows {
        let v = &by_step[r[1]];
        assert_eq!((r[2], r[3]), ("3", "3"));
        let mean = v.iter().sum::<f64>() / 3.0;
        let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / 2.0).sqrt();
        let got = |i: usize| r[i].parse::<f64>().unwrap();
        assert!(
            (got(4) - mean).abs() <= 1e-12 * mean.abs(),
            "{r:?} vs {v:?}"
        );
        assert!((got(5) - sd).abs() <= 1e-9 * sd.abs(), "{r:?} vs {v:?}");
        // the jittered lattices differ from seed to seed
        assert!(sd > 0.0, "{v:?}");
        assert!(
            stdout.contains(&format!("dem.time_step={}: dem.kinetic_energy", r[1])),
            "{stdout}"
        );
    }
    assert!(stdout.contains("(3 of 3 runs)"), "{stdout}");
}

/// `--jobs 2`: the two runs at once share the cores (each node's pool gets half of them),
/// where one run alone keeps them all.
#[test]
fn runs_of_a_study_at_once_share_the_cores() {
    if std::env::var_os("RAYON_NUM_THREADS").is_some() {
        eprintln!("RAYON_NUM_THREADS is set: the study keeps it, nothing to test");
        return;
    }
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let dir = tempfile::tempdir().unwrap();
    let threads = |out: &Path, run: &str| {
        let log = std::fs::read_to_string(out.join(run).join("logs/dem.log")).unwrap();
        let line = log
            .lines()
            .find(|l| l.contains("particles on"))
            .unwrap_or_else(|| panic!("no thread count in {run}'s DEM log:\n{log}"))
            .to_string();
        line.split("particles on ")
            .nth(1)
            .unwrap()
            .split(' ')
            .next()
            .unwrap()
            .parse::<usize>()
            .unwrap()
    };
    let study = |out: &Path, jobs: &str| {
        let o = study_minimal(out, &["--vary", "dem.time_step=1e-5,2e-5", "--jobs", jobs]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    };
    let two = dir.path().join("two");
    study(&two, "2");
    for r in ["run000", "run001"] {
        assert_eq!(threads(&two, r), (cores / 2).max(1), "{r}");
    }
    let one = dir.path().join("one");
    study(&one, "1");
    for r in ["run000", "run001"] {
        assert_eq!(threads(&one, r), cores, "{r}");
    }
}

/// Two studies of one scene at once, into two folders: each variant's scene file (beside the
/// user's scene, for its relative paths) is the study's own, so neither overwrites the
/// other's, and both complete.
#[test]
fn two_studies_of_one_scene_at_once_keep_their_variant_files_apart() {
    let dir = tempfile::tempdir().unwrap();
    let outs = [dir.path().join("a"), dir.path().join("b")];
    let handles: Vec<_> = outs
        .iter()
        .cloned()
        .map(|out| std::thread::spawn(move || study_of_minimal(&out, "1e-5")))
        .collect();
    for h in handles {
        let o = h.join().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    let files: Vec<String> = outs
        .iter()
        .map(|out| {
            let record = std::fs::read_to_string(out.join("run000/run.json")).unwrap();
            let v: serde_json::Value = serde_json::from_str(&record).unwrap();
            v["scene_file"].as_str().unwrap().to_string()
        })
        .collect();
    println!("{files:?}");
    assert!(
        files.iter().all(|f| f.contains(".study-minimal-")),
        "{files:?}"
    );
    assert_ne!(files[0], files[1]);
}

/// `cosim study scenes/minimal.toml --vary <vary>` that must be refused before any run: its
/// error output.
fn refused_study(out: &Path, vary: &str) -> String {
    let mut c = cosim();
    c.args(["study", "scenes/minimal.toml", "--vary", vary, "--out"])
        .arg(out);
    let o = run(c);
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(!o.status.success(), "{err}");
    assert!(!out.join("run000").exists(), "nothing was run");
    assert!(
        !err.contains(".study-"),
        "no temporary file is named: {err}"
    );
    err
}

#[test]
fn an_invalid_variant_refuses_the_study_before_any_run() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("study");
    // 10 ms windows are not a whole number of 3e-5 s steps (found by the DEM's check)
    let err = refused_study(&out, "dem.time_step=1e-5,3e-5");
    assert!(
        err.contains("scenes/minimal.toml with --vary dem.time_step=3e-5")
            && err.contains("not a whole multiple of the DEM time step Δt^D = 30 µs"),
        "{err}"
    );
    // a misspelt key: every variant is invalid, the key is named
    let err = refused_study(&out, "dem.time_stp=1e-5,2e-5");
    assert!(
        err.contains("scenes/minimal.toml with --vary dem.time_stp=1e-5: unknown field `time_stp`"),
        "{err}"
    );
    // a coordinator key out of range is found the same way
    let err = refused_study(&out, "coupling.max_force_growth=0.5");
    assert!(
        err.contains(
            "scenes/minimal.toml with --vary coupling.max_force_growth=0.5: coupling.max_force_growth"
        ),
        "{err}"
    );
}

#[test]
fn a_study_where_no_run_completes_still_writes_its_table_and_stability_map() {
    // no window's messages arrive within a microsecond: both runs fail (timed out)
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("study");
    let o = study_minimal(&out, &["--vary", "coupling.window_timeout=1e-6,2e-6"]);
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

#[test]
fn a_second_study_into_the_same_folder_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("study");
    let mut c = cosim();
    c.args([
        "study",
        "scenes/minimal.toml",
        "--vary",
        "scene.end_time=60",
        "--out",
    ])
    .arg(&out)
    .stdout(std::process::Stdio::null())
    .stderr(std::process::Stdio::null());
    let mut first = cosim_tests::Reaper(vec![c.spawn().unwrap()]);
    // its run is under way once the run's summary says so
    let t0 = std::time::Instant::now();
    while !std::fs::read_to_string(out.join("run000/summary.json"))
        .is_ok_and(|s| s.contains("\"running\""))
    {
        assert!(
            t0.elapsed() < std::time::Duration::from_secs(60),
            "the first study did not start"
        );
        assert!(
            first.0[0].try_wait().unwrap().is_none(),
            "the first study ended early"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let mut c = cosim();
    c.args([
        "study",
        "scenes/minimal.toml",
        "--vary",
        "scene.end_time=60",
        "--out",
    ])
    .arg(&out);
    let o = run(c);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{err}");
    assert!(
        err.contains("in use by another cosim process") && err.contains("study of scene `minimal`"),
        "{err}"
    );
    first.0[0].kill().unwrap();
}

/// A study killed half-way (a session's end, a crash) continues each unfinished run from its
/// newest checkpoint when the scene writes them, and ends as an uninterrupted study would,
/// bit for bit.
#[test]
fn a_study_stopped_half_way_continues_its_run_from_the_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    // a name of its own: its nodes are found by it after the study is killed
    let name = format!("study-resume-{}", std::process::id());
    let text = std::fs::read_to_string(cosim_tests::root().join("scenes/plate.toml"))
        .unwrap()
        .replace("name = \"plate\"", &format!("name = \"{name}\""))
        .replace(
            "end_time = \"30 ms\"",
            "end_time = \"12 ms\"\n[output]\ncheckpoint_every = 10\nfinal_state = true",
        );
    assert!(text.contains(&name) && text.contains("checkpoint_every"));
    let scene = cosim_tests::write_scene(dir.path(), "plate.toml", &text);
    let study = |out: &Path| {
        let mut c = cosim();
        c.arg("study")
            .arg(&scene)
            .args([
                "--vary",
                "coupling.window=1e-4",
                "--metric",
                "fem.probe.centre.uz",
                "--out",
            ])
            .arg(out);
        c
    };
    let whole = dir.path().join("whole");
    let o = run(study(&whole));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));

    let broken = dir.path().join("broken");
    let mut c = study(&broken);
    c.stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null());
    let mut child = c.spawn().unwrap();
    cosim_tests::wait_for_checkpoint(&broken.join("run000"), 49, &mut child);
    cosim_tests::kill(child.id());
    let _ = child.wait();
    // its nodes notice that their coordinator is gone and leave
    cosim_tests::wait_for_nodes_to_leave(&name);
    let s = cosim_tests::summary(&broken.join("run000"));
    assert_ne!(s["status"], "completed", "{s}");
    // a wall-time checkpoint period (and a comment) added meanwhile: the variant's text
    // differs, its settings do not, so the run continues
    let edited = text.replace(
        "checkpoint_every = 10",
        "checkpoint_every = 10 # a note\ncheckpoint_wall = \"1 h\"",
    );
    assert_ne!(edited, text);
    std::fs::write(
        &scene,
        format!("# edited while the study was stopped\n{edited}"),
    )
    .unwrap();

    let o = run(study(&broken));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("resuming after window"), "{err}");
    let s = cosim_tests::summary(&broken.join("run000"));
    assert_eq!(s["status"], "completed", "{s}");
    assert!(s["resumed_after_window"].as_u64().unwrap() >= 49, "{s}");
    assert_eq!(s["windows_done"], 120);
    // the run's folder has the text it went on with (after its next checkpoint)
    let kept = std::fs::read_to_string(broken.join("run000/scene.toml")).unwrap();
    assert!(kept.contains("checkpoint_wall"), "{kept}");
    for node in ["dem", "fem"] {
        let a = std::fs::read(whole.join(format!("run000/final/{node}.state"))).unwrap();
        let b = std::fs::read(broken.join(format!("run000/final/{node}.state"))).unwrap();
        assert!(a == b, "{node}: the resumed run's final state differs");
    }
    let a = std::fs::read_to_string(whole.join("run000/fem/fem_probes.csv")).unwrap();
    let b = std::fs::read_to_string(broken.join("run000/fem/fem_probes.csv")).unwrap();
    assert_eq!(a, b, "the probes' rows continue from the checkpoint");
    let csv = std::fs::read_to_string(broken.join("study.csv")).unwrap();
    assert_eq!(rows(&csv).len(), 1);
    assert_eq!(rows(&csv)[0][2], "completed", "{csv}");
}
