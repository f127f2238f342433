//! LLFF captures written by hand (a `poses_bounds.npy` laid out byte by byte from known
//! cameras) read back: rays, bounds and folder choice; and each bad file refused.

use std::path::Path;

use fogray_data::{
    downscale_intrinsics, load, load_cameras, DataError, Format, ImageSource, Intrinsics, LoadOptions, PinholeCamera,
    SceneData,
};

use crate::capture_files::{llff_row, npy, poses_bounds};
use crate::common::{names, solid_png, tempdir};

const VIEWS: usize = 9;

/// Nine forward-facing cameras (a 3 x 3 grid in a tilted plane, each looking at its own point
/// ahead), 16 x 12 pixels, focal 20, principal point at the centre; their near and far bounds.
fn views() -> Vec<(PinholeCamera, f64, f64)> {
    let k = Intrinsics {
        fx: 20.0,
        fy: 20.0,
        cx: 8.0,
        cy: 6.0,
        width: 16,
        height: 12,
    };
    (0..VIEWS)
        .map(|i| {
            let (a, b) = ((i % 3) as f64, (i / 3) as f64);
            let eye = [a * 0.5, 2.0 + b * 0.4, -0.3 * a + 0.1 * b];
            let target = [eye[0] + 0.2 * a, eye[1] + 0.1, eye[2] - 10.0];
            let camera = PinholeCamera::look_at(k, eye, target, [0.1, -1.0, 0.05]).unwrap();
            (camera, 1.0 + 0.1 * i as f64, 20.0 + i as f64)
        })
        .collect()
}

fn color(i: usize) -> [u8; 3] {
    [10 + 20 * i as u8, 3, 200]
}

/// `dir/poses_bounds.npy` and `dir/images/img_NN.png` for `views`.
fn write_capture(dir: &Path, views: &[(PinholeCamera, f64, f64)]) {
    let rows: Vec<[f64; 17]> = views.iter().map(|(c, n, f)| llff_row(c, *n, *f)).collect();
    std::fs::write(dir.join("poses_bounds.npy"), poses_bounds(&rows)).unwrap();
    for i in 0..views.len() {
        solid_png(&dir.join(format!("images/img_{i:02}.png")), 16, 12, color(i));
    }
}

fn close(got: [f64; 3], want: [f64; 3], what: &str) {
    assert!(
        (0..3).all(|i| (got[i] - want[i]).abs() < 1e-9),
        "{what}: got {got:?}, want {want:?}"
    );
}

fn frames(scene: &SceneData) -> Vec<&fogray_data::Frame> {
    let mut all: Vec<_> = scene.train.iter().chain(&scene.test).collect();
    all.sort_by(|a, b| a.name.cmp(&b.name));
    all
}

#[test]
fn rows_give_the_cameras_they_were_written_from() {
    let dir = tempdir();
    let views = views();
    write_capture(dir.path(), &views);
    let scene = load(dir.path(), &LoadOptions::default()).unwrap();
    assert_eq!(scene.format, Format::Llff);
    assert_eq!(
        scene.test.iter().map(|f| f.name.as_str()).collect::<Vec<_>>(),
        ["img_00", "img_08"]
    );
    // The mean centre goes to the origin, the largest centre coordinate to 1.
    let mean: [f64; 3] = std::array::from_fn(|k| views.iter().map(|v| v.0.centre()[k]).sum::<f64>() / VIEWS as f64);
    close(scene.world.apply_point(mean), [0.0; 3], "mean centre");
    let largest = views
        .iter()
        .flat_map(|v| scene.world.apply_point(v.0.centre()))
        .fold(0.0f64, |m, x| m.max(x.abs()));
    assert!((largest - 1.0).abs() < 1e-12);
    for (i, frame) in frames(&scene).into_iter().enumerate() {
        let (want, near, far) = &views[i];
        assert_eq!(frame.name, format!("img_{i:02}"));
        assert_eq!(frame.camera.intrinsics(), want.intrinsics());
        close(frame.camera.centre(), scene.world.apply_point(want.centre()), "origin");
        for (r, c) in [(0, 0), (11, 15), (6, 8), (3, 12)] {
            close(
                frame.camera.direction(r, c),
                scene.world.apply_direction(want.direction(r, c)),
                "direction",
            );
        }
        let bounds = frame.depth_bounds.unwrap();
        assert!((bounds.near - near * scene.world.scale).abs() < 1e-12);
        assert!((bounds.far - far * scene.world.scale).abs() < 1e-12);
        let rgb = color(i).map(|c| c as f32 / 255.0);
        assert!((0..3).all(|c| (frame.picture.color[[5, 5, c]] - rgb[c]).abs() < 1e-6));
    }
    // The cameras alone are the same, and so is the capture named by its file.
    let cameras = load_cameras(dir.path(), 1).unwrap();
    for (named, frame) in cameras.iter().zip(frames(&scene)) {
        assert_eq!((&named.name, &named.camera), (&frame.name, &frame.camera));
    }
    let again = load(&dir.path().join("poses_bounds.npy"), &LoadOptions::default()).unwrap();
    assert_eq!(again.test[1].camera, scene.test[1].camera);
}

