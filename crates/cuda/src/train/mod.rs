//! A whole training step of a dense grid radiance field on the device: rays in, loss and
//! updated grid out, with the model class of `fogray fit` (see `docs/cuda.md`): density
//! `softplus(raw + shift)`, colour `sigmoid(raw)` from every direction alike or through
//! spherical harmonics ([`TrainerSettings::sh_degree`]); a fixed number of samples a ray
//! spread evenly between where it enters and leaves the box (at a random offset each step),
//! those in empty cells of an occupancy grid dropped ([`TrainerSettings::occupancy`]) and the
//! rest packed ray by ray; the composite over the dataset's background or, for pictures with
//! alpha, over a random colour per ray ([`TrainerSettings::random_background`]); the mean
//! squared error plus the distortion loss ([`TrainerSettings::distortion`]); Adam with
//! bias-corrected moments on the entries the batch reached. [`DenseGridTrainer::resample`]
//! grows the grid coarse to fine.
//!
//! Every op of the step is a kernel of this crate checked against the CPU op
//! ([`CudaGrid`], [`CudaDensityColor`], [`CudaShDensityColor`], [`CudaComposite`]); the step's
//! own kernels (`kernels/train.cu`) draw and pack the batch, take the losses, refresh the
//! occupancy grid and update the grid, and are checked against the same step through the CPU
//! ops (`tests/integration/train.rs`).

mod device;
mod host;
mod phases;
mod settings;
mod step;

use cudarc::driver::{CudaSlice, PushKernelArg};

use crate::activation::CudaDensityColor;
use crate::buffers::{launch_config, put};
use crate::composite::{CudaComposite, DeviceForward, DeviceGradients, DeviceRays, DeviceUpstream, HostRays};
use crate::error::CudaError;
use crate::grid::{CudaGrid, GridSpec};
use crate::kernel::compile_train;
use crate::sh::CudaShDensityColor;
use device::{DeviceBox, DeviceCells, GridState, OccupancyState, Shading, Staging, TrainKernels};
use settings::check;

pub use phases::StepPhases;
pub use settings::{OccupancySettings, TrainerSettings, TrainingRays};

/// The device state of a dense grid fit: the training rays, the grid and its Adam moments,
/// and one batch's buffers.
pub struct DenseGridTrainer<'g> {
    gpu: &'g CudaComposite,
    settings: TrainerSettings,
    state: GridState,
    shading: Shading,
    kernels: TrainKernels,
    scene: DeviceBox,
    rays: usize,
    origins: CudaSlice<f32>,
    directions: CudaSlice<f32>,
    targets: CudaSlice<f32>,
    /// The targets' opacities (one zero where there are none).
    alpha: CudaSlice<f32>,
    /// Whether the loss draws a random background per ray.
    random: bool,
    staging: Staging,
    /// The samples kept this batch (of nonzero length), packed ray by ray: the first `kept`
    /// values of `positions`, the batch's `delta`, `ts` and `sample_dirs`.
    kept: usize,
    positions: CudaSlice<f32>,
    /// Each sample's view direction `[n, 3]` (with spherical harmonics; else one zero).
    sample_dirs: CudaSlice<f32>,
    /// Each sample's midpoint along its ray `[n]`.
    ts: CudaSlice<f32>,
    /// The distortion loss's weights, prefix sums and optical depths `[n]` each (with the
    /// loss; else one zero each), and the sum of its values since it was last read.
    distortion_scratch: [CudaSlice<f64>; 3],
    distortion_sum: CudaSlice<f64>,
    /// The cells the sampling kernels skip the empty ones of (0 cells: no occupancy grid,
    /// every sample kept).
    cells: DeviceCells,
    /// One byte a cell, nonzero where occupied (one unread byte without an occupancy grid).
    occupied: CudaSlice<u8>,
    occupancy: Option<OccupancyState>,
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
    /// Whether Adam keeps each step's gradient in `state.grad` for `last_gradient`.
    record_gradients: bool,
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

