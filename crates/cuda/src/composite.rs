//! The composite on the device: the context, the compiled kernels, device batches and the
//! launches, and the host-to-host convenience calls built on them.

use std::sync::Arc;

use cudarc::driver::{
    CudaContext, CudaFunction, CudaModule, CudaSlice, CudaStream, DeviceRepr, LaunchConfig, PushKernelArg,
    ValidAsZeroBits,
};

use crate::buffers::{check_len, put};
use crate::error::CudaError;
use crate::kernel::{compile_tuned, KernelTuning, REDUCE_BLOCK};
use crate::packing::{check_packing, residual_len, CHANNELS, WARP};

mod sealed {
    pub trait Sealed {}
    impl Sealed for f32 {}
    impl Sealed for f64 {}
}

/// The element types the kernels are built for: `f32` and `f64` (every value inside the
/// kernels is an `f64` either way, as in the CPU op).
pub trait DeviceFloat: DeviceRepr + ValidAsZeroBits + Copy + Default + Send + Sync + sealed::Sealed + 'static {
    /// The suffix of the kernels' names for this type.
    const SUFFIX: &'static str;
    /// The value as an `f64` (host-side checks).
    fn to_f64(self) -> f64;
}

impl DeviceFloat for f32 {
    const SUFFIX: &'static str = "f32";
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
}

impl DeviceFloat for f64 {
    const SUFFIX: &'static str = "f64";
    fn to_f64(self) -> f64 {
        self
    }
}

/// One element type's three kernels.
struct Kernels {
    forward: CudaFunction,
    backward: CudaFunction,
    reduce: CudaFunction,
}

impl Kernels {
    fn load(module: &Arc<CudaModule>, suffix: &str) -> Result<Self, CudaError> {
        Ok(Kernels {
            forward: module.load_function(&format!("composite_forward_{suffix}"))?,
            backward: module.load_function(&format!("composite_backward_{suffix}"))?,
            reduce: module.load_function(&format!("composite_reduce_background_{suffix}"))?,
        })
    }
}

/// A GPU, its stream and the composite kernels compiled for it.
pub struct CudaComposite {
    ctx: Arc<CudaContext>,
    stream: Arc<CudaStream>,
    f32: Kernels,
    f64: Kernels,
    name: String,
    capability: (i32, i32),
    tuning: KernelTuning,
}

impl std::fmt::Debug for CudaComposite {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CudaComposite")
            .field("device", &self.name)
            .field("capability", &self.capability)
            .finish()
    }
}

/// A batch of packed rays on the device: `offsets [R + 1]`, `sigma [n]`, `delta [n]`,
/// `color [n, 3]`, `background [3]` (shared by every ray).
#[derive(Debug)]
pub struct DeviceRays<F> {
    offsets: CudaSlice<u64>,
    sigma: CudaSlice<F>,
    delta: CudaSlice<F>,
    color: CudaSlice<F>,
    background: CudaSlice<F>,
    rays: usize,
    samples: usize,
}

impl<F> DeviceRays<F> {
    /// The per-sample arrays, for kernels of this crate that write them in place: `sigma`,
    /// `delta`, `color`.
    pub(crate) fn samples_mut(&mut self) -> (&mut CudaSlice<F>, &mut CudaSlice<F>, &mut CudaSlice<F>) {
        (&mut self.sigma, &mut self.delta, &mut self.color)
    }

    /// Every buffer of the batch at once, for kernels of this crate that pack the samples on
    /// the device (within the buffers' `samples`) or read them.
    pub(crate) fn parts_mut(&mut self) -> RaysMut<'_, F> {
        RaysMut {
            offsets: &mut self.offsets,
            sigma: &mut self.sigma,
            delta: &mut self.delta,
        }
    }

    /// The number of rays.
    pub fn rays(&self) -> usize {
        self.rays
    }

    /// The number of samples.
    pub fn samples(&self) -> usize {
        self.samples
    }
}

