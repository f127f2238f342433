//! The forward and the backward into the positions of the sparse lookup: the dense kernels'
//! arithmetic, with each corner's row read through the index and an absent corner's value 0.
//!
//! A corner's term is skipped where the dense grid would add `w 0 = +0`, so with every node
//! kept the sums are the dense grid's, term for term.

use fogray_tape::Float;
use rayon::prelude::*;

use super::super::forward::{position, CHUNK};
use super::super::geometry::{weight_derivatives, weights, Layout};
use super::index::NodeIndex;
use crate::prefetch::prefetch;

/// Looks up every position (`[n, 3]`, flat) in `data` (`[kept, ch]`, flat) through `index`
/// into `out` (`[n, ch]`, flat, every value written; 0 outside the box and where no corner is
/// stored).
pub(crate) fn forward<F: Float>(
    layout: &Layout<3>,
    index: &NodeIndex,
    data: &[F],
    positions: &[F],
    ch: usize,
    out: &mut [F],
) {
    out.par_chunks_mut(CHUNK * ch)
        .zip(positions.par_chunks(CHUNK * 3))
        .for_each(|(o, p)| lerp_chunk(layout, index, data, p, o, ch));
}

/// Positions whose corner rows are requested from memory before the first is interpolated.
const BATCH: usize = 16;

fn lerp_chunk<F: Float>(layout: &Layout<3>, index: &NodeIndex, data: &[F], positions: &[F], out: &mut [F], ch: usize) {
    let corners = &layout.corners;
    for (b, out) in out.chunks_mut(BATCH * ch).enumerate() {
        // First every cell of the batch and its corners' rows, with the rows requested...
        let mut cells = [None; BATCH];
        let mut rows = [[None; 8]; BATCH];
        for (i, (cell, rows)) in cells.iter_mut().zip(&mut rows).enumerate().take(out.len() / ch) {
            *cell = layout.locate(position::<F, 3>(positions, b * BATCH + i));
            if let Some(c) = cell {
                for (row, &corner) in rows.iter_mut().zip(corners) {
                    *row = index.row_at(c.node + corner);
                    if let Some(r) = row {
                        prefetch(data.as_ptr().wrapping_add(*r * ch));
                    }
                }
            }
        }
        // ...then the weighted sums, corner by corner in the order of the corners.
        for ((o, cell), rows) in out.chunks_exact_mut(ch).zip(&cells).zip(&rows) {
            o.fill(F::zero());
            let Some(cell) = cell else {
                continue;
            };
            let w = weights(cell.t).map(F::lit);
            let mut first = true;
            for (&wk, row) in w.iter().zip(rows) {
                let Some(r) = row else {
                    continue;
                };
                let values = &data[r * ch..(r + 1) * ch];
                // The first product starts the sum (0 + w v would turn -0 into +0).
                if first {
                    o.iter_mut().zip(values).for_each(|(o, &v)| *o = wk * v);
                    first = false;
                } else {
                    o.iter_mut().zip(values).for_each(|(o, &v)| *o += wk * v);
                }
            }
        }
    }
}

/// Writes `dL/dpositions` (`[n, 3]`, flat, every value) for upstream gradients `upstream`
/// (`[n, ch]`, flat): the dense formula with an absent corner's value 0.
pub(crate) fn position_gradient<F: Float>(
    layout: &Layout<3>,
    index: &NodeIndex,
    data: &[F],
    positions: &[F],
    upstream: &[F],
    ch: usize,
    out: &mut [F],
) {
    out.par_chunks_mut(CHUNK * 3)
        .zip(positions.par_chunks(CHUNK * 3))
        .zip(upstream.par_chunks(CHUNK * ch))
        .for_each(|((o, p), g)| {
            for (s, (o, g)) in o.chunks_exact_mut(3).zip(g.chunks_exact(ch)).enumerate() {
                o.fill(F::zero());
                if g.iter().all(|&v| v == F::zero()) {
                    continue;
                }
                let Some(cell) = layout.locate(position::<F, 3>(p, s)) else {
                    continue;
                };
                let mut gv = [0.0f64; 8];
                for (gv, &corner) in gv.iter_mut().zip(&layout.corners) {
                    if let Some(r) = index.row_at(cell.node + corner) {
                        let row = &data[r * ch..(r + 1) * ch];
                        *gv = row.iter().zip(g).map(|(&v, &g)| v.as_f64() * g.as_f64()).sum();
                    }
                }
                for (a, o) in o.iter_mut().enumerate() {
                    let dw = weight_derivatives(cell.t, a);
                    let d: f64 = dw.iter().zip(&gv).map(|(w, v)| w * v).sum();
                    *o = F::lit(d * layout.axes[a].scale);
                }
            }
        });
}
