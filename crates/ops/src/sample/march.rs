//! The occupancy marcher: each ray walked cell by cell through the grid (a 3-D DDA), sampled
//! at a fixed step only over its runs of occupied cells.

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
    /// The ray is walked cell by cell (a 3-D DDA). Cell boundaries are computed from the cell
    /// index each time (never accumulated), so long rays do not drift; a start index off by
    /// one through rounding costs one zero-length step. The walk is latency-bound: each step
    /// chooses the axis of the first exit, so that choice is made without branches and the
    /// crossed axis's next exit is computed one step ahead.
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
        // The exit of the next cell along each axis, computed a step ahead: a step's new exit
        // is then a copy, and the next choice of axis need not wait for the arithmetic.
        let mut t_after: [f64; 3] = std::array::from_fn(|a| exit(a, idx[a] + dir[a]));
        // The boundary index of the exit after `t_after` along each axis, kept as an f64 (an
        // integer, so exactly `exit`'s): no conversion on the walk's chain of arithmetic.
        let dir_f: [f64; 3] = dir.map(|s| s as f64);
        let mut edge_f: [f64; 3] = std::array::from_fn(|a| (idx[a] + 2 * dir[a] + i64::from(dir[a] > 0)) as f64);
        // The last cell along each axis before the ray leaves the grid (an axis the ray does
        // not move along is never the first exit).
        let last: [i64; 3] = dir.map(|s| if s > 0 { r - 1 } else { 0 });
        // The linear cell index, stepped with the cell index (see OccupancyGrid's layout).
        let stride = [r * r, r, 1];
        let step: [i64; 3] = std::array::from_fn(|a| dir[a] * stride[a]);
        let mut linear = idx[0] * stride[0] + idx[1] * stride[1] + idx[2];
        // The run being grown, handed to `run` once the next one does not touch it.
        let mut pending: Option<(f64, f64)> = None;
        let mut t = lo;
        loop {
            let axis = first_exit(&t_exit);
            let leaving = idx[axis] == last[axis];
            if self.is_occupied_linear(linear as usize) {
                // The last cell before the grid's far face runs to hi: the face's t, rounded
                // differently from the clip that gave hi, must not leave a sliver.
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
            }
            if leaving || t_exit[axis] >= hi {
                break;
            }
            t = t.max(t_exit[axis]);
            idx[axis] += dir[axis];
            linear += step[axis];
            // Only the crossed axis has a new exit, computed a step ago.
            t_exit[axis] = t_after[axis];
            // exit(axis, idx[axis] + dir[axis]): the crossed axis moves, so dir[axis] != 0.
            t_after[axis] = (min[axis] + edge_f[axis] * self.cell[axis] - o[axis]) * inv[axis];
            edge_f[axis] += dir_f[axis];
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
