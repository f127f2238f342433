//! Why a measurement of the lab failed: `fogray-lab bench` prints the error's message as one
//! line on stderr (exit status 2).

use std::path::Path;

use fogray_ops::OpsError;
use fogray_tape::TapeError;
use thiserror::Error;

/// Why a bench (or the report it writes) could not run.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum LabError {
    /// An op refused its input (its message names the op, and the ray and sample).
    #[error("{0}")]
    Ops(#[from] OpsError),
    /// A tape operation failed.
    #[error("{0}")]
    Tape(#[from] TapeError),
    /// Arrays that do not fit the shapes built from them.
    #[error("{0}")]
    Shape(#[from] ndarray::ShapeError),
    /// The output could not be serialised.
    #[error("{0}")]
    Json(#[from] serde_json::Error),
    /// A file or directory could not be read, written or created.
    #[error("cannot {action} {path}: {source}")]
    File {
        /// `"read"`, `"write"` or `"create"`.
        action: &'static str,
        /// The path, as displayed.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// A file written whole (a fresh temporary renamed) that could not be.
    #[error("{0}")]
    Data(#[from] fogray_data::DataError),
    /// A README without the markers of the generated block to replace.
    #[error("{path} has no {start} ... {end} block")]
    MissingMarkers {
        /// The README, as displayed.
        path: String,
        /// The start marker.
        start: String,
        /// The end marker.
        end: String,
    },
    /// The thread pool of a one-thread run could not be built.
    #[error("{0}")]
    ThreadPool(#[from] rayon::ThreadPoolBuildError),
    /// A command-line option outside its domain (a workload that is not one).
    #[error("{0}")]
    Option(String),
    /// A computation that should have produced a value did not (a gradient missing...).
    #[error("{0}")]
    Missing(&'static str),
    /// The platform does not offer what was asked for.
    #[error("{0}")]
    Unsupported(&'static str),
}

impl LabError {
    /// A file operation's error, naming the path.
    pub fn file<'a>(action: &'static str, path: &'a Path) -> impl FnOnce(std::io::Error) -> LabError + 'a {
        move |source| LabError::File {
            action,
            path: fogray_data::shown(path).to_string(),
            source,
        }
    }
}
