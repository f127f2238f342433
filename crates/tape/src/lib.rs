//! # fogray-tape
//!
//! Generic reverse-mode automatic differentiation over [`ndarray`], for `f32` and `f64`.
//!
//! A [`Tape`] is a Wengert list: values in creation order, plus a record of every op
//! application that needs a backward. [`Tape::backward`] walks the records once in reverse
//! (no recursion: a chain of a million ops is fine) and returns [`Gradients`] read by handle.
//! Every op, built-in or yours, is a [`CustomOp`]: a forward, and a backward that receives the
//! inputs and outputs from the tape, the op's saved residuals, which inputs need a gradient
//! and `Option` upstream gradients. [`gradcheck()`] checks any of it against central finite
//! differences in f64.
//!
//! ```
//! use fogray_tape::{gradcheck, BackwardCtx, CustomOp, GradcheckOptions, OpError, Tape};
//! use ndarray::{arr1, ArrayD, ArrayViewD};
//!
//! /// softplus(x) = ln(1 + e^x), whose derivative is the logistic 1 / (1 + e^-x).
//! #[derive(Debug)]
//! struct Softplus;
//!
//! impl CustomOp<f64> for Softplus {
//!     type Saved = ();
//!     fn name(&self) -> &'static str { "softplus" }
//!     fn forward(&self, x: &[ArrayViewD<'_, f64>]) -> Result<(Vec<ArrayD<f64>>, ()), OpError> {
//!         // max(x, 0) + ln(1 + e^-|x|) never overflows.
//!         Ok((vec![x[0].mapv(|x| x.max(0.0) + (-x.abs()).exp().ln_1p())], ()))
//!     }
//!     fn backward(
//!         &self,
//!         ctx: &BackwardCtx<'_, f64, ()>,
//!         grads: &[Option<ArrayViewD<'_, f64>>],
//!     ) -> Result<Vec<Option<ArrayD<f64>>>, OpError> {
//!         let Some(g) = &grads[0] else { return Ok(vec![None]) };
//!         Ok(vec![Some(g * &ctx.input(0).mapv(|x| 1.0 / (1.0 + (-x).exp())))])
//!     }
//! }
//!
//! // Use it like any built-in op...
//! let mut tape = Tape::<f64>::new();
//! let x = tape.param(arr1(&[-2.0, 0.0, 3.0]));
//! let y = tape.apply1(Softplus, &[x])?;
//! let loss = tape.sum(y)?;
//! let grads = tape.backward(loss)?;
//! assert!((grads.get(x).unwrap()[[1]] - 0.5).abs() < 1e-15); // logistic(0) = 1/2
//!
//! // ...and check its backward against finite differences.
//! let report = gradcheck(
//!     |t, v| t.apply1(Softplus, &[v[0]]),
//!     &[arr1(&[-2.0, 0.0, 3.0]).into_dyn()],
//!     &GradcheckOptions::default(),
//! )?;
//! assert!(report.passes(), "{report}");
//! # Ok::<(), fogray_tape::TapeError>(())
//! ```
//!
//! Conventions: a zero upstream gradient contributes exactly zero even where a local
//! derivative is infinite (the strong-zero rule); "never reached" ([`Gradients::get`] is
//! `None`) is distinct from a zero gradient; every fallible call returns [`TapeError`] and
//! leaves the tape unchanged on error. Ops with large outputs (yours too) allocate them with
//! [`buffer`], which asks Linux for huge pages before the first touch and, in a
//! training loop that reuses one tape through [`Tape::clear`], hands out the buffers of the
//! step before instead of fresh pages (see [`Tape::clear`] and [`Tape::recycle`]).
//!
//! Training: parameters that live across steps belong in a [`params::Params`] store, which
//! lends each to a tape in O(1) ([`Tape::param_from`]: the tape shares the array, whatever its
//! size, and gives it back on [`Tape::clear`]); constants that live across steps are lent the
//! same way ([`Tape::constant_shared`]). The optimisers of [`optim`] ([`optim::Sgd`] with
//! momentum, [`optim::Adam`]) update the store's arrays in place from a backward's
//! [`Gradients`], which know which parameter each gradient belongs to. The module docs of
//! [`optim`] show a training loop.

#![warn(missing_docs)]

mod backward;
pub mod broadcast;
pub mod buffer;
mod custom;
mod error;
mod float;
pub mod gradcheck;
mod gradients;
mod offsets;
pub mod ops;
pub mod optim;
pub mod params;
mod pool;
pub mod profile;
mod storage;
mod tape;
mod var;

pub use custom::{grad_or_zeros, BackwardCtx, CustomOp};
pub use error::{OpError, Result, TapeError, TypedError};
pub use float::Float;
pub use gradcheck::{gradcheck, GradcheckEntry, GradcheckOptions, GradcheckReport};
pub use gradients::Gradients;
pub use offsets::{Offsets, OffsetsError};
pub use profile::{OpTime, Profile};
pub use tape::{Tape, TapeStats};
pub use var::Var;
