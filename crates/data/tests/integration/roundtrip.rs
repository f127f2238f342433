//! Datasets written by `write_blender` and `write_instant_ngp` read back to the same rays and
//! (to 8-bit rounding) the same images.

use fogray_data::{load, load_cameras, write_blender, write_instant_ngp, Format, Frame, LoadOptions};
use fogray_ops::{Intrinsics, LensDistortion, PinholeCamera};
use ndarray::Array3;

use crate::common::tempdir;

fn image(h: usize, w: usize, seed: usize) -> Array3<f64> {
    Array3::from_shape_fn((h, w, 3), |(r, c, ch)| {
        ((r * 7 + c * 3 + ch * 5 + seed) % 11) as f64 / 10.0
    })
}

fn cameras(k: Intrinsics) -> Vec<PinholeCamera> {
    let eyes = [[0.0, 0.0, 4.0], [3.0, 1.0, 0.5], [-2.0, -3.0, 1.5]];
    eyes.iter()
        .map(|&eye| PinholeCamera::look_at(k, eye, [0.1, -0.2, 0.0], [0.0, 0.0, 1.0]).unwrap())
        .collect()
}

/// Every pixel's ray of `got` equals `want`'s to 1e-6, and the images to 8-bit rounding.
fn same(got: &Frame, want: &PinholeCamera, img: &Array3<f64>) {
    let (k, kw) = (got.camera.intrinsics(), want.intrinsics());
    assert_eq!((k.width, k.height), (kw.width, kw.height), "{}", got.name);
    for i in 0..3 {
        assert!((got.camera.centre()[i] - want.centre()[i]).abs() < 1e-6, "{}", got.name);
    }
    for row in 0..k.height {
        for col in 0..k.width {
            let (a, b) = (got.camera.direction(row, col), want.direction(row, col));
            for i in 0..3 {
                assert!(
                    (a[i] - b[i]).abs() < 1e-6,
                    "{} pixel ({row}, {col}): {a:?} vs {b:?}",
                    got.name
                );
            }
            for c in 0..3 {
                let d = (got.picture.color[[row, col, c]] as f64 - img[[row, col, c]]).abs();
                assert!(
                    d <= 0.5 / 255.0 + 1e-6,
                    "{} pixel ({row}, {col}, {c}) off by {d}",
                    got.name
                );
            }
        }
    }
}

fn by_name<'a>(frames: &'a [Frame], name: &str) -> &'a Frame {
    frames.iter().find(|f| f.name == name).unwrap()
}

#[test]
fn blender_round_trip() {
    let dir = tempdir();
    let cams = cameras(Intrinsics::from_vertical_fov(6, 4, 0.7).unwrap());
    let imgs: Vec<_> = (0..3).map(|i| image(4, 6, i)).collect();
    let names = ["v0", "v1", "v2"];
    let frames: Vec<_> = (0..3).map(|i| (names[i], &cams[i], &imgs[i])).collect();
    write_blender(dir.path(), &frames).unwrap();
    let scene = load(dir.path(), &LoadOptions::default()).unwrap();
    assert_eq!(scene.format, Format::Blender);
    assert_eq!((scene.train.len(), scene.test.len()), (2, 1));
    let all: Vec<Frame> = scene.train.into_iter().chain(scene.test).collect();
    for i in 0..3 {
        same(by_name(&all, names[i]), &cams[i], &imgs[i]);
    }
    // With a val file beside train, val is the test split, and load_cameras reads both.
    std::fs::copy(
        dir.path().join("transforms_train.json"),
        dir.path().join("transforms_val.json"),
    )
    .unwrap();
    let scene = load(dir.path(), &LoadOptions::default()).unwrap();
    assert_eq!((scene.train.len(), scene.test.len()), (3, 3));
    let cams_read = load_cameras(dir.path(), 1).unwrap();
    assert_eq!(cams_read.len(), 6);
    assert_eq!(cams_read[4].name, "v1");
    assert_eq!(cams_read[4].camera, scene.test[1].camera);
    // A transforms_*.json file given directly loads its Blender folder.
    let again = load(&dir.path().join("transforms_val.json"), &LoadOptions::default()).unwrap();
    assert_eq!(
        (again.format, again.train.len(), again.test.len()),
        (Format::Blender, 3, 3)
    );
}

#[test]
fn blender_refuses_cameras_it_cannot_store() {
    let dir = tempdir();
    let k = Intrinsics {
        cx: 2.5,
        ..Intrinsics::from_vertical_fov(6, 4, 0.7).unwrap()
    };
    let cam = PinholeCamera::look_at(k, [0.0, 0.0, 4.0], [0.0; 3], [0.0, 1.0, 0.0]).unwrap();
    let img = image(4, 6, 0);
    let err = write_blender(dir.path(), &[("a", &cam, &img)]).unwrap_err();
    assert!(matches!(err, fogray_data::DataError::BadInput { .. }), "{err}");
    assert!(err.to_string().contains("transforms_train.json"));
    let wrong = image(3, 6, 0);
    let err = write_instant_ngp(dir.path(), &[("a", &cam, &wrong)]).unwrap_err();
    assert!(err.to_string().contains("3x6x3"), "{err}");
}

fn ngp_round_trip(per_frame: bool) {
    let dir = tempdir();
    let k = Intrinsics {
        fx: 7.3,
        fy: 6.9,
        cx: 2.7,
        cy: 2.1,
        width: 6,
        height: 4,
    };
    let lens = LensDistortion {
        k1: 0.05,
        k2: -0.01,
        p1: 0.002,
        p2: -0.001,
        ..LensDistortion::default()
    };
    let mut cams: Vec<_> = cameras(k)
        .into_iter()
        .map(|c| c.with_distortion(lens).unwrap())
        .collect();
    if per_frame {
        let k2 = Intrinsics { fx: 8.1, cy: 1.7, ..k };
        cams[2] = PinholeCamera::look_at(k2, [1.0, 2.0, 3.0], [0.0; 3], [0.0, 0.0, 1.0])
            .unwrap()
            .with_distortion(LensDistortion { k3: 0.001, ..lens })
            .unwrap();
    }
    let imgs: Vec<_> = (0..3).map(|i| image(4, 6, i + 4)).collect();
    let names = ["a", "b", "c"];
    let frames: Vec<_> = (0..3).map(|i| (names[i], &cams[i], &imgs[i])).collect();
    let path = write_instant_ngp(dir.path(), &frames).unwrap();
    let doc: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    assert_eq!(doc.get("fl_x").is_some(), !per_frame);
    assert_eq!(doc["frames"][0].get("fl_x").is_some(), per_frame);
    assert_eq!(doc["frames"][0]["file_path"], "images/a.png");
    let scene = load(dir.path(), &LoadOptions::default()).unwrap();
    assert_eq!(scene.format, Format::InstantNgp);
    assert_eq!((scene.train.len(), scene.test.len()), (2, 1));
    let all: Vec<Frame> = scene.train.into_iter().chain(scene.test).collect();
    for i in 0..3 {
        let got = by_name(&all, names[i]);
        assert_eq!(got.camera.distortion(), cams[i].distortion());
        same(got, &cams[i], &imgs[i]);
    }
    let read = load_cameras(&path, 1).unwrap();
    assert_eq!(read.len(), 3);
    assert_eq!(read[0].camera, by_name(&all, "a").camera);
}

#[test]
fn instant_ngp_round_trip_with_shared_intrinsics() {
    ngp_round_trip(false);
}

#[test]
fn instant_ngp_round_trip_with_per_frame_intrinsics() {
    ngp_round_trip(true);
}
