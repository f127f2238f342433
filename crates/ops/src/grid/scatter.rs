//! The backward into the grid values: a deterministic scatter of `w_k g` into the `2^D`
//! corner rows of every position's cell.
//!
//! The grid's cells are cut into tiles: slabs of `T` cell layers along axis 0, each cut into
//! `R` cell rows along axis 1 (`T` and `R` from the grid's shape alone). A position in slab
//! `j` only touches node layers `jT ..= (j+1)T`, so the even slabs touch disjoint nodes, and so
//! do the odd ones: the even slabs are summed in parallel, then the odd ones. Each position is
//! listed under its tile by a stable counting sort within fixed blocks of positions, and a
//! slab is summed tile by tile, each tile in block order, then position order: a tile's
//! nodes are few enough to stay in cache while it is summed.
//!
//! Every node's terms are summed in f64 (a node may collect millions of terms: the f32 sum of
//! 2^20 equal terms is off by several percent), in one buffer the size of the grid, rounded
//! once at the end. Nothing depends on the thread count, so neither does any bit of the result.

use fogray_tape::Float;
use rayon::prelude::*;

use multiversion::multiversion;

use super::forward::position;
use super::geometry::{weights, Layout};
use super::scratch::Scratch;
use crate::prefetch::prefetch;

/// Positions per block of the counting sort (fixed: the order of the sums depends on it).
const BLOCK: usize = 1 << 15;

/// A slab holds at least this many gradient values (unless the grid is thinner): fewer,
/// larger tasks.
const MIN_SLAB_VALUES: usize = 1 << 14;

/// A tile's nodes hold at most about this many gradient values (unless one cell row of a
/// slab holds more): its f64 sums then fit in a core's L2 cache.
const TILE_VALUES: usize = 1 << 14;

/// The positions of one block grouped by tile, each with its upstream gradient: records
/// `starts[k]..starts[k + 1]` (of `D + C` values each: the position, then the gradient) are
/// those of tile `k`, in position order. The copy turns the slab pass's scattered reads into
/// one sequential run per block and tile. Kept between calls (see `scratch.rs`).
struct Sorted<F> {
    records: Vec<F>,
    starts: Vec<u32>,
    /// Each position's tile (working memory of the sort).
    keys: Vec<u32>,
}

impl<F> Default for Sorted<F> {
    fn default() -> Self {
        Sorted {
            records: Vec::new(),
            starts: Vec::new(),
            keys: Vec::new(),
        }
    }
}

/// How the grid's cells are cut into tiles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Tiles {
    /// Cell layers per slab along axis 0 (`T`).
    pub(crate) thickness: usize,
    /// Number of slabs.
    pub(crate) slabs: usize,
    /// Cell rows per tile along axis 1 (`R`).
    pub(crate) rows: usize,
    /// Tiles per slab.
    pub(crate) per_slab: usize,
    /// Values per node layer (`n1 (n2) C`).
    pub(crate) layer: usize,
}

impl Tiles {
    pub(crate) fn new<const D: usize>(layout: &Layout<D>, ch: usize) -> Self {
        let layer = layout.strides[0] * ch;
        let thickness = (MIN_SLAB_VALUES / layer).max(1);
        let row = layout.strides[1] * ch;
        // A tile of R rows spans (T + 1) (R + 1) node rows.
        let rows = (TILE_VALUES / ((thickness + 1) * row)).saturating_sub(1).max(1);
        let (cells0, cells1) = (layout.axes[0].last_cell + 1, layout.axes[1].last_cell + 1);
        Tiles {
            thickness,
            slabs: cells0.div_ceil(thickness),
            rows,
            per_slab: cells1.div_ceil(rows),
            layer,
        }
    }

    /// Number of tiles.
    fn count(&self) -> usize {
        self.slabs * self.per_slab
    }
}

/// The tile of a cell from two tables, one entry per cell layer and per cell row: two loads
/// where [`Tiles`]' arithmetic takes two integer divisions, the slowest instructions of the
/// sort.
struct TileOf {
    /// The first tile of each cell layer's slab.
    layer: Vec<u32>,
    /// Each cell row's tile within its slab.
    row: Vec<u32>,
}

