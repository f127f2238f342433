//! The pinhole camera: intrinsics, a camera-to-world transform, and a ray through every pixel.
//!
//! Convention (OpenCV): in the camera frame x points right, y down and z forward (the viewing
//! direction); pixel (row `a`, column `b`) has its centre at image coordinates
//! `(b + 0.5, a + 0.5)` and its ray the camera-frame direction
//! `((b + 0.5 - cx) / fx, (a + 0.5 - cy) / fy, 1)`, undistorted first when the camera has a
//! lens [`LensDistortion`]. Pixel index `a * width + b` (row-major).

use fogray_tape::Float;

use super::batch::{normalise, RayBatch};
use super::distortion::LensDistortion;
use super::frame::{checked_transform, Frame};
use crate::error::{At, Op, OpsError};

/// Focal lengths and principal point in pixels, and the image size.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Intrinsics {
    /// Focal length along x, in pixels (finite, non-zero).
    pub fx: f64,
    /// Focal length along y, in pixels (finite, non-zero).
    pub fy: f64,
    /// Principal point x, in pixels (finite).
    pub cx: f64,
    /// Principal point y, in pixels (finite).
    pub cy: f64,
    /// Pixels per row (at least 1).
    pub width: usize,
    /// Rows (at least 1).
    pub height: usize,
}

impl Intrinsics {
    /// Square pixels with the principal point at the image centre and the vertical field of
    /// view `fov_y` (radians, in (0, pi)): `fy = fx = height / (2 tan(fov_y / 2))`,
    /// `cx = width / 2`, `cy = height / 2`.
    ///
    /// Errors: a zero size, a field of view outside (0, pi).
    pub fn from_vertical_fov(width: usize, height: usize, fov_y: f64) -> Result<Self, OpsError> {
        if !(fov_y > 0.0 && fov_y < std::f64::consts::PI) {
            return Err(OpsError::Domain {
                op: Op::Rays,
                at: At::Value,
                what: "vertical field of view".into(),
                value: fov_y,
                rule: "must be in (0, pi) radians",
            });
        }
        let f = height as f64 / (2.0 * (fov_y / 2.0).tan());
        let k = Intrinsics {
            fx: f,
            fy: f,
            cx: width as f64 / 2.0,
            cy: height as f64 / 2.0,
            width,
            height,
        };
        k.check()?;
        Ok(k)
    }

    /// Checks the domain of every field (see the field docs).
    pub fn check(&self) -> Result<(), OpsError> {
        if self.width == 0 || self.height == 0 {
            return Err(OpsError::EmptyImage {
                op: Op::Rays,
                width: self.width,
                height: self.height,
            });
        }
        for (what, v, nonzero) in [
            ("fx", self.fx, true),
            ("fy", self.fy, true),
            ("cx", self.cx, false),
            ("cy", self.cy, false),
        ] {
            if !v.is_finite() || (nonzero && v == 0.0) {
                return Err(OpsError::Domain {
                    op: Op::Rays,
                    at: At::Value,
                    what: what.into(),
                    value: v,
                    rule: if nonzero {
                        "must be finite and non-zero"
                    } else {
                        "must be finite"
                    },
                });
            }
        }
        Ok(())
    }

    /// Number of pixels, `width * height`.
    pub fn pixels(&self) -> usize {
        self.width * self.height
    }
}

/// A pinhole camera: [`Intrinsics`] and where the camera is (see the [module docs](self) for
/// the axis convention).
#[derive(Debug, Clone, PartialEq)]
pub struct PinholeCamera {
    intrinsics: Intrinsics,
    frame: Frame,
    distortion: LensDistortion,
}

