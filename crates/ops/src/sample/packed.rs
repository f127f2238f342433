//! Packed samples: every ray's samples in one run of flat arrays, with offsets, ready for the
//! composite (`Composite::new(&s.offsets)`, `delta`, `t`) and a field op (`positions`).

use fogray_tape::{Float, Offsets, Tape, TapeError, Var};
use ndarray::{Array1, Array2};
use rayon::prelude::*;

use crate::error::{Op, OpsError};
use crate::rays::{RayBatch, RayIntervals};

/// The samples of `R` rays, packed: ray `r` owns samples `offsets[r]..offsets[r + 1]`, in
/// increasing depth.
///
/// Sample `k` stands for the piece `[t[k] - delta[k] / 2, t[k] + delta[k] / 2]` of its ray
/// (its depth is the piece's midpoint); a ray's pieces never overlap. Every ray of the input
/// has a range, in order; a ray that misses (or whose piece is all empty space) has an empty
/// one.
#[derive(Debug, Clone, PartialEq)]
pub struct PackedSamples<F: Float> {
    /// Sample positions `[n, 3]`: `origin + t * direction` of the sample's ray.
    pub positions: Array2<F>,
    /// Depths `[n]`: distance along the ray (directions are unit).
    pub t: Array1<F>,
    /// Lengths `[n]` of the pieces the samples stand for (the composite's `delta`).
    pub delta: Array1<F>,
    /// `R + 1` offsets, starting at 0, never decreasing (the composite's packing: pass it to
    /// `Composite::packed` to share it, or to `Composite::new` as a slice).
    pub offsets: Offsets,
    /// The ray of each sample, `[n]`.
    pub ray: Vec<usize>,
}

/// The tape constants made by [`PackedSamples::to_tape`].
#[derive(Debug, Clone, Copy)]
pub struct SampleVars {
    /// Positions `[n, 3]`.
    pub positions: Var,
    /// Depths `[n]`.
    pub t: Var,
    /// Lengths `[n]`.
    pub delta: Var,
}

impl<F: Float> PackedSamples<F> {
    /// Number of rays.
    pub fn rays(&self) -> usize {
        self.offsets.len() - 1
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t.len()
    }

    /// Whether there is no sample at all.
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// The sample range of ray `r`, or `None` if there is no ray `r`.
    pub fn range(&self, r: usize) -> Option<std::ops::Range<usize>> {
        self.offsets.range(r)
    }

    /// Mean samples per ray (0 for no ray).
    pub fn samples_per_ray(&self) -> f64 {
        if self.rays() == 0 {
            0.0
        } else {
            self.len() as f64 / self.rays() as f64
        }
    }

    /// Records positions, depths and lengths on `tape` as constants (copies), for a taped
    /// render: feed `positions` to the field and `delta`, `t` to the composite.
    pub fn to_tape(&self, tape: &mut Tape<F>) -> Result<SampleVars, TapeError> {
        Ok(SampleVars {
            positions: tape.constant(self.positions.clone()),
            t: tape.constant(self.t.clone()),
            delta: tape.constant(self.delta.clone()),
        })
    }

    /// Moves positions, depths and lengths onto `tape` as constants, as
    /// [`PackedSamples::to_tape`] records them but without a copy (a training step's samples
    /// are megabytes), and returns them with the offsets for the composite.
    pub fn into_tape(self, tape: &mut Tape<F>) -> (SampleVars, Offsets) {
        let vars = SampleVars {
            positions: tape.constant(self.positions),
            t: tape.constant(self.t),
            delta: tape.constant(self.delta),
        };
        (vars, self.offsets)
    }
}

/// A piece `[lo, hi]` of a ray, in f64.
pub(crate) type Piece = (f64, f64);

/// Checks that a sampler got one interval per ray.
pub(crate) fn check_lengths<F: Float>(rays: &RayBatch<F>, intervals: &RayIntervals) -> Result<(), OpsError> {
    if rays.len() != intervals.len() {
        return Err(OpsError::Shape {
            op: Op::Sample,
            what: "intervals",
            expected: format!("one per ray ({})", rays.len()),
            got: format!("{}", intervals.len()),
        });
    }
    Ok(())
}

/// A sampler's step must be finite and positive.
pub(crate) fn check_step(step: f64) -> Result<(), OpsError> {
    if step.is_finite() && step > 0.0 {
        Ok(())
    } else {
        Err(OpsError::Config {
            op: Op::Sample,
            what: "step",
            value: step,
            rule: "must be finite and positive",
        })
    }
}

/// One parallel task's share of the pieces: its rays' piece counts and pieces, in order.
struct Chunk {
    counts: Vec<usize>,
    pieces: Vec<Piece>,
}

/// Rays per parallel task: enough to amortise the task, few enough to balance two cores.
pub(crate) const RAYS_PER_TASK: usize = 64;

