//! Errors of the volume-rendering ops: each names the ray and sample at fault.

use fogray_tape::{OffsetsError, OpError, TapeError};
use thiserror::Error;

/// Why a composite's input was rejected. Nothing is computed when one is returned.
///
/// Through a tape it arrives inside [`TapeError::Op`], whole:
/// `err.downcast_ref::<CompositeError>()` gives back the ray and the sample. It converts into
/// a [`TapeError`] (and an [`OpError`]), so `?` works in a function that mixes tape calls and
/// composite calls.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum CompositeError {
    /// The offsets are not a valid packing (must start at 0 and never decrease).
    #[error("offsets: {0}")]
    Offsets(#[from] OffsetsError),
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
    /// An optional input, upstream gradient, buffer or wanted gradient that the op's
    /// configuration requires and was not given, or that it has no use for and was given (a
    /// background with [`Background::None`](crate::Background::None), `t` without depth...).
    #[error("{what}: {problem}")]
    Mismatch {
        /// Which argument (`"background"`, `"t"`, `"depth buffer"`, ...).
        what: &'static str,
        /// What is wrong with it, given the configuration.
        problem: &'static str,
    },
}

/// Why a camera, a box or a batch of rays was rejected. Nothing is built when one is returned.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum GeometryError {
    /// An image with no pixel (`width` or `height` is 0).
    #[error("image size {width}x{height}: both must be at least 1")]
    EmptyImage {
        /// Pixels per row.
        width: usize,
        /// Rows.
        height: usize,
    },
    /// A number outside its domain (NaN, infinite, a zero focal length...).
    #[error("{what} is {value} ({rule})")]
    InvalidValue {
        /// Which value.
        what: String,
        /// The offending value.
        value: f64,
        /// The rule it breaks.
        rule: &'static str,
    },
    /// A camera-to-world transform that cannot place a camera.
    #[error("camera-to-world transform: {0}")]
    Transform(String),
    /// A box whose bounds are not finite or not increasing on some axis.
    #[error("box axis {axis}: min {min}, max {max} (must be finite with min < max)")]
    InvalidBox {
        /// Axis (0 = x, 1 = y, 2 = z).
        axis: usize,
        /// Lower bound given.
        min: f64,
        /// Upper bound given.
        max: f64,
    },
    /// An array whose shape does not fit.
    #[error("{what}: expected {expected}, got {got}")]
    Shape {
        /// Which input.
        what: &'static str,
        /// What was required.
        expected: String,
        /// What was given.
        got: String,
    },
    /// A pixel or camera index out of range.
    #[error("{what} {index} is out of range (must be below {len})")]
    OutOfRange {
        /// `"pixel"` or `"camera"`.
        what: &'static str,
        /// The index given.
        index: usize,
        /// The number of valid indices.
        len: usize,
    },
    /// A `look_at` whose eye, target and up do not define a frame.
    #[error("look_at: {0}")]
    Degenerate(String),
}

/// Why a sampler or the occupancy grid rejected its input. Nothing is returned or changed
/// when one is returned.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum SampleError {
    /// A configuration value outside its domain (a step that is not positive, no samples...).
    #[error("{what} is {value} ({rule})")]
    Config {
        /// Which setting.
        what: &'static str,
        /// The offending value.
        value: f64,
        /// The rule it breaks.
        rule: &'static str,
    },
    /// Arrays that do not fit each other.
    #[error("{what}: expected {expected}, got {got}")]
    Shape {
        /// Which input.
        what: &'static str,
        /// What was required.
        expected: String,
        /// What was given.
        got: String,
    },
    /// A per-ray or per-sample value outside its domain.
    #[error("ray {ray}: {what} is {value} ({rule})")]
    InvalidValue {
        /// Ray index (or cell index for densities).
        ray: usize,
        /// Which value.
        what: String,
        /// The offending value.
        value: f64,
        /// The rule it breaks.
        rule: &'static str,
    },
    /// The caller's density function failed or returned something unusable.
    #[error("density function: {0}")]
    Density(String),
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

/// Why the density/colour activation rejected its input or its configuration. Nothing is
/// computed (and nothing of the caller's is changed) when one is returned.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum ActivationError {
    /// A shift that is not finite.
    #[error("shift is {value} (must be finite)")]
    InvalidShift {
        /// The offending value.
        value: f64,
    },
    /// An array whose shape does not fit: raw values not `[n, k]` with `k >= 2`, or an
    /// output or gradient not of the shape the raw values give.
    #[error("{what}: expected {expected}, got {got}")]
    Shape {
        /// Which input or output.
        what: &'static str,
        /// What is required.
        expected: String,
        /// What was given.
        got: String,
    },
    /// A NaN raw value (infinities are valid: they saturate).
    #[error("raw value at row {row}, channel {channel} is NaN")]
    NanRaw {
        /// Row of the raw values.
        row: usize,
        /// Channel (0 is the density).
        channel: usize,
    },
}

