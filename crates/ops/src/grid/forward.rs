//! The forward kernel: each output row is the weighted sum of the `2^D` corner rows of its
//! position's cell, in parallel over fixed chunks of positions.
//!
//! The weights are computed in f64 from the position (also for f32 data) and rounded once to
//! the data's precision; the `2^D`-term sum per channel runs in the data's precision, corner by
//! corner in the order of [`Layout::corners`]. Channels last puts a corner's `C` values in one
//! place, and the two corners that differ along the last axis next to each other: a 3-D lookup
//! with up to 8 f32 channels touches 4 pairs of adjacent rows, 4 to 8 cache lines.

use fogray_tape::Float;
use rayon::prelude::*;

use super::geometry::{weights, Layout};

/// Positions per parallel task (the results do not depend on it).
pub(crate) const CHUNK: usize = 4096;

/// The position of row `s` of packed `[n, D]` positions, widened to f64.
#[inline(always)]
pub(crate) fn position<F: Float, const D: usize>(positions: &[F], s: usize) -> [f64; D] {
    let p = &positions[s * D..(s + 1) * D];
    std::array::from_fn(|a| p[a].as_f64())
}

/// Looks up every position of `positions` (`[n, D]`, flat) in `grid` (channels last, `ch`
/// channels) into `out` (`[n, ch]`, flat, every value written; 0 outside the box).
pub(crate) fn forward<F: Float, const D: usize>(
    layout: &Layout<D>,
    grid: &[F],
    positions: &[F],
    ch: usize,
    out: &mut [F],
) {
    out.par_chunks_mut(CHUNK * ch)
        .zip(positions.par_chunks(CHUNK * D))
        .for_each(|(o, p)| match ch {
            // A constant channel count lets the compiler unroll the channel loop.
            1 => lerp_chunk(layout, grid, p, o, 1),
            2 => lerp_chunk(layout, grid, p, o, 2),
            3 => lerp_chunk(layout, grid, p, o, 3),
            4 => lerp_chunk(layout, grid, p, o, 4),
            _ => lerp_chunk(layout, grid, p, o, ch),
        });
}

/// Positions whose corner rows are requested from memory before the first of them is
/// interpolated: random lookups in a large grid wait on memory, and a batch keeps many
/// loads in flight where one lookup at a time keeps two or three.
const BATCH: usize = 16;

/// Asks the CPU to start loading the cache line holding `x` into cache (a hint: it changes no
/// value, and does nothing on other architectures).
#[inline(always)]
fn prefetch<T>(x: &T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch never faults and has no visible effect; `x` is a valid reference and
    // SSE is part of the x86_64 baseline. (The intrinsic is a safe function from Rust 1.87.)
    #[allow(unused_unsafe)]
    unsafe {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        _mm_prefetch::<_MM_HINT_T0>((x as *const T).cast::<i8>());
    }
}

#[inline(always)]
fn lerp_chunk<F: Float, const D: usize>(layout: &Layout<D>, grid: &[F], positions: &[F], out: &mut [F], ch: usize) {
    let corners = &layout.corners[..1 << D];
    for (b, out) in out.chunks_mut(BATCH * ch).enumerate() {
        // First every cell of the batch, with its corner rows requested...
        let mut cells = [None; BATCH];
        for (i, cell) in cells.iter_mut().enumerate().take(out.len() / ch) {
            *cell = layout.locate(position::<F, D>(positions, b * BATCH + i));
            if let Some(c) = cell {
                for &corner in corners {
                    if let Some(v) = grid.get((c.node + corner) * ch) {
                        prefetch(v);
                    }
                }
            }
        }
        // ...then the weighted sums.
        for (o, cell) in out.chunks_exact_mut(ch).zip(&cells) {
            let Some(cell) = cell else {
                o.fill(F::zero());
                continue;
            };
            let w = weights(cell.t);
            for (k, &corner) in corners.iter().enumerate() {
                let wk = F::lit(w[k]);
                let row = &grid[(cell.node + corner) * ch..][..ch];
                if k == 0 {
                    for (o, &v) in o.iter_mut().zip(row) {
                        *o = wk * v;
                    }
                } else {
                    for (o, &v) in o.iter_mut().zip(row) {
                        *o += wk * v;
                    }
                }
            }
        }
    }
}
