//! Helpers for the integration tests: where the built binaries are, scratch folders, and
//! running `cosim` as a user would.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

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

/// Writes a scene into `dir` (with the other files it names copied from `scenes/`).
pub fn write_scene(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).expect("write scene");
    p
}
