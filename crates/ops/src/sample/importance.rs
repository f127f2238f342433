//! Importance resampling (NeRF's hierarchical sampling): new samples drawn by inverse
//! transform from the piecewise-constant density of a previous pass's weights.

use fogray_tape::Float;
use ndarray::ArrayView1;

use super::packed::{pack, PackedSamples, Piece};
use super::stratified::{Jitter, RayJitter};
use crate::error::{At, Op, OpsError};
use crate::rays::RayBatch;

/// Inverse-transform resampling of each ray from the weights of a previous pass.
///
/// On ray `r`, previous sample `k` stands for the piece `[t_k - delta_k / 2, t_k + delta_k / 2]`
/// and gets the probability mass `(1 - floor) w_k / W + floor delta_k / L` (`W`, `L` the
/// ray's total weight and length; a ray with `W = 0` is sampled uniformly), spread evenly
/// over its piece. The unit interval of probability is cut into `n` equal pieces (with the
/// edges randomised by a [`Jitter`], as the stratified sampler does in depth); each cut is
/// mapped back to a depth through the inverse of the cumulative distribution, giving `n`
/// pieces of equal probability `1 / n`, sorted, one sample at each midpoint with `delta` its
/// length. Where the previous pieces leave gaps (empty space skipped by the occupancy
/// marcher), a new piece that spans a gap is split at it and the gap dropped, so a ray may
/// get more than `n` samples; rays with no previous sample get none.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Importance {
    samples: usize,
    floor: f64,
    jitter: Jitter,
}

impl Importance {
    /// `samples_per_ray >= 1`; `uniform_floor` in `[0, 1]` (the share of every ray's
    /// probability spread uniformly over its previous pieces, so zero-weight regions keep
    /// being explored; 0.01 is a reasonable start).
    pub fn new(samples_per_ray: usize, uniform_floor: f64, jitter: Jitter) -> Result<Self, OpsError> {
        if samples_per_ray == 0 {
            return Err(OpsError::Config {
                op: Op::Sample,
                what: "samples per ray",
                value: 0.0,
                rule: "must be at least 1",
            });
        }
        if !(0.0..=1.0).contains(&uniform_floor) {
            return Err(OpsError::Config {
                op: Op::Sample,
                what: "uniform floor",
                value: uniform_floor,
                rule: "must be in [0, 1]",
            });
        }
        Ok(Importance {
            samples: samples_per_ray,
            floor: uniform_floor,
            jitter,
        })
    }

    /// Resamples `rays` from `previous` (their samples from an earlier pass) and its weights
    /// `[n]` (e.g. the composite's `weights` output), in parallel over rays.
    ///
    /// Errors: `previous` not over `rays.len()` rays or not a valid packing, `weights` not
    /// one per previous sample, a weight that is negative or not finite, a previous `t` or
    /// `delta` that is not finite or a negative `delta`.
    pub fn sample<F: Float>(
        &self,
        rays: &RayBatch<F>,
        previous: &PackedSamples<F>,
        weights: ArrayView1<'_, F>,
    ) -> Result<PackedSamples<F>, OpsError> {
        check_previous(rays, previous, weights)?;
        Ok(pack(rays, |r, out| {
            // check_previous made sure there is one range per ray.
            let range = previous.range(r).unwrap_or_default();
            let pieces: Vec<Piece> = range
                .clone()
                .map(|k| {
                    let (t, d) = (previous.t[k].as_f64(), previous.delta[k].as_f64());
                    (t - 0.5 * d, t + 0.5 * d)
                })
                .collect();
            let w: Vec<f64> = range.map(|k| weights[k].as_f64()).collect();
            let jitter = RayJitter::for_ray(self.jitter, r);
            out.extend(resample(&pieces, &w, self.floor, self.samples, jitter));
        }))
    }
}

