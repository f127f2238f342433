//! One test per way a dataset can be wrong: the error variant, and a message naming the file.

use fogray_data::{load, load_cameras, DataError, LoadOptions, MatrixProblem};
use serde_json::json;

use crate::common::{at, blender_folder, names, ngp_file, solid_png, tempdir, write_json};

fn opts() -> LoadOptions {
    LoadOptions::default()
}

/// A one-frame instant-ngp file with the given top-level keys and frame, its 4x3 image written.
fn ngp_one(dir: &std::path::Path, top: serde_json::Value, frame: serde_json::Value) -> std::path::PathBuf {
    solid_png(&dir.join("images/a.png"), 4, 3, [10, 20, 30]);
    ngp_file(dir, top, vec![frame])
}

fn frame() -> serde_json::Value {
    json!({ "file_path": "images/a.png", "transform_matrix": at([0.0, 0.0, 3.0]) })
}

#[test]
fn an_unreadable_file_is_an_io_error() {
    let dir = tempdir();
    let path = dir.path().join("transforms.json");
    let err = load(&path, &opts()).unwrap_err();
    assert!(matches!(err, DataError::Io { .. }), "{err}");
    names(&err, &path);
}

#[test]
fn truncated_json_gives_line_and_column() {
    let dir = tempdir();
    let path = dir.path().join("transforms.json");
    std::fs::write(&path, "{\n  \"fl_x\": 10,\n  \"frames\": [\n").unwrap();
    let err = load(&path, &opts()).unwrap_err();
    match &err {
        DataError::Json { line, .. } => assert!(*line >= 3, "line {line}"),
        other => panic!("{other}"),
    }
    names(&err, &path);
    assert!(err.to_string().contains("line"));
}

#[test]
fn a_missing_key_is_named() {
    let dir = tempdir();
    let path = blender_folder(dir.path(), 0.7, &[("r_0", [0.0, 0.0, 4.0])], 4, 4);
    let mut doc: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    doc.as_object_mut().unwrap().remove("camera_angle_x");
    write_json(&path, &doc);
    let err = load(dir.path(), &opts()).unwrap_err();
    assert!(
        matches!(&err, DataError::MissingKey { key, .. } if key == "camera_angle_x"),
        "{err}"
    );
    names(&err, &path);

    let path = ngp_one(
        dir.path(),
        json!({ "fl_x": 5.0 }),
        json!({ "file_path": "images/a.png" }),
    );
    let err = load(&path, &opts()).unwrap_err();
    assert!(
        matches!(&err, DataError::MissingKey { key, .. } if key == "frames[0].transform_matrix"),
        "{err}"
    );
    names(&err, &path);
}

