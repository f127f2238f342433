//! The activation's forward and backward on flat row-major slices, parallel over fixed chunks
//! of rows. Every value depends on its own row alone, so the results are bitwise the same for
//! any number of threads.
//!
//! Within a chunk, the density column and the colour columns are first gathered into
//! contiguous f64 scratch, so that each function runs as one straight loop over a slice
//! (which the compiler vectorises: the math kernels have no branch and no table), and the
//! results are scattered back, rounded once to the data's precision.
//!
//! The forward may keep every value's decay `exp(-|x|)` (its one exponential) for the
//! backward, which then computes no exponential at all: the same f64 values go into the same
//! forms, so the gradients are bitwise those computed from the raw values alone. The kept
//! decays are f64, laid out chunk by chunk as the scratch is: a chunk of `r` rows starting at
//! row `i` holds values `i k .. (i + r) k`, its `r` density decays first, then its colour
//! decays row by row.

use fogray_tape::Float;
use multiversion::multiversion;
use rayon::prelude::*;

use crate::math::exp::single_tier;
use crate::math::logistic::{decay, sigmoid_decayed, sigmoid_slope_decayed, softplus_decayed};

/// Rows per parallel task: enough to amortise a task, few enough that the scratch of one
/// chunk (8 bytes a value) stays in the core's cache.
pub(crate) const CHUNK: usize = 2048;

/// Per-task buffers: the density column, then the colour columns.
#[derive(Default)]
struct Scratch {
    density: Vec<f64>,
    color: Vec<f64>,
}

impl Scratch {
    /// Gathers `raw[., 0] + shift` of the chunk's rows (`k` values a row).
    #[inline(always)]
    fn gather_density<F: Float>(&mut self, raw: &[F], k: usize, shift: f64) -> &mut [f64] {
        self.density.resize(raw.len() / k, 0.0);
        for (d, row) in self.density.iter_mut().zip(raw.chunks_exact(k)) {
            *d = row[0].as_f64() + shift;
        }
        &mut self.density
    }

    /// `len` values of colour scratch, whatever they hold (to be written whole).
    #[inline(always)]
    fn color_room(&mut self, len: usize) -> &mut [f64] {
        self.color.resize(len, 0.0);
        &mut self.color
    }

    /// Gathers `raw[., 1..k]` of the chunk's rows, row-major.
    #[inline(always)]
    fn gather_color<F: Float>(&mut self, raw: &[F], k: usize) -> &mut [f64] {
        self.color.resize(raw.len() / k * (k - 1), 0.0);
        if k == 4 {
            // The common RGB case with the row length a constant: no inner loop to set up.
            for (c, row) in self.color.chunks_exact_mut(3).zip(raw.chunks_exact(4)) {
                c[0] = row[1].as_f64();
                c[1] = row[2].as_f64();
                c[2] = row[3].as_f64();
            }
        } else {
            for (c, row) in self.color.chunks_exact_mut(k - 1).zip(raw.chunks_exact(k)) {
                for (c, v) in c.iter_mut().zip(&row[1..]) {
                    *c = v.as_f64();
                }
            }
        }
        &mut self.color
    }
}

/// The density column alone: `sigma[i] = softplus(raw[i, 0] + shift)`.
pub(crate) fn density<F: Float>(shift: f64, k: usize, raw: &[F], sigma: &mut [F]) {
    sigma
        .par_chunks_mut(CHUNK)
        .zip(raw.par_chunks(CHUNK * k))
        .for_each_init(Scratch::default, |scratch, (sigma, raw)| {
            density_chunk(shift, k, raw, sigma, scratch, None)
        });
}

