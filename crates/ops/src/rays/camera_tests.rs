//! Value tests of the pinhole camera against directions derived by hand.

use super::*;
use crate::error::{At, Op, OpsError};

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn unit(v: [f64; 3]) -> [f64; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    v.map(|x| x / n)
}

/// The brief's formula for a square image with fx = fy = W / (2 tan(fov/2)), cx = cy = W/2:
/// direction(a, b) = normalise(forward + u right + v up), u = ((b+0.5)/W*2-1) tan(fov/2),
/// v = -((a+0.5)/W*2-1) tan(fov/2), with right = normalise(forward x up) and the image's
/// up = right x forward.
#[test]
fn look_at_directions_match_the_field_of_view_formula() {
    let w = 16;
    let fov = 40f64.to_radians();
    let k = Intrinsics::from_vertical_fov(w, w, fov).unwrap();
    assert_eq!(k.fx, w as f64 / (2.0 * (fov / 2.0).tan()));
    let views = [
        ([0.0, -3.0, 0.0], [0.0, 0.0, 1.0]),
        ([2.0, 1.0, 1.5], [0.0, 0.0, 1.0]),
        ([0.0, 0.0, 3.0], [0.0, 1.0, 0.0]),
        ([0.3, -0.2, -2.9], [0.0, 1.0, 0.0]),
    ];
    let tan = (fov / 2.0).tan();
    for (eye, world_up) in views {
        let cam = PinholeCamera::look_at(k, eye, [0.0; 3], world_up).unwrap();
        let forward = unit(sub([0.0; 3], eye));
        let right = unit(cross(forward, world_up));
        let up = cross(right, forward);
        let rays = cam.rays::<f64>();
        assert_eq!(rays.len(), w * w);
        for a in 0..w {
            for b in 0..w {
                let u = ((b as f64 + 0.5) / w as f64 * 2.0 - 1.0) * tan;
                let v = -((a as f64 + 0.5) / w as f64 * 2.0 - 1.0) * tan;
                let want = unit(std::array::from_fn(|i| forward[i] + u * right[i] + v * up[i]));
                let got = rays.directions().row(a * w + b).to_vec();
                for i in 0..3 {
                    assert!(
                        (got[i] - want[i]).abs() < 1e-14,
                        "eye {eye:?} pixel ({a}, {b}): {got:?} vs {want:?}"
                    );
                }
                assert_eq!(rays.origins().row(a * w + b).to_vec(), eye.to_vec());
            }
        }
    }
}

/// Intrinsics fx = 2, fy = 4, cx = 1, cy = 0.5 of a 5 x 3 image, and the identity rotation
/// at centre (1, 2, 3): the camera frame is the world frame shifted.
fn shifted_camera() -> (Intrinsics, [[f64; 4]; 4]) {
    let k = Intrinsics {
        fx: 2.0,
        fy: 4.0,
        cx: 1.0,
        cy: 0.5,
        width: 5,
        height: 3,
    };
    let m = [
        [1.0, 0.0, 0.0, 1.0],
        [0.0, 1.0, 0.0, 2.0],
        [0.0, 0.0, 1.0, 3.0],
        [0.0, 0.0, 0.0, 1.0],
    ];
    (k, m)
}

#[test]
fn general_intrinsics_and_transform() {
    // Identity rotation, centre (1, 2, 3): the camera frame is the world frame shifted.
    // Pixel (row 1, col 3) with fx = 2, fy = 4, cx = 1, cy = 0.5: camera direction
    // ((3.5 - 1) / 2, (1.5 - 0.5) / 4, 1) = (1.25, 0.25, 1), length sqrt(2.625).
    let (k, m) = shifted_camera();
    let cam = PinholeCamera::new(k, m).unwrap();
    let n = 2.625f64.sqrt();
    let d = cam.direction(1, 3);
    for (g, w) in d.iter().zip([1.25 / n, 0.25 / n, 1.0 / n]) {
        assert!((g - w).abs() < 1e-15);
    }
    assert_eq!(cam.camera_to_world(), m);
    assert_eq!(cam.centre(), [1.0, 2.0, 3.0]);
    // A scaled transform gives the same unit directions.
    let mut scaled = m;
    (0..3).for_each(|i| (0..3).for_each(|j| scaled[i][j] *= 2.5));
    let d2 = PinholeCamera::new(k, scaled).unwrap().direction(1, 3);
    assert!(d.iter().zip(d2).all(|(a, b)| (a - b).abs() < 1e-15));
}

