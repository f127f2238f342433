//! Stratified sampling: the uniform pieces with their edges moved at random (seeded), so that
//! over many draws every depth gets sampled, not only the fixed midpoints.

use fogray_tape::Float;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use super::packed::{cut, PackedSamples, Piece};
use super::uniform::{sample_segments, Spacing};
use crate::error::SampleError;
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
    pub fn new(spacing: Spacing, jitter: Jitter) -> Result<Self, SampleError> {
        Ok(Stratified {
            spacing: spacing.check()?,
            jitter,
        })
    }

    /// Samples every ray within its interval (parallel over rays; the same output whatever
    /// the thread count). Errors: `intervals` not one per ray.
    pub fn sample<F: Float>(&self, rays: &RayBatch<F>, intervals: &RayIntervals) -> Result<PackedSamples<F>, SampleError> {
        sample_segments(rays, intervals, self.spacing, |r| RayJitter::for_ray(self.jitter, r))
    }
}
