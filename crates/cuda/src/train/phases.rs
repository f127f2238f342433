//! Where a step's time goes ([`StepPhases`]), measured phase by phase when asked.

use crate::composite::CudaComposite;
use crate::error::CudaError;

/// Where a step's time goes, in seconds, as
/// [`DenseGridTrainer::step_timed`](crate::DenseGridTrainer::step_timed) measures it (the
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
pub(super) struct PhaseClock {
    on: bool,
    at: std::time::Instant,
    pub(super) phases: StepPhases,
}

impl PhaseClock {
    pub(super) fn new(on: bool) -> Self {
        PhaseClock {
            on,
            at: std::time::Instant::now(),
            phases: StepPhases::default(),
        }
    }

    /// Adds the time since the last lap to the phase `slot` picks.
    pub(super) fn lap(&mut self, gpu: &CudaComposite, slot: fn(&mut StepPhases) -> &mut f64) -> Result<(), CudaError> {
        if self.on {
            gpu.stream().synchronize()?;
            let now = std::time::Instant::now();
            *slot(&mut self.phases) += (now - self.at).as_secs_f64();
            self.at = now;
        }
        Ok(())
    }
}
