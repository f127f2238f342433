//! Errors of the volume-rendering ops: each names the ray and sample at fault.

use fogray_tape::{OpError, TapeError};
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

impl From<CompositeError> for OpError {
    fn from(e: CompositeError) -> Self {
        OpError::typed(e)
    }
}

impl From<CompositeError> for TapeError {
    fn from(e: CompositeError) -> Self {
        TapeError::from_op("composite", e.into())
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
