//! The ring's exact photographs of the built-in scene written as datasets on disk (Blender,
//! and instant-ngp through an off-centre, distorted lens) and read back by fogray-data: every
//! pixel's ray is the original camera's and every picture is the photograph to 8-bit
//! rounding, so a fit on the files sees what a fit on the photographs sees.

use std::collections::BTreeMap;

use fogray::ops::{Intrinsics, LensDistortion, PinholeCamera};
use fogray_data::{load, write_blender, write_instant_ngp, Format, LoadOptions};
use fogray_grid::photographs::photograph;
use fogray_grid::ring::Ring;
use fogray_grid::scene::Scene;
use fogray_grid::views::view_name;
use ndarray::Array3;

/// How far a read-back ray may be from the original (centre and unit direction, per entry).
const RAY_TOLERANCE: f64 = 1e-6;
/// How far a read-back picture may be from the photograph: its 8-bit rounding, and the `f32`
/// the loader keeps.
const PIXEL_TOLERANCE: f64 = 0.5 / 255.0 + 1e-6;

/// Writes `cameras` and their photographs of the built-in scene with `write`, loads the folder
/// back and checks every frame against its camera and photograph.
fn round_trip(
    cameras: &[PinholeCamera],
    format: Format,
    write: impl Fn(&std::path::Path, &[(&str, &PinholeCamera, &Array3<f64>)]),
) {
    let scene = Scene::default();
    let photos: Vec<Array3<f64>> = cameras.iter().map(|c| photograph(&scene, c)).collect();
    let names: Vec<String> = (0..cameras.len()).map(view_name).collect();
    let frames: Vec<_> = names
        .iter()
        .zip(cameras)
        .zip(&photos)
        .map(|((n, c), p)| (n.as_str(), c, p))
        .collect();
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), &frames);

    let data = load(dir.path(), &LoadOptions::default()).unwrap();
    assert_eq!(data.format, format);
    assert_eq!(data.skipped, 0);
    // Neither format stores a split here, so every eighth frame is held out.
    let held_out: Vec<&str> = data.test.iter().map(|f| f.name.as_str()).collect();
    let want: Vec<String> = (0..cameras.len()).step_by(8).map(view_name).collect();
    assert_eq!(held_out, want);
    let loaded: BTreeMap<&str, _> = data
        .train
        .iter()
        .chain(&data.test)
        .map(|f| (f.name.as_str(), f))
        .collect();
    assert_eq!(loaded.len(), cameras.len());

    for (i, (camera, photo)) in cameras.iter().zip(&photos).enumerate() {
        let name = view_name(i);
        let frame = loaded[name.as_str()];
        let read = &frame.camera;
        let k = camera.intrinsics();
        assert_eq!((read.intrinsics().width, read.intrinsics().height), (k.width, k.height));
        for (a, b) in read.centre().iter().zip(camera.centre()) {
            assert!(
                (a - b).abs() <= RAY_TOLERANCE,
                "{name}: centre {:?} vs {:?}",
                read.centre(),
                camera.centre()
            );
        }
        let mut worst = 0.0f64;
        for row in 0..k.height {
            for col in 0..k.width {
                let (a, b) = (read.direction(row, col), camera.direction(row, col));
                worst = (0..3).map(|j| (a[j] - b[j]).abs()).fold(worst, f64::max);
            }
        }
        assert!(worst <= RAY_TOLERANCE, "{name}: a direction is {worst} off");

        let picture = &frame.picture;
        assert!(picture.alpha.is_none(), "{name}");
        assert_eq!(picture.color.dim(), photo.dim(), "{name}");
        let off = picture
            .color
            .iter()
            .zip(photo)
            .map(|(a, b)| (f64::from(*a) - b).abs())
            .fold(0.0, f64::max);
        assert!(
            off <= PIXEL_TOLERANCE,
            "{name}: a pixel is {off} off ({} / 255)",
            off * 255.0
        );
    }
}

#[test]
fn the_rings_photographs_read_back_from_a_blender_dataset() {
    let ring = Ring::new(14, 2, 32).unwrap();
    let cameras: Vec<PinholeCamera> = (0..ring.len()).map(|i| ring.camera(i).unwrap()).collect();
    round_trip(&cameras, Format::Blender, |dir, frames| {
        let file = write_blender(dir, frames).unwrap();
        assert_eq!(file, dir.join("transforms_train.json"));
    });
}

