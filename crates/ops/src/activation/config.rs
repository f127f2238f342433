//! The activation's configuration (the density's shift), the named bundles of its outputs and
//! upstream gradients, and how it is applied to a tape.

use fogray_tape::{Float, Tape, TapeError, Var};
use ndarray::{Array1, Array2, ArrayView1, ArrayView2, ArrayViewMut1, ArrayViewMut2};

use crate::error::{Op, OpsError};

/// The activations of a grid renderer's raw values (see the [module docs](super)): raw
/// `[n, k]` (`k >= 2`, density first) to a density `softplus(raw_0 + shift)` `[n]` and a
/// colour `sigmoid(raw_1..k)` `[n, k - 1]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DensityColor {
    shift: f64,
}

/// The activation's outputs, owned.
#[derive(Debug, Clone, PartialEq)]
pub struct Activated<F: Float> {
    /// `softplus(raw_0 + shift)`, `[n]`.
    pub sigma: Array1<F>,
    /// `sigmoid(raw_1..k)`, `[n, k - 1]`.
    pub color: Array2<F>,
}

/// Buffers of the caller's for the activation's outputs ([`DensityColor::evaluate_into`]).
#[derive(Debug)]
pub struct ActivatedMut<'a, F: Float> {
    /// `[n]`.
    pub sigma: ArrayViewMut1<'a, F>,
    /// `[n, k - 1]`.
    pub color: ArrayViewMut2<'a, F>,
}

/// The gradients of a loss with respect to the activation's outputs, each `None` where the
/// loss does not depend on that output (its contribution is then zero).
#[derive(Debug, Clone, Copy)]
pub struct ActivatedGrads<'a, F: Float> {
    /// `dL/dsigma`, `[n]`.
    pub sigma: Option<ArrayView1<'a, F>>,
    /// `dL/dcolor`, `[n, k - 1]`.
    pub color: Option<ArrayView2<'a, F>>,
}

/// The activation's outputs on a tape.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ActivatedVars {
    /// `softplus(raw_0 + shift)`, `[n]`.
    pub sigma: Var,
    /// `sigmoid(raw_1..k)`, `[n, k - 1]`.
    pub color: Var,
}

impl DensityColor {
    /// The activation with the density's shift: a raw density of 0 gives `softplus(shift)`
    /// (a negative shift starts a fresh grid as a thin fog).
    ///
    /// Errors: a shift that is not finite ([`OpsError::Config`]).
    pub fn new(shift: f64) -> Result<Self, OpsError> {
        if !shift.is_finite() {
            return Err(OpsError::config(Op::DensityColor, "shift", shift, "must be finite"));
        }
        Ok(DensityColor { shift })
    }

    /// The density's shift.
    pub fn shift(&self) -> f64 {
        self.shift
    }

    /// Drops the decay buffer the calling thread keeps for the next forward on a tape (see
    /// [`KeptDecays`](super::KeptDecays)); the next forward there allocates one again. The
    /// buffer belongs to the thread, shared by every activation that runs on it, not to
    /// `self`.
    pub fn release_buffers(&self) {
        super::kept::release_spare();
    }

    /// Records the activation of `raw` (`[n, k]`, `k >= 2`) on `tape` as one op through the
    /// tape's public custom-op interface; its backward gives `dL/draw` where the tape needs it.
    /// It keeps every value's decay for that backward ([`KeptDecays`](super::KeptDecays), 8
    /// bytes a raw value) only when the tape keeps a record of it: not under
    /// [`Tape::no_grad`], nor on a value that needs no gradient.
    ///
    /// Errors (the tape is unchanged): `raw` not `[n, k]` with `k >= 2`, or a NaN raw value
    /// (the [`OpsError`] itself inside [`TapeError::Op`], read back with
    /// [`TapeError::downcast_ref`]), or a stale handle.
    pub fn apply<F: Float>(&self, tape: &mut Tape<F>, raw: Var) -> Result<ActivatedVars, TapeError> {
        let out = tape.apply(*self, &[raw])?;
        Ok(ActivatedVars {
            sigma: out[0],
            color: out[1],
        })
    }
}
