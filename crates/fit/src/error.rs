//! Why a fit, a render or a model could not run: one error for the pipeline, which keeps the
//! error of the op or library underneath it.

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
    /// A setting outside its range, or inputs that do not fit together (named in the text).
    #[error("{0}")]
    Config(String),
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
