//! The kernels' CUDA C source and its compilation by NVRTC at run time.

use cudarc::nvrtc::{compile_ptx_with_opts, CompileOptions, Ptx};

use crate::error::CudaError;

/// How the composite kernels are built: how they stage their memory traffic, and in which
/// precision they take f32 data's exponentials. The results do not depend on the staging
/// (every layout computes the same sums in the same order); the speed does, differently on
/// each device, so the benchmark compares layouts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct KernelTuning {
    /// Bytes of densities in the span of a ray that a lane takes per step: 32 or 64 (whole
    /// 8-sample residual chunks, so at least one chunk).
    pub span_bytes: u32,
    /// How a warp's loads are staged.
    pub staging: Staging,
    /// Threads (rays) per block: 32, 64 or 128 ([`Staging::Pipelined`]: 32 or 64, since its two
    /// stages a warp must fit a block's 48 KB of static shared memory).
    pub threads_per_block: u32,
    /// How each sample's `exp(-depth)` and `-expm1(-tau)` are taken for f32 data.
    pub exponentials: Exponentials,
}

/// The precision of the per-sample exponentials of f32 data (f64 data always takes them in
/// f64). Every sum, and each ray's final transmittance, stays f64 either way.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Exponentials {
    /// In f64, as the CPU op takes them.
    Double,
    /// With the single-precision functions: `T = expf(-hi) (1 - lo)` for the depth split into
    /// its f32 rounding `hi` and the exact rest `lo` (so that rounding a long ray's depth
    /// costs nothing), `alpha = -expm1f(-tau)`. Cheaper; within expf's 2 ulp of each `T`.
    SplitSingle,
}

/// How a warp brings its rays' spans into shared memory.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Staging {
    /// Load a step's spans, then compute on them: each lane issues `loads_in_flight` loads
    /// (4, 8 or 16) before it stores any of them to shared memory.
    Batched {
        /// Loads a lane has in flight.
        loads_in_flight: u32,
    },
    /// Copy the next step's spans into a second stage while computing on this one's, with
    /// asynchronous copies (`cp.async`) on compute capability 8.0 and newer (on older devices
    /// the copies are plain loads and stores, in the same order).
    Pipelined,
    /// One stage, as [`Staging::Batched`], filled with asynchronous copies (`cp.async`, compute
    /// capability 8.0 and newer) that are all posted before any is waited for: every element of
    /// a step's spans in flight at once, without holding registers (on older devices, plain
    /// loads and stores).
    Async,
}

/// Threads of the background gradient's reduction (`REDUCE` in the kernel source, which is
/// compiled with this value).
pub(crate) const REDUCE_BLOCK: usize = 256;

/// The values of each [`KernelTuning`] field the kernels are built for.
const SPAN_BYTES: [u32; 2] = [32, 64];
const LOADS_IN_FLIGHT: [u32; 3] = [4, 8, 16];
const THREADS_PER_BLOCK: [u32; 3] = [32, 64, 128];
const PIPELINED_THREADS_PER_BLOCK: [u32; 2] = [32, 64];

impl Default for KernelTuning {
    /// The layout chosen from the benchmark's comparison of layouts on an H200
    /// (`reports/cuda/h200/composite-layouts-async*.log`: the fastest, with 64 threads level).
    fn default() -> Self {
        KernelTuning {
            span_bytes: 64,
            staging: Staging::Async,
            threads_per_block: 128,
            exponentials: Exponentials::Double,
        }
    }
}

impl Staging {
    /// Every staging the kernels are built for, in the order [`KernelTuning::every`] lists them.
    fn every() -> Vec<Staging> {
        let batched = LOADS_IN_FLIGHT.map(|loads_in_flight| Staging::Batched { loads_in_flight });
        [batched.as_slice(), &[Staging::Pipelined, Staging::Async]].concat()
    }

    /// The threads per block the kernels are built for with this staging (the pipelined one's
    /// two stages a warp must fit a block's 48 KB of static shared memory).
    fn threads_per_block(self) -> &'static [u32] {
        match self {
            Staging::Pipelined => &PIPELINED_THREADS_PER_BLOCK,
            Staging::Batched { .. } | Staging::Async => &THREADS_PER_BLOCK,
        }
    }
}

impl KernelTuning {
    /// Every staging layout the kernels are built for, each with `Exponentials::Double`.
    pub fn every() -> Vec<KernelTuning> {
        let mut all = Vec::new();
        for span_bytes in SPAN_BYTES {
            for staging in Staging::every() {
                for &threads_per_block in staging.threads_per_block() {
                    all.push(KernelTuning {
                        span_bytes,
                        staging,
                        threads_per_block,
                        exponentials: Exponentials::Double,
                    });
                }
            }
        }
        all
    }

    fn check(&self) -> Result<(), CudaError> {
        let staging_ok = Staging::every().contains(&self.staging)
            && self.staging.threads_per_block().contains(&self.threads_per_block);
        if !SPAN_BYTES.contains(&self.span_bytes) || !staging_ok {
            return Err(CudaError::Tuning(*self));
        }
        Ok(())
    }

    /// The preprocessor definitions that build the kernels for this layout.
    fn defines(&self) -> Vec<String> {
        let staging = match self.staging {
            Staging::Batched { loads_in_flight } => format!("-DLOADS={loads_in_flight}"),
            Staging::Pipelined => "-DPIPELINED=1".to_string(),
            Staging::Async => "-DASYNC_STAGE=1".to_string(),
        };
        let exponentials = match self.exponentials {
            Exponentials::Double => 0,
            Exponentials::SplitSingle => 1,
        };
        vec![
            format!("-DSPAN_BYTES={}", self.span_bytes),
            staging,
            format!("-DBLOCK={}", self.threads_per_block),
            format!("-DF32_EXP={exponentials}"),
            format!("-DREDUCE={REDUCE_BLOCK}"),
        ]
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
    // No multiply-add the source does not write as `fma`: where the compiler fuses one depends
    // on the code around it, so the staging layouts' f64 results differed in the last bit
    // (the pipelined backward's against the batched, measured on an H200), and the CPU op
    // (Rust) never fuses.
    nvrtc(
        COMPOSITE_SOURCE,
        capability,
        [tuning.defines(), vec!["--fmad=false".to_string()]].concat(),
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

fn nvrtc(source: &str, capability: (i32, i32), extra_options: Vec<String>) -> Result<Ptx, CudaError> {
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
            extra_options,
        ]
        .concat(),
        ..Default::default()
    };
    compile_ptx_with_opts(source, opts).map_err(|e| CudaError::Compile(format!("{e:?}")))
}
