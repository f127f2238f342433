//! Adam (Kingma and Ba, 2015) with bias-corrected moments.

use ndarray::{ArrayD, IxDyn};

use super::chunks::{first_non_finite, zip4};
use super::slots::{Rule, Slots};
use super::source::GradientSource;
use super::{check_range, StepSummary};
use crate::float::Float;
use crate::params::{ParamError, ParamId, Params};

/// Adam's settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdamConfig {
    /// Learning rate (the step's size when the moments agree): finite, at least 0.
    pub lr: f64,
    /// Decay of the first moment (the mean of the gradients), in `[0, 1)`.
    pub beta1: f64,
    /// Decay of the second moment (the mean of their squares), in `[0, 1)`.
    pub beta2: f64,
    /// Added to the root of the second moment so the step stays finite: finite, above 0.
    pub eps: f64,
}

impl Default for AdamConfig {
    /// The usual settings: `lr = 1e-3, beta1 = 0.9, beta2 = 0.999, eps = 1e-8`.
    fn default() -> Self {
        AdamConfig {
            lr: 1e-3,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
        }
    }
}

impl AdamConfig {
    /// Checks every setting's range. Errors: [`ParamError::InvalidSetting`] naming the first
    /// setting out of range.
    pub fn validate(&self) -> Result<(), ParamError> {
        check_range("lr", self.lr, self.lr >= 0.0, "finite and at least 0")?;
        check_range("beta1", self.beta1, (0.0..1.0).contains(&self.beta1), "in [0, 1)")?;
        check_range("beta2", self.beta2, (0.0..1.0).contains(&self.beta2), "in [0, 1)")?;
        check_range("eps", self.eps, self.eps > 0.0, "finite and above 0")
    }
}

/// One parameter's Adam state, as [`Adam::state`] exports it and [`Adam::restore`] imports
/// it: enough to continue the optimisation exactly where it stopped (with the same
/// [`AdamConfig`] and learning-rate scale, which are settings, not state).
#[derive(Debug, Clone, PartialEq)]
pub struct AdamState<F> {
    /// The first moment `m` (running mean of the gradients), the parameter's shape.
    pub first_moment: ArrayD<F>,
    /// The second moment `v` (running mean of their squares), the parameter's shape, `>= 0`.
    pub second_moment: ArrayD<F>,
    /// Updates so far, `t` of the bias corrections `1 - beta^t`.
    pub updates: usize,
}

/// One parameter's moments and its number of updates.
#[derive(Debug, Clone)]
pub(crate) struct Moments<F> {
    m: Vec<F>,
    v: Vec<F>,
    t: i32,
}

impl<F: Float> Rule<F> for AdamConfig {
    type State = Moments<F>;

    fn new_state(&self, len: usize) -> Moments<F> {
        Moments {
            m: vec![F::zero(); len],
            v: vec![F::zero(); len],
            t: 0,
        }
    }

    fn update(&self, x: &mut [F], g: &[F], s: &mut Moments<F>, lr: f64) {
        s.t = s.t.saturating_add(1);
        // Step constants in f64, rounded once to F; the per-element arithmetic is in F.
        let (b1, b2) = (F::lit(self.beta1), F::lit(self.beta2));
        let (c1, c2) = (F::lit(1.0 - self.beta1), F::lit(1.0 - self.beta2));
        let bc1 = F::lit(1.0 - self.beta1.powi(s.t));
        let bc2 = F::lit(1.0 - self.beta2.powi(s.t));
        let (lr, eps) = (F::lit(lr), F::lit(self.eps));
        zip4(x, g, &mut s.m, &mut s.v, |x, g, m, v| {
            *m = b1 * *m + c1 * g;
            *v = b2 * *v + c2 * g * g;
            let m_hat = *m / bc1;
            let v_hat = *v / bc2;
            *x -= lr * m_hat / (v_hat.sqrt() + eps);
        });
    }
}

/// Adam: per element, `m = b1 m + (1 - b1) g`, `v = b2 v + (1 - b2) g²`, and
/// `x -= lr m̂ / (sqrt(v̂) + eps)` with the bias-corrected `m̂ = m / (1 - b1^t)`,
/// `v̂ = v / (1 - b2^t)`, where `t` counts this parameter's updates (so the first update moves
/// each element by `lr` against the sign of its gradient, up to `eps`).
///
/// Moments are kept per parameter, made at its first update with its shape, in the
/// parameter's float type: the update is computed in `F` (in `f32` for an `f32` grid, as
/// usual for Adam; its per-element error is a few ulps of a step, far below the noise of a
/// stochastic gradient), with the step's constants (`1 - b^t`, the rate) computed in `f64`.
/// Large parameters are updated in parallel chunks; every element is updated on its own, so
/// the result does not depend on the number of threads. See [`crate::optim`] for a training
/// loop.
#[derive(Debug, Clone)]
pub struct Adam<F: Float> {
    config: AdamConfig,
    slots: Slots<Moments<F>>,
}

impl<F: Float> Adam<F> {
    /// An optimiser with no state yet. Errors: [`ParamError::InvalidSetting`].
    pub fn new(config: AdamConfig) -> Result<Self, ParamError> {
        config.validate()?;
        Ok(Adam {
            config,
            slots: Slots::default(),
        })
    }

    /// The settings in use.
    pub fn config(&self) -> AdamConfig {
        self.config
    }

