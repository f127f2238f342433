//! A whole training step of a dense grid radiance field on the device: rays in, loss and
//! updated grid out. The model is the dense grid of `fogray-fit` without its extras: `4`
//! channels a node (density, then RGB), density `softplus(raw + shift)`, colour
//! `sigmoid(raw)` from every direction alike, a fixed number of samples a ray spread evenly
//! between where it enters and leaves the box (at a random offset each step), the composite
//! over one background, the mean squared error, and Adam with bias-corrected moments.
//!
//! Every op of the step is a kernel of this crate checked against the CPU op
//! ([`CudaGrid`], [`CudaDensityColor`], [`CudaComposite`]); the step's own kernels
//! (`kernels/train.cu`) draw the batch, take the loss and update the grid.

use cudarc::driver::{CudaFunction, CudaSlice, DeviceRepr, PushKernelArg};

use crate::activation::CudaDensityColor;
use crate::buffers::launch_config;
use crate::composite::{CudaComposite, DeviceForward, DeviceGradients, DeviceRays, DeviceUpstream, HostRays};
use crate::error::CudaError;
use crate::grid::{CudaGrid, GridSpec};
use crate::kernel::compile_train;

/// The box as the sampling kernels take it.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
struct DeviceBox {
    min: [f64; 3],
    max: [f64; 3],
}

// SAFETY: a plain `#[repr(C)]` struct of f64, laid out as the kernels' `Box`.
unsafe impl DeviceRepr for DeviceBox {}

/// How a [`DenseGridTrainer`] fits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrainerSettings {
    /// The box the grid spans: (min, max corners).
    pub scene_box: ([f64; 3], [f64; 3]),
    /// Nodes per axis of the grid.
    pub nodes: usize,
    /// Samples per ray, spread evenly over its chord through the box.
    pub samples_per_ray: usize,
    /// Rays per step.
    pub batch: usize,
    /// The density's shift: raw 0 is density `softplus(shift)`.
    pub shift: f64,
    /// The background colour behind every ray.
    pub background: [f32; 3],
    /// Seed of the batches.
    pub seed: u64,
}

struct TrainKernels {
    sample_batch: CudaFunction,
    sample_range: CudaFunction,
    squared_error: CudaFunction,
    adam: CudaFunction,
}

/// The device state of a dense grid fit: the training rays, the grid and its Adam moments,
/// and one batch's buffers.
pub struct DenseGridTrainer<'g> {
    gpu: &'g CudaComposite,
    settings: TrainerSettings,
    grid: CudaGrid,
    activation: CudaDensityColor,
    kernels: TrainKernels,
    scene: DeviceBox,
    rays: usize,
    origins: CudaSlice<f32>,
    directions: CudaSlice<f32>,
    targets: CudaSlice<f32>,
    params: CudaSlice<f32>,
    grad: CudaSlice<f32>,
    acc: CudaSlice<f64>,
    m: CudaSlice<f32>,
    v: CudaSlice<f32>,
    positions: CudaSlice<f32>,
    raw: CudaSlice<f32>,
    d_raw: CudaSlice<f32>,
    picked: CudaSlice<u64>,
    batch_rays: DeviceRays<f32>,
    forward: DeviceForward<f32>,
    upstream: DeviceUpstream<f32>,
    gradients: DeviceGradients<f32>,
    invalid: CudaSlice<u32>,
    sse: CudaSlice<f64>,
    steps: u64,
}

impl std::fmt::Debug for DenseGridTrainer<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DenseGridTrainer")
            .field("settings", &self.settings)
            .field("rays", &self.rays)
            .field("steps", &self.steps)
            .finish()
    }
}

/// Values a node of the trained grid holds: density, then RGB.
const NODE_CHANNELS: usize = 4;

