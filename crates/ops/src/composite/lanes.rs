//! Rays of equal length taken [`LANES`] at a time, one ray per vector lane: the attenuation,
//! the colour sums and the back-to-front chain then run across rays instead of along one, and
//! their sequential chains (the running optical depth, the suffix recurrence) no longer bound
//! the loops by their latency.
//!
//! The contract is bitwise: each lane does the operations of the per-ray code on its own ray,
//! in the same order (the same polynomial exponential, the same groups of four in the prefix
//! sums and the suffix chain, the same interleaved partial colour sums, a fused multiply-add
//! exactly where the per-ray code has one), so a pack gives the values the per-ray path gives.
//! The per-sample arrays are kept transposed, `[sample][lane]`.

use std::ops::Range;

use super::layout::{Block, Ray};

/// Rays per pack: one AVX-512 register of f64, two of AVX2. Every value is an f64, also for
/// f32 data (the per-ray code computes in f64), so f32 packs are as wide as f64 ones.
pub(crate) const LANES: usize = 8;

/// One value per lane.
pub(crate) type Lanes = [f64; LANES];

/// The same value in every lane.
#[inline(always)]
pub(crate) fn splat(v: f64) -> Lanes {
    [v; LANES]
}

/// `f(a[l], b[l])` in every lane.
#[inline(always)]
pub(crate) fn zip_with(a: Lanes, b: Lanes, f: impl Fn(f64, f64) -> f64) -> Lanes {
    std::array::from_fn(|l| f(a[l], b[l]))
}

/// `out[k][l] = x[l * len + k]`: [`LANES`] rays of `len` values each, ray-major, into lanes.
#[inline(always)]
pub(crate) fn to_lanes(x: &[f64], len: usize, out: &mut [Lanes]) {
    for (l, ray) in x.chunks_exact(len).enumerate() {
        for (o, &v) in out.iter_mut().zip(ray) {
            o[l] = v;
        }
    }
}

/// `out[l * len + k] = x[k][l]` for `k < len`: lanes back into [`LANES`] rays, ray-major.
#[inline(always)]
pub(crate) fn from_lanes(x: &[Lanes], len: usize, out: &mut [f64]) {
    for (l, ray) in out.chunks_exact_mut(len).enumerate() {
        for (o, v) in ray.iter_mut().zip(x) {
            *o = v[l];
        }
    }
}

/// What a block's loop takes next: a pack of [`LANES`] consecutive rays of one length, or a
/// single ray (ragged neighbours, an empty ray, the block's tail, or packs turned off).
pub(crate) enum Unit {
    /// Rays `first.index..first.index + LANES`, each of `len > 0` samples, contiguous.
    Pack {
        first: Ray,
        len: usize,
    },
    Single(Ray),
}

impl Unit {
    /// The pack's samples in the op (ray-major), `LANES * len` of them.
    pub(crate) fn pack_samples(first: &Ray, len: usize) -> Range<usize> {
        first.samples.start..first.samples.start + LANES * len
    }

    /// The unit's samples: in the op, and within its block.
    pub(crate) fn spans(&self) -> (Range<usize>, Range<usize>) {
        match self {
            Unit::Single(ray) => (ray.samples.clone(), ray.local.clone()),
            Unit::Pack { first, len } => {
                let samples = Self::pack_samples(first, *len);
                (samples.clone(), first.local.start..first.local.start + samples.len())
            }
        }
    }
}

impl Block {
    /// The block's rays in order, grouped into packs where [`LANES`] consecutive rays have the
    /// same non-zero length (and `packs` is on), else one at a time.
    pub(crate) fn units<'a>(&'a self, offsets: &'a [usize], packs: bool) -> impl Iterator<Item = Unit> + 'a {
        let mut r = self.rays.start;
        std::iter::from_fn(move || {
            if r >= self.rays.end {
                return None;
            }
            let len = offsets[r + 1] - offsets[r];
            let equal = packs
                && len > 0
                && r + LANES <= self.rays.end
                && (r..r + LANES).all(|q| offsets[q + 1] - offsets[q] == len);
            let ray = self.ray(offsets, r);
            if equal {
                r += LANES;
                Some(Unit::Pack { first: ray, len })
            } else {
                r += 1;
                Some(Unit::Single(ray))
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::composite::layout::blocks;

    #[test]
    fn units_cover_every_ray_once_and_pack_only_equal_non_empty_neighbours() {
        // Lengths: a run of 9 threes, then ragged, then 16 fives, an empty ray among 8 twos.
        let mut lengths = vec![3; 9];
        lengths.extend([1, 2, 1]);
        lengths.extend(vec![5; 16]);
        lengths.extend([2, 2, 2, 0, 2, 2, 2, 2]);
        let mut offsets = vec![0];
        for l in &lengths {
            offsets.push(offsets[offsets.len() - 1] + l);
        }
        let mut seen = Vec::new();
        let mut packs = Vec::new();
        for block in blocks(&offsets) {
            for unit in block.units(&offsets, true) {
                match unit {
                    Unit::Pack { first, len } => {
                        packs.push(first.index);
                        for q in first.index..first.index + LANES {
                            assert_eq!(offsets[q + 1] - offsets[q], len);
                            seen.push(q);
                        }
                        assert_eq!(
                            Unit::pack_samples(&first, len),
                            offsets[first.index]..offsets[first.index + LANES]
                        );
                    }
                    Unit::Single(ray) => seen.push(ray.index),
                }
            }
            assert!(block.units(&offsets, false).all(|u| matches!(u, Unit::Single(_))));
        }
        assert_eq!(seen, (0..lengths.len()).collect::<Vec<_>>());
        assert_eq!(packs, vec![0, 12, 20]);
    }
}
