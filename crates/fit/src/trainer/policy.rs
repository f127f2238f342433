//! What runs around a training step: a [`StepPolicy`] sees the model, its optimiser and its
//! occupancy grid before the step and after it, and may change them (grow the model, set the
//! learning rate, refresh the occupancy grid), as gsplat's strategies and nerfacc's
//! estimators do around theirs. The trainer calls its policies in a fixed order, so that a fit
//! takes the same steps however it is driven.

use fogray_ops::sample::OccupancyGrid;
use fogray_tape::optim::Adam;
use fogray_tape::Float;

use crate::error::FitError;

/// What a policy may read and change between two steps.
pub(crate) struct StepContext<'a, F: Float, M> {
    /// Steps done: before a step, the steps before it; after a step, counting it.
    pub step: usize,
    /// The fraction of the budget spent (in `[0, 1)` before a step; at most 1 after the last).
    pub fraction: f64,
    /// The model being fitted.
    pub(crate) model: &'a mut M,
    /// Adam, whose moments follow the model's parameters.
    pub optimiser: &'a mut Adam<F>,
    /// The occupancy grid, with occupancy sampling.
    pub occupancy: &'a mut Option<OccupancyGrid>,
}

/// A rule applied around every training step. Both hooks do nothing by default.
pub(crate) trait StepPolicy<F: Float, M> {
    /// Called before the step, with the step count and budget fraction before it.
    ///
    /// Errors: whatever the policy's change can raise (a model that cannot grow).
    fn before_step(&mut self, at: &mut StepContext<'_, F, M>) -> Result<(), FitError> {
        let _ = at;
        Ok(())
    }

    /// Called after the step, with the step count that includes it.
    ///
    /// Errors: as [`StepPolicy::before_step`].
    fn after_step(&mut self, at: &mut StepContext<'_, F, M>) -> Result<(), FitError> {
        let _ = at;
        Ok(())
    }
}