/// The packing and the per-sample buffers of a [`DeviceRays`], borrowed together.
pub(crate) struct RaysMut<'a, F> {
    /// `[R + 1]`.
    pub offsets: &'a mut CudaSlice<u64>,
    /// `[n]`.
    pub sigma: &'a mut CudaSlice<F>,
    /// `[n]`.
    pub delta: &'a mut CudaSlice<F>,
}

/// The forward's outputs on the device, and its residual for the backward.
#[derive(Debug)]
pub struct DeviceForward<F> {
    /// `[R, 3]`.
    pub color: CudaSlice<F>,
    /// `[R]`.
    pub opacity: CudaSlice<F>,
    /// The exact optical depth before every 8th sample of each ray (the backward's residual).
    chunk_depth: CudaSlice<f64>,
    /// Nonzero when some sample value was out of its domain.
    invalid: CudaSlice<u32>,
}

/// The upstream gradients on the device: `dL/dC [R, 3]` and, optionally, `dL/dopacity [R]`.
#[derive(Debug)]
pub struct DeviceUpstream<F> {
    color: CudaSlice<F>,
    opacity: Option<CudaSlice<F>>,
}

impl<F> DeviceUpstream<F> {
    /// `dL/dC` and `dL/dopacity`, for kernels of this crate that write both in place (the
    /// opacity's is `None` when the upstream was made without one).
    pub(crate) fn both_mut(&mut self) -> (&mut CudaSlice<F>, Option<&mut CudaSlice<F>>) {
        (&mut self.color, self.opacity.as_mut())
    }
}

/// The input gradients on the device.
#[derive(Debug)]
pub struct DeviceGradients<F> {
    /// `[n]`.
    pub sigma: CudaSlice<F>,
    /// `[n]`.
    pub delta: CudaSlice<F>,
    /// `[n, 3]`.
    pub color: CudaSlice<F>,
    /// `[3]`.
    pub background: CudaSlice<F>,
    /// Per-warp sums of the background gradient, `[warps, 3]`.
    partial: CudaSlice<f64>,
}

/// The forward's outputs on the host.
#[derive(Debug, Clone, PartialEq)]
pub struct HostOutputs<F> {
    /// `[R, 3]`, row-major.
    pub color: Vec<F>,
    /// `[R]`.
    pub opacity: Vec<F>,
}

/// The input gradients on the host.
#[derive(Debug, Clone, PartialEq)]
pub struct HostGradients<F> {
    /// `[n]`.
    pub sigma: Vec<F>,
    /// `[n]`.
    pub delta: Vec<F>,
    /// `[n, 3]`, row-major.
    pub color: Vec<F>,
    /// `[3]`.
    pub background: Vec<F>,
}

/// A batch of packed rays on the host, borrowed: what [`CudaComposite::upload`] and the host
/// calls take.
#[derive(Debug, Clone, Copy)]
pub struct HostRays<'a, F> {
    /// `[R + 1]`: ray `r` owns samples `offsets[r]..offsets[r + 1]`.
    pub offsets: &'a [usize],
    /// Density per sample, `[n]`, finite and non-negative.
    pub sigma: &'a [F],
    /// Length per sample, `[n]`, finite and non-negative.
    pub delta: &'a [F],
    /// Colour per sample, `[n, 3]` row-major, finite.
    pub color: &'a [F],
    /// The background colour shared by every ray, `[3]`, finite.
    pub background: &'a [F],
}

/// What the driver reports of one of the composite's kernels once compiled for the device:
/// what decides how many of its blocks share a multiprocessor.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct KernelInfo {
    /// `forward_f32`, `backward_f64`, `reduce_f32`, ...
    pub name: String,
    /// Registers per thread.
    pub registers: i32,
    /// Local memory (stack) per thread, in bytes: spills show here.
    pub local_bytes: i32,
    /// Static shared memory per block, in bytes.
    pub shared_bytes: i32,
    /// Threads per block it is launched with.
    pub threads_per_block: u32,
    /// Blocks that fit on one multiprocessor at once (the occupancy calculator's answer).
    pub blocks_per_multiprocessor: u32,
}

