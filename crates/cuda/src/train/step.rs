//! A training step: the occupancy grid's refresh, the batch drawn, sampled and packed, its
//! render, the photometric and distortion losses, the backwards and Adam.

use cudarc::driver::{LaunchConfig, PushKernelArg};

use super::device::{DeviceRgb, Shading};
use super::phases::{PhaseClock, StepPhases};
use super::{DenseGridTrainer, VIEW_INDEPENDENT_CHANNELS};
use crate::buffers::launch_config;
use crate::error::CudaError;

/// Threads a block of the compaction kernels (`COMPACT_THREADS` in `kernels/train.cu`).
const COMPACT_THREADS: u32 = 256;

impl DenseGridTrainer<'_> {
    /// Refreshes the occupancy grid from the grid's densities now (`step` does every
    /// [`OccupancySettings::every`](super::OccupancySettings::every) steps); nothing without one.
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

    /// Packs the staged samples of nonzero length ray by ray into the step's buffers and the
    /// batch's offsets, and reads how many there are (the one wait of a step: the kernels
    /// after it are launched for that many).
    pub(super) fn compact_samples(&mut self) -> Result<(), CudaError> {
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
    pub(super) fn render_batch(&mut self, clock: &mut PhaseClock) -> Result<(), CudaError> {
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
}
