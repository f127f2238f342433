//! The backward into the packed values: a deterministic scatter of `w_k g` into the stored
//! corner rows of every position's cell.
//!
//! Rows are in node order, so the nodes of cell layer `j` along x (node layers `j` and
//! `j + 1`) are one run of rows, and the runs of the even layers are disjoint, as are those of
//! the odd ones. Positions are listed under their cell layer by a stable counting sort; the
//! even layers are summed in parallel, then the odd ones, each layer's positions in position
//! order, into f64 sums rounded once. No order depends on the number of threads, so neither
//! does any bit of the result.

use fogray_tape::Float;
use rayon::prelude::*;

use super::super::forward::{position, CHUNK};
use super::super::geometry::{weights, Layout};
use super::super::scratch::Scratch;
use super::index::NodeIndex;

/// Writes `dL/ddata` (`[kept, ch]`, flat, every value) for upstream gradients `upstream`
/// (`[n, ch]`, flat) at `positions` (`[n, 3]`, flat), the f64 sums kept in `scratch`.
pub(crate) fn data_gradient<F: Float>(
    layout: &Layout<3>,
    index: &NodeIndex,
    positions: &[F],
    upstream: &[F],
    ch: usize,
    out: &mut [F],
    scratch: &Scratch,
) {
    let n = positions.len() / 3;
    let layers = layout.axes[0].last_cell + 1;
    // Each position's cell layer; `layers` for one outside the box or with a zero gradient.
    let mut keys = vec![layers as u32; n];
    keys.par_chunks_mut(CHUNK).enumerate().for_each(|(c, keys)| {
        for (i, key) in keys.iter_mut().enumerate() {
            let s = c * CHUNK + i;
            if upstream[s * ch..(s + 1) * ch].iter().any(|&v| v != F::zero()) {
                if let Some(cell) = layout.locate(position::<F, 3>(positions, s)) {
                    *key = cell.index[0] as u32;
                }
            }
        }
    });
    let mut starts = vec![0usize; layers + 2];
    for &k in &keys {
        starts[k as usize + 1] += 1;
    }
    for k in 0..=layers {
        starts[k + 1] += starts[k];
    }
    let mut next = starts.clone();
    let mut order = vec![0u32; starts[layers]];
    for (s, &k) in keys.iter().enumerate() {
        if (k as usize) < layers {
            order[next[k as usize]] = s as u32;
            next[k as usize] += 1;
        }
    }
    let mut acc = scratch.take_zeros(out.len());
    let n0 = layout.axes[0].last_cell + 2;
    for parity in 0..2 {
        // Cell layer j's rows run from node layer j's first row to node layer j + 2's.
        let first = index.layer_start(parity.min(n0)) * ch;
        let mut rest = &mut acc[first..];
        let mut windows = Vec::new();
        for j in (parity..layers).step_by(2) {
            let len = (index.layer_start((j + 2).min(n0)) - index.layer_start(j)) * ch;
            let (window, tail) = rest.split_at_mut(len);
            windows.push((j, window));
            rest = tail;
        }
        windows.into_par_iter().for_each(|(j, window)| {
            let origin = index.layer_start(j);
            for &s in &order[starts[j]..starts[j + 1]] {
                let s = s as usize;
                let Some(cell) = layout.locate(position::<F, 3>(positions, s)) else {
                    continue;
                };
                let w = weights(cell.t);
                let g = &upstream[s * ch..(s + 1) * ch];
                for (&wk, &corner) in w.iter().zip(&layout.corners) {
                    if let Some(r) = index.row_at(cell.node + corner) {
                        let sums = &mut window[(r - origin) * ch..(r - origin + 1) * ch];
                        for (a, &g) in sums.iter_mut().zip(g) {
                            *a += wk * g.as_f64();
                        }
                    }
                }
            }
        });
    }
    out.par_chunks_mut(CHUNK * ch)
        .zip(acc.par_chunks_mut(CHUNK * ch))
        .for_each(|(out, sums)| {
            for (o, a) in out.iter_mut().zip(sums) {
                *o = F::lit(*a);
                *a = 0.0;
            }
        });
    scratch.give_zeros(acc);
}
