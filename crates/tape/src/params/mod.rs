//! Parameters that live across training steps: a store the tape borrows from, never copies.
//!
//! A [`Tape`](crate::Tape) is cleared every step, and [`Tape::param`](crate::Tape::param) takes
//! its array by value, so a loop that keeps its parameters outside the tape would copy each of
//! them onto the tape every step (a 128³ × 4 `f32` grid is 33.5 MB). A [`Params`] store holds
//! each parameter behind an `Arc`; [`Tape::param_from`](crate::Tape::param_from) lends it to
//! the tape in O(1) by cloning that `Arc`, whatever its size. [`Tape::clear`](crate::Tape::clear)
//! drops the tape's references (shared arrays never enter the tape's buffer pool), after which
//! the store is again the only owner and an optimiser of [`crate::optim`] updates the
//! parameter in place through `Arc::get_mut`. An update while a tape still holds the array is
//! [`ParamError::InUse`], never a silent copy.
//!
//! Which gradient belongs to which parameter is recorded by the tape, not by the caller: the
//! tape notes every parameter it lends and the [`Gradients`](crate::Gradients) of its backward
//! carry that binding, so an optimiser pairs each gradient with its parameter itself. Each
//! parameter has a version, bumped on every change; a gradient computed at an earlier version
//! (applied twice, say) is [`ParamError::StaleGradient`]. Handles lent on a tape go stale
//! on `clear` like any other [`Var`](crate::Var).
//!
//! Constants that live across steps (targets, a fixed mask) need no store: keep them in an
//! `Arc` and lend them with [`Tape::constant_shared`](crate::Tape::constant_shared).
//!
//! ```
//! use fogray_tape::params::Params;
//! use fogray_tape::Tape;
//! use ndarray::{arr1, Array4};
//!
//! let mut params = Params::<f32>::new();
//! let grid = params.add("grid", Array4::<f32>::zeros((16, 16, 16, 4)))?;
//! let bias = params.add("bias", arr1(&[0.5f32]))?;
//!
//! let mut tape = Tape::<f32>::new();
//! let g = tape.param_from(&params, grid)?; // no copy: the tape shares the store's array
//! let b = tape.param_from(&params, bias)?;
//! assert_eq!(tape.shape(g)?, &[16, 16, 16, 4]);
//! assert_eq!(tape.stats().shared_bytes, (16 * 16 * 16 * 4 + 1) * 4);
//! assert!(params.is_lent(grid)?);
//! // Lent arrays cannot be changed...
//! assert!(params.get_mut(bias).is_err());
//! tape.clear();
//! // ...until the tape gives them back.
//! params.get_mut(bias)?[[0]] = 1.0;
//! assert_eq!(params.get(bias)?[[0]], 1.0);
//! # let _ = b;
//! # Ok::<(), fogray_tape::TapeError>(())
//! ```

mod error;
mod lend;

use std::sync::Arc;

use ndarray::{Array, ArrayD, ArrayViewD, ArrayViewMutD, Dimension};

pub use error::ParamError;
pub(crate) use lend::Lent;

use crate::float::Float;
use crate::var::fresh_epoch;

/// A typed handle to one parameter of one [`Params`] store.
///
/// Ids are `Copy` and carry the identity of their store: using one with another store is
/// [`ParamError::ForeignParam`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ParamId {
    pub(crate) store: u64,
    pub(crate) index: u32,
}

impl ParamId {
    /// Position of the parameter in its store (the order of [`Params::add`]).
    pub fn index(self) -> usize {
        self.index as usize
    }
}

/// One named parameter.
#[derive(Debug)]
pub(crate) struct Entry<F: Float> {
    pub(crate) name: String,
    /// In standard (row-major, contiguous) layout, so optimisers update it as one slice.
    pub(crate) value: Arc<ArrayD<F>>,
    /// Bumped on every change, so gradients computed before one are recognised as stale.
    pub(crate) version: u64,
}

/// Named parameter arrays that live across steps, lent to tapes without copies.
///
/// See the [module documentation](self) for the life of a parameter through a step.
#[derive(Debug)]
pub struct Params<F: Float> {
    pub(crate) store: u64,
    pub(crate) entries: Vec<Entry<F>>,
}

impl<F: Float> Default for Params<F> {
    fn default() -> Self {
        Self::new()
    }
}