impl PinholeCamera {
    /// A camera from its intrinsics and its camera-to-world transform, a 4x4 matrix
    /// `[[R, c], [0 0 0 1]]` (row-major) mapping camera-frame points (x right, y down,
    /// z forward) to world points; `c` is the camera centre.
    ///
    /// `R` may scale or shear (rays are normalised after it) but must be invertible.
    /// Errors: bad intrinsics, a non-finite entry, a last row other than `0 0 0 1`, or a
    /// singular `R` (its determinant below `1e-9` times the product of its column lengths).
    pub fn new(intrinsics: Intrinsics, camera_to_world: [[f64; 4]; 4]) -> Result<Self, OpsError> {
        intrinsics.check()?;
        Ok(PinholeCamera {
            intrinsics,
            frame: checked_transform(camera_to_world)?,
            distortion: LensDistortion::NONE,
        })
    }

    /// A camera from a camera-to-world transform in the OpenGL / NeRF-Blender convention
    /// (x right, y up, z backward): the same as [`PinholeCamera::new`] after negating the
    /// transform's y and z columns. Errors as [`PinholeCamera::new`].
    pub fn from_opengl(intrinsics: Intrinsics, camera_to_world: [[f64; 4]; 4]) -> Result<Self, OpsError> {
        let mut m = camera_to_world;
        for row in m.iter_mut().take(3) {
            row[1] = -row[1];
            row[2] = -row[2];
        }
        Self::new(intrinsics, m)
    }

    /// A camera at `eye` looking at `target`, rolled so that `up` (world) appears up in the
    /// image: forward `f = normalise(target - eye)`, right `x = normalise(f × up)`, down
    /// `y = f × x`.
    ///
    /// Errors: bad intrinsics, a non-finite input, `eye == target`, or `up` (nearly) parallel
    /// to the viewing direction (the sine of their angle below `1e-9`).
    pub fn look_at(intrinsics: Intrinsics, eye: [f64; 3], target: [f64; 3], up: [f64; 3]) -> Result<Self, OpsError> {
        intrinsics.check()?;
        let frame = Frame::look_at(eye, target, up)?;
        Ok(PinholeCamera {
            intrinsics,
            frame,
            distortion: LensDistortion::NONE,
        })
    }

    /// The same camera seen through a lens with `distortion`: each pixel's ray goes where the
    /// lens sent it (the pixel's normalised coordinates undistorted, then rotated).
    ///
    /// Errors: a coefficient that is not finite.
    pub fn with_distortion(self, distortion: LensDistortion) -> Result<Self, OpsError> {
        distortion.check()?;
        Ok(PinholeCamera { distortion, ..self })
    }

    /// The lens distortion ([`LensDistortion::NONE`] unless set).
    pub fn distortion(&self) -> &LensDistortion {
        &self.distortion
    }

    /// Where the world point `point` appears in the image, as image coordinates `[x, y]`
    /// (column and row positions: pixel (row `a`, column `b`) spans `[b, b + 1] x [a, a + 1]`
    /// and its centre is `(b + 0.5, a + 0.5)`), through the lens; `None` for a point on or
    /// behind the camera's plane. The point may fall outside the image.
    pub fn project(&self, point: [f64; 3]) -> Option<[f64; 2]> {
        let [x, y, z] = self.frame.to_camera(point)?;
        // NaN (a non-finite point) is refused with the points behind.
        if z.is_nan() || z <= 0.0 {
            return None;
        }
        let [xd, yd] = self.distortion.distort([x / z, y / z]);
        let k = &self.intrinsics;
        Some([k.fx * xd + k.cx, k.fy * yd + k.cy])
    }

    /// The intrinsics.
    pub fn intrinsics(&self) -> &Intrinsics {
        &self.intrinsics
    }

    /// The camera-to-world transform (OpenCV axes), as given or as built by `look_at`.
    pub fn camera_to_world(&self) -> [[f64; 4]; 4] {
        self.frame.matrix()
    }

    /// The camera centre (every ray's origin).
    pub fn centre(&self) -> [f64; 3] {
        self.frame.centre
    }

