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
//! - [`slices`]: a model's density and its occupancy grid on planes through its box, as PNGs;
//! - [`machine`]: the memory bandwidth of the machine at the time of a measurement (a short
//!   STREAM triad);
//! - [`stamp`]: the provenance (date, machine, command) at the top of every generated report,
//!   re-exported from fogray-fit, whose own fit report (`fogray fit --out`) writes it too;
//! - the benches of `fogray-lab bench` (this crate's binary, `docs/performance.md`): [`bench`]
//!   (the composite against its taped twins), [`grid_bench`] (the grid field), [`tape_cost`]
//!   (the tape's own cost per op and per byte), each error against an independent f64
//!   [`reference`]; [`bandwidth`] (the fraction of the machine's memory bound a fused row
//!   reaches), [`heap`] (glibc told to keep freed memory), [`markdown`] (the generated report
//!   and the README's headline blocks), [`error`].
//!
//! The criterion benches (`benches/`) time the very steps of [`bench`] on the same rays.

#![warn(missing_docs)]

pub mod bandwidth;
pub mod bench;
pub mod curves;
pub mod error;
pub mod grid_bench;
pub mod heap;
pub mod machine;
pub mod markdown;
pub mod reference;
pub mod slices;
pub mod sweep;
pub mod tape_cost;

pub use fogray_fit::stamp;
