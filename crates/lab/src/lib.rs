//! # fogray-lab
//!
//! The measuring tools of the fogray workspace: what its reports and experiments use to
//! measure the pipeline, kept apart from the pipeline itself so that a user who fits, renders
//! or exports a scene compiles none of it. Nothing here is part of a user's pipeline, and the
//! crate is not published.
//!
//! - [`sweep`]: one fit per configuration (fused or taped, uniform or occupancy, f32 or f64)
//!   for the same budget, and fused against taped over the same steps;
//! - [`curves`]: fit logs read as curves and compared (the PSNR at a time, the time to a PSNR,
//!   one run against another or against an outside pipeline's log);
//! - [`slices`]: a model's density and its occupancy grid on planes through its box, as PNGs.

#![warn(missing_docs)]

pub mod curves;
pub mod slices;
pub mod sweep;
