//! Helpers of the tests: running the `fogray-grid` binary, temporary directories, datasets.
#![allow(dead_code)] // each test file uses the helpers it needs

use std::path::PathBuf;
use std::process::Command;
use std::sync::atomic::{AtomicUsize, Ordering};

use fogray::fit::dataset::Dataset;
use fogray_grid::ring::Ring;
use fogray_grid::scene::Scene;
use fogray_grid::views::dataset;

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

/// A fresh directory for this call: the tests share one process and run in parallel, so two
/// calls never share a directory, whatever their `name`.
pub fn temp_dir(name: &str) -> PathBuf {
    static CALLS: AtomicUsize = AtomicUsize::new(0);
    let call = CALLS.fetch_add(1, Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("fogray-grid-tests-{}-{call}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The exact photographs of the built-in scene from `ring`'s cameras.
pub fn default_scene_data(ring: &Ring) -> Dataset {
    dataset(&Scene::default(), ring).unwrap()
}
