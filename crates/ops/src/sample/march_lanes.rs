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

/// The state of `K` rays being walked, one slot (lane) each, as arrays over the lanes.
struct Lanes<const K: usize> {
    /// The span each lane walks, `None` once no span is left for it.
    span: [Option<usize>; K],
    o: [[f64; K]; 3],
    inv: [[f64; K]; 3],
    dir: [[i64; K]; 3],
    idx: [[i64; K]; 3],
    last: [[i64; K]; 3],
    step: [[i64; K]; 3],
    linear: [i64; K],
    t_exit: [[f64; K]; 3],
    t_after: [[f64; K]; 3],
    t: [f64; K],
    hi: [f64; K],
    /// The run being grown, if any.
    pending: [Option<(f64, f64)>; K],
}

impl OccupancyGrid {
    /// The runs of every span, as [`OccupancyGrid::occupied_runs`] gives them one span at a
    /// time, walked `K` spans at a time. `out` is reused (its buffers keep their capacity).
    pub(crate) fn occupied_runs_of_spans<const K: usize>(&self, spans: &[RaySpan], out: &mut SpanRuns) {
        out.closed.clear();
        let mut lanes = Lanes::<K> {
            span: [None; K],
            o: [[0.0; K]; 3],
            inv: [[0.0; K]; 3],
            dir: [[0; K]; 3],
            idx: [[0; K]; 3],
            last: [[0; K]; 3],
            step: [[0; K]; 3],
            linear: [0; K],
            t_exit: [[0.0; K]; 3],
            t_after: [[0.0; K]; 3],
            t: [0.0; K],
            hi: [0.0; K],
            pending: [None; K],
        };
        let mut next = 0;
        for k in 0..K {
            next = self.start_lane(&mut lanes, k, spans, next);
        }
        while lanes.span.iter().any(Option::is_some) {
            for k in 0..K {
                let Some(s) = lanes.span[k] else { continue };
                if self.step_lane(&mut lanes, k, s, &mut out.closed) {
                    if let Some((a, b)) = lanes.pending[k] {
                        out.closed.push((s, a, b));
                    }
                    next = self.start_lane(&mut lanes, k, spans, next);
                }
            }
        }
        out.sort(spans.len());
    }

    /// Puts the first span from `next` on whose start lies in the grid in lane `k` (spans
    /// that start outside have no run); returns the span after it.
    fn start_lane<const K: usize>(&self, lanes: &mut Lanes<K>, k: usize, spans: &[RaySpan], mut next: usize) -> usize {
        lanes.span[k] = None;
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
                lanes.idx[a][k] = i;
                lanes.last[a][k] = if s > 0 { r - 1 } else { 0 };
                lanes.step[a][k] = s * stride[a];
                lanes.t_exit[a][k] = exit(i);
                lanes.t_after[a][k] = exit(i + s);
            }
            lanes.linear[k] = start[0] as i64 * stride[0] + start[1] as i64 * stride[1] + start[2] as i64;
            lanes.t[k] = lo;
            lanes.hi[k] = span.hi;
            lanes.pending[k] = None;
            lanes.span[k] = Some(next - 1);
            break;
        }
        next
    }

    /// One step of lane `k` (walking span `s`), as one pass of `occupied_runs`' loop; returns
    /// whether the ray is done (its pending run not yet handed on).
    #[inline(always)]
    fn step_lane<const K: usize>(
        &self,
        lanes: &mut Lanes<K>,
        k: usize,
        s: usize,
        closed: &mut Vec<(usize, f64, f64)>,
    ) -> bool {
        let t_exit = [lanes.t_exit[0][k], lanes.t_exit[1][k], lanes.t_exit[2][k]];
        let axis = first_exit(&t_exit);
        let leaving = lanes.idx[axis][k] == lanes.last[axis][k];
        let (t, hi) = (lanes.t[k], lanes.hi[k]);
        if self.is_occupied_linear(lanes.linear[k] as usize) {
            let t_end = if leaving { hi } else { t_exit[axis].min(hi) };
            if t_end > t {
                match &mut lanes.pending[k] {
                    Some(p) if p.1 == t => p.1 = t_end,
                    pending => {
                        if let Some((a, b)) = *pending {
                            closed.push((s, a, b));
                        }
                        *pending = Some((t, t_end));
                    }
                }
            }
        }
        if leaving || t_exit[axis] >= hi {
            return true;
        }
        lanes.t[k] = t.max(t_exit[axis]);
        let i = lanes.idx[axis][k] + lanes.dir[axis][k];
        lanes.idx[axis][k] = i;
        lanes.linear[k] += lanes.step[axis][k];
        lanes.t_exit[axis][k] = lanes.t_after[axis][k];
        // A crossed axis is one the ray moves along (dir != 0): the same product as
        // occupied_runs' exit.
        let up = i64::from(lanes.dir[axis][k] > 0);
        let min = self.bounds.min();
        lanes.t_after[axis][k] = (min[axis] + (i + lanes.dir[axis][k] + up) as f64 * self.cell[axis]
            - lanes.o[axis][k])
            * lanes.inv[axis][k];
        false
    }
}
