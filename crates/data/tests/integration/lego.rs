//! The real lego scene, when `FOGRAY_DATA` names a folder holding `nerf_synthetic/lego`.

use std::path::PathBuf;

use fogray_data::{load, Format, LoadOptions};

#[test]
fn lego_at_downscale_4_when_present() {
    let Some(root) = std::env::var_os("FOGRAY_DATA") else {
        eprintln!("skipping lego: FOGRAY_DATA is not set");
        return;
    };
    let path = PathBuf::from(root).join("nerf_synthetic/lego");
    let options = LoadOptions {
        downscale: 4,
        ..LoadOptions::default()
    };
    let scene = load(&path, &options).unwrap();
    assert_eq!(scene.format, Format::Blender);
    assert_eq!((scene.train.len(), scene.test.len()), (78, 12));
    for frame in scene.train.iter().chain(&scene.test) {
        assert_eq!(frame.picture.color.dim(), (200, 200, 3));
        let k = frame.camera.intrinsics();
        assert_eq!((k.width, k.height), (200, 200));
        assert!(frame.picture.alpha.is_some());
    }
    assert_eq!(scene.test[0].name, "r_0");
    // lego's camera_angle_x 0.6911112: fx = 800 / (2 tan(0.3455556)) / 4.
    let fx = scene.train[0].camera.intrinsics().fx;
    assert!((fx - 800.0 / (2.0 * (0.6911112070083618f64 / 2.0).tan()) / 4.0).abs() < 1e-9);
}