/// `direction_at` takes any point of the image: with the intrinsics of the test above, the
/// point (y 0.25, x 3.75) of pixel (0, 3) has the camera direction ((3.75 - 1) / 2,
/// (0.25 - 0.5) / 4, 1) = (1.375, -0.0625, 1); a pixel's centre is `direction`'s ray, bit for
/// bit, through a lens too.
#[test]
fn a_point_of_the_image_has_the_direction_through_it() {
    let (k, m) = shifted_camera();
    let cam = PinholeCamera::new(k, m).unwrap();
    let n = (1.375f64 * 1.375 + 0.0625 * 0.0625 + 1.0).sqrt();
    let d = cam.direction_at(0.25, 3.75);
    for (g, w) in d.iter().zip([1.375 / n, -0.0625 / n, 1.0 / n]) {
        assert!((g - w).abs() < 1e-15, "{d:?}");
    }
    let lens = LensDistortion {
        k1: 0.1,
        k2: -0.02,
        p1: 0.001,
        p2: -0.002,
        k3: 0.0,
        k4: 0.0,
    };
    for camera in [cam, PinholeCamera::new(k, m).unwrap().with_distortion(lens).unwrap()] {
        for (row, col) in [(0, 0), (1, 3), (2, 4)] {
            let centre = camera.direction_at(row as f64 + 0.5, col as f64 + 0.5);
            assert_eq!(centre, camera.direction(row, col));
        }
        assert_ne!(camera.direction_at(1.25, 3.5), camera.direction(1, 3));
    }
}

#[test]
fn opengl_pose_is_the_opencv_pose_with_y_and_z_flipped() {
    let k = Intrinsics::from_vertical_fov(6, 4, 0.8).unwrap();
    let cv = PinholeCamera::look_at(k, [1.0, -2.0, 0.5], [0.1, 0.2, 0.0], [0.0, 0.0, 1.0]).unwrap();
    let mut gl = cv.camera_to_world();
    for row in gl.iter_mut().take(3) {
        row[1] = -row[1];
        row[2] = -row[2];
    }
    let from_gl = PinholeCamera::from_opengl(k, gl).unwrap();
    assert_eq!(from_gl.rays::<f64>(), cv.rays::<f64>());
}

#[test]
fn chosen_pixels_and_pairs_pick_rows_of_the_full_batch() {
    let k = Intrinsics::from_vertical_fov(7, 5, 0.7).unwrap();
    let a = PinholeCamera::look_at(k, [0.0, -3.0, 0.0], [0.0; 3], [0.0, 0.0, 1.0]).unwrap();
    let b = PinholeCamera::look_at(k, [3.0, 0.0, 0.0], [0.0; 3], [0.0, 0.0, 1.0]).unwrap();
    let (all_a, all_b) = (a.rays::<f32>(), b.rays::<f32>());
    let picked = a.rays_for_pixels::<f32>(&[34, 0, 34, 12]).unwrap();
    for (i, p) in [34, 0, 34, 12].into_iter().enumerate() {
        assert_eq!(picked.directions().row(i), all_a.directions().row(p));
    }
    let pairs = [
        CameraPixel { camera: 1, pixel: 3 },
        CameraPixel { camera: 0, pixel: 20 },
    ];
    let mixed = rays_for_camera_pixels::<f32>(&[a.clone(), b.clone()], &pairs).unwrap();
    assert_eq!(mixed.directions().row(0), all_b.directions().row(3));
    assert_eq!(mixed.origins().row(1), all_a.origins().row(20));
    assert_eq!(
        a.rays_for_pixels::<f32>(&[35]).unwrap_err(),
        OpsError::OutOfRange {
            op: Op::Rays,
            what: "pixel",
            index: 35,
            len: 35
        }
    );
    assert_eq!(
        rays_for_camera_pixels::<f32>(&[a, b], &[CameraPixel { camera: 2, pixel: 0 }]).unwrap_err(),
        OpsError::OutOfRange {
            op: Op::Rays,
            what: "camera",
            index: 2,
            len: 2
        }
    );
}

#[test]
fn bad_cameras_are_errors() {
    let k = Intrinsics::from_vertical_fov(4, 4, 1.0).unwrap();
    let id = [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ];
    assert_eq!(
        Intrinsics::from_vertical_fov(0, 4, 1.0),
        Err(OpsError::EmptyImage {
            op: Op::Rays,
            width: 0,
            height: 4
        })
    );
    assert!(Intrinsics::from_vertical_fov(4, 4, 0.0).is_err());
    assert!(Intrinsics::from_vertical_fov(4, 4, 3.2).is_err());
    assert!(PinholeCamera::new(Intrinsics { fx: 0.0, ..k }, id).is_err());
    assert!(PinholeCamera::new(Intrinsics { cx: f64::NAN, ..k }, id).is_err());
    assert!(PinholeCamera::new(Intrinsics { height: 0, ..k }, id).is_err());
    let mut nan = id;
    nan[1][3] = f64::NAN;
    assert!(matches!(
        PinholeCamera::new(k, nan),
        Err(OpsError::Frame {
            op: Op::Rays,
            what: "camera-to-world transform",
            ..
        })
    ));
    let mut singular = id;
    singular[2] = [1.0, 0.0, 0.0, 0.0]; // third row = first: rank 2
    assert!(matches!(
        PinholeCamera::new(k, singular),
        Err(OpsError::Frame {
            op: Op::Rays,
            what: "camera-to-world transform",
            ..
        })
    ));
    let mut projective = id;
    projective[3][0] = 0.5;
    assert!(matches!(
        PinholeCamera::new(k, projective),
        Err(OpsError::Frame {
            op: Op::Rays,
            what: "camera-to-world transform",
            ..
        })
    ));
    let look = |eye, target, up| PinholeCamera::look_at(k, eye, target, up);
    assert!(matches!(
        look([1.0; 3], [1.0; 3], [0.0, 0.0, 1.0]),
        Err(OpsError::Frame {
            op: Op::Rays,
            what: "look_at",
            ..
        })
    ));
    assert!(matches!(
        look([0.0, 0.0, 3.0], [0.0; 3], [0.0, 0.0, 1.0]),
        Err(OpsError::Frame {
            op: Op::Rays,
            what: "look_at",
            ..
        })
    ));
    assert!(matches!(
        look([0.0, 0.0, 3.0], [0.0; 3], [0.0; 3]),
        Err(OpsError::Frame {
            op: Op::Rays,
            what: "look_at",
            ..
        })
    ));
    assert!(look([f64::INFINITY, 0.0, 3.0], [0.0; 3], [0.0, 1.0, 0.0]).is_err());
}

