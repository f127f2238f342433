//! The speed-against-error report: one fit per configuration (fused or taped ops, uniform or
//! occupancy sampling, f32 or f64), run one after another for the same training budget, compared
//! on test PSNR against training time, with pictures of the best configuration's model.
//!
//! - [`reach`]: a log read as a curve (PSNR at a time, time to a PSNR);
//! - [`anchor`]: an outside pipeline's log, set beside the configurations;
//! - [`compare`]: fused against taped, occupancy against uniform, each against the anchor;
//! - [`same_steps`]: fused against taped over the same steps (the time to the same PSNR);
//! - [`configuration`]: the configurations and their names;
//! - [`run`]: running the fits; [`markdown`] and [`mod@write`]: the report's files.
//!
//! ```
//! use fogray::fit::train::LogEntry;
//! use fogray_grid::report::reach::{psnr_at, reach};
//!
//! let e = |step, seconds, test_psnr| LogEntry { step, seconds, train_loss: 0.0, test_psnr, test_ssim: f64::NAN, samples: 100 * step };
//! let log = [e(0, 0.0, 10.0), e(10, 2.0, 20.0), e(20, 4.0, 24.0)];
//! assert_eq!(psnr_at(&log, 1.0)?, Some(15.0)); // halfway from 10 dB to 20 dB
//! assert_eq!(reach(&log, 22.0)?.unwrap().seconds, 3.0);
//! assert_eq!(psnr_at(&log, 5.0)?, None); // the run stopped at 4 s
//! # Ok::<(), fogray_grid::report::ReportError>(())
//! ```

use std::path::PathBuf;

use thiserror::Error;

use fogray::fit::images::ImageError;
use fogray::fit::FitError;

pub mod anchor;
pub mod compare;
pub mod configuration;
pub mod markdown;
pub mod reach;
pub mod run;
pub mod same_steps;
pub mod write;

/// Why a report could not be made.
#[non_exhaustive]
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ReportError {
    /// A log that cannot be read as a curve (empty, out of time order, a NaN PSNR).
    #[error("bad log: {0}")]
    Log(String),
    /// A bad configuration name or report setting.
    #[error("{0}")]
    Config(String),
    /// From a fit.
    #[error(transparent)]
    Fit(#[from] FitError),
    /// From a picture.
    #[error(transparent)]
    Image(#[from] ImageError),
    /// A file that could not be written.
    #[error("cannot write {path}: {message}")]
    Write {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
}

#[cfg(test)]
mod tests;