/// Runs `pieces_of(r, out)` (which appends ray `r`'s pieces to `out`) for every ray, in
/// parallel over chunks of rays, and packs the samples in ray order (so the output does not
/// depend on the number of threads).
pub(crate) fn pack<F: Float>(
    rays: &RayBatch<F>,
    pieces_of: impl Fn(usize, &mut Vec<Piece>) + Sync,
) -> PackedSamples<F> {
    pack_chunks(
        rays,
        |task: std::ops::Range<usize>, counts: &mut Vec<usize>, pieces: &mut Vec<Piece>| {
            for r in task {
                let before = pieces.len();
                pieces_of(r, pieces);
                counts.push(pieces.len() - before);
            }
        },
    )
}

/// [`pack`] for a sampler that handles a task's rays together: `fill(rays, counts, pieces)`
/// appends, for each ray of the range in order, its piece count to `counts` and its pieces to
/// `pieces`.
///
/// The pieces are gathered first and the samples written once, in parallel, straight into
/// the output arrays: no growing per-task copies of the samples to concatenate.
pub(crate) fn pack_chunks<F: Float>(
    rays: &RayBatch<F>,
    fill: impl Fn(std::ops::Range<usize>, &mut Vec<usize>, &mut Vec<Piece>) + Sync,
) -> PackedSamples<F> {
    let n_rays = rays.len();
    let task_rays = |c: usize| c * RAYS_PER_TASK..((c + 1) * RAYS_PER_TASK).min(n_rays);
    let chunks: Vec<Chunk> = (0..n_rays.div_ceil(RAYS_PER_TASK))
        .into_par_iter()
        .map(|c| {
            let mut chunk = Chunk {
                counts: Vec::with_capacity(RAYS_PER_TASK),
                pieces: Vec::new(),
            };
            let task = task_rays(c);
            let rays_in_task = task.len();
            fill(task, &mut chunk.counts, &mut chunk.pieces);
            assert_eq!(chunk.counts.len(), rays_in_task, "one piece count per ray");
            chunk
        })
        .collect();
    let offsets = Offsets::from_lengths(chunks.iter().flat_map(|c| c.counts.iter().copied()));
    let n = offsets.rows();
    // The outputs are written once, in parallel, into uninitialised capacity: a zero-filled
    // `vec!` is a serial pass over megabytes that every sample then overwrites.
    let mut positions: Vec<F> = Vec::with_capacity(3 * n);
    let mut t: Vec<F> = Vec::with_capacity(n);
    let mut delta: Vec<F> = Vec::with_capacity(n);
    let mut ray: Vec<usize> = Vec::with_capacity(n);
    // Each task's share of the outputs, split off in order: the shares partition the first
    // `3 n` / `n` slots, since the chunks' pieces add up to the offsets' rows.
    let mut shares = Vec::with_capacity(chunks.len());
    let (mut p_rest, mut t_rest, mut d_rest, mut r_rest) = (
        &mut positions.spare_capacity_mut()[..3 * n],
        &mut t.spare_capacity_mut()[..n],
        &mut delta.spare_capacity_mut()[..n],
        &mut ray.spare_capacity_mut()[..n],
    );
    for chunk in &chunks {
        let m = chunk.pieces.len();
        let (p, p_next) = p_rest.split_at_mut(3 * m);
        let (tt, t_next) = t_rest.split_at_mut(m);
        let (dd, d_next) = d_rest.split_at_mut(m);
        let (rr, r_next) = r_rest.split_at_mut(m);
        shares.push((p, tt, dd, rr));
        (p_rest, t_rest, d_rest, r_rest) = (p_next, t_next, d_next, r_next);
    }
    let all_written = shares
        .into_par_iter()
        .zip(chunks.par_iter().enumerate())
        .map(|((p, tt, dd, rr), (c, chunk))| {
            let mut k = 0;
            for (r, &count) in task_rays(c).zip(&chunk.counts) {
                let (o, d) = rays.ray(r);
                for &(lo, hi) in &chunk.pieces[k..k + count] {
                    let mid = 0.5 * (lo + hi);
                    for a in 0..3 {
                        p[3 * k + a].write(F::lit(o[a] + mid * d[a]));
                    }
                    tt[k].write(F::lit(mid));
                    dd[k].write(F::lit(hi - lo));
                    rr[k].write(r);
                    k += 1;
                }
            }
            k == tt.len()
        })
        .all(|written| written);
    // A broken invariant must not expose uninitialised memory: checked, not assumed.
    assert!(all_written, "every packed sample is written");
    // SAFETY: the shares partition the first 3 n slots of `positions` and the first n of the
    // others (checked just above: each task wrote its share's every slot, k reaching the
    // share's length), so these elements are initialised.
    unsafe {
        positions.set_len(3 * n);
        t.set_len(n);
        delta.set_len(n);
        ray.set_len(n);
    }
    PackedSamples {
        positions: Array2::from_shape_vec((n, 3), positions).expect("three coordinates per sample"),
        t: Array1::from(t),
        delta: Array1::from(delta),
        offsets,
        ray,
    }
}

