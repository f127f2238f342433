//! The binary's model files: `fit --save-model` then `render` gives the fit's test renders bit
//! for bit; `fit --resume` continues; Ctrl-C (SIGINT) saves the fit and exits 130; bad model
//! files, mismatched flags and views out of range exit 2 with one line.

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use fogray::fit::checkpoint::{load, read_info};
use fogray::fit::dense::DenseGrid;
use fogray::fit::settings::Budget;

use crate::common;
use common::{grid, ok, temp_dir};

const TINY: [&str; 10] = [
    "--views",
    "8",
    "--test-views",
    "2",
    "--size",
    "10",
    "--grid",
    "8",
    "--batch",
    "128",
];

/// Fits with `flags` (and --json), saving the model and the final renders in `dir`, then
/// renders the saved model's test views with `render --json`: the model file, the fit's
/// renders and the render's output.
fn fit_then_render(
    dir: &std::path::Path,
    flags: &[&str],
) -> (std::path::PathBuf, serde_json::Value, serde_json::Value) {
    let (model, renders) = (dir.join("m.safetensors"), dir.join("renders.json"));
    let (model_s, renders_s) = (model.to_str().unwrap(), renders.to_str().unwrap());
    let saving = ["--json", "--save-model", model_s, "--save-renders", renders_s];
    ok(&[&["fit"], &TINY[..], flags, &saving[..]].concat());
    let out_dir = dir.join("pngs");
    let rendered = ok(&[
        "render",
        "--model",
        model_s,
        "--json",
        "--out",
        out_dir.to_str().unwrap(),
    ]);
    let fit = serde_json::from_str(&std::fs::read_to_string(&renders).unwrap()).unwrap();
    (model, fit, serde_json::from_str(&rendered).unwrap())
}

#[test]
fn a_saved_occupancy_model_renders_bitwise_as_the_fit() {
    // 80 steps: the occupancy grid is refreshed at steps 64 and 80, so it is no longer the
    // fresh all-occupied grid; `render` uses the saved one.
    let dir = temp_dir("render-occupancy");
    let (_, fit, render) = fit_then_render(&dir, &["--steps", "80"]);
    assert_eq!(render["images"], fit["images"]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn saved_models_render_as_the_fit_and_resume() {
    let dir = temp_dir("render");
    // Uniform sampling: its renders need nothing but the saved grid.
    let (model, fit, render) = fit_then_render(&dir, &["--steps", "6", "--sampling", "uniform"]);
    let model_s = model.to_str().unwrap();
    let out_dir = dir.join("pngs");
    // Test views 2 and 7 by default, read back from JSON as the same f64s.
    assert_eq!(render["views"], serde_json::json!([2, 7]));
    assert_eq!(render["images"], fit["images"]);
    assert_eq!(render["psnr"].as_array().unwrap().len(), 2);
    for name in ["view-002.png", "depth-002.png", "view-007.png", "depth-007.png"] {
        assert!(out_dir.join(name).exists(), "{name}");
    }
    // Text output: one line per view with its PSNR.
    let text = ok(&[
        "render",
        "--model",
        model_s,
        "--view",
        "0",
        "--view",
        "9",
        "--out",
        out_dir.to_str().unwrap(),
    ]);
    assert_eq!(text.lines().count(), 2, "{text}");
    assert!(text.lines().all(|l| l.contains("PSNR") && l.contains(" dB")), "{text}");

    // Resuming to 10 steps in all continues from step 6 with the file's settings.
    let resumed = dir.join("resumed.safetensors");
    let out = ok(&[
        "fit",
        "--resume",
        model_s,
        "--steps",
        "10",
        "--json",
        "--save-model",
        resumed.to_str().unwrap(),
    ]);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["log"][0]["step"], 6);
    assert_eq!(v["log"].as_array().unwrap().last().unwrap()["step"], 10);
    let info = read_info(&resumed).unwrap();
    assert_eq!((info.step, info.nodes, info.settings.batch), (10, 8, 128));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn ctrl_c_saves_the_fit_and_exits_130() {
    let dir = temp_dir("sigint");
    let model = dir.join("m.safetensors");
    let mut child = Command::new(env!("CARGO_BIN_EXE_fogray-grid"))
        .args(["fit"])
        .args(TINY)
        .args([
            "--steps",
            "100000000",
            "--json",
            "--save-model",
            model.to_str().unwrap(),
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The binary says so on stderr once its first step is done (and its handler is set).
    let mut stderr = BufReader::new(child.stderr.take().unwrap());
    let mut line = String::new();
    stderr.read_line(&mut line).unwrap();
    assert!(line.contains("Ctrl-C stops"), "{line}");
    let status = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let start = Instant::now();
    let code = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status.code();
        }
        if start.elapsed() > Duration::from_secs(20) {
            child.kill().unwrap();
            panic!("the fit did not stop on SIGINT");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let mut rest = String::new();
    std::io::Read::read_to_string(&mut stderr, &mut rest).unwrap();
    assert_eq!(code, Some(130), "{rest}");
    assert!(
        rest.contains("interrupted after step") && rest.contains("m.safetensors"),
        "{rest}"
    );
    let saved = load::<f32, DenseGrid<f32>>(&model).unwrap();
    assert!(saved.start.training.step >= 1);
    assert_eq!(saved.settings.budget(), Budget::Steps(100000000));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_models_and_flags_exit_2_with_one_line() {
    let dir = temp_dir("bad");
    let model = dir.join("m.safetensors");
    let m = model.to_str().unwrap();
    ok(&[&["fit"], &TINY[..], &["--steps", "2", "--json", "--save-model", m]].concat());
    let junk = dir.join("junk.safetensors");
    std::fs::write(&junk, b"junk").unwrap();
    let j = junk.to_str().unwrap();
    for args in [
        &["render", "--model", "/nonexistent/m.safetensors"][..],
        &["render", "--model", j][..],
        &["render", "--model", m, "--view", "10"][..],
        &["render", "--model", m, "--views", "3", "--test-views", "0"][..],
        &["render", "--model", m, "--size", "0"][..],
        &["render", "--model", m, "--all", "--view", "1"][..],
        &["render"][..],
        &["fit", "--resume", j, "--steps", "3"][..],
        &["fit", "--resume", m, "--grid", "16"][..],
        &["fit", "--resume", m, "--precision", "f64"][..],
        &[
            "fit",
            "--size",
            "4",
            "--grid",
            "4",
            "--steps",
            "1",
            "--save-model",
            "/nonexistent/m.safetensors",
        ][..],
    ] {
        let (code, out, err) = grid(args);
        assert_eq!(code, 2, "{args:?}: {err}");
        assert!(out.is_empty(), "{args:?}: {out}");
        assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
        assert!(err.starts_with("fogray-grid: error: "), "{args:?}: {err}");
    }
    let (_, _, err) = grid(&["fit", "--resume", m, "--grid", "16"]);
    assert!(err.contains("--grid 8") && err.contains("--grid 16"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