impl TileOf {
    fn new<const D: usize>(layout: &Layout<D>, tiles: Tiles) -> Self {
        let cells = |a: usize| layout.axes[a].last_cell + 1;
        TileOf {
            layer: (0..cells(0))
                .map(|i| ((i / tiles.thickness) * tiles.per_slab) as u32)
                .collect(),
            row: (0..cells(1)).map(|i| (i / tiles.rows) as u32).collect(),
        }
    }

    /// The tile of the cell with indices `i0` and `i1` along axes 0 and 1.
    #[inline(always)]
    fn of(&self, i0: usize, i1: usize) -> u32 {
        self.layer[i0] + self.row[i1]
    }
}

/// Sorts one block of positions (and their upstream gradients) by tile into `sorted`.
fn sort_block<F: Float, const D: usize>(
    sorted: &mut Sorted<F>,
    layout: &Layout<D>,
    tiles: Tiles,
    tile_of: &TileOf,
    positions: &[F],
    upstream: &[F],
    ch: usize,
) {
    let n = positions.len() / D;
    // Positions outside the box, or with a zero gradient, get the key after the last tile and
    // are not copied.
    let skip = tiles.count();
    let Sorted { records, starts, keys } = sorted;
    keys.clear();
    keys.extend((0..n).map(|s| {
        if upstream[s * ch..(s + 1) * ch].iter().all(|&v| v == F::zero()) {
            return skip as u32;
        }
        layout
            .locate(position::<F, D>(positions, s))
            .map_or(skip as u32, |c| tile_of.of(c.index[0], c.index[1]))
    }));
    starts.clear();
    starts.resize(skip + 2, 0);
    for &k in keys.iter() {
        starts[k as usize + 1] += 1;
    }
    for k in 0..=skip {
        starts[k + 1] += starts[k];
    }
    let width = D + ch;
    let len = starts[skip] as usize * width;
    // Every record below `len` is written below, so only growth needs a value.
    records.truncate(len);
    records.resize(len, F::zero());
    // next[k], each tile's next free record, begins at starts[k] and ends at starts[k + 1],
    // so that the array shifted by one holds the starts again when the copy is done.
    let next = &mut starts[1..];
    next.rotate_right(1);
    next[0] = 0;
    for (s, &k) in keys.iter().enumerate() {
        if (k as usize) < skip {
            let at = next[k as usize] as usize;
            next[k as usize] += 1;
            let record = &mut records[at * width..(at + 1) * width];
            record[..D].copy_from_slice(&positions[s * D..(s + 1) * D]);
            record[D..].copy_from_slice(&upstream[s * ch..(s + 1) * ch]);
        }
    }
}

/// Writes `dL/dgrid` for upstream gradients `upstream` (`[n, ch]`, flat) at `positions`
/// (`[n, D]`, flat) into `out` (the grid's shape, flat; every value written), with the
/// working memory kept in `scratch`.
pub(crate) fn grid_gradient<F: Float, const D: usize>(
    layout: &Layout<D>,
    positions: &[F],
    upstream: &[F],
    ch: usize,
    out: &mut [F],
    scratch: &Scratch,
) {
    let tiles = Tiles::new(layout, ch);
    let tile_of = TileOf::new(layout, tiles);
    let mut blocks: Vec<Sorted<F>> = scratch.take_blocks();
    blocks.resize_with(positions.len().div_ceil(BLOCK * D), Sorted::default);
    blocks
        .par_iter_mut()
        .zip(positions.par_chunks(BLOCK * D))
        .zip(upstream.par_chunks(BLOCK * ch))
        .for_each(|((sorted, p), g)| sort_block(sorted, layout, tiles, &tile_of, p, g, ch));
    // The sums go to kept f64 zeros, are rounded once into `out` (which therefore needs no
    // zeros of its own, in either precision) and cleared for the next call.
    let mut acc = scratch.take_zeros(out.len());
    sum_slabs(layout, tiles, &blocks, ch, &mut acc, out);
    scratch.give_zeros(acc);
    scratch.give_blocks(blocks);
}

