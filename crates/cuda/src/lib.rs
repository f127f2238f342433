//! fogray on NVIDIA GPUs: the fused emission-absorption composite ([`CudaComposite`]), the
//! dense grid field ([`CudaGrid`]), the density/colour activation ([`CudaDensityColor`]) and
//! its view-dependent form through spherical harmonics ([`CudaShDensityColor`]), and a dense
//! grid's whole training step ([`DenseGridTrainer`]), each kernel tested against the CPU
//! op of `fogray-ops` (see `docs/cuda.md`). The composite is described below.
//!
//! The kernels are CUDA C (`src/kernels/composite.cu`) compiled at run time by NVRTC for the
//! device found, and the CUDA libraries are loaded when first used (cudarc with dynamic
//! loading): the crate builds on any machine, with no CUDA toolkit and no GPU. Where there is
//! no driver, [`CudaComposite::new`] returns [`CudaError::NoDriver`] (and the crate's tests
//! skip, saying so); NVRTC (`libnvrtc.so.13`, in the toolkit's `lib64` or the
//! `nvidia-cuda-nvrtc` wheel) must be on the library path.
//!
//! # What it computes
//!
//! The composite of `fogray_ops::Composite` with a shared background (`docs/volume-rendering.md`),
//! on packed rays: ray `r` owns samples `offsets[r]..offsets[r+1]` of `sigma [n]`, `delta [n]`,
//! `color [n, 3]`, with `background [3]`:
//!
//! ```text
//! alpha_k = -expm1(-sigma_k delta_k)   T_k = exp(-sum_{j<k} sigma_j delta_j)   w_k = T_k alpha_k
//! C = sum_k w_k c_k + T_end c_bg       opacity = -expm1(-sum_k sigma_k delta_k)
//! ```
//!
//! and its backward given `dL/dC [R, 3]` and optionally `dL/dopacity [R]`: the gradients of
//! sigma, delta, the colours and the background, by the back-to-front recurrence of the CPU op.
//! The numerics are the CPU op's: every value inside the kernels is an `f64`, for `f32` data
//! too, the transmittance comes from the running optical depth, never a product of `1 - alpha`,
//! and the backward subtracts nothing from a total. The forward keeps, as the backward's only
//! residual, the exact optical depth before every 8th sample (one `f64` per 8 samples), so
//! the backward recomputes `T` and `alpha` without a subtraction that would lose them behind a
//! huge optical depth. Early termination (`min_transmittance`), per-ray backgrounds, depth,
//! weights and transmittance outputs, and channel counts other than 3 are the CPU op's alone
//! for now.
//!
//! # Example
//!
//! ```no_run
//! use fogray_cuda::{CudaComposite, CudaError, HostRays};
//!
//! let gpu = match CudaComposite::new(0) {
//!     Err(CudaError::NoDriver | CudaError::NoDevice { .. }) => return Ok(()), // no GPU here
//!     other => other?,
//! };
//! // Two rays: samples 0..3 and 3..5.
//! let offsets = [0, 3, 5];
//! let sigma = [0.5f32, 2.0, 8.0, 1.0, 0.0];
//! let delta = [0.5f32; 5];
//! let color = [0.25f32; 15];
//! let background = [1.0f32, 1.0, 1.0];
//! let rays = HostRays { offsets: &offsets, sigma: &sigma, delta: &delta, color: &color, background: &background };
//! // dL/dC = 1 for every channel of every ray.
//! let (out, grads) = gpu.evaluate_vjp(&rays, &[1.0f32; 6], None)?;
//! assert_eq!(out.color.len(), 6);
//! assert_eq!(grads.sigma.len(), 5);
//! # Ok::<(), CudaError>(())
//! ```
//!
//! For repeated work on the device (a training step, the benchmark), upload once
//! ([`CudaComposite::upload`]), keep the buffers ([`CudaComposite::forward_buffers`],
//! [`CudaComposite::gradient_buffers`]) and launch ([`CudaComposite::launch_forward`],
//! [`CudaComposite::launch_backward`]), which queue work on the stream and return at once.

mod activation;
mod buffers;
mod composite;
mod error;
mod grid;
mod kernel;
mod packing;
mod sh;
mod train;

pub use activation::{CudaDensityColor, HostActivated};
pub use composite::{
    CudaComposite, DeviceFloat, DeviceForward, DeviceGradients, DeviceRays, DeviceUpstream, HostGradients, HostOutputs,
    HostRays, KernelInfo,
};
pub use cudarc;
pub use error::CudaError;
pub use grid::{CudaGrid, GridSpec};
pub use kernel::{
    compile, compile_grid, compile_train, compile_tuned, Exponentials, KernelTuning, Staging, COMPOSITE_SOURCE,
    GRID_SOURCE, TRAIN_SOURCE,
};
pub use packing::{check_packing, CHANNELS};
pub use sh::{CudaShDensityColor, MAX_SH_DEGREE};
pub use train::{DenseGridTrainer, OccupancySettings, StepPhases, TrainerSettings, TrainingRays};

/// Opens device 0 for a test or a benchmark, or says why not and returns `None` when there is
/// no driver or no device (so that machines without a GPU skip). With `FOGRAY_CUDA_REQUIRED=1`
/// in the environment a missing GPU is an error instead of a skip (for runs on a GPU machine,
/// where a skip would hide a broken setup).
pub fn device_for_tests() -> Result<Option<CudaComposite>, CudaError> {
    let required = std::env::var("FOGRAY_CUDA_REQUIRED").is_ok_and(|v| v == "1");
    match CudaComposite::new(0) {
        Ok(gpu) => Ok(Some(gpu)),
        Err(e @ (CudaError::NoDriver | CudaError::NoDevice { .. })) if !required => {
            eprintln!("SKIPPED: no CUDA device ({e})");
            Ok(None)
        }
        Err(e) => Err(e),
    }
}
