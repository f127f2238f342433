//! 3-D Gaussian splats as fogray's second model class: [`SplatModel`] (the parameters in a
//! tape store, initialised from a point cloud or at random in a box, scales from the 3
//! nearest neighbours), [`SplatTrainer`] (one training view a step, L1 loss, 3DGS's
//! per-parameter Adam rates), and the densification policies ([`Densify`], [`OpacityReset`]).
//!
//! ```
//! use fogray_fit::splats::SplatModel;
//! use fogray_ops::{Intrinsics, PinholeCamera};
//!
//! let model = SplatModel::<f32>::random([[-0.5; 3], [0.5; 3]], 50, 1, 7, 1000)?;
//! let k = Intrinsics::from_vertical_fov(16, 16, 0.7)?;
//! let camera = PinholeCamera::look_at(k, [3.0, 0.0, 0.0], [0.0; 3], [0.0, 0.0, 1.0])?;
//! let image = model.render(&camera, [1.0; 3])?;
//! assert_eq!(image.dim(), (256, 3));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub(crate) mod carve;
pub(crate) mod densify;
pub(crate) mod knn;
pub(crate) mod model;
pub(crate) mod ply;
pub(crate) mod policies;
pub(crate) mod resize;
pub(crate) mod session;
pub(crate) mod settings;
#[cfg(test)]
mod tests;
pub(crate) mod trainer;
pub(crate) mod undistort;

pub use densify::Densify;
pub use model::{SplatArraysOwned, SplatIds, SplatModel};
pub use policies::{OpacityReset, SplatRates};
pub use settings::SplatSettings;
pub use trainer::SplatTrainer;
