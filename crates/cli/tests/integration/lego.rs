//! A smoke test on a real dataset: the NeRF-synthetic lego scene, where the environment has
//! it. Set `FOGRAY_DATA` to the folder that holds `nerf_synthetic/lego`; unset, the test says
//! it is skipped and passes.

use std::path::Path;

use serde_json::Value;

use crate::common::{arg, fogray};

/// How many frames a Blender transforms file lists.
fn frames(file: &Path) -> usize {
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(file).unwrap()).unwrap();
    doc["frames"].as_array().unwrap().len()
}

#[test]
fn lego_fits_for_30_steps_at_downscale_8() {
    let Some(root) = std::env::var_os("FOGRAY_DATA") else {
        eprintln!("skipped: FOGRAY_DATA is not set (the folder holding nerf_synthetic/lego)");
        return;
    };
    let lego = Path::new(&root).join("nerf_synthetic").join("lego");
    // The split `fogray fit` must find: the test (else val) file's frames, else every eighth
    // training frame. A copy with only its 90 training frames gives 78 and 12.
    let train = frames(&lego.join("transforms_train.json"));
    let held_out = ["test", "val"]
        .map(|s| lego.join(format!("transforms_{s}.json")))
        .into_iter()
        .find(|f| f.is_file());
    let views = match held_out {
        Some(file) => [train, frames(&file)],
        None => [train - train.div_ceil(8), train.div_ceil(8)],
    };
    let run = fogray(&[
        "fit",
        "--data",
        arg(&lego),
        "--downscale",
        "8",
        "--steps",
        "30",
        "--json",
    ]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    let json: Value = serde_json::from_str(&run.stdout).unwrap();
    assert_eq!(json["views"], serde_json::json!(views), "{json}");
    // 800x800 pictures averaged over 8x8 blocks.
    assert_eq!(json["size"], serde_json::json!([100, 100]), "{json}");
    assert_eq!(json["steps"], 30);
    let first = &json["log"][0];
    assert_eq!(first["step"], 0);
    let (start, end) = (
        first["test_psnr"].as_f64().unwrap(),
        json["final_test_psnr"].as_f64().unwrap(),
    );
    assert!(end > start, "test PSNR {start} dB at step 0, {end} dB after 30 steps");
}
