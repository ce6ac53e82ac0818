//! Runs that can be trusted: output folders that cannot lie (a lock, no mixing with an earlier
//! run, `--overwrite`), interrupts (SIGINT / SIGTERM stop the nodes, checkpoint, `interrupted`),
//! nodes that end with their coordinator's process, and resume refusing another scene's
//! checkpoint. Every case runs the real `cosim` and node processes on real folders.

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use cosim_tests::{bin, cosim, pid_of, root, run, summary, wait_for_windows, write_scene};

/// The minimal DEM scene with its end time and extra `[output]` lines.
fn minimal(dir: &Path, name: &str, end_time: &str, output: &str) -> std::path::PathBuf {
    let text = std::fs::read_to_string(root().join("scenes/minimal.toml"))
        .unwrap()
        .replace(
            "end_time = \"0.2 s\"",
            &format!("end_time = \"{end_time}\""),
        )
        .replace("[coupling]", &format!("[output]\n{output}\n\n[coupling]"));
    write_scene(dir, name, &text)
}

fn start(scene: &Path, out: &Path, run_id: &str, extra: &[&str]) -> Child {
    let mut c = cosim();
    c.arg("run")
        .arg(scene)
        .args(["--no-progress", "--run-id", run_id, "--out"])
        .arg(out)
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    c.spawn().unwrap()
}

fn signal(pid: u32, sig: &str) {
    let ok = Command::new("kill")
        .args([&format!("-{sig}"), &pid.to_string()])
        .status()
        .unwrap();
    assert!(ok.success(), "kill -{sig} {pid}");
}

/// Waits (at most `limit`) until no process of `run_id`'s nodes is left.
fn nodes_gone(run_id: &str, limit: Duration) {
    let t = Instant::now();
    while pid_of(&["-node", run_id]).is_some() {
        assert!(
            t.elapsed() < limit,
            "node processes of {run_id} still running after {limit:?}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn exit_with(child: Child, limit: Duration) -> (i32, String) {
    let t = Instant::now();
    let mut child = child;
    while child.try_wait().unwrap().is_none() {
        assert!(t.elapsed() < limit, "cosim did not end within {limit:?}");
        std::thread::sleep(Duration::from_millis(20));
    }
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    eprintln!("--- stderr\n{err}");
    (o.status.code().unwrap_or(-1), err)
}

#[test]
fn a_second_run_into_a_folder_is_refused_until_overwrite_which_starts_it_fresh() {
    let dir = tempfile::tempdir().unwrap();
    let scene = minimal(dir.path(), "m.toml", "0.05 s", "");
    let out = dir.path().join("out");
    let go = |extra: &[&str]| {
        let mut c = cosim();
        c.arg("run")
            .arg(&scene)
            .args(["--no-progress", "--out"])
            .arg(&out)
            .args(extra);
        run(c)
    };
    assert!(go(&[]).status.success());
    let first = std::fs::read_to_string(out.join("summary.json")).unwrap();
    // an earlier run's files, as another scene would leave them
    std::fs::create_dir_all(out.join("fem")).unwrap();
    std::fs::write(out.join("fem/fem_probes.csv"), "time,probe.x.uz\n0.1,1\n").unwrap();

    let o = go(&[]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("a run of scene `minimal` (status `completed`)")
            && err.contains("--overwrite"),
        "{err}"
    );
    // nothing was touched
    assert_eq!(
        std::fs::read_to_string(out.join("summary.json")).unwrap(),
        first
    );
    assert!(out.join("fem/fem_probes.csv").exists());

    assert!(go(&["--overwrite"]).status.success());
    assert!(
        !out.join("fem").exists(),
        "the earlier run's files are gone"
    );
    let csv = std::fs::read_to_string(out.join("dem/dem_timeseries.csv")).unwrap();
    assert_eq!(
        csv.lines().filter(|l| l.starts_with("time")).count(),
        1,
        "one header: {csv}"
    );
    let times: Vec<f64> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap().parse().unwrap())
        .collect();
    assert_eq!(times.len(), 5, "one row per window: {csv}");
    assert!(
        times.windows(2).all(|w| w[1] > w[0]),
        "time runs forward: {csv}"
    );
    assert_eq!(summary(&out)["status"], "completed");

    // a folder of the user's own files is never cleared
    let mine = dir.path().join("mine");
    std::fs::create_dir_all(&mine).unwrap();
    std::fs::write(mine.join("notes.txt"), "keep").unwrap();
    let mut c = cosim();
    c.arg("run")
        .arg(&scene)
        .args(["--no-progress", "--overwrite", "--out"])
        .arg(&mine);
    let o = run(c);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("not a cosim run's"));
    assert_eq!(
        std::fs::read_to_string(mine.join("notes.txt")).unwrap(),
        "keep"
    );
}