/// The background gradient's partial sums: one per warp of 32 rays, at least one (zeros) so
/// that the reduction always has something to add.
fn partials(rays: usize) -> usize {
    rays.div_ceil(WARP).max(1)
}

fn config(rays: usize, block: usize) -> LaunchConfig {
    // `check_packing` bounds the warp count, hence the block count, by i32::MAX; at least one
    // block, which writes the (zero) partial sum when there is no ray.
    let blocks = u32::try_from(rays.div_ceil(block).max(1)).unwrap_or(u32::MAX);
    LaunchConfig {
        grid_dim: (blocks, 1, 1),
        block_dim: (block as u32, 1, 1),
        shared_mem_bytes: 0,
    }
}

impl CudaComposite {
    /// Opens device `ordinal` and compiles the kernels for it with NVRTC.
    ///
    /// Errors: [`CudaError::NoDriver`] where no NVIDIA driver is installed (what callers and
    /// tests test for to skip), [`CudaError::NoDevice`], [`CudaError::NoNvrtc`],
    /// [`CudaError::Compile`], [`CudaError::Driver`].
    pub fn new(ordinal: usize) -> Result<Self, CudaError> {
        Self::with_tuning(ordinal, KernelTuning::default())
    }

    /// [`CudaComposite::new`] with the kernels compiled for another staging layout (the
    /// results are the same; see [`KernelTuning`]); [`CudaError::Tuning`] for one not built.
    pub fn with_tuning(ordinal: usize, tuning: KernelTuning) -> Result<Self, CudaError> {
        // cudarc's dynamic loading panics when a library is missing; ask first.
        // SAFETY: only tries to open the library by its usual names.
        if !unsafe { cudarc::driver::sys::is_culib_present() } {
            return Err(CudaError::NoDriver);
        }
        // SAFETY: as above.
        if !unsafe { cudarc::nvrtc::sys::is_culib_present() } {
            return Err(CudaError::NoNvrtc);
        }
        let count = match CudaContext::device_count() {
            Ok(c) => usize::try_from(c).unwrap_or(0),
            // cuInit fails with CUDA_ERROR_NO_DEVICE where a driver is installed but no GPU.
            Err(e) if e.0 == cudarc::driver::sys::CUresult::CUDA_ERROR_NO_DEVICE => 0,
            Err(e) => return Err(e.into()),
        };
        if ordinal >= count {
            return Err(CudaError::NoDevice { ordinal, count });
        }
        let ctx = CudaContext::new(ordinal)?;
        let capability = ctx.compute_capability()?;
        let name = ctx.name()?;
        let ptx = compile_tuned(capability, tuning)?;
        let module = ctx.load_module(ptx)?;
        let stream = ctx.default_stream();
        Ok(CudaComposite {
            f32: Kernels::load(&module, "f32")?,
            f64: Kernels::load(&module, "f64")?,
            ctx,
            stream,
            name,
            capability,
            tuning,
        })
    }

    /// The layout and exponentials the kernels were built with.
    pub fn tuning(&self) -> KernelTuning {
        self.tuning
    }

    /// Threads a block of the forward and backward kernels.
    fn block(&self) -> usize {
        self.tuning.threads_per_block as usize
    }

    /// The device's name, as the driver reports it.
    pub fn device_name(&self) -> &str {
        &self.name
    }

    /// The device's compute capability (major, minor).
    pub fn compute_capability(&self) -> (i32, i32) {
        self.capability
    }

    /// The context, for callers that allocate or time on the same device.
    pub fn context(&self) -> &Arc<CudaContext> {
        &self.ctx
    }

    /// The stream every launch of this object goes to.
    pub fn stream(&self) -> &Arc<CudaStream> {
        &self.stream
    }

