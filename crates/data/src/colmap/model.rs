//! A COLMAP sparse model as read from either layout: cameras (model and parameters), images
//! (pose and camera), points; and the checks that both readers share.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use fogray_ops::LensDistortion;

use crate::error::DataError;
use crate::escape::escape_controls;
use crate::world::{mul, transpose};

/// COLMAP's camera models by id (the binary layout's `model_id`), name and number of
/// parameters; only the first five are read, the others are named in the refusal.
const MODELS: [(&str, usize); 12] = [
    ("SIMPLE_PINHOLE", 3),
    ("PINHOLE", 4),
    ("SIMPLE_RADIAL", 4),
    ("RADIAL", 5),
    ("OPENCV", 8),
    ("OPENCV_FISHEYE", 8),
    ("FULL_OPENCV", 12),
    ("FOV", 5),
    ("SIMPLE_RADIAL_FISHEYE", 4),
    ("RADIAL_FISHEYE", 5),
    ("THIN_PRISM_FISHEYE", 12),
    ("RAD_TAN_THIN_PRISM_FISHEYE", 16),
];

/// How many of [`MODELS`] are read: pinhole cameras with OpenCV radial-tangential distortion.
const SUPPORTED: usize = 5;

/// Largest image side accepted (the transforms files' limit).
const MAX_SIDE: u64 = u32::MAX as u64;

/// A camera model that fogray reads: its index in [`MODELS`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Model(usize);

impl Model {
    /// The model of binary id `id`. Errors: an id of a model fogray does not read, or of none.
    pub fn by_id(path: &Path, camera: i64, id: i32) -> Result<Model, DataError> {
        match usize::try_from(id).ok().filter(|&i| i < MODELS.len()) {
            Some(i) if i < SUPPORTED => Ok(Model(i)),
            Some(i) => Err(refused(path, camera, MODELS[i].0.to_string())),
            None => Err(refused(path, camera, format!("id {id} (no COLMAP model has it)"))),
        }
    }

    /// The model named `name` (text layout). Errors as [`Model::by_id`].
    pub fn by_name(path: &Path, camera: i64, name: &str) -> Result<Model, DataError> {
        match MODELS.iter().position(|(n, _)| *n == name) {
            Some(i) if i < SUPPORTED => Ok(Model(i)),
            _ => Err(refused(path, camera, escape_controls(name).into_owned())),
        }
    }

    /// How many parameters the model has.
    pub fn params(self) -> usize {
        MODELS[self.0].1
    }
}

fn refused(path: &Path, camera: i64, model: String) -> DataError {
    DataError::CameraModel {
        path: path.to_path_buf(),
        camera,
        model,
    }
}

/// A camera: full-size intrinsics and lens.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Camera {
    pub width: usize,
    pub height: usize,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub distortion: LensDistortion,
}

