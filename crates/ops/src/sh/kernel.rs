//! The op's forward and backward on flat row-major slices, parallel over fixed chunks of rows.
//! Every value depends on its own row alone, and each row is computed by the same sequence of
//! operations whichever thread runs it, so the results are bitwise the same for any number of
//! threads.
//!
//! Each row is computed in f64 (the basis, the sums, the sigmoid and its slope, from
//! [`crate::math::logistic`]) and rounded once to the data's precision.

use fogray_tape::Float;
use rayon::prelude::*;

use super::basis::basis;
use crate::math::exp::single_tier;
use crate::math::logistic::{decay, sigmoid_decayed, sigmoid_slope_decayed};

/// Rows per parallel task.
pub(crate) const CHUNK: usize = 1024;

/// The direction of a row, in f64.
#[inline(always)]
fn direction<F: Float>(d: &[F]) -> [f64; 3] {
    [d[0].as_f64(), d[1].as_f64(), d[2].as_f64()]
}

/// `sum_k coeffs[k] y[k]`, in order.
#[inline(always)]
fn dot<F: Float>(coeffs: &[F], y: &[f64]) -> f64 {
    coeffs.iter().zip(y).fold(0.0, |acc, (c, y)| acc + c.as_f64() * y)
}

/// `sigmoid(x)` in the stable form, to the tier of `F`.
#[inline(always)]
fn sigmoid<F: Float>(x: f64) -> f64 {
    if single_tier::<F>() {
        sigmoid_decayed::<true>(x, decay::<true>(x))
    } else {
        sigmoid_decayed::<false>(x, decay::<false>(x))
    }
}

/// `sigmoid'(x) = e / (1 + e)^2` with `e = exp(-|x|)`, to the tier of `F`.
#[inline(always)]
fn slope<F: Float>(x: f64) -> f64 {
    if single_tier::<F>() {
        sigmoid_slope_decayed::<true>(decay::<true>(x))
    } else {
        sigmoid_slope_decayed::<false>(decay::<false>(x))
    }
}

/// `color[i, c] = sigmoid(sum_k coeffs[i, c b + k] Y_k(d_i))`; `coeffs` is `[n, 3 b]`,
/// `directions` `[n, 3]`, `color` `[n, 3]`, all row-major and checked.
pub(crate) fn forward<F: Float>(b: usize, coeffs: &[F], directions: &[F], color: &mut [F]) {
    color
        .par_chunks_mut(CHUNK * 3)
        .zip(coeffs.par_chunks(CHUNK * 3 * b))
        .zip(directions.par_chunks(CHUNK * 3))
        .for_each(|((color, coeffs), directions)| {
            let rows = color
                .chunks_exact_mut(3)
                .zip(coeffs.chunks_exact(3 * b))
                .zip(directions.chunks_exact(3));
            for ((out, row), d) in rows {
                let y = basis(direction(d));
                for (o, channel) in out.iter_mut().zip(row.chunks_exact(b)) {
                    *o = F::lit(sigmoid::<F>(dot(channel, &y[..b])));
                }
            }
        });
}

/// `g_coeffs[i, c b + k] = g_color[i, c] sigmoid'(x_ic) Y_k(d_i)`, with `x_ic` recomputed as
/// in [`forward`]; shapes as there, `g_color` `[n, 3]`, `g_coeffs` as `coeffs`.
pub(crate) fn backward<F: Float>(b: usize, coeffs: &[F], directions: &[F], g_color: &[F], g_coeffs: &mut [F]) {
    g_coeffs
        .par_chunks_mut(CHUNK * 3 * b)
        .zip(coeffs.par_chunks(CHUNK * 3 * b))
        .zip(directions.par_chunks(CHUNK * 3))
        .zip(g_color.par_chunks(CHUNK * 3))
        .for_each(|(((g_coeffs, coeffs), directions), g_color)| {
            let rows = g_coeffs
                .chunks_exact_mut(3 * b)
                .zip(coeffs.chunks_exact(3 * b))
                .zip(directions.chunks_exact(3))
                .zip(g_color.chunks_exact(3));
            for (((g_row, row), d), g_out) in rows {
                let y = basis(direction(d));
                let channels = g_row.chunks_exact_mut(b).zip(row.chunks_exact(b)).zip(g_out);
                for ((g, channel), g_c) in channels {
                    let s = g_c.as_f64() * slope::<F>(dot(channel, &y[..b]));
                    for (g, &y) in g.iter_mut().zip(&y[..b]) {
                        *g = F::lit(s * y);
                    }
                }
            }
        });
}
