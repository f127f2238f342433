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

use cudarc::driver::{CudaFunction, CudaSlice, DeviceRepr, LaunchConfig, PushKernelArg};

use crate::activation::CudaDensityColor;
use crate::buffers::{check_len, launch_config, put};
use crate::composite::{CudaComposite, DeviceForward, DeviceGradients, DeviceRays, DeviceUpstream, HostRays};
use crate::error::CudaError;
use crate::grid::{CudaGrid, GridSpec};
use crate::kernel::compile_train;
use crate::sh::{CudaShDensityColor, MAX_SH_DEGREE};

/// The box as the sampling kernels take it.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
struct DeviceBox {
    min: [f64; 3],
    max: [f64; 3],
}

// SAFETY: a plain `#[repr(C)]` struct of f64, laid out as the kernels' `Box`.
unsafe impl DeviceRepr for DeviceBox {}

/// A colour as the loss kernel takes it (`Rgb`).
#[repr(C)]
#[derive(Debug, Clone, Copy)]
struct DeviceRgb([f64; 3]);

// SAFETY: a plain `#[repr(C)]` array of f64, laid out as the kernels' `Rgb`.
unsafe impl DeviceRepr for DeviceRgb {}

/// The occupancy grid's cells as the sampling kernels take them (`Cells`).
#[repr(C)]
#[derive(Debug, Clone, Copy)]
struct DeviceCells {
    min: [f64; 3],
    scale: [f64; 3],
    cells: u64,
}

// SAFETY: a plain `#[repr(C)]` struct of 8-byte numbers, laid out as the kernels' `Cells`.
unsafe impl DeviceRepr for DeviceCells {}

/// An occupancy grid over the box that the samples skip where it is empty, as `fogray fit`'s:
/// each cell keeps a density estimate, `max(estimate * decay, fresh)` at every refresh, where
/// `fresh` is the larger density at the cell's centre and at a random point in it; a cell is
/// occupied while its estimate exceeds `density`. Every cell is occupied until the first
/// refresh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OccupancySettings {
    /// Cells per axis.
    pub cells: usize,
    /// The density above which a cell is occupied.
    pub density: f64,
    /// Refresh every this many steps (the first after as many).
    pub every: u64,
    /// The estimate's decay per refresh, in [0, 1].
    pub decay: f64,
}

/// Where a step's time goes, in seconds, as [`DenseGridTrainer::step_timed`] measures it (the
/// stream waited on after each phase, so that each phase's kernels are timed alone).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StepPhases {
    /// The occupancy grid's refresh (0 on the steps without one).
    pub occupancy: f64,
    /// Drawing the batch and placing its samples.
    pub sampling: f64,
    /// The grid's lookup at the samples.
    pub lookup: f64,
    /// Density and colour from the raw values.
    pub shading: f64,
    /// The composite.
    pub composite: f64,
    /// The loss and its gradient.
    pub loss: f64,
    /// The composite's backward.
    pub composite_backward: f64,
    /// The distortion loss and its gradient (0 without it).
    pub distortion: f64,
    /// The shading's backward.
    pub shading_backward: f64,
    /// The grid's backward: the scatter of the samples' gradients into the grid's f64 sums.
    pub grid_backward: f64,
    /// Adam over the grid (it also rounds the sums and zeroes them).
    pub adam: f64,
}

impl StepPhases {
    /// The step's whole time.
    pub fn total(&self) -> f64 {
        self.occupancy
            + self.sampling
            + self.lookup
            + self.shading
            + self.composite
            + self.loss
            + self.composite_backward
            + self.distortion
            + self.shading_backward
            + self.grid_backward
            + self.adam
    }
}

impl std::ops::AddAssign for StepPhases {
    fn add_assign(&mut self, o: StepPhases) {
        self.occupancy += o.occupancy;
        self.sampling += o.sampling;
        self.lookup += o.lookup;
        self.shading += o.shading;
        self.composite += o.composite;
        self.loss += o.loss;
        self.composite_backward += o.composite_backward;
        self.distortion += o.distortion;
        self.shading_backward += o.shading_backward;
        self.grid_backward += o.grid_backward;
        self.adam += o.adam;
    }
}

