//! The backward into the grid values: a deterministic scatter of `w_k g` into the `2^D`
//! corner rows of every position's cell.
//!
//! The grid is cut along axis 0 into slabs of `T` cell layers (`T` from the grid's shape
//! alone). A position in slab `j` only touches node layers `jT ..= (j+1)T`, so the even slabs
//! touch disjoint nodes, and so do the odd ones: the even slabs are summed in parallel, then
//! the odd ones. Each slab's positions are listed by a stable counting sort within fixed
//! blocks of positions, and summed in block order, then position order, into an f64 buffer
//! (a node may collect millions of terms: the f32 sum of 2^20 equal terms is off by several
//! percent), rounded once and added to the gradient. Nothing depends on the thread count, so
//! neither does any bit of the result; and a slab's nodes stay in cache while it is summed.

use fogray_tape::Float;
use rayon::prelude::*;

use super::forward::position;
use super::geometry::{weights, Layout};

/// Positions per block of the counting sort (fixed: the order of the sums depends on it).
const BLOCK: usize = 1 << 15;

/// A slab holds at least this many gradient values (unless the grid is thinner).
const MIN_SLAB_VALUES: usize = 1 << 14;

/// The positions of one block grouped by slab, each with its upstream gradient: records
/// `starts[j]..starts[j + 1]` (of `D + C` values each: the position, then the gradient) are
/// those of slab `j`, in position order. The copy turns the slab pass's scattered reads into
/// one sequential run per block and slab.
struct Sorted<F> {
    records: Vec<F>,
    starts: Vec<u32>,
}

/// How the grid is cut into slabs.
#[derive(Debug, Clone, Copy)]
struct Slabs {
    /// Cell layers per slab (`T`).
    thickness: usize,
    /// Number of slabs.
    count: usize,
    /// Values per node layer (`n1 (n2) C`).
    layer: usize,
}

impl Slabs {
    fn new<const D: usize>(layout: &Layout<D>, ch: usize) -> Self {
        let layer = layout.strides[0] * ch;
        let thickness = (MIN_SLAB_VALUES / layer).max(1);
        let cells = layout.axes[0].last_cell + 1;
        Slabs {
            thickness,
            count: cells.div_ceil(thickness),
            layer,
        }
    }
}

fn sort_block<F: Float, const D: usize>(
    layout: &Layout<D>,
    slabs: Slabs,
    positions: &[F],
    upstream: &[F],
    ch: usize,
) -> Sorted<F> {
    let n = positions.len() / D;
    let outside = slabs.count;
    let keys: Vec<usize> = (0..n)
        .map(|s| {
            layout
                .cell_along_first_axis(position::<F, D>(positions, s))
                .map_or(outside, |i| i / slabs.thickness)
        })
        .collect();
    let mut starts = vec![0u32; slabs.count + 2];
    for &k in &keys {
        starts[k + 1] += 1;
    }
    for j in 0..=slabs.count {
        starts[j + 1] += starts[j];
    }
    let mut next = starts.clone();
    let mut order = vec![0u32; n];
    for (s, &k) in keys.iter().enumerate() {
        order[next[k] as usize] = s as u32;
        next[k] += 1;
    }
    // Positions outside the box (key `slabs.count`, sorted last) are not copied.
    let inside = starts[slabs.count] as usize;
    let mut records = Vec::with_capacity(inside * (D + ch));
    for &s in &order[..inside] {
        let s = s as usize;
        records.extend_from_slice(&positions[s * D..(s + 1) * D]);
        records.extend_from_slice(&upstream[s * ch..(s + 1) * ch]);
    }
    Sorted { records, starts }
}

/// Adds `dL/dgrid` for upstream gradients `upstream` (`[n, ch]`, flat) at `positions`
/// (`[n, D]`, flat) into `out` (the grid's shape, flat; zeros on entry).
pub(crate) fn grid_gradient<F: Float, const D: usize>(
    layout: &Layout<D>,
    positions: &[F],
    upstream: &[F],
    ch: usize,
    out: &mut [F],
) {
    let slabs = Slabs::new(layout, ch);
    let blocks: Vec<Sorted<F>> = positions
        .par_chunks(BLOCK * D)
        .zip(upstream.par_chunks(BLOCK * ch))
        .map(|(p, g)| sort_block(layout, slabs, p, g, ch))
        .collect();
    let window = 2 * slabs.thickness * slabs.layer;
    for parity in 0..2 {
        // Slab j = 2 i + parity starts at node layer j T; its window runs to the next slab of
        // the same parity, which covers its nodes jT ..= (j+1)T since T >= 1.
        let first = parity * slabs.thickness * slabs.layer;
        if first >= out.len() {
            break;
        }
        out[first..]
            .par_chunks_mut(window)
            .enumerate()
            .for_each_init(Vec::new, |acc, (i, dst)| {
                let j = 2 * i + parity;
                if j < slabs.count {
                    let task = SlabTask { layout, slab: j, slabs };
                    match ch {
                        // A constant channel count lets the compiler unroll the channel loop.
                        1 => task.sum(&blocks, acc, dst, 1),
                        2 => task.sum(&blocks, acc, dst, 2),
                        3 => task.sum(&blocks, acc, dst, 3),
                        4 => task.sum(&blocks, acc, dst, 4),
                        _ => task.sum(&blocks, acc, dst, ch),
                    }
                }
            });
    }
}

/// One slab's share of the scatter.
struct SlabTask<'a, const D: usize> {
    layout: &'a Layout<D>,
    slab: usize,
    slabs: Slabs,
}

impl<const D: usize> SlabTask<'_, D> {
    /// Sums the slab's terms into `acc` (f64, reused across tasks) and adds them to `dst`, the
    /// gradient from the slab's first node layer on.
    #[inline(always)]
    fn sum<F: Float>(&self, blocks: &[Sorted<F>], acc: &mut Vec<f64>, dst: &mut [F], ch: usize) {
        let len = dst.len().min((self.slabs.thickness + 1) * self.slabs.layer);
        acc.clear();
        acc.resize(len, 0.0);
        // The slab's first node, as a linear node index.
        let origin = self.slab * self.slabs.thickness * self.layout.strides[0];
        for block in blocks {
            let (lo, hi) = (block.starts[self.slab] as usize, block.starts[self.slab + 1] as usize);
            for record in block.records[lo * (D + ch)..hi * (D + ch)].chunks_exact(D + ch) {
                let (p, g) = record.split_at(D);
                if g.iter().all(|&v| v == F::zero()) {
                    continue;
                }
                // The sort located it in this slab; the same code finds the same cell.
                let Some(cell) = self.layout.locate(position::<F, D>(p, 0)) else {
                    continue;
                };
                let w = weights(cell.t);
                for (k, &corner) in self.layout.corners[..1 << D].iter().enumerate() {
                    let row = &mut acc[(cell.node - origin + corner) * ch..][..ch];
                    for (a, &v) in row.iter_mut().zip(g) {
                        *a += w[k] * v.as_f64();
                    }
                }
            }
        }
        for (d, &a) in dst.iter_mut().zip(acc.iter()) {
            *d += F::lit(a);
        }
    }
}
