//! Hostile input into a live run: a rogue zenoh session joins the run's network and sends
//! garbage, messages of another run, another protocol version, NaN. Each is refused at the
//! boundary; the run continues or stops cleanly, as PROTOCOL.md says.

use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

use cosim_tests::{cosim, process_args, root, summary, wait_for_windows, write_scene};
use proto::{encode, InterfaceForces, LinkConfig, Status, StatusBody, PROTOCOL_VERSION};

fn start_plate(dir: &std::path::Path, end_time: &str, run_id: &str, port: u16) -> Child {
    let text = std::fs::read_to_string(root().join("scenes/plate.toml"))
        .unwrap()
        .replace(
            "end_time = \"30 ms\"",
            &format!("end_time = \"{end_time}\""),
        );
    let scene = write_scene(dir, "plate.toml", &text);
    let mut c = cosim();
    c.arg("run")
        .arg(&scene)
        .args([
            "--no-progress",
            "--run-id",
            run_id,
            "--listen",
            &format!("tcp/127.0.0.1:{port}"),
            "--out",
        ])
        .arg(dir.join("out"))
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    c.spawn().unwrap()
}

/// The `--listen` port of the run's node process `node`.
fn node_port(node: &str, run_id: &str) -> u16 {
    let (_, args) = process_args(&[&format!("{node}-node"), run_id])
        .unwrap_or_else(|| panic!("no {node}-node in run {run_id}"));
    let i = args.iter().position(|a| a == "--listen").expect("--listen");
    args[i + 1].rsplit(':').next().unwrap().parse().unwrap()
}

/// A session on the run's network, linked to the coordinator and to both nodes.
async fn rogue(port: u16, run_id: &str) -> zenoh::Session {
    let ports = [port, node_port("dem", run_id), node_port("fem", run_id)];
    let s = LinkConfig::loopback_peer(None, &ports)
        .open()
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(300)).await;
    s
}

fn forces(run_id: &str, window: u64, value: f64) -> InterfaceForces {
    InterfaceForces {
        version: PROTOCOL_VERSION,
        run_id: run_id.into(),
        interface: "top".into(),
        window,
        iteration: 0,
        time: 0.0,
        forces: vec![value; 3 * 169].into(),
        averaged: false,
        samples: 1,
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn garbage_wrong_run_and_wrong_version_are_refused_and_the_run_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let port = proto::link::free_loopback_port().unwrap();
    let run_id = format!("hostile-a-{}", std::process::id());
    // long enough (≈ 4 s) that the rogue messages below arrive while the run is going: 600
    // windows took under a second on an idle machine and the run could end before them
    let mut child = start_plate(dir.path(), "300 ms", &run_id, port);
    wait_for_windows(
        &dir.path().join("out"),
        5,
        &mut child,
        Duration::from_secs(60),
    );
    let s = rogue(port, &run_id).await;
    let keys = proto::Keys::new(&run_id).unwrap();
    // garbage and a foreign version on the status keys: the coordinator refuses and logs them
    s.put(keys.status("dem"), vec![0xc1u8, 0xff, 0x00, 0x13])
        .await
        .unwrap();
    let mut old = Status::new(
        &run_id,
        "fem",
        StatusBody::Stopped {
            results: Default::default(),
            compute_s: 0.0,
            wait_s: 0.0,
        },
    );
    old.version = PROTOCOL_VERSION + 7;
    s.put(keys.status("fem"), encode(&old).unwrap())
        .await
        .unwrap();
    // a status claiming to be another node's
    let spoof = Status::new(
        &run_id,
        "dem",
        StatusBody::Stopped {
            results: Default::default(),
            compute_s: 0.0,
            wait_s: 0.0,
        },
    );
    s.put(keys.status("fem"), encode(&spoof).unwrap())
        .await
        .unwrap();
    // interface data of another run on this run's key: the FEM refuses it and keeps waiting
    for w in 0..5 {
        s.put(
            keys.forces("top"),
            encode(&forces("someone-else", w, 1e9)).unwrap(),
        )
        .await
        .unwrap();
    }
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    eprintln!("{err}");
    assert!(out.status.success(), "the run must go on");
    assert!(err.contains("refused"), "refusals are logged: {err}");
    assert!(
        err.contains(&format!("version {}", PROTOCOL_VERSION + 7)),
        "{err}"
    );
    let sum = summary(&dir.path().join("out"));
    assert_eq!(sum["status"], "completed");
    assert_eq!(sum["windows_done"], 3000);
    let fem_log = std::fs::read_to_string(dir.path().join("out/logs/fem.log")).unwrap();
    assert!(
        fem_log.contains("someone-else"),
        "the FEM logs the foreign data: {fem_log}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn nan_forces_stop_the_run_cleanly_naming_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let port = proto::link::free_loopback_port().unwrap();
    let run_id = format!("hostile-b-{}", std::process::id());
    let mut child = start_plate(dir.path(), "10 s", &run_id, port);
    wait_for_windows(
        &dir.path().join("out"),
        5,
        &mut child,
        Duration::from_secs(60),
    );
    let s = rogue(port, &run_id).await;
    let keys = proto::Keys::new(&run_id).unwrap();
    let t0 = Instant::now();
    // keep injecting until the run reacts (the rogue's links may take a moment to form)
    let mut w = 0;
    while child.try_wait().unwrap().is_none() {
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "the run ignored NaN interface data"
        );
        s.put(
            keys.forces("top"),
            encode(&forces(&run_id, w, f64::NAN)).unwrap(),
        )
        .await
        .unwrap();
        w += 1;
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    eprintln!(
        "stopped {:.2} s after the injection began:\n{err}",
        t0.elapsed().as_secs_f64()
    );
    assert!(!out.status.success());
    let sum = summary(&dir.path().join("out"));
    let e = sum["error"].as_str().unwrap();
    // The injected message is wrong twice (NaN, and a window index the FEM is not at). The
    // coordinator's monitor refuses the NaN, the FEM node refuses the window index — whoever
    // sees it first stops the run, naming the interface forces and what is wrong with them:
    // invalid data from the node that sends forces, not an instability of the run.
    assert!(e.contains("forces"), "{e}");
    assert!(
        e.contains("invalid interface data from the dem node") && e.contains("non-finite")
            || e.contains("expected window"),
        "{e}"
    );
    assert_eq!(sum["status"], "failed", "{sum}");
    // nothing non-finite reached the summary
    for (k, v) in sum["results"].as_object().into_iter().flatten() {
        assert!(v.as_f64().is_some_and(f64::is_finite), "{k} = {v}");
    }
    // what was written so far is intact
    let csv = std::fs::read_to_string(dir.path().join("out/windows.csv")).unwrap();
    let columns = csv.lines().next().unwrap().split(',').count();
    assert!(csv.lines().skip(1).all(|l| l.split(',').count() == columns));
}
