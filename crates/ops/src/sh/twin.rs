//! The op written with tape primitives only: the basis of each direction as a constant
//! `[n, 1, B]`, the coefficients reshaped to `[n, 3, B]`, multiplied (broadcasting), summed
//! over the basis axis and passed through the tape's own sigmoid: four records instead of one.
//! The fused op is checked against it.

use fogray_tape::{Float, Tape, TapeError, Var};

use crate::error::{Op, OpsError};
use ndarray::{Array3, ArrayView2, Ix2};

use super::basis::basis;
use super::check::{check_shapes, check_values};
use super::config::ShColor;

/// Records `op`'s colour of `coeffs` (`[n, 3 B]`) along `directions` (`[n, 3]`, unit
/// vectors, read as constants) with the tape's own ops.
///
/// Errors (the tape is unchanged): those of [`ShColor::evaluate`] (the
/// [`OpsError`](crate::OpsError) inside [`TapeError::Op`]), a stale handle.
pub fn sh_color<F: Float>(tape: &mut Tape<F>, op: &ShColor, coeffs: Var, directions: Var) -> Result<Var, TapeError> {
    let b = op.basis_count();
    let y = {
        let c = tape.value(coeffs)?;
        let d = tape.value(directions)?;
        let c = c.into_dimensionality::<Ix2>().map_err(|_| {
            OpsError::shape_of(
                Op::ShColor,
                "coefficients",
                "[n, 3 (degree + 1)^2]",
                tape.shape(coeffs).unwrap_or(&[]),
            )
        })?;
        let d: ArrayView2<'_, F> = d.into_dimensionality::<Ix2>().map_err(|_| {
            OpsError::shape_of(
                Op::ShColor,
                "directions",
                "[n, 3]",
                tape.shape(directions).unwrap_or(&[]),
            )
        })?;
        let n = check_shapes(op.degree(), b, &c, &d)?;
        check_values(&c, &d)?;
        Array3::from_shape_fn((n, 1, b), |(i, _, k)| {
            F::lit(basis([d[[i, 0]].as_f64(), d[[i, 1]].as_f64(), d[[i, 2]].as_f64()])[k])
        })
    };
    let n = y.shape()[0];
    let y = tape.constant(y);
    let c = tape.reshape(coeffs, &[n, 3, b])?;
    let x = tape.mul(c, y)?;
    let x = tape.sum_axis(x, 2)?;
    tape.sigmoid(x)
}
