//! The occupancy grid's midpoint sampler: each ray's uniform (or jittered) pieces, kept where
//! the piece's midpoint lies in an occupied cell.
//!
//! [`OccupancyGrid::march`] walks every cell a ray crosses, a chain of dependent steps per
//! ray, and cuts the pieces at the faces of the occupied runs. Here each piece is tested on
//! its own: the tests of a ray's pieces are independent, so they run in vector lanes (the
//! cell's bit fetched by a gather where the machine has one), and the cost follows the number
//! of pieces rather than of cells crossed.

use fogray_tape::Float;
use multiversion::multiversion;

use super::occupancy::OccupancyGrid;
use super::packed::{check_lengths, check_step, pack_chunks, PackedSamples, Piece};
use super::stratified::{Jitter, RayJitter};
use crate::error::OpsError;
use crate::rays::{RayBatch, RayIntervals};

/// A ray's cell coordinates as a function of depth: cell coordinate `a` at depth `t` is
/// `base[a] + t dir[a]` (the position in cell units from the grid's min corner).
struct CellRay {
    base: [f64; 3],
    dir: [f64; 3],
}

/// What the midpoint test needs of the grid.
struct CellMap<'a> {
    bits: &'a [u64],
    min: [f64; 3],
    /// `1 / cell size` per axis: products, not divisions, in the vector loop.
    inv: [f64; 3],
    /// The last cell index per axis, as an `f64`.
    top: f64,
    /// The linear index's stride per axis, as `f64`s (exact: at most 2^30 cells).
    stride: [f64; 3],
}

impl<'a> CellMap<'a> {
    fn new(grid: &'a OccupancyGrid) -> Self {
        let r = grid.resolution as f64;
        let min = grid.bounds.min();
        CellMap {
            bits: grid.bits(),
            min,
            inv: std::array::from_fn(|a| 1.0 / grid.cell[a]),
            top: r - 1.0,
            stride: [r * r, r, 1.0],
        }
    }

    fn ray(&self, o: [f64; 3], d: [f64; 3]) -> CellRay {
        CellRay {
            base: std::array::from_fn(|a| (o[a] - self.min[a]) * self.inv[a]),
            dir: std::array::from_fn(|a| d[a] * self.inv[a]),
        }
    }
}

/// `flags[k] = 1` where the midpoint of `pieces[k]` lies in an occupied cell, else 0.
///
/// Each coordinate is floored and clamped to the grid (a midpoint a rounding error outside
/// the box reads its nearest cell, a NaN coordinate cell 0), so the linear index is an integer
/// in `[0, cells)` and its word is within `bits`. Compiled for the vector units this machine has.
#[multiversion(targets("x86_64+avx512f+avx512dq+fma", "x86_64+avx2+fma", "aarch64+neon"))]
fn occupied_flags<'a>(map: &CellMap<'a>, ray: &CellRay, pieces: &[Piece], flags: &mut [u8]) {
    let Some(last_word) = map.bits.len().checked_sub(1) else {
        flags.fill(0);
        return;
    };
    for (f, &(a, b)) in flags.iter_mut().zip(pieces) {
        let mid = 0.5 * (a + b);
        let mut index = 0.0f64;
        for axis in 0..3 {
            // `max` before `min`: a NaN (from overflowing coordinates) becomes cell 0.
            let c = (ray.base[axis] + mid * ray.dir[axis]).floor().max(0.0).min(map.top);
            index += c * map.stride[axis];
        }
        // SAFETY: `index` is an integer in [0, 2^30): each term above is a whole cell index
        // in [0, top] (never NaN, see above) times its stride, so their sum is a cell's
        // linear index, exact in f64.
        // (`to_int_unchecked` rather than `as`: the saturating cast keeps the loop scalar.)
        let i: u64 = unsafe { index.to_int_unchecked() };
        let word = ((i >> 6) as usize).min(last_word);
        // SAFETY: `word <= last_word < bits.len()`. (A checked index keeps the loop scalar.)
        let bits = unsafe { *map.bits.get_unchecked(word) };
        *f = (bits >> (i & 63) & 1) as u8;
    }
}

impl OccupancyGrid {
    /// Samples each ray at the fixed step `step` over its interval within the grid's box,
    /// keeping the pieces whose midpoint lies in an occupied cell: the pieces are those of
    /// [`Stratified`](super::Stratified) with `Spacing::Step(step)` and `jitter` on the box
    /// segment (edges `t_near + (i + shift) step`), one sample at each kept piece's midpoint
    /// with `delta` its length.
    ///
    /// Against [`OccupancyGrid::march`]: pieces are not cut at the faces of the occupied
    /// cells, so a kept piece may reach up to half a step into an empty cell, and a ray that
    /// crosses an occupied cell over less than a step may get no sample in it (when no
    /// midpoint falls inside). In exchange each piece is tested independently of the others
    /// (in vector lanes), where the march walks every cell in turn. With every cell occupied
    /// both give the uniform sampler's output. A midpoint within rounding of a cell face may
    /// be given to either cell. Parallel over rays; the same output whatever the thread count.
    ///
    /// Errors: `intervals` not one per ray, `step` not finite and positive.
    pub fn march_midpoints<F: Float>(
        &self,
        rays: &RayBatch<F>,
        intervals: &RayIntervals,
        step: f64,
        jitter: Jitter,
    ) -> Result<PackedSamples<F>, OpsError> {
        check_lengths(rays, intervals)?;
        check_step(step)?;
        let map = CellMap::new(self);
        Ok(pack_chunks(rays, |task, counts, pieces| {
            // A ray's pieces before the test, and their flags: kept across the task's rays.
            let mut candidates: Vec<Piece> = Vec::new();
            let mut flags: Vec<u8> = Vec::new();
            for r in task {
                let before = pieces.len();
                let (o, d) = rays.ray(r);
                if let Some((lo, hi)) = self.box_segment(o, d, intervals.segment(r)) {
                    candidates.clear();
                    RayJitter::for_ray(jitter, r).cut(lo, hi, lo, step, &mut candidates);
                    flags.clear();
                    flags.resize(candidates.len(), 0);
                    occupied_flags(&map, &map.ray(o, d), &candidates, &mut flags);
                    let kept = candidates.iter().zip(&flags).filter(|(_, &f)| f != 0);
                    pieces.extend(kept.map(|(&p, _)| p));
                }
                counts.push(pieces.len() - before);
            }
        }))
    }
}
