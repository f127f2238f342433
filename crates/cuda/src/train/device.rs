//! What a trainer keeps on the device beside its settings: the structs its kernels take by
//! value (the box, a colour, the occupancy cells), the step's kernels, the batch's staging
//! buffers, the occupancy grid's refresh state, the shading and the grid with Adam's moments.

use cudarc::driver::{CudaFunction, CudaSlice, DeviceRepr};

use super::settings::OccupancySettings;
use super::VIEW_INDEPENDENT_CHANNELS;
use crate::activation::CudaDensityColor;
use crate::error::CudaError;
use crate::grid::CudaGrid;
use crate::sh::CudaShDensityColor;

/// The box as the sampling kernels take it.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub(super) struct DeviceBox {
    pub(super) min: [f64; 3],
    pub(super) max: [f64; 3],
}

// SAFETY: a plain `#[repr(C)]` struct of f64, laid out as the kernels' `Box`.
unsafe impl DeviceRepr for DeviceBox {}

/// A colour as the loss kernel takes it (`Rgb`).
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub(super) struct DeviceRgb(pub(super) [f64; 3]);

// SAFETY: a plain `#[repr(C)]` array of f64, laid out as the kernels' `Rgb`.
unsafe impl DeviceRepr for DeviceRgb {}

/// The occupancy grid's cells as the sampling kernels take them (`Cells`).
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub(super) struct DeviceCells {
    pub(super) min: [f64; 3],
    pub(super) scale: [f64; 3],
    pub(super) cells: u64,
}

// SAFETY: a plain `#[repr(C)]` struct of 8-byte numbers, laid out as the kernels' `Cells`.
unsafe impl DeviceRepr for DeviceCells {}

/// The step's kernels (`kernels/train.cu`).
pub(super) struct TrainKernels {
    pub(super) sample_batch: CudaFunction,
    pub(super) sample_range: CudaFunction,
    pub(super) photometric_loss: CudaFunction,
    pub(super) lattice: CudaFunction,
    pub(super) occupancy_points: CudaFunction,
    pub(super) occupancy_update: CudaFunction,
    pub(super) distortion: CudaFunction,
    pub(super) count_kept: CudaFunction,
    pub(super) scan_offsets: CudaFunction,
    pub(super) compact: CudaFunction,
    pub(super) adam: CudaFunction,
}

/// Where the sampling kernels write every sample of the batch, before the samples of nonzero
/// length are packed into the buffers the rest of the step reads.
pub(super) struct Staging {
    pub(super) positions: CudaSlice<f32>,
    pub(super) delta: CudaSlice<f32>,
    pub(super) ts: CudaSlice<f32>,
    /// `[n, 3]` with spherical harmonics, else one zero.
    pub(super) dirs: CudaSlice<f32>,
    /// Each ray's kept samples.
    pub(super) counts: CudaSlice<u64>,
}

/// The occupancy grid's refresh state on the device (its cells are the trainer's).
pub(super) struct OccupancyState {
    pub(super) settings: OccupancySettings,
    pub(super) estimate: CudaSlice<f32>,
    /// The refresh's points `[2 cells^3, 3]` and their raw values `[2 cells^3, channels]`.
    pub(super) points: CudaSlice<f32>,
    pub(super) raw: CudaSlice<f32>,
    pub(super) refreshes: u64,
}

/// How raw values become density and colour.
pub(super) enum Shading {
    /// `4` values a node: density, then RGB.
    Plain(CudaDensityColor),
    /// Density, then each channel's spherical-harmonics coefficients.
    Harmonics(CudaShDensityColor),
}

impl Shading {
    pub(super) fn channels(&self) -> usize {
        match self {
            Shading::Plain(_) => VIEW_INDEPENDENT_CHANNELS,
            Shading::Harmonics(sh) => sh.channels(),
        }
    }
}

/// The grid's parameters and Adam's state for them.
pub(super) struct GridState {
    pub(super) grid: CudaGrid,
    pub(super) params: CudaSlice<f32>,
    pub(super) grad: CudaSlice<f32>,
    pub(super) acc: CudaSlice<f64>,
    pub(super) m: CudaSlice<f32>,
    pub(super) v: CudaSlice<f32>,
    /// Adam steps on these moments (the bias correction's `t`).
    pub(super) adam_steps: u64,
}

impl GridState {
    /// `grid`'s values, all zero, with fresh moments.
    pub(super) fn zeros(
        stream: &std::sync::Arc<cudarc::driver::CudaStream>,
        grid: CudaGrid,
    ) -> Result<Self, CudaError> {
        let values = grid.spec().values();
        Ok(GridState {
            grid,
            params: stream.alloc_zeros(values)?,
            grad: stream.alloc_zeros(values)?,
            acc: stream.alloc_zeros(values)?,
            m: stream.alloc_zeros(values)?,
            v: stream.alloc_zeros(values)?,
            adam_steps: 0,
        })
    }
}
