//! Where a tape value's elements live: in a buffer the tape owns, or in an array it shares
//! with a parameter store or a caller that keeps it across steps.

use std::sync::Arc;

use ndarray::{ArrayD, ArrayViewD};

use crate::float::Float;

/// A value's elements. Shared arrays are lent in O(1) (an `Arc` clone) and are never put in
/// the buffer pool: the tape gives its reference back on `clear` and the owner keeps them.
#[derive(Debug)]
pub(crate) enum Storage<F: Float> {
    /// Made on the tape (an op's output, `param`, `constant`); recycled through the pool.
    Owned(ArrayD<F>),
    /// Lent by a [`Params`](crate::params::Params) store or through [`Tape::constant_shared`](crate::Tape::constant_shared).
    Shared(Arc<ArrayD<F>>),
}

impl<F: Float> Storage<F> {
    pub(crate) fn view(&self) -> ArrayViewD<'_, F> {
        self.array().view()
    }

    pub(crate) fn shape(&self) -> &[usize] {
        self.array().shape()
    }

    pub(crate) fn len(&self) -> usize {
        self.array().len()
    }

    pub(crate) fn is_shared(&self) -> bool {
        matches!(self, Storage::Shared(_))
    }

    fn array(&self) -> &ArrayD<F> {
        match self {
            Storage::Owned(a) => a,
            Storage::Shared(a) => a,
        }
    }
}