/// Why the spherical-harmonics colour op ([`ShColor`](crate::ShColor)) rejected its
/// configuration or its input. Nothing is computed (and nothing of the caller's is changed)
/// when one is returned.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum ShError {
    /// A degree above 3 (the basis is written out to degree 3).
    #[error("degree {degree} is not supported (must be 0, 1, 2 or 3)")]
    Degree {
        /// The degree given.
        degree: usize,
    },
    /// An array whose shape does not fit: coefficients not `[n, 3 (degree + 1)^2]`,
    /// directions not `[n, 3]` (with the coefficients' `n`), or an upstream gradient not
    /// `[n, 3]`.
    #[error("{what}: expected {expected}, got {got}")]
    Shape {
        /// Which input.
        what: &'static str,
        /// What is required.
        expected: String,
        /// What was given.
        got: String,
    },
    /// A coefficient or a direction component that is NaN or infinite.
    #[error("{what} at row {row}, column {column} is {value} (must be finite)")]
    NonFinite {
        /// `"coefficient"` or `"direction"`.
        what: &'static str,
        /// Row (sample).
        row: usize,
        /// Column.
        column: usize,
        /// The offending value.
        value: f64,
    },
    /// A direction whose length is not 1 within `1e-3`.
    #[error("direction at row {row} has length {norm} (must be 1 within 1e-3)")]
    NotUnit {
        /// Row (sample).
        row: usize,
        /// Its Euclidean length.
        norm: f64,
    },
}

/// Why a prior's configuration or input was rejected. Nothing is computed (and nothing of the
/// caller's is changed) when one is returned.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum PriorError {
    /// A weight that is negative or not finite.
    #[error("weight is {value} (must be finite and non-negative)")]
    InvalidWeight {
        /// The offending value.
        value: f64,
    },
    /// An array whose shape does not fit.
    #[error("{what}: expected {expected}, got {got}")]
    Shape {
        /// Which input or output.
        what: &'static str,
        /// What is required.
        expected: String,
        /// What was given.
        got: String,
    },
}

/// Each op's error as the tape's, naming the op it came from.
macro_rules! tape_error_from {
    ($($error:ty => $op:literal),* $(,)?) => {
        $(impl From<$error> for TapeError {
            fn from(e: $error) -> Self {
                TapeError::from_op($op, OpError::typed(e))
            }
        })*
    };
}

tape_error_from! {
    PriorError => "total_variation",
    ActivationError => "density_color",
    ShError => "sh_color",
    GridError => "grid_field",
    GeometryError => "rays",
    SampleError => "sample",
    CompositeError => "composite",
}

impl From<CompositeError> for OpError {
    fn from(e: CompositeError) -> Self {
        OpError::typed(e)
    }
}

#[cfg(test)]
mod tests {
    use fogray_tape::{Tape, TapeError};
    use ndarray::{arr1, arr2};

    use super::CompositeError;
    use crate::{Composite, CompositeInputs};

    /// A pipeline mixing composite construction, tape ops and the composite's forward.
    fn pipeline(offsets: &[usize], sigma0: f64) -> Result<f64, TapeError> {
        let op = Composite::new(offsets)?;
        let mut tape = Tape::<f64>::new();
        let raw = tape.param(arr1(&[sigma0, 1.0]));
        let sigma = tape.mul_scalar(raw, 2.0)?;
        let delta = tape.constant(arr1(&[0.5, 0.5]));
        let color = tape.constant(arr2(&[[1.0], [0.0]]));
        let background = Some(tape.constant(arr1(&[0.0])));
        let out = op.apply(
            &mut tape,
            &CompositeInputs {
                sigma,
                delta,
                color,
                background,
                t: None,
            },
        )?;
        Ok(tape.value(out.color)?[[0, 0]])
    }

    #[test]
    fn question_mark_carries_the_composite_error_whole_through_a_pipeline() {
        // 1 - exp(-2 * 0.5 * 1) of the front sample's colour 1.
        let c = pipeline(&[0, 2], 1.0).unwrap();
        assert!((c - (1.0 - (-1.0f64).exp())).abs() < 1e-15);
        let bad_offsets = pipeline(&[0, 3, 2], 1.0).unwrap_err();
        assert!(matches!(
            bad_offsets.downcast_ref::<CompositeError>(),
            Some(CompositeError::Offsets(_))
        ));
        let bad_value = pipeline(&[0, 1, 2], -1.0).unwrap_err();
        match bad_value.downcast_ref::<CompositeError>() {
            Some(CompositeError::InvalidSample { ray, sample, .. }) => assert_eq!((*ray, *sample), (0, 0)),
            other => panic!("{other:?}"),
        }
        assert!(bad_value
            .to_string()
            .starts_with("composite: ray 0, sample 0: sigma is -2"));
    }
}
