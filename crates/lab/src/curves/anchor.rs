//! A pipeline run outside fogray (a PyTorch fit of the same scene, say), read from its log so
//! that a report can set it beside fogray's runs: its curve on the plots, and how much sooner
//! each run reaches the test PSNR the anchor ends at ([`against_anchor`](super::against_anchor)).
//!
//! The file is JSON: `{"name": "...", "note": "...", "log": [{"seconds": s, "test_psnr": p}, ...]}`
//! with `note` optional and each entry's `step` optional (other fields are ignored, so a
//! `fogray fit --json` or `fogray-grid fit --json` output with a `name` added is an anchor
//! too). The seconds must be training seconds measured like fogray's (evaluations excluded) on
//! the same machine; a report can only say where the numbers came from, not check them.
//!
//! ```
//! use fogray_lab::curves::Anchor;
//!
//! let anchor = Anchor::from_json(
//!     r#"{"name": "other", "log": [{"seconds": 0, "test_psnr": 10}, {"seconds": 300, "test_psnr": 23.9}]}"#,
//! )?;
//! assert_eq!(anchor.final_psnr(), 23.9);
//! assert!(Anchor::from_json(r#"{"name": "other", "log": []}"#).is_err());
//! # Ok::<(), fogray_lab::curves::CurveError>(())
//! ```

use std::path::Path;

use serde::{Deserialize, Serialize};

use fogray_fit::train::LogEntry;

use super::reach::check;
use super::CurveError;

/// One evaluation of the anchor's run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AnchorPoint {
    /// Training seconds (evaluations excluded).
    pub seconds: f64,
    /// Test PSNR (dB) on the same held-out views.
    pub test_psnr: f64,
    /// Steps so far, if the file gives them.
    #[serde(default)]
    pub step: Option<usize>,
}

/// An outside pipeline's run: what it is, and its test PSNR against training seconds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Anchor {
    /// What ran (shown in the legend and the tables).
    pub name: String,
    /// Where and how it was measured (shown under the table).
    #[serde(default)]
    pub note: Option<String>,
    /// The evaluations, in time order.
    pub log: Vec<AnchorPoint>,
}

impl Anchor {
    /// Reads an anchor from its JSON text.
    ///
    /// Errors: [`CurveError::Anchor`] for text that is not such an object, an empty name, an
    /// empty log, a negative or non-finite time, a non-finite PSNR, or times (or steps) that
    /// decrease.
    pub fn from_json(text: &str) -> Result<Self, CurveError> {
        let anchor: Anchor = serde_json::from_str(text).map_err(|e| CurveError::Anchor(format!("anchor: {e}")))?;
        if anchor.name.trim().is_empty() {
            return Err(CurveError::Anchor("anchor: the name is empty".into()));
        }
        if let Some((i, p)) = anchor
            .log
            .iter()
            .enumerate()
            .find(|(_, p)| !(p.seconds >= 0.0 && p.seconds.is_finite() && p.test_psnr.is_finite()))
        {
            return Err(CurveError::Anchor(format!(
                "anchor: entry {i}: seconds {} must be finite and not negative, test PSNR {} finite",
                p.seconds, p.test_psnr
            )));
        }
        check(&anchor.entries()).map_err(|e| CurveError::Anchor(format!("anchor: {e}")))?;
        Ok(anchor)
    }

    /// Reads the anchor file at `path`. Errors: [`CurveError::Anchor`] naming the file, for a
    /// file that cannot be read or as [`Anchor::from_json`].
    pub fn read(path: &Path) -> Result<Self, CurveError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| CurveError::Anchor(format!("cannot read the anchor {}: {e}", path.display())))?;
        Self::from_json(&text).map_err(|e| CurveError::Anchor(format!("{}: {e}", path.display())))
    }

    /// The log as a fit's log entries (steps 0 where the file gives none; no training loss or
    /// samples), to be read as a curve.
    pub fn entries(&self) -> Vec<LogEntry> {
        self.log
            .iter()
            .map(|p| LogEntry {
                step: p.step.unwrap_or(0),
                seconds: p.seconds,
                train_loss: f64::NAN,
                test_psnr: p.test_psnr,
                test_ssim: f64::NAN,
                samples: 0,
            })
            .collect()
    }

    /// The last evaluation's test PSNR (a checked anchor has one).
    pub fn final_psnr(&self) -> f64 {
        self.log.last().map_or(f64::NAN, |p| p.test_psnr)
    }
}