#[test]
fn each_bad_matrix_is_named_with_its_problem() {
    let dir = tempdir();
    let rows = |r: [[f64; 4]; 4]| json!(r);
    let cases = [
        (
            json!([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
            MatrixProblem::NotFourByFour,
        ),
        (
            rows([
                [1.0, 0.0, 0.0, 0.0],
                [0.0, 1.0, 0.0, 0.0],
                [0.0, 0.0, 1.0, 3.0],
                [0.0, 0.0, 1.0, 1.0],
            ]),
            MatrixProblem::LastRow,
        ),
    ];
    for (matrix, want) in cases {
        let path = ngp_one(
            dir.path(),
            json!({ "fl_x": 5.0 }),
            json!({ "file_path": "images/a.png", "transform_matrix": matrix }),
        );
        let err = load(&path, &opts()).unwrap_err();
        assert!(
            matches!(&err, DataError::BadMatrix { problem, key, .. } if *problem == want && key == "frames[0].transform_matrix"),
            "{err}"
        );
        names(&err, &path);
    }
    let scaled = rows([
        [2.0, 0.0, 0.0, 0.0],
        [0.0, 2.0, 0.0, 0.0],
        [0.0, 0.0, 2.0, 3.0],
        [0.0, 0.0, 0.0, 1.0],
    ]);
    let path = ngp_one(
        dir.path(),
        json!({ "fl_x": 5.0 }),
        json!({ "file_path": "images/a.png", "transform_matrix": scaled }),
    );
    let err = load(&path, &opts()).unwrap_err();
    assert!(
        matches!(&err, DataError::BadMatrix { problem: MatrixProblem::NotOrthonormal { deviation }, .. } if (*deviation - 3.0).abs() < 1e-12),
        "{err}"
    );
    assert!(err.to_string().contains("not orthonormal"));
    names(&err, &path);
    let mirror = rows([
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, -1.0, 3.0],
        [0.0, 0.0, 0.0, 1.0],
    ]);
    let path = ngp_one(
        dir.path(),
        json!({ "fl_x": 5.0 }),
        json!({ "file_path": "images/a.png", "transform_matrix": mirror }),
    );
    let err = load(&path, &opts()).unwrap_err();
    assert!(
        matches!(
            &err,
            DataError::BadMatrix {
                problem: MatrixProblem::Reflection { .. },
                ..
            }
        ),
        "{err}"
    );
    assert!(err.to_string().contains("determinant"));
    names(&err, &path);
}

#[test]
fn a_non_positive_focal_length_or_field_of_view_is_refused() {
    let dir = tempdir();
    for (top, key) in [
        (json!({ "fl_x": 0.0 }), "fl_x"),
        (json!({ "fl_x": 5.0, "fl_y": -2.0 }), "fl_y"),
        (json!({ "camera_angle_x": -0.5 }), "camera_angle_x"),
        (json!({ "camera_angle_x": 3.5 }), "camera_angle_x"),
    ] {
        let path = ngp_one(dir.path(), top, frame());
        let err = load(&path, &opts()).unwrap_err();
        assert!(matches!(&err, DataError::BadValue { key: k, .. } if k == key), "{err}");
        names(&err, &path);
    }
    // A frame's own value is checked too, and named with its frame.
    let mut f = frame();
    f.as_object_mut().unwrap().insert("fl_y".into(), json!(0.0));
    let path = ngp_one(dir.path(), json!({ "fl_x": 5.0 }), f);
    let err = load(&path, &opts()).unwrap_err();
    assert!(
        matches!(&err, DataError::BadValue { key, .. } if key == "frames[0].fl_y"),
        "{err}"
    );
}

#[test]
fn no_focal_length_at_all_is_a_missing_key() {
    let dir = tempdir();
    let path = ngp_one(dir.path(), json!({ "w": 4, "h": 3 }), frame());
    let err = load(&path, &opts()).unwrap_err();
    assert!(
        matches!(&err, DataError::MissingKey { key, .. } if key.starts_with("frames[0].fl_x")),
        "{err}"
    );
    names(&err, &path);
}

#[test]
fn no_frames_is_an_error() {
    let dir = tempdir();
    let path = ngp_file(dir.path(), json!({ "fl_x": 5.0 }), vec![]);
    let err = load(&path, &opts()).unwrap_err();
    assert!(matches!(err, DataError::NoFrames { .. }), "{err}");
    names(&err, &path);
}

#[test]
fn an_image_that_does_not_decode_is_named() {
    let dir = tempdir();
    blender_folder(
        dir.path(),
        0.7,
        &[("r_0", [0.0, 0.0, 4.0]), ("r_1", [0.0, 0.0, 5.0])],
        4,
        4,
    );
    let bad = dir.path().join("r_1.png");
    std::fs::write(&bad, b"\x89PNG\r\n\x1a\nnot really").unwrap();
    let err = load(dir.path(), &opts()).unwrap_err();
    assert!(matches!(err, DataError::Decode { .. }), "{err}");
    names(&err, &bad);
}

#[test]
fn images_of_different_sizes_in_one_blender_split_are_refused() {
    let dir = tempdir();
    blender_folder(
        dir.path(),
        0.7,
        &[("r_0", [0.0, 0.0, 4.0]), ("r_1", [0.0, 0.0, 5.0])],
        4,
        4,
    );
    let odd = dir.path().join("r_1.png");
    solid_png(&odd, 5, 4, [0, 0, 0]);
    let err = load(dir.path(), &opts()).unwrap_err();
    assert!(
        matches!(
            &err,
            DataError::MixedSizes {
                size: (5, 4),
                first_size: (4, 4),
                ..
            }
        ),
        "{err}"
    );
    names(&err, &odd);
    assert!(err.to_string().contains("r_0.png"));
}

#[test]
fn an_image_that_disagrees_with_w_and_h_is_refused() {
    let dir = tempdir();
    let path = ngp_one(dir.path(), json!({ "fl_x": 5.0, "w": 4, "h": 4 }), frame());
    let err = load(&path, &opts()).unwrap_err();
    assert!(
        matches!(
            &err,
            DataError::SizeMismatch {
                size: (4, 3),
                expected: (4, 4),
                ..
            }
        ),
        "{err}"
    );
    names(&err, &dir.path().join("images/a.png"));
    assert!(err.to_string().contains("transforms.json"));
}

#[test]
fn a_folder_without_transforms_is_refused() {
    let dir = tempdir();
    solid_png(&dir.path().join("a.png"), 2, 2, [0, 0, 0]);
    let err = load(dir.path(), &opts()).unwrap_err();
    assert!(matches!(err, DataError::NoTransforms { .. }), "{err}");
    names(&err, dir.path());
    let err = load_cameras(dir.path(), 1).unwrap_err();
    assert!(matches!(err, DataError::NoTransforms { .. }), "{err}");
}

#[test]
fn a_downscale_of_zero_or_larger_than_the_image_is_refused() {
    let dir = tempdir();
    blender_folder(dir.path(), 0.7, &[("r_0", [0.0, 0.0, 4.0])], 4, 4);
    let err = load(dir.path(), &LoadOptions { downscale: 0, ..opts() }).unwrap_err();
    assert!(matches!(err, DataError::BadDownscale { downscale: 0, .. }), "{err}");
    names(&err, dir.path());
    let err = load(dir.path(), &LoadOptions { downscale: 5, ..opts() }).unwrap_err();
    assert!(matches!(err, DataError::BadDownscale { downscale: 5, .. }), "{err}");
    names(&err, &dir.path().join("r_0.png"));
    let err = load_cameras(dir.path(), 0).unwrap_err();
    assert!(matches!(err, DataError::BadDownscale { downscale: 0, .. }), "{err}");
}

#[test]
fn missing_images_are_listed_unless_skipped() {
    let dir = tempdir();
    solid_png(&dir.path().join("images/f0.png"), 4, 3, [1, 2, 3]);
    let frames: Vec<_> = (0..9)
        .map(|i| json!({ "file_path": format!("images/f{i}.png"), "transform_matrix": at([0.0, 0.0, 3.0 + i as f64]) }))
        .collect();
    let path = ngp_file(dir.path(), json!({ "fl_x": 5.0 }), frames);
    let err = load(&path, &opts()).unwrap_err();
    match &err {
        DataError::MissingImages { count, first, .. } => {
            assert_eq!(*count, 8);
            assert_eq!(first.len(), 5);
            assert!(first[0].ends_with("images/f1.png"));
        }
        other => panic!("{other}"),
    }
    names(&err, &path);
    assert!(err.to_string().contains("f1.png") && err.to_string().contains("8 image"));

    // Skipped, they leave one frame: nothing to train on beside the held-out one.
    let skip = LoadOptions {
        skip_missing: true,
        ..opts()
    };
    let err = load(&path, &skip).unwrap_err();
    assert!(
        matches!(
            err,
            DataError::TooFewFrames {
                frames: 1,
                skipped: 8,
                ..
            }
        ),
        "{err}"
    );
    names(&err, &path);
    // With a second picture, two frames remain: f0 held out, f1 trained on.
    solid_png(&dir.path().join("images/f1.png"), 4, 3, [1, 2, 3]);
    let scene = load(&path, &skip).unwrap();
    assert_eq!(scene.skipped, 7);
    assert_eq!((scene.train.len(), scene.test.len()), (1, 1));
    assert_eq!(
        (scene.test[0].name.as_str(), scene.train[0].name.as_str()),
        ("f0", "f1")
    );
}

#[test]
fn an_unsupported_camera_model_is_named() {
    let dir = tempdir();
    let path = ngp_one(
        dir.path(),
        json!({ "fl_x": 5.0, "camera_model": "OPENCV_FISHEYE" }),
        frame(),
    );
    let err = load(&path, &opts()).unwrap_err();
    assert!(
        matches!(&err, DataError::Unsupported { what, .. } if what.contains("OPENCV_FISHEYE")),
        "{err}"
    );
    names(&err, &path);
    assert!(err.to_string().contains("not supported"));
}

#[test]
fn cameras_without_images_need_w_and_h() {
    let dir = tempdir();
    let path = blender_folder(dir.path(), 0.7, &[("r_0", [0.0, 0.0, 4.0])], 4, 4);
    std::fs::remove_file(dir.path().join("r_0.png")).unwrap();
    let err = load_cameras(dir.path(), 1).unwrap_err();
    assert!(matches!(err, DataError::NoImageSize { .. }), "{err}");
    names(&err, &path);
    // With w and h in the file the size comes from them.
    let mut doc: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    doc.as_object_mut().unwrap().insert("w".into(), json!(10));
    doc.as_object_mut().unwrap().insert("h".into(), json!(6));
    write_json(&path, &doc);
    let cams = load_cameras(dir.path(), 2).unwrap();
    assert_eq!(
        (cams[0].camera.intrinsics().width, cams[0].camera.intrinsics().height),
        (5, 3)
    );
}

#[test]
fn a_wrong_type_is_named() {
    let dir = tempdir();
    let path = ngp_one(dir.path(), json!({ "fl_x": "five" }), frame());
    let err = load(&path, &opts()).unwrap_err();
    assert!(
        matches!(&err, DataError::WrongType { key, .. } if key == "fl_x"),
        "{err}"
    );
    names(&err, &path);
}
