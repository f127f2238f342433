//! The crate's one error type.

use cudarc::driver::DriverError;
use thiserror::Error;

/// Why a GPU composite could not be set up or run.
#[derive(Debug, Error)]
pub enum CudaError {
    /// The CUDA driver library (`libcuda.so`) could not be loaded: no NVIDIA driver here.
    #[error("no CUDA driver: the library libcuda could not be loaded")]
    NoDriver,
    /// The driver loaded but reports no device (or not the one asked for).
    #[error("no CUDA device {ordinal} (the driver reports {count})")]
    NoDevice {
        /// The device asked for.
        ordinal: usize,
        /// How many the driver sees.
        count: usize,
    },
    /// The NVRTC library (`libnvrtc.so`), which compiles the kernels at run time, could not be
    /// loaded: it ships with the CUDA toolkit (or the `nvidia-cuda-nvrtc` wheel); put its
    /// folder on `LD_LIBRARY_PATH`.
    #[error("no NVRTC: the library libnvrtc could not be loaded (add the CUDA toolkit's lib64 to LD_LIBRARY_PATH)")]
    NoNvrtc,
    /// NVRTC rejected the kernel source (a bug in this crate, or an NVRTC too old).
    #[error("NVRTC could not compile the kernels: {0}")]
    Compile(String),
    /// A call into the CUDA driver failed.
    #[error("CUDA driver: {0}")]
    Driver(#[from] DriverError),
    /// The offsets are not a packing of the samples.
    #[error("offsets: {0}")]
    Offsets(String),
    /// An array's length does not fit the packing.
    #[error("{what}: expected {expected} values, got {got}")]
    Shape {
        /// Which array.
        what: &'static str,
        /// The length the packing requires.
        expected: usize,
        /// The length given.
        got: usize,
    },
    /// A background value is not finite.
    #[error("background[{channel}] is {value} (must be finite)")]
    InvalidBackground {
        /// The channel.
        channel: usize,
        /// The value.
        value: f64,
    },
    /// Some sample value is outside its domain: a density or length negative, NaN or infinite,
    /// or a colour NaN or infinite (the composite); a NaN coordinate (the grid field) or raw
    /// value (the activation). Found on the device, which does not say where: the CPU op's
    /// `evaluate` names the ray and the sample.
    #[error("a sample value is outside its domain (sigma and delta finite and >= 0, colour finite)")]
    InvalidSample,
    /// A grid whose box or lattice is not one (the message says which axis and why).
    #[error("grid: {0}")]
    InvalidGrid(String),
    /// A trainer setting out of its range (the message says which).
    #[error("trainer settings: {0}")]
    InvalidSettings(String),
    /// The activation's density shift is not finite.
    #[error("density shift {0} (must be finite)")]
    InvalidShift(f64),
    /// A staging layout the kernels are not built for.
    #[error(
        "kernel tuning {0:?}: span_bytes must be 32 or 64, loads_in_flight 4, 8 or 16, threads_per_block 32, 64 or 128 (32 or 64 when pipelined)"
    )]
    Tuning(crate::kernel::KernelTuning),
    /// The batch is larger than one launch can cover.
    #[error("{0}")]
    TooLarge(String),
}
