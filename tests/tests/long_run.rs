//! A long run of 10^5 small windows: memory stays flat in the coordinator and the node.

use std::process::Stdio;
use std::time::{Duration, Instant};

use cosim_tests::{cosim, pid_of, root, summary, wait_for_windows, write_scene};

/// Peak and current resident memory (kB) of a process.
fn memory_kb(pid: u32) -> Option<(u64, u64)> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let field = |name: &str| {
        status
            .lines()
            .find(|l| l.starts_with(name))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|v| v.parse().ok())
    };
    Some((field("VmHWM:")?, field("VmRSS:")?))
}

#[test]
fn hundred_thousand_windows_with_flat_memory() {
    const WINDOWS: usize = 100_000;
    let dir = tempfile::tempdir().unwrap();
    // the minimal scene with one DEM step per window: the run is all coupling machinery
    let text = std::fs::read_to_string(root().join("scenes/minimal.toml"))
        .unwrap()
        .replace("end_time = \"0.2 s\"", "end_time = 1.0")
        .replace("window = \"10 ms\"", "window = 1e-5");
    let scene = write_scene(dir.path(), "long.toml", &text);
    let out = dir.path().join("out");
    let run_id = format!("long-{}", std::process::id());
    let mut c = cosim();
    c.arg("run")
        .arg(&scene)
        .args(["--no-progress", "--run-id", &run_id, "--out"])
        .arg(&out);
    let mut child = c
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    let limit = Duration::from_secs(600);
    wait_for_windows(&out, WINDOWS / 10, &mut child, limit);
    let coord = child.id();
    let dem = pid_of(&["dem-node", &run_id]).unwrap();
    let start = (memory_kb(coord).unwrap(), memory_kb(dem).unwrap());
    wait_for_windows(&out, WINDOWS * 95 / 100, &mut child, limit);
    let end = (memory_kb(coord).unwrap(), memory_kb(dem).unwrap());
    assert!(child.wait().unwrap().success());
    let s = summary(&out);
    assert_eq!(s["windows_done"], WINDOWS as u64);
    eprintln!(
        "{WINDOWS} windows in {:.1} s; peak RSS at 10 % / 95 %: coordinator {} / {} kB, dem-node {} / {} kB",
        t0.elapsed().as_secs_f64(),
        start.0 .0,
        end.0 .0,
        start.1 .0,
        end.1 .0
    );
    // flat: no more than 8 MB of growth over 85,000 windows (≤ 100 bytes per window)
    assert!(
        end.0 .0 <= start.0 .0 + 8 * 1024,
        "coordinator grew {} → {} kB",
        start.0 .0,
        end.0 .0
    );
    assert!(
        end.1 .0 <= start.1 .0 + 8 * 1024,
        "dem-node grew {} → {} kB",
        start.1 .0,
        end.1 .0
    );
}
