//! The worker's command line as a user meets it. (Also makes `cargo test` build the worker
//! binary that the farm tests in coordinator/tests start.)

use std::process::Command;

#[test]
fn bad_arguments_fail_with_a_message() {
    let worker = env!("CARGO_BIN_EXE_worker");
    let o = Command::new(worker).output().unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--coordinator"));
    let o = Command::new(worker)
        .args(["--coordinator", "http://127.0.0.1:9", "--threads", "0"])
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("--threads must be at least 1"));
}
