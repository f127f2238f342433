//! Typed errors: [`OpError`] is what an op reports, [`TapeError`] what the tape returns.

use thiserror::Error;

use crate::params::ParamError;

/// An error raised by an op's forward or backward (built-in or custom).
///
/// The tape wraps it into a [`TapeError`] that carries the op's name.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum OpError {
    /// Two shapes that the op needs to agree do not.
    #[error("shapes {lhs:?} and {rhs:?} do not agree")]
    ShapeMismatch {
        /// The first (or expected) shape.
        lhs: Vec<usize>,
        /// The second (or offending) shape.
        rhs: Vec<usize>,
    },
    /// An argument is outside what the op accepts; the text says which and why.
    #[error("{0}")]
    InvalidArgument(String),
    /// The op has no backward; differentiating through it is an error, never a silent zero.
    #[error("the op is not differentiable")]
    NotDifferentiable,
}

/// Every error the tape returns. A call that fails leaves the tape exactly as it was.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum TapeError {
    /// An op received operands whose shapes do not agree.
    #[error("{op}: shapes {lhs:?} and {rhs:?} do not agree")]
    ShapeMismatch {
        /// The op's name.
        op: &'static str,
        /// The first (or expected) shape.
        lhs: Vec<usize>,
        /// The second (or offending) shape.
        rhs: Vec<usize>,
    },
    /// An op received an argument it does not accept.
    #[error("{op}: {reason}")]
    InvalidArgument {
        /// The op's name.
        op: &'static str,
        /// What is wrong, in words.
        reason: String,
    },
    /// The handle belongs to another tape, or to this tape before a `clear()`.
    #[error("stale variable: handle #{index} of epoch {epoch} is not on this tape (epoch {tape_epoch})")]
    StaleVar {
        /// The handle's index.
        index: u32,
        /// The handle's epoch.
        epoch: u64,
        /// The tape's current epoch.
        tape_epoch: u64,
    },
    /// `backward` needs a one-element output; use `backward_with` and a seed otherwise.
    #[error("backward needs a one-element output, got shape {shape:?} (use backward_with)")]
    NotScalar {
        /// The output's shape.
        shape: Vec<usize>,
    },
    /// A backward returned a gradient list of the wrong length.
    #[error("{op}: backward returned {got} gradients for {expected} inputs")]
    BadGradientCount {
        /// The op's name.
        op: &'static str,
        /// Number of inputs of the op.
        expected: usize,
        /// Number of gradients returned.
        got: usize,
    },
    /// A backward returned a gradient whose shape is not its input's.
    #[error("{op}: gradient for input {input} has shape {got:?}, the input has {expected:?}")]
    BadGradient {
        /// The op's name.
        op: &'static str,
        /// Which input.
        input: usize,
        /// The input's shape.
        expected: Vec<usize>,
        /// The returned gradient's shape.
        got: Vec<usize>,
    },
    /// An op failed for another reason (for example it is not differentiable).
    #[error("{op}: {source}")]
    Op {
        /// The op's name.
        op: &'static str,
        /// What the op reported.
        source: OpError,
    },
    /// A parameter store or an optimiser rejected the call (see [`ParamError`]); it converts
    /// with `?`, so a training loop can return one error type.
    #[error(transparent)]
    Param(#[from] ParamError),
}

impl TapeError {
    /// Attaches an op's name to what it reported.
    pub(crate) fn from_op(op: &'static str, e: OpError) -> Self {
        match e {
            OpError::ShapeMismatch { lhs, rhs } => TapeError::ShapeMismatch { op, lhs, rhs },
            OpError::InvalidArgument(reason) => TapeError::InvalidArgument { op, reason },
            source => TapeError::Op { op, source },
        }
    }
}

/// Shorthand for results of tape calls.
pub type Result<T, E = TapeError> = std::result::Result<T, E>;
