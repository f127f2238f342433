//! The op's forward and backward on flat row-major slices, parallel over fixed chunks of rows.
//! Every value depends on its own row alone, and each row is computed by the same sequence of
//! operations whichever thread runs it, so the results are bitwise the same for any number of
//! threads.
//!
//! Each row is computed in f64 (the basis, the sums, the sigmoid and its slope, from
//! [`crate::math::logistic`]) and rounded once to the data's precision.

use fogray_tape::Float;
use multiversion::multiversion;
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
        .for_each(|((color, coeffs), directions)| forward_chunk(b, coeffs, directions, color));
}

/// The sums of one chunk's rows, `x[3 i + c] = sum_k coeffs[i, c b + k] Y_k(d_i)`.
#[inline(always)]
fn sums<F: Float>(b: usize, coeffs: &[F], directions: &[F], x: &mut [f64]) {
    let rows = coeffs.chunks_exact(3 * b).zip(directions.chunks_exact(3));
    for ((row, d), x) in rows.zip(x.chunks_exact_mut(3)) {
        let y = basis(direction(d));
        for (x, channel) in x.iter_mut().zip(row.chunks_exact(b)) {
            *x = dot(channel, &y[..b]);
        }
    }
}

/// One chunk of [`forward`]: the sums first, then the sigmoid over all of them in one loop.
/// Compiled for the vector units this machine has (chosen at run time; the exponential's
/// fused multiply-adds are otherwise the C library's slow `fma`); the values do not depend on
/// which, each being the same sequence of correctly rounded operations.
#[multiversion(targets("x86_64+avx512f+avx512dq+fma", "x86_64+avx2+fma", "aarch64+neon"))]
fn forward_chunk<F: Float>(b: usize, coeffs: &[F], directions: &[F], color: &mut [F]) {
    let mut x = [0.0; CHUNK * 3];
    let x = &mut x[..color.len()];
    sums(b, coeffs, directions, x);
    for (o, &x) in color.iter_mut().zip(x.iter()) {
        *o = F::lit(sigmoid::<F>(x));
    }
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
            backward_chunk(b, coeffs, directions, g_color, g_coeffs)
        });
}

/// One chunk of [`backward`] (compiled as [`forward_chunk`] is): the sums, the sigmoid's
/// slope times the upstream gradient over all of them, then the products with the basis.
#[multiversion(targets("x86_64+avx512f+avx512dq+fma", "x86_64+avx2+fma", "aarch64+neon"))]
fn backward_chunk<F: Float>(b: usize, coeffs: &[F], directions: &[F], g_color: &[F], g_coeffs: &mut [F]) {
    let mut x = [0.0; CHUNK * 3];
    let x = &mut x[..g_color.len()];
    sums(b, coeffs, directions, x);
    for (x, g) in x.iter_mut().zip(g_color) {
        *x = g.as_f64() * slope::<F>(*x);
    }
    let rows = g_coeffs.chunks_exact_mut(3 * b).zip(directions.chunks_exact(3));
    for ((g_row, d), s) in rows.zip(x.chunks_exact(3)) {
        let y = basis(direction(d));
        for (g, &s) in g_row.chunks_exact_mut(b).zip(s) {
            for (g, &y) in g.iter_mut().zip(&y[..b]) {
                *g = F::lit(s * y);
            }
        }
    }
}
