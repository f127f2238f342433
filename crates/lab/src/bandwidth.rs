//! The machine's memory bound for `fogray-lab bench`: the triad of [`crate::machine`] gives the
//! bytes per second the cores can stream, and the fused composite's bytes per sample turn it
//! into a bound in samples per second, so that each fused row can say what fraction of the
//! machine it reaches.

use crate::bench::within;
use crate::error::LabError;

pub use crate::machine::Bandwidth;

/// The triad ([`crate::machine::triad`]) on `pool` (the global pool when `None`).
pub fn triad(pool: Option<&rayon::ThreadPool>, runs: usize) -> Result<Bandwidth, LabError> {
    within(pool, || Ok(crate::machine::triad(runs)))
}

/// Which fused call a byte count is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FusedPath {
    /// `evaluate_into` then `vjp_into`: the backward reads sigma, delta and the colours again.
    TwoCalls,
    /// `evaluate_vjp_into`: every input read once.
    OnePass,
}

/// Bytes that the fused forward + backward (gradients for sigma and colour) must move per
/// sample, at `value_bytes` per value and `channels` colour channels: sigma, delta and the
/// colours read (twice through two calls), dL/dsigma and dL/dcolour written. The per-ray
/// outputs (colour, opacity, one index of residuals) are left out: a ray has many samples.
pub fn fused_bytes_per_sample(value_bytes: usize, channels: usize, path: FusedPath) -> usize {
    let inputs = (2 + channels) * value_bytes;
    let gradients = (1 + channels) * value_bytes;
    let reads = if path == FusedPath::TwoCalls { 2 } else { 1 };
    reads * inputs + gradients
}

/// A fused speed against the machine's bound: the fraction of `bandwidth` that
/// `samples_per_sec` samples of `bytes_per_sample` each take.
pub fn fraction_of_bound(samples_per_sec: f64, bytes_per_sample: usize, bandwidth: &Bandwidth) -> f64 {
    samples_per_sec * bytes_per_sample as f64 / bandwidth.bytes_per_sec
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bytes_per_sample_are_the_issue_counts_for_rgb() {
        // f32 RGB: 4 (sigma) + 4 (delta) + 12 (colour) read, 4 + 12 written.
        assert_eq!(fused_bytes_per_sample(4, 3, FusedPath::OnePass), 36);
        assert_eq!(fused_bytes_per_sample(4, 3, FusedPath::TwoCalls), 56);
        assert_eq!(fused_bytes_per_sample(8, 3, FusedPath::OnePass), 72);
        assert_eq!(fused_bytes_per_sample(8, 1, FusedPath::TwoCalls), 8 * (2 * 3 + 2));
    }

    #[test]
    fn the_fraction_of_the_bound_is_bytes_moved_over_bytes_available() {
        let bw = Bandwidth {
            threads: 2,
            bytes_per_sec: 28e9,
        };
        // 500 M samples/s of 56 bytes is exactly 28 GB/s.
        assert!((fraction_of_bound(500e6, 56, &bw) - 1.0).abs() < 1e-12);
        assert!((fraction_of_bound(250e6, 36, &bw) - 9e9 / 28e9).abs() < 1e-12);
    }
}
