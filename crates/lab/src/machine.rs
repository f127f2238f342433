//! How fast the machine's memory is at the time of a measurement: a short STREAM triad
//! (`a = b + s c` over arrays far larger than the caches) gives the bytes per second the
//! cores can stream. `fogray-lab bench` turns it into a bound for the fused composite, and the
//! grid example's report measures it before and after its timed runs, so that figures taken in
//! different hours on a shared machine can be compared with the state the machine was in.

use std::time::Instant;

use rayon::prelude::*;
use serde::Serialize;

/// The smallest triad array: 32 MiB of f64 values.
const MIN_TRIAD_LEN: usize = 1 << 22;
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

/// f64 values per triad array: each array at least as large as the largest cache (so the three
/// together are three times any cache, and a pass streams from memory rather than from a cache
/// it fits in), at least [`MIN_TRIAD_LEN`], rounded up to a power of two. Some server parts
/// have a last-level cache of hundreds of MiB, where a fixed 96 MiB triad measured the cache.
fn triad_len(largest_cache_bytes: Option<usize>) -> usize {
    let cache_values = largest_cache_bytes.unwrap_or(0).div_ceil(std::mem::size_of::<f64>());
    cache_values.max(MIN_TRIAD_LEN).next_power_of_two()
}

/// The largest cache of CPU 0 in bytes, as Linux reports it (`None` elsewhere, or where it
/// cannot be read).
fn largest_cache_bytes() -> Option<usize> {
    let dir = std::fs::read_dir("/sys/devices/system/cpu/cpu0/cache").ok()?;
    dir.filter_map(|entry| {
        let size = std::fs::read_to_string(entry.ok()?.path().join("size")).ok()?;
        parse_cache_size(&size)
    })
    .max()
}

/// A sysfs cache size (`48K`, `2048K`, `516096K`, `32M`, or bytes) in bytes.
fn parse_cache_size(text: &str) -> Option<usize> {
    let text = text.trim();
    let (digits, unit) = match text.char_indices().find(|(_, c)| !c.is_ascii_digit()) {
        Some((i, _)) => text.split_at(i),
        None => (text, ""),
    };
    let scale = match unit {
        "" => 1,
        "K" => 1 << 10,
        "M" => 1 << 20,
        "G" => 1 << 30,
        _ => return None,
    };
    digits.parse::<usize>().ok()?.checked_mul(scale)
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
/// under other load. Its three arrays take 96 MiB while it runs, or three to six times the
/// largest cache where that is larger (see [`triad_len`]); a pass moves them once.
pub fn triad(runs: usize) -> Bandwidth {
    let threads = rayon::current_num_threads();
    let len = triad_len(largest_cache_bytes());
    let b: Vec<f64> = (0..len).into_par_iter().map(|i| (i % 7) as f64).collect();
    let c: Vec<f64> = (0..len).into_par_iter().map(|i| (i % 5) as f64).collect();
    let mut a = vec![0.0; len];
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
        bytes_per_sec: (3 * len * std::mem::size_of::<f64>()) as f64 / best.max(1e-9),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sysfs_cache_sizes_parse_in_their_units_and_nonsense_does_not() {
        assert_eq!(parse_cache_size("48K\n"), Some(48 << 10));
        assert_eq!(parse_cache_size("516096K"), Some(516_096 << 10));
        assert_eq!(parse_cache_size("32M"), Some(32 << 20));
        assert_eq!(parse_cache_size("1G"), Some(1 << 30));
        assert_eq!(parse_cache_size("65536"), Some(65_536));
        assert_eq!(parse_cache_size("12 KB"), None);
        assert_eq!(parse_cache_size("K"), None);
        assert_eq!(parse_cache_size(""), None);
    }

    #[test]
    fn triad_arrays_are_each_at_least_the_largest_cache_and_never_below_32_mib() {
        let mib = 1usize << 20;
        // No cache known, or small caches: the 32 MiB floor (4 Mi f64 values).
        assert_eq!(triad_len(None), 1 << 22);
        assert_eq!(triad_len(Some(32 * mib)), 1 << 22);
        // A 504 MiB last-level cache (516096K): 512 MiB arrays, 1.5 GiB in all.
        assert_eq!(triad_len(Some(516_096 << 10)), 1 << 26);
        // Just over a power of two rounds up, so an array never fits in the cache.
        assert_eq!(triad_len(Some(64 * mib + 1)), 1 << 24);
        for cache in [40 * mib, 96 * mib, 300 * mib] {
            assert!(triad_len(Some(cache)) * 8 >= cache, "{cache}");
        }
    }

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
