//! The gradient store returned by `backward`, read by handle.

use ndarray::{ArrayD, ArrayViewD, Zip};

use crate::error::Result;
use crate::float::Float;
use crate::params::Lent;
use crate::tape::Tape;
use crate::var::Var;

/// Gradients of one backward sweep, indexed by the handles of the tape that made them.
///
/// Params always keep their gradient; intermediates only if [`Tape::retain`] was called before
/// the sweep. A value the sweep never reached has no entry: [`Gradients::get`] returns `None`,
/// which is not the same as a gradient of zeros.
#[derive(Debug, Clone)]
pub struct Gradients<F: Float> {
    pub(crate) grads: Vec<Option<ArrayD<F>>>,
    pub(crate) epoch: u64,
    /// The parameters the tape had lent, pairing each with its gradient's index.
    pub(crate) lent: Vec<Lent>,
}

impl<F: Float> Gradients<F> {
    /// The gradient of `v`, or `None` if the sweep never reached it (or `v` is stale, or an
    /// intermediate that was not retained).
    pub fn get(&self, v: Var) -> Option<ArrayViewD<'_, F>> {
        if v.epoch != self.epoch {
            return None;
        }
        self.grads.get(v.index()).and_then(|g| g.as_ref()).map(|g| g.view())
    }

    /// The gradient of `v`, or zeros of `v`'s shape if the sweep never reached it.
    pub fn get_or_zeros(&self, tape: &Tape<F>, v: Var) -> Result<ArrayD<F>> {
        let shape = tape.shape(v)?.to_vec();
        Ok(self
            .get(v)
            .map(|g| g.to_owned())
            .unwrap_or_else(|| ArrayD::zeros(shape)))
    }

    /// Moves the gradient of `v` out of the store.
    pub fn take(&mut self, v: Var) -> Option<ArrayD<F>> {
        if v.epoch != self.epoch {
            return None;
        }
        self.grads.get_mut(v.index()).and_then(Option::take)
    }

    /// Adds `g` into the entry at `index`: the first contribution is moved in, later ones are
    /// added in place (no zero-filled buffer is ever allocated).
    pub(crate) fn accumulate(&mut self, index: usize, g: ArrayD<F>) {
        match &mut self.grads[index] {
            slot @ None => *slot = Some(g),
            Some(acc) => {
                Zip::from(acc).and(&g).for_each(|a, &b| *a += b);
                crate::pool::give(g.into_raw_vec_and_offset().0);
            }
        }
    }
}
