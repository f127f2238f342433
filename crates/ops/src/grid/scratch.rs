//! The working memory of the backward into the grid, kept by the field between calls.
//!
//! The scatter copies every lookup into tile order and sums into an f64 buffer the size of
//! the grid (in either precision, so that the gradient's own buffer needs no zeros). Fresh buffers that large come from the system as pages to be faulted
//! in and cleared on every call, which costs more than the sums; kept buffers cost nothing.
//! A [`GridField`](super::GridField) and its clones share one [`Scratch`] (a tape records a
//! clone of the field, so a training loop's steps share it), held until the last of them is
//! dropped or [`GridField::release_buffers`](super::GridField::release_buffers) is called.

use std::any::Any;
use std::fmt;
use std::sync::{Arc, Mutex, PoisonError};

/// Buffers shared by a field and its clones; a call takes them and gives them back, and two
/// calls at once simply allocate for the second.
#[derive(Clone, Default)]
pub(crate) struct Scratch(Arc<Mutex<Kept>>);

#[derive(Default)]
struct Kept {
    /// The sorted blocks of the last call, as `Vec<Sorted<F>>` of the data's type.
    blocks: Option<Box<dyn Any + Send>>,
    /// f64 sums, all zeros (the pass that rounds them clears them).
    zeros: Vec<f64>,
}

impl Scratch {
    fn kept<R>(&self, f: impl FnOnce(&mut Kept) -> R) -> R {
        // The buffers hold no invariant a panic could break but the zeros, which are cleared
        // after their last use: a poisoned lock is still usable.
        f(&mut self.0.lock().unwrap_or_else(PoisonError::into_inner))
    }

    /// The kept blocks if they are of type `T`, else `T::default()`.
    pub(crate) fn take_blocks<T: Default + Send + 'static>(&self) -> T {
        self.kept(|k| k.blocks.take())
            .and_then(|b| b.downcast::<T>().ok())
            .map_or_else(T::default, |b| *b)
    }

    pub(crate) fn give_blocks<T: Send + 'static>(&self, blocks: T) {
        self.kept(|k| k.blocks = Some(Box::new(blocks)));
    }

    /// `len` f64 zeros: the kept ones if there are enough, else fresh ones.
    pub(crate) fn take_zeros(&self, len: usize) -> Vec<f64> {
        let mut v = self.kept(|k| std::mem::take(&mut k.zeros));
        if v.len() >= len {
            v.truncate(len);
            v
        } else {
            fogray_tape::buffer::zeroed(len)
        }
    }

    /// Keeps `zeros` (every value must be 0) for the next call.
    pub(crate) fn give_zeros(&self, zeros: Vec<f64>) {
        debug_assert!(zeros.iter().all(|&v| v == 0.0));
        self.kept(|k| {
            if zeros.len() >= k.zeros.len() {
                k.zeros = zeros;
            }
        });
    }

    /// Drops every kept buffer.
    pub(crate) fn release(&self) {
        self.kept(|k| *k = Kept::default());
    }
}

/// Buffers are not part of what a field is: any two compare equal.
impl PartialEq for Scratch {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl fmt::Debug for Scratch {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("Scratch")
    }
}
