//! A fit's log read as a curve of test PSNR against training time, and two runs (or a run and
//! an outside pipeline's log) compared on it: the PSNR at a time, the first time (and step, and
//! samples drawn) at which a PSNR is reached, and the speed-ups these give.
//!
//! Between two evaluations the test PSNR is taken as linear in training time, and the steps
//! and samples as linear in it too, so that "the PSNR at 30 s" and "the time to reach 25 dB"
//! are read between the evaluations around them rather than rounded to one of them.
//!
//! - [`reach`](mod@reach): [`psnr_at`], [`reach()`] and [`final_psnr`] on one log;
//! - [`compare`]: fused against taped, occupancy against uniform sampling, a run against an
//!   anchor, each at a PSNR both reach;
//! - [`anchor`]: an outside pipeline's log ([`Anchor`]), read from JSON.
//!
//! ```
//! use fogray_lab::curves::{psnr_at, reach};
//! use fogray_fit::train::LogEntry;
//!
//! let e = |step, seconds, test_psnr| LogEntry { step, seconds, train_loss: 0.0, test_psnr, test_ssim: f64::NAN, samples: 100 * step };
//! let log = [e(0, 0.0, 10.0), e(10, 2.0, 20.0), e(20, 4.0, 24.0)];
//! assert_eq!(psnr_at(&log, 1.0)?, Some(15.0)); // halfway from 10 dB to 20 dB
//! assert_eq!(reach(&log, 22.0)?.unwrap().seconds, 3.0);
//! assert_eq!(psnr_at(&log, 5.0)?, None); // the run stopped at 4 s
//! # Ok::<(), fogray_lab::curves::CurveError>(())
//! ```

use thiserror::Error;

pub mod anchor;
pub mod compare;
pub mod reach;

pub use anchor::{Anchor, AnchorPoint};
pub use compare::{
    against_anchor, fused_vs_taped, occupancy_vs_uniform, AgainstAnchor, FusedVsTaped, OccupancyVsUniform,
};
pub use reach::{final_psnr, psnr_at, reach, Reach};

/// Why a log could not be read as a curve.
#[non_exhaustive]
#[derive(Debug, Clone, PartialEq, Error)]
pub enum CurveError {
    /// A log that cannot be read as a curve (empty, out of time order, a NaN PSNR), or a
    /// comparison's argument out of its range (a batch of 0 rays).
    #[error("bad log: {0}")]
    Log(String),
    /// An anchor file that cannot be read or is not an anchor (named in the text).
    #[error("{0}")]
    Anchor(String),
}

#[cfg(test)]
mod tests;
