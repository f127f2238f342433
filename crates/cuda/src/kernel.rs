//! The kernels' CUDA C source and its compilation by NVRTC at run time.

use cudarc::nvrtc::{compile_ptx_with_opts, CompileOptions, Ptx};

use crate::error::CudaError;

/// The CUDA C source of the composite's kernels (forward, backward and the background
/// gradient's reduction, each for f32 and f64 data).
pub const COMPOSITE_SOURCE: &str = include_str!("kernels/composite.cu");

/// Compiles [`COMPOSITE_SOURCE`] to PTX for a device of compute capability `(major, minor)`
/// (a virtual architecture, `compute_XY`, which the driver compiles for the device itself, so
/// that Hopper gets Hopper code; NVRTC 13 knows capability 7.5 and newer). Needs NVRTC only, no device: the tests compile it on any
/// machine where libnvrtc loads.
pub fn compile(capability: (i32, i32)) -> Result<Ptx, CudaError> {
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
        options: vec![
            format!("--gpu-architecture=compute_{major}{minor}"),
            "--std=c++17".into(),
        ],
        ..Default::default()
    };
    compile_ptx_with_opts(COMPOSITE_SOURCE, opts).map_err(|e| CudaError::Compile(format!("{e:?}")))
}
