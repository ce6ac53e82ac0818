//! The coupling contract v2 through real node processes driven by hand over zenoh (the
//! coordinator's end of the wire, `CoordinatorLink`): window checkpoint and rollback repeat a
//! window bitwise, and a node of protocol version 1 is refused naming both versions.

use std::collections::BTreeMap;
use std::process::{Command, Stdio};
use std::time::Duration;

use cosim_tests::{bin, cosim, root, Reaper};
use proto::participant::{CoordinatorLink, Event};
use proto::{
    AdvanceWindow, CommandBody, Init, InterfaceDecl, InterfaceKind, Label, LinkConfig, MotionRule,
    StatusBody,
};

const WAIT: Duration = Duration::from_secs(60);

/// The next status of `node`, skipping others' and liveliness events.
async fn status_of(link: &CoordinatorLink, want: &[&str]) -> (String, StatusBody) {
    loop {
        match link.next_event(WAIT, "a node's status").await.unwrap() {
            Event::Status(s) if want.contains(&s.node.as_str()) => {
                if let StatusBody::Error { message, .. } = &s.body {
                    panic!("node `{}` failed: {message}", s.node);
                }
                return (s.node, s.body);
            }
            _ => {}
        }
    }
}

/// Waits for one status per node matching `is`; returns their bodies by node.
async fn all(
    link: &CoordinatorLink,
    nodes: &[&str],
    is: impl Fn(&StatusBody) -> bool,
) -> BTreeMap<String, StatusBody> {
    let mut got = BTreeMap::new();
    while got.len() < nodes.len() {
        let (n, b) = status_of(link, nodes).await;
        if is(&b) {
            got.insert(n, b);
        }
    }
    got
}

fn advance(
    window: u64,
    iteration: u32,
    input: Option<Label>,
    output: Option<Label>,
) -> CommandBody {
    CommandBody::AdvanceWindow(AdvanceWindow {
        window,
        iteration,
        t_start: window as f64 * 1e-4,
        dt: 1e-4,
        motion: MotionRule::Linear,
        input,
        output,
        static_solve: false,
    })
}

fn label(window: u64, iteration: u32) -> Option<Label> {
    Some(Label { window, iteration })
}

