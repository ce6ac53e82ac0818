//! Helpers for the integration tests: where the built binaries are, scratch folders, and
//! running `cosim` as a user would.

pub mod timoshenko;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output};

/// The folder of the binaries built with the tests (`target/<profile>`).
pub fn bin_dir() -> PathBuf {
    // the test executable is target/<profile>/deps/<name>-<hash>
    let exe = std::env::current_exe().expect("test executable path");
    exe.parent()
        .and_then(Path::parent)
        .expect("target/<profile>")
        .to_path_buf()
}

/// Path of a workspace binary; fails with the command to build it if it is missing.
pub fn bin(name: &str) -> PathBuf {
    let p = bin_dir().join(format!("{name}{}", std::env::consts::EXE_SUFFIX));
    assert!(
        p.exists(),
        "{} is missing: run the tests with `cargo nextest run --workspace` (or `cargo build --workspace --bins` first)",
        p.display()
    );
    p
}

/// The workspace root.
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("workspace root")
        .to_path_buf()
}

/// A `cosim` command running in the workspace root.
pub fn cosim() -> Command {
    let mut c = Command::new(bin("cosim"));
    c.current_dir(root()).env("COSIM_BIN_DIR", bin_dir());
    c
}

/// Runs a command and returns its output, printing it when the test fails to help debugging.
pub fn run(mut c: Command) -> Output {
    let out = c.output().expect("start the command");
    eprintln!(
        "--- {:?} exited {}\n--- stdout\n{}\n--- stderr\n{}",
        c,
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Reads `summary.json` of an output folder.
pub fn summary(out_dir: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(out_dir.join("summary.json")).expect("summary.json exists");
    serde_json::from_str(&text).expect("summary.json is JSON")
}

/// scenes/plate.toml with another schedule (and force averaging) and window; `tables` are
/// appended (e.g. `[coupling.implicit]`).
pub fn plate_with(schedule: &str, window: &str, tables: &str) -> String {
    std::fs::read_to_string(root().join("scenes/plate.toml"))
        .expect("scenes/plate.toml")
        .replace(
            "schedule = \"predictive\"",
            &format!("schedule = \"{schedule}\"\nforce_averaging = true"),
        )
        .replace("window = \"0.1 ms\"", &format!("window = \"{window}\""))
        + "\n"
        + tables
}

/// The column `name` of a CSV text, as strings.
pub fn csv_column(text: &str, name: &str) -> Vec<String> {
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("a header").split(',').collect();
    let i = header
        .iter()
        .position(|h| *h == name)
        .unwrap_or_else(|| panic!("no {name} in {header:?}"));
    lines
        .map(|l| l.split(',').nth(i).expect("a full row").to_string())
        .collect()
}

/// The numbers of a CSV column (panics naming a value that is not one).
pub fn csv_f64(text: &str, name: &str) -> Vec<f64> {
    csv_column(text, name)
        .iter()
        .map(|v| {
            v.parse()
                .unwrap_or_else(|e| panic!("{name}: '{v}' is not a number ({e})"))
        })
        .collect()
}

/// Writes a scene into `dir` (with the other files it names copied from `scenes/`).
pub fn write_scene(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).expect("write scene");
    p
}

/// Runs `cosim run` on scene text written to `dir/name`, output in `dir/out-<name>`; fails the
/// test (printing the nodes' logs) if the run fails. Returns the summary.
pub fn run_scene(dir: &Path, name: &str, text: &str) -> serde_json::Value {
    let scene = write_scene(dir, name, text);
    let out = dir.join(format!("out-{name}"));
    let mut c = cosim();
    c.arg("run")
        .arg(&scene)
        .arg("--no-progress")
        .arg("--out")
        .arg(&out);
    let o = run(c);
    if !o.status.success() {
        let mut logs: Vec<_> = std::fs::read_dir(out.join("logs"))
            .into_iter()
            .flatten()
            .flatten()
            .map(|e| e.path())
            .collect();
        logs.sort();
        for log in logs {
            if let Ok(text) = std::fs::read_to_string(&log) {
                eprintln!("--- {}\n{text}", log.display());
            }
        }
        panic!("{name} failed");
    }
    summary(&out)
}

/// The window of the newest checkpoint of a run's output folder (0 before the first): it
/// counts once `checkpoints/latest.json` points at it (that file moves last).
pub fn latest_checkpoint_window(out: &Path) -> u64 {
    std::fs::read_to_string(out.join("checkpoints/latest.json"))
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .and_then(|v| v["window"].as_u64())
        .unwrap_or(0)
}

/// Arguments of the running process whose command line contains all of `needles`.
pub fn process_args(needles: &[&str]) -> Option<(u32, Vec<String>)> {
    for entry in std::fs::read_dir("/proc").ok()?.flatten() {
        let Ok(pid) = entry.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let Ok(cmd) = std::fs::read(entry.path().join("cmdline")) else {
            continue;
        };
        let args: Vec<String> = String::from_utf8_lossy(&cmd)
            .split('\0')
            .map(String::from)
            .collect();
        let line = args.join(" ");
        if needles.iter().all(|n| line.contains(n)) {
            return Some((pid, args));
        }
    }
    None
}

/// Pid of the running process whose command line contains all of `needles`.
pub fn pid_of(needles: &[&str]) -> Option<u32> {
    process_args(needles).map(|(pid, _)| pid)
}

/// Waits until no node process whose command line names `run` is left (nodes leave by
/// themselves when their coordinator is gone); fails after 10 s.
pub fn wait_for_nodes_to_leave(run: &str) {
    let t0 = std::time::Instant::now();
    while pid_of(&["-node", run]).is_some() {
        assert!(
            t0.elapsed() < std::time::Duration::from_secs(10),
            "nodes still running without a coordinator"
        );
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
}

/// SIGKILL.
pub fn kill(pid: u32) {
    signal(pid, "KILL");
}

/// Sends signal `sig` (`KILL`, `STOP`, `CONT`, ...) to process `pid`.
pub fn signal(pid: u32, sig: &str) {
    let ok = Command::new("kill")
        .args([&format!("-{sig}"), &pid.to_string()])
        .status()
        .map(|s| s.success());
    assert!(matches!(ok, Ok(true)), "kill -{sig} {pid}");
}

/// Kills and reaps its processes when dropped (also when a test fails half-way).
pub struct Reaper(pub Vec<Child>);

impl Drop for Reaper {
    fn drop(&mut self) {
        for c in &mut self.0 {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// Waits until `<out>/windows.csv` holds `n` completed windows; fails if `child` (the run)
/// ends first or `limit` passes.
pub fn wait_for_windows(out: &Path, n: usize, child: &mut Child, limit: std::time::Duration) {
    let csv = out.join("windows.csv");
    let t0 = std::time::Instant::now();
    loop {
        let done = std::fs::read_to_string(&csv)
            .map(|s| s.lines().count().saturating_sub(1))
            .unwrap_or(0);
        if done >= n {
            return;
        }
        assert!(
            t0.elapsed() < limit,
            "{n} windows not done after {limit:?} ({done} are)"
        );
        assert!(
            child.try_wait().expect("run status").is_none(),
            "the run ended after {done} windows, before {n}"
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// Starts `cosim run <scene> --no-progress --run-id <run_id> --out <out>` in the background,
/// its output discarded (a run the test will kill).
pub fn spawn_run(scene: &Path, run_id: &str, out: &Path) -> Child {
    let mut c = cosim();
    c.arg("run")
        .arg(scene)
        .args(["--no-progress", "--run-id", run_id, "--out"])
        .arg(out);
    c.stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("start cosim run")
}

/// Runs `scene` once uninterrupted into `<dir>/whole`, once into `<dir>/broken` killing
/// `victim` (a node id, or `cosim`) once the checkpoint after `window` exists, then resumes
/// the broken run (which must succeed). Returns the two output folders and the resume's
/// output.
pub fn whole_and_resumed(
    dir: &Path,
    scene: &Path,
    tag: &str,
    window: u64,
    victim: &str,
) -> (PathBuf, PathBuf, Output) {
    let whole = dir.join("whole");
    let mut c = cosim();
    c.arg("run")
        .arg(scene)
        .arg("--no-progress")
        .arg("--out")
        .arg(&whole);
    assert!(run(c).status.success());

    let broken = dir.join("broken");
    let run_id = format!("{tag}-{victim}-{}", std::process::id());
    let mut child = spawn_run(scene, &run_id, &broken);
    wait_for_checkpoint(&broken, window, &mut child);
    let pid = match victim {
        "cosim" => child.id(),
        node => pid_of(&[&format!("{node}-node"), &run_id]).expect("the node's process"),
    };
    kill(pid);
    assert!(
        !child.wait().unwrap().success(),
        "the interrupted run must fail"
    );
    if victim == "cosim" {
        // the nodes notice that the coordinator is gone and leave by themselves
        wait_for_nodes_to_leave(&run_id);
    }
    assert!(!broken.join("final").exists());
    let mut c = cosim();
    c.arg("resume").arg(&broken).arg("--no-progress");
    let o = run(c);
    assert!(o.status.success());
    (whole, broken, o)
}

/// Waits until the checkpoint after `window` exists in `out`; fails if `child` (the run) ends
/// first or a minute passes.
pub fn wait_for_checkpoint(out: &Path, window: u64, child: &mut Child) {
    let t0 = std::time::Instant::now();
    while latest_checkpoint_window(out) < window {
        assert!(
            t0.elapsed() < std::time::Duration::from_secs(60),
            "no checkpoint after window {window}"
        );
        assert!(
            child.try_wait().expect("run status").is_none(),
            "the run ended before it could be killed"
        );
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
}