/// Sums every tile's terms into `acc` (the grid's shape, f64, zeros on entry): the even
/// slabs in parallel, then the odd ones; rounds the sums into `out` and leaves `acc` zeros.
///
/// An odd slab's window (its node layers up to the next odd slab's) is final once that slab
/// is summed, the even slabs being done: its task rounds and clears the window while the
/// sums are still in its core's cache, instead of a pass over the whole grid afterwards.
fn sum_slabs<F: Float, const D: usize>(
    layout: &Layout<D>,
    tiles: Tiles,
    blocks: &[Sorted<F>],
    ch: usize,
    acc: &mut [f64],
    out: &mut [F],
) {
    let window = 2 * tiles.thickness * tiles.layer;
    // The node layers before the first odd slab, which only even slab 0 touches.
    let head = (tiles.thickness * tiles.layer).min(acc.len());
    for parity in 0..2 {
        // Slab j = 2 i + parity starts at node layer j T; its window runs to the next slab of
        // the same parity, which covers its nodes jT ..= (j+1)T since T >= 1.
        let first = parity * tiles.thickness * tiles.layer;
        if first >= acc.len() {
            break;
        }
        let tasks = acc[first..]
            .par_chunks_mut(window)
            .zip(out[first..].par_chunks_mut(window));
        tasks.enumerate().for_each(|(i, (dst, out))| {
            let j = 2 * i + parity;
            if j < tiles.slabs {
                let task = SlabTask { layout, slab: j, tiles };
                match ch {
                    // A channel group the compiler knows the width of is summed in vector
                    // lanes.
                    1 => sum_slab::<F, D, 1>(&task, blocks, dst, 1),
                    2 => sum_slab::<F, D, 2>(&task, blocks, dst, 2),
                    3 => sum_slab::<F, D, 3>(&task, blocks, dst, 3),
                    4 => sum_slab::<F, D, 4>(&task, blocks, dst, 4),
                    _ if ch % 4 == 0 => sum_slab::<F, D, 4>(&task, blocks, dst, ch),
                    _ => sum_slab::<F, D, 1>(&task, blocks, dst, ch),
                }
            }
            if parity == 1 {
                round_and_clear(dst, out);
            }
        });
    }
    round_and_clear(&mut acc[..head], &mut out[..head]);
}

/// `out = sums` rounded to the data's precision, and `sums` cleared.
fn round_and_clear<F: Float>(sums: &mut [f64], out: &mut [F]) {
    for (o, a) in out.iter_mut().zip(sums) {
        *o = F::lit(*a);
        *a = 0.0;
    }
}

/// One slab's share of the scatter.
struct SlabTask<'a, const D: usize> {
    layout: &'a Layout<D>,
    slab: usize,
    tiles: Tiles,
}

/// Records whose corner rows are requested from memory before the first of them is summed:
/// a tile's sums are read and written at scattered places, and one record at a time waits on
/// each of them in turn. The sums are still added record by record, in order.
const BATCH: usize = 16;

