//! Where a tape's time goes, op by op: with profiling on ([`Tape::set_profiling`]), every op's
//! forward and every backward rule the sweep runs are timed and summed under the op's name,
//! across steps, until [`Tape::take_profile`]. A fused op against the taped ops it replaces is
//! then a comparison of two rows of one table, measured in the user's own loop.
//!
//! ```
//! use fogray_tape::Tape;
//!
//! let mut tape = Tape::<f64>::new();
//! tape.set_profiling(true);
//! for _ in 0..3 {
//!     tape.clear();
//!     let x = tape.param(ndarray::arr1(&[1.0, 2.0]));
//!     let y = tape.exp(x)?;
//!     let s = tape.sum(y)?;
//!     let grads = tape.backward(s)?;
//!     tape.recycle(grads);
//! }
//! let profile = tape.take_profile().unwrap();
//! let exp = profile.get("exp").unwrap();
//! assert_eq!((exp.forward_calls, exp.backward_calls), (3, 3));
//! assert!(tape.take_profile().unwrap().is_empty()); // taken: counting starts again
//! # Ok::<(), fogray_tape::TapeError>(())
//! ```
//!
//! [`Tape::set_profiling`]: crate::Tape::set_profiling
//! [`Tape::take_profile`]: crate::Tape::take_profile

use std::collections::BTreeMap;
use std::time::Duration;

/// The summed time of one op (by name) on a profiled tape.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct OpTime {
    /// Successful forward calls.
    pub forward_calls: usize,
    /// Time in those forwards (the op's own computation; the tape's bookkeeping is not counted).
    pub forward: Duration,
    /// Backward rules run by the sweeps (records whose outputs got a gradient).
    pub backward_calls: usize,
    /// Time in those rules, with the adding of their gradients into the inputs' (where a value
    /// used twice has its two contributions summed).
    pub backward: Duration,
}

impl OpTime {
    /// Forward and backward time together.
    pub fn total(&self) -> Duration {
        self.forward + self.backward
    }
}

/// Op times by op name (see the [module docs](self)).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Profile {
    ops: BTreeMap<&'static str, OpTime>,
}

impl Profile {
    /// The times of the op named `name`, if it ran.
    pub fn get(&self, name: &str) -> Option<OpTime> {
        self.ops.get(name).copied()
    }

    /// Every op that ran, by name in alphabetical order.
    pub fn iter(&self) -> impl Iterator<Item = (&'static str, OpTime)> + '_ {
        self.ops.iter().map(|(&name, &t)| (name, t))
    }

    /// Every op that ran, the most time first (ties by name).
    pub fn by_time(&self) -> Vec<(&'static str, OpTime)> {
        let mut rows: Vec<_> = self.iter().collect();
        rows.sort_by(|a, b| b.1.total().cmp(&a.1.total()).then(a.0.cmp(b.0)));
        rows
    }

    /// Whether no op has run since profiling started or the profile was last taken.
    pub fn is_empty(&self) -> bool {
        self.ops.is_empty()
    }

    /// The forward time of every op.
    pub fn forward(&self) -> Duration {
        self.ops.values().map(|t| t.forward).sum()
    }

    /// The backward time of every op.
    pub fn backward(&self) -> Duration {
        self.ops.values().map(|t| t.backward).sum()
    }

    pub(crate) fn add_forward(&mut self, name: &'static str, time: Duration) {
        let t = self.ops.entry(name).or_default();
        t.forward_calls += 1;
        t.forward += time;
    }

    pub(crate) fn add_backward(&mut self, name: &'static str, time: Duration) {
        let t = self.ops.entry(name).or_default();
        t.backward_calls += 1;
        t.backward += time;
    }
}
