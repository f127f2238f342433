//! The speed-against-error report: one fit per configuration (fused or taped ops, uniform or
//! occupancy sampling, f32 or f64), run one after another for the same training budget
//! (fogray-lab's [`sweep`](fogray_lab::sweep)), compared on test PSNR against training time
//! ([`curves`](fogray_lab::curves)), with pictures of the best configuration's model beside
//! the scene's exact density.
//!
//! - [`markdown`]: the report's tables, as numbers and as markdown;
//! - [`mod@write`]: the report's files.
//!
//! ```
//! use fogray::fit::settings::Budget;
//! use fogray_grid::report::markdown::checkpoints;
//!
//! // The table's PSNR columns of a 60 s report: a quarter, half and all of the budget.
//! assert_eq!(checkpoints(Budget::Seconds(60.0), &[]), vec![15.0, 30.0, 60.0]);
//! ```

use std::path::PathBuf;

use thiserror::Error;

use fogray::fit::images::ImageError;
use fogray::fit::FitError;
use fogray_lab::curves::CurveError;
use fogray_lab::sweep::SweepError;

pub mod markdown;
pub mod write;

/// Why a report could not be made.
#[non_exhaustive]
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ReportError {
    /// A log that cannot be read as a curve, or an anchor that cannot be read.
    #[error(transparent)]
    Curve(#[from] CurveError),
    /// A bad configuration or report setting, or a fit's error, from the sweep.
    #[error(transparent)]
    Sweep(#[from] SweepError),
    /// A report with no runs.
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
