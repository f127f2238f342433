//! [`ParamError`]: what a parameter store or an optimiser rejects.

use thiserror::Error;

/// An error from a [`Params`](super::Params) store or an optimiser of
/// [`crate::optim`]. A call that fails changes no parameter and no optimiser state.
#[non_exhaustive]
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ParamError {
    /// The [`ParamId`](super::ParamId) was made by another store.
    #[error("parameter #{index} belongs to another parameter store")]
    ForeignParam {
        /// The id's index in the store that made it.
        index: u32,
    },
    /// [`Params::add`](super::Params::add) was given a name the store already holds.
    #[error("the store already holds a parameter named {name:?}")]
    DuplicateName {
        /// The name.
        name: String,
    },
    /// The parameter is still lent to a tape, so it cannot be changed in place.
    #[error("parameter {name:?} is still lent to a tape: clear() or drop the tape before updating it")]
    InUse {
        /// The parameter's name.
        name: String,
    },
    /// A gradient's shape is not its parameter's.
    #[error("gradient for parameter {name:?} has shape {got:?}, the parameter has {expected:?}")]
    GradientShape {
        /// The parameter's name.
        name: String,
        /// The parameter's shape.
        expected: Vec<usize>,
        /// The gradient's shape.
        got: Vec<usize>,
    },
    /// A gradient holds a NaN or an infinity, which would poison the optimiser's state.
    #[error("gradient for parameter {name:?} is not finite at flat index {index} ({value})")]
    NonFiniteGradient {
        /// The parameter's name.
        name: String,
        /// Position of the first offending element in the gradient's logical order.
        index: usize,
        /// The offending element, widened to `f64`.
        value: f64,
    },
    /// The gradient was computed at an earlier value of the parameter: it was updated (or
    /// changed through [`Params::get_mut`](super::Params::get_mut)) after it was lent.
    #[error("gradient for parameter {name:?} is stale: the parameter changed after the step that computed it")]
    StaleGradient {
        /// The parameter's name.
        name: String,
    },
    /// An optimiser was given a store other than the one it has been stepping.
    #[error("this optimiser holds state for another parameter store")]
    ForeignStore,
    /// An optimiser setting is outside its range.
    #[error("{setting} must be {range}, got {value}")]
    InvalidSetting {
        /// The setting's name.
        setting: &'static str,
        /// The accepted range, in words.
        range: &'static str,
        /// The value given.
        value: f64,
    },
    /// Optimiser state given to a `restore` does not have its parameter's shape.
    #[error("optimiser state for parameter {name:?}: {what} has shape {got:?}, the parameter has {expected:?}")]
    StateShape {
        /// The parameter's name.
        name: String,
        /// Which part of the state.
        what: &'static str,
        /// The parameter's shape.
        expected: Vec<usize>,
        /// The state's shape.
        got: Vec<usize>,
    },
    /// Optimiser state given to a `restore` holds a value no run of the optimiser can reach
    /// (a NaN, an infinity, a negative second moment, a count too large).
    #[error("optimiser state for parameter {name:?}: {what} at flat index {index} is {value}, which must be {range}")]
    InvalidState {
        /// The parameter's name.
        name: String,
        /// Which part of the state.
        what: &'static str,
        /// Position of the first offending element (0 for a count).
        index: usize,
        /// The offending value, widened to `f64`.
        value: f64,
        /// What it must be, in words.
        range: &'static str,
    },
}
