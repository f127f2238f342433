//! Stratified sampling: the uniform pieces with their edges moved at random (seeded), so that
//! over many draws every depth gets sampled, not only the fixed midpoints.

use fogray_tape::Float;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use super::packed::{cut, PackedSamples, Piece};
use super::uniform::{sample_segments, Spacing};
use crate::error::OpsError;
use crate::rays::{RayBatch, RayIntervals};

/// How the edges of the pieces are randomised. Each ray draws from its own generator,
/// seeded from `seed` and the ray's index, so the samples do not depend on the number of
/// threads; use a new seed per training step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Jitter {
    /// No randomness: the uniform pieces.
    None,
    /// The whole grid of edges `t_near + (i + u) h` shifted by one `u ~ U[0, 1)` per ray
    /// (a ray's first piece is `u h` long, so it may get one piece more than unjittered).
    PerRay {
        /// Seed of the draws.
        seed: u64,
    },
    /// Each interior edge moved independently, uniformly between the midpoints of the two
    /// uniform pieces it separates (so edges stay ordered and pieces are at most `2h` long).
    PerSample {
        /// Seed of the draws.
        seed: u64,
    },
}

/// One ray's draws.
pub(crate) struct RayJitter {
    shift: f64,
    per_sample: Option<StdRng>,
}

/// A generator for ray `r` from `seed`: the splitmix64 constant spreads neighbouring rays
/// apart before `seed_from_u64` expands the seed.
fn ray_rng(seed: u64, r: usize) -> StdRng {
    StdRng::seed_from_u64(seed ^ (r as u64).wrapping_add(1).wrapping_mul(0x9E37_79B9_7F4A_7C15))
}

impl RayJitter {
    pub(crate) fn none() -> Self {
        RayJitter {
            shift: 0.0,
            per_sample: None,
        }
    }

    pub(crate) fn for_ray(jitter: Jitter, r: usize) -> Self {
        match jitter {
            Jitter::None => Self::none(),
            Jitter::PerRay { seed } => RayJitter {
                shift: ray_rng(seed, r).gen::<f64>(),
                per_sample: None,
            },
            Jitter::PerSample { seed } => RayJitter {
                shift: 0.0,
                per_sample: Some(ray_rng(seed, r)),
            },
        }
    }

    /// Cuts `[lo, hi]` on the grid `origin + (i + shift) step` and, per sample, moves each
    /// interior edge within the midpoints of its two pieces.
    pub(crate) fn cut(&mut self, lo: f64, hi: f64, origin: f64, step: f64, out: &mut Vec<Piece>) {
        let first = out.len();
        cut(lo, hi, origin, step, self.shift, out);
        if let Some(rng) = &mut self.per_sample {
            let pieces = &mut out[first..];
            let mid = |p: Piece| 0.5 * (p.0 + p.1);
            // Piece k's own end is untouched until edge k + 1 moves, so mid(pieces[k]) below
            // is the unjittered midpoint; `a` carries the previous one.
            let mut a = pieces.first().map_or(0.0, |&p| mid(p));
            for k in 1..pieces.len() {
                let b = mid(pieces[k]);
                let edge = a + rng.gen::<f64>() * (b - a);
                a = b;
                pieces[k - 1].1 = edge;
                pieces[k].0 = edge;
            }
        }
    }
}

/// Stratified sampling: the pieces of a [`Spacing`] with randomised edges ([`Jitter`]), one
/// sample at each piece's midpoint with `delta` its length; the pieces still tile each
/// segment exactly. Misses and zero-length segments get no sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stratified {
    spacing: Spacing,
    jitter: Jitter,
}

impl Stratified {
    /// Errors: a step that is not finite and positive, a count of 0.
    pub fn new(spacing: Spacing, jitter: Jitter) -> Result<Self, OpsError> {
        Ok(Stratified {
            spacing: spacing.check()?,
            jitter,
        })
    }

