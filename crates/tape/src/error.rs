//! Typed errors: [`OpError`] is what an op reports, [`TapeError`] what the tape returns.
//!
//! An op with an error type of its own (the composite's names the ray and the sample at
//! fault) reports it whole as [`OpError::Typed`]; it reaches the caller inside
//! [`TapeError::Op`], and [`TapeError::downcast_ref`] gives it back typed, so `?` can carry it
//! through a pipeline of tape calls without flattening it into a string.

use std::error::Error as StdError;
use std::fmt;
use std::sync::Arc;

use thiserror::Error;

use crate::params::ParamError;

/// An op's own error, kept whole (shared, so that errors stay cheap to clone).
#[derive(Clone)]
pub struct TypedError(Arc<dyn StdError + Send + Sync + 'static>);

impl TypedError {
    /// Wraps any error.
    pub fn new<E: StdError + Send + Sync + 'static>(error: E) -> Self {
        TypedError(Arc::new(error))
    }

    /// The wrapped error as an `E`, if it is one.
    pub fn downcast_ref<E: StdError + 'static>(&self) -> Option<&E> {
        self.0.downcast_ref::<E>()
    }
}

impl fmt::Debug for TypedError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(&self.0, f)
    }
}

impl fmt::Display for TypedError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Display::fmt(&self.0, f)
    }
}

impl StdError for TypedError {
    fn source(&self) -> Option<&(dyn StdError + 'static)> {
        self.0.source()
    }
}

/// Two typed errors are equal when they are the same error or read the same.
impl PartialEq for TypedError {
    fn eq(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.0, &other.0) || self.0.to_string() == other.0.to_string()
    }
}

/// An error raised by an op's forward or backward (built-in or custom).
///
/// The tape wraps it into a [`TapeError`] that carries the op's name.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
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
    /// The op's own typed error (see [`OpError::typed`]).
    #[error(transparent)]
    Typed(TypedError),
}

impl OpError {
    /// Reports an op's own error whole, so that the caller can read it back typed with
    /// [`TapeError::downcast_ref`].
    pub fn typed<E: StdError + Send + Sync + 'static>(error: E) -> Self {
        OpError::Typed(TypedError::new(error))
    }
}

/// Every error the tape returns. A call that fails leaves the tape exactly as it was.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
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
    /// An op failed for another reason: it is not differentiable, or it reported an error of
    /// its own type (read it back with [`TapeError::downcast_ref`]). The message begins with
    /// the op's name once: an op's own error whose message already does is written as it is.
    #[error("{}", OpMessage(.op, .source))]
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
    /// Attaches an op's name to what it reported: shape and argument errors become
    /// [`TapeError::ShapeMismatch`] and [`TapeError::InvalidArgument`], anything else
    /// [`TapeError::Op`].
    pub fn from_op(op: &'static str, e: OpError) -> Self {
        match e {
            OpError::ShapeMismatch { lhs, rhs } => TapeError::ShapeMismatch { op, lhs, rhs },
            OpError::InvalidArgument(reason) => TapeError::InvalidArgument { op, reason },
            source => TapeError::Op { op, source },
        }
    }

    /// The op's own error inside this one, as an `E`, if an op reported one of that type
    /// through [`OpError::typed`].
    ///
    /// ```
    /// use fogray_tape::{OpError, TapeError};
    ///
    /// #[derive(Debug, thiserror::Error)]
    /// #[error("ray {ray}: no samples")]
    /// struct Empty { ray: usize }
    ///
    /// let e = TapeError::from_op("render", OpError::typed(Empty { ray: 3 }));
    /// assert_eq!(e.to_string(), "render: ray 3: no samples");
    /// assert_eq!(e.downcast_ref::<Empty>().map(|e| e.ray), Some(3));
    /// ```
    pub fn downcast_ref<E: StdError + 'static>(&self) -> Option<&E> {
        match self {
            TapeError::Op {
                source: OpError::Typed(t),
                ..
            } => t.downcast_ref(),
            _ => None,
        }
    }
}

/// `op: source`, unless the source's message already begins with `op: ` (an op's own error
/// type that names its op, so that it reads the same alone and through the tape).
struct OpMessage<'a>(&'a str, &'a OpError);

impl fmt::Display for OpMessage<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let OpMessage(op, source) = *self;
        let message = source.to_string();
        let named = message.strip_prefix(op).is_some_and(|rest| rest.starts_with(": "));
        if named {
            f.write_str(&message)
        } else {
            write!(f, "{op}: {message}")
        }
    }
}

/// Shorthand for results of tape calls.
pub type Result<T, E = TapeError> = std::result::Result<T, E>;

#[cfg(test)]
mod tests {
    use super::{OpError, TapeError};

    #[derive(Debug, thiserror::Error)]
    #[error("{0}")]
    struct Said(&'static str);

    #[test]
    fn the_op_name_is_written_once() {
        let said = |m| TapeError::from_op("render", OpError::typed(Said(m))).to_string();
        assert_eq!(said("ray 3: no samples"), "render: ray 3: no samples");
        // An error that names its op already reads the same through the tape.
        assert_eq!(said("render: ray 3: no samples"), "render: ray 3: no samples");
        // Only the whole name followed by ": " counts.
        assert_eq!(said("renderer: ray 3"), "render: renderer: ray 3");
        assert_eq!(said("render"), "render: render");
    }
}