    /// Sets the learning rate of the next steps (a schedule). Errors:
    /// [`ParamError::InvalidSetting`] if `lr` is negative or not finite; nothing changes.
    pub fn set_lr(&mut self, lr: f64) -> Result<(), ParamError> {
        AdamConfig { lr, ..self.config }.validate()?;
        self.config.lr = lr;
        Ok(())
    }

    /// Multiplies the learning rate of parameter `id` by `scale` (1 unless set; a grid's
    /// density and colour often want different rates). Binds the optimiser to `id`'s store.
    ///
    /// Errors: [`ParamError::InvalidSetting`] if `scale` is negative or not finite,
    /// [`ParamError::ForeignStore`] if the optimiser steps another store; nothing changes.
    pub fn set_lr_scale(&mut self, id: ParamId, scale: f64) -> Result<(), ParamError> {
        self.slots.set_lr_scale(id, scale)
    }

    /// How many updates parameter `id` has had (0 before its first).
    pub fn updates(&self, id: ParamId) -> usize {
        self.slots.state(id).map_or(0, |s| s.t as usize)
    }

    /// Parameter `id`'s state (moments and count of updates), `None` before its first update:
    /// saved with the parameter, it lets [`Adam::restore`] continue the optimisation exactly.
    ///
    /// Errors: [`ParamError::ForeignParam`] if `id` is not of `params` (whose shape the
    /// moments take), [`ParamError::ForeignStore`] if this optimiser steps another store.
    pub fn state(&self, params: &Params<F>, id: ParamId) -> Result<Option<AdamState<F>>, ParamError> {
        self.slots.check_store(params.store)?;
        let shape = params.entry(id)?.value.shape().to_vec();
        let Some(s) = self.slots.state(id) else {
            return Ok(None);
        };
        // The moments were made with the parameter's length and a parameter never changes
        // shape, so the reshape cannot fail.
        let shaped = |flat: &[F]| {
            ArrayD::from_shape_vec(IxDyn(&shape), flat.to_vec()).expect("moments have the parameter's length")
        };
        Ok(Some(AdamState {
            first_moment: shaped(&s.m),
            second_moment: shaped(&s.v),
            updates: s.t as usize,
        }))
    }

    /// Sets parameter `id`'s state (as exported by [`Adam::state`], perhaps by another
    /// optimiser or another process), so that the next [`Adam::step`] continues from it; binds
    /// the optimiser to `params`.
    ///
    /// Expects both moments in the parameter's shape, finite, the second at least 0, and at
    /// most `i32::MAX` updates. Errors, checked before anything changes (so on error the
    /// optimiser is as it was): [`ParamError::StateShape`], [`ParamError::InvalidState`],
    /// [`ParamError::ForeignParam`], [`ParamError::ForeignStore`].
    pub fn restore(&mut self, params: &Params<F>, id: ParamId, state: AdamState<F>) -> Result<(), ParamError> {
        self.slots.check_store(params.store)?;
        let entry = params.entry(id)?;
        let name = || entry.name.clone();
        let invalid = |what, index, value, range| ParamError::InvalidState {
            name: name(),
            what,
            index,
            value,
            range,
        };
        let t = i32::try_from(state.updates)
            .map_err(|_| invalid("updates", 0, state.updates as f64, "at most 2^31 - 1"))?;
        let moments = [
            ("first moment", &state.first_moment),
            ("second moment", &state.second_moment),
        ];
        for (what, moment) in moments {
            if moment.shape() != entry.value.shape() {
                return Err(ParamError::StateShape {
                    name: name(),
                    what,
                    expected: entry.value.shape().to_vec(),
                    got: moment.shape().to_vec(),
                });
            }
        }
        // Flattened in logical order, whatever the arrays' layout.
        let flat = |a: &ArrayD<F>| -> Vec<F> { a.iter().copied().collect() };
        let (m, v) = (flat(&state.first_moment), flat(&state.second_moment));
        for (what, values) in [("first moment", &m), ("second moment", &v)] {
            if let Some(index) = first_non_finite(values) {
                return Err(invalid(what, index, values[index].as_f64(), "finite"));
            }
        }
        if let Some(index) = v.iter().position(|x| *x < F::zero()) {
            return Err(invalid("second moment", index, v[index].as_f64(), "at least 0"));
        }
        self.slots.restore(params, id, Moments { m, v, t })
    }

    /// Updates in place every parameter of `params` that `grads` holds a gradient for.
    ///
    /// A parameter without a gradient (the backward never reached it, or it was not lent this
    /// step) is skipped: its value and moments stay as they were, and its count of updates
    /// does not advance. Returns how many were updated and skipped.
    ///
    /// Errors, checked for every gradient before anything changes (so on error no parameter
    /// and no moment has changed): [`ParamError::GradientShape`],
    /// [`ParamError::NonFiniteGradient`], [`ParamError::StaleGradient`] (the parameter changed
    /// since the gradient was computed), [`ParamError::InUse`] (a tape still holds the
    /// parameter: clear it first), [`ParamError::ForeignStore`] (this optimiser has stepped
    /// another store).
    pub fn step(&mut self, params: &mut Params<F>, grads: &impl GradientSource<F>) -> Result<StepSummary, ParamError> {
        self.slots.step(&self.config, self.config.lr, params, grads)
    }
}