/// A camera at (0, 0, 4) (OpenGL axes: looking down -Z, +Y up) with fx = fy = 100, the
/// principal point off centre at (37, 21): the origin lands on the principal point, (1, 0, 0)
/// at x = 37 + 100 * 1/4, and (0, 1, 0) above it (y = 21 - 25, rows grow downwards).
#[test]
fn known_points_project_where_the_pinhole_formula_puts_them() {
    let k = Intrinsics {
        fx: 100.0,
        fy: 100.0,
        cx: 37.0,
        cy: 21.0,
        width: 64,
        height: 48,
    };
    let c2w = [
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 4.0],
        [0.0, 0.0, 0.0, 1.0],
    ];
    let cam = PinholeCamera::from_opengl(k, c2w).unwrap();
    let close = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).abs() < 1e-12 && (a[1] - b[1]).abs() < 1e-12;
    assert!(close(cam.project([0.0; 3]).unwrap(), [37.0, 21.0]));
    assert!(close(cam.project([1.0, 0.0, 0.0]).unwrap(), [62.0, 21.0]));
    assert!(close(cam.project([0.0, 1.0, 0.0]).unwrap(), [37.0, -4.0]));
    assert_eq!(cam.project([0.0, 0.0, 5.0]), None, "behind the camera");
}

/// Every pixel's ray, followed to any depth and projected back through the lens, lands on
/// that pixel's centre: the ray is undistorted exactly as the projection distorts. Without the
/// undistortion (the pinhole ray), border pixels land pixels away.
#[test]
fn a_distorted_cameras_rays_project_back_onto_their_pixels() {
    let k = Intrinsics {
        fx: 60.0,
        fy: 58.0,
        cx: 33.0,
        cy: 22.5,
        width: 64,
        height: 48,
    };
    let lens = LensDistortion {
        k1: -0.2,
        k2: 0.05,
        k3: 0.0,
        k4: 0.0,
        p1: 0.002,
        p2: -0.001,
    };
    let cam = PinholeCamera::look_at(k, [2.0, -3.0, 1.0], [0.0; 3], [0.0, 0.0, 1.0]).unwrap();
    let pinhole = cam.clone();
    let cam = cam.with_distortion(lens).unwrap();
    assert_eq!(*cam.distortion(), lens);
    let c = cam.centre();
    let mut worst_pinhole = 0.0f64;
    for row in 0..48 {
        for col in 0..64 {
            let want = [col as f64 + 0.5, row as f64 + 0.5];
            for (camera, t) in [(&cam, 0.7), (&cam, 3.0), (&pinhole, 3.0)] {
                let d = camera.direction(row, col);
                let p = [c[0] + t * d[0], c[1] + t * d[1], c[2] + t * d[2]];
                let got = cam.project(p).unwrap();
                let off = (got[0] - want[0]).abs().max((got[1] - want[1]).abs());
                if std::ptr::eq(camera, &pinhole) {
                    worst_pinhole = worst_pinhole.max(off);
                } else {
                    assert!(off < 1e-9, "pixel ({row}, {col}) at t = {t}: {got:?}");
                }
            }
        }
    }
    assert!(worst_pinhole > 1.0, "{worst_pinhole}");
}

#[test]
fn a_non_finite_distortion_is_refused() {
    let k = Intrinsics::from_vertical_fov(8, 8, 0.8).unwrap();
    let cam = PinholeCamera::look_at(k, [0.0, -3.0, 0.0], [0.0; 3], [0.0, 0.0, 1.0]).unwrap();
    let lens = LensDistortion {
        k1: f64::INFINITY,
        ..LensDistortion::NONE
    };
    assert!(matches!(
        cam.with_distortion(lens),
        Err(OpsError::Domain {
            op: Op::Rays,
            at: At::Value,
            ..
        })
    ));
}
