//! Validation of the splats' parameters: shapes, finite values, quaternions that can be
//! normalised. Each check names the first splat (row) at fault; nothing is computed before
//! every input has passed.

use fogray_tape::Float;
use ndarray::ArrayView2;

use super::project::widen;
use crate::error::{At, Op, OpsError};

/// The geometric parameters of `n` splats, widened to f64 and checked.
#[derive(Debug, Clone, Default)]
pub(crate) struct SplatParams {
    pub(crate) means: Vec<[f64; 3]>,
    pub(crate) log_scales: Vec<[f64; 3]>,
    pub(crate) quats: Vec<[f64; 4]>,
}

impl SplatParams {
    pub(crate) fn len(&self) -> usize {
        self.means.len()
    }
}

/// `x` as `[n, cols]`, or the shape error naming `what`.
pub(crate) fn expect_shape<F: Float>(
    what: &'static str,
    x: &ArrayView2<'_, F>,
    n: usize,
    cols: usize,
) -> Result<(), OpsError> {
    if x.dim() != (n, cols) {
        return Err(OpsError::shape(
            Op::Splat,
            what,
            format!("[{n}, {cols}]"),
            format!("{:?}", x.shape()),
        ));
    }
    Ok(())
}

/// The first NaN or infinite entry of `x`, as an error naming `what`.
pub(crate) fn expect_finite<F: Float>(what: &'static str, x: &ArrayView2<'_, F>) -> Result<(), OpsError> {
    match x.indexed_iter().find(|(_, v)| !v.is_finite()) {
        None => Ok(()),
        Some(((row, column), v)) => Err(OpsError::domain(
            Op::Splat,
            At::Entry { row, column },
            what,
            v.as_f64(),
            "must be finite",
        )),
    }
}

/// The rows of `x` (checked `[n, K]`), widened.
pub(crate) fn rows<F: Float, const K: usize>(x: &ArrayView2<'_, F>) -> Vec<[f64; K]> {
    match x.as_slice() {
        Some(s) => widen::<F, K>(s),
        None => widen::<F, K>(&x.iter().copied().collect::<Vec<F>>()),
    }
}

/// Checks means `[n, 3]`, log-scales `[n, 3]` and quaternions `[n, 4]` (`w, x, y, z`, any
/// non-zero length), and widens them.
pub(crate) fn params<F: Float>(
    means: &ArrayView2<'_, F>,
    log_scales: &ArrayView2<'_, F>,
    quats: &ArrayView2<'_, F>,
) -> Result<SplatParams, OpsError> {
    let n = means.nrows();
    expect_shape("means", means, n, 3)?;
    expect_shape("log-scales", log_scales, n, 3)?;
    expect_shape("quaternions", quats, n, 4)?;
    expect_finite("mean", means)?;
    expect_finite("log-scale", log_scales)?;
    expect_finite("quaternion", quats)?;
    let quats: Vec<[f64; 4]> = rows(quats);
    for (row, q) in quats.iter().enumerate() {
        let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        // Normalising a zero (or underflowing) quaternion has no answer.
        if !(norm > 1e-30 && norm.is_finite()) {
            return Err(OpsError::domain(
                Op::Splat,
                At::Entry { row, column: 0 },
                "quaternion length",
                norm,
                "must be positive and finite",
            ));
        }
    }
    Ok(SplatParams {
        means: rows(means),
        log_scales: rows(log_scales),
        quats,
    })
}
