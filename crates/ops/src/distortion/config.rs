//! The op's configuration (the ray packing) and how it is applied to a tape.

use fogray_tape::{Float, Offsets, Tape, TapeError, Var};

use crate::error::{Op, OpsError};

/// The mip-NeRF 360 distortion loss over packed rays (see the [module docs](super)): densities
/// `sigma [n]`, interval lengths `delta [n]` and midpoints `t [n]` to the mean over the rays of
/// `sum_i sum_j w_i w_j |t_i - t_j| + (1/3) sum_i w_i^2 delta_i`, a 0-d value.
///
/// Holds the ray packing; the inputs are tape values passed to [`DistortionLoss::apply`] (or
/// arrays passed to [`DistortionLoss::evaluate`] and [`DistortionLoss::vjp`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DistortionLoss {
    pub(crate) offsets: Offsets,
}

impl DistortionLoss {
    /// The loss over rays packed by `offsets` (`R + 1` entries, starting at 0, never
    /// decreasing; ray `r` owns samples `offsets[r]..offsets[r+1]`; empty rays are allowed).
    ///
    /// Errors: offsets that are not a packing ([`OpsError::Offsets`]).
    pub fn new(offsets: &[usize]) -> Result<Self, OpsError> {
        Ok(Self::packed(Offsets::new(offsets).map_err(|source| {
            OpsError::Offsets {
                op: Op::DistortionLoss,
                source,
            }
        })?))
    }

    /// [`DistortionLoss::new`] over an already validated packing (a sampler's, for example:
    /// [`PackedSamples::into_tape`](crate::sample::PackedSamples::into_tape) gives it beside
    /// the `t` and `delta` this op reads), which it shares instead of copying.
    pub fn packed(offsets: Offsets) -> Self {
        DistortionLoss { offsets }
    }

    /// Number of rays `R` (the mean's denominator: empty rays count).
    pub fn rays(&self) -> usize {
        self.offsets.segments()
    }

    /// Number of samples `n` the packing expects.
    pub fn samples(&self) -> usize {
        self.offsets.rows()
    }

    /// The packing's `R + 1` offsets.
    pub fn offsets(&self) -> &[usize] {
        &self.offsets
    }

    /// The packing, as the validated type (cloning it is cheap).
    pub fn packing(&self) -> &Offsets {
        &self.offsets
    }

    /// Records the loss of `sigma`, `delta` and `t` (each `[n]`) on `tape` as one op through
    /// the tape's public custom-op interface: a 0-d value, whose backward gives `dL/dsigma`.
    /// `delta` and `t` are treated as constants: no gradient flows to them, even where they
    /// are params.
    ///
    /// Errors (the tape is unchanged): an input not `[n]`, a density that is negative or not
    /// finite, a step that is not finite and positive, a midpoint that is not finite or
    /// decreases along its ray (the [`OpsError`] itself inside [`TapeError::Op`], read
    /// back with [`TapeError::downcast_ref`], naming the ray and the sample), or a stale
    /// handle.
    pub fn apply<F: Float>(&self, tape: &mut Tape<F>, sigma: Var, delta: Var, t: Var) -> Result<Var, TapeError> {
        tape.apply1(self.clone(), &[sigma, delta, t])
    }
}
