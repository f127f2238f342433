//! Optimisers that update the parameters of a [`Params`](crate::params::Params) store in place:
//! [`Sgd`] (with momentum) and [`Adam`].
//!
//! A training step lends the parameters to a tape ([`Tape::param_from`](crate::Tape::param_from),
//! O(1) per parameter), runs the forward and the backward, clears the tape (which gives the
//! arrays back to the store) and calls the optimiser's `step` with the gradients. The
//! gradients know which parameter each belongs to (the tape recorded the loans), so no
//! gradient can be paired with the wrong parameter; one computed before the parameter last
//! changed is an error, as is a gradient of the wrong shape, a NaN in one, or a parameter a
//! tape still holds. Every gradient is checked before anything changes, so a failed step
//! leaves every parameter and every moment as it was. A parameter the backward never reached
//! has no gradient and is skipped (its state does not advance).
//!
//! Only the optimiser's in-place update touches parameter data in a step: nothing is copied
//! onto the tape, whatever the parameters' size.
//!
//! ```
//! use std::sync::Arc;
//!
//! use fogray_tape::optim::{Adam, AdamConfig};
//! use fogray_tape::params::Params;
//! use fogray_tape::Tape;
//! use ndarray::{arr0, Array2};
//!
//! // Fit `grid + offset` to a target image: a 2-D grid and a scalar offset.
//! let target = Arc::new(Array2::from_shape_fn((8, 8), |(i, j)| (i * j) as f32 / 49.0).into_dyn());
//! let mut params = Params::<f32>::new();
//! let grid = params.add("grid", Array2::<f32>::zeros((8, 8)))?;
//! let offset = params.add("offset", arr0(0.0f32))?;
//!
//! let mut adam = Adam::new(AdamConfig { lr: 0.02, ..AdamConfig::default() })?;
//! adam.set_lr_scale(offset, 0.5)?; // a per-parameter rate
//! let mut tape = Tape::<f32>::new();
//! let mut loss_value = f32::INFINITY;
//! for _ in 0..400 {
//!     let g = tape.param_from(&params, grid)?; // O(1): the store's array, shared
//!     let o = tape.param_from(&params, offset)?;
//!     let t = tape.constant_shared(&target); // O(1) as well
//!     let pred = tape.add(g, o)?;
//!     let r = tape.sub(pred, t)?;
//!     let sq = tape.square(r)?;
//!     let loss = tape.mean(sq)?;
//!     loss_value = tape.value(loss)?[[]];
//!     let grads = tape.backward(loss)?;
//!     tape.clear(); // gives the arrays back to the store
//!     adam.step(&mut params, &grads)?; // in place
//!     tape.recycle(grads);
//! }
//! assert!(loss_value < 1e-5, "loss {loss_value}");
//! assert_eq!(adam.updates(grid), 400);
//! # Ok::<(), fogray_tape::TapeError>(())
//! ```
//!
//! Calling `step` before `clear` is [`ParamError::InUse`]:
//! the update is never made on a silent copy. For a gradient computed without a tape, insert
//! it in a [`ParamGradients`].

mod adam;
pub(crate) mod chunks;
mod sgd;
mod slots;
mod source;

pub use adam::{Adam, AdamConfig, AdamState};
pub use sgd::{Sgd, SgdConfig};
pub use source::{GradientSource, ParamGradients};

use crate::params::ParamError;

/// What one optimiser step did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StepSummary {
    /// Parameters updated (those with a gradient).
    pub updated: usize,
    /// Parameters of the store left as they were, having no gradient this step.
    pub without_gradient: usize,
}

/// `Ok` if `value` is finite and `ok`, else `InvalidSetting` naming `setting` and `range`.
fn check_range(setting: &'static str, value: f64, ok: bool, range: &'static str) -> Result<(), ParamError> {
    if value.is_finite() && ok {
        Ok(())
    } else {
        Err(ParamError::InvalidSetting { setting, range, value })
    }
}
