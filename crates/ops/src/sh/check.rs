//! Validation of the op's inputs: shapes, finiteness, unit directions. Valid input (the common
//! case) is read in parallel with a fold; the first fault is looked for only once one is known
//! to be there, so the error names the first row at fault.

use fogray_tape::Float;
use ndarray::ArrayView2;
use rayon::prelude::*;

use super::kernel::CHUNK;
use crate::error::{At, Op, OpsError};

/// How far from 1 a direction's length may be.
pub(crate) const UNIT_TOLERANCE: f64 = 1e-3;

/// A coefficient or a direction component (`what`) that is NaN or infinite.
fn non_finite(what: &'static str, row: usize, column: usize, value: f64) -> OpsError {
    OpsError::domain(Op::ShColor, At::Entry { row, column }, what, value, "must be finite")
}

/// Checks the shapes of `coeffs` (`[n, 3 b]`) and `directions` (`[n, 3]`); returns `n`.
pub(crate) fn check_shapes<F: Float>(
    degree: usize,
    b: usize,
    coeffs: &ArrayView2<'_, F>,
    directions: &ArrayView2<'_, F>,
) -> Result<usize, OpsError> {
    let n = coeffs.nrows();
    if coeffs.ncols() != 3 * b {
        return Err(OpsError::shape_of(
            Op::ShColor,
            "coefficients",
            format!("[n, {}] (3 channels of {b} for degree {degree})", 3 * b),
            coeffs.shape(),
        ));
    }
    if directions.dim() != (n, 3) {
        return Err(OpsError::shape_of(
            Op::ShColor,
            "directions",
            format!("[{n}, 3]"),
            directions.shape(),
        ));
    }
    Ok(n)
}

/// Checks that every coefficient is finite, and that every direction is finite and of length 1
/// within [`UNIT_TOLERANCE`]; the first fault by row (a row's direction before its
/// coefficients).
pub(crate) fn check_values<F: Float>(
    coeffs: &ArrayView2<'_, F>,
    directions: &ArrayView2<'_, F>,
) -> Result<(), OpsError> {
    let row_fault = |i: usize| -> Option<OpsError> {
        let d = directions.row(i);
        if let Some(column) = d.iter().position(|v| !v.is_finite()) {
            return Some(non_finite("direction", i, column, d[column].as_f64()));
        }
        let norm = d.iter().map(|v| v.as_f64() * v.as_f64()).sum::<f64>().sqrt();
        if (norm - 1.0).abs() > UNIT_TOLERANCE {
            return Some(OpsError::NotUnit {
                op: Op::ShColor,
                row: i,
                norm,
            });
        }
        let c = coeffs.row(i);
        c.iter()
            .position(|v| !v.is_finite())
            .map(|column| non_finite("coefficient", i, column, c[column].as_f64()))
    };
    let n = coeffs.nrows();
    let starts: Vec<usize> = (0..n).step_by(CHUNK).collect();
    let bad = starts
        .par_iter()
        .any(|&start| (start..(start + CHUNK).min(n)).fold(false, |acc, i| acc | row_fault(i).is_some()));
    if bad {
        if let Some(e) = (0..n).find_map(row_fault) {
            return Err(e);
        }
    }
    Ok(())
}
