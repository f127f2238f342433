//! How fast the machine's memory is at the time of a measurement: a short STREAM triad
//! (`a = b + s c` over arrays far larger than the caches) gives the bytes per second the
//! cores can stream. `fogray bench` turns it into a bound for the fused composite, and the
//! grid example's report measures it before and after its timed runs, so that figures taken in
//! different hours on a shared machine can be compared with the state the machine was in.

use std::time::Instant;

use rayon::prelude::*;
use serde::Serialize;

/// f64 values per triad array: 32 MiB each, 96 MiB in all, several times any cache here.
const TRIAD_LEN: usize = 1 << 22;
/// Values per parallel piece of the triad.
const PIECE: usize = 1 << 16;

/// What a short triad measured on `threads` threads.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Bandwidth {
    /// Threads of the rayon pool the triad ran on.
    pub threads: usize,
    /// The best pass's bytes per second, counted as STREAM counts them: two arrays read and
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

/// Measures the triad on the current rayon pool (run it inside `pool.install` for another):
/// the arrays are written once (so that their pages exist), then the best of `runs` timed
/// passes (at least one) is kept, as STREAM does: the machine's capacity, not its average
/// under other load. Takes about a tenth of a second a pass and 96 MiB while it runs.
pub fn triad(runs: usize) -> Bandwidth {
    let threads = rayon::current_num_threads();
    let b: Vec<f64> = (0..TRIAD_LEN).into_par_iter().map(|i| (i % 7) as f64).collect();
    let c: Vec<f64> = (0..TRIAD_LEN).into_par_iter().map(|i| (i % 5) as f64).collect();
    let mut a = vec![0.0; TRIAD_LEN];
    triad_pass(&mut a, &b, &c, 3.0);
    let mut best = f64::INFINITY;
    for _ in 0..runs.max(1) {
        let start = Instant::now();
        // The arrays pass through `black_box`, so that no pass can be dropped or merged.
        triad_pass(std::hint::black_box(&mut a), std::hint::black_box(&b), &c, 3.0);
        best = best.min(start.elapsed().as_secs_f64());
    }
    Bandwidth {
        threads,
        bytes_per_sec: (3 * TRIAD_LEN * std::mem::size_of::<f64>()) as f64 / best.max(1e-9),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_triad_computes_its_values_and_reports_a_rate() {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
        let bw = pool.install(|| triad(1));
        assert_eq!(bw.threads, 2);
        assert!(bw.bytes_per_sec.is_finite() && bw.bytes_per_sec > 0.0, "{bw:?}");
        let (b, c) = (vec![1.5; 3 * PIECE + 5], vec![-2.0; 3 * PIECE + 5]);
        let mut a = vec![0.0; b.len()];
        triad_pass(&mut a, &b, &c, 0.25);
        assert!(a.iter().all(|&v| v == 1.0));
    }
}
