//! The occupancy marcher: each ray walked cell by cell through the grid (a 3-D DDA), sampled
//! at a fixed step only over its runs of occupied cells.

use fogray_tape::Float;

use super::occupancy::OccupancyGrid;
use super::packed::{check_lengths, check_step, pack_chunks, PackedSamples, Piece};
use super::stratified::{Jitter, RayJitter};
use crate::error::OpsError;
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

/// A ray's origin, direction and the part `[lo, hi]` of it to walk.
type Segment = ([f64; 3], [f64; 3], f64, f64);

/// One ray's walk through the grid's cells, a step at a time (see
/// [`OccupancyGrid::occupied_runs`]), so that two rays can be walked in one loop.
struct Walk {
    o: [f64; 3],
    hi: f64,
    min: [f64; 3],
    /// `1 / d`: the exits are products with it, not divisions, on the walk's one chain.
    inv: [f64; 3],
    /// The direction's sign along each axis, as a cell index step and as an `f64`.
    dir: [i64; 3],
    dir_f: [f64; 3],
    /// The last cell along each axis before the ray leaves the grid (an axis the ray does
    /// not move along is never the first exit).
    last: [i64; 3],
    /// The linear index's step along each axis (see OccupancyGrid's layout).
    step: [i64; 3],
    idx: [i64; 3],
    linear: i64,
    /// Where the ray leaves the current cell across each axis.
    t_exit: [f64; 3],
    /// The exit of the next cell along each axis, computed a step ahead: a step's new exit
    /// is then a copy, and the next choice of axis need not wait for the arithmetic.
    t_after: [f64; 3],
    /// The boundary index of the exit after `t_after` along each axis, kept as an f64 (an
    /// integer, so exactly the one the exit's formula takes): no conversion on the chain.
    edge_f: [f64; 3],
    t: f64,
    /// The run being grown, handed on once the next one does not touch it.
    pending: Option<(f64, f64)>,
}

impl Walk {
    /// The walk of `o + t d` over `[lo, hi]`, or `None` if it starts in no cell.
    #[inline(always)]
    fn new(grid: &OccupancyGrid, o: [f64; 3], d: [f64; 3], lo: f64, hi: f64) -> Option<Self> {
        let r = grid.resolution as i64;
        let min = grid.bounds.min();
        let start = grid.cell_of(std::array::from_fn(|a| {
            (o[a] + lo * d[a]).clamp(min[a], grid.bounds.max()[a])
        }))?;
        let idx = start.map(|i| i as i64);
        let dir: [i64; 3] = std::array::from_fn(|a| {
            if d[a] > 0.0 {
                1
            } else if d[a] < 0.0 {
                -1
            } else {
                0
            }
        });
        let inv: [f64; 3] = std::array::from_fn(|a| 1.0 / d[a]);
        let exit = |a: usize, i: i64| -> f64 {
            match dir[a] {
                0 => f64::INFINITY,
                s => (min[a] + (i + i64::from(s > 0)) as f64 * grid.cell[a] - o[a]) * inv[a],
            }
        };
        let stride = [r * r, r, 1];
        Some(Walk {
            o,
            hi,
            min,
            inv,
            dir,
            dir_f: dir.map(|s| s as f64),
            last: dir.map(|s| if s > 0 { r - 1 } else { 0 }),
            step: std::array::from_fn(|a| dir[a] * stride[a]),
            idx,
            linear: idx[0] * stride[0] + idx[1] * stride[1] + idx[2],
            t_exit: std::array::from_fn(|a| exit(a, idx[a])),
            t_after: std::array::from_fn(|a| exit(a, idx[a] + dir[a])),
            edge_f: std::array::from_fn(|a| (idx[a] + 2 * dir[a] + i64::from(dir[a] > 0)) as f64),
            t: lo,
            pending: None,
        })
    }

    /// Handles the current cell and moves to the next; `false` once the ray has left the
    /// grid or passed `hi` (then `step` must not be called again).
    #[inline(always)]
    fn step(&mut self, grid: &OccupancyGrid, run: &mut impl FnMut(f64, f64)) -> bool {
        let axis = first_exit(&self.t_exit);
        let leaving = self.idx[axis] == self.last[axis];
        if grid.is_occupied_linear(self.linear as usize) {
            // The last cell before the grid's far face runs to hi: the face's t, rounded
            // differently from the clip that gave hi, must not leave a sliver.
            let t_end = if leaving {
                self.hi
            } else {
                self.t_exit[axis].min(self.hi)
            };
            if t_end > self.t {
                match &mut self.pending {
                    Some(p) if p.1 == self.t => p.1 = t_end,
                    _ => {
                        if let Some((a, b)) = self.pending {
                            run(a, b);
                        }
                        self.pending = Some((self.t, t_end));
                    }
                }
            }
        }
        if leaving || self.t_exit[axis] >= self.hi {
            return false;
        }
        self.t = self.t.max(self.t_exit[axis]);
        self.idx[axis] += self.dir[axis];
        self.linear += self.step[axis];
        // Only the crossed axis has a new exit, computed a step ago; it moves, so that exit
        // is finite.
        self.t_exit[axis] = self.t_after[axis];
        self.t_after[axis] = (self.min[axis] + self.edge_f[axis] * grid.cell[axis] - self.o[axis]) * self.inv[axis];
        self.edge_f[axis] += self.dir_f[axis];
        true
    }

    /// Hands on the last run.
    #[inline(always)]
    fn finish(self, run: &mut impl FnMut(f64, f64)) {
        if let Some((a, b)) = self.pending {
            run(a, b);
        }
    }
}