#[test]
fn a_run_holds_its_folder_and_sigterm_stops_it_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let scene = minimal(dir.path(), "long.toml", "60 s", "");
    let out = dir.path().join("out");
    let run_id = format!("trust-term-{}", std::process::id());
    let mut first = start(&scene, &out, &run_id, &[]);
    wait_for_windows(&out, 3, &mut first, Duration::from_secs(60));
    assert_eq!(summary(&out)["status"], "running");

    // a second run into the same folder, even with --overwrite, is refused naming the first
    let mut c = cosim();
    c.arg("run")
        .arg(&scene)
        .args(["--no-progress", "--overwrite", "--out"])
        .arg(&out);
    let o = run(c);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains(&format!("in use by another cosim process {}", first.id())),
        "{err}"
    );
    assert_eq!(summary(&out)["status"], "running");

    signal(first.id(), "TERM");
    let (code, err) = exit_with(first, Duration::from_secs(30));
    assert_eq!(code, 143, "the conventional exit code of SIGTERM: {err}");
    assert!(err.contains("interrupted by SIGTERM"), "{err}");
    let s = summary(&out);
    assert_eq!(s["status"], "interrupted", "{s}");
    assert!(s["windows_done"].as_u64().unwrap() >= 3, "{s}");
    nodes_gone(&run_id, Duration::from_secs(5));
    // the DEM node was stopped, not killed: its log says so
    let log = std::fs::read_to_string(out.join("logs/dem.log")).unwrap();
    assert!(log.contains("stop: the run was interrupted"), "{log}");
}

#[test]
fn ctrl_c_checkpoints_and_resume_continues_bitwise() {
    let dir = tempfile::tempdir().unwrap();
    // 500 windows: the signal lands long before the end, however busy the machine
    let scene = minimal(
        dir.path(),
        "ck.toml",
        "5 s",
        "checkpoint_every = 100000\nfinal_state = true",
    );
    let whole = dir.path().join("whole");
    let mut c = cosim();
    c.arg("run")
        .arg(&scene)
        .args(["--no-progress", "--out"])
        .arg(&whole);
    assert!(run(c).status.success());

    let broken = dir.path().join("broken");
    let run_id = format!("trust-int-{}", std::process::id());
    let mut child = start(&scene, &broken, &run_id, &[]);
    wait_for_windows(&broken, 20, &mut child, Duration::from_secs(60));
    signal(child.id(), "INT");
    let (code, err) = exit_with(child, Duration::from_secs(30));
    assert_eq!(code, 130, "{err}");
    let s = summary(&broken);
    assert_eq!(s["status"], "interrupted", "{s}");
    let done = s["windows_done"].as_u64().unwrap();
    assert!((20..500).contains(&done), "{s}");
    // the checkpoint of the interrupt (checkpoint_every alone would have made none yet)
    let latest: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(broken.join("checkpoints/latest.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(latest["window"].as_u64(), Some(done - 1), "{latest}");
    nodes_gone(&run_id, Duration::from_secs(5));

    let mut c = cosim();
    c.arg("resume").arg(&broken).arg("--no-progress");
    assert!(run(c).status.success());
    let s = summary(&broken);
    assert_eq!(s["status"], "completed");
    assert_eq!(s["resumes"], 1);
    let t = &s["timing"];
    let total = t["total_wall_s"].as_f64().unwrap();
    assert!(
        total >= t["windows_wall_s"].as_f64().unwrap() + t["startup_s"].as_f64().unwrap() - 1e-9,
        "the resumed run's total wall time holds its parts: {t}"
    );
    let state = |d: &Path| std::fs::read(d.join("final/dem.state")).unwrap();
    assert!(
        state(&whole) == state(&broken),
        "resumed final state differs"
    );
    for csv in ["windows.csv", "dem/dem_timeseries.csv"] {
        let rows = |d: &Path| {
            std::fs::read_to_string(d.join(csv))
                .unwrap()
                .lines()
                .map(|l| l.split(',').take(2).collect::<Vec<_>>().join(","))
                .collect::<Vec<_>>()
        };
        if csv == "windows.csv" {
            // wall times differ; windows and times do not
            assert_eq!(rows(&whole), rows(&broken), "{csv}");
        } else {
            assert_eq!(
                std::fs::read_to_string(whole.join(csv)).unwrap(),
                std::fs::read_to_string(broken.join(csv)).unwrap(),
                "{csv}"
            );
        }
    }
}

#[test]
fn resume_refuses_a_checkpoint_of_another_scene_and_touches_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let scene = minimal(dir.path(), "a.toml", "0.1 s", "checkpoint_every = 3");
    let out = dir.path().join("out");
    let mut c = cosim();
    c.arg("run")
        .arg(&scene)
        .args(["--no-progress", "--out"])
        .arg(&out);
    assert!(run(c).status.success());
    // the folder's scene is now another one (as an earlier version of cosim could leave it)
    let other = std::fs::read_to_string(&scene)
        .unwrap()
        .replace("name = \"minimal\"", "name = \"other\"");
    std::fs::write(out.join("scene.toml"), &other).unwrap();
    let before = std::fs::read(out.join("summary.json")).unwrap();
    let mut c = cosim();
    c.arg("resume").arg(&out).arg("--no-progress");
    let o = run(c);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("written by a run of scene `minimal`") && err.contains("`other`"),
        "{err}"
    );
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), before);
    // the folder's own scene: the run completed, nothing to resume
    std::fs::write(out.join("scene.toml"), std::fs::read(&scene).unwrap()).unwrap();
    let mut c = cosim();
    c.arg("resume").arg(&out).arg("--no-progress");
    let o = run(c);
    assert!(!o.status.success());
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("completed; there is nothing to resume"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), before);
    // comments edited since: the same settings, so the checkpoint is its own (and the run
    // is complete)
    std::fs::write(
        out.join("scene.toml"),
        format!(
            "# notes added later\n{}",
            std::fs::read_to_string(&scene).unwrap()
        ),
    )
    .unwrap();
    let mut c = cosim();
    c.arg("resume").arg(&out).arg("--no-progress");
    let o = run(c);
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("completed; there is nothing to resume"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    // the same name with other settings is refused
    let changed = std::fs::read_to_string(&scene)
        .unwrap()
        .replace("friction = 0.3", "friction = 0.4");
    std::fs::write(out.join("scene.toml"), &changed).unwrap();
    let mut c = cosim();
    c.arg("resume").arg(&out).arg("--no-progress");
    let o = run(c);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("refusing to resume a different scene") && err.contains("with other settings"),
        "{err}"
    );
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), before);
}

