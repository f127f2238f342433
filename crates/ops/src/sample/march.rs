//! The occupancy marcher: each ray walked cell by cell through the grid (a 3-D DDA), empty
//! blocks of cells crossed in one step, sampled at a fixed step only over its runs of
//! occupied cells.

use fogray_tape::Float;

use super::occupancy::OccupancyGrid;
use super::packed::{check_lengths, pack, PackedSamples};
use super::stratified::{Jitter, RayJitter};
use crate::error::SampleError;
use crate::rays::{RayBatch, RayIntervals};

/// The axis whose exit comes first (the lowest axis on a tie), chosen without branches: the
/// choice follows the ray's geometry, which a branch predictor cannot guess.
#[inline]
fn first_exit(t_exit: &[f64; 3]) -> usize {
    let a01 = usize::from(t_exit[1] < t_exit[0]);
    let t01 = if a01 == 1 { t_exit[1] } else { t_exit[0] };
    if t_exit[2] < t01 {
        2
    } else {
        a01
    }
}

impl OccupancyGrid {
    /// Calls `run(a, b)` for each part `[a, b]` of `[lo, hi]` on the ray `o + t d` that lies
    /// in occupied cells, as maximal runs in increasing `t`.
    ///
    /// The ray is walked cell by cell (a 3-D DDA), except that a block of cells with no
    /// occupied cell (see [`Blocks`](super::blocks::Blocks)) is crossed in one step: the ray
    /// leaves the block across the face of its first exit, and the other axes' cell indices
    /// catch up with the per-axis exits that come before it. Cell boundaries are computed from
    /// the cell index each time (never accumulated), so long rays do not drift, and with the
    /// same formula whether a cell is walked or skipped: the runs are those of the walk alone.
    /// A start index off by one through rounding costs one zero-length step.
    pub(crate) fn occupied_runs(&self, o: [f64; 3], d: [f64; 3], lo: f64, hi: f64, mut run: impl FnMut(f64, f64)) {
        let r = self.resolution as i64;
        let min = self.bounds.min();
        let start = self.cell_of(std::array::from_fn(|a| {
            (o[a] + lo * d[a]).clamp(min[a], self.bounds.max()[a])
        }));
        let Some(start) = start else { return };
        let mut idx = start.map(|i| i as i64);
        let dir: [i64; 3] = std::array::from_fn(|a| {
            if d[a] > 0.0 {
                1
            } else if d[a] < 0.0 {
                -1
            } else {
                0
            }
        });
        // The t at which the ray leaves cell idx across axis a: a product with 1/d, not a
        // division, on the DDA's one dependent chain.
        let inv: [f64; 3] = std::array::from_fn(|a| 1.0 / d[a]);
        let exit = |a: usize, i: i64| -> f64 {
            match dir[a] {
                0 => f64::INFINITY,
                s => (min[a] + (i + i64::from(s > 0)) as f64 * self.cell[a] - o[a]) * inv[a],
            }
        };
        let mut t_exit: [f64; 3] = std::array::from_fn(|a| exit(a, idx[a]));
        // The last cell along each axis before the ray leaves the grid (an axis the ray does
        // not move along is never the first exit).
        let last: [i64; 3] = dir.map(|s| if s > 0 { r - 1 } else { 0 });
        // The linear cell index, stepped with the cell index (see OccupancyGrid's layout).
        let stride = [r * r, r, 1];
        let step: [i64; 3] = std::array::from_fn(|a| dir[a] * stride[a]);
        let mut linear = idx[0] * stride[0] + idx[1] * stride[1] + idx[2];
        let block_mask = !((1i64 << super::blocks::BLOCK_SHIFT) - 1);
        let block_size = 1i64 << super::blocks::BLOCK_SHIFT;
        // The run being grown, handed to `run` once the next one does not touch it.
        let mut pending: Option<(f64, f64)> = None;
        let mut t = lo;
        loop {
            if self.is_occupied_linear(linear as usize) {
                let axis = first_exit(&t_exit);
                // The last cell before the grid's far face runs to hi: the face's t, rounded
                // differently from the clip that gave hi, must not leave a sliver.
                let leaving = idx[axis] == last[axis];
                let t_end = if leaving { hi } else { t_exit[axis].min(hi) };
                if t_end > t {
                    match &mut pending {
                        Some(p) if p.1 == t => p.1 = t_end,
                        _ => {
                            if let Some((a, b)) = pending {
                                run(a, b);
                            }
                            pending = Some((t, t_end));
                        }
                    }
                }
                if leaving || t_exit[axis] >= hi {
                    break;
                }
                t = t.max(t_exit[axis]);
                idx[axis] += dir[axis];
                linear += step[axis];
                // Only the crossed axis has a new exit.
                t_exit[axis] = exit(axis, idx[axis]);
            } else if self.blocks.is_empty_at(idx) {
                // The block's last cell along each axis the way the ray goes, and the ray's
                // exit from it: the first of those exits is where the ray leaves the block.
                let far: [i64; 3] = std::array::from_fn(|a| {
                    let first = idx[a] & block_mask;
                    if dir[a] > 0 {
                        (first + block_size - 1).min(r - 1)
                    } else {
                        first
                    }
                });
                let far_exit: [f64; 3] = std::array::from_fn(|a| exit(a, far[a]));
                let axis = first_exit(&far_exit);
                let t_leave = far_exit[axis];
                if far[axis] == last[axis] || t_leave >= hi {
                    break;
                }
                // Every other axis crosses the cell faces it reaches before t_leave, exactly
                // as the walk would (at most to its own far cell, whose exit is not earlier).
                for b in 0..3 {
                    if b != axis {
                        while t_exit[b] < t_leave {
                            idx[b] += dir[b];
                            t_exit[b] = exit(b, idx[b]);
                        }
                    }
                }
                idx[axis] = far[axis] + dir[axis];
                t_exit[axis] = exit(axis, idx[axis]);
                t = t.max(t_leave);
                linear = idx[0] * stride[0] + idx[1] * stride[1] + idx[2];
            } else {
                let axis = first_exit(&t_exit);
                if idx[axis] == last[axis] || t_exit[axis] >= hi {
                    break;
                }
                t = t.max(t_exit[axis]);
                idx[axis] += dir[axis];
                linear += step[axis];
                t_exit[axis] = exit(axis, idx[axis]);
            }
        }
        if let Some((a, b)) = pending {
            run(a, b);
        }
    }