    /// Samples every ray within its interval (parallel over rays; the same output whatever
    /// the thread count). Errors: `intervals` not one per ray.
    pub fn sample<F: Float>(&self, rays: &RayBatch<F>, intervals: &RayIntervals) -> Result<PackedSamples<F>, OpsError> {
        sample_segments(rays, intervals, self.spacing, |r| RayJitter::for_ray(self.jitter, r))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::Array2;

    /// 4000 rays from the origin along +x over [0, 1] at step 0.25 (four uniform pieces).
    fn setup() -> (RayBatch<f64>, RayIntervals) {
        let n = 4000;
        let mut d = Array2::zeros((n, 3));
        d.column_mut(0).fill(1.0);
        let rays = RayBatch::new(Array2::zeros((n, 3)), d).unwrap();
        (rays, RayIntervals::new(vec![0.0; n], vec![1.0; n]).unwrap())
    }

    /// The pieces of every ray tile [0, 1]: consecutive, from 0 to 1.
    fn assert_tiles(s: &PackedSamples<f64>) {
        for r in 0..s.rays() {
            let mut at = 0.0;
            for k in s.range(r).unwrap() {
                let (lo, hi) = (s.t[k] - s.delta[k] / 2.0, s.t[k] + s.delta[k] / 2.0);
                assert!(
                    (lo - at).abs() < 1e-12 && hi > lo,
                    "ray {r} piece {k}: [{lo}, {hi}] after {at}"
                );
                at = hi;
            }
            assert!((at - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn per_ray_shift_is_uniform_and_keeps_whole_steps() {
        let (rays, iv) = setup();
        let s = Stratified::new(Spacing::Step(0.25), Jitter::PerRay { seed: 7 })
            .unwrap()
            .sample(&rays, &iv)
            .unwrap();
        assert_tiles(&s);
        // The first piece is [0, u h]: u should be U[0, 1), so its mean is 1/2 (standard error
        // 1/sqrt(12 * 4000) = 0.0046) and each quarter holds a quarter of the rays (+-3.5 sd).
        let u: Vec<f64> = (0..s.rays()).map(|r| s.delta[s.offsets[r]] / 0.25).collect();
        let mean = u.iter().sum::<f64>() / u.len() as f64;
        assert!((mean - 0.5).abs() < 0.02, "mean {mean}");
        for q in 0..4 {
            let c = u
                .iter()
                .filter(|&&x| (q as f64 / 4.0..(q + 1) as f64 / 4.0).contains(&x))
                .count();
            assert!((c as f64 - 1000.0).abs() < 95.0, "quarter {q}: {c}");
        }
        // Interior pieces keep the whole step; every ray has 4 or 5 pieces.
        for r in 0..s.rays() {
            let range = s.range(r).unwrap();
            assert!(range.len() == 4 || range.len() == 5);
            for k in range.start + 1..range.end - 1 {
                assert!((s.delta[k] - 0.25).abs() < 1e-12);
            }
        }
        // The same seed gives the same samples; another seed different ones.
        let again = Stratified::new(Spacing::Step(0.25), Jitter::PerRay { seed: 7 })
            .unwrap()
            .sample(&rays, &iv)
            .unwrap();
        assert_eq!(again, s);
        let other = Stratified::new(Spacing::Step(0.25), Jitter::PerRay { seed: 8 })
            .unwrap()
            .sample(&rays, &iv)
            .unwrap();
        assert_ne!(other.t, s.t);
    }

    #[test]
    fn per_sample_edges_move_between_midpoints() {
        let (rays, iv) = setup();
        let s = Stratified::new(Spacing::Count(4), Jitter::PerSample { seed: 1 })
            .unwrap()
            .sample(&rays, &iv)
            .unwrap();
        assert_tiles(&s);
        // Four pieces per ray; edge i (i = 1, 2, 3, at 0.25 i unjittered) lies uniformly in
        // [0.25 i - 0.125, 0.25 i + 0.125].
        let mut sums = [0.0; 3];
        for r in 0..s.rays() {
            assert_eq!(s.range(r).unwrap().len(), 4);
            for i in 1..4 {
                let k = s.offsets[r] + i;
                let edge = s.t[k] - s.delta[k] / 2.0;
                let centre = 0.25 * i as f64;
                assert!((edge - centre).abs() <= 0.125 + 1e-12, "ray {r} edge {i}: {edge}");
                sums[i - 1] += edge - centre;
            }
        }
        // Mean offset 0 with standard error 0.25 / sqrt(12 * 4000) = 0.0011.
        for (i, sum) in sums.iter().enumerate() {
            assert!(
                (sum / 4000.0).abs() < 0.005,
                "edge {}: mean offset {}",
                i + 1,
                sum / 4000.0
            );
        }
        // Rays draw independently: the first two rays' second edges differ.
        assert_ne!(s.t[1], s.t[5]);
    }

    #[test]
    fn no_jitter_is_uniform() {
        let (rays, iv) = setup();
        let s = Stratified::new(Spacing::Step(0.3), Jitter::None)
            .unwrap()
            .sample(&rays, &iv)
            .unwrap();
        let u = super::super::Uniform::new(Spacing::Step(0.3))
            .unwrap()
            .sample(&rays, &iv)
            .unwrap();
        assert_eq!(s, u);
        assert!(Stratified::new(Spacing::Step(-1.0), Jitter::None).is_err());
    }
}