/// `sigma[i] = softplus(raw[i, 0] + shift)`, `color[i, c] = sigmoid(raw[i, c + 1])`; `raw`
/// is `[n, k]`, `sigma` `[n]`, `color` `[n, k - 1]`, all row-major; with `kept` (`n k` values)
/// each value's decay is written there too (see the module's docs for its layout).
pub(crate) fn forward<F: Float>(
    shift: f64,
    k: usize,
    raw: &[F],
    sigma: &mut [F],
    color: &mut [F],
    kept: Option<&mut [f64]>,
) {
    let chunks = sigma
        .par_chunks_mut(CHUNK)
        .zip(color.par_chunks_mut(CHUNK * (k - 1)))
        .zip(raw.par_chunks(CHUNK * k));
    match kept {
        Some(kept) => chunks.zip(kept.par_chunks_mut(CHUNK * k)).for_each_init(
            Scratch::default,
            |scratch, (((sigma, color), raw), kept)| {
                let (density_kept, color_kept) = kept.split_at_mut(sigma.len());
                density_chunk(shift, k, raw, sigma, scratch, Some(density_kept));
                color_chunk(k, raw, color, scratch, Some(color_kept));
            },
        ),
        None => chunks.for_each_init(Scratch::default, |scratch, ((sigma, color), raw)| {
            density_chunk(shift, k, raw, sigma, scratch, None);
            color_chunk(k, raw, color, scratch, None);
        }),
    }
}

/// `g_raw[i, 0] = g_sigma[i] sigmoid(raw[i, 0] + shift)`, `g_raw[i, c + 1] = g_color[i, c]
/// sigmoid'(raw[i, c + 1])`, zero where an upstream gradient is `None`; shapes as
/// [`forward`], `g_raw` as `raw`; `kept`, the decays the forward kept, if it did.
pub(crate) fn backward<F: Float>(
    shift: f64,
    k: usize,
    raw: &[F],
    g_sigma: Option<&[F]>,
    g_color: Option<&[F]>,
    g_raw: &mut [F],
    kept: Option<&[f64]>,
) {
    g_raw
        .par_chunks_mut(CHUNK * k)
        .zip(raw.par_chunks(CHUNK * k))
        .enumerate()
        .for_each_init(Scratch::default, |scratch, (chunk, (g_raw, raw))| {
            let rows = raw.len() / k;
            let start = chunk * CHUNK;
            let g_sigma = g_sigma.map(|g| &g[start..start + rows]);
            let g_color = g_color.map(|g| &g[start * (k - 1)..(start + rows) * (k - 1)]);
            let kept = kept.map(|d| d[start * k..(start + rows) * k].split_at(rows));
            backward_chunk(shift, k, raw, g_sigma, g_color, g_raw, scratch, kept);
        });
}

/// One chunk's densities, and their decays into `kept` if given. Compiled for the vector
/// units this machine has (chosen at run time); the values do not depend on which: every
/// fused multiply-add is written as one.
#[multiversion(targets("x86_64+avx512f+avx512dq+fma", "x86_64+avx2+fma", "aarch64+neon"))]
fn density_chunk<F: Float>(
    shift: f64,
    k: usize,
    raw: &[F],
    sigma: &mut [F],
    scratch: &mut Scratch,
    kept: Option<&mut [f64]>,
) {
    let x = scratch.gather_density(raw, k, shift);
    if single_tier::<F>() {
        activate::<true>(x, kept, softplus_decayed::<true>);
    } else {
        activate::<false>(x, kept, softplus_decayed::<false>);
    }
    for (o, &v) in sigma.iter_mut().zip(x.iter()) {
        *o = F::lit(v);
    }
}

/// `x[i] = form(x[i], decay(x[i]))` (softplus or sigmoid from their decays), keeping the
/// decays in `kept` if given. `form` is passed as a function item, not a closure, so that
/// the loops are compiled with their vectorised callers' features.
#[inline(always)]
fn activate<const SINGLE: bool>(x: &mut [f64], kept: Option<&mut [f64]>, form: impl Fn(f64, f64) -> f64) {
    match kept {
        Some(kept) => {
            for (e, &v) in kept.iter_mut().zip(x.iter()) {
                *e = decay::<SINGLE>(v);
            }
            for (v, &e) in x.iter_mut().zip(kept.iter()) {
                *v = form(*v, e);
            }
        }
        None => {
            for v in x.iter_mut() {
                *v = form(*v, decay::<SINGLE>(*v));
            }
        }
    }
}

