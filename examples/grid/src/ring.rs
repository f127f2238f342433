//! The cameras: `V + T` pinhole views spread evenly over the sphere of radius 3 (a Fibonacci
//! lattice), each looking at the origin, some held out for testing.
//!
//! View `i` of `n = V + T` has its eye at `3 (r cos phi, r sin phi, z)` with
//! `z = 1 - 2 (i + 0.5) / n`, `r = sqrt(1 - z^2)` and `phi = pi (1 + sqrt 5) (i + 0.5)`.
//! Forward is towards the origin; up is `+z`, or `+y` where `|forward . z| >= 0.99`;
//! `right = normalise(forward x up)` and `up' = right x forward`. Images are `W x W` with a
//! vertical field of view of 40 degrees: pixel (row `a`, column `b`) looks along
//! `normalise(forward + u right + v up')`, `f = tan 20 deg`, `u = ((b + 0.5) / W * 2 - 1) f`,
//! `v = -((a + 0.5) / W * 2 - 1) f` (the library's [`PinholeCamera::look_at`] with the
//! principal point at the image centre: the same rays, up to rounding). With `e = n / T` (integer division), view `i` is a test
//! view when `i mod e == e / 2`. Scripts outside this crate rebuild these cameras from the same
//! formulas, so they are kept exactly.
//!
//! ```
//! use fogray_grid::ring::Ring;
//!
//! let ring = Ring::new(32, 4, 64)?;
//! assert_eq!(ring.test_views(), vec![4, 13, 22, 31]);
//! let camera = ring.camera(0)?;
//! let eye_distance = camera.centre().iter().map(|x| x * x).sum::<f64>().sqrt();
//! assert!((eye_distance - 3.0).abs() < 1e-12);
//! assert_eq!(ring.rays(0)?.len(), 64 * 64);
//! # Ok::<(), fogray_grid::ring::RingError>(())
//! ```

use fogray::ops::{Intrinsics, OpsError, PinholeCamera};
use thiserror::Error;

use crate::exact::Ray;

/// Distance of every eye from the origin.
pub const EYE_DISTANCE: f64 = 3.0;
/// Vertical (and, the images being square, horizontal) field of view, in degrees.
pub const FIELD_OF_VIEW_DEGREES: f64 = 40.0;

/// Why a ring of cameras was rejected.
#[non_exhaustive]
#[derive(Debug, Clone, PartialEq, Error)]
pub enum RingError {
    /// A count that must be at least 1.
    #[error("{what} must be at least 1, got 0")]
    Zero {
        /// `views` or `size`.
        what: &'static str,
    },
    /// The library camera refused a view (not expected for the ring's eyes).
    #[error(transparent)]
    Camera(#[from] OpsError),
}

/// `V` training and `T` test views of `W x W` pixels (see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ring {
    views: usize,
    test_views: usize,
    size: usize,
}

/// The up vector of a camera looking along `forward`: `+z`, or `+y` where the view is steep.
fn world_up(forward_z: f64) -> [f64; 3] {
    if forward_z.abs() >= 0.99 {
        [0.0, 1.0, 0.0]
    } else {
        [0.0, 0.0, 1.0]
    }
}

impl Ring {
    /// `views` training and `test_views` held-out views of `size x size` pixels.
    ///
    /// Errors: [`RingError::Zero`] if `views` or `size` is 0. `test_views = 0` holds nothing
    /// out. The rule of the [module docs](self) picks the test views; it gives exactly
    /// `test_views` of them when `(views + test_views) / test_views` divides the total with
    /// little remainder (as for 32 and 4), and can give more otherwise: [`Ring::test_views`]
    /// is what counts.
    pub fn new(views: usize, test_views: usize, size: usize) -> Result<Ring, RingError> {
        if views == 0 {
            return Err(RingError::Zero { what: "views" });
        }
        if size == 0 {
            return Err(RingError::Zero { what: "size" });
        }
        Ok(Ring {
            views,
            test_views,
            size,
        })
    }

    /// All views, `V + T`.
    pub fn len(&self) -> usize {
        self.views + self.test_views
    }

    /// Always false: a ring has at least one view.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// Image width and height in pixels.
    pub fn size(&self) -> usize {
        self.size
    }

    /// Whether view `i` is held out for testing.
    pub fn is_test(&self, i: usize) -> bool {
        if self.test_views == 0 {
            return false;
        }
        let e = self.len() / self.test_views;
        i % e == e / 2
    }

    /// The held-out views, ascending.
    pub fn test_views(&self) -> Vec<usize> {
        (0..self.len()).filter(|&i| self.is_test(i)).collect()
    }

    /// The training views, ascending.
    pub fn train_views(&self) -> Vec<usize> {
        (0..self.len()).filter(|&i| !self.is_test(i)).collect()
    }

    /// The eye of view `i` (any `i`; views past `len()` continue the lattice formula).
    pub fn eye(&self, i: usize) -> [f64; 3] {
        let n = self.len() as f64;
        let k = i as f64 + 0.5;
        let z = 1.0 - 2.0 * k / n;
        let r = (1.0 - z * z).sqrt();
        let phi = std::f64::consts::PI * (1.0 + 5f64.sqrt()) * k;
        [r * phi.cos(), r * phi.sin(), z].map(|x| EYE_DISTANCE * x)
    }

