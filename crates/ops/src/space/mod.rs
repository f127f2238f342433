//! Unbounded scenes: the scene contraction that maps all of space into the cube
//! `[-2, 2]^3` (so that one grid of cells covers a foreground and a background reaching to
//! infinity), and the framing of its inner region from a capture's cameras.
//!
//! `docs/contraction.md` in the repository says why the L-infinity form, and how the
//! samplers' steps and the occupancy thresholds stay in world units.
//!
//! ```
//! use fogray_ops::space::{framing_from_cameras, Contraction};
//!
//! // Four cameras on a circle of radius 3 around (1, 0, 0), looking at it.
//! let centres = [[4.0, 0.0, 0.0], [1.0, 3.0, 0.0], [-2.0, 0.0, 0.0], [1.0, -3.0, 0.0]];
//! let forward = [[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
//! let region = framing_from_cameras(&centres, &forward)?;
//! assert!((region.centre[0] - 1.0).abs() < 1e-12);
//! let space = Contraction::new(region)?;
//! // Inside the inner region the map is the identity on (x - c) / r ...
//! assert_eq!(space.contract([1.0f64, 0.0, 0.0]), [0.0; 3]);
//! // ... and infinity lies on the cube's faces.
//! let far = space.contract([1e300f64, 0.0, 0.0]);
//! assert_eq!(far, [2.0, 0.0, 0.0]);
//! # Ok::<(), fogray_ops::OpsError>(())
//! ```

mod contraction;
#[cfg(test)]
mod contraction_tests;
mod framing;
#[cfg(test)]
mod framing_tests;

pub use contraction::{Contraction, InnerRegion, CONTRACTED_HALF_WIDTH};
pub use framing::{
    axes_meeting_point, framing_from_cameras, MIN_AXES_RECIPROCAL_CONDITION, RADIUS_PER_MEDIAN_CAMERA_DISTANCE,
};
