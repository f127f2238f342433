//! Stochastic gradient descent with (heavy-ball) momentum.

use super::chunks::{zip2, zip3};
use super::slots::{Rule, Slots};
use super::source::GradientSource;
use super::{check_range, StepSummary};
use crate::float::Float;
use crate::params::{ParamError, ParamId, Params};

/// SGD's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SgdConfig {
    /// Learning rate: finite, at least 0.
    pub lr: f64,
    /// Fraction of the last velocity kept, in `[0, 1)`; 0 is plain gradient descent.
    pub momentum: f64,
}

impl Default for SgdConfig {
    /// `lr = 1e-2`, no momentum.
    fn default() -> Self {
        SgdConfig {
            lr: 1e-2,
            momentum: 0.0,
        }
    }
}

impl SgdConfig {
    /// Checks every setting's range. Errors: [`ParamError::InvalidSetting`] naming the first
    /// setting out of range.
    pub fn validate(&self) -> Result<(), ParamError> {
        check_range("lr", self.lr, self.lr >= 0.0, "finite and at least 0")?;
        check_range(
            "momentum",
            self.momentum,
            (0.0..1.0).contains(&self.momentum),
            "in [0, 1)",
        )
    }
}

impl<F: Float> Rule<F> for SgdConfig {
    /// The velocity; empty without momentum.
    type State = Vec<F>;

    fn new_state(&self, len: usize) -> Vec<F> {
        if self.momentum > 0.0 {
            vec![F::zero(); len]
        } else {
            Vec::new()
        }
    }

    fn update(&self, x: &mut [F], g: &[F], velocity: &mut Vec<F>, lr: f64) {
        let lr = F::lit(lr);
        if velocity.is_empty() {
            zip2(x, g, |x, g| *x -= lr * g);
        } else {
            let mu = F::lit(self.momentum);
            zip3(x, g, velocity, |x, g, u| {
                *u = mu * *u + g;
                *x -= lr * *u;
            });
        }
    }
}

/// Gradient descent with momentum: per element `u = momentum u + g`, `x -= lr u`, the velocity
/// `u` starting at 0 for each parameter (so the first update is `x -= lr g`, as in PyTorch).
///
/// State, precision, parallelism and the rules for missing gradients and errors are those of
/// [`Adam`](super::Adam): see its documentation and [`crate::optim`].
#[derive(Debug, Clone)]
pub struct Sgd<F: Float> {
    config: SgdConfig,
    slots: Slots<Vec<F>>,
}

impl<F: Float> Sgd<F> {
    /// An optimiser with no state yet. Errors: [`ParamError::InvalidSetting`].
    pub fn new(config: SgdConfig) -> Result<Self, ParamError> {
        config.validate()?;
        Ok(Sgd {
            config,
            slots: Slots::default(),
        })
    }

    /// The settings in use.
    pub fn config(&self) -> SgdConfig {
        self.config
    }

    /// Sets the learning rate of the next steps. Errors: [`ParamError::InvalidSetting`] if
    /// `lr` is negative or not finite; nothing changes.
    pub fn set_lr(&mut self, lr: f64) -> Result<(), ParamError> {
        SgdConfig { lr, ..self.config }.validate()?;
        self.config.lr = lr;
        Ok(())
    }

    /// Multiplies the learning rate of parameter `id` by `scale` (1 unless set), as
    /// [`Adam::set_lr_scale`](super::Adam::set_lr_scale).
    pub fn set_lr_scale(&mut self, id: ParamId, scale: f64) -> Result<(), ParamError> {
        self.slots.set_lr_scale(id, scale)
    }

    /// Updates in place every parameter of `params` that `grads` holds a gradient for, with
    /// the skips and errors of [`Adam::step`](super::Adam::step).
    pub fn step(&mut self, params: &mut Params<F>, grads: &impl GradientSource<F>) -> Result<StepSummary, ParamError> {
        self.slots.step(&self.config, self.config.lr, params, grads)
    }
}
