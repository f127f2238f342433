//! The learning-rate policy: Adam's rate set before each step from the fraction of the budget
//! spent ([`learning_rate`]: constant, then a geometric anneal).

use fogray_tape::Float;

use crate::error::FitError;
use crate::schedule::learning_rate;
use crate::settings::FitSettings;
use crate::trainer::policy::{StepContext, StepPolicy};

/// Sets Adam's rate to [`learning_rate`] of the budget's fraction before every step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct LearningRate {
    settings: FitSettings,
}

impl LearningRate {
    /// The schedule of `settings` (`lr`, `lr_final`).
    pub(crate) fn new(settings: &FitSettings) -> Self {
        LearningRate { settings: *settings }
    }
}

impl<F: Float, M> StepPolicy<F, M> for LearningRate {
    fn before_step(&mut self, at: &mut StepContext<'_, F, M>) -> Result<(), FitError> {
        at.optimiser.set_lr(learning_rate(&self.settings, at.fraction))?;
        Ok(())
    }
}
