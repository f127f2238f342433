//! The emission-absorption composite over packed rays, as one fused op (the model and its
//! derivative are those of the lesson *Making visibility soft: volume rendering*, restated in
//! `docs/volume-rendering.md`).
//!
//! # The formulas
//!
//! Ray `r` owns samples `offsets[r]..offsets[r+1]`. Sample `k` has density `sigma_k >= 0`,
//! length `delta_k >= 0`, colour `c_k` (any number of channels) and optionally a depth `t_k`.
//! With optical depth `tau_k = sigma_k delta_k`:
//!
//! ```text
//! alpha_k = 1 - exp(-tau_k)            T_k = exp(-sum_{j<k} tau_j)       w_k = T_k alpha_k
//! C = sum_k w_k c_k + T_end c_bg       opacity = 1 - T_end               depth = sum_k w_k t_k
//! ```
//!
//! (`depth` is the unnormalised expected depth: the background contributes 0, an empty ray has
//! depth 0; divide by the opacity for the depth given that the ray stops.)
//!
//! The backward is the lesson's closed form ("what a sample adds minus what it hides"). For a loss `L` with upstream gradients
//! `gC`, `gO`, `gD`, `gW_k`, `gT_k`, every output is linear in per-sample "values"
//! `v_k = gC.c_k + gO + gD t_k + gW_k` (the background's value is `gC.c_bg`), and
//!
//! ```text
//! dL/dtau_k = T_{k+1} (v_k - R_{k+1}) - sum_{i>k} gT_i T_i     "what it adds minus what it hides"
//! R_k = R_{k+1} + alpha_k (v_k - R_{k+1}),  R_end = gC.c_bg       (back to front)
//! dL/dsigma_k = delta_k dL/dtau_k    dL/ddelta_k = sigma_k dL/dtau_k    dL/dc_k = w_k gC
//! dL/dt_k = w_k gD                   dL/dc_bg = T_end gC
//! ```
//!
//! `R_k` is the expected value of what lies behind sample `k` given that the ray reaches it,
//! so `T_{k+1} R_{k+1}` is the suffix sum `S_k = sum_{i>k} w_i v_i + T_end v_bg` of the lesson,
//! accumulated back to front with no division and no `C - prefix` subtraction.
//!
//! # Numerics, by design
//!
//! - `alpha = -expm1(-tau)`: `1 - exp(-tau)` loses every digit for `tau < 1e-8` (and 0.6 % at
//!   `tau = 1e-5` in f32, coherently along a ray).
//! - `T_k = exp(-running optical depth)`, not a product of `1 - alpha`, which rounds to 0 or
//!   loses all digits as `alpha -> 1`; the opacity is `-expm1(-total depth)`, not `1 - T_end`,
//!   which is 0 for a faint ray.
//! - Every running sum (optical depth, colour, depth, the suffix recurrence) is carried in
//!   f64, also for f32 data: f32 running sums lose 1e-4 of C on a 1e5-sample ray.
//! - The suffix is a true back-to-front recurrence (above): `C - prefix` is off by
//!   thousands of times behind an opaque sample.
//!
//! # Speed, by design
//!
//! - `exp` and `expm1` are one branch-free polynomial kernel (`math::exp`, shared with the
//!   field activations; within 2 ulp of the C library over the whole domain, subnormals
//!   included; for f32 data a shorter series within 7e-10 relative) applied to a ray's slices
//!   of optical depths: the scalar library calls were most of the op's time and never
//!   vectorise.
//! - The forward and backward of each block of rays are compiled for AVX-512, AVX2+FMA and the
//!   baseline and chosen at run time, with the per-ray loops inlined into them. The values do
//!   not depend on which one runs: every fused multiply-add is written as one (`mul_add`), and
//!   the compiler contracts nothing else.
//! - Each block's loop asks for the next ray's cache lines (inputs, and the gradients it
//!   writes) before it computes the current ray, so that their misses overlap with the work
//!   (`crate::prefetch`, a hint: no value changes).
//! - A ray whose length is not a multiple of 8 runs its exponentials over whole vector steps
//!   into the attenuation buffers' padding, its `T_len` and opacity included, instead of one
//!   scalar polynomial per value of its tail (`attenuation`, the same bits).
//! - The forward keeps only each ray's stop index; the backward recomputes `T_k` and `alpha_k`
//!   from sigma and delta with the same code (bitwise the same values), so the op's extra
//!   memory is its outputs and gradients alone; the price is two vectorised exponentials per
//!   sample more (`fogray-lab bench` measures what that costs against the one-pass call).
//! - The colour loops are compiled for 1 to 4 channels with the count a constant and sum in
//!   four interleaved chains; for three channels on AVX2 with FMA they run four samples' twelve
//!   values in three vector registers (`rows_x86`, every result bitwise the scalar loop's); the
//!   one sequential chain of the backward carries one fused multiply-add per four samples.
//! - [`Composite::evaluate_into`] and [`Composite::vjp_into`] write into buffers the caller
//!   keeps: fresh output pages, which the kernel clears, are a quarter of the time of
//!   [`Composite::evaluate`] + [`Composite::vjp`] on large batches.

//! # Early termination
//!
//! With `min_transmittance > 0`, the first sample whose transmittance `T_k` is below the
//! threshold and every sample after it are treated as empty (density 0): they get zero weight
//! and zero gradient, their `T` is the ray's residual `T_stop`, and the background is blended
//! with `T_stop`. The forward and backward compute exactly that truncated function, whose
//! colour differs from the exact one by at most `T_stop max|c - c_bg|`. The default 0 is exact.

mod arrays;
mod attenuation;
mod backward;
mod config;
mod forward;
mod gradients;
mod layout;
mod mse;

pub(crate) use layout::validate;
mod one_pass;
mod op;
mod rows;
#[cfg(target_arch = "x86_64")]
mod rows_x86;
mod suffix;
mod tape_order;

pub use arrays::{CompositeArrays, CompositeOutputBuffers, CompositeOutputs};
pub use config::{Background, Composite, CompositeInputs, CompositeVars};
pub use forward::Residuals;
pub use gradients::{CompositeGradientBuffers, CompositeGradients, CompositeUpstream, CompositeWanted};
