//! 3-D Gaussian splats as fogray's second model class: [`SplatModel`](model::SplatModel) (the parameters in a
//! tape store, initialised from a point cloud or at random in a box, scales from the 3
//! nearest neighbours), [`SplatTrainer`](trainer::SplatTrainer) (one training view a step, L1 loss, 3DGS's
//! per-parameter Adam rates), and the densification policies ([`Densify`](densify::Densify), [`OpacityReset`](policies::OpacityReset)).

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
