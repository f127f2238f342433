//! Cameras read from hand-written files project known world points where the closed-form
//! pinhole model puts them.

use fogray_data::{load, load_cameras, LoadOptions};
use serde_json::json;

use crate::common::{blender_folder, ngp_file, tempdir};

fn close(got: [f64; 2], want: [f64; 2]) {
    assert!(
        (got[0] - want[0]).abs() < 1e-9 && (got[1] - want[1]).abs() < 1e-9,
        "got {got:?}, want {want:?}"
    );
}

#[test]
fn a_blender_camera_projects_by_the_field_of_view() {
    // Camera at (0, 0, 4), identity OpenGL rotation: looks down -Z at the origin, +Y up.
    let dir = tempdir();
    let angle: f64 = 0.9;
    blender_folder(
        dir.path(),
        angle,
        &[("r_0", [0.0, 0.0, 4.0]), ("r_1", [0.0, 0.0, 5.0])],
        8,
        6,
    );
    let scene = load(dir.path(), &LoadOptions::default()).unwrap();
    let cam = &scene.test[0].camera;
    let f = 8.0 / (2.0 * (angle / 2.0).tan());
    let (cx, cy) = (4.0, 3.0);
    // The origin is straight ahead: the image centre.
    close(cam.project([0.0, 0.0, 0.0]).unwrap(), [cx, cy]);
    // +X world is right in the image, +Y world is up (smaller row), depth 4.
    close(
        cam.project([1.0, 0.5, 0.0]).unwrap(),
        [cx + f * 1.0 / 4.0, cy - f * 0.5 / 4.0],
    );
    // Depth 3.
    close(cam.project([-1.0, -1.0, 1.0]).unwrap(), [cx - f / 3.0, cy + f / 3.0]);
    // Behind the camera.
    assert_eq!(cam.project([0.0, 0.0, 5.0]), None);
    assert_eq!(cam.centre(), [0.0, 0.0, 4.0]);
    let k = cam.intrinsics();
    assert!((k.fx - f).abs() < 1e-12 && (k.fy - f).abs() < 1e-12);
}

#[test]
fn an_ngp_camera_projects_through_its_principal_point_and_lens() {
    // Camera at (5, 0, 0) looking down -X (OpenGL back axis +X, up +Y, right -Z).
    let dir = tempdir();
    let pose = json!([
        [0.0, 0.0, 1.0, 5.0],
        [0.0, 1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, 1.0]
    ]);
    let top = json!({ "fl_x": 10.0, "fl_y": 12.0, "cx": 3.5, "cy": 2.25, "w": 8, "h": 6 });
    let frames = vec![
        json!({ "file_path": "a.png", "transform_matrix": pose }),
        json!({ "file_path": "b.png", "transform_matrix": pose, "k1": 0.1 }),
    ];
    let path = ngp_file(dir.path(), top, frames);
    let cams = load_cameras(&path, 1).unwrap();
    assert_eq!(cams.len(), 2);
    assert_eq!((cams[0].name.as_str(), cams[1].name.as_str()), ("a", "b"));
    // (0, -0.5, -1) is 5 ahead, 1 right (world -Z) and 0.5 down: normalised (0.2, 0.1).
    let p = [0.0, -0.5, -1.0];
    close(
        cams[0].camera.project(p).unwrap(),
        [10.0 * 0.2 + 3.5, 12.0 * 0.1 + 2.25],
    );
    // Through k1 = 0.1: r^2 = 0.05, radial factor 1.005.
    close(
        cams[1].camera.project(p).unwrap(),
        [10.0 * 0.2 * 1.005 + 3.5, 12.0 * 0.1 * 1.005 + 2.25],
    );
    assert_eq!(cams[1].camera.distortion().k1, 0.1);
    // The pixel whose centre is that projection sees the point (undistorted through the lens).
    // Pixel (row 3, col 5) has centre (5.5, 3.5); its ray hits x = 0 at the point whose
    // normalised coordinates are ((5.5 - 3.5) / 10, (3.5 - 2.25) / 12) for the pinhole camera.
    let d = cams[0].camera.direction(3, 5);
    let t = -5.0 / d[0];
    let hit = [5.0 + t * d[0], t * d[1], t * d[2]];
    assert!(
        (hit[2] + 5.0 * 0.2).abs() < 1e-9 && (hit[1] + 5.0 * 1.25 / 12.0).abs() < 1e-9,
        "{hit:?}"
    );
}
