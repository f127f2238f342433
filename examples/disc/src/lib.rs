//! # fogray-disc
//!
//! The disc experiment of the lesson *Making visibility soft: volume rendering* (its first and
//! sixth sections; `docs/disc.md` restates the setup): a disc photographed by six cameras, a model
//! disc offset by `x`, and the loss of a hard renderer (a staircase) against that of a soft
//! one (a smooth landscape whose slope comes from the tape's `backward` through the fused
//! composite). A template for a differentiable renderer of your own: build the density on the
//! tape from your parameters, composite with [`fogray::ops::Composite`], put the loss on the
//! tape, and read the gradient.

pub mod adam;
pub mod anneal;
pub mod error;
pub mod experiments;
pub mod hard;
pub mod plots;
pub mod report;
pub mod reproduce;
pub mod sampling;
pub mod scene;
pub mod setup;
pub mod soft;
