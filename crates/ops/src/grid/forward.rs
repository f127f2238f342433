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
use crate::prefetch::prefetch;

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
            // A channel group the compiler knows the width of is summed in registers, in
            // vector lanes.
            1 => lerp_chunk::<F, D, 1>(layout, grid, p, o, 1),
            2 => lerp_chunk::<F, D, 2>(layout, grid, p, o, 2),
            3 => lerp_chunk::<F, D, 3>(layout, grid, p, o, 3),
            4 => lerp_chunk::<F, D, 4>(layout, grid, p, o, 4),
            _ if ch % 4 == 0 => lerp_chunk::<F, D, 4>(layout, grid, p, o, ch),
            _ => lerp_chunk::<F, D, 1>(layout, grid, p, o, ch),
        });
}

/// Positions whose corner rows are requested from memory before the first of them is
/// interpolated: random lookups in a large grid wait on memory, and a batch keeps many
/// loads in flight where one lookup at a time keeps two or three.
const BATCH: usize = 16;

/// Interpolates one chunk, `ch` channels per row in groups of `G` (`G` divides `ch`).
#[inline(always)]
fn lerp_chunk<F: Float, const D: usize, const G: usize>(
    layout: &Layout<D>,
    grid: &[F],
    positions: &[F],
    out: &mut [F],
    ch: usize,
) {
    let corners = &layout.corners[..1 << D];
    for (b, out) in out.chunks_mut(BATCH * ch).enumerate() {
        // First every cell of the batch, with its corner rows requested...
        let mut cells = [None; BATCH];
        for (i, cell) in cells.iter_mut().enumerate().take(out.len() / ch) {
            *cell = layout.locate(position::<F, D>(positions, b * BATCH + i));
            if let Some(c) = cell {
                for &corner in corners {
                    // A hint needs no bounds check: the address is computed, never read.
                    prefetch(grid.as_ptr().wrapping_add((c.node + corner) * ch));
                }
            }
        }
        // ...then the weighted sums, corner by corner in the order of the corners.
        for (o, cell) in out.chunks_exact_mut(ch).zip(&cells) {
            let Some(cell) = cell else {
                o.fill(F::zero());
                continue;
            };
            let w = weights(cell.t).map(F::lit);
            let rows = &grid[cell.node * ch..];
            for (group, o) in o.chunks_exact_mut(G).enumerate() {
                let row = |k: usize| -> &[F; G] {
                    let at = corners[k] * ch + group * G;
                    rows[at..at + G].try_into().expect("a row holds G values")
                };
                // The first product starts the sum (0 + w v would turn -0 into +0).
                let first = row(0);
                let mut acc: [F; G] = std::array::from_fn(|c| w[0] * first[c]);
                for (k, &wk) in w.iter().enumerate().take(1 << D).skip(1) {
                    let r = row(k);
                    for c in 0..G {
                        acc[c] += wk * r[c];
                    }
                }
                o.copy_from_slice(&acc);
            }
        }
    }
}