/// Adds the slab's terms, tile by tile, to `dst`: the f64 sums from the slab's first node
/// layer on; `ch` channels per row in groups of `G` (`G` divides `ch`). Compiled for the
/// vector units this machine has (the products and sums are separate operations, as in the
/// baseline build, so the values do not depend on it).
#[multiversion(targets("x86_64+avx512f+avx512dq+fma", "x86_64+avx2+fma", "aarch64+neon"))]
fn sum_slab<F: Float, const D: usize, const G: usize>(
    task: &SlabTask<'_, D>,
    blocks: &[Sorted<F>],
    dst: &mut [f64],
    ch: usize,
) {
    let layout = task.layout;
    // The slab's first node, as a linear node index.
    let origin = task.slab * task.tiles.thickness * layout.strides[0];
    let first = task.slab * task.tiles.per_slab;
    let corners = &layout.corners[..1 << D];
    let width = D + ch;
    for tile in first..first + task.tiles.per_slab {
        for block in blocks {
            let (lo, hi) = (block.starts[tile] as usize, block.starts[tile + 1] as usize);
            for batch in block.records[lo * width..hi * width].chunks(BATCH * width) {
                // First every cell of the batch, with its corner rows requested...
                let mut cells = [None; BATCH];
                for (cell, record) in cells.iter_mut().zip(batch.chunks_exact(width)) {
                    // The sort located it in this tile; the same code finds the same cell.
                    *cell = layout.locate(position::<F, D>(record, 0));
                    if let Some(c) = cell {
                        for &corner in corners {
                            // A hint needs no bounds check: the address is computed, never read.
                            let at = (c.node + corner).wrapping_sub(origin).wrapping_mul(ch);
                            prefetch(dst.as_ptr().wrapping_add(at));
                        }
                    }
                }
                // ...then their terms, record by record.
                for (cell, record) in cells.iter().zip(batch.chunks_exact(width)) {
                    let Some(cell) = cell else {
                        continue;
                    };
                    let w = weights(cell.t);
                    let rows = &mut dst[(cell.node - origin) * ch..];
                    for (group, g) in record[D..].chunks_exact(G).enumerate() {
                        let g: [f64; G] = std::array::from_fn(|c| g[c].as_f64());
                        for (&wk, &corner) in w.iter().zip(corners) {
                            let at = corner * ch + group * G;
                            let row: &mut [f64; G] = (&mut rows[at..at + G]).try_into().expect("G values");
                            for c in 0..G {
                                row[c] += wk * g[c];
                            }
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::GridBox;

    #[test]
    fn tiles_follow_the_grid_shape() {
        let bbox = GridBox::new(&[0.0; 3], &[1.0; 3]).unwrap();
        // 128^3 x 4: a node layer holds 65536 values, so slabs of one cell layer; a node row
        // 512, so tiles of 15 cell rows (2 x 16 node rows of 512 values = 16384).
        let t = Tiles::new(&Layout::<3>::new(&bbox, &[128, 128, 128]), 4);
        assert_eq!((t.thickness, t.slabs, t.rows, t.per_slab), (1, 127, 15, 9));
        // 9 x 6 x 5 x 3: one slab of all 8 cell layers (a layer holds 90 values, 16384 / 90 =
        // 182); a node row holds 15, so 183 x 15 x 5 <= 16384 gives tiles of 4 cell rows.
        let t = Tiles::new(&Layout::<3>::new(&bbox, &[9, 6, 5]), 3);
        assert_eq!((t.thickness, t.slabs, t.rows, t.per_slab), (182, 1, 4, 2));
        // 2-D, 9 x 4096 x 4: a node row is one node, 16384 / (2 x 4) - 1 = 2047 cell rows.
        let bbox = GridBox::new(&[0.0; 2], &[1.0; 2]).unwrap();
        let t = Tiles::new(&Layout::<2>::new(&bbox, &[9, 4096]), 4);
        assert_eq!((t.thickness, t.slabs, t.rows, t.per_slab), (1, 8, 2047, 3));
    }

    #[test]
    fn tile_tables_agree_with_the_division() {
        let bbox = GridBox::new(&[0.0; 3], &[1.0; 3]).unwrap();
        for (nodes, ch) in [([128, 128, 128], 4), ([9, 6, 5], 3), ([70, 33, 2], 1)] {
            let layout = Layout::<3>::new(&bbox, &nodes);
            let tiles = Tiles::new(&layout, ch);
            let tile_of = TileOf::new(&layout, tiles);
            for i0 in 0..nodes[0] - 1 {
                for i1 in 0..nodes[1] - 1 {
                    let want = (i0 / tiles.thickness) * tiles.per_slab + i1 / tiles.rows;
                    assert_eq!(tile_of.of(i0, i1) as usize, want, "{nodes:?} cell ({i0}, {i1})");
                    assert!(want < tiles.count());
                }
            }
        }
    }
}
