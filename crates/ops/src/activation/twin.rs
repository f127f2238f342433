//! The activation written with tape primitives only (slice, reshape, add_scalar, softplus,
//! sigmoid): five records instead of one, each a pass over memory. The fused op is checked
//! against it and timed against it.

use fogray_tape::{Float, Tape, TapeError, Var};

use super::config::{ActivatedVars, DensityColor};
use crate::error::{Op, OpsError};

/// Records `op`'s activation of `raw` (`[n, k]`, `k >= 2`) with the tape's own ops.
///
/// Errors (the tape is unchanged): `raw` not `[n, k]` with `k >= 2` ([`OpsError::Shape`]
/// inside [`TapeError::Op`]), a stale handle. A NaN raw value is not an error here: it
/// propagates, as through any tape primitive.
pub fn density_color<F: Float>(tape: &mut Tape<F>, op: &DensityColor, raw: Var) -> Result<ActivatedVars, TapeError> {
    let shape = tape.shape(raw)?.to_vec();
    let &[n, k] = shape.as_slice() else {
        return Err(OpsError::shape_of(Op::DensityColor, "raw values", "[n, k] with k >= 2", &shape).into());
    };
    if k < 2 {
        return Err(OpsError::shape_of(Op::DensityColor, "raw values", "[n, k] with k >= 2", &shape).into());
    }
    let density = tape.slice(raw, 1, 0, 1)?;
    let density = tape.reshape(density, &[n])?;
    let x = tape.add_scalar(density, F::lit(op.shift()))?;
    let sigma = tape.softplus(x)?;
    let x = tape.slice(raw, 1, 1, k)?;
    let color = tape.sigmoid(x)?;
    Ok(ActivatedVars { sigma, color })
}
