//! The occupancy marcher: each ray walked cell by cell through the grid (a 3-D DDA), sampled
//! at a fixed step only over its runs of occupied cells.

use fogray_tape::Float;

use super::occupancy::OccupancyGrid;
use super::packed::{check_lengths, pack_chunks, PackedSamples};
use super::stratified::{Jitter, RayJitter};
use crate::error::SampleError;
use crate::rays::{RayBatch, RayIntervals};

/// Per axis, the `t` at which a ray leaves each cell it can meet along that axis, in the
/// order it meets them: scratch for [`OccupancyGrid::occupied_runs`], reused from ray to ray.
#[derive(Debug, Default)]
pub(crate) struct ExitTables {
    t: [Vec<f64>; 3],
}

impl OccupancyGrid {
    /// Calls `run(a, b)` for each part `[a, b]` of `[lo, hi]` on the ray `o + t d` that lies
    /// in occupied cells, as maximal runs in increasing `t`.
    ///
    /// The ray is walked cell by cell (a 3-D DDA). Cell boundaries are computed from the cell
    /// index (never accumulated), so long rays do not drift; a start index off by one through
    /// rounding costs one zero-length step. The walk is latency-bound: each step chooses the
    /// axis of the first exit and needs that axis's next exit before the next choice. So all
    /// the exits the ray can meet are computed first, independently of one another, into
    /// `tables`, and the walk keeps the three current exits in registers, choosing by selects
    /// (the choice follows the ray's geometry, which a branch predictor cannot guess) and
    /// reading the crossed axis's next exit from its table.
    pub(crate) fn occupied_runs(
        &self,
        o: [f64; 3],
        d: [f64; 3],
        lo: f64,
        hi: f64,
        tables: &mut ExitTables,
        mut run: impl FnMut(f64, f64),
    ) {
        let r = self.resolution as i64;
        let min = self.bounds.min();
        let start = self.cell_of(std::array::from_fn(|a| {
            (o[a] + lo * d[a]).clamp(min[a], self.bounds.max()[a])
        }));
        let Some(start) = start else { return };
        let stride = [r * r, r, 1];
        let mut linear = 0;
        let mut step = [0i64; 3];
        for a in 0..3 {
            let i = start[a] as i64;
            linear += i * stride[a];
            let table = &mut tables.t[a];
            table.clear();
            if d[a] == 0.0 {
                // Never left across this axis.
                table.push(f64::INFINITY);
                continue;
            }
            let (dir, crossings) = if d[a] > 0.0 { (1, r - 1 - i) } else { (-1, i) };
            step[a] = dir * stride[a];
            // The far face of cell i + j dir along the ray: a product with 1/d.
            // The face's index i + j dir + up is counted in f64 (exact for any grid), so the
            // loop has no integer conversion and vectorises.
            let (first, inv) = ((i + i64::from(dir > 0)) as f64, 1.0 / d[a]);
            let (dir, cell) = (dir as f64, self.cell[a]);
            table.resize(crossings as usize + 1, 0.0);
            for (j, t) in table.iter_mut().enumerate() {
                *t = (min[a] + (first + j as f64 * dir) * cell - o[a]) * inv;
            }
        }
        let [tx, ty, tz] = &tables.t;
        // The last cell along each axis before the ray leaves the grid (an axis the ray does
        // not move along is never the first exit, or only at an infinite t, past hi).
        let last = [tx.len() - 1, ty.len() - 1, tz.len() - 1];
        let mut k = [0usize; 3];
        let (mut x, mut y, mut z) = (tx[0], ty[0], tz[0]);
        // The run being grown, handed to `run` once the next one does not touch it.
        let mut pending: Option<(f64, f64)> = None;
        let mut t = lo;
        loop {
            // The axis of the first exit, the lowest on a tie, as one flag per axis.
            let on_y = y < x;
            let t_xy = if on_y { y } else { x };
            let on_z = z < t_xy;
            let t_exit = if on_z { z } else { t_xy };
            let on = [!on_z & !on_y, !on_z & on_y, on_z];
            let leaving = (0..3).any(|a| on[a] & (k[a] == last[a]));
            if self.is_occupied_linear(linear as usize) {
                // The last cell before the grid's far face runs to hi: the face's t, rounded
                // differently from the clip that gave hi, must not leave a sliver.
                let t_end = if leaving { hi } else { t_exit.min(hi) };
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
            if leaving || t_exit >= hi {
                break;
            }
            t = t.max(t_exit);
            for a in 0..3 {
                k[a] += usize::from(on[a]);
                linear += i64::from(on[a]) * step[a];
            }
            (x, y, z) = (tx[k[0]], ty[k[1]], tz[k[2]]);
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
        Ok(pack_chunks(rays, |chunk, counts, pieces| {
            let mut tables = ExitTables::default();
            for r in chunk {
                let before = pieces.len();
                let (o, d) = rays.ray(r);
                if let (Some((near, far)), Some((box_near, box_far))) =
                    (intervals.segment(r), self.bounds.clip_ray(o, d))
                {
                    let (lo, hi) = (near.max(box_near), far.min(box_far));
                    if hi > lo {
                        let mut jitter = RayJitter::for_ray(jitter, r);
                        self.occupied_runs(o, d, lo, hi, &mut tables, |a, b| jitter.cut(a, b, lo, step, pieces));
                    }
                }
                counts.push(pieces.len() - before);
            }
        }))
    }
}
