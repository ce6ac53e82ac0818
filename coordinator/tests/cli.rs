//! The `cosim` binary's own command line (also makes `cargo test --workspace` build it for the
//! integration tests in `tests/`).

use std::process::Command;

#[test]
fn cosim_help_lists_run_and_check() {
    let out = Command::new(env!("CARGO_BIN_EXE_cosim"))
        .arg("--help")
        .output()
        .unwrap();
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("run") && text.contains("check"), "{text}");
}

#[test]
fn cosim_without_a_scene_is_a_usage_error() {
    let out = Command::new(env!("CARGO_BIN_EXE_cosim"))
        .arg("run")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("<SCENE>"));
}
