//! Faults during a run: a node that dies must end the run quickly, with its name and window.

use std::io::Read;
use std::process::Stdio;
use std::time::{Duration, Instant};

use cosim_tests::{cosim, kill, pid_of, root, summary, wait_for_windows, write_scene};

#[test]
fn killing_the_dem_node_mid_run_ends_the_run_within_5_s_naming_the_node_and_window() {
    let dir = tempfile::tempdir().unwrap();
    // the minimal scene, made long enough to be killed in the middle
    let text = std::fs::read_to_string(root().join("scenes/minimal.toml"))
        .unwrap()
        .replace("end_time = \"0.2 s\"", "end_time = \"1000 s\"");
    let scene = write_scene(dir.path(), "long.toml", &text);
    let out = dir.path().join("out");
    let run_id = format!("kill-{}", std::process::id());
    let mut c = cosim();
    c.arg("run")
        .arg(&scene)
        .args(["--no-progress", "--run-id", &run_id, "--out"])
        .arg(&out);
    let mut child = c
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();

    // wait until windows are being computed
    wait_for_windows(&out, 4, &mut child, Duration::from_secs(60));
    let csv = out.join("windows.csv");
    let pid = pid_of(&["dem-node", &run_id]).expect("the dem-node process");
    let killed = Instant::now();
    kill(pid);

    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        assert!(
            killed.elapsed() < Duration::from_secs(5),
            "cosim still running 5 s after the DEM node was killed"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    let elapsed = killed.elapsed();
    let mut err = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    eprintln!(
        "cosim exited {status} {:.2} s after the kill:\n{err}",
        elapsed.as_secs_f64()
    );
    assert!(!status.success());
    assert!(err.contains("dem"), "{err}");
    assert!(err.contains("window"), "{err}");
    let s = summary(&out);
    assert_eq!(s["status"], "failed");
    assert!(s["error"].as_str().unwrap().contains("dem"), "{s}");
    // what was written so far is intact: the window table parses row by row
    let rows = std::fs::read_to_string(&csv).unwrap();
    for row in rows.lines().skip(1) {
        assert_eq!(row.split(',').count(), 7, "{row}");
    }
}

#[test]
fn killing_the_fem_node_mid_iteration_of_an_implicit_run_ends_it_naming_node_and_window() {
    let dir = tempfile::tempdir().unwrap();
    // the plate, implicit, long enough to be killed while its windows iterate
    let text = std::fs::read_to_string(root().join("scenes/plate.toml"))
        .unwrap()
        .replace(
            "schedule = \"predictive\"",
            "schedule = \"implicit\"\nforce_averaging = true",
        )
        .replace("end_time = \"30 ms\"", "end_time = \"10 s\"");
    let scene = write_scene(dir.path(), "implicit.toml", &text);
    let out = dir.path().join("out");
    let run_id = format!("kill-implicit-{}", std::process::id());
    let mut c = cosim();
    c.arg("run")
        .arg(&scene)
        .args(["--no-progress", "--run-id", &run_id, "--out"])
        .arg(&out);
    let mut child = c
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // past the first impacts (window 68 and on iterate several times)
    wait_for_windows(&out, 75, &mut child, Duration::from_secs(120));
    let pid = pid_of(&["fem-node", &run_id]).expect("the fem-node process");
    let killed = Instant::now();
    kill(pid);
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        assert!(
            killed.elapsed() < Duration::from_secs(5),
            "cosim still running 5 s after the FEM node was killed"
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
    eprintln!("exited {status}:\n{err}");
    assert!(!status.success());
    assert!(err.contains("node `fem`") && err.contains("window"), "{err}");
    let s = summary(&out);
    assert_eq!(s["status"], "failed");
}
