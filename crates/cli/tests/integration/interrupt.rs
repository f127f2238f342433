//! `fogray fit` stopped by Ctrl-C: it saves the model it has (exit status 130), with the
//! settings its command line chose, the lattice that depends on the budget included.
#![cfg(unix)]

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use fogray_fit::checkpoint::read_info;

use crate::common::{arg, cameras, intrinsics, write_ball, LENS};

/// Starts `fogray fit` with `args`, sends it SIGINT once it says training begins, and returns
/// its exit status.
fn fit_then_ctrl_c(args: &[&str]) -> i32 {
    let mut child = Command::new(env!("CARGO_BIN_EXE_fogray"))
        .arg("fit")
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stderr = BufReader::new(child.stderr.take().unwrap());
    let mut line = String::new();
    // The handler is installed before this line is written.
    while !line.contains("Ctrl-C stops and saves") {
        line.clear();
        assert_ne!(
            stderr.read_line(&mut line).unwrap(),
            0,
            "fogray fit ended before training"
        );
    }
    let kill = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    // It stops after the step under way; a fit that ignored the signal would run its budget.
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            return status.code().unwrap_or(-1);
        }
        if start.elapsed() > Duration::from_secs(60) {
            child.kill().unwrap();
            panic!("fogray fit did not stop on SIGINT");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn a_fit_stopped_by_ctrl_c_saves_its_model_with_the_lattice_of_its_budget() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("ball");
    write_ball(&data, &cameras(8, intrinsics(16), LENS));
    let model = dir.path().join("model.safetensors");
    // A long budget grows to the finer lattice unless --grid says otherwise; a short one, and a
    // budget of steps, to the usual one.
    let cases: [(&[&str], usize); 4] = [
        (&["--seconds", "150"], 192),
        (&["--seconds", "150", "--grid", "40"], 40),
        (&["--seconds", "149"], 128),
        (&["--steps", "1000000"], 128),
    ];
    for (budget, grid) in cases {
        let mut args = vec!["--data", arg(&data), "--save-model", arg(&model)];
        args.extend_from_slice(budget);
        assert_eq!(fit_then_ctrl_c(&args), 130, "{budget:?}");
        let info = read_info(&model).unwrap();
        assert_eq!(info.settings.grid, grid, "{budget:?}");
        std::fs::remove_file(&model).unwrap();
    }
}
