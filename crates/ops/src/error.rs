//! Errors of the volume-rendering ops: each names the ray and sample at fault.

use thiserror::Error;

/// Why a composite's input was rejected. Nothing is computed when one is returned.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum CompositeError {
    /// The offsets are not a valid packing (must start at 0 and never decrease).
    #[error("offsets: {0}")]
    Offsets(String),
    /// An array's length or shape does not fit the packing.
    #[error("{what}: expected {expected}, got {got}")]
    Shape {
        /// Which input.
        what: &'static str,
        /// What the packing requires.
        expected: String,
        /// What was given.
        got: String,
    },
    /// A value outside its domain (NaN, infinite, negative density or step...).
    #[error("ray {ray}, sample {sample}: {what} is {value} ({rule})")]
    InvalidSample {
        /// Ray index.
        ray: usize,
        /// Sample index within the ray.
        sample: usize,
        /// Which input (`sigma`, `delta`, `color[1]`, `t`).
        what: String,
        /// The offending value.
        value: f64,
        /// The rule it breaks.
        rule: &'static str,
    },
    /// A background value that is not finite.
    #[error("ray {ray}: background[{channel}] is {value} (must be finite)")]
    InvalidBackground {
        /// Ray index (0 for a shared background).
        ray: usize,
        /// Channel.
        channel: usize,
        /// The offending value.
        value: f64,
    },
    /// A configuration value outside its domain.
    #[error("{0}")]
    Config(String),
}

/// Why a grid field's configuration or input was rejected. Nothing is computed (and nothing
/// of the caller's is changed) when one is returned.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum GridError {
    /// A box axis with a non-finite bound or `min >= max`.
    #[error("box axis {axis}: [{min}, {max}] must be finite with min < max")]
    InvalidBox {
        /// The axis (0 = x, 1 = y, 2 = z).
        axis: usize,
        /// Its lower bound.
        min: f64,
        /// Its upper bound.
        max: f64,
    },
    /// A shape that does not fit: the grid's (fewer than 2 nodes on an axis, no channel, the
    /// wrong number of axes), or an input's against the op's.
    #[error("{what}: expected {expected}, got {got}")]
    Shape {
        /// Which input or setting.
        what: &'static str,
        /// What is required.
        expected: String,
        /// What was given.
        got: String,
    },
    /// A position with a NaN coordinate (a position outside the box, infinite or not, is
    /// valid: it reads zero).
    #[error("position {sample}: coordinate {axis} is NaN")]
    NanPosition {
        /// Index of the position (row of `positions`).
        sample: usize,
        /// Which coordinate.
        axis: usize,
    },
}
