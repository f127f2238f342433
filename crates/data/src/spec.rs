//! A frame as a transforms file describes it, before its image is read: the image file, the
//! pose, the lens, and what the file says of the image size.
//!
//! Both formats end here, so that decoding, size checks, downscaling and camera building are
//! written once.

use std::path::{Path, PathBuf};

use fogray_ops::{Intrinsics, LensDistortion, PinholeCamera};

use crate::downscale::downscale_intrinsics;
use crate::error::DataError;
use crate::json::Obj;

/// Focal lengths and principal point as a transforms file gives them; the image size turns
/// them into [`Intrinsics`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct Lens {
    pub fl_x: Option<f64>,
    pub fl_y: Option<f64>,
    /// Horizontal field of view, radians.
    pub angle_x: Option<f64>,
    /// Vertical field of view, radians.
    pub angle_y: Option<f64>,
    pub cx: Option<f64>,
    pub cy: Option<f64>,
}

impl Lens {
    /// The keys `fl_x fl_y camera_angle_x camera_angle_y cx cy` of `obj` (each absent is
    /// `None`). Errors: a focal length that is not positive and finite, a field of view outside
    /// (0, pi), a principal point that is not finite.
    pub fn read(obj: Obj<'_>) -> Result<Lens, DataError> {
        let angle = |key: &str| -> Result<Option<f64>, DataError> {
            match obj.number(key)? {
                Some(a) if !(a.is_finite() && a > 0.0 && a < std::f64::consts::PI) => {
                    Err(obj.bad_value(key, a, "a field of view must be in (0, pi) radians"))
                }
                a => Ok(a),
            }
        };
        Ok(Lens {
            fl_x: obj.positive("fl_x")?,
            fl_y: obj.positive("fl_y")?,
            angle_x: angle("camera_angle_x")?,
            angle_y: angle("camera_angle_y")?,
            cx: obj.finite("cx")?,
            cy: obj.finite("cy")?,
        })
    }

    /// `self` with every value that `frame` gives replaced by the frame's.
    pub fn overridden_by(self, frame: Lens) -> Lens {
        Lens {
            fl_x: frame.fl_x.or(self.fl_x),
            fl_y: frame.fl_y.or(self.fl_y),
            angle_x: frame.angle_x.or(self.angle_x),
            angle_y: frame.angle_y.or(self.angle_y),
            cx: frame.cx.or(self.cx),
            cy: frame.cy.or(self.cy),
        }
    }

    /// Whether some focal length can be found (one axis is enough: square pixels then).
    pub fn has_focal(&self) -> bool {
        self.fl_x.is_some() || self.fl_y.is_some() || self.angle_x.is_some() || self.angle_y.is_some()
    }

    /// The intrinsics for a `width x height` image: `fx = fl_x`, or `W / (2 tan(angle_x / 2))`;
    /// `fy` likewise with `H`; an axis without either takes the other's focal length; the
    /// principal point defaults to the image centre. Call only when [`Lens::has_focal`].
    pub fn intrinsics(&self, width: usize, height: usize) -> Intrinsics {
        let (w, h) = (width as f64, height as f64);
        let fx = self.fl_x.or(self.angle_x.map(|a| w / (2.0 * (a / 2.0).tan())));
        let fy = self.fl_y.or(self.angle_y.map(|a| h / (2.0 * (a / 2.0).tan())));
        let (fx, fy) = match (fx, fy) {
            (Some(x), Some(y)) => (x, y),
            (Some(x), None) => (x, x),
            (None, Some(y)) => (y, y),
            (None, None) => (f64::NAN, f64::NAN),
        };
        Intrinsics {
            fx,
            fy,
            cx: self.cx.unwrap_or(w / 2.0),
            cy: self.cy.unwrap_or(h / 2.0),
            width,
            height,
        }
    }
}

