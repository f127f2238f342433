//! Rays: pinhole cameras and orbits of them, batches of rays, and where rays cross an axis-aligned box.
//!
//! Camera frame convention (OpenCV): x right, y down, z forward; pixel (row `a`, column `b`)
//! is centred at `(b + 0.5, a + 0.5)` and indexed `a * width + b`. All geometry is computed
//! in f64 and rounded to the batch's float type at the end.
//!
//! ```
//! use fogray_ops::rays::{rays_for_camera_pixels, Aabb, CameraPixel, Intrinsics, PinholeCamera};
//!
//! // Two views of the box [-0.5, 0.5]^3 from distance 3, 64x64 pixels, 40 degrees vertically.
//! let k = Intrinsics::from_vertical_fov(64, 64, 40f64.to_radians())?;
//! let cams = [
//!     PinholeCamera::look_at(k, [0.0, -3.0, 0.0], [0.0; 3], [0.0, 0.0, 1.0])?,
//!     PinholeCamera::look_at(k, [0.0, 0.0, 3.0], [0.0; 3], [0.0, 1.0, 0.0])?,
//! ];
//! // A batch mixing pixels of both views: the centre pixel of each, and a corner of the first.
//! let centre = 32 * 64 + 32;
//! let pairs = [
//!     CameraPixel { camera: 0, pixel: centre },
//!     CameraPixel { camera: 1, pixel: centre },
//!     CameraPixel { camera: 0, pixel: 0 },
//! ];
//! let rays = rays_for_camera_pixels::<f32>(&cams, &pairs)?;
//! let clip = Aabb::new([-0.5; 3], [0.5; 3])?.clip(&rays);
//! // Near-central rays cross the box from about t = 2.5 to t = 3.5; the corner ray, 20
//! // degrees off in both directions, passes beside it.
//! let (near, far) = clip.segment(0).unwrap();
//! assert!((near - 2.5).abs() < 1e-3 && (far - 3.5).abs() < 1e-3);
//! assert!(clip.segment(1).is_some());
//! assert_eq!(clip.segment(2), None);
//! # Ok::<(), fogray_ops::OpsError>(())
//! ```

mod aabb;
pub(crate) mod batch;
pub mod camera;
#[cfg(test)]
mod camera_tests;
mod distortion;
mod frame;
pub mod orbit;

pub use aabb::{Aabb, RayIntervals};
pub use batch::RayBatch;
pub use camera::{rays_for_camera_pixels, CameraPixel, Intrinsics, PinholeCamera};
pub use distortion::LensDistortion;
pub use orbit::Orbit;
