//! Why a `fogray-disc` command failed: the one line it prints on stderr (exit status 2) is the
//! error's message.

use std::path::Path;

use fogray::ops::OpsError;
use fogray::tape::TapeError;
use thiserror::Error;

/// Why an experiment, a plot or a report could not be made.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum DiscError {
    /// A numeric option outside its domain.
    #[error("--{name} must be {rule}, got {value}")]
    Setting {
        /// The option, without its dashes.
        name: &'static str,
        /// The value given.
        value: f64,
        /// What it must be.
        rule: &'static str,
    },
    /// A ray interval that is not increasing.
    #[error("need t0 < t1, got {t0} and {t1}")]
    Interval {
        /// Where the rays start.
        t0: f64,
        /// Where they end.
        t1: f64,
    },
    /// A landscape range that is empty or has no step.
    #[error("need --from < --to and --step > 0, got {from}, {to}, {step}")]
    Range {
        /// `--from`.
        from: f64,
        /// `--to`.
        to: f64,
        /// `--step`.
        step: f64,
    },
    /// A pixel outside the scene.
    #[error("camera {camera} pixel {pixel} is not in the scene ({cameras} cameras x {pixels} pixels)")]
    NoSuchPixel {
        /// The camera asked for.
        camera: usize,
        /// The pixel asked for.
        pixel: usize,
        /// Cameras in the scene.
        cameras: usize,
        /// Pixels per camera.
        pixels: usize,
    },
    /// Options that do not go together, or another rule of the command line.
    #[error("{0}")]
    Usage(&'static str),
    /// A tape operation failed (a renderer, a fit).
    #[error("{0}")]
    Tape(#[from] TapeError),
    /// An op refused its input (the composite, naming the ray and sample).
    #[error("{0}")]
    Ops(#[from] OpsError),
    /// Arrays that do not fit the shapes built from them.
    #[error("{0}")]
    Shape(#[from] ndarray::ShapeError),
    /// JSON could not be written.
    #[error("{0}")]
    Json(#[from] serde_json::Error),
    /// An output file could not be written (nothing is left under its name but the file it
    /// replaces, if any).
    #[error("{0}")]
    Output(#[from] fogray_data::DataError),
    /// A file or directory could not be written or created.
    #[error("cannot {action} {path}: {source}")]
    File {
        /// `"write"` or `"create"`.
        action: &'static str,
        /// The path, as displayed.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// A plot could not be drawn. (plotters' errors are generic over the drawing backend, so
    /// their message is what is kept.)
    #[error("{0}")]
    Plot(String),
}

impl DiscError {
    /// A file operation's error, naming the path.
    pub fn file<'a>(action: &'static str, path: &'a Path) -> impl FnOnce(std::io::Error) -> DiscError + 'a {
        move |source| DiscError::File {
            action,
            path: path.display().to_string(),
            source,
        }
    }

    /// A plotting error, by its message.
    pub fn plot(e: impl std::fmt::Display) -> DiscError {
        DiscError::Plot(e.to_string())
    }
}