fn check_previous<F: Float>(
    rays: &RayBatch<F>,
    previous: &PackedSamples<F>,
    weights: ArrayView1<'_, F>,
) -> Result<(), OpsError> {
    let offsets = &previous.offsets;
    let n = previous.t.len();
    let packing_ok = offsets.rows() == n && previous.delta.len() == n;
    if !packing_ok {
        return Err(OpsError::Shape {
            op: Op::Sample,
            what: "previous samples",
            expected: format!("offsets ending at {n}, and {n} deltas"),
            got: format!(
                "{} offsets ending at {:?}, {} deltas",
                offsets.len(),
                offsets.last(),
                previous.delta.len()
            ),
        });
    }
    if offsets.len() - 1 != rays.len() {
        return Err(OpsError::Shape {
            op: Op::Sample,
            what: "previous samples",
            expected: format!("samples of {} rays", rays.len()),
            got: format!("samples of {} rays", offsets.len() - 1),
        });
    }
    if weights.len() != n {
        return Err(OpsError::Shape {
            op: Op::Sample,
            what: "weights",
            expected: format!("one per previous sample ({n})"),
            got: format!("{}", weights.len()),
        });
    }
    for r in 0..offsets.len() - 1 {
        for k in offsets[r]..offsets[r + 1] {
            let at = At::Sample {
                ray: r,
                sample: k - offsets[r],
            };
            let bad = |what: &str, value: F, rule| OpsError::domain(Op::Sample, at, what, value.as_f64(), rule);
            let w = weights[k];
            if !(w.is_finite() && w >= F::zero()) {
                return Err(bad("weights", w, "must be finite and non-negative"));
            }
            let (t, d) = (previous.t[k], previous.delta[k]);
            if !t.is_finite() {
                return Err(bad("t", t, "must be finite"));
            }
            if !(d.is_finite() && d >= F::zero()) {
                return Err(bad("delta", d, "must be finite and non-negative"));
            }
        }
    }
    Ok(())
}

/// Previous pieces closer than this fraction of the longer one are one run (their ends come
/// back from `t -+ delta / 2`, rounded to `F`).
const JOIN: f64 = 1e-3;

/// One ray: the pieces of equal probability `1 / n`, split at gaps between `pieces`.
pub(crate) fn resample(pieces: &[Piece], weights: &[f64], floor: f64, n: usize, mut jitter: RayJitter) -> Vec<Piece> {
    let length: f64 = pieces.iter().map(|p| p.1 - p.0).sum();
    // Deltas were checked finite and non-negative, so the length is too.
    if pieces.is_empty() || length <= 0.0 {
        return Vec::new();
    }
    let total: f64 = weights.iter().sum();
    let mass: Vec<f64> = pieces
        .iter()
        .zip(weights)
        .map(|(p, &w)| {
            let share = (p.1 - p.0) / length;
            if total > 0.0 {
                (1.0 - floor) * w / total + floor * share
            } else {
                share
            }
        })
        .collect();
    // Cuts of the unit interval of probability, then their depths.
    let mut unit = Vec::with_capacity(n + 1);
    jitter.cut(0.0, 1.0, 0.0, 1.0 / n as f64, &mut unit);
    let cuts: Vec<f64> = std::iter::once(0.0).chain(unit.iter().map(|p| p.1)).collect();
    let depths = invert(pieces, &mass, &cuts);
    // Runs of the previous pieces, to split new pieces at the gaps.
    let mut runs: Vec<Piece> = Vec::new();
    for &(lo, hi) in pieces {
        match runs.last_mut() {
            Some(run) if lo - run.1 <= JOIN * (hi - lo).max(run.1 - run.0) => run.1 = run.1.max(hi),
            _ => runs.push((lo, hi)),
        }
    }
    let mut out = Vec::with_capacity(n + runs.len());
    let mut first_run = 0;
    for w in depths.windows(2) {
        let (a, b) = (w[0], w[1]);
        while first_run < runs.len() && runs[first_run].1 <= a {
            first_run += 1;
        }
        for &(lo, hi) in &runs[first_run..] {
            if lo >= b {
                break;
            }
            let (p, q) = (a.max(lo), b.min(hi));
            if q > p {
                out.push((p, q));
            }
        }
    }
    out
}

/// The depths at which the cumulative distribution of `mass` over `pieces` (uniform within
/// each piece) reaches each of the sorted `cuts` in `[0, 1]`.
fn invert(pieces: &[Piece], mass: &[f64], cuts: &[f64]) -> Vec<f64> {
    // Cuts at 0 and 1 land on the first and last pieces with mass, not on empty ends.
    let last = mass.iter().rposition(|&m| m > 0.0).unwrap_or(pieces.len() - 1);
    let (mut k, mut below) = (0, 0.0);
    cuts.iter()
        .map(|&u| {
            // Advance to the piece holding u; the last piece absorbs rounding in the total.
            while k < last && (mass[k] <= 0.0 || below + mass[k] < u) {
                below += mass[k];
                k += 1;
            }
            let (lo, hi) = pieces[k];
            if mass[k] <= 0.0 {
                return hi;
            }
            let frac = ((u - below) / mass[k]).clamp(0.0, 1.0);
            frac.mul_add(hi - lo, lo)
        })
        .collect()
}
