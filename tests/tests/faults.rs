//! Faults during a run: a node that dies must end the run quickly, with its name and window.

use std::io::Read;
use std::process::Stdio;
use std::time::{Duration, Instant};

use cosim_tests::{cosim, kill, pid_of, root, signal, summary, wait_for_windows, write_scene};

/// Starts `cosim run` of `scene` into `out` with its stderr piped, and waits until `windows`
/// windows are done. Returns the process and the pid of its node `node`.
fn start_and_wait(
    scene: &std::path::Path,
    run_id: &str,
    out: &std::path::Path,
    windows: usize,
    node: &str,
) -> (std::process::Child, u32) {
    let mut child = cosim()
        .arg("run")
        .arg(scene)
        .args(["--no-progress", "--run-id", run_id, "--out"])
        .arg(out)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    wait_for_windows(out, windows, &mut child, Duration::from_secs(120));
    let pid = pid_of(&[&format!("{node}-node"), run_id]).expect("the node's process");
    (child, pid)
}

/// Waits at most `limit` after `since` for `child` to end (`what` names the wait in the
/// failure); its exit status and stderr.
fn wait_exit(
    child: &mut std::process::Child,
    since: Instant,
    limit: Duration,
    what: &str,
) -> (std::process::ExitStatus, String) {
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        assert!(
            since.elapsed() < limit,
            "cosim still running {limit:?} after {what}"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    let mut err = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    (status, err)
}

/// Runs `text` as a scene, kills node `victim` once `windows` windows are done, and waits (at
/// most 5 s) for cosim to end. Returns its exit status, its stderr and the output folder.
fn kill_mid_run(
    dir: &std::path::Path,
    text: &str,
    victim: &str,
    windows: usize,
) -> (std::process::ExitStatus, String, std::path::PathBuf) {
    let scene = write_scene(dir, "scene.toml", text);
    let out = dir.join("out");
    let run_id = format!("kill-{victim}-{}", std::process::id());
    let (mut child, pid) = start_and_wait(&scene, &run_id, &out, windows, victim);
    let killed = Instant::now();
    kill(pid);
    let (status, err) = wait_exit(
        &mut child,
        killed,
        Duration::from_secs(5),
        &format!("the {victim} node was killed"),
    );
    eprintln!(
        "cosim exited {status} {:.2} s after the kill:\n{err}",
        killed.elapsed().as_secs_f64()
    );
    (status, err, out)
}

#[test]
fn killing_the_dem_node_mid_run_ends_the_run_within_5_s_naming_the_node_and_window() {
    let dir = tempfile::tempdir().unwrap();
    // the minimal scene, made long enough to be killed in the middle
    let text = std::fs::read_to_string(root().join("scenes/minimal.toml"))
        .unwrap()
        .replace("end_time = \"0.2 s\"", "end_time = \"1000 s\"");
    let (status, err, out) = kill_mid_run(dir.path(), &text, "dem", 4);
    assert!(!status.success());
    assert!(err.contains("dem"), "{err}");
    assert!(err.contains("window"), "{err}");
    let s = summary(&out);
    assert_eq!(s["status"], "failed");
    assert!(s["error"].as_str().unwrap().contains("dem"), "{s}");
    // what was written so far is intact: the window table parses row by row
    let rows = std::fs::read_to_string(out.join("windows.csv")).unwrap();
    for row in rows.lines().skip(1) {
        assert_eq!(row.split(',').count(), 7, "{row}");
    }
}

#[test]
fn killing_the_fem_node_mid_iteration_of_an_implicit_run_ends_it_naming_node_and_window() {
    let dir = tempfile::tempdir().unwrap();
    // the plate, implicit, long enough to be killed while its windows iterate (past the first
    // impacts: windows 68 and on iterate several times)
    let text = std::fs::read_to_string(root().join("scenes/plate.toml"))
        .unwrap()
        .replace(
            "schedule = \"predictive\"",
            "schedule = \"implicit\"\nforce_averaging = true",
        )
        .replace("end_time = \"30 ms\"", "end_time = \"10 s\"");
    let (status, err, out) = kill_mid_run(dir.path(), &text, "fem", 75);
    assert!(!status.success());
    assert!(
        err.contains("node `fem`") && err.contains("window"),
        "{err}"
    );
    assert_eq!(summary(&out)["status"], "failed");
}

/// A node that does not run for longer than zenoh's usual 3 s lease (stopped here with
/// SIGSTOP, as a process starved of CPU on a busy machine would be) is not a dead node when
/// the coordinator started it on this host: the run goes on and ends as it would have.
#[test]
fn a_local_node_stalled_longer_than_three_seconds_does_not_end_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(root().join("scenes/plate.toml")).unwrap();
    let scene = write_scene(dir.path(), "plate.toml", &text);
    let out = dir.path().join("out");
    let run_id = format!("stall-{}", std::process::id());
    let (mut child, pid) = start_and_wait(&scene, &run_id, &out, 20, "dem");
    signal(pid, "STOP");
    // stopped in the middle of the run: windows are left
    let rows = |out: &std::path::Path| {
        std::fs::read_to_string(out.join("windows.csv"))
            .unwrap()
            .lines()
            .count()
            - 1
    };
    let done = rows(&out);
    std::thread::sleep(Duration::from_secs(6));
    signal(pid, "CONT");
    assert!(
        done < 250,
        "{done} of 300 windows were done before the stall"
    );
    let (status, err) = wait_exit(
        &mut child,
        Instant::now(),
        Duration::from_secs(300),
        "the stall",
    );
    assert!(status.success(), "{err}");
    let s = summary(&out);
    assert_eq!(s["status"], "completed", "{s}");
    // all 300 windows (plate.toml: 30 ms of 0.1 ms) are in the table
    assert!(text.contains("end_time = \"30 ms\"") && text.contains("window = \"0.1 ms\""));
    assert_eq!(rows(&out), 300);
}