impl<'g> DenseGridTrainer<'g> {
    /// Uploads the training rays (`origins`, unit `directions` and `targets`, each `[R, 3]`)
    /// and a fresh grid (raw 0: density `softplus(shift)`, colour grey).
    ///
    /// Errors: shapes, an empty ray set, a batch or sample count of 0
    /// ([`CudaError::InvalidSettings`]), a bad grid ([`CudaError::InvalidGrid`]), and the
    /// device's.
    pub fn new(
        gpu: &'g CudaComposite,
        settings: TrainerSettings,
        origins: &[f32],
        directions: &[f32],
        targets: &[f32],
    ) -> Result<Self, CudaError> {
        let rays = origins.len() / 3;
        if rays == 0 || origins.len() != 3 * rays {
            return Err(CudaError::Shape {
                what: "ray origins ([R, 3], R >= 1)",
                expected: 3 * rays.max(1),
                got: origins.len(),
            });
        }
        for (what, v) in [("ray directions ([R, 3])", directions), ("targets ([R, 3])", targets)] {
            if v.len() != 3 * rays {
                return Err(CudaError::Shape {
                    what,
                    expected: 3 * rays,
                    got: v.len(),
                });
            }
        }
        if settings.batch == 0 || settings.samples_per_ray == 0 {
            return Err(CudaError::InvalidSettings(format!(
                "{} rays a step and {} samples a ray (each at least 1)",
                settings.batch, settings.samples_per_ray
            )));
        }
        let spec = GridSpec {
            min: settings.scene_box.0,
            max: settings.scene_box.1,
            nodes: [settings.nodes; 3],
            channels: NODE_CHANNELS,
        };
        let grid = CudaGrid::new(gpu, spec)?;
        let activation = CudaDensityColor::new(gpu, settings.shift)?;
        let module = gpu.context().load_module(compile_train(gpu.compute_capability())?)?;
        let kernels = TrainKernels {
            sample_batch: module.load_function("sample_batch")?,
            sample_range: module.load_function("sample_range")?,
            squared_error: module.load_function("squared_error")?,
            adam: module.load_function("adam")?,
        };
        let s = gpu.stream();
        let values = spec.values();
        let n = settings.batch * settings.samples_per_ray;
        let offsets: Vec<usize> = (0..=settings.batch).map(|b| b * settings.samples_per_ray).collect();
        let zeros = vec![0.0f32; 3 * n];
        let batch_rays = gpu.upload(&HostRays {
            offsets: &offsets,
            sigma: &zeros[..n],
            delta: &zeros[..n],
            color: &zeros,
            background: &settings.background,
        })?;
        let forward = gpu.forward_buffers(&batch_rays)?;
        let upstream = gpu.upload_upstream(&batch_rays, &zeros[..3 * settings.batch], None)?;
        let gradients = gpu.gradient_buffers(&batch_rays)?;
        Ok(DenseGridTrainer {
            gpu,
            settings,
            grid,
            activation,
            kernels,
            scene: DeviceBox {
                min: settings.scene_box.0,
                max: settings.scene_box.1,
            },
            rays,
            origins: s.clone_htod(origins)?,
            directions: s.clone_htod(directions)?,
            targets: s.clone_htod(targets)?,
            params: s.alloc_zeros(values)?,
            grad: s.alloc_zeros(values)?,
            acc: s.alloc_zeros(values)?,
            m: s.alloc_zeros(values)?,
            v: s.alloc_zeros(values)?,
            positions: s.alloc_zeros(3 * n)?,
            raw: s.alloc_zeros(NODE_CHANNELS * n)?,
            d_raw: s.alloc_zeros(NODE_CHANNELS * n)?,
            picked: s.alloc_zeros(settings.batch)?,
            batch_rays,
            forward,
            upstream,
            gradients,
            invalid: s.alloc_zeros(1)?,
            sse: s.alloc_zeros(1)?,
            steps: 0,
        })
    }

    /// Steps taken.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Looks up, activates and composites the batch whose positions and step lengths are in
    /// place.
    fn render_batch(&mut self) -> Result<(), CudaError> {
        let n = self.settings.batch * self.settings.samples_per_ray;
        self.grid
            .launch_lookup(&self.params, &self.positions, n, &mut self.raw, &mut self.invalid)?;
        let (sigma, _, color) = self.batch_rays.samples_mut();
        self.activation
            .launch_forward(&self.raw, n, NODE_CHANNELS, sigma, color, &mut self.invalid)?;
        self.gpu.launch_forward(&self.batch_rays, &mut self.forward)
    }

    /// One training step at learning rate `lr` (queued on the stream; nothing waits). The
    /// batch's squared error is added to what [`DenseGridTrainer::take_mean_squared_error`]
    /// reads.
    pub fn step(&mut self, lr: f64) -> Result<(), CudaError> {
        let st = self.settings;
        let (batch, samples) = (st.batch as u64, st.samples_per_ray as u64);
        let (rays, seed, step) = (self.rays as u64, st.seed, self.steps);
        {
            let (_, delta, _) = self.batch_rays.samples_mut();
            let mut launch = self.gpu.stream().launch_builder(&self.kernels.sample_batch);
            launch
                .arg(&self.origins)
                .arg(&self.directions)
                .arg(&rays)
                .arg(&batch)
                .arg(&samples)
                .arg(&seed)
                .arg(&step)
                .arg(&self.scene)
                .arg(&mut self.positions)
                .arg(delta)
                .arg(&mut self.picked);
            // SAFETY: the kernel's arguments in its order and types; `rays` rays in the ray
            // buffers, `batch * samples` samples in the batch buffers, `batch` picks.
            unsafe { launch.launch(launch_config(st.batch)) }?;
        }
        self.render_batch()?;
        {
            let mut launch = self.gpu.stream().launch_builder(&self.kernels.squared_error);
            launch
                .arg(&self.forward.color)
                .arg(&self.targets)
                .arg(&self.picked)
                .arg(&batch)
                .arg(self.upstream.color_mut())
                .arg(&mut self.sse);
            // SAFETY: `batch` rays' colours and gradients, picks below `rays`.
            unsafe { launch.launch(launch_config(st.batch)) }?;
        }
        self.gpu
            .launch_backward(&self.batch_rays, &self.forward, &self.upstream, &mut self.gradients)?;
        let n = st.batch * st.samples_per_ray;
        self.activation.launch_backward(
            &self.raw,
            n,
            NODE_CHANNELS,
            Some(&self.gradients.sigma),
            Some(&self.gradients.color),
            &mut self.d_raw,
        )?;
        self.grid.launch_backward(
            &self.params,
            &self.positions,
            &self.d_raw,
            n,
            &mut self.acc,
            &mut self.grad,
            None,
        )?;
        self.steps += 1;
        let t = self.steps as i32;
        let (beta1, beta2, eps) = (0.9f64, 0.999f64, 1e-8f64);
        let (c1, c2) = (1.0 - beta1.powi(t), 1.0 - beta2.powi(t));
        let values = self.params.len();
        let len = values as u64;
        let mut launch = self.gpu.stream().launch_builder(&self.kernels.adam);
        launch
            .arg(&mut self.params)
            .arg(&self.grad)
            .arg(&mut self.m)
            .arg(&mut self.v)
            .arg(&len)
            .arg(&lr)
            .arg(&beta1)
            .arg(&beta2)
            .arg(&eps)
            .arg(&c1)
            .arg(&c2);
        // SAFETY: four buffers of the grid's `values` values.
        unsafe { launch.launch(launch_config(values)) }?;
        Ok(())
    }

