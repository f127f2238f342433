//! The machine's memory bound for `fogray bench`: a short STREAM triad (`a = b + s c` over
//! arrays far larger than the caches) gives the bytes per second the cores can stream, and the
//! fused composite's bytes per sample turn it into a bound in samples per second, so that each
//! fused row can say what fraction of the machine it reaches.

use std::time::Instant;

use rayon::prelude::*;
use serde::Serialize;

use super::bench::within;
use super::error::CliError;

/// f64 values per triad array: 32 MiB each, 96 MiB in all, several times any cache here.
const TRIAD_LEN: usize = 1 << 22;
/// Values per parallel piece of the triad.
const PIECE: usize = 1 << 16;

/// What a short triad measured on `threads` threads.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Bandwidth {
    pub threads: usize,
    /// The best run's bytes per second, counted as STREAM counts them: two arrays read and
    /// one written, 24 bytes a value (the write's read for ownership not counted).
    pub bytes_per_sec: f64,
}

/// One triad pass, `a[i] = b[i] + s c[i]`, on the current rayon pool.
fn triad_pass(a: &mut [f64], b: &[f64], c: &[f64], s: f64) {
    a.par_chunks_mut(PIECE)
        .zip(b.par_chunks(PIECE))
        .zip(c.par_chunks(PIECE))
        .for_each(|((a, b), c)| {
            for ((a, &b), &c) in a.iter_mut().zip(b).zip(c) {
                *a = b + s * c;
            }
        });
}

/// Measures the triad on `pool` (the global pool when `None`): the arrays are written once
/// (so that their pages exist), then the best of `runs` timed passes is kept (as STREAM does:
/// the machine's capacity, not its average under other load).
pub fn triad(pool: Option<&rayon::ThreadPool>, runs: usize) -> Result<Bandwidth, CliError> {
    within(pool, || {
        let threads = rayon::current_num_threads();
        let b: Vec<f64> = (0..TRIAD_LEN).into_par_iter().map(|i| (i % 7) as f64).collect();
        let c: Vec<f64> = (0..TRIAD_LEN).into_par_iter().map(|i| (i % 5) as f64).collect();
        let mut a = vec![0.0; TRIAD_LEN];
        triad_pass(&mut a, &b, &c, 3.0);
        let mut best = f64::INFINITY;
        for _ in 0..runs.max(1) {
            let start = Instant::now();
            triad_pass(&mut a, &b, &c, 3.0);
            best = best.min(start.elapsed().as_secs_f64());
        }
        // The result is read, so that no pass can be dropped: a[i] = (i % 7) + 3 (i % 5).
        let i = TRIAD_LEN - 1;
        if a[i] != (i % 7) as f64 + 3.0 * (i % 5) as f64 {
            return Err(CliError::Missing("the triad computed a wrong value"));
        }
        Ok(Bandwidth {
            threads,
            bytes_per_sec: (3 * TRIAD_LEN * std::mem::size_of::<f64>()) as f64 / best.max(1e-9),
        })
    })
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

    #[test]
    fn the_triad_computes_its_values_and_reports_a_rate() {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
        let bw = triad(Some(&pool), 1).unwrap();
        assert_eq!(bw.threads, 2);
        assert!(bw.bytes_per_sec.is_finite() && bw.bytes_per_sec > 0.0, "{bw:?}");
        let (b, c) = (vec![1.5; 3 * PIECE + 5], vec![-2.0; 3 * PIECE + 5]);
        let mut a = vec![0.0; b.len()];
        triad_pass(&mut a, &b, &c, 0.25);
        assert!(a.iter().all(|&v| v == 1.0));
    }
}