#[test]
fn a_node_ends_when_its_coordinator_process_is_gone() {
    // a stand-in coordinator process; the node is not its child, so it watches the pid
    let mut parent = Command::new("sleep").arg("1").spawn().unwrap();
    let port = proto::link::free_loopback_port().unwrap();
    let node = Command::new(bin("dem-node"))
        .args([
            "--run-id",
            &format!("orphan-{}", std::process::id()),
            "--node",
            "dem",
            "--listen",
            &format!("tcp/127.0.0.1:{port}"),
        ])
        .env(proto::node::COORDINATOR_PID_ENV, parent.id().to_string())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // reaped: the process is gone (a zombie would still exist)
    parent.wait().unwrap();
    let (code, err) = exit_with(node, Duration::from_secs(10));
    assert_eq!(code, 3, "{err}");
    assert!(
        err.contains(&format!(
            "the coordinator (process {}) is gone",
            parent.id()
        )),
        "{err}"
    );
}

#[test]
fn a_fem_scene_error_stops_the_waiting_dem_node_at_once() {
    // the FEM refuses its table; the DEM is then waiting for the interface mesh and must take
    // the coordinator's `stop` there (it used to be killed after a 5 s grace)
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(root().join("scenes/plate.toml"))
        .unwrap()
        .replacen("[fem]", "[fem]\nnot_a_key = 1", 1);
    let scene = write_scene(dir.path(), "bad-fem.toml", &text);
    let out = dir.path().join("out");
    let t0 = Instant::now();
    let mut c = cosim();
    c.arg("run")
        .arg(&scene)
        .args(["--no-progress", "--out"])
        .arg(&out);
    let o = run(c);
    eprintln!("the run failed after {:.2} s", t0.elapsed().as_secs_f64());
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("not_a_key"), "{err}");
    let dem = std::fs::read_to_string(out.join("logs/dem.log")).unwrap();
    assert!(
        dem.contains("stopped by the coordinator"),
        "the DEM node left on the coordinator's stop: {dem}"
    );
    assert_eq!(summary(&out)["status"], "failed");
}

