//! The marcher's walk over several rays at once: `K` rays walked in lockstep in one thread,
//! each step advancing every live ray by one cell, so that the rays' dependent chains (choose
//! the axis of the first exit, then the next exit, then the next choice) overlap. A ray that
//! leaves hands its slot to the next ray. Each ray's runs are the same, bit for bit and in the
//! same order, as [`OccupancyGrid::occupied_runs`] gives for it alone.

use super::march::first_exit;
use super::occupancy::OccupancyGrid;

/// The part `[lo, hi]` of the ray `o + t d` to walk.
#[derive(Debug, Clone, Copy)]
pub(crate) struct RaySpan {
    pub(crate) o: [f64; 3],
    pub(crate) d: [f64; 3],
    pub(crate) lo: f64,
    pub(crate) hi: f64,
}

/// The runs of a list of spans, in span order: span `i`'s are `runs[starts[i]..starts[i + 1]]`.
#[derive(Debug, Default)]
pub(crate) struct SpanRuns {
    starts: Vec<usize>,
    runs: Vec<(f64, f64)>,
    /// The runs as the lanes close them, tagged with their span, before they are put in order.
    closed: Vec<(usize, f64, f64)>,
}

impl SpanRuns {
    /// The runs of span `i`, in increasing `t`.
    pub(crate) fn of(&self, i: usize) -> &[(f64, f64)] {
        &self.runs[self.starts[i]..self.starts[i + 1]]
    }

    /// Puts the closed runs in span order (a counting sort: each span's runs were closed in
    /// increasing `t`, and the sort is stable).
    fn sort(&mut self, spans: usize) {
        self.starts.clear();
        self.starts.resize(spans + 1, 0);
        for &(s, ..) in &self.closed {
            self.starts[s + 1] += 1;
        }
        for i in 0..spans {
            self.starts[i + 1] += self.starts[i];
        }
        self.runs.clear();
        self.runs.resize(self.closed.len(), (0.0, 0.0));
        let mut next = self.starts.clone();
        for &(s, a, b) in &self.closed {
            self.runs[next[s]] = (a, b);
            next[s] += 1;
        }
    }
}

/// The state of `K` rays being walked, one slot (lane) each, as arrays over the lanes. Every
/// lane steps every round, without a branch on its ray's geometry or occupancy: choices are
/// selects, and a lane with no ray left sits still on cell 0 with nothing to hand on.
struct Lanes<const K: usize> {
    /// The span each lane walks, `None` once no span is left for it.
    span: [Option<usize>; K],
    o: [[f64; K]; 3],
    inv: [[f64; K]; 3],
    dir: [[i64; K]; 3],
    /// 1 along an axis the ray moves up, else 0: the far face of a cell it leaves.
    up: [[i64; K]; 3],
    idx: [[i64; K]; 3],
    last: [[i64; K]; 3],
    step: [[i64; K]; 3],
    linear: [i64; K],
    t_exit: [[f64; K]; 3],
    t_after: [[f64; K]; 3],
    t: [f64; K],
    hi: [f64; K],
    /// The run being grown: whether there is one, and its ends.
    pending: [bool; K],
    run_lo: [f64; K],
    run_hi: [f64; K],
    /// The lanes whose ray left in the last round.
    done: [bool; K],
}

/// `a` where `c`, else `b`, by bits (a select, never a branch).
#[inline(always)]
fn pick(c: bool, a: f64, b: f64) -> f64 {
    let m = u64::from(c).wrapping_neg();
    f64::from_bits((a.to_bits() & m) | (b.to_bits() & !m))
}

impl<const K: usize> Lanes<K> {
    fn new() -> Self {
        let mut lanes = Lanes {
            span: [None; K],
            o: [[0.0; K]; 3],
            inv: [[0.0; K]; 3],
            dir: [[0; K]; 3],
            up: [[0; K]; 3],
            idx: [[0; K]; 3],
            last: [[0; K]; 3],
            step: [[0; K]; 3],
            linear: [0; K],
            t_exit: [[0.0; K]; 3],
            t_after: [[0.0; K]; 3],
            t: [0.0; K],
            hi: [0.0; K],
            pending: [false; K],
            run_lo: [0.0; K],
            run_hi: [0.0; K],
            done: [false; K],
        };
        for k in 0..K {
            lanes.idle(k);
        }
        lanes
    }

    /// Parks lane `k`: it stays on cell 0 (exits at infinity, no step), and no cell it sees
    /// ends after its `t` (hi is minus infinity), so it never grows or hands on a run.
    fn idle(&mut self, k: usize) {
        self.span[k] = None;
        for a in 0..3 {
            self.dir[a][k] = 0;
            self.up[a][k] = 0;
            self.step[a][k] = 0;
            self.t_exit[a][k] = f64::INFINITY;
            self.t_after[a][k] = f64::INFINITY;
        }
        self.linear[k] = 0;
        self.t[k] = 0.0;
        self.hi[k] = f64::NEG_INFINITY;
        self.pending[k] = false;
    }
}

