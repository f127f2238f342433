//! A sweep over the pipeline's configurations: one fit of one dataset per configuration (fused
//! or taped ops, uniform or occupancy sampling, f32 or f64), run one after another for the
//! same budget so that they can be compared on test PSNR against training time, and pictures
//! of each final model.
//!
//! - [`config`]: the configurations and their names (`fused-uniform`, `taped-occupancy-f64`);
//! - [`run`]: running the fits ([`run_configs`]) and keeping what a report shows of each
//!   ([`ConfigRun`]);
//! - [`same_steps`](mod@same_steps): fused against taped over the same steps, the time each
//!   method takes to the same PSNR;
//! - [`pairs`]: the runs that differ in one setting compared on their curves (fused against
//!   taped, occupancy against uniform, each run against an anchor).
//!
//! The runs are timed, so they never run side by side: run a sweep on a quiet machine. The
//! curves of its runs are compared with [`crate::curves`].
//!
//! ```
//! use fogray_fit::dataset::{Dataset, View};
//! use fogray_fit::settings::FitSettings;
//! use fogray_lab::sweep::{run_configs, RunConfig, SweepOptions};
//! use fogray_ops::{Intrinsics, PinholeCamera};
//! use ndarray::Array3;
//!
//! // Four views of a mid-grey fog, one held out.
//! let k = Intrinsics::from_vertical_fov(8, 8, 40f64.to_radians())?;
//! let eyes = [[3.0, 0.0, 0.0], [0.0, 3.0, 0.0], [-3.0, 0.0, 0.0], [0.0, -3.0, 0.0]];
//! let mut views = Vec::new();
//! for (i, eye) in eyes.into_iter().enumerate() {
//!     let camera = PinholeCamera::look_at(k, eye, [0.0; 3], [0.0, 0.0, 1.0])?;
//!     views.push(View::new(format!("{i}"), &camera, Array3::from_elem((8, 8, 3), 0.5))?);
//! }
//! let test = vec![views.pop().unwrap()];
//! let data = Dataset::new(views, test, [1.0; 3])?;
//! let options = SweepOptions {
//!     fit: FitSettings { grid: 8, batch: 256, steps: Some(5), evaluations: 1, ..FitSettings::default() },
//!     configs: vec!["fused-uniform".parse()?, "taped-uniform".parse()?],
//!     slice_pixels: 4,
//! };
//! let runs = run_configs(&data, &options, &mut |_, _| {})?;
//! assert_eq!(runs.iter().map(|r| r.name.as_str()).collect::<Vec<_>>(), ["fused-uniform", "taped-uniform"]);
//! assert!(runs.iter().all(|r| r.steps == 5));
//! // The two methods do the same arithmetic: the same PSNR up to rounding.
//! assert!((runs[0].final_test_psnr - runs[1].final_test_psnr).abs() < 1e-3);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use thiserror::Error;

use fogray_fit::FitError;

pub mod config;
pub mod pairs;
pub mod run;
pub mod same_steps;

pub use config::{shared_name, RunConfig, DEFAULT_CONFIGS};
pub use run::{best, run_configs, ConfigRun, FinalPictures, SweepOptions};
pub use same_steps::{same_steps, SameSteps, StepsRun};

/// Why a sweep could not run.
#[non_exhaustive]
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SweepError {
    /// A bad configuration name or sweep setting (named in the text).
    #[error("{0}")]
    Config(String),
    /// From a fit.
    #[error(transparent)]
    Fit(#[from] FitError),
}

#[cfg(test)]
mod tests;
