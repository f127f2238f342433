//! The mip-NeRF 360 distortion loss over packed rays, fused: densities, interval lengths and
//! midpoints of the samples to one scalar, as one op ([`DistortionLoss`]) with a hand-written
//! backward, with a tape ([`DistortionLoss::apply`]) or without ([`DistortionLoss::evaluate`],
//! [`DistortionLoss::vjp`]), and its taped twin ([`twin::distortion_loss`]).
//!
//! # The definition
//!
//! Ray `r` owns samples `offsets[r]..offsets[r+1]`, in order along the ray. Sample `k` has
//! density `sigma_k >= 0`, interval length `delta_k > 0` and midpoint `t_k`: it covers
//! `[t_k - delta_k / 2, t_k + delta_k / 2]`. The weights are the
//! [composite](crate::composite)'s:
//!
//! ```text
//! alpha_k = 1 - exp(-sigma_k delta_k)    T_k = exp(-sum_{j<k} sigma_j delta_j)    w_k = T_k alpha_k
//! ```
//!
//! and the loss of a ray (Barron et al., *Mip-NeRF 360*, 2022, eq. 15, with the weights held
//! constant over each interval) is
//!
//! ```text
//! L_r = sum_i sum_j w_i w_j |t_i - t_j|  +  (1/3) sum_i w_i^2 delta_i
//! ```
//!
//! The op's value is the mean over the `R` rays, `L = (1/R) sum_r L_r`, a 0-d value. A ray
//! with no samples has `L_r = 0` and still counts in the mean; no ray at all gives 0. The
//! gradient flows into `sigma` only: `delta` and `t` are the sampler's, constants of the op
//! (as the directions are of [`ShColor`](crate::ShColor)); where they are params they get no
//! gradient from this op. The inputs are those the composite reads, so a sampler's
//! [`PackedSamples::into_tape`](crate::sample::PackedSamples::into_tape) gives `t`, `delta`
//! and the packing ([`DistortionLoss::packed`]) beside the densities a field computes.
//!
//! # The forward, O(n) a ray
//!
//! With the samples sorted along the ray, `|t_i - t_j|` is `t_i - t_j` for `j < i`, so
//!
//! ```text
//! sum_{i,j} w_i w_j |t_i - t_j| = 2 sum_i w_i A_i,   A_i = sum_{j<i} w_j (t_i - t_j) = t_i S_{<i} - U_{<i}
//! ```
//!
//! with the prefix sums `S_{<i} = sum_{j<i} w_j` and `U_{<i} = sum_{j<i} w_j t_j`. `A_i` is not
//! computed as that difference (which cancels: at `t ~ 1e4` with spacings of `1e-2` it keeps
//! six fewer digits) but by its recurrence `A_i = A_{i-1} + S_{<i} (t_i - t_{i-1})`, a sum of
//! non-negative terms. This is why `t` must not decrease within a ray: a midpoint below its
//! predecessor is an error naming the ray and the sample (ties are allowed).
//!
//! # The backward, in closed form, O(n) a ray
//!
//! For the upstream gradient `g` of the mean, `c = g / R`, and with
//! `B_i = sum_{j>i} w_j (t_j - t_i) = U_{>i} - t_i S_{>i}` (back to front, by
//! `B_i = B_{i+1} + S_{>i} (t_{i+1} - t_i)`):
//!
//! ```text
//! g_i = dL/dw_i = c (2 A_i + 2 B_i + (2/3) w_i delta_i)
//! ```
//!
//! Through the weights (`dw_k/dtau_j` is `T_{j+1} = T_j exp(-tau_j)` for `k = j`, `-w_k` for
//! `k > j`, 0 for `k < j`, with `tau_j = sigma_j delta_j`):
//!
//! ```text
//! dL/dsigma_j = delta_j ( T_j exp(-sigma_j delta_j) g_j - sum_{k>j} g_k w_k )
//!             = delta_j T_{j+1} (g_j - R_{j+1}),    R_j = R_{j+1} + alpha_j (g_j - R_{j+1}),  R_end = 0
//! ```
//!
//! the composite's "what it adds minus what it hides", with its back-to-front recurrence:
//! `T_{j+1} R_{j+1}` is the suffix sum `sum_{k>j} g_k w_k` with no division and no
//! subtraction from a total.
//!
//! # Numerics, by design
//!
//! - Everything of a ray (weights, prefix sums, recurrences, the loss and its gradient) is
//!   computed in f64, also for f32 data, and rounded once to the data's precision. The
//!   differences `t_i - t_{i-1}` of f32 data are exact in f64.
//! - The pairwise sum is carried by recurrences of non-negative terms (above), never by
//!   `t_i S - U`: on rays at `t ~ 1e4` with spacings of `1e-3`, an f32 prefix-sum evaluation
//!   is 3 % off, this one (on the same f32 data) within `1e-7` of the exact value (tested).
//! - `alpha = -expm1(-tau)` and `T_k = exp(-running optical depth)` as in the composite
//!   (`math::exp`, to the tier of the data's precision): a tiny `sigma delta` (`1e-12`) keeps
//!   every digit of its weight, a huge one saturates to `alpha = 1`, `T = 0`, with finite
//!   values and gradients.
//! - The backward recomputes the weights from the inputs (nothing is kept on the tape), so the
//!   tape's gradient is bitwise that of [`DistortionLoss::vjp`].
//! - Rays run in parallel over fixed chunks, each ray on its own, and the per-ray losses are
//!   summed in ray order: the results are bitwise the same for any number of threads.
//!
//! # Speed
//!
//! The exponentials of a ray run over its slices of optical depths (`math::exp`'s branch-free
//! polynomial kernel, which vectorises), and each chunk of rays is compiled for AVX-512,
//! AVX2+FMA and the baseline and chosen at run time, as the composite's blocks are (without
//! FMA the kernel's `mul_add`s are library calls: ten times slower). On 4096 rays of 48 samples
//! the fused forward + backward on a tape is about 65 times faster than the twin's
//! (`benches/distortion.rs`).
//!
//! Input is checked: offsets that are a packing, `sigma`, `delta` and `t` each `[n]`,
//! densities finite and non-negative, steps finite and positive, midpoints finite and
//! non-decreasing along each ray; the errors are the composite's
//! ([`OpsError`](crate::OpsError)), naming the first ray and sample at fault.
//!
//! ```
//! use fogray_ops::DistortionLoss;
//! use fogray_tape::Tape;
//! use ndarray::arr1;
//!
//! // One ray of two samples of weights 1/4 (alpha = 1/4) and 3/4 (opaque), one empty ray.
//! let op = DistortionLoss::new(&[0, 2, 2])?;
//! let mut tape = Tape::<f64>::new();
//! let sigma = tape.param(arr1(&[(4.0f64 / 3.0).ln(), 1e3]));
//! let delta = tape.constant(arr1(&[1.0, 1.0]));
//! let t = tape.constant(arr1(&[0.5, 1.5]));
//! let loss = op.apply(&mut tape, sigma, delta, t)?;
//! // L_0 = 2 (1/4)(3/4) 1 + (1/3)(1/16 + 9/16) = 7/12; L_1 = 0; the mean is 7/24.
//! assert!((tape.value(loss)?[[]] - 7.0 / 24.0).abs() < 1e-15);
//! let grads = tape.backward(loss)?;
//! // With w_0 = a: dL_0/da = 2 - 4a + (4a - 2)/3 = 2/3 and da/dsigma_0 = exp(-sigma_0) = 3/4,
//! // halved by the mean; the opaque sample's density has nothing left to change.
//! assert!((grads.get(sigma).unwrap()[0] - 0.25).abs() < 1e-15);
//! assert_eq!(grads.get(sigma).unwrap()[1], 0.0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod check;
mod config;
mod kernel;
mod op;
pub mod twin;

pub use config::DistortionLoss;