#[test]
fn counts_beyond_the_machine_are_scene_errors_not_aborts() {
    let dir = tempfile::tempdir().unwrap();
    let base = std::fs::read_to_string(root().join("scenes/plate.toml")).unwrap();
    let fem_table = base.find("[fem]").unwrap();
    let cases = [
        (
            "lattice",
            std::fs::read_to_string(root().join("scenes/minimal.toml"))
                .unwrap()
                .replace("count = [3, 3, 3]", "count = [10000, 10000, 10000]"),
            "dem.particles[0].count",
        ),
        (
            "threads",
            std::fs::read_to_string(root().join("scenes/minimal.toml"))
                .unwrap()
                .replace("time_step = 1e-5", "time_step = 1e-5\nthreads = 1000000"),
            "dem.threads",
        ),
        (
            "mesh",
            format!(
                "{}[fem]\nmesh = {{ size = [1.0, 1.0, 1.0], divisions = [2000, 2000, 200], element = \"hex8\" }}\n{}",
                &base[..fem_table],
                &base[fem_table..]
                    .lines()
                    .skip(1)
                    .filter(|l| !l.starts_with("mesh"))
                    .collect::<Vec<_>>()
                    .join("\n")
            ),
            "fem.mesh.divisions",
        ),
    ];
    for (name, text, field) in cases {
        let scene = write_scene(dir.path(), &format!("{name}.toml"), &text);
        let out = dir.path().join(name);
        let mut c = cosim();
        c.arg("run")
            .arg(&scene)
            .args(["--no-progress", "--out"])
            .arg(&out);
        let o = run(c);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{name}: {err}");
        assert!(err.contains(field), "{name}: {err}");
        assert!(!err.contains("panicked"), "{name}: {err}");
        if name != "threads" {
            assert!(
                err.contains("needs ≈") && err.contains("available"),
                "{name}: {err}"
            );
        }
        assert_eq!(summary(&out)["status"], "failed", "{name}");
    }
}

#[test]
fn cosim_check_never_deletes_an_existing_folder() {
    // `cosim check --out <a finished run>` used to delete that folder after the check
    let dir = tempfile::tempdir().unwrap();
    let scene = minimal(dir.path(), "m.toml", "0.02 s", "");
    let out = dir.path().join("out");
    let mut c = cosim();
    c.arg("run")
        .arg(&scene)
        .args(["--no-progress", "--out"])
        .arg(&out);
    assert!(run(c).status.success());
    let before = std::fs::read(out.join("summary.json")).unwrap();
    let mut c = cosim();
    c.arg("check").arg(&scene).arg("--out").arg(&out);
    let o = run(c);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("give an empty or new one"), "{err}");
    assert_eq!(std::fs::read(out.join("summary.json")).unwrap(), before);
    // an empty folder given to a check is used and kept
    let scratch = dir.path().join("scratch");
    std::fs::create_dir_all(&scratch).unwrap();
    let mut c = cosim();
    c.arg("check").arg(&scene).arg("--out").arg(&scratch);
    assert!(run(c).status.success());
    assert!(scratch.exists());
}

#[test]
fn a_long_wait_for_a_node_is_reported_while_it_lasts() {
    // the DEM node is external and never comes: the coordinator waits for its hello (120 s)
    // and says so every quarter of window_timeout (0.5 s here); SIGTERM then ends the wait
    let dir = tempfile::tempdir().unwrap();
    let scene = minimal(dir.path(), "waiting.toml", "0.2 s", "");
    let text = std::fs::read_to_string(&scene)
        .unwrap()
        .replace("[coupling]", "[coupling]\nwindow_timeout = 2.0");
    std::fs::write(&scene, text).unwrap();
    let run_id = format!("waiting-{}", std::process::id());
    let child = start(
        &scene,
        &dir.path().join("out"),
        &run_id,
        &["--external", "dem"],
    );
    std::thread::sleep(Duration::from_millis(2500));
    signal(child.id(), "TERM");
    let (code, err) = exit_with(child, Duration::from_secs(30));
    assert_eq!(code, 143, "{err}");
    let notices = err
        .matches("still waiting for hello from dem: no message for")
        .count();
    assert!((2..=6).contains(&notices), "{notices} notices: {err}");
    assert!(err.contains("no message for 0.5 s"), "{err}");
}