/// Values a node holds without spherical harmonics: density, then RGB.
const VIEW_INDEPENDENT_CHANNELS: usize = 4;

impl<'g> DenseGridTrainer<'g> {
    /// Uploads the training rays and a fresh grid (raw 0: density `softplus(shift)`, colour
    /// grey).
    ///
    /// Errors: shapes, an empty ray set ([`CudaError::Shape`]); a batch or sample count of 0,
    /// a degree above 3 ([`CudaError::InvalidSettings`]); a bad grid
    /// ([`CudaError::InvalidGrid`]); a background colour that is not finite
    /// ([`CudaError::InvalidBackground`]); and the device's.
    pub fn new(gpu: &'g CudaComposite, settings: TrainerSettings, data: TrainingRays<'_>) -> Result<Self, CudaError> {
        let rays = check(&settings, &data)?;
        let shading = match settings.sh_degree {
            0 => Shading::Plain(CudaDensityColor::new(gpu, settings.shift)?),
            d => Shading::Harmonics(CudaShDensityColor::new(gpu, settings.shift, d)?),
        };
        let spec = GridSpec {
            min: settings.scene_box.0,
            max: settings.scene_box.1,
            nodes: [settings.nodes; 3],
            channels: shading.channels(),
        };
        let grid = CudaGrid::new(gpu, spec)?;
        let module = gpu.context().load_module(compile_train(gpu.compute_capability())?)?;
        let kernels = TrainKernels {
            sample_batch: module.load_function("sample_batch")?,
            sample_range: module.load_function("sample_range")?,
            photometric_loss: module.load_function("photometric_loss")?,
            lattice: module.load_function("lattice")?,
            occupancy_points: module.load_function("occupancy_points")?,
            occupancy_update: module.load_function("occupancy_update")?,
            distortion: module.load_function("distortion")?,
            count_kept: module.load_function("count_kept")?,
            scan_offsets: module.load_function("scan_offsets")?,
            compact: module.load_function("compact")?,
            adam: module.load_function("adam")?,
        };
        let s = gpu.stream();
        let n = settings.batch * settings.samples_per_ray;
        let offsets: Vec<usize> = (0..=settings.batch).map(|b| b * settings.samples_per_ray).collect();
        let zeros = vec![0.0f32; 3 * n];
        // The batch is composited over black; the loss and the render add the background.
        let batch_rays = gpu.upload(&HostRays {
            offsets: &offsets,
            sigma: &zeros[..n],
            delta: &zeros[..n],
            color: &zeros,
            background: &[0.0; 3],
        })?;
        let forward = gpu.forward_buffers(&batch_rays)?;
        let upstream = gpu.upload_upstream(
            &batch_rays,
            &zeros[..3 * settings.batch],
            Some(&zeros[..settings.batch]),
        )?;
        let gradients = gpu.gradient_buffers(&batch_rays)?;
        let channels = shading.channels();
        let with_dirs = matches!(shading, Shading::Harmonics(_));
        let per_axis = settings.occupancy.map_or(0, |o| o.cells);
        let (lo, hi) = settings.scene_box;
        let cells = DeviceCells {
            min: lo,
            scale: std::array::from_fn(|a| per_axis as f64 / (hi[a] - lo[a])),
            cells: per_axis as u64,
        };
        // Every cell occupied until the first refresh.
        let occupied = s.clone_htod(&vec![1u8; per_axis.pow(3).max(1)])?;
        let occupancy = match settings.occupancy {
            None => None,
            Some(o) => {
                let count = o.cells.pow(3);
                Some(OccupancyState {
                    settings: o,
                    estimate: s.alloc_zeros(count)?,
                    points: s.alloc_zeros(6 * count)?,
                    raw: s.alloc_zeros(2 * count * channels)?,
                    refreshes: 0,
                })
            }
        };
        Ok(DenseGridTrainer {
            gpu,
            settings,
            state: GridState::zeros(s, grid)?,
            shading,
            kernels,
            scene: DeviceBox {
                min: settings.scene_box.0,
                max: settings.scene_box.1,
            },
            rays,
            origins: s.clone_htod(data.origins)?,
            directions: s.clone_htod(data.directions)?,
            targets: s.clone_htod(data.colors)?,
            alpha: put(s, data.alpha.unwrap_or(&[]))?,
            random: settings.random_background && data.alpha.is_some(),
            staging: Staging {
                positions: s.alloc_zeros(3 * n)?,
                delta: s.alloc_zeros(n)?,
                ts: s.alloc_zeros(n)?,
                dirs: s.alloc_zeros(if with_dirs { 3 * n } else { 1 })?,
                counts: s.alloc_zeros(settings.batch)?,
            },
            kept: 0,
            positions: s.alloc_zeros(3 * n)?,
            sample_dirs: s.alloc_zeros(if with_dirs { 3 * n } else { 1 })?,
            ts: s.alloc_zeros(n)?,
            distortion_scratch: {
                let len = if settings.distortion > 0.0 { n } else { 1 };
                [s.alloc_zeros(len)?, s.alloc_zeros(len)?, s.alloc_zeros(len)?]
            },
            distortion_sum: s.alloc_zeros(1)?,
            cells,
            occupied,
            occupancy,
            raw: s.alloc_zeros(channels * n)?,
            d_raw: s.alloc_zeros(channels * n)?,
            picked: s.alloc_zeros(settings.batch)?,
            batch_rays,
            forward,
            upstream,
            gradients,
            invalid: s.alloc_zeros(1)?,
            sse: s.alloc_zeros(1)?,
            steps: 0,
            record_gradients: false,
        })
    }