    /// Waits for the steps queued.
    pub fn wait(&self) -> Result<(), CudaError> {
        Ok(self.gpu.stream().synchronize()?)
    }

    /// Waits for the steps queued, and returns the mean squared error per channel over the
    /// batches since the last call (0 if none), or [`CudaError::InvalidSample`] if a value
    /// went NaN.
    pub fn take_mean_squared_error(&mut self, steps: u64) -> Result<f64, CudaError> {
        let s = self.gpu.stream();
        let sse = s.clone_dtoh(&self.sse)?[0];
        let invalid = s.clone_dtoh(&self.invalid)?[0];
        s.memset_zeros(&mut self.sse)?;
        if invalid != 0 {
            return Err(CudaError::InvalidSample);
        }
        let values = (steps as f64) * 3.0 * self.settings.batch as f64;
        Ok(if values > 0.0 { sse / values } else { 0.0 })
    }

    /// Renders rays (`origins`, unit `directions`, `[R, 3]`) with samples at the centres of
    /// their steps: colours `[R, 3]`.
    pub fn render(&mut self, origins: &[f32], directions: &[f32]) -> Result<Vec<f32>, CudaError> {
        let rays = origins.len() / 3;
        if origins.len() != 3 * rays || directions.len() != origins.len() {
            return Err(CudaError::Shape {
                what: "rays to render (origins and directions [R, 3])",
                expected: origins.len() / 3 * 3,
                got: directions.len(),
            });
        }
        let s = self.gpu.stream().clone();
        let (o, d) = (s.clone_htod(origins)?, s.clone_htod(directions)?);
        let st = self.settings;
        let mut colors = Vec::with_capacity(3 * rays);
        let mut first = 0;
        while first < rays {
            let count = st.batch.min(rays - first);
            let (first64, count64, samples) = (first as u64, count as u64, st.samples_per_ray as u64);
            {
                let (_, delta, _) = self.batch_rays.samples_mut();
                // The batch's rays past `count` keep step length 0: they add nothing.
                s.memset_zeros(delta)?;
                let mut launch = s.launch_builder(&self.kernels.sample_range);
                launch
                    .arg(&o)
                    .arg(&d)
                    .arg(&first64)
                    .arg(&count64)
                    .arg(&samples)
                    .arg(&self.scene)
                    .arg(&mut self.positions)
                    .arg(delta);
                // SAFETY: rays first..first + count exist; the batch buffers hold `batch >=
                // count` rays of samples.
                unsafe { launch.launch(launch_config(count)) }?;
            }
            self.render_batch()?;
            let out = s.clone_dtoh(&self.forward.color)?;
            colors.extend_from_slice(&out[..3 * count]);
            first += count;
        }
        if s.clone_dtoh(&self.invalid)?[0] != 0 {
            return Err(CudaError::InvalidSample);
        }
        Ok(colors)
    }

    /// The grid's raw values, `[nodes, nodes, nodes, 4]` row-major (density, then RGB).
    pub fn grid_values(&self) -> Result<Vec<f32>, CudaError> {
        Ok(self.gpu.stream().clone_dtoh(&self.params)?)
    }

    /// Replaces the grid's raw values (as [`DenseGridTrainer::grid_values`] gives them; Adam's
    /// moments are kept). Errors: a length other than the grid's; the grid is unchanged then.
    pub fn set_grid_values(&mut self, values: &[f32]) -> Result<(), CudaError> {
        if values.len() != self.params.len() {
            return Err(CudaError::Shape {
                what: "grid values ([nodes, nodes, nodes, 4])",
                expected: self.params.len(),
                got: values.len(),
            });
        }
        Ok(self.gpu.stream().memcpy_htod(values, &mut self.params)?)
    }

    /// The gradient of the last step's loss with respect to the grid's raw values (before
    /// Adam used it), for checks against the CPU ops.
    pub fn last_gradient(&self) -> Result<Vec<f32>, CudaError> {
        Ok(self.gpu.stream().clone_dtoh(&self.grad)?)
    }
}
