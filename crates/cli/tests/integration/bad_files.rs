//! `fogray fit` and `fogray render` on bad files: exit status 2, nothing on stdout, and one
//! line on stderr that names the file at fault (never a panic).

use std::path::{Path, PathBuf};

use serde_json::Value;

use crate::common::{arg, assert_refused, cameras, fogray, intrinsics, render_cameras, write_ball, LENS, TINY_FIT};

/// A good dataset of 8 views of 8x8 pixels in a fresh folder `dir/name`.
fn dataset(dir: &Path, name: &str) -> PathBuf {
    let data = dir.join(name);
    write_ball(&data, &cameras(8, intrinsics(8), LENS));
    data
}

/// `fogray fit` on `data`, as short as a fit goes (it must not get that far).
fn fit(data: &Path, extra: &[&str]) -> crate::common::Run {
    let mut args = vec!["fit", "--data", arg(data)];
    args.extend(TINY_FIT);
    args.extend_from_slice(extra);
    fogray(&args)
}

/// Rewrites `data/transforms.json` through `edit`.
fn edit_transforms(data: &Path, edit: impl FnOnce(&mut Value)) {
    let path = data.join("transforms.json");
    let mut doc: Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    edit(&mut doc);
    std::fs::write(&path, serde_json::to_string_pretty(&doc).unwrap()).unwrap();
}

#[test]
fn fit_refuses_a_folder_without_a_transforms_file() {
    let dir = tempfile::tempdir().unwrap();
    let empty = dir.path().join("no-transforms-here");
    std::fs::create_dir(&empty).unwrap();
    assert_refused(&fit(&empty, &[]), "no-transforms-here", "empty folder");
}

#[test]
fn fit_refuses_a_truncated_transforms_file() {
    let dir = tempfile::tempdir().unwrap();
    let data = dataset(dir.path(), "truncated");
    let path = data.join("transforms.json");
    let text = std::fs::read_to_string(&path).unwrap();
    std::fs::write(&path, &text[..text.len() / 2]).unwrap();
    let run = fit(&data, &[]);
    assert_refused(&run, "transforms.json", "truncated");
    assert!(run.stderr.contains("invalid JSON"), "{}", run.stderr);
}

#[test]
fn fit_refuses_poses_that_are_not_rigid_4x4_transforms() {
    let dir = tempfile::tempdir().unwrap();
    // A 3x4 matrix (the last row dropped, as some tools store poses).
    let data = dataset(dir.path(), "three-by-four");
    edit_transforms(&data, |doc| {
        doc["frames"][3]["transform_matrix"].as_array_mut().unwrap().pop();
    });
    let run = fit(&data, &[]);
    assert_refused(&run, "transforms.json", "3x4 matrix");
    assert!(
        run.stderr.contains("frames[3]") && run.stderr.contains("4x4"),
        "{}",
        run.stderr
    );
    // A scaling (diag 2) where the rotation belongs.
    let data = dataset(dir.path(), "scaled");
    edit_transforms(&data, |doc| {
        let m = &mut doc["frames"][5]["transform_matrix"];
        for r in 0..3 {
            for c in 0..3 {
                m[r][c] = Value::from(if r == c { 2.0 } else { 0.0 });
            }
        }
    });
    let run = fit(&data, &[]);
    assert_refused(&run, "transforms.json", "scaled rotation");
    assert!(
        run.stderr.contains("frames[5]") && run.stderr.contains("not a rotation"),
        "{}",
        run.stderr
    );
}

#[test]
fn fit_refuses_images_that_do_not_decode_or_disagree_with_the_size() {
    let dir = tempfile::tempdir().unwrap();
    let data = dataset(dir.path(), "garbage");
    std::fs::write(data.join("images/view_04.png"), b"this is not a PNG at all").unwrap();
    let run = fit(&data, &[]);
    assert_refused(&run, "view_04.png", "garbage PNG");
    assert!(run.stderr.contains("decode"), "{}", run.stderr);

    // A 10x6 image where transforms.json says w = h = 8.
    let data = dataset(dir.path(), "wrong-size");
    image::RgbImage::from_pixel(10, 6, image::Rgb([255, 0, 0]))
        .save(data.join("images/view_06.png"))
        .unwrap();
    let run = fit(&data, &[]);
    assert_refused(&run, "view_06.png", "wrong size");
    assert!(run.stderr.contains("10x6"), "{}", run.stderr);
}

#[test]
fn fit_refuses_a_zero_downscale_and_a_background_outside_0_1() {
    let dir = tempfile::tempdir().unwrap();
    let data = dataset(dir.path(), "options");
    let run = fit(&data, &["--downscale", "0"]);
    assert_refused(&run, "options", "--downscale 0");
    assert!(run.stderr.contains("downscale 0"), "{}", run.stderr);
    // Refused by clap's value parser (its error folded to one line, exit status 2).
    let run = fit(&data, &["--background", "2,0,0"]);
    assert_eq!(run.code, 2, "{}", run.stderr);
    assert!(run.stdout.is_empty(), "{}", run.stdout);
    assert!(
        run.stderr.contains("--background") && run.stderr.contains("2,0,0"),
        "{}",
        run.stderr
    );
    assert!(!run.stderr.contains("panicked"), "{}", run.stderr);
}

#[test]
fn render_refuses_a_file_that_is_not_a_model_and_missing_cameras() {
    let dir = tempfile::tempdir().unwrap();
    let data = dataset(dir.path(), "data");
    let transforms = data.join("transforms.json");
    let out = dir.path().join("renders");

    let not_a_model = dir.path().join("not-a-model.safetensors");
    std::fs::write(&not_a_model, "{\"frames\": []}").unwrap();
    let run = render_cameras(&not_a_model, &transforms, &out, &[]);
    assert_refused(&run, "not-a-model.safetensors", "not a model");

    // A real model (one step of a tiny fit), and cameras that are not there.
    let model = dir.path().join("tiny.safetensors");
    let run = fit(&data, &["--save-model", arg(&model)]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    let missing = dir.path().join("missing-transforms.json");
    let run = render_cameras(&model, &missing, &out, &[]);
    assert_refused(&run, "missing-transforms.json", "missing cameras");
    assert!(!out.exists(), "a refused render made {}", out.display());
    // The dataset's own cameras render: the refusal above was the missing file's.
    let run = render_cameras(&model, &data, &out, &[]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    assert_eq!(run.stdout.lines().count(), 8, "{}", run.stdout);
}