/// Times the phases of a step when on: waits for the stream at each lap.
struct PhaseClock {
    on: bool,
    at: std::time::Instant,
    phases: StepPhases,
}

impl PhaseClock {
    fn new(on: bool) -> Self {
        PhaseClock {
            on,
            at: std::time::Instant::now(),
            phases: StepPhases::default(),
        }
    }

    /// Adds the time since the last lap to the phase `slot` picks.
    fn lap(&mut self, gpu: &CudaComposite, slot: fn(&mut StepPhases) -> &mut f64) -> Result<(), CudaError> {
        if self.on {
            gpu.stream().synchronize()?;
            let now = std::time::Instant::now();
            *slot(&mut self.phases) += (now - self.at).as_secs_f64();
            self.at = now;
        }
        Ok(())
    }
}

/// The training pixels, each `[R, ...]` in the same order.
#[derive(Debug, Clone, Copy)]
pub struct TrainingRays<'a> {
    /// Ray origins `[R, 3]`.
    pub origins: &'a [f32],
    /// Unit ray directions `[R, 3]`.
    pub directions: &'a [f32],
    /// The pixels' colours `[R, 3]`, composited over [`TrainerSettings::background`] where
    /// their picture had alpha.
    pub colors: &'a [f32],
    /// The pixels' opacities `[R]` (1 for a picture without alpha), if any picture had alpha:
    /// with [`TrainerSettings::random_background`], each training ray is composited over a
    /// random colour and its target recomposited over the same colour.
    pub alpha: Option<&'a [f32]>,
}

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
    /// Colour through spherical harmonics of this degree (1 to 3: `1 + 3 (degree + 1)^2`
    /// values a node), or 0: one colour from every direction (4 values a node).
    pub sh_degree: usize,
    /// The background colour behind every ray (and behind the targets' transparent pixels).
    pub background: [f32; 3],
    /// With the rays' alpha given: train each ray over a uniform random colour of its own,
    /// so that the grid cannot paint the background into the scene.
    pub random_background: bool,
    /// The weight of mip-NeRF 360's distortion loss (the mean over the batch's rays of
    /// `sum_ij w_i w_j |t_i - t_j| + (1/3) sum_i w_i^2 delta_i`, distances along the ray) in the
    /// objective; 0: none.
    pub distortion: f64,
    /// Skip the samples in empty cells of an occupancy grid (training and renders), or keep
    /// every sample.
    pub occupancy: Option<OccupancySettings>,
    /// Seed of the batches.
    pub seed: u64,
}

struct TrainKernels {
    sample_batch: CudaFunction,
    sample_range: CudaFunction,
    photometric_loss: CudaFunction,
    lattice: CudaFunction,
    occupancy_points: CudaFunction,
    occupancy_update: CudaFunction,
    distortion: CudaFunction,
    count_kept: CudaFunction,
    scan_offsets: CudaFunction,
    compact: CudaFunction,
    adam: CudaFunction,
}

/// Where the sampling kernels write every sample of the batch, before the samples of nonzero
/// length are packed into the buffers the rest of the step reads.
struct Staging {
    positions: CudaSlice<f32>,
    delta: CudaSlice<f32>,
    ts: CudaSlice<f32>,
    /// `[n, 3]` with spherical harmonics, else one zero.
    dirs: CudaSlice<f32>,
    /// Each ray's kept samples.
    counts: CudaSlice<u64>,
}

/// The occupancy grid's refresh state on the device (its cells are the trainer's).
struct OccupancyState {
    settings: OccupancySettings,
    estimate: CudaSlice<f32>,
    /// The refresh's points `[2 cells^3, 3]` and their raw values `[2 cells^3, channels]`.
    points: CudaSlice<f32>,
    raw: CudaSlice<f32>,
    refreshes: u64,
}

