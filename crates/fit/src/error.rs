//! Why a fit, a render or a model could not run: one error for the pipeline, which keeps the
//! error of the op or library underneath it.

use fogray_ops::{ActivationError, GeometryError, GridError, SampleError};
use fogray_tape::params::ParamError;
use fogray_tape::TapeError;
use thiserror::Error;

use crate::images::ImageError;
use crate::mesh::MeshError;

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
    /// From a sampler or the occupancy grid.
    #[error(transparent)]
    Sample(#[from] SampleError),
    /// From the rays or cameras.
    #[error(transparent)]
    Geometry(#[from] GeometryError),
    /// From the grid field.
    #[error(transparent)]
    Grid(#[from] GridError),
    /// From the density/colour activation.
    #[error(transparent)]
    Activation(#[from] ActivationError),
    /// From the parameter store or the optimiser.
    #[error(transparent)]
    Param(#[from] ParamError),
    /// From a mesh's extraction (a level or resolution it cannot take).
    #[error(transparent)]
    Mesh(#[from] MeshError),
    /// From an image (PSNR, PNG).
    #[error(transparent)]
    Image(#[from] ImageError),
}
