//! `fogray fit --resume`: a fit saved half way and continued takes the steps of the fit that
//! was never stopped, reading its dataset and settings from the file; a lattice other than the
//! file's is refused, naming it.

use std::path::Path;

use serde_json::Value;

use crate::common::{arg, assert_refused, cameras, fogray, intrinsics, write_ball, Run, LENS};

/// A fit whose steps do not depend on its budget: one lattice from the start and a constant
/// learning rate (growth and the anneal happen at fractions of the budget).
const FIXED_SCHEDULE: [&str; 8] = [
    "--grid",
    "12",
    "--batch",
    "256",
    "--no-grow",
    "--lr-final",
    "0.4",
    "--json",
];

fn fit(extra: &[&str]) -> Value {
    let mut args = vec!["fit"];
    args.extend_from_slice(extra);
    args.extend_from_slice(&FIXED_SCHEDULE);
    let run: Run = fogray(&args);
    assert_eq!(run.code, 0, "{args:?}: {}", run.stderr);
    serde_json::from_str(&run.stdout).unwrap()
}

fn final_figures(json: &Value) -> (u64, f64, f64) {
    let last = json["log"].as_array().unwrap().last().unwrap().clone();
    (
        json["steps"].as_u64().unwrap(),
        json["final_test_psnr"].as_f64().unwrap(),
        last["train_loss"].as_f64().unwrap(),
    )
}

fn ball(dir: &Path) -> std::path::PathBuf {
    let data = dir.join("ball");
    write_ball(&data, &cameras(10, intrinsics(16), LENS));
    data
}

#[test]
fn a_fit_resumed_half_way_takes_the_steps_of_the_unbroken_fit() {
    let dir = tempfile::tempdir().unwrap();
    let data = ball(dir.path());
    let half = dir.path().join("half.safetensors");
    let (whole, resumed) = (
        dir.path().join("whole.safetensors"),
        dir.path().join("resumed.safetensors"),
    );

    // A seed of their own: a resume that read the default settings instead of the file's
    // would draw other batches.
    let seeded = ["--data", arg(&data), "--seed", "7"];
    let first = fit(&[&seeded[..], &["--steps", "6", "--save-model", arg(&half)]].concat());
    assert_eq!(first["steps"], 6);
    let unbroken = fit(&[&seeded[..], &["--steps", "12", "--save-model", arg(&whole)]].concat());
    // No --data, no --seed: the file names its dataset and settings; the budget is given.
    let continued = fit(&["--resume", arg(&half), "--steps", "12", "--save-model", arg(&resumed)]);
    // It starts where the file stopped (a fresh fit of 12 steps would land on the unbroken
    // one too, from step 0).
    assert_eq!(continued["log"][0]["step"], 6, "{continued}");

    let (steps, psnr, loss) = final_figures(&unbroken);
    assert_eq!(steps, 12);
    // Bit for bit: the same held-out PSNR and last training loss to every digit printed.
    assert_eq!(final_figures(&continued), (steps, psnr, loss), "{continued}");
    // The six steps between them moved the model: a resume that restarted, or that skipped
    // the steps, would not land on the unbroken fit.
    assert_ne!(final_figures(&first).1, psnr);
    // The saved models hold the same tensors (the files differ in the seconds they record).
    assert_eq!(saved_tensors(&resumed), saved_tensors(&whole));
}

/// The tensors of a saved model, by name, as bytes.
fn saved_tensors(path: &Path) -> Vec<(String, Vec<u8>)> {
    let bytes = std::fs::read(path).unwrap();
    let file = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let mut tensors: Vec<(String, Vec<u8>)> = file
        .tensors()
        .into_iter()
        .map(|(name, view)| (name, view.data().to_vec()))
        .collect();
    tensors.sort();
    tensors
}

#[test]
fn a_resume_refuses_another_lattice_and_a_missing_file_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let data = ball(dir.path());
    let saved = dir.path().join("saved.safetensors");
    fit(&["--data", arg(&data), "--steps", "2", "--save-model", arg(&saved)]);

    let other_grid = fogray(&["fit", "--resume", arg(&saved), "--grid", "16", "--steps", "4"]);
    assert_refused(&other_grid, "saved.safetensors", "--grid 16 on a 12^3 fit");
    assert!(other_grid.stderr.contains("--grid"), "{}", other_grid.stderr);

    let missing = dir.path().join("missing.safetensors");
    let run = fogray(&["fit", "--resume", arg(&missing), "--steps", "4"]);
    assert_refused(&run, "missing.safetensors", "a missing file");

    // Neither a dataset nor a fit to resume: clap's usage error (one line), exit status 2.
    let run = fogray(&["fit", "--steps", "4"]);
    assert_eq!(run.code, 2, "{}", run.stderr);
    assert!(run.stderr.contains("--data"), "{}", run.stderr);
}