/// How raw values become density and colour.
enum Shading {
    /// `4` values a node: density, then RGB.
    Plain(CudaDensityColor),
    /// Density, then each channel's spherical-harmonics coefficients.
    Harmonics(CudaShDensityColor),
}

impl Shading {
    fn channels(&self) -> usize {
        match self {
            Shading::Plain(_) => VIEW_INDEPENDENT_CHANNELS,
            Shading::Harmonics(sh) => sh.channels(),
        }
    }
}

/// The grid's parameters and Adam's state for them.
struct GridState {
    grid: CudaGrid,
    params: CudaSlice<f32>,
    grad: CudaSlice<f32>,
    acc: CudaSlice<f64>,
    m: CudaSlice<f32>,
    v: CudaSlice<f32>,
    /// Adam steps on these moments (the bias correction's `t`).
    adam_steps: u64,
}

impl GridState {
    /// `grid`'s values, all zero, with fresh moments.
    fn zeros(stream: &std::sync::Arc<cudarc::driver::CudaStream>, grid: CudaGrid) -> Result<Self, CudaError> {
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

/// Threads a block of the compaction kernels (`COMPACT_THREADS` in `kernels/train.cu`).
const COMPACT_THREADS: u32 = 256;

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
        let rays = data.origins.len() / 3;
        if rays == 0 || data.origins.len() != 3 * rays {
            return Err(CudaError::Shape {
                what: "ray origins ([R, 3], R >= 1)",
                expected: 3 * rays.max(1),
                got: data.origins.len(),
            });
        }
        for (what, v) in [
            ("ray directions ([R, 3])", data.directions),
            ("colours ([R, 3])", data.colors),
        ] {
            if v.len() != 3 * rays {
                return Err(CudaError::Shape {
                    what,
                    expected: 3 * rays,
                    got: v.len(),
                });
            }
        }
        if let Some(a) = data.alpha {
            check_len("opacities ([R])", rays, a.len())?;
        }
        if settings.batch == 0 || settings.samples_per_ray == 0 {
            return Err(CudaError::InvalidSettings(format!(
                "{} rays a step and {} samples a ray (each at least 1)",
                settings.batch, settings.samples_per_ray
            )));
        }
        if settings.sh_degree > MAX_SH_DEGREE {
            return Err(CudaError::InvalidSettings(format!(
                "spherical harmonics of degree {} (at most {MAX_SH_DEGREE})",
                settings.sh_degree
            )));
        }
        if let Some((channel, &v)) = settings.background.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(CudaError::InvalidBackground {
                channel,
                value: f64::from(v),
            });
        }
        if !(settings.distortion.is_finite() && settings.distortion >= 0.0) {
            return Err(CudaError::InvalidSettings(format!(
                "distortion weight {} (finite, at least 0)",
                settings.distortion
            )));
        }
        if let Some(o) = settings.occupancy {
            if o.cells == 0 || o.every == 0 || !(o.density.is_finite() && (0.0..=1.0).contains(&o.decay)) {
                return Err(CudaError::InvalidSettings(format!(
                    "occupancy {o:?}: at least one cell and one step between refreshes, a finite density, a decay in [0, 1]"
                )));
            }
        }
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