    /// Steps taken.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Nodes per axis of the grid now.
    pub fn nodes(&self) -> usize {
        self.state.grid.spec().nodes[0]
    }

    /// Values a node holds: density, then 3 colour values or `3 (degree + 1)^2`
    /// spherical-harmonics coefficients.
    pub fn channels(&self) -> usize {
        self.shading.channels()
    }

    /// The occupancy grid's cells (`[cells, cells, cells]` row-major, 1 where occupied), if
    /// there is one.
    pub fn occupancy(&self) -> Result<Option<Vec<u8>>, CudaError> {
        match &self.occupancy {
            Some(_) => Ok(Some(self.gpu.stream().clone_dtoh(&self.occupied)?)),
            None => Ok(None),
        }
    }

    /// Whether the sampling kernels write each sample's direction (for spherical harmonics).
    fn with_dirs(&self) -> u64 {
        u64::from(matches!(self.shading, Shading::Harmonics(_)))
    }

    /// Grows (or shrinks) the grid to `nodes` per axis over the same box: each new node takes
    /// the current field's trilinear value at its position (the lookup kernel at the nodes of
    /// the new lattice), and Adam starts afresh, as `fogray fit`'s coarse-to-fine growth does.
    ///
    /// Errors: [`CudaError::InvalidGrid`] for fewer than 2 nodes (the trainer is unchanged
    /// then), and the device's.
    pub fn resample(&mut self, nodes: usize) -> Result<(), CudaError> {
        let spec = GridSpec {
            nodes: [nodes; 3],
            ..*self.state.grid.spec()
        };
        let grid = self.state.grid.for_spec(spec)?;
        let s = self.gpu.stream().clone();
        let mut next = GridState::zeros(&s, grid)?;
        let count = nodes.pow(3);
        let mut at = s.alloc_zeros::<f32>(3 * count)?;
        let nodes64 = nodes as u64;
        let mut launch = s.launch_builder(&self.kernels.lattice);
        launch.arg(&self.scene).arg(&nodes64).arg(&mut at);
        // SAFETY: `at` holds `nodes^3` positions.
        unsafe { launch.launch(launch_config(count)) }?;
        let old = &self.state;
        old.grid
            .launch_lookup(&old.params, &at, count, &mut next.params, &mut self.invalid)?;
        self.state = next;
        Ok(())
    }

    /// Waits for the steps queued.
    pub fn wait(&self) -> Result<(), CudaError> {
        Ok(self.gpu.stream().synchronize()?)
    }
}