impl Camera {
    /// The camera `id` of `model` for a `width x height` image with COLMAP's `params`
    /// (`model.params()` of them): SIMPLE_PINHOLE `f cx cy`, PINHOLE `fx fy cx cy`,
    /// SIMPLE_RADIAL `f cx cy k`, RADIAL `f cx cy k1 k2`, OPENCV `fx fy cx cy k1 k2 p1 p2`
    /// (COLMAP's principal point is in the same pixel convention as fogray's: the first
    /// pixel's centre at (0.5, 0.5)). Errors ([`DataError::BadValue`]): a side of 0 or over
    /// `2^32 - 1`, a focal length that is not positive and finite, a principal point or
    /// coefficient that is not finite.
    pub fn new(
        path: &Path,
        id: i64,
        model: Model,
        width: u64,
        height: u64,
        params: &[f64],
    ) -> Result<Camera, DataError> {
        let bad = |what: &str, value: f64, rule| DataError::BadValue {
            path: path.to_path_buf(),
            key: format!("camera {id} {what}"),
            value,
            rule,
        };
        for (what, side) in [("width", width), ("height", height)] {
            if side == 0 || side > MAX_SIDE {
                return Err(bad(what, side as f64, "must be a whole number from 1 to 2^32 - 1"));
            }
        }
        let p = |i: usize| params[i];
        let (fx, fy, cx, cy, k) = match model.0 {
            0 => (p(0), p(0), p(1), p(2), [0.0; 4]),
            1 => (p(0), p(1), p(2), p(3), [0.0; 4]),
            2 => (p(0), p(0), p(1), p(2), [p(3), 0.0, 0.0, 0.0]),
            3 => (p(0), p(0), p(1), p(2), [p(3), p(4), 0.0, 0.0]),
            _ => (p(0), p(1), p(2), p(3), [p(4), p(5), p(6), p(7)]),
        };
        for (what, f) in [("fx", fx), ("fy", fy)] {
            if !(f.is_finite() && f > 0.0) {
                return Err(bad(what, f, "a focal length must be positive and finite"));
            }
        }
        for (what, v) in [
            ("cx", cx),
            ("cy", cy),
            ("k1", k[0]),
            ("k2", k[1]),
            ("p1", k[2]),
            ("p2", k[3]),
        ] {
            if !v.is_finite() {
                return Err(bad(what, v, "must be finite"));
            }
        }
        Ok(Camera {
            width: width as usize,
            height: height as usize,
            fx,
            fy,
            cx,
            cy,
            distortion: LensDistortion {
                k1: k[0],
                k2: k[1],
                p1: k[2],
                p2: k[3],
                ..LensDistortion::NONE
            },
        })
    }
}

/// A registered image: its pose (world to camera, OpenCV axes) and camera.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Image {
    pub id: i64,
    /// The rotation as a unit quaternion `w x y z`.
    pub quaternion: [f64; 4],
    pub translation: [f64; 3],
    pub camera: i64,
    /// The file name, relative to the images folder (`/` separated).
    pub name: String,
}

impl Image {
    /// The image `id`: its quaternion normalised (COLMAP normalises it too; it is written to
    /// about 1e-16). Errors ([`DataError::BadValue`]): a value that is not finite, a zero
    /// quaternion.
    pub fn new(path: &Path, id: i64, q: [f64; 4], t: [f64; 3], camera: i64, name: String) -> Result<Image, DataError> {
        let bad = |what: &str, value: f64, rule| DataError::BadValue {
            path: path.to_path_buf(),
            key: format!("image {id} (`{}`) {what}", escape_controls(&name)),
            value,
            rule,
        };
        for (what, v) in ["qw", "qx", "qy", "qz"]
            .into_iter()
            .zip(q)
            .chain(["tx", "ty", "tz"].into_iter().zip(t))
        {
            if !v.is_finite() {
                return Err(bad(what, v, "must be finite"));
            }
        }
        let length = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        if !(length > 1e-12 && length.is_finite()) {
            return Err(bad(
                "quaternion length",
                length,
                "a rotation's quaternion must not be zero",
            ));
        }
        Ok(Image {
            id,
            quaternion: q.map(|v| v / length),
            translation: t,
            camera,
            name,
        })
    }

    /// The camera-to-world matrix in OpenCV axes: COLMAP stores world-to-camera
    /// `x_cam = R x_world + t`, so the camera's axes are the rows of `R` and its centre
    /// `-Rᵀ t`.
    pub fn camera_to_world(&self) -> [[f64; 4]; 4] {
        let r = rotation(self.quaternion);
        let rt = transpose(&r);
        let centre = mul(&rt, self.translation).map(|v| -v);
        let mut m = [[0.0, 0.0, 0.0, 0.0], [0.0; 4], [0.0; 4], [0.0, 0.0, 0.0, 1.0]];
        for ((row, axes), c) in m.iter_mut().zip(rt).zip(centre) {
            row[..3].copy_from_slice(&axes);
            row[3] = c;
        }
        m
    }
}