    /// What the driver reports of each kernel after compiling the PTX for the device.
    pub fn kernel_info(&self) -> Result<Vec<KernelInfo>, CudaError> {
        let mut info = Vec::new();
        for (suffix, k) in [("f32", &self.f32), ("f64", &self.f64)] {
            for (name, f, block) in [
                ("forward", &k.forward, self.block()),
                ("backward", &k.backward, self.block()),
                ("reduce", &k.reduce, REDUCE_BLOCK),
            ] {
                info.push(KernelInfo {
                    name: format!("{name}_{suffix}"),
                    registers: f.num_regs()?,
                    local_bytes: f.local_size_bytes()?,
                    shared_bytes: f.shared_size_bytes()?,
                    blocks_per_multiprocessor: f.occupancy_max_active_blocks_per_multiprocessor(
                        block as u32,
                        0,
                        None,
                    )?,
                    threads_per_block: block as u32,
                });
            }
        }
        Ok(info)
    }

    fn kernels<F: DeviceFloat>(&self) -> &Kernels {
        if F::SUFFIX == "f32" {
            &self.f32
        } else {
            &self.f64
        }
    }

    /// Checks a host batch (packing, lengths, a finite background) and uploads it.
    pub fn upload<F: DeviceFloat>(&self, x: &HostRays<'_, F>) -> Result<DeviceRays<F>, CudaError> {
        let rays = check_packing(x.offsets, x.sigma.len(), x.color.len(), x.background.len())?;
        check_len("delta", x.sigma.len(), x.delta.len())?;
        if let Some((channel, v)) = x.background.iter().enumerate().find(|(_, v)| !v.to_f64().is_finite()) {
            return Err(CudaError::InvalidBackground {
                channel,
                value: v.to_f64(),
            });
        }
        let offsets: Vec<u64> = x.offsets.iter().map(|&o| o as u64).collect();
        Ok(DeviceRays {
            offsets: put(&self.stream, &offsets)?,
            sigma: put(&self.stream, x.sigma)?,
            delta: put(&self.stream, x.delta)?,
            color: put(&self.stream, x.color)?,
            background: put(&self.stream, x.background)?,
            rays,
            samples: x.sigma.len(),
        })
    }

    /// Output buffers for the forward of `x`.
    pub fn forward_buffers<F: DeviceFloat>(&self, x: &DeviceRays<F>) -> Result<DeviceForward<F>, CudaError> {
        let s = &self.stream;
        Ok(DeviceForward {
            color: s.alloc_zeros((x.rays * CHANNELS).max(1))?,
            opacity: s.alloc_zeros(x.rays.max(1))?,
            chunk_depth: s.alloc_zeros(residual_len(x.rays, x.samples))?,
            invalid: s.alloc_zeros(1)?,
        })
    }

    /// Gradient buffers for the backward of `x`.
    pub fn gradient_buffers<F: DeviceFloat>(&self, x: &DeviceRays<F>) -> Result<DeviceGradients<F>, CudaError> {
        let s = &self.stream;
        // Zero-length device allocations are refused: at least one element each.
        Ok(DeviceGradients {
            sigma: s.alloc_zeros(x.samples.max(1))?,
            delta: s.alloc_zeros(x.samples.max(1))?,
            color: s.alloc_zeros((x.samples * CHANNELS).max(1))?,
            background: s.alloc_zeros(CHANNELS)?,
            partial: s.alloc_zeros(partials(x.rays) * CHANNELS)?,
        })
    }

