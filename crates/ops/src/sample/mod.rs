//! Samplers: where along each ray the scene is looked up, as [`PackedSamples`] that feed the
//! composite (`offsets`, `delta`, `t`) and a field (`positions`) with no reshaping.
//!
//! Every sampler cuts each ray's segment into pieces and puts one sample at each piece's
//! midpoint with `delta` its length: [`Uniform`] (a fixed step or count), [`Stratified`]
//! (the same pieces with seeded random edges), [`Importance`] (pieces of equal probability
//! under a previous pass's weights) and the [`OccupancyGrid`]'s two samplers of the occupied
//! parts only: [`OccupancyGrid::march`] (the uniform pieces of the occupied runs, cut at their
//! faces) and [`OccupancyGrid::march_midpoints`] (the uniform pieces whose midpoint is
//! occupied, tested in vector lanes). For unbounded scenes, [`ContractedSampler`] cuts rays
//! into pieces of equal length in contracted space (positions contracted, depths and
//! lengths in the world), with [`ContractedOccupancy`] to judge a contracted grid's cells.
//!
//! ```
//! use fogray_ops::rays::{Aabb, Intrinsics, PinholeCamera};
//! use fogray_ops::sample::{OccupancyGrid, OccupancyConfig, CellPoints, Spacing, Uniform};
//! use fogray_ops::Composite;
//! use ndarray::{Array1, ArrayView2};
//!
//! let k = Intrinsics::from_vertical_fov(16, 16, 40f64.to_radians())?;
//! let cam = PinholeCamera::look_at(k, [0.0, -3.0, 0.0], [0.0; 3], [0.0, 0.0, 1.0])?;
//! let rays = cam.rays::<f32>();
//! let bounds = Aabb::new([-1.0; 3], [1.0; 3])?;
//! let clip = bounds.clip(&rays);
//!
//! // Uniform samples every 1/32 across the box.
//! let step = 1.0 / 32.0;
//! let uniform = Uniform::new(Spacing::Step(step))?.sample(&rays, &clip)?;
//! let op = Composite::new(&uniform.offsets)?; // packs exactly as the composite expects
//! assert_eq!(op.rays(), rays.len());
//!
//! // A ball of radius 0.5 is the only matter: the occupancy grid learns that from the
//! // density and the marcher samples only near it.
//! let ball = |p: ArrayView2<'_, f32>| {
//!     Ok::<_, std::convert::Infallible>(Array1::from_iter(p.rows().into_iter().map(|q| {
//!         if q.dot(&q) < 0.25 { 10.0f32 } else { 0.0 }
//!     })))
//! };
//! let mut grid = OccupancyGrid::new(bounds, 32, OccupancyConfig::opacity(step, 0.01)?)?;
//! grid.update(ball, CellPoints::Centre)?;
//! let marched = grid.march(&rays, &clip, step, fogray_ops::sample::Jitter::None)?;
//! assert!(marched.len() * 3 < uniform.len());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod contracted;
mod contracted_occupancy;
#[cfg(test)]
mod contracted_occupancy_tests;
#[cfg(test)]
mod contracted_tests;
mod importance;
#[cfg(test)]
mod importance_tests;
mod march;
#[cfg(test)]
mod march_tests;
#[cfg(test)]
mod march_walk_tests;
mod midpoints;
#[cfg(test)]
mod midpoints_tests;
mod occupancy;
mod occupancy_config;
#[cfg(test)]
mod occupancy_tests;
mod packed;
mod stratified;
mod uniform;
mod visible;
#[cfg(test)]
mod visible_tests;

pub use contracted::{ContractedSampler, DEFAULT_FAR_GAP, MAX_CONTRACTED_PATH, MAX_SAMPLES_PER_RAY, MIN_STEP};
pub use contracted_occupancy::ContractedOccupancy;
pub use importance::Importance;
pub use occupancy::{GridAxis, KnownCells, OccupancyGrid, OccupancySlice, OccupancyState};
pub use occupancy_config::{CellPoints, OccupancyConfig, Refresh, Threshold};
pub use packed::{PackedSamples, SampleVars};
pub use stratified::{Jitter, Stratified};
pub use uniform::{Spacing, Uniform};
