//! Why a fit, a render or a model could not run: one error for the pipeline, which keeps the
//! error of the op or library underneath it.

use std::path::PathBuf;

use fogray_data::shown;
use fogray_ops::OpsError;
use fogray_tape::params::ParamError;
use fogray_tape::TapeError;
use thiserror::Error;

use crate::images::ImageError;
use crate::mesh::MeshError;
use crate::settings::ModelKind;

/// Why a fit, a render or a model could not run.
#[non_exhaustive]
#[derive(Debug, Clone, PartialEq, Error)]
pub enum FitError {
    /// An internal inconsistency that is not expected (a shape lost on the way, settings that
    /// cannot be merged), or an input not yet given a typed variant (named in the text).
    #[error("{0}")]
    Config(String),
    /// A setting outside its range, as a flag gave it or a checkpoint carries it: the flag
    /// (`--grid`) or the settings named in words, the value when the line shows it, and the
    /// rule it breaks.
    #[error("{flag}{} {rule}", setting_value(.value))]
    Setting {
        /// The flag, or the settings named in words.
        flag: &'static str,
        /// The value given, when the message shows it (`--steps 0` needs no repeat).
        value: Option<String>,
        /// The rule it breaks.
        rule: String,
    },
    /// A setting refused by the op it configures (`--tv` by the total-variation prior,
    /// `--sh-degree` and `--background-degree` by the spherical harmonics): the flag, and the
    /// op's error, which holds the value and the rule.
    #[error("{flag}: {source}")]
    SettingOp {
        /// The flag.
        flag: &'static str,
        /// The op's refusal.
        source: OpsError,
    },
    /// A file of the fit's (the splats' PLY file) that could not be written: nothing was left
    /// under its name.
    #[error("{}: {what} cannot be written: {reason}", shown(.path))]
    Write {
        /// The file.
        path: PathBuf,
        /// What it holds (`"the splats"`).
        what: &'static str,
        /// The operating system's reason, on one line.
        reason: String,
    },
    /// A `--box` whose bounds on some axis are not finite or not increasing.
    #[error("--box: axis {axis} runs from {min} to {max} (must be finite and increasing)")]
    BoxAxis {
        /// Axis (0 = x, 1 = y, 2 = z).
        axis: usize,
        /// Lower bound given.
        min: f64,
        /// Upper bound given.
        max: f64,
    },
    /// A `--box` reaching farther from the origin than a dataset's coordinates may: beyond it
    /// the samplers' steps and distances overflow.
    #[error("--box: axis {axis} runs from {min:e} to {max:e}, beyond {limit:e} from the origin")]
    BoxBeyondRange {
        /// Axis (0 = x, 1 = y, 2 = z).
        axis: usize,
        /// Lower bound given.
        min: f64,
        /// Upper bound given.
        max: f64,
        /// The farthest a bound may lie from the origin.
        limit: f64,
    },
    /// A view's picture or alpha that is not its camera's size.
    #[error("view {view}: {what} {got:?}, but the camera's image is {expected:?}")]
    ViewSize {
        /// The view's name.
        view: String,
        /// `"picture"` or `"alpha"`.
        what: &'static str,
        /// Its shape.
        got: Vec<usize>,
        /// The camera's (`[H, W, 3]` for a picture, `[H, W]` for alpha).
        expected: Vec<usize>,
    },
    /// A view's alpha outside `[0, 1]` (NaN included).
    #[error("view {view}: alpha {value} at row {row}, column {column} (must be in [0, 1])")]
    AlphaOutOfRange {
        /// The view's name.
        view: String,
        /// The first offending pixel's row.
        row: usize,
        /// Its column.
        column: usize,
        /// Its alpha.
        value: f64,
    },
    /// A dataset with no held-out view to evaluate the fit on.
    #[error("the fit needs at least one test view")]
    NoTestView,
    /// A dataset whose training views hold no pixel.
    #[error("the fit needs at least one training pixel")]
    NoTrainingPixel,
    /// A training pixel past the last of the views' table.
    #[error("training pixel {pixel} asked of a table of {pixels}")]
    PixelOutOfRange {
        /// The pixel asked for.
        pixel: usize,
        /// The pixels in the table.
        pixels: usize,
    },
    /// Backgrounds for a batch that are not one colour a pixel (`[n, 3]`).
    #[error("backgrounds {got:?} for a batch of {pixels} pixels")]
    BackgroundsShape {
        /// Their shape.
        got: Vec<usize>,
        /// The batch's pixels.
        pixels: usize,
    },
    /// Ctrl-C could not be caught (the process's handler is set once a process).
    #[error("cannot catch Ctrl-C: {reason}")]
    CtrlC {
        /// The handler's error, in words.
        reason: String,
    },
    /// From the tape or an op on it.
    #[error(transparent)]
    Tape(#[from] TapeError),
    /// From an op called outside the tape, a sampler, the occupancy grid or the rays and
    /// cameras (the error names which).
    #[error(transparent)]
    Ops(#[from] OpsError),
    /// From the parameter store or the optimiser.
    #[error(transparent)]
    Param(#[from] ParamError),
    /// From a mesh's extraction (a level or resolution it cannot take).
    #[error(transparent)]
    Mesh(#[from] MeshError),
    /// From an image (PSNR, PNG).
    #[error(transparent)]
    Image(#[from] ImageError),
    /// A size (of the grid, of a batch) that needs more memory than the machine has, refused
    /// before anything was allocated.
    #[error(transparent)]
    TooLarge(#[from] fogray_ops::limits::TooLarge),
    /// Work on a field marched along rays asked of a model kind that is not one (the splats,
    /// drawn by projection).
    #[error("{} is not a model kind marched along rays (a dense or sparse grid)", .0.name())]
    NotAField(ModelKind),
    /// More splats than the settings allow (`max_splats`), refused before allocation.
    #[error("{count} splats exceed the cap of {cap}")]
    TooManySplats {
        /// The splats asked for.
        count: usize,
        /// The cap.
        cap: usize,
    },
}

/// A setting's value as its message shows it: ` 0:` after the flag, or nothing where the rule
/// reads on from the flag (`--grid must be at least 2`).
fn setting_value(value: &Option<String>) -> String {
    value.as_ref().map(|v| format!(" {v}:")).unwrap_or_default()
}

#[cfg(test)]
mod tests;