#[test]
fn images_k_is_read_and_the_intrinsics_follow_its_size() {
    let dir = tempdir();
    let views = views();
    write_capture(dir.path(), &views);
    // LLFF's quarter-size copies, under other names (only their order counts).
    for i in 0..VIEWS {
        solid_png(&dir.path().join(format!("images_4/image{i:03}.png")), 4, 3, color(i));
    }
    let options = LoadOptions {
        downscale: 4,
        ..LoadOptions::default()
    };
    let scene = load(dir.path(), &options).unwrap();
    assert!(
        matches!(scene.images, ImageSource::Prescaled { factor: 4, .. }),
        "{}",
        scene.images
    );
    for (i, frame) in frames(&scene).into_iter().enumerate() {
        let want = &views[i].0;
        // fx = focal w / W = 20 * 4 / 16, centre (2, 1.5).
        assert_eq!(frame.camera.intrinsics(), &downscale_intrinsics(want.intrinsics(), 4));
        // Pixel (r, c) covers the full-size square of corner (4r, 4c): centre (4r + 2, 4c + 2).
        for (r, c) in [(0, 0), (2, 3)] {
            let d = scene
                .world
                .apply_direction(want.direction_at(4.0 * r as f64 + 2.0, 4.0 * c as f64 + 2.0));
            close(frame.camera.direction(r, c), d, "quarter-size ray");
        }
    }
    // images_4 short of one: the full-size images, downscaled on load, say why.
    std::fs::remove_file(dir.path().join("images_4/image004.png")).unwrap();
    let scene = load(dir.path(), &options).unwrap();
    assert!(matches!(&scene.images, ImageSource::FullSize { downscale: 4, .. }));
    assert!(
        scene.images.to_string().contains("holds 8 images for 9 poses"),
        "{}",
        scene.images
    );
    assert_eq!(scene.test[0].picture.color.dim(), (3, 4, 3));
}

/// Writes `bytes` as the capture's `poses_bounds.npy` (with its nine pictures) and loads it.
fn load_npy(bytes: Vec<u8>) -> (tempfile::TempDir, DataError) {
    let dir = tempdir();
    write_capture(dir.path(), &views());
    let path = dir.path().join("poses_bounds.npy");
    std::fs::write(&path, bytes).unwrap();
    let err = load(dir.path(), &LoadOptions::default()).unwrap_err();
    names(&err, &path);
    (dir, err)
}

fn rows() -> Vec<[f64; 17]> {
    views().iter().map(|(c, n, f)| llff_row(c, *n, *f)).collect()
}

fn data(rows: &[[f64; 17]]) -> Vec<u8> {
    rows.iter().flatten().flat_map(|v| v.to_le_bytes()).collect()
}

#[test]
fn a_poses_file_of_another_dtype_order_or_shape_is_refused() {
    let all = data(&rows());
    let f4: Vec<u8> = rows()
        .iter()
        .flatten()
        .flat_map(|v| (*v as f32).to_le_bytes())
        .collect();
    let (_d, err) = load_npy(npy("<f4", false, "(9, 17)", &f4));
    assert!(matches!(&err, DataError::BadArray { what: "the dtype", .. }), "{err}");
    let (_d, err) = load_npy(npy(">f8", false, "(9, 17)", &all));
    assert!(err.to_string().contains("'>f8'"), "{err}");
    let (_d, err) = load_npy(npy("<f8", true, "(9, 17)", &all));
    assert!(
        matches!(
            &err,
            DataError::BadArray {
                what: "fortran_order",
                ..
            }
        ),
        "{err}"
    );
    let (_d, err) = load_npy(npy("<f8", false, "(17, 9)", &all));
    assert!(err.to_string().contains("(17, 9), expected (N, 17)"), "{err}");
    let (_d, err) = load_npy(npy("<f8", false, "(153,)", &all));
    assert!(matches!(&err, DataError::BadArray { what: "the shape", .. }), "{err}");
    let (_d, err) = load_npy(npy("<f8", false, "(0, 17)", &[]));
    assert!(matches!(&err, DataError::BadArray { what: "the shape", .. }), "{err}");
    let mut v3 = npy("<f8", false, "(9, 17)", &all);
    v3[6] = 3;
    let (_d, err) = load_npy(v3);
    assert!(err.to_string().contains("3.0, expected 1.0 or 2.0"), "{err}");
    let (_d, err) = load_npy(b"PK\x03\x04 a zip file".to_vec());
    assert!(matches!(&err, DataError::BadArray { what: "the start", .. }), "{err}");
    let (_d, err) = load_npy(npy("<f8", false, "[9, 17]", &all));
    assert!(matches!(&err, DataError::BadArray { what: "the header", .. }), "{err}");
}

