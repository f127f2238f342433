//! What the host reads back from a trainer and writes into it: the losses since the last
//! read, renders of any rays, the grid's values and the last step's gradient.

use cudarc::driver::PushKernelArg;

use super::phases::PhaseClock;
use super::DenseGridTrainer;
use crate::buffers::{launch_config, put};
use crate::error::CudaError;

impl DenseGridTrainer<'_> {
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
