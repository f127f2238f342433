//! What every optimiser shares: per-parameter state and learning-rate scales, and a step that
//! checks every gradient before it changes anything.

use std::sync::Arc;

use ndarray::CowArray;

use super::chunks::first_non_finite;
use super::source::GradientSource;
use super::StepSummary;
use crate::float::Float;
use crate::params::{ParamError, ParamId, Params};

/// An update rule: how one parameter moves given its gradient and its state.
pub(crate) trait Rule<F: Float> {
    /// Per-parameter state (moments, a step count).
    type State;
    /// The state of a parameter of `len` elements before its first update.
    fn new_state(&self, len: usize) -> Self::State;
    /// Updates `x` in place from gradient `g` (same length) with learning rate `lr`.
    fn update(&self, x: &mut [F], g: &[F], state: &mut Self::State, lr: f64);
}

/// Per-parameter state of an optimiser, bound to one store on first use.
#[derive(Debug, Clone)]
pub(crate) struct Slots<S> {
    store: Option<u64>,
    states: Vec<Option<S>>,
    lr_scales: Vec<f64>,
}

impl<S> Default for Slots<S> {
    fn default() -> Self {
        Slots {
            store: None,
            states: Vec::new(),
            lr_scales: Vec::new(),
        }
    }
}

impl<S> Slots<S> {
    pub(crate) fn check_store(&self, store: u64) -> Result<(), ParamError> {
        match self.store {
            Some(s) if s != store => Err(ParamError::ForeignStore),
            _ => Ok(()),
        }
    }

    /// Sets `id`'s learning-rate factor; binds the optimiser to `id`'s store.
    pub(crate) fn set_lr_scale(&mut self, id: ParamId, scale: f64) -> Result<(), ParamError> {
        self.check_store(id.store)?;
        super::check_range("lr scale", scale, scale >= 0.0, "finite and at least 0")?;
        self.store = Some(id.store);
        if self.lr_scales.len() <= id.index() {
            self.lr_scales.resize(id.index() + 1, 1.0);
        }
        self.lr_scales[id.index()] = scale;
        Ok(())
    }

    /// Whether parameter `id` has state (it has been updated at least once).
    pub(crate) fn state(&self, id: ParamId) -> Option<&S> {
        if self.store != Some(id.store) {
            return None;
        }
        self.states.get(id.index())?.as_ref()
    }

    /// Replaces parameter `id`'s state with `state` (already checked by the caller); binds the
    /// optimiser to `params`. Errors: `ForeignStore`, `ForeignParam`; nothing changes on error.
    pub(crate) fn restore<F: Float>(&mut self, params: &Params<F>, id: ParamId, state: S) -> Result<(), ParamError> {
        self.check_store(params.store)?;
        params.entry(id)?;
        self.store = Some(params.store);
        if self.states.len() < params.len() {
            self.states.resize_with(params.len(), || None);
        }
        self.states[id.index()] = Some(state);
        Ok(())
    }

    /// One step of `rule` at learning rate `lr` on every parameter of `params` that `grads`
    /// has a gradient for. Every gradient is checked (store, version, shape, finiteness, the
    /// array not lent) before the first parameter changes.
    pub(crate) fn step<F: Float, R: Rule<F, State = S>>(
        &mut self,
        rule: &R,
        lr: f64,
        params: &mut Params<F>,
        grads: &impl GradientSource<F>,
    ) -> Result<StepSummary, ParamError> {
        self.check_store(params.store)?;
        let mut planned: Vec<(ParamId, CowArray<'_, F, ndarray::IxDyn>)> = Vec::new();
        for (id, version, g) in grads.for_store(params.store) {
            let entry = params.entry(id)?;
            let name = || entry.name.clone();
            if version != entry.version {
                return Err(ParamError::StaleGradient { name: name() });
            }
            if g.shape() != entry.value.shape() {
                return Err(ParamError::GradientShape {
                    name: name(),
                    expected: entry.value.shape().to_vec(),
                    got: g.shape().to_vec(),
                });
            }
            if Arc::strong_count(&entry.value) > 1 {
                return Err(ParamError::InUse { name: name() });
            }
            // Gradients are contiguous as ops make them; a strided one is copied once here.
            let g = if g.is_standard_layout() {
                CowArray::from(g)
            } else {
                CowArray::from(g.as_standard_layout().into_owned())
            };
            let flat = g.as_slice().expect("a standard-layout array is one slice");
            if let Some(index) = first_non_finite(flat) {
                return Err(ParamError::NonFiniteGradient {
                    name: name(),
                    index,
                    value: flat[index].as_f64(),
                });
            }
            planned.push((id, g));
        }
        self.store = Some(params.store);
        if self.states.len() < params.len() {
            self.states.resize_with(params.len(), || None);
        }
        for (id, g) in &planned {
            let x = params.exclusive(*id)?;
            let x = x.as_slice_mut().expect("parameters are kept in standard layout");
            let g = g.as_slice().expect("made standard above");
            let state = self.states[id.index()].get_or_insert_with(|| rule.new_state(x.len()));
            let scale = self.lr_scales.get(id.index()).copied().unwrap_or(1.0);
            rule.update(x, g, state, lr * scale);
        }
        Ok(StepSummary {
            updated: planned.len(),
            without_gradient: params.len() - planned.len(),
        })
    }
}
