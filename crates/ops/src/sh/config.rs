//! The op's configuration (its degree) and how it is applied to a tape.

use fogray_tape::{Float, Tape, TapeError, Var};

use super::basis::{basis_count, MAX_DEGREE};
use crate::error::{Op, OpsError};

/// View-dependent colour from spherical-harmonics coefficients (see the [module docs](super)):
/// coefficients `[n, 3 B]` and unit directions `[n, 3]` to a colour `[n, 3]`,
/// `sigmoid(sum_b coeffs[i, c B + b] Y_b(d_i))`, with `B = (degree + 1)^2`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ShColor {
    degree: usize,
}

impl ShColor {
    /// The op of `degree` (0 to 3: 1, 4, 9 or 16 basis functions a channel).
    ///
    /// Errors: a degree above 3 ([`OpsError::Config`]).
    pub fn new(degree: usize) -> Result<Self, OpsError> {
        if degree > MAX_DEGREE {
            return Err(OpsError::config(
                Op::ShColor,
                "degree",
                degree as f64,
                "must be 0, 1, 2 or 3",
            ));
        }
        Ok(ShColor { degree })
    }

    /// The degree.
    pub fn degree(&self) -> usize {
        self.degree
    }

    /// Basis functions a channel, `B = (degree + 1)^2`.
    pub fn basis_count(&self) -> usize {
        basis_count(self.degree)
    }

    /// Coefficients a row, `3 B` (channel-major: channel `c`'s are columns `c B .. (c + 1) B`).
    pub fn coefficient_count(&self) -> usize {
        3 * self.basis_count()
    }

    /// Records the colour of `coeffs` (`[n, 3 B]`) seen along `directions` (`[n, 3]`, unit
    /// vectors) on `tape` as one op through the tape's public custom-op interface; its
    /// backward gives `dL/dcoeffs`. The directions are treated as constants: no gradient flows
    /// to them, even where they are params.
    ///
    /// Errors (the tape is unchanged): shapes that do not fit, a non-finite value, a direction
    /// that is not a unit vector (the [`OpsError`] itself inside [`TapeError::Op`], read back
    /// with [`TapeError::downcast_ref`]), or a stale handle.
    pub fn apply<F: Float>(&self, tape: &mut Tape<F>, coeffs: Var, directions: Var) -> Result<Var, TapeError> {
        tape.apply1(*self, &[coeffs, directions])
    }
}