    /// Samples each ray at the fixed step `step` over the occupied parts of its interval
    /// within the grid's box: the runs of occupied cells are cut on the ray's step grid
    /// `t_near + (i + shift) step` (`shift` from `jitter`, 0 without), one sample per piece
    /// at its midpoint with `delta` its length.
    ///
    /// So every sample lies in `[t_near, t_far]` and in an occupied cell, the pieces cover
    /// every occupied cell the ray crosses (a crossing shorter than a step shares a piece with
    /// its occupied neighbour), no piece is longer than `step` without per-sample jitter, and
    /// with every cell occupied the output is [`Uniform`](super::Uniform) with
    /// `Spacing::Step(step)`. Parallel over rays; the same output whatever the thread count.
    ///
    /// Errors: `intervals` not one per ray, `step` not finite and positive.
    pub fn march<F: Float>(
        &self,
        rays: &RayBatch<F>,
        intervals: &RayIntervals,
        step: f64,
        jitter: Jitter,
    ) -> Result<PackedSamples<F>, SampleError> {
        check_lengths(rays, intervals)?;
        if !(step.is_finite() && step > 0.0) {
            return Err(SampleError::Config {
                what: "step",
                value: step,
                rule: "must be finite and positive",
            });
        }
        Ok(pack(rays, |r, pieces| {
            let (o, d) = rays.ray(r);
            let (Some((near, far)), Some((box_near, box_far))) = (intervals.segment(r), self.bounds.clip_ray(o, d))
            else {
                return;
            };
            let (lo, hi) = (near.max(box_near), far.min(box_far));
            if hi > lo {
                let mut jitter = RayJitter::for_ray(jitter, r);
                self.occupied_runs(o, d, lo, hi, |a, b| jitter.cut(a, b, lo, step, pieces));
            }
        }))
    }
}
