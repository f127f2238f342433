//! Lending arrays to a tape: parameters from a [`Params`] store and shared constants, in O(1).

use std::sync::Arc;

use ndarray::{ArrayD, ArrayViewD};

use super::{ParamId, Params};
use crate::error::Result;
use crate::float::Float;
use crate::gradients::Gradients;
use crate::storage::Storage;
use crate::tape::Tape;
use crate::var::Var;

/// The record of one parameter lent to a tape: which parameter, at which version, as which
/// value. The tape keeps one per lent parameter and its `Gradients` carry a copy.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Lent {
    pub(crate) param: ParamId,
    pub(crate) version: u64,
    pub(crate) value: u32,
}

impl<F: Float> Tape<F> {
    /// A leaf that gradients are computed for, sharing the array of parameter `id` of
    /// `params`: O(1) whatever its size (an `Arc` clone; nothing is copied).
    ///
    /// Lending the same parameter twice in one step returns the same handle, so its gradient
    /// is one entry. The tape records the loan, and the [`Gradients`] of its backward pair the
    /// gradient with `id` (see [`Gradients::param`] and the optimisers of [`crate::optim`]).
    /// The array goes back to the store on [`Tape::clear`] (or when the tape is dropped).
    ///
    /// Errors: [`ParamError::ForeignParam`](super::ParamError::ForeignParam) (as
    /// [`TapeError::Param`](crate::TapeError::Param)) if `id` is not of `params`; the tape is
    /// unchanged.
    pub fn param_from(&mut self, params: &Params<F>, id: ParamId) -> Result<Var> {
        let entry = params.entry(id)?;
        if let Some(lent) = self.lent.iter().find(|l| l.param == id) {
            // While the tape holds the array the store cannot change it: same version.
            return Ok(self.handle(lent.value as usize));
        }
        let var = self.push_leaf(Storage::Shared(Arc::clone(&entry.value)), true);
        self.lent.push(Lent {
            param: id,
            version: entry.version,
            value: var.index,
        });
        Ok(var)
    }

    /// A leaf that never receives a gradient, sharing `value` with the caller: O(1), for
    /// constants that live across steps (targets, masks). The tape drops its reference on
    /// [`Tape::clear`]; the array never enters the buffer pool.
    pub fn constant_shared(&mut self, value: &Arc<ArrayD<F>>) -> Var {
        self.push_leaf(Storage::Shared(Arc::clone(value)), false)
    }
}

impl<F: Float> Gradients<F> {
    /// The gradient of parameter `id`, if the tape that made these gradients lent it (through
    /// [`Tape::param_from`]) and the sweep reached it; `None` otherwise.
    pub fn param(&self, id: ParamId) -> Option<ArrayViewD<'_, F>> {
        let lent = self.lent.iter().find(|l| l.param == id)?;
        self.grads.get(lent.value as usize)?.as_ref().map(|g| g.view())
    }

    /// The gradients of the parameters of store `store` that the sweep reached: which
    /// parameter, at which version it was lent, and the gradient.
    pub(crate) fn of_store(&self, store: u64) -> impl Iterator<Item = (ParamId, u64, ArrayViewD<'_, F>)> + '_ {
        self.lent
            .iter()
            .filter(move |l| l.param.store == store)
            .filter_map(|l| {
                let g = self.grads.get(l.value as usize)?.as_ref()?;
                Some((l.param, l.version, g.view()))
            })
    }
}