    /// The unit world direction through the centre of pixel (`row`, `col`) (which may lie
    /// outside the image: no check), through the lens. Where the lens model cannot be inverted
    /// (far outside a calibrated lens's field) the pinhole direction is used.
    pub fn direction(&self, row: usize, col: usize) -> [f64; 3] {
        self.direction_at(row as f64 + 0.5, col as f64 + 0.5)
    }

    /// The unit world direction through the image point (`y`, `x`) in pixels (the top-left
    /// corner of the image is (0, 0), pixel (`row`, `col`)'s centre is (`row + 0.5`,
    /// `col + 0.5`)), through the lens, as [`PinholeCamera::direction`].
    pub fn direction_at(&self, y: f64, x: f64) -> [f64; 3] {
        let k = &self.intrinsics;
        let distorted = [(x - k.cx) / k.fx, (y - k.cy) / k.fy];
        let [x, y] = self.distortion.undistort(distorted).unwrap_or(distorted);
        let cam = [x, y, 1.0];
        // An invertible R maps a non-zero vector to a non-zero one.
        normalise(self.frame.rotate(cam)).unwrap_or([0.0, 0.0, 1.0])
    }

    fn push_pixel<F: Float>(&self, pixel: usize, origins: &mut Vec<F>, directions: &mut Vec<F>) {
        let w = self.intrinsics.width;
        origins.extend(self.frame.centre.map(F::lit));
        directions.extend(self.direction(pixel / w, pixel % w).map(F::lit));
    }

    /// One ray per pixel in row-major order (pixel `a * width + b` is ray `a * width + b`).
    pub fn rays<F: Float>(&self) -> RayBatch<F> {
        let all: Vec<usize> = (0..self.intrinsics.pixels()).collect();
        let (mut o, mut d) = (Vec::with_capacity(3 * all.len()), Vec::with_capacity(3 * all.len()));
        all.iter().for_each(|&p| self.push_pixel(p, &mut o, &mut d));
        RayBatch::from_checked(o, d)
    }

    /// The rays through the chosen pixel indices (`row * width + col`), in the order given
    /// (repeats allowed). Errors: an index `>= width * height`.
    pub fn rays_for_pixels<F: Float>(&self, pixels: &[usize]) -> Result<RayBatch<F>, OpsError> {
        rays_for_camera_pixels(
            std::slice::from_ref(self),
            &pixels
                .iter()
                .map(|&pixel| CameraPixel { camera: 0, pixel })
                .collect::<Vec<_>>(),
        )
    }
}

/// One pixel of one camera of a slice of cameras.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CameraPixel {
    /// Index into the slice of cameras.
    pub camera: usize,
    /// Pixel index `row * width + col` in that camera's image.
    pub pixel: usize,
}

/// The rays through (camera, pixel) pairs of several cameras, in the order given: a training
/// batch drawn across views.
///
/// Errors: a camera index `>= cameras.len()` or a pixel index outside its camera's image
/// (nothing is built then).
pub fn rays_for_camera_pixels<F: Float>(
    cameras: &[PinholeCamera],
    pairs: &[CameraPixel],
) -> Result<RayBatch<F>, OpsError> {
    for p in pairs {
        let cam = cameras.get(p.camera).ok_or(OpsError::OutOfRange {
            op: Op::Rays,
            what: "camera",
            index: p.camera,
            len: cameras.len(),
        })?;
        let len = cam.intrinsics.pixels();
        if p.pixel >= len {
            return Err(OpsError::OutOfRange {
                op: Op::Rays,
                what: "pixel",
                index: p.pixel,
                len,
            });
        }
    }
    let (mut o, mut d) = (Vec::with_capacity(3 * pairs.len()), Vec::with_capacity(3 * pairs.len()));
    for p in pairs {
        cameras[p.camera].push_pixel(p.pixel, &mut o, &mut d);
    }
    Ok(RayBatch::from_checked(o, d))
}