    /// Uploads the upstream gradients `dL/dC [R, 3]` and optionally `dL/dopacity [R]`.
    pub fn upload_upstream<F: DeviceFloat>(
        &self,
        x: &DeviceRays<F>,
        d_color: &[F],
        d_opacity: Option<&[F]>,
    ) -> Result<DeviceUpstream<F>, CudaError> {
        check_len("dL/dcolor ([R, 3])", x.rays * CHANNELS, d_color.len())?;
        if let Some(g) = d_opacity {
            check_len("dL/dopacity ([R])", x.rays, g.len())?;
        }
        Ok(DeviceUpstream {
            color: put(&self.stream, d_color)?,
            opacity: d_opacity.map(|g| put(&self.stream, g)).transpose()?,
        })
    }

    /// Launches the forward of `x` into `out` (asynchronous: nothing waits for it). The
    /// values are not checked until [`CudaComposite::check_forward`].
    pub fn launch_forward<F: DeviceFloat>(
        &self,
        x: &DeviceRays<F>,
        out: &mut DeviceForward<F>,
    ) -> Result<(), CudaError> {
        check_len("forward colour buffer", (x.rays * CHANNELS).max(1), out.color.len())?;
        check_len("forward opacity buffer", x.rays.max(1), out.opacity.len())?;
        check_len(
            "forward residual",
            residual_len(x.rays, x.samples),
            out.chunk_depth.len(),
        )?;
        if x.rays == 0 {
            return Ok(());
        }
        self.stream.memset_zeros(&mut out.invalid)?;
        let rays = x.rays as u64;
        let mut launch = self.stream.launch_builder(&self.kernels::<F>().forward);
        launch
            .arg(&x.offsets)
            .arg(&rays)
            .arg(&x.sigma)
            .arg(&x.delta)
            .arg(&x.color)
            .arg(&x.background)
            .arg(&mut out.color)
            .arg(&mut out.opacity)
            .arg(&mut out.chunk_depth)
            .arg(&mut out.invalid);
        // SAFETY: the arguments are the kernel's, in its order and of its types; every buffer
        // has the length the kernel indexes (checked above and when the buffers were made);
        // `rays` threads do the work, the rest of the last block returns at once.
        unsafe { launch.launch(config(x.rays, self.block())) }?;
        Ok(())
    }

    /// Waits for the forward and reports an invalid sample value, if the kernel saw one.
    pub fn check_forward<F: DeviceFloat>(&self, out: &DeviceForward<F>) -> Result<(), CudaError> {
        let flag = self.stream.clone_dtoh(&out.invalid)?;
        if flag.first().copied().unwrap_or(0) != 0 {
            return Err(CudaError::InvalidSample);
        }
        Ok(())
    }

    /// Launches the backward of `x` (asynchronous) into `grads`, from the forward's residual
    /// `fwd` and the upstream gradients `up`: every value of `grads` is overwritten.
    pub fn launch_backward<F: DeviceFloat>(
        &self,
        x: &DeviceRays<F>,
        fwd: &DeviceForward<F>,
        up: &DeviceUpstream<F>,
        grads: &mut DeviceGradients<F>,
    ) -> Result<(), CudaError> {
        check_len(
            "forward residual",
            residual_len(x.rays, x.samples),
            fwd.chunk_depth.len(),
        )?;
        check_len("sigma gradient", x.samples.max(1), grads.sigma.len())?;
        check_len("delta gradient", x.samples.max(1), grads.delta.len())?;
        check_len("colour gradient", (x.samples * CHANNELS).max(1), grads.color.len())?;
        check_len(
            "background partial sums",
            partials(x.rays) * CHANNELS,
            grads.partial.len(),
        )?;
        check_len("dL/dcolor ([R, 3])", (x.rays * CHANNELS).max(1), up.color.len())?;
        let k = self.kernels::<F>();
        let rays = x.rays as u64;
        let partials = partials(x.rays) as u64;
        let has_opacity = i32::from(up.opacity.is_some());
        // The kernel reads dL/dopacity only when told it is there; any buffer stands in.
        let d_opacity = up.opacity.as_ref().unwrap_or(&up.color);
        let mut launch = self.stream.launch_builder(&k.backward);
        launch
            .arg(&x.offsets)
            .arg(&rays)
            .arg(&x.sigma)
            .arg(&x.delta)
            .arg(&x.color)
            .arg(&x.background)
            .arg(&up.color)
            .arg(d_opacity)
            .arg(&has_opacity)
            .arg(&fwd.chunk_depth)
            .arg(&mut grads.sigma)
            .arg(&mut grads.delta)
            .arg(&mut grads.color)
            .arg(&mut grads.partial)
            .arg(&partials);
        // SAFETY: as in `launch_forward`: the kernel's arguments and types, every buffer
        // checked against the lengths it indexes; a warp past `partials` writes nothing, one
        // past `rays` (only when there is no ray) writes its zero partial sum.
        unsafe { launch.launch(config(x.rays, self.block())) }?;
        let mut reduce = self.stream.launch_builder(&k.reduce);
        reduce.arg(&grads.partial).arg(&partials).arg(&mut grads.background);
        // SAFETY: one block of the kernel's REDUCE_BLOCK threads reads `partials * 3` partial
        // sums (the buffer's length, checked above) and writes 3 values.
        unsafe {
            reduce.launch(LaunchConfig {
                grid_dim: (1, 1, 1),
                block_dim: (REDUCE_BLOCK as u32, 1, 1),
                shared_mem_bytes: 0,
            })
        }?;
        Ok(())
    }

