//! Why `fogray prepare` stopped: each message is the one line it prints on stderr.

use thiserror::Error;

/// Why `fogray prepare` refused its input or could not finish. Paths are as displayed, their
/// control characters escaped.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum PrepareError {
    /// The photographs' folder does not exist or is not a folder.
    #[error("{path} is not a folder of photographs (it does not exist or is not a folder)")]
    NotAFolder {
        /// The folder given.
        path: String,
    },
    /// A folder without a `.jpg`, `.jpeg` or `.png` file (any case) at its top level.
    #[error("{path} holds no photograph (no .jpg, .jpeg or .png file at its top level)")]
    NoPhotographs {
        /// The folder given.
        path: String,
    },
    /// `--out` is the photographs' folder or lies inside it (COLMAP would read its own
    /// output as photographs, and the photographs must stay untouched).
    #[error("--out {out} lies inside the photographs' folder {images}: choose a folder outside it")]
    OutInsideImages {
        /// `--out`.
        out: String,
        /// The photographs' folder.
        images: String,
    },
    /// `--out` exists and is not an empty folder.
    #[error("--out {path} already exists and is not an empty folder: choose a new folder or remove it")]
    OutNotEmpty {
        /// `--out`.
        path: String,
    },
    /// No `colmap` program on `PATH`.
    #[error(
        "no colmap on PATH: install COLMAP (apt install colmap on Debian/Ubuntu, brew install colmap on macOS, \
         or see https://colmap.github.io/install.html) and run fogray prepare again"
    )]
    NoColmap,
    /// `colmap` is there but could not be started.
    #[error("cannot run colmap: {0}")]
    CannotRun(#[source] std::io::Error),
    /// A COLMAP step exited with a failure (or was killed by something other than Ctrl-C).
    #[error("COLMAP's {step} failed ({status}): see {log}")]
    StepFailed {
        /// The step (`feature extraction`, `exhaustive matching`...).
        step: String,
        /// How it ended (`exit status 1`, `killed by signal 9`).
        status: String,
        /// `DIR/colmap.log`.
        log: String,
    },
    /// The mapper ended without a model: no pair of photographs it could start from.
    #[error(
        "COLMAP's mapping reconstructed nothing (no two photographs it could pose together; \
         photographs need to overlap, with texture in common): see {log}"
    )]
    NoModel {
        /// `DIR/colmap.log`.
        log: String,
    },
    /// A model's `images.bin` that is not COLMAP's binary layout.
    #[error("{path}: {reason}")]
    BadModel {
        /// The file.
        path: String,
        /// What is wrong, and where.
        reason: String,
    },
    /// A file or folder that could not be read, written, linked or renamed.
    #[error("cannot {action} {path}: {source}")]
    File {
        /// `"read"`, `"create"`, `"link"`...
        action: &'static str,
        /// The path.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// Ctrl-C (exit status 130): COLMAP was stopped and no model written.
    #[error(
        "interrupted during {step}: COLMAP stopped, no model written; {out} holds the photographs and \
         colmap.log (remove it before running fogray prepare again)"
    )]
    Interrupted {
        /// The step under way.
        step: String,
        /// `--out`.
        out: String,
    },
    /// Ctrl-C could not be caught.
    #[error("{0}")]
    CtrlC(#[from] fogray_fit::FitError),
}

impl PrepareError {
    /// A file operation's error, naming the path.
    pub fn file<'a>(
        action: &'static str,
        path: &'a std::path::Path,
    ) -> impl FnOnce(std::io::Error) -> PrepareError + 'a {
        move |source| PrepareError::File {
            action,
            path: fogray_data::shown(path).to_string(),
            source,
        }
    }
}