impl<F: Float> Params<F> {
    /// An empty store with a process-wide unique identity.
    pub fn new() -> Self {
        Params {
            store: fresh_epoch(),
            entries: Vec::new(),
        }
    }

    /// Adds a parameter of any shape (0-d included) and returns its id.
    ///
    /// The array is kept in standard layout (a transposed or strided array is copied into one,
    /// once, here). Errors: [`ParamError::DuplicateName`] if `name` is taken (names are what
    /// errors report, so they must tell parameters apart).
    pub fn add<D: Dimension>(&mut self, name: impl Into<String>, value: Array<F, D>) -> Result<ParamId, ParamError> {
        let name = name.into();
        if self.entries.iter().any(|e| e.name == name) {
            return Err(ParamError::DuplicateName { name });
        }
        let value = value.into_dyn();
        let value = if value.is_standard_layout() {
            value
        } else {
            value.as_standard_layout().into_owned()
        };
        let id = ParamId {
            store: self.store,
            // A store cannot hold 2^32 entries: each one is a heap allocation and a name.
            index: self.entries.len() as u32,
        };
        self.entries.push(Entry {
            name,
            value: Arc::new(value),
            version: 0,
        });
        Ok(id)
    }

    /// The id of the parameter called `name`, if there is one.
    pub fn id(&self, name: &str) -> Option<ParamId> {
        self.entries.iter().position(|e| e.name == name).map(|i| self.id_at(i))
    }

    /// Every parameter's id, in the order they were added.
    pub fn ids(&self) -> impl Iterator<Item = ParamId> + '_ {
        (0..self.entries.len()).map(|i| self.id_at(i))
    }

    /// The name given to `id` in [`Params::add`]. Errors: [`ParamError::ForeignParam`].
    pub fn name(&self, id: ParamId) -> Result<&str, ParamError> {
        Ok(&self.entry(id)?.name)
    }

    /// The current value of `id` (readable while lent). Errors: [`ParamError::ForeignParam`].
    pub fn get(&self, id: ParamId) -> Result<ArrayViewD<'_, F>, ParamError> {
        Ok(self.entry(id)?.value.view())
    }

    /// The value of `id` for changing in place (a reset, a pruning), which makes gradients
    /// computed before it stale.
    ///
    /// Errors: [`ParamError::InUse`] while a tape holds the array (clear or drop it first),
    /// [`ParamError::ForeignParam`]. Nothing changes on error.
    pub fn get_mut(&mut self, id: ParamId) -> Result<ArrayViewMutD<'_, F>, ParamError> {
        Ok(self.exclusive(id)?.view_mut())
    }

    /// Whether a tape (or a clone of a lent array) still holds `id`'s array.
    /// Errors: [`ParamError::ForeignParam`].
    pub fn is_lent(&self, id: ParamId) -> Result<bool, ParamError> {
        Ok(Arc::strong_count(&self.entry(id)?.value) > 1)
    }

    /// Number of parameters.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether the store holds no parameter.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Bytes of parameter data in the store.
    pub fn bytes(&self) -> usize {
        self.entries
            .iter()
            .map(|e| e.value.len() * std::mem::size_of::<F>())
            .sum()
    }

    /// The entry of `id`, or `ForeignParam`.
    pub(crate) fn entry(&self, id: ParamId) -> Result<&Entry<F>, ParamError> {
        if id.store != self.store {
            return Err(ParamError::ForeignParam { index: id.index });
        }
        // An id of this store indexes an entry that exists: entries are never removed.
        Ok(&self.entries[id.index()])
    }

    /// `id`'s array for an in-place change: bumps its version. Errors: `InUse`, `ForeignParam`.
    pub(crate) fn exclusive(&mut self, id: ParamId) -> Result<&mut ArrayD<F>, ParamError> {
        self.entry(id)?;
        let entry = &mut self.entries[id.index()];
        match Arc::get_mut(&mut entry.value) {
            Some(value) => {
                entry.version += 1;
                Ok(value)
            }
            None => Err(ParamError::InUse {
                name: entry.name.clone(),
            }),
        }
    }

    pub(crate) fn id_at(&self, index: usize) -> ParamId {
        ParamId {
            store: self.store,
            index: index as u32,
        }
    }
}