    /// Refreshes the occupancy grid from the grid's densities now (`step` does every
    /// [`OccupancySettings::every`] steps); nothing without one.
    pub fn refresh_occupancy(&mut self) -> Result<(), CudaError> {
        let Some(o) = &mut self.occupancy else { return Ok(()) };
        let s = self.gpu.stream();
        let count = o.settings.cells.pow(3);
        let (seed, refresh) = (self.settings.seed, o.refreshes);
        let mut launch = s.launch_builder(&self.kernels.occupancy_points);
        launch.arg(&self.cells).arg(&seed).arg(&refresh).arg(&mut o.points);
        // SAFETY: `points` holds `2 cells^3` positions.
        unsafe { launch.launch(launch_config(count)) }?;
        let st = &self.state;
        st.grid
            .launch_lookup(&st.params, &o.points, 2 * count, &mut o.raw, &mut self.invalid)?;
        let (channels, count64) = (self.shading.channels() as u64, count as u64);
        let mut launch = s.launch_builder(&self.kernels.occupancy_update);
        launch
            .arg(&o.raw)
            .arg(&channels)
            .arg(&count64)
            .arg(&self.settings.shift)
            .arg(&o.settings.decay)
            .arg(&o.settings.density)
            .arg(&mut o.estimate)
            .arg(&mut self.occupied);
        // SAFETY: `raw` holds `2 cells^3` rows of `channels`, the estimate and the bytes
        // `cells^3`.
        unsafe { launch.launch(launch_config(count)) }?;
        o.refreshes += 1;
        Ok(())
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

    /// Packs the staged samples of nonzero length ray by ray into the step's buffers and the
    /// batch's offsets, and reads how many there are (the one wait of a step: the kernels
    /// after it are launched for that many).
    fn compact_samples(&mut self) -> Result<(), CudaError> {
        let st = self.settings;
        let (batch, samples, with_dirs) = (st.batch as u64, st.samples_per_ray as u64, self.with_dirs());
        let s = self.gpu.stream().clone();
        let blocks = LaunchConfig {
            grid_dim: (u32::try_from(st.batch).unwrap_or(u32::MAX), 1, 1),
            block_dim: (COMPACT_THREADS, 1, 1),
            shared_mem_bytes: 0,
        };
        let g = &mut self.staging;
        let mut launch = s.launch_builder(&self.kernels.count_kept);
        launch.arg(&g.delta).arg(&samples).arg(&mut g.counts);
        // SAFETY: a block a ray of the batch, over its `samples` staged lengths; `counts`
        // holds `batch` values.
        unsafe { launch.launch(blocks) }?;
        let parts = self.batch_rays.parts_mut();
        let mut launch = s.launch_builder(&self.kernels.scan_offsets);
        launch.arg(&g.counts).arg(&batch).arg(&mut *parts.offsets);
        // SAFETY: one block of 1024 threads reads `batch` counts and writes `batch + 1`
        // offsets (the packing's length).
        unsafe {
            launch.launch(LaunchConfig {
                grid_dim: (1, 1, 1),
                block_dim: (1024, 1, 1),
                shared_mem_bytes: 0,
            })
        }?;
        let total = s.clone_dtoh(&parts.offsets.slice(st.batch..))?[0];
        let (offsets, delta) = (&*parts.offsets, parts.delta);
        let mut launch = s.launch_builder(&self.kernels.compact);
        launch
            .arg(&g.positions)
            .arg(&g.delta)
            .arg(&g.ts)
            .arg(&g.dirs)
            .arg(&with_dirs)
            .arg(&samples)
            .arg(offsets)
            .arg(&mut self.positions)
            .arg(delta)
            .arg(&mut self.ts)
            .arg(&mut self.sample_dirs);
        // SAFETY: a block a ray; the compact buffers hold the batch's `batch * samples`
        // samples, of which it writes the `total` kept (the directions only `with_dirs`,
        // when both direction buffers hold `3 n`).
        unsafe { launch.launch(blocks) }?;
        self.kept = usize::try_from(total).unwrap_or(usize::MAX);
        Ok(())
    }

    /// Looks up, activates and composites the batch whose positions, step lengths (and
    /// directions) are in place.
    fn render_batch(&mut self, clock: &mut PhaseClock) -> Result<(), CudaError> {
        let n = self.kept;
        let st = &self.state;
        st.grid
            .launch_lookup(&st.params, &self.positions, n, &mut self.raw, &mut self.invalid)?;
        clock.lap(self.gpu, |p| &mut p.lookup)?;
        let (sigma, _, color) = self.batch_rays.samples_mut();
        match &self.shading {
            Shading::Plain(act) => {
                act.launch_forward(&self.raw, n, VIEW_INDEPENDENT_CHANNELS, sigma, color, &mut self.invalid)?
            }
            Shading::Harmonics(sh) => {
                sh.launch_forward(&self.raw, &self.sample_dirs, n, sigma, color, &mut self.invalid)?
            }
        }
        clock.lap(self.gpu, |p| &mut p.shading)?;
        self.gpu.launch_forward(&self.batch_rays, &mut self.forward)?;
        clock.lap(self.gpu, |p| &mut p.composite)
    }

    /// One training step at learning rate `lr` (queued on the stream; nothing waits). The
    /// batch's squared error is added to what [`DenseGridTrainer::take_mean_squared_error`]
    /// reads.
    pub fn step(&mut self, lr: f64) -> Result<(), CudaError> {
        self.step_with(lr, &mut PhaseClock::new(false))
    }

    /// [`DenseGridTrainer::step`], waiting for the device after each phase to time it: the
    /// same step (the same batch and update), slower by the waits.
    pub fn step_timed(&mut self, lr: f64) -> Result<StepPhases, CudaError> {
        self.wait()?;
        let mut clock = PhaseClock::new(true);
        self.step_with(lr, &mut clock)?;
        Ok(clock.phases)
    }

    /// Draws the step's batch, places its samples (skipping empty occupancy cells) and packs
    /// the kept ones.
    fn sample_batch(&mut self) -> Result<(), CudaError> {
        let st = self.settings;
        let (batch, samples) = (st.batch as u64, st.samples_per_ray as u64);
        let (rays, seed, step, with_dirs) = (self.rays as u64, st.seed, self.steps, self.with_dirs());
        {
            let g = &mut self.staging;
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
                .arg(&mut g.positions)
                .arg(&mut g.delta)
                .arg(&mut g.ts)
                .arg(&mut self.picked)
                .arg(&with_dirs)
                .arg(&mut g.dirs)
                .arg(&self.cells)
                .arg(&self.occupied);
            // SAFETY: the kernel's arguments in its order and types; `rays` rays in the ray
            // buffers, `batch * samples` samples in the batch buffers (and their directions
            // when `with_dirs`), `batch` picks; a thread a sample.
            unsafe { launch.launch(launch_config(st.batch * st.samples_per_ray)) }?;
        }
        self.compact_samples()
    }

    /// Whether the trainer has an occupancy grid and none of its cells is occupied (reads the
    /// cells back: called only when a batch kept no sample).
    fn occupancy_is_empty(&self) -> Result<bool, CudaError> {
        Ok(self.occupancy()?.is_some_and(|cells| cells.iter().all(|&c| c == 0)))
    }

    fn step_with(&mut self, lr: f64, clock: &mut PhaseClock) -> Result<(), CudaError> {
        let st = self.settings;
        if let Some(o) = st.occupancy {
            if self.steps > 0 && self.steps % o.every == 0 {
                self.refresh_occupancy()?;
            }
        }
        clock.lap(self.gpu, |p| &mut p.occupancy)?;
        self.sample_batch()?;
        if self.kept == 0 && self.occupancy_is_empty()? {
            // A refresh emptied the occupancy grid (every density below its threshold, as a
            // slow learning rate can leave it): with no samples nothing could raise a density
            // again, so every cell is occupied until the next refresh, as `fogray fit` does.
            let every = vec![1u8; self.occupied.len()];
            self.gpu.stream().memcpy_htod(&every, &mut self.occupied)?;
            self.sample_batch()?;
        }
        clock.lap(self.gpu, |p| &mut p.sampling)?;
        self.render_batch(clock)?;
        let (batch, seed, step) = (st.batch as u64, st.seed, self.steps);
        {
            let random = u64::from(self.random);
            let background = DeviceRgb(st.background.map(f64::from));
            let (d_color, d_opacity) = match self.upstream.both_mut() {
                (c, Some(o)) => (c, o),
                // Made with an opacity gradient in `new`.
                (_, None) => return Err(CudaError::InvalidSettings("no opacity upstream".into())),
            };
            let mut launch = self.gpu.stream().launch_builder(&self.kernels.photometric_loss);
            launch
                .arg(&self.forward.color)
                .arg(&self.forward.opacity)
                .arg(&self.targets)
                .arg(&self.alpha)
                .arg(&random)
                .arg(&self.picked)
                .arg(&batch)
                .arg(&seed)
                .arg(&step)
                .arg(&background)
                .arg(d_color)
                .arg(d_opacity)
                .arg(&mut self.sse);
            // SAFETY: `batch` rays' colours, opacities and gradients; picks below `rays`;
            // the opacities of `rays` pixels are read only when `random` (then given).
            unsafe { launch.launch(launch_config(st.batch)) }?;
        }
        clock.lap(self.gpu, |p| &mut p.loss)?;
        self.gpu
            .launch_backward(&self.batch_rays, &self.forward, &self.upstream, &mut self.gradients)?;
        clock.lap(self.gpu, |p| &mut p.composite_backward)?;
        if st.distortion > 0.0 {
            let c = st.distortion / st.batch as f64;
            let parts = self.batch_rays.parts_mut();
            let [w, a, depth] = &mut self.distortion_scratch;
            let mut launch = self.gpu.stream().launch_builder(&self.kernels.distortion);
            launch
                .arg(&*parts.sigma)
                .arg(&*parts.delta)
                .arg(&self.ts)
                .arg(&*parts.offsets)
                .arg(&batch)
                .arg(&c)
                .arg(w)
                .arg(a)
                .arg(depth)
                .arg(&mut self.gradients.sigma)
                .arg(&mut self.distortion_sum);
            // SAFETY: the packing's samples (at most `batch * samples`) in each per-sample
            // buffer (the scratch ones are that long when the weight is above 0); a thread a
            // ray.
            unsafe { launch.launch(launch_config(st.batch)) }?;
        }
        clock.lap(self.gpu, |p| &mut p.distortion)?;
        let n = self.kept;
        match &self.shading {
            Shading::Plain(act) => act.launch_backward(
                &self.raw,
                n,
                VIEW_INDEPENDENT_CHANNELS,
                Some(&self.gradients.sigma),
                Some(&self.gradients.color),
                &mut self.d_raw,
            )?,
            Shading::Harmonics(sh) => sh.launch_backward(
                &self.raw,
                &self.sample_dirs,
                n,
                &self.gradients.sigma,
                &self.gradients.color,
                &mut self.d_raw,
            )?,
        }
        clock.lap(self.gpu, |p| &mut p.shading_backward)?;
        let state = &mut self.state;
        state
            .grid
            .launch_scatter(&self.positions, &self.d_raw, n, &mut state.acc)?;
        clock.lap(self.gpu, |p| &mut p.grid_backward)?;
        self.steps += 1;
        state.adam_steps += 1;
        let t = i32::try_from(state.adam_steps).unwrap_or(i32::MAX);
        let (beta1, beta2, eps) = (0.9f64, 0.999f64, 1e-8f64);
        let (c1, c2) = (1.0 - beta1.powi(t), 1.0 - beta2.powi(t));
        let values = state.params.len();
        let len = values as u64;
        let keep = u64::from(self.record_gradients);
        let mut launch = self.gpu.stream().launch_builder(&self.kernels.adam);
        launch
            .arg(&mut state.params)
            .arg(&mut state.acc)
            .arg(&mut state.grad)
            .arg(&keep)
            .arg(&mut state.m)
            .arg(&mut state.v)
            .arg(&len)
            .arg(&lr)
            .arg(&beta1)
            .arg(&beta2)
            .arg(&eps)
            .arg(&c1)
            .arg(&c2);
        // SAFETY: five buffers of the grid's `values` values (the gradient's written only when
        // it is kept, then that long).
        unsafe { launch.launch(launch_config(values)) }?;
        clock.lap(self.gpu, |p| &mut p.adam)
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

    /// Waits for the steps queued, and returns the mean over them of the weighted distortion
    /// loss since the last call (0 if none or without the loss).
    pub fn take_distortion_loss(&mut self, steps: u64) -> Result<f64, CudaError> {
        let s = self.gpu.stream();
        let sum = s.clone_dtoh(&self.distortion_sum)?[0];
        s.memset_zeros(&mut self.distortion_sum)?;
        Ok(if steps > 0 { sum / steps as f64 } else { 0.0 })
    }

    /// Renders rays (`origins`, unit `directions`, `[R, 3]`) over the settings' background
    /// with samples at the centres of their steps: colours `[R, 3]`.
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
        let (o, d) = (put(&s, origins)?, put(&s, directions)?);
        let st = self.settings;
        let with_dirs = self.with_dirs();
        let mut colors = Vec::with_capacity(3 * rays);
        let mut first = 0;
        while first < rays {
            let count = st.batch.min(rays - first);
            let (first64, count64, samples) = (first as u64, count as u64, st.samples_per_ray as u64);
            {
                let g = &mut self.staging;
                // The batch's rays past `count` keep step length 0: they add nothing.
                s.memset_zeros(&mut g.delta)?;
                let mut launch = s.launch_builder(&self.kernels.sample_range);
                launch
                    .arg(&o)
                    .arg(&d)
                    .arg(&first64)
                    .arg(&count64)
                    .arg(&samples)
                    .arg(&self.scene)
                    .arg(&mut g.positions)
                    .arg(&mut g.delta)
                    .arg(&mut g.ts)
                    .arg(&with_dirs)
                    .arg(&mut g.dirs)
                    .arg(&self.cells)
                    .arg(&self.occupied);
                // SAFETY: rays first..first + count exist; the batch buffers hold `batch >=
                // count` rays of samples; a thread a sample.
                unsafe { launch.launch(launch_config(count * st.samples_per_ray)) }?;
            }
            self.compact_samples()?;
            self.render_batch(&mut PhaseClock::new(false))?;
            let color0 = s.clone_dtoh(&self.forward.color)?;
            let opacity = s.clone_dtoh(&self.forward.opacity)?;
            for r in 0..count {
                let seen = 1.0 - f64::from(opacity[r]);
                for c in 0..3 {
                    colors.push((f64::from(color0[3 * r + c]) + seen * f64::from(st.background[c])) as f32);
                }
            }
            first += count;
        }
        if s.clone_dtoh(&self.invalid)?[0] != 0 {
            return Err(CudaError::InvalidSample);
        }
        Ok(colors)
    }

    /// The grid's raw values, `[nodes, nodes, nodes, channels]` row-major (density, then the
    /// colour's values).
    pub fn grid_values(&self) -> Result<Vec<f32>, CudaError> {
        Ok(self.gpu.stream().clone_dtoh(&self.state.params)?)
    }

    /// Replaces the grid's raw values (as [`DenseGridTrainer::grid_values`] gives them; Adam's
    /// moments are kept). Errors: a length other than the grid's; the grid is unchanged then.
    pub fn set_grid_values(&mut self, values: &[f32]) -> Result<(), CudaError> {
        if values.len() != self.state.params.len() {
            return Err(CudaError::Shape {
                what: "grid values ([nodes, nodes, nodes, channels])",
                expected: self.state.params.len(),
                got: values.len(),
            });
        }
        Ok(self.gpu.stream().memcpy_htod(values, &mut self.state.params)?)
    }

    /// Keeps (or stops keeping) each step's gradient for [`DenseGridTrainer::last_gradient`],
    /// at the cost of writing the grid's size of values a step.
    pub fn record_gradients(&mut self, on: bool) {
        self.record_gradients = on;
    }

    /// The gradient of the last step's loss with respect to the grid's raw values (before
    /// Adam used it), for checks against the CPU ops. Errors: [`CudaError::InvalidSettings`]
    /// unless [`DenseGridTrainer::record_gradients`] was on for that step.
    pub fn last_gradient(&self) -> Result<Vec<f32>, CudaError> {
        if !self.record_gradients {
            return Err(CudaError::InvalidSettings(
                "the gradients are not kept: call record_gradients(true) before the step".into(),
            ));
        }
        Ok(self.gpu.stream().clone_dtoh(&self.state.grad)?)
    }
}