    /// The camera of view `i`: at [`Ring::eye`], looking at the origin, `size x size` pixels
    /// with a vertical field of view of [`FIELD_OF_VIEW_DEGREES`].
    ///
    /// Errors: [`RingError::Camera`] (not expected: every eye is off the origin).
    pub fn camera(&self, i: usize) -> Result<PinholeCamera, RingError> {
        let eye = self.eye(i);
        let k = Intrinsics::from_vertical_fov(self.size, self.size, FIELD_OF_VIEW_DEGREES.to_radians())?;
        let forward_z = -eye[2] / eye.iter().map(|x| x * x).sum::<f64>().sqrt();
        Ok(PinholeCamera::look_at(k, eye, [0.0; 3], world_up(forward_z))?)
    }

    /// The rays of view `i`, one per pixel in row-major order (`row * size + column`).
    ///
    /// Errors: as [`Ring::camera`].
    pub fn rays(&self, i: usize) -> Result<Vec<Ray>, RingError> {
        let camera = self.camera(i)?;
        Ok((0..self.size * self.size)
            .map(|p| Ray {
                origin: camera.centre(),
                direction: camera.direction(p / self.size, p % self.size),
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
        (0..3).map(|k| a[k] * b[k]).sum()
    }

    #[test]
    fn test_views_for_32_and_4_are_4_13_22_31() {
        // e = 36 / 4 = 9, e / 2 = 4.
        let ring = Ring::new(32, 4, 8).unwrap();
        assert_eq!(ring.test_views(), vec![4, 13, 22, 31]);
        assert_eq!(ring.train_views().len(), 32);
        assert!(Ring::new(5, 0, 8).unwrap().test_views().is_empty());
        // e = 8 / 3 = 2, e / 2 = 1: every odd view, four of them for three asked.
        assert_eq!(Ring::new(5, 3, 8).unwrap().test_views(), vec![1, 3, 5, 7]);
        assert_eq!(Ring::new(0, 4, 8), Err(RingError::Zero { what: "views" }));
        assert_eq!(Ring::new(4, 4, 0), Err(RingError::Zero { what: "size" }));
    }

    #[test]
    fn a_single_view_sits_on_the_equator_at_half_the_golden_turn() {
        // n = 1: z = 1 - 2 * 0.5 = 0, r = 1, phi = pi (1 + sqrt 5) / 2 = 5.0832036923152595 rad,
        // whose cosine and sine (evaluated apart from this crate) are 0.3623748900804798 and
        // -0.9320324238132277.
        let eye = Ring::new(1, 0, 4).unwrap().eye(0);
        let want = [3.0 * 0.3623748900804798, 3.0 * -0.9320324238132277, 0.0];
        for k in 0..3 {
            assert!((eye[k] - want[k]).abs() < 1e-14, "{eye:?}");
        }
    }

    /// A camera's eye and unit frame (forward, right, image up) read off its camera-to-world
    /// matrix (OpenCV columns: right, down, forward).
    struct Frame {
        eye: [f64; 3],
        forward: [f64; 3],
        right: [f64; 3],
        up: [f64; 3],
    }

    fn frame(ring: &Ring, i: usize) -> Frame {
        let m = ring.camera(i).unwrap().camera_to_world();
        let column = |c: usize| [m[0][c], m[1][c], m[2][c]];
        Frame {
            eye: column(3),
            forward: column(2),
            right: column(0),
            up: column(1).map(|x| -x),
        }
    }

    #[test]
    fn eyes_lie_on_the_radius_3_sphere_and_frames_are_orthonormal() {
        // 200 views: view 0 has z = 1 - 1/200 = 0.995, steep enough for the +y up vector.
        let ring = Ring::new(190, 10, 5).unwrap();
        assert!(frame(&ring, 0).forward[2].abs() >= 0.99 && frame(&ring, 1).forward[2].abs() < 0.99);
        for i in 0..ring.len() {
            let c = frame(&ring, i);
            assert!((dot(c.eye, c.eye).sqrt() - 3.0).abs() < 1e-12);
            for (a, b) in [(c.forward, c.right), (c.forward, c.up), (c.right, c.up)] {
                assert!(dot(a, b).abs() < 1e-12);
            }
            for v in [c.forward, c.right, c.up] {
                assert!((dot(v, v) - 1.0).abs() < 1e-12);
            }
            // Forward points at the origin; the image's up has no downward z (+z up) or,
            // for the steep views, no -y.
            assert!((dot(c.forward, c.eye) + 3.0).abs() < 1e-12);
            let world_up = if c.forward[2].abs() >= 0.99 { 1 } else { 2 };
            assert!(c.up[world_up] > 0.0);
        }
    }

    #[test]
    fn pixel_rays_are_unit_and_the_centre_pixel_of_an_odd_image_hits_the_origin() {
        let ring = Ring::new(6, 2, 5).unwrap();
        for i in 0..ring.len() {
            let rays = ring.rays(i).unwrap();
            for r in &rays {
                assert!((dot(r.direction, r.direction) - 1.0).abs() < 1e-14);
            }
            // Row 2, column 2 of 5: u = v = 0, so the ray goes through the origin at depth 3.
            let centre = rays[2 * 5 + 2];
            let at3 = [0, 1, 2].map(|k| centre.origin[k] + 3.0 * centre.direction[k]);
            assert!(dot(at3, at3).sqrt() < 1e-12, "{at3:?}");
            // The top-left pixel centre is up and to the left: its angle from forward is
            // atan(sqrt(u^2 + v^2)) with u = -v = -(4/5) tan 20 deg.
            let c = frame(&ring, i);
            let corner = rays[0];
            let t = 0.8 * 20f64.to_radians().tan();
            assert!((dot(corner.direction, c.forward) - (2.0 * t * t).sqrt().atan().cos()).abs() < 1e-12);
            assert!(dot(corner.direction, c.right) < 0.0 && dot(corner.direction, c.up) > 0.0);
        }
    }
}
