//! Inputs refused where they enter, naming the file: sizes the machine cannot hold (before any
//! picture is decoded), numbers no camera or scene can have, a truncated JPEG, too few frames;
//! and many frames naming one picture decoded once, with progress.

use std::path::Path;
use std::sync::{Arc, Mutex};

use fogray_data::{load, load_with_progress, DataError, LoadOptions, LoadProgress, MatrixProblem};
use image::{Rgb, RgbImage};
use serde_json::{json, Value};

use crate::common::{at, names, ngp_file, solid_png, tempdir};

/// Two frames naming the 4x3 picture `a.png` in `dir`, with `top` keys and `frame` keys added
/// to the first.
fn two_frames(dir: &Path, top: Value, first: Value) -> std::path::PathBuf {
    solid_png(&dir.join("a.png"), 4, 3, [10, 20, 30]);
    let mut a = json!({ "file_path": "a.png", "transform_matrix": at([0.0, 0.0, 3.0]) });
    for (k, v) in first.as_object().unwrap() {
        a.as_object_mut().unwrap().insert(k.clone(), v.clone());
    }
    let b = json!({ "file_path": "a.png", "transform_matrix": at([0.0, 0.0, 4.0]) });
    let mut doc = json!({ "fl_x": 4.0 });
    for (k, v) in top.as_object().unwrap() {
        doc.as_object_mut().unwrap().insert(k.clone(), v.clone());
    }
    ngp_file(dir, doc, vec![a, b])
}

#[test]
fn pictures_claimed_larger_than_memory_are_refused_before_decoding() {
    // The picture on disk is 4x3; the file claims 200000 x 200000 (40 bytes a pixel while it
    // decodes: 1.6e12 bytes). Refused on what the file states, before the picture is opened:
    // a decode would have found the sizes disagree.
    let dir = tempdir();
    let path = two_frames(dir.path(), json!({ "w": 200000, "h": 200000 }), json!({}));
    let err = load(&path, &LoadOptions::default()).unwrap_err();
    match &err {
        DataError::TooLarge { source, .. } => {
            assert!(source.what.starts_with("frames[0] (200000x200000 pixels)"), "{err}");
            assert!(source.need.0 >= 200_000 * 200_000 * 40, "{err}");
        }
        other => panic!("{other}"),
    }
    names(&err, &path);
}

#[test]
fn numbers_no_camera_or_scene_can_have_are_refused_naming_the_file() {
    let cases: [(Value, Value, &str); 7] = [
        // A box sent beyond any scene is blamed on the entry the file gives, with its value.
        (
            json!({ "offset": [1e300, 0.0, 0.0] }),
            json!({}),
            "`offset` is 1e300 (the scene box it gives",
        ),
        (
            json!({ "scale": 1e-300 }),
            json!({}),
            "`scale` is 1e-300 (the scene box it gives",
        ),
        (
            json!({ "fl_x": 1e308 }),
            json!({}),
            "`fl_x of frames[0]` is 1e308 (a focal length must lie between",
        ),
        (
            json!({ "k1": 1e30 }),
            json!({}),
            "`k1` is 1e30 (a radial coefficient must be at most 100",
        ),
        (json!({}), json!({ "p2": -2.0 }), "`frames[0].p2` is -2 (a tangential"),
        (
            json!({ "aabb_scale": 1e308 }),
            json!({}),
            "`aabb_scale` is 1e308 (must be at most 1024)",
        ),
        (
            json!({ "cx": -50.0 }),
            json!({}),
            "`cx of frames[0]` is -50 (the principal point",
        ),
    ];
    for (top, first, message) in cases {
        let dir = tempdir();
        let path = two_frames(dir.path(), top, first);
        let err = load(&path, &LoadOptions::default()).unwrap_err();
        assert!(matches!(err, DataError::BadValue { .. }), "{err}");
        assert!(err.to_string().contains(message), "{err} / {message}");
        names(&err, &path);
    }
}

#[test]
fn a_translation_beyond_any_scene_is_refused_naming_the_file() {
    let dir = tempdir();
    let path = two_frames(
        dir.path(),
        json!({}),
        json!({ "transform_matrix": at([1e308, 0.0, 3.0]) }),
    );
    let err = load(&path, &LoadOptions::default()).unwrap_err();
    match &err {
        DataError::BadMatrix { key, problem, .. } => {
            assert_eq!(key, "frames[0].transform_matrix");
            assert_eq!(problem, &MatrixProblem::FarTranslation { value: 1e308 });
        }
        other => panic!("{other}"),
    }
    names(&err, &path);
    assert!(err.to_string().contains("translation entry 1e308"), "{err}");
}