/// One chunk's colours (as [`density_chunk`]).
#[multiversion(targets("x86_64+avx512f+avx512dq+fma", "x86_64+avx2+fma", "aarch64+neon"))]
fn color_chunk<F: Float>(k: usize, raw: &[F], color: &mut [F], scratch: &mut Scratch, kept: Option<&mut [f64]>) {
    let x = scratch.gather_color(raw, k);
    if single_tier::<F>() {
        activate::<true>(x, kept, sigmoid_decayed::<true>);
    } else {
        activate::<false>(x, kept, sigmoid_decayed::<false>);
    }
    for (o, &v) in color.iter_mut().zip(x.iter()) {
        *o = F::lit(v);
    }
}

/// `x[i] = g[i] slope(x[i], decay(x[i]))`, the decays read from `kept` if given (then `x`
/// may hold anything for a `slope` that reads only the decay). `slope` is a function item, as
/// in [`activate`].
#[inline(always)]
fn slopes<F: Float, const SINGLE: bool>(x: &mut [f64], g: &[F], kept: Option<&[f64]>, slope: impl Fn(f64, f64) -> f64) {
    match kept {
        Some(kept) => {
            for ((v, &g), &e) in x.iter_mut().zip(g).zip(kept) {
                *v = g.as_f64() * slope(*v, e);
            }
        }
        None => {
            for (v, &g) in x.iter_mut().zip(g) {
                *v = g.as_f64() * slope(*v, decay::<SINGLE>(*v));
            }
        }
    }
}

/// `sigmoid'` from the decay alone, in the shape [`slopes`] takes.
#[inline(always)]
fn color_slope<const SINGLE: bool>(_x: f64, e: f64) -> f64 {
    sigmoid_slope_decayed::<SINGLE>(e)
}

/// One chunk's gradient (as [`density_chunk`]); products in f64, rounded once. `kept`: the
/// chunk's density decays and colour decays, if the forward kept them.
#[allow(clippy::too_many_arguments)]
#[multiversion(targets("x86_64+avx512f+avx512dq+fma", "x86_64+avx2+fma", "aarch64+neon"))]
fn backward_chunk<F: Float>(
    shift: f64,
    k: usize,
    raw: &[F],
    g_sigma: Option<&[F]>,
    g_color: Option<&[F]>,
    g_raw: &mut [F],
    scratch: &mut Scratch,
    kept: Option<(&[f64], &[f64])>,
) {
    match g_sigma {
        Some(g) => {
            let x = scratch.gather_density(raw, k, shift);
            let kept = kept.map(|(density, _)| density);
            // softplus' = sigmoid.
            if single_tier::<F>() {
                slopes::<F, true>(x, g, kept, sigmoid_decayed::<true>);
            } else {
                slopes::<F, false>(x, g, kept, sigmoid_decayed::<false>);
            }
            for (row, &v) in g_raw.chunks_exact_mut(k).zip(x.iter()) {
                row[0] = F::lit(v);
            }
        }
        None => {
            for row in g_raw.chunks_exact_mut(k) {
                row[0] = F::zero();
            }
        }
    }
    match g_color {
        Some(g) => {
            let kept = kept.map(|(_, color)| color);
            // With the decays the raw colours are not needed: only room for the results.
            let x = match kept {
                Some(_) => scratch.color_room(raw.len() / k * (k - 1)),
                None => scratch.gather_color(raw, k),
            };
            if single_tier::<F>() {
                slopes::<F, true>(x, g, kept, color_slope::<true>);
            } else {
                slopes::<F, false>(x, g, kept, color_slope::<false>);
            }
            if k == 4 {
                for (row, v) in g_raw.chunks_exact_mut(4).zip(x.chunks_exact(3)) {
                    row[1] = F::lit(v[0]);
                    row[2] = F::lit(v[1]);
                    row[3] = F::lit(v[2]);
                }
            } else {
                for (row, values) in g_raw.chunks_exact_mut(k).zip(x.chunks_exact(k - 1)) {
                    for (o, &v) in row[1..].iter_mut().zip(values) {
                        *o = F::lit(v);
                    }
                }
            }
        }
        None => {
            for row in g_raw.chunks_exact_mut(k) {
                row[1..].fill(F::zero());
            }
        }
    }
}