#[test]
fn the_rings_photographs_through_a_distorted_lens_read_back_from_an_instant_ngp_dataset() {
    let ring = Ring::new(14, 2, 32).unwrap();
    let lens = LensDistortion {
        k1: -0.1,
        k2: 0.02,
        p1: 0.001,
        p2: -0.001,
        ..LensDistortion::NONE
    };
    let cameras: Vec<PinholeCamera> = (0..ring.len())
        .map(|i| {
            let pose = ring.camera(i).unwrap().camera_to_world();
            let k = *ring.camera(i).unwrap().intrinsics();
            // Off the centre by more than a pixel in each direction, and non-square pixels.
            let k = Intrinsics {
                fy: 1.03 * k.fy,
                cx: k.cx + 1.7,
                cy: k.cy - 2.3,
                ..k
            };
            PinholeCamera::new(k, pose).unwrap().with_distortion(lens).unwrap()
        })
        .collect();
    // The lens moves the picture's edge by a pixel or so: the test would see a reader that
    // dropped it.
    let plain = PinholeCamera::new(*cameras[0].intrinsics(), cameras[0].camera_to_world()).unwrap();
    let corner = (plain.direction(0, 0), cameras[0].direction(0, 0));
    assert!((0..3).map(|j| (corner.0[j] - corner.1[j]).abs()).fold(0.0, f64::max) > 1e-3);
    round_trip(&cameras, Format::InstantNgp, |dir, frames| {
        let file = write_instant_ngp(dir, frames).unwrap();
        assert_eq!(file, dir.join("transforms.json"));
    });
}

/// `fogray-grid capture` writes an instant-ngp dataset that fogray-data reads back with its
/// lens, its split and, in every picture, the exact capture photograph to 8-bit rounding.
#[test]
fn the_capture_command_writes_a_capture_that_reads_back() {
    use fogray_grid::capture::{cameras, capture_photograph, frame_name, CaptureSettings};
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("capture");
    let args = ["capture", "--views", "9", "--width", "24", "--height", "18"];
    crate::common::ok(&[&args[..], &["--out", out.to_str().unwrap()]].concat());
    let settings = CaptureSettings {
        views: 9,
        width: 24,
        height: 18,
        ..CaptureSettings::default()
    };
    let cams = cameras(&settings).unwrap();
    let data = load(&out, &LoadOptions::default()).unwrap();
    assert_eq!(data.format, Format::InstantNgp);
    let held_out: Vec<&str> = data.test.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(held_out, [frame_name(0), frame_name(8)]);
    assert_eq!(data.train.len(), 7);
    let scene = Scene::default();
    for frame in data.train.iter().chain(&data.test) {
        let i: usize = frame.name["frame_".len()..].parse().unwrap();
        assert_eq!(*frame.camera.distortion(), settings.distortion, "{}", frame.name);
        assert!(frame.picture.alpha.is_none());
        let exact = capture_photograph(&scene, &cams[i], settings.room_radius);
        let mut worst = 0.0f64;
        for row in 0..18 {
            for col in 0..24 {
                let (a, b) = (frame.camera.direction(row, col), cams[i].direction(row, col));
                worst = (0..3).map(|j| (a[j] - b[j]).abs()).fold(worst, f64::max);
                for c in 0..3 {
                    let read = f64::from(frame.picture.color[[row, col, c]]);
                    assert!((read - exact[[row, col, c]]).abs() <= PIXEL_TOLERANCE, "{}", frame.name);
                }
            }
        }
        assert!(worst <= RAY_TOLERANCE, "{}: a direction is {worst} off", frame.name);
    }
}

/// Settings that cannot make a capture are refused with one line and status 2, and nothing is
/// written.
#[test]
fn the_capture_command_refuses_bad_settings_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("capture");
    for (flag, value, names) in [
        ("--room-radius", "2", "room radius 2"),
        ("--views", "1", "1 views"),
        ("--width", "0", "0 x 360"),
    ] {
        let (code, stdout, stderr) = crate::common::grid(&["capture", flag, value, "--out", out.to_str().unwrap()]);
        assert_eq!(code, 2, "{flag} {value}: {stderr}");
        assert!(stdout.is_empty());
        assert_eq!(stderr.lines().count(), 1, "{stderr}");
        assert!(stderr.contains(names), "{flag} {value}: {stderr}");
        assert!(!out.exists());
    }
}
