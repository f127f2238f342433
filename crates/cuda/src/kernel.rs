//! The kernels' CUDA C source and its compilation by NVRTC at run time.

use cudarc::nvrtc::{compile_ptx_with_opts, CompileOptions, Ptx};

use crate::error::CudaError;

/// How the composite kernels stage their memory traffic, fixed when they are compiled. The
/// results do not depend on it (every layout computes the same sums in the same order); the
/// speed does, differently on each device, so the benchmark compares layouts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct KernelTuning {
    /// Bytes of densities in the span of a ray that a lane takes per step: 32 or 64 (whole
    /// 8-sample residual chunks, so at least one chunk).
    pub span_bytes: u32,
    /// Loads a lane issues before it stores any of them to shared memory: 4, 8 or 16.
    pub loads_in_flight: u32,
    /// Threads (rays) per block: 32, 64 or 128.
    pub threads_per_block: u32,
}

/// The values of each [`KernelTuning`] field the kernels are built for.
const SPAN_BYTES: [u32; 2] = [32, 64];
const LOADS_IN_FLIGHT: [u32; 3] = [4, 8, 16];
const THREADS_PER_BLOCK: [u32; 3] = [32, 64, 128];

impl Default for KernelTuning {
    /// The layout chosen from the benchmark's comparison of layouts on an H100
    /// (`reports/cuda/composite-layouts.log`; within noise of the fastest there).
    fn default() -> Self {
        KernelTuning {
            span_bytes: 64,
            loads_in_flight: 8,
            threads_per_block: 128,
        }
    }
}

impl KernelTuning {
    /// Every layout the kernels are built for.
    pub fn every() -> Vec<KernelTuning> {
        let mut all = Vec::new();
        for span_bytes in SPAN_BYTES {
            for loads_in_flight in LOADS_IN_FLIGHT {
                for threads_per_block in THREADS_PER_BLOCK {
                    all.push(KernelTuning {
                        span_bytes,
                        loads_in_flight,
                        threads_per_block,
                    });
                }
            }
        }
        all
    }

    fn check(&self) -> Result<(), CudaError> {
        if !SPAN_BYTES.contains(&self.span_bytes)
            || !LOADS_IN_FLIGHT.contains(&self.loads_in_flight)
            || !THREADS_PER_BLOCK.contains(&self.threads_per_block)
        {
            return Err(CudaError::Tuning(*self));
        }
        Ok(())
    }
}

/// The CUDA C source of the composite's kernels (forward, backward and the background
/// gradient's reduction, each for f32 and f64 data).
pub const COMPOSITE_SOURCE: &str = include_str!("kernels/composite.cu");

/// Compiles [`COMPOSITE_SOURCE`] to PTX for a device of compute capability `(major, minor)`
/// (a virtual architecture, `compute_XY`, which the driver compiles for the device itself, so
/// that Hopper gets Hopper code; NVRTC 13 knows capability 7.5 and newer). Needs NVRTC only, no device: the tests compile it on any
/// machine where libnvrtc loads.
pub fn compile(capability: (i32, i32)) -> Result<Ptx, CudaError> {
    compile_tuned(capability, KernelTuning::default())
}

/// [`compile`] with another staging layout than the default.
pub fn compile_tuned(capability: (i32, i32), tuning: KernelTuning) -> Result<Ptx, CudaError> {
    tuning.check()?;
    nvrtc(
        COMPOSITE_SOURCE,
        capability,
        vec![
            format!("-DSPAN_BYTES={}", tuning.span_bytes),
            format!("-DLOADS={}", tuning.loads_in_flight),
            format!("-DBLOCK={}", tuning.threads_per_block),
        ],
    )
}

/// The CUDA C source of the grid field's and the activation's kernels.
pub const GRID_SOURCE: &str = include_str!("kernels/grid.cu");

/// Compiles [`GRID_SOURCE`] to PTX for a device of compute capability `(major, minor)`, as
/// [`compile`] does the composite's.
pub fn compile_grid(capability: (i32, i32)) -> Result<Ptx, CudaError> {
    nvrtc(GRID_SOURCE, capability, Vec::new())
}

/// The CUDA C source of the training step's own kernels (batch sampling, loss, Adam).
pub const TRAIN_SOURCE: &str = include_str!("kernels/train.cu");

/// Compiles [`TRAIN_SOURCE`] to PTX for a device of compute capability `(major, minor)`.
pub fn compile_train(capability: (i32, i32)) -> Result<Ptx, CudaError> {
    nvrtc(TRAIN_SOURCE, capability, Vec::new())
}

fn nvrtc(source: &str, capability: (i32, i32), defines: Vec<String>) -> Result<Ptx, CudaError> {
    // SAFETY: only tries to open the library by its usual names (cudarc's loader panics when
    // it is missing, so ask first).
    if !unsafe { cudarc::nvrtc::sys::is_culib_present() } {
        return Err(CudaError::NoNvrtc);
    }
    let (major, minor) = capability;
    let opts = CompileOptions {
        // Exact division and square roots, no flush of subnormals: the CPU op's numerics (an
        // f32 transmittance underflows through the subnormals there too).
        ftz: Some(false),
        prec_div: Some(true),
        prec_sqrt: Some(true),
        use_fast_math: Some(false),
        options: [
            vec![
                format!("--gpu-architecture=compute_{major}{minor}"),
                "--std=c++17".into(),
            ],
            defines,
        ]
        .concat(),
        ..Default::default()
    };
    compile_ptx_with_opts(source, opts).map_err(|e| CudaError::Compile(format!("{e:?}")))
}
