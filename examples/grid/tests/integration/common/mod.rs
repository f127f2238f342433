//! Running the `fogray-grid` binary from the CLI tests.
#![allow(dead_code)] // each test file uses the helpers it needs

use std::path::PathBuf;
use std::process::Command;

/// Runs the binary with `args`: its exit status, stdout and stderr.
pub fn grid(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_fogray-grid"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8(out.stdout).unwrap(),
        String::from_utf8(out.stderr).unwrap(),
    )
}

/// Runs the binary, asserts status 0 and returns its stdout.
pub fn ok(args: &[&str]) -> String {
    let (code, out, err) = grid(args);
    assert_eq!(code, 0, "{args:?}: {err}");
    out
}

/// A fresh directory for this test process and `name`.
pub fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("fogray-grid-tests-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}