    /// The forward on host data: colour `[R, 3]` and opacity `[R]`.
    pub fn evaluate<F: DeviceFloat>(&self, x: &HostRays<'_, F>) -> Result<HostOutputs<F>, CudaError> {
        let d = self.upload(x)?;
        let mut fwd = self.forward_buffers(&d)?;
        self.launch_forward(&d, &mut fwd)?;
        self.check_forward(&fwd)?;
        self.download_outputs(&d, &fwd)
    }

    /// The forward and the backward on host data, given `dL/dC [R, 3]` and optionally
    /// `dL/dopacity [R]`: the outputs and the gradients of sigma, delta, colour and the
    /// background.
    pub fn evaluate_vjp<F: DeviceFloat>(
        &self,
        x: &HostRays<'_, F>,
        d_color: &[F],
        d_opacity: Option<&[F]>,
    ) -> Result<(HostOutputs<F>, HostGradients<F>), CudaError> {
        let d = self.upload(x)?;
        let up = self.upload_upstream(&d, d_color, d_opacity)?;
        let mut fwd = self.forward_buffers(&d)?;
        self.launch_forward(&d, &mut fwd)?;
        self.check_forward(&fwd)?;
        let mut grads = self.gradient_buffers(&d)?;
        self.launch_backward(&d, &fwd, &up, &mut grads)?;
        let outputs = self.download_outputs(&d, &fwd)?;
        let s = &self.stream;
        let (n, c) = (d.samples, d.samples * CHANNELS);
        let mut sigma = s.clone_dtoh(&grads.sigma)?;
        let mut delta = s.clone_dtoh(&grads.delta)?;
        let mut color = s.clone_dtoh(&grads.color)?;
        // Drop the stand-in element of an empty batch.
        sigma.truncate(n);
        delta.truncate(n);
        color.truncate(c);
        Ok((
            outputs,
            HostGradients {
                sigma,
                delta,
                color,
                background: s.clone_dtoh(&grads.background)?,
            },
        ))
    }

    /// Copies the forward's outputs to the host (waits for the stream).
    pub fn download_outputs<F: DeviceFloat>(
        &self,
        x: &DeviceRays<F>,
        fwd: &DeviceForward<F>,
    ) -> Result<HostOutputs<F>, CudaError> {
        if x.rays == 0 {
            return Ok(HostOutputs {
                color: Vec::new(),
                opacity: Vec::new(),
            });
        }
        Ok(HostOutputs {
            color: self.stream.clone_dtoh(&fwd.color)?,
            opacity: self.stream.clone_dtoh(&fwd.opacity)?,
        })
    }
}