/// One frame of a transforms file, its image not yet read.
#[derive(Debug, Clone)]
pub(crate) struct FrameSpec {
    /// The transforms file it comes from.
    pub transforms: PathBuf,
    /// `frames[i]`, to name it in errors.
    pub key: String,
    /// `file_path` without folder and extension.
    pub name: String,
    /// The image file.
    pub file: PathBuf,
    /// The OpenGL camera-to-world matrix, checked rigid.
    pub pose: [[f64; 4]; 4],
    pub lens: Lens,
    pub distortion: LensDistortion,
    /// `w` and `h` where the file gives them.
    pub size: Option<(usize, usize)>,
}

impl FrameSpec {
    /// The camera for a `width x height` image (the file's full size), downscaled by `factor`.
    pub fn camera(&self, width: usize, height: usize, factor: usize) -> Result<PinholeCamera, DataError> {
        if width / factor == 0 || height / factor == 0 {
            return Err(DataError::BadDownscale {
                path: self.file.clone(),
                downscale: factor,
                problem: "is larger than the image",
            });
        }
        let full = self.lens.intrinsics(width, height);
        if let Some((key, value, rule)) = crate::ranges::intrinsics_outside(&full) {
            // Named as the file gives it (a focal length may come from a field of view), for
            // the frame it applies to (its own value or the file's global one).
            let key = match (key, self.lens.fl_x, self.lens.fl_y) {
                ("fl_x", None, _) => "fx (from camera_angle_x or fl_y)",
                ("fl_y", _, None) => "fy (from camera_angle_y or fl_x)",
                _ => key,
            };
            return Err(DataError::BadValue {
                path: self.transforms.clone(),
                key: format!("{key} of {}", self.key),
                value,
                rule,
            });
        }
        let k = downscale_intrinsics(&full, factor);
        let wrap = |source| DataError::Camera {
            path: self.transforms.clone(),
            key: self.key.clone(),
            source: Box::new(source),
        };
        PinholeCamera::from_opengl(k, self.pose)
            .and_then(|c| c.with_distortion(self.distortion))
            .map_err(wrap)
    }
}

/// `file_path` resolved against the transforms file's folder, with `.png` appended when it has
/// no extension and `append_png` (the Blender convention), and its name (the file stem).
pub(crate) fn image_path(folder: &Path, file_path: &str, append_png: bool) -> (PathBuf, String) {
    // Paths written on Windows use backslashes; a Linux file name with one is rare enough.
    let relative = file_path.replace('\\', "/");
    let mut file = folder.join(&relative);
    if append_png && Path::new(&relative).extension().is_none() {
        let mut s = file.into_os_string();
        s.push(".png");
        file = PathBuf::from(s);
    }
    let name = Path::new(&relative)
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let name = match (append_png, Path::new(&relative).extension()) {
        (true, None) => name,
        _ => Path::new(&name)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or(name),
    };
    (file, name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blender_paths_get_png_and_keep_their_stem() {
        let (file, name) = image_path(Path::new("/d"), "./train/r_0", true);
        assert_eq!(file, Path::new("/d/./train/r_0.png"));
        assert_eq!(name, "r_0");
        let (file, name) = image_path(Path::new("/d"), "images/f.1.jpg", true);
        assert_eq!(file, Path::new("/d/images/f.1.jpg"));
        assert_eq!(name, "f.1");
    }

    #[test]
    fn focal_from_either_axis_and_centre_by_default() {
        let lens = Lens {
            angle_x: Some(2.0 * (0.5f64).atan()),
            ..Lens::default()
        };
        let k = lens.intrinsics(8, 6);
        assert!((k.fx - 8.0).abs() < 1e-12 && (k.fy - 8.0).abs() < 1e-12);
        assert_eq!((k.cx, k.cy), (4.0, 3.0));
        let lens = Lens {
            fl_y: Some(5.0),
            angle_x: Some(2.0 * (0.5f64).atan()),
            cx: Some(1.0),
            ..Lens::default()
        };
        let k = lens.intrinsics(8, 6);
        assert!((k.fx - 8.0).abs() < 1e-12);
        assert_eq!((k.fy, k.cx, k.cy), (5.0, 1.0, 3.0));
    }
}
