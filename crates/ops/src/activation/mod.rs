//! The activations every grid renderer needs, fused: raw values `[n, k]` (density first, then
//! `k - 1` colour channels, as a [`GridField`](crate::GridField) looks them up) to a density
//! `sigma = softplus(raw_0 + shift)` `[n]` and a colour `sigmoid(raw_1..k)` `[n, k - 1]`, as one
//! op ([`DensityColor`]) with a hand-written backward, with a tape ([`DensityColor::apply`]) or
//! without ([`DensityColor::evaluate`], [`DensityColor::vjp`] and their `_into` forms that
//! write into the caller's buffers), and its taped twin ([`twin::density_color`]).
//!
//! # The forms
//!
//! With `e = exp(-|x|)`, which is in `[0, 1]` for every `x`:
//!
//! ```text
//! softplus(x) = max(x, 0) + ln(1 + e)        softplus'(x) = sigmoid(x)
//! sigmoid(x)  = exp(min(x, 0)) / (1 + e)     sigmoid'(x)  = e / (1 + e)^2
//! ```
//!
//! Nothing overflows (the textbook `ln(1 + exp(x))` is infinite from `x = 89` in f32, 710 in
//! f64), the tails keep their relative accuracy (`softplus(-40) = 4.2e-18`, where
//! `ln(1 + exp(x))` is 0), and the slope is never `y (1 - y)`, which is 0 once `y` rounds to 1
//! (at `x = 20` in f32, 40 in f64) though the true slope is not. `softplus(0) = ln 2`,
//! `sigmoid(0) = softplus'(0) = 1/2`, `sigmoid'(0) = 1/4`; infinities saturate (to `x`, 0, 1
//! and 0); a NaN raw value is an error.
//!
//! # Accuracy and speed, by design
//!
//! Each value is computed in f64 from one branch-free polynomial `exp` (the composite's) and
//! `ln(1 + e) = 2 atanh(e / (2 + e))` by its series, with no table, and rounded once to the
//! data's precision. For f64 data the roundings inside are recovered with fused multiply-adds:
//! softplus and sigmoid are within 2 ulp, the slope within 4 ulp, of the same forms through
//! the C library (whose own error is part of that distance), over the whole range,
//! subnormals included. For f32 data shorter series (error below 1e-9 relative) give results
//! within 0.51 f32 ulp of the exact values. The loops run over contiguous f64 columns so that
//! they vectorise (compiled for AVX-512, AVX2+FMA and the baseline, chosen at run time, with
//! the same values); chunks of rows run in parallel, and every value depends on its own row
//! alone, so the results are bitwise the same for any number of threads. On a tape that
//! records it the forward keeps every value's `e` (in f64, [`KeptDecays`]) and the backward
//! computes from it with no exponential, bitwise the gradients [`DensityColor::vjp`]
//! recomputes from the raw values; the buffer is kept on its thread between steps (until
//! [`DensityColor::release_buffers`]). Under [`Tape::no_grad`](fogray_tape::Tape::no_grad),
//! or on a constant, nothing is kept.
//!
//! ```
//! use fogray_ops::activation::DensityColor;
//! use fogray_tape::Tape;
//! use ndarray::arr2;
//!
//! let op = DensityColor::new(0.0)?;
//! let mut tape = Tape::<f64>::new();
//! let raw = tape.param(arr2(&[[0.0, 0.0, 50.0, -800.0]]));
//! let out = op.apply(&mut tape, raw)?;
//! assert_eq!(tape.value(out.sigma)?[[0]], std::f64::consts::LN_2); // softplus(0) = ln 2
//! assert_eq!(tape.value(out.color)?[[0, 0]], 0.5);
//! assert_eq!(tape.value(out.color)?[[0, 2]], 0.0); // saturated, not NaN
//! let loss = tape.sum(out.sigma)?;
//! let grads = tape.backward(loss)?;
//! assert_eq!(grads.get(raw).unwrap()[[0, 0]], 0.5); // softplus'(0) = 1/2
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod config;
mod kept;
mod kernel;
mod op;
pub mod twin;

pub use config::{Activated, ActivatedGrads, ActivatedMut, ActivatedVars, DensityColor};
pub use kept::KeptDecays;
