//! `Var`: a cheap, copyable handle to a value on a tape.

use std::sync::atomic::{AtomicU64, Ordering};

/// A handle to one value on a [`Tape`](crate::Tape): an index plus the tape's epoch.
///
/// Handles are `Copy` and carry no lifetime. A handle from another tape, or from this tape
/// before [`Tape::clear`](crate::Tape::clear), is rejected with
/// [`TapeError::StaleVar`](crate::TapeError::StaleVar) instead of reading someone else's value.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Var {
    pub(crate) index: u32,
    pub(crate) epoch: u64,
}

impl Var {
    /// Position of the value on its tape (creation order).
    pub fn index(self) -> usize {
        self.index as usize
    }
}

static NEXT_EPOCH: AtomicU64 = AtomicU64::new(1);

/// A process-wide fresh epoch: every new or cleared tape gets one, so no two tapes share one.
pub(crate) fn fresh_epoch() -> u64 {
    NEXT_EPOCH.fetch_add(1, Ordering::Relaxed)
}
