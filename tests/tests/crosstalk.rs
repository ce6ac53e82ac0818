//! Two runs on one router never see each other's data, and a node that arrives in a run already
//! under way is refused with a clear message while the run goes on.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use cosim_tests::{bin, bin_dir, cosim, root, run, summary, wait_for_windows, write_scene, Reaper};

fn config(dir: &Path, name: &str, text: String) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn node(kind: &str, run_id: &str, cfg: &Path) -> Command {
    let mut c = Command::new(bin(&format!("{kind}-node")));
    c.args(["--run-id", run_id, "--node", kind])
        .arg("--zenoh-config")
        .arg(cfg)
        .current_dir(root());
    c
}

#[test]
fn two_runs_on_one_router_do_not_cross_talk_and_a_late_duplicate_node_is_refused() {
    let text = std::fs::read_to_string(root().join("scenes/plate.toml"))
        .unwrap()
        .replace("end_time = \"30 ms\"", "end_time = \"20 ms\"");
    two_runs_on_one_router(&text, "plate");
}

/// The same for two Arlequin runs (a volume interface: the overlap, the kinematics and the
/// penalty pull keyed by the run, nothing else).
#[test]
fn two_volume_coupled_runs_on_one_router_do_not_cross_talk() {
    let text = std::fs::read_to_string(root().join("scenes/arlequin-column-ci.toml"))
        .unwrap()
        // 150 windows: still running well after window 19, when the late node joins
        .replace("end_time = \"40 ms\"", "end_time = \"15 ms\"");
    assert!(text.contains("end_time = \"15 ms\""));
    two_runs_on_one_router(&text, "column");
}

/// Runs the scene `text` twice at once on one router (each run's nodes started by hand with
/// its run id), joins a late duplicate DEM node to the first (refused), and compares both
/// runs' results bitwise with a run alone.
fn two_runs_on_one_router(text: &str, name: &str) {
    let dir = tempfile::tempdir().unwrap();
    let port = proto::link::free_loopback_port().unwrap();
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let router = config(
        dir.path(),
        "router.json5",
        format!(
            r#"{{ mode: "router", listen: {{ endpoints: ["{endpoint}"] }}, scouting: {{ multicast: {{ enabled: false }} }} }}"#
        ),
    );
    let client = config(
        dir.path(),
        "client.json5",
        format!(
            r#"{{ mode: "client", connect: {{ endpoints: ["{endpoint}"] }}, scouting: {{ multicast: {{ enabled: false }} }},
                 transport: {{ link: {{ tx: {{ lease: 3000, keep_alive: 4 }} }} }} }}"#
        ),
    );
    let mut procs = Reaper(vec![Command::new(bin("cosim"))
        .arg("router")
        .arg("--config")
        .arg(&router)
        .stderr(Stdio::null())
        .spawn()
        .unwrap()]);
    std::thread::sleep(Duration::from_millis(300));

    let scene = write_scene(dir.path(), &format!("{name}.toml"), text);
    let tag = std::process::id();
    let runs: Vec<String> = ["a", "b"]
        .iter()
        .map(|r| format!("xtalk-{name}-{r}-{tag}"))
        .collect();
    let mut coordinators = Vec::new();
    for id in &runs {
        let mut c = cosim();
        c.arg("run")
            .arg(&scene)
            .args([
                "--no-progress",
                "--external",
                "dem",
                "--external",
                "fem",
                "--run-id",
                id,
                "--config",
            ])
            .arg(&client)
            .arg("--out")
            .arg(dir.path().join(id))
            .env("COSIM_BIN_DIR", bin_dir())
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        coordinators.push(c.spawn().unwrap());
        for kind in ["dem", "fem"] {
            procs.0.push(
                node(kind, id, &client)
                    .stderr(Stdio::null())
                    .spawn()
                    .unwrap(),
            );
        }
    }

    // a second DEM node for run a, once the run is under way
    wait_for_windows(
        &dir.path().join(&runs[0]),
        19,
        &mut coordinators[0],
        Duration::from_secs(60),
    );
    let late = node("dem", &runs[0], &client).output().unwrap();
    let late_err = String::from_utf8_lossy(&late.stderr);
    eprintln!("late node: {late_err}");
    assert!(!late.status.success());
    assert!(late_err.contains("already under way"), "{late_err}");

    for (id, c) in runs.iter().zip(coordinators) {
        let o = c.wait_with_output().unwrap();
        assert!(
            o.status.success(),
            "run {id} failed: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
    // each run's numbers equal a run alone on loopback, to the last bit
    let alone = dir.path().join("alone");
    let mut c = cosim();
    c.arg("run")
        .arg(&scene)
        .arg("--no-progress")
        .arg("--out")
        .arg(&alone);
    assert!(run(c).status.success());
    let reference = summary(&alone);
    for id in &runs {
        let s = summary(&dir.path().join(id));
        assert_eq!(s["status"], "completed", "{id}");
        assert_eq!(s["results"], reference["results"], "{id}");
    }
}