/// Cuts `[lo, hi]` at the edges `origin + (i + shift) * step` (any integer `i`) that lie
/// inside it, appending the pieces. Edges within `step * 1e-6` of an end are not used, so
/// no piece is a rounding sliver unless the whole segment is (then it is one piece); a
/// zero-length segment gives nothing.
pub(crate) fn cut(lo: f64, hi: f64, origin: f64, step: f64, shift: f64, out: &mut Vec<Piece>) {
    if hi <= lo {
        return;
    }
    let eps = step * 1e-6;
    let mut start = lo;
    let mut i = ((lo + eps - origin) / step - shift).ceil();
    loop {
        // Not mul_add: without FMA in the target it is a library call in this hot loop.
        let edge = origin + (i + shift) * step;
        if edge >= hi - eps {
            break;
        }
        if edge > start + eps {
            out.push((start, edge));
            start = edge;
        }
        i += 1.0;
    }
    out.push((start, hi));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cut_at_a_grid_by_hand() {
        let mut p = Vec::new();
        // [0.1, 0.75] cut at multiples of 0.25: edges 0.25, 0.5.
        cut(0.1, 0.75, 0.0, 0.25, 0.0, &mut p);
        assert_eq!(p, vec![(0.1, 0.25), (0.25, 0.5), (0.5, 0.75)]);
        // The same grid shifted by 0.2 steps: edges 0.3, 0.55 (0.05 is before the segment).
        p.clear();
        cut(0.1, 0.75, 0.0, 0.25, 0.2, &mut p);
        assert_eq!(p.len(), 3);
        assert!((p[0].1 - 0.3).abs() < 1e-15 && (p[1].1 - 0.55).abs() < 1e-15 && p[2].1 == 0.75);
        // An edge a rounding error past an end is not a piece.
        p.clear();
        cut(0.0, 0.5 + 1e-15, 0.0, 0.25, 0.0, &mut p);
        assert_eq!(p, vec![(0.0, 0.25), (0.25, 0.5 + 1e-15)]);
        // Shorter than a step: one piece; empty: none.
        p.clear();
        cut(0.3, 0.31, 0.0, 0.25, 0.0, &mut p);
        cut(0.4, 0.4, 0.0, 0.25, 0.0, &mut p);
        assert_eq!(p, vec![(0.3, 0.31)]);
    }
}

#[cfg(test)]
mod tape_tests {
    use super::*;
    use crate::rays::Aabb;
    use crate::sample::{Spacing, Uniform};
    use crate::{Background, Composite, CompositeInputs};
    use ndarray::arr2;

    #[test]
    fn samples_drive_a_taped_render() {
        // One ray along +x across [-1, 1]^3 (t in [2, 4]), density sigma = a * (x + 1) with
        // a = 0.5 at the sample positions; opacity 1 - exp(-sum sigma_k delta_k). The midpoint
        // rule is exact for a linear density: the integral of 0.5 (x + 1) over x in [-1, 1] is
        // 1, so opacity = 1 - 1/e and d opacity / da = exp(-1) * 2 (the integral of x + 1).
        let rays = RayBatch::new(arr2(&[[-3.0f64, 0.0, 0.0]]), arr2(&[[1.0, 0.0, 0.0]])).unwrap();
        let clip = Aabb::new([-1.0; 3], [1.0; 3]).unwrap().clip(&rays);
        let s = Uniform::new(Spacing::Step(0.3)).unwrap().sample(&rays, &clip).unwrap();
        let mut tape = Tape::<f64>::new();
        let vars = s.to_tape(&mut tape).unwrap();
        // Moved instead of copied, the same constants.
        let (moved, offsets) = s.clone().into_tape(&mut tape);
        for (a, b) in [
            (vars.positions, moved.positions),
            (vars.t, moved.t),
            (vars.delta, moved.delta),
        ] {
            assert_eq!(tape.value(a).unwrap(), tape.value(b).unwrap());
        }
        assert_eq!(offsets, s.offsets);
        let a = tape.param(ndarray::arr1(&[0.5]));
        let x = s.positions.column(0).mapv(|x| x + 1.0);
        let x1 = tape.constant(x);
        let sigma = tape.mul(x1, a).unwrap();
        let color = tape.constant(ndarray::Array2::<f64>::ones((s.len(), 1)));
        let op = Composite::new(&s.offsets).unwrap().background(Background::None);
        let inputs = CompositeInputs {
            sigma,
            delta: vars.delta,
            color,
            background: None,
            t: None,
        };
        let out = op.apply(&mut tape, &inputs).unwrap();
        let opacity = tape.value(out.opacity).unwrap()[0];
        assert!((opacity - (1.0 - (-1.0f64).exp())).abs() < 1e-12, "{opacity}");
        let g = tape.backward(out.opacity).unwrap();
        let da = g.get(a).unwrap()[0];
        assert!((da - 2.0 * (-1.0f64).exp()).abs() < 1e-12, "{da}");
        assert_eq!(tape.value(vars.t).unwrap().len(), s.len());
    }
}