impl OccupancyGrid {
    /// The runs of every span, as [`OccupancyGrid::occupied_runs`] gives them one span at a
    /// time, walked `K` spans at a time. `out` is reused (its buffers keep their capacity).
    pub(crate) fn occupied_runs_of_spans<const K: usize>(&self, spans: &[RaySpan], out: &mut SpanRuns) {
        let mut lanes = Lanes::<K>::new();
        let mut next = 0;
        for k in 0..K {
            next = self.start_lane(&mut lanes, k, spans, next);
        }
        // Closed runs are written unconditionally at `n` and kept by moving `n` on; the
        // buffer has room for every lane to close one run each round.
        let closed = &mut out.closed;
        closed.clear();
        let mut n = 0;
        while lanes.span.iter().any(Option::is_some) {
            if closed.len() < n + K {
                closed.resize(2 * closed.len() + K, (0, 0.0, 0.0));
            }
            n += self.step_lanes(&mut lanes, &mut closed[n..n + K]);
            if lanes.done.iter().any(|&d| d) {
                for k in 0..K {
                    if let (true, Some(s)) = (lanes.done[k], lanes.span[k]) {
                        if lanes.pending[k] {
                            closed.resize(closed.len().max(n + 1), (0, 0.0, 0.0));
                            closed[n] = (s, lanes.run_lo[k], lanes.run_hi[k]);
                            n += 1;
                        }
                        next = self.start_lane(&mut lanes, k, spans, next);
                    }
                }
            }
        }
        closed.truncate(n);
        out.sort(spans.len());
    }

    /// Puts the first span from `next` on whose start lies in the grid in lane `k` (spans
    /// that start outside have no run), or parks the lane; returns the span after it.
    fn start_lane<const K: usize>(&self, lanes: &mut Lanes<K>, k: usize, spans: &[RaySpan], mut next: usize) -> usize {
        lanes.idle(k);
        let min = self.bounds.min();
        let r = self.resolution as i64;
        while let Some(span) = spans.get(next) {
            let (o, d, lo) = (span.o, span.d, span.lo);
            next += 1;
            let start = self.cell_of(std::array::from_fn(|a| {
                (o[a] + lo * d[a]).clamp(min[a], self.bounds.max()[a])
            }));
            let Some(start) = start else { continue };
            let stride = [r * r, r, 1];
            for a in 0..3 {
                let s: i64 = if d[a] > 0.0 {
                    1
                } else if d[a] < 0.0 {
                    -1
                } else {
                    0
                };
                let i = start[a] as i64;
                let inv = 1.0 / d[a];
                let exit = |i: i64| -> f64 {
                    match s {
                        0 => f64::INFINITY,
                        s => (min[a] + (i + i64::from(s > 0)) as f64 * self.cell[a] - o[a]) * inv,
                    }
                };
                lanes.o[a][k] = o[a];
                lanes.inv[a][k] = inv;
                lanes.dir[a][k] = s;
                lanes.up[a][k] = i64::from(s > 0);
                lanes.idx[a][k] = i;
                lanes.last[a][k] = if s > 0 { r - 1 } else { 0 };
                lanes.step[a][k] = s * stride[a];
                lanes.t_exit[a][k] = exit(i);
                lanes.t_after[a][k] = exit(i + s);
            }
            lanes.linear[k] = start[0] as i64 * stride[0] + start[1] as i64 * stride[1] + start[2] as i64;
            lanes.t[k] = lo;
            lanes.hi[k] = span.hi;
            lanes.span[k] = Some(next - 1);
            break;
        }
        next
    }

    /// One round: every lane takes one pass of `occupied_runs`' loop, with selects for its
    /// branches. The runs the lanes close are written to the start of `closed` (`K` slots), in
    /// lane order; returns how many. A lane whose ray leaves is marked done (its pending run
    /// not yet handed on).
    #[inline(always)]
    fn step_lanes<const K: usize>(&self, lanes: &mut Lanes<K>, closed: &mut [(usize, f64, f64)]) -> usize {
        let min = self.bounds.min();
        let mut kept = 0;
        for k in 0..K {
            let te = [lanes.t_exit[0][k], lanes.t_exit[1][k], lanes.t_exit[2][k]];
            let axis = first_exit(&te);
            let t_exit = te[axis];
            let leaving = lanes.idx[axis][k] == lanes.last[axis][k];
            let (t, hi) = (lanes.t[k], lanes.hi[k]);
            let occupied = self.is_occupied_linear(lanes.linear[k] as usize);
            let t_end = pick(leaving, hi, t_exit.min(hi));
            let grows = occupied & (t_end > t);
            let extends = grows & lanes.pending[k] & (lanes.run_hi[k] == t);
            let opens = grows & !extends;
            let closes = opens & lanes.pending[k];
            closed[kept] = (lanes.span[k].unwrap_or(0), lanes.run_lo[k], lanes.run_hi[k]);
            kept += usize::from(closes);
            lanes.run_lo[k] = pick(opens, t, lanes.run_lo[k]);
            lanes.run_hi[k] = pick(grows, t_end, lanes.run_hi[k]);
            lanes.pending[k] |= grows;
            lanes.done[k] = leaving | (t_exit >= hi);
            lanes.t[k] = t.max(t_exit);
            let i = lanes.idx[axis][k] + lanes.dir[axis][k];
            lanes.idx[axis][k] = i;
            lanes.linear[k] += lanes.step[axis][k];
            lanes.t_exit[axis][k] = lanes.t_after[axis][k];
            // The exit after the next, as occupied_runs' exit: a crossed axis is one the ray
            // moves along, or the ray is done and the value never used.
            lanes.t_after[axis][k] = (min[axis]
                + (i + lanes.dir[axis][k] + lanes.up[axis][k]) as f64 * self.cell[axis]
                - lanes.o[axis][k])
                * lanes.inv[axis][k];
        }
        kept
    }
}
