//! Where an optimiser's gradients come from: a tape's [`Gradients`], or gradients given per
//! parameter in a [`ParamGradients`] (for a gradient computed without a tape).

use ndarray::{Array, ArrayD, ArrayViewD, Dimension};

use crate::float::Float;
use crate::gradients::Gradients;
use crate::params::{ParamError, ParamId, Params};

pub(crate) mod sealed {
    use ndarray::ArrayViewD;

    use crate::float::Float;
    use crate::params::ParamId;

    /// One parameter's gradient: which parameter, the version it was computed at, the values.
    pub type Item<'a, F> = (ParamId, u64, ArrayViewD<'a, F>);

    /// The gradients a source holds for the parameters of one store.
    pub trait Source<F: Float> {
        /// Every gradient for a parameter of store `store`, at most one per parameter.
        fn for_store(&self, store: u64) -> Vec<Item<'_, F>>;
    }
}

/// What an optimiser's `step` accepts: [`Gradients`] from a tape's backward (paired with the
/// parameters the tape lent through [`Tape::param_from`](crate::Tape::param_from)) or a
/// [`ParamGradients`]. Sealed: those two are the only sources.
pub trait GradientSource<F: Float>: sealed::Source<F> {}

impl<F: Float> sealed::Source<F> for Gradients<F> {
    fn for_store(&self, store: u64) -> Vec<sealed::Item<'_, F>> {
        self.of_store(store).collect()
    }
}
impl<F: Float> GradientSource<F> for Gradients<F> {}

/// Gradients given by parameter, for a gradient that no tape computed (a finite difference,
/// a hand-derived formula). Each records the version of the parameter when it was inserted,
/// so it goes stale, as a tape's does, once the parameter changes.
#[derive(Debug, Clone, Default)]
pub struct ParamGradients<F: Float> {
    entries: Vec<(ParamId, u64, ArrayD<F>)>,
}

impl<F: Float> ParamGradients<F> {
    /// No gradients.
    pub fn new() -> Self {
        ParamGradients { entries: Vec::new() }
    }

    /// Sets the gradient of parameter `id` of `params` (replacing an earlier one for `id`),
    /// stamped with the parameter's current version. Its shape is checked by the optimiser's
    /// `step`, with the others, before anything changes.
    ///
    /// Errors: [`ParamError::ForeignParam`] if `id` is not of `params`; nothing is inserted.
    pub fn insert<D: Dimension>(
        &mut self,
        params: &Params<F>,
        id: ParamId,
        grad: Array<F, D>,
    ) -> Result<(), ParamError> {
        let version = params.entry(id)?.version;
        let grad = (id, version, grad.into_dyn());
        match self.entries.iter_mut().find(|e| e.0 == id) {
            Some(slot) => *slot = grad,
            None => self.entries.push(grad),
        }
        Ok(())
    }

    /// The gradient set for `id`, if any.
    pub fn get(&self, id: ParamId) -> Option<ArrayViewD<'_, F>> {
        self.entries.iter().find(|e| e.0 == id).map(|e| e.2.view())
    }

    /// Number of parameters with a gradient.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether no gradient is set.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }
}

impl<F: Float> sealed::Source<F> for ParamGradients<F> {
    fn for_store(&self, store: u64) -> Vec<sealed::Item<'_, F>> {
        self.entries
            .iter()
            .filter(|e| e.0.store == store)
            .map(|e| (e.0, e.1, e.2.view()))
            .collect()
    }
}
impl<F: Float> GradientSource<F> for ParamGradients<F> {}