/// The monitor values of a `window_done`.
fn monitor(b: &StatusBody) -> BTreeMap<String, f64> {
    match b {
        StatusBody::WindowDone { monitor, .. } => monitor.clone(),
        other => panic!("not window_done: {other:?}"),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rollback_repeats_a_predictive_window_bitwise_in_both_rust_nodes() {
    let dir = tempfile::tempdir().unwrap();
    let scene = root().join("scenes/plate.toml");
    let run = format!("rollback-{}", std::process::id());
    let ports: Vec<u16> = (0..3)
        .map(|_| proto::link::free_loopback_port().unwrap())
        .collect();
    let link = CoordinatorLink::open(&LinkConfig::loopback_peer(Some(ports[0]), &[]), &run)
        .await
        .unwrap();
    let mut procs = Reaper(Vec::new());
    for (i, node) in ["dem", "fem"].iter().enumerate() {
        let mut c = Command::new(bin(&format!("{node}-node")));
        c.args(["--run-id", &run, "--node", node])
            .args(["--listen", &format!("tcp/127.0.0.1:{}", ports[i + 1])])
            .args(["--connect", &format!("tcp/127.0.0.1:{}", ports[0])]);
        if i == 1 {
            c.args(["--connect", &format!("tcp/127.0.0.1:{}", ports[1])]);
        }
        c.stdout(Stdio::null()).stderr(Stdio::inherit());
        procs.0.push(c.spawn().unwrap());
    }
    let nodes = ["dem", "fem"];
    all(&link, &nodes, |b| matches!(b, StatusBody::Hello(_))).await;
    let top = InterfaceDecl {
        name: "top".into(),
        kind: InterfaceKind::Surface,
        provider: "fem".into(),
        users: vec!["dem".into()],
        force_averaging: true,
        relaxed_forces: false,
        relaxed_kinematics: false,
    };
    let mut link = link;
    for node in nodes {
        let init = Init {
            scene_path: scene.display().to_string(),
            scene_toml: std::fs::read_to_string(&scene).unwrap(),
            table: node.into(),
            out_dir: dir.path().display().to_string(),
            interfaces: vec![top.clone()],
            check_only: false,
            trace: false,
        };
        link.send(node, CommandBody::Init(init)).await.unwrap();
    }
    all(&link, &nodes, |b| matches!(b, StatusBody::Ready { .. })).await;
    let done = |b: &StatusBody| matches!(b, StatusBody::WindowDone { .. });
    // predictive windows up to the first contacts (the beads reach the plate at ~7 ms)
    for k in 0..69u64 {
        link.send(
            "fem",
            advance(k, 0, k.checked_sub(1).map(Label::window), label(k, 0)),
        )
        .await
        .unwrap();
        link.send("dem", advance(k, 0, label(k, 0), label(k, 0)))
            .await
            .unwrap();
        all(&link, &nodes, done).await;
    }
    // window 69 (impacts) from a checkpoint, then again after a rollback, as an implicit scheme would
    let k = 69u64;
    for node in nodes {
        link.send(node, CommandBody::Checkpoint { window: k })
            .await
            .unwrap();
    }
    link.send("fem", advance(k, 0, label(k - 1, 0), label(k, 0)))
        .await
        .unwrap();
    link.send("dem", advance(k, 0, label(k, 0), label(k, 0)))
        .await
        .unwrap();
    let first = all(&link, &nodes, done).await;
    for node in nodes {
        link.send(node, CommandBody::Rollback { window: k })
            .await
            .unwrap();
    }
    // the forces of window k − 1 again (the DEM's restored average), labelled iteration 1
    link.send(
        "dem",
        CommandBody::Publish {
            label: Label {
                window: k - 1,
                iteration: 1,
            },
        },
    )
    .await
    .unwrap();
    link.send("fem", advance(k, 1, label(k - 1, 1), label(k, 1)))
        .await
        .unwrap();
    link.send("dem", advance(k, 1, label(k, 1), label(k, 1)))
        .await
        .unwrap();
    let second = all(&link, &nodes, done).await;
    for node in nodes {
        let (a, b) = (monitor(&first[node]), monitor(&second[node]));
        eprintln!("{node}: {a:?}");
        assert_eq!(a, b, "{node}: the repeated window differs");
    }
    // the repeated window's rows replaced the first attempt's: every time series runs forward
    for file in ["fem/fem_probes.csv", "dem/dem_timeseries.csv"] {
        let text = std::fs::read_to_string(dir.path().join(file)).unwrap();
        let times: Vec<f64> = text
            .lines()
            .skip(1)
            .map(|l| l.split(',').next().unwrap().parse().unwrap())
            .collect();
        assert!(times.len() >= 69, "{file}: {} rows", times.len());
        assert!(
            times.windows(2).all(|t| t[0] < t[1]),
            "{file}: a time appears twice or goes back"
        );
    }
    // the window did something: the beads are on the plate
    assert!(monitor(&first["dem"])["interface_work.top"] != 0.0);
    assert!(monitor(&first["fem"])["max_interface_speed"] > 0.0);
    // a rollback to a window without its checkpoint is refused, naming both
    link.send("fem", CommandBody::Rollback { window: 3 })
        .await
        .unwrap();
    loop {
        if let Event::Status(s) = link.next_event(WAIT, "fem's error").await.unwrap() {
            if let StatusBody::Error { message, .. } = s.body {
                assert!(
                    message.contains("window 3") && message.contains("window 69"),
                    "{message}"
                );
                break;
            }
        }
    }
    link.send(
        "dem",
        CommandBody::Stop {
            reason: "done".into(),
        },
    )
    .await
    .unwrap();
    drop(procs);
    let _ = link.close().await;
}

#[test]
fn a_node_of_protocol_version_1_is_refused_naming_both_versions() {
    // the FEM node is external; in its place a process that speaks version 1 says hello
    let dir = tempfile::tempdir().unwrap();
    let port = proto::link::free_loopback_port().unwrap();
    let run = format!("v1-{}", std::process::id());
    let out = dir.path().join("out");
    let mut c = cosim();
    c.args([
        "run",
        "scenes/plate.toml",
        "--no-progress",
        "--external",
        "fem",
    ])
    .args([
        "--run-id",
        &run,
        "--listen",
        &format!("tcp/127.0.0.1:{port}"),
    ])
    .arg("--out")
    .arg(&out)
    .stdout(Stdio::null())
    .stderr(Stdio::piped());
    let mut coordinator = c.spawn().unwrap();
    let rt = tokio::runtime::Runtime::new().unwrap();
    rt.block_on(async {
        let s = LinkConfig::loopback_peer(None, &[port])
            .open()
            .await
            .unwrap();
        #[derive(serde::Serialize)]
        struct HelloV1 {
            software: &'static str,
            role: &'static str,
            capabilities: Vec<String>,
            pid: u32,
        }
        #[derive(serde::Serialize)]
        #[serde(tag = "type", rename_all = "snake_case")]
        enum Body {
            Hello(HelloV1),
        }
        #[derive(serde::Serialize)]
        struct StatusV1 {
            version: u32,
            run_id: String,
            node: &'static str,
            body: Body,
        }
        let hello = StatusV1 {
            version: 1,
            run_id: run.clone(),
            node: "fem",
            body: Body::Hello(HelloV1 {
                software: "an old fem node",
                role: "fem",
                capabilities: vec![],
                pid: 1,
            }),
        };
        let key = proto::Keys::new(&run).unwrap().status("fem");
        // as a v1 node does: hello every 0.5 s until the coordinator answers (or here: leaves)
        for _ in 0..60 {
            if coordinator.try_wait().unwrap().is_some() {
                break;
            }
            s.put(&key, rmp_serde::to_vec_named(&hello).unwrap())
                .await
                .unwrap();
            tokio::time::sleep(Duration::from_millis(500)).await;
        }
        s.close().await.unwrap();
    });
    let o = coordinator.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    eprintln!("{err}");
    assert!(!o.status.success());
    assert!(
        err.contains("node `fem` speaks protocol version 1; this coordinator speaks version 2"),
        "{err}"
    );
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(s["status"], "failed");
}