impl OccupancyGrid {
    /// The part `[lo, hi]` (with `hi > lo`) of the ray `o + t d`'s interval `interval` that
    /// lies in the grid's box, or `None` (a miss, no interval, or an empty part).
    pub(crate) fn box_segment(&self, o: [f64; 3], d: [f64; 3], interval: Option<(f64, f64)>) -> Option<(f64, f64)> {
        let (near, far) = interval?;
        let (box_near, box_far) = self.bounds.clip_ray(o, d)?;
        let (lo, hi) = (near.max(box_near), far.min(box_far));
        (hi > lo).then_some((lo, hi))
    }

    /// Calls `run(a, b)` for each part `[a, b]` of `[lo, hi]` on the ray `o + t d` that lies
    /// in occupied cells, as maximal runs in increasing `t`.
    ///
    /// The ray is walked cell by cell (a 3-D DDA). Cell boundaries are computed from the cell
    /// index each time (never accumulated), so long rays do not drift; a start index off by
    /// one through rounding costs one zero-length step. The walk is latency-bound: each step
    /// chooses the axis of the first exit, so that choice is made without branches and the
    /// crossed axis's next exit is computed one step ahead.
    pub(crate) fn occupied_runs(&self, o: [f64; 3], d: [f64; 3], lo: f64, hi: f64, mut run: impl FnMut(f64, f64)) {
        let Some(mut walk) = Walk::new(self, o, d, lo, hi) else {
            return;
        };
        while walk.step(self, &mut run) {}
        walk.finish(&mut run);
    }

    /// [`OccupancyGrid::occupied_runs`] of two rays, walked in one loop a step of each at a
    /// time: one ray's walk is a chain of dependent steps, and the other ray's steps fill its
    /// latency. Each ray's runs are exactly those of its own walk.
    pub(crate) fn occupied_runs_pair(
        &self,
        first: Segment,
        second: Segment,
        mut run_first: impl FnMut(f64, f64),
        mut run_second: impl FnMut(f64, f64),
    ) {
        let a = Walk::new(self, first.0, first.1, first.2, first.3);
        let b = Walk::new(self, second.0, second.1, second.2, second.3);
        match (a, b) {
            (Some(mut a), Some(mut b)) => {
                loop {
                    let more_a = a.step(self, &mut run_first);
                    let more_b = b.step(self, &mut run_second);
                    if !(more_a && more_b) {
                        if more_a {
                            while a.step(self, &mut run_first) {}
                        }
                        if more_b {
                            while b.step(self, &mut run_second) {}
                        }
                        break;
                    }
                }
                a.finish(&mut run_first);
                b.finish(&mut run_second);
            }
            (Some(mut a), None) => {
                while a.step(self, &mut run_first) {}
                a.finish(&mut run_first);
            }
            (None, Some(mut b)) => {
                while b.step(self, &mut run_second) {}
                b.finish(&mut run_second);
            }
            (None, None) => {}
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
    ) -> Result<PackedSamples<F>, OpsError> {
        check_lengths(rays, intervals)?;
        check_step(step)?;
        // A ray's part of the grid's box within its interval.
        let segment = |r: usize| -> Option<Segment> {
            let (o, d) = rays.ray(r);
            let (lo, hi) = self.box_segment(o, d, intervals.segment(r))?;
            Some((o, d, lo, hi))
        };
        // One ray walked alone, its pieces and their count appended.
        let single = |r: usize, seg: Option<Segment>, counts: &mut Vec<usize>, pieces: &mut Vec<Piece>| {
            let before = pieces.len();
            if let Some((o, d, lo, hi)) = seg {
                let mut jitter = RayJitter::for_ray(jitter, r);
                self.occupied_runs(o, d, lo, hi, |a, b| jitter.cut(a, b, lo, step, pieces));
            }
            counts.push(pieces.len() - before);
        };
        // Ray r's buffered runs (its walk started at lo) cut into pieces, and their count.
        let cut_runs = |r: usize, lo: f64, runs: &[(f64, f64)], counts: &mut Vec<usize>, pieces: &mut Vec<Piece>| {
            let before = pieces.len();
            let mut jitter = RayJitter::for_ray(jitter, r);
            for &(a, b) in runs {
                jitter.cut(a, b, lo, step, pieces);
            }
            counts.push(pieces.len() - before);
        };
        // Rays walked two at a time; their runs wait in two buffers and are cut into pieces
        // in ray order (so a jittered ray draws in the same order as walked alone).
        Ok(pack_chunks(rays, |task, counts, pieces| {
            let mut first_runs: Vec<(f64, f64)> = Vec::new();
            let mut second_runs: Vec<(f64, f64)> = Vec::new();
            let mut r = task.start;
            while r + 1 < task.end {
                match (segment(r), segment(r + 1)) {
                    (Some(a), Some(b)) => {
                        first_runs.clear();
                        second_runs.clear();
                        self.occupied_runs_pair(a, b, |x, y| first_runs.push((x, y)), |x, y| second_runs.push((x, y)));
                        cut_runs(r, a.2, &first_runs, counts, pieces);
                        cut_runs(r + 1, b.2, &second_runs, counts, pieces);
                    }
                    (a, b) => {
                        single(r, a, counts, pieces);
                        single(r + 1, b, counts, pieces);
                    }
                }
                r += 2;
            }
            if r < task.end {
                single(r, segment(r), counts, pieces);
            }
        }))
    }
}