#[test]
fn a_poses_file_shorter_than_its_shape_is_refused_before_allocating() {
    let all = data(&rows());
    let (_d, err) = load_npy(npy("<f8", false, "(9, 17)", &all[..all.len() - 3]));
    assert!(
        matches!(
            &err,
            DataError::Truncated {
                needed: 1224,
                available: 1221,
                ..
            }
        ),
        "{err}"
    );
    // A shape of 2^60 rows in a file of a few bytes.
    let (_d, err) = load_npy(npy("<f8", false, "(1152921504606846976, 17)", &all));
    assert!(matches!(&err, DataError::Truncated { .. }), "{err}");
    let (_d, err) = load_npy(npy("<f8", false, "(99999999999999999999999, 17)", &all));
    assert!(matches!(&err, DataError::BadArray { what: "the header", .. }), "{err}");
    let mut header_cut = npy("<f8", false, "(9, 17)", &all);
    header_cut.truncate(40);
    let (_d, err) = load_npy(header_cut);
    assert!(matches!(&err, DataError::Truncated { .. }), "{err}");
    let (_d, err) = load_npy(npy("<f8", false, "(9, 17)", &[all.clone(), vec![0; 8]].concat()));
    assert!(matches!(&err, DataError::BadArray { what: "the data", .. }), "{err}");
}

#[test]
fn absurd_rows_are_refused_naming_the_row() {
    let cases: [(usize, usize, f64, &str); 6] = [
        (2, 14, 0.0, "row 2 focal"),
        (3, 14, f64::NAN, "row 3 focal"),
        (4, 4, 0.0, "row 4 height"),
        (5, 9, f64::INFINITY, "row 5 width"),
        (6, 15, -1.0, "row 6 near"),
        (7, 16, 0.5, "row 7 far"),
    ];
    for (row, col, value, key) in cases {
        let mut r = rows();
        r[row][col] = value;
        let (_d, err) = load_npy(poses_bounds(&r));
        assert!(matches!(&err, DataError::BadValue { key: k, .. } if k == key), "{err}");
    }
    let mut r = rows();
    r[1][0] *= 2.0;
    let (_d, err) = load_npy(poses_bounds(&r));
    assert!(
        matches!(&err, DataError::BadMatrix { key, .. } if key == "row 1 pose"),
        "{err}"
    );
}

#[test]
fn pictures_that_do_not_match_the_poses_are_refused() {
    let dir = tempdir();
    write_capture(dir.path(), &views());
    let poses = dir.path().join("poses_bounds.npy");
    std::fs::remove_file(dir.path().join("images/img_03.png")).unwrap();
    let err = load(dir.path(), &LoadOptions::default()).unwrap_err();
    assert!(
        matches!(
            &err,
            DataError::ImageCount {
                poses: 9,
                images: 8,
                ..
            }
        ),
        "{err}"
    );
    names(&err, &poses);
    // A picture turned on its side.
    solid_png(&dir.path().join("images/img_03.png"), 12, 16, [0, 0, 0]);
    let err = load(dir.path(), &LoadOptions::default()).unwrap_err();
    assert!(
        matches!(&err, DataError::AspectMismatch { size: (12, 16), .. }),
        "{err}"
    );
    names(&err, &dir.path().join("images/img_03.png"));
    std::fs::remove_dir_all(dir.path().join("images")).unwrap();
    let err = load(dir.path(), &LoadOptions::default()).unwrap_err();
    assert!(matches!(&err, DataError::MissingFolder { .. }), "{err}");
    names(&err, &dir.path().join("images"));
    let err = load_cameras(dir.path(), 1).unwrap_err();
    assert!(matches!(&err, DataError::MissingFolder { .. }), "{err}");
}
