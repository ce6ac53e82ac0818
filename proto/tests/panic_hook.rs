//! A panic in a binary (a node or `cosim`; a bug: scene errors are values) reaches the log as one line
//! naming the message and the place, not as the default report with a backtrace hint.

use std::process::Command;

const CHILD: &str = "COSIM_PANIC_HOOK_CHILD";

#[test]
fn a_panic_prints_one_line_with_message_and_location_and_fails() {
    if std::env::var_os(CHILD).is_some() {
        // the child: the hook the binary installs, then a panic as a bug would raise it
        proto::node::install_panic_hook("dem-node");
        let counts: Vec<usize> = Vec::new();
        let _ = counts[usize::from(std::env::var_os(CHILD).is_some())];
        return;
    }
    let out = Command::new(std::env::current_exe().unwrap())
        .args([
            "a_panic_prints_one_line_with_message_and_location_and_fails",
            "--exact",
            "--nocapture",
            "--test-threads=1",
        ])
        .env(CHILD, "1")
        .env_remove("RUST_BACKTRACE")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    println!("{stderr}");
    assert!(!out.status.success(), "a panic still fails the process");
    let line = stderr
        .lines()
        .find(|l| l.starts_with("dem-node: internal error: "))
        .unwrap_or_else(|| panic!("no internal-error line in: {stderr}"));
    assert!(
        line.contains("index out of bounds: the len is 0 but the index is 1 at ")
            && line.contains("proto/tests/panic_hook.rs:")
            && line.ends_with("; please report"),
        "{line}"
    );
    assert!(!stderr.contains("panicked at"), "{stderr}");
    assert!(!stderr.contains("RUST_BACKTRACE"), "{stderr}");
}