#[test]
fn a_truncated_jpeg_is_refused_naming_it() {
    let dir = tempdir();
    // Busy enough that most of the file is scan data, so that the cut falls inside it (a cut
    // in the headers is refused by the decoder itself).
    let image = RgbImage::from_fn(256, 192, |x, y| {
        Rgb([(x * 7 + y * 3) as u8, (x * y) as u8, (x ^ y) as u8])
    });
    let mut whole = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut whole, 90)
        .encode_image(&image)
        .unwrap();
    let picture = dir.path().join("a.jpg");
    std::fs::write(&picture, &whole[..whole.len() / 3]).unwrap();
    let frames = [3.0, 4.0].map(|z| json!({ "file_path": "a.jpg", "transform_matrix": at([0.0, 0.0, z]) }));
    let path = ngp_file(dir.path(), json!({ "fl_x": 200.0 }), frames.to_vec());
    let err = load(&path, &LoadOptions::default()).unwrap_err();
    assert!(matches!(err, DataError::Decode { .. }), "{err}");
    assert!(err.to_string().contains("truncated JPEG"), "{err}");
    names(&err, &picture);
    // The whole file loads.
    std::fs::write(&picture, &whole).unwrap();
    assert_eq!(
        load(&path, &LoadOptions::default()).unwrap().train[0].picture.width(),
        256
    );
}

#[test]
fn a_dataset_of_one_frame_or_none_left_is_refused_in_one_line() {
    let dir = tempdir();
    solid_png(&dir.path().join("a.png"), 4, 3, [10, 20, 30]);
    let one = json!({ "file_path": "a.png", "transform_matrix": at([0.0, 0.0, 3.0]) });
    let path = ngp_file(dir.path(), json!({ "fl_x": 4.0 }), vec![one]);
    let err = load(&path, &LoadOptions::default()).unwrap_err();
    assert!(
        matches!(
            err,
            DataError::TooFewFrames {
                frames: 1,
                skipped: 0,
                ..
            }
        ),
        "{err}"
    );
    assert!(
        err.to_string()
            .contains("1 frame(s) with a picture; a fit needs at least two"),
        "{err}"
    );
    names(&err, &path);
    // Every picture missing, and skipped: one line, no frame left.
    let gone = [3.0, 4.0].map(|z| json!({ "file_path": "gone.png", "transform_matrix": at([0.0, 0.0, z]) }));
    let path = ngp_file(dir.path(), json!({ "fl_x": 4.0 }), gone.to_vec());
    let skip = LoadOptions {
        skip_missing: true,
        ..LoadOptions::default()
    };
    let err = load(&path, &skip).unwrap_err();
    assert!(
        matches!(
            err,
            DataError::TooFewFrames {
                frames: 0,
                skipped: 2,
                ..
            }
        ),
        "{err}"
    );
    names(&err, &path);
}

#[test]
fn frames_naming_one_picture_decode_it_once_with_progress() {
    let dir = tempdir();
    solid_png(&dir.path().join("a.png"), 4, 3, [10, 20, 30]);
    solid_png(&dir.path().join("b.png"), 4, 3, [40, 50, 60]);
    // 40 frames, 39 naming a.png and one b.png: two pictures to decode.
    let frames: Vec<Value> = (0..40)
        .map(|i| {
            let file = if i == 7 { "b.png" } else { "a.png" };
            json!({ "file_path": file, "transform_matrix": at([0.0, 0.0, 3.0 + i as f64]) })
        })
        .collect();
    let path = ngp_file(dir.path(), json!({ "fl_x": 4.0 }), frames);
    let seen = Arc::new(Mutex::new(Vec::new()));
    let record = Arc::clone(&seen);
    let scene = load_with_progress(&path, &LoadOptions::default(), move |p| record.lock().unwrap().push(p)).unwrap();
    assert_eq!(scene.train.len() + scene.test.len(), 40);
    let mut seen = seen.lock().unwrap().clone();
    seen.sort_by_key(|p| p.decoded);
    assert_eq!(
        seen,
        [1, 2].map(|decoded| LoadProgress { decoded, pictures: 2 }).to_vec()
    );
    // Frame 7 (train, after frame 0 is held out: train index 6) has b's colour, 40 / 255.
    assert!((scene.train[6].picture.color[[0, 0, 0]] - 40.0 / 255.0).abs() < 1e-6);
    assert!((scene.train[5].picture.color[[0, 0, 0]] - 10.0 / 255.0).abs() < 1e-6);
}