/// The rotation of the unit quaternion `w x y z` (Hamilton's convention, as COLMAP's).
pub(crate) fn rotation([w, x, y, z]: [f64; 4]) -> [[f64; 3]; 3] {
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// A sparse point: position (the file's world) and colour.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Point {
    pub position: [f64; 3],
    pub color: [u8; 3],
}

impl Point {
    /// Errors ([`DataError::BadValue`]): a coordinate that is not finite.
    pub fn new(path: &Path, id: u64, position: [f64; 3], color: [u8; 3]) -> Result<Point, DataError> {
        match position.iter().find(|v| !v.is_finite()) {
            Some(&v) => Err(DataError::BadValue {
                path: path.to_path_buf(),
                key: format!("point {id} position"),
                value: v,
                rule: "must be finite",
            }),
            None => Ok(Point { position, color }),
        }
    }
}

/// Cameras by id, for one file; a second camera with an id already seen is an error.
pub(crate) fn insert_camera(
    cameras: &mut HashMap<i64, Camera>,
    path: &Path,
    at: String,
    id: i64,
    camera: Camera,
) -> Result<(), DataError> {
    if cameras.insert(id, camera).is_some() {
        return Err(DataError::Malformed {
            path: path.to_path_buf(),
            at,
            message: format!("camera id {id} appears twice"),
        });
    }
    Ok(())
}

/// The three files of a model in one layout.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ModelFiles {
    pub cameras: PathBuf,
    pub images: PathBuf,
    pub points: PathBuf,
    pub binary: bool,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quaternions_give_the_rotations_they_name() {
        // A quarter turn about +z: (cos 45°, 0, 0, sin 45°) sends x to y and y to -x.
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let r = rotation([h, 0.0, 0.0, h]);
        let want = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
        assert!(
            r.iter()
                .flatten()
                .zip(want.iter().flatten())
                .all(|(a, b)| (a - b).abs() < 1e-15),
            "{r:?}"
        );
        // A half turn about +x: (0, 1, 0, 0) negates y and z.
        assert_eq!(
            rotation([0.0, 1.0, 0.0, 0.0]),
            [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]
        );
    }

    #[test]
    fn an_image_centre_is_minus_r_transpose_t() {
        // R a quarter turn about +z (x -> y), t = (1, 2, 3): centre = -Rᵀ t = -(2, -1, 3).
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let image = Image::new(
            Path::new("i"),
            1,
            [2.0 * h, 0.0, 0.0, 2.0 * h],
            [1.0, 2.0, 3.0],
            1,
            "a".into(),
        )
        .unwrap();
        let m = image.camera_to_world();
        let want = [-2.0, 1.0, -3.0];
        assert!(m.iter().zip(want).all(|(row, w)| (row[3] - w).abs() < 1e-15), "{m:?}");
        // The camera's x axis (first column) is the first row of R: (0, -1, 0).
        assert!((m[0][0]).abs() < 1e-15 && (m[1][0] + 1.0).abs() < 1e-15);
    }

    #[test]
    fn models_are_named_in_refusals() {
        let p = Path::new("cameras.bin");
        assert_eq!(Model::by_id(p, 1, 4).unwrap().params(), 8);
        assert_eq!(Model::by_name(p, 1, "SIMPLE_RADIAL").unwrap().params(), 4);
        let e = Model::by_id(p, 7, 5).unwrap_err().to_string();
        assert!(e.contains("OPENCV_FISHEYE") && e.contains("camera 7"), "{e}");
        let e = Model::by_id(p, 7, 99).unwrap_err().to_string();
        assert!(e.contains("id 99"), "{e}");
        let e = Model::by_name(p, 2, "FULL_OPENCV").unwrap_err().to_string();
        assert!(e.contains("FULL_OPENCV"), "{e}");
    }
}
