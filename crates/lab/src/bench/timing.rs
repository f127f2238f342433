//! Timing a step: the median of repeated runs, and a closure run on a chosen thread pool.

use super::*;

/// Wall times of repeated runs: the median, and the spread, the interquartile range over the
/// median (robust to the odd outlier run; 0 with a single run).
#[derive(Debug, Clone, Copy)]
pub struct Timing {
    /// The median run's seconds.
    pub median: f64,
    /// The interquartile range of the runs' seconds over their median.
    pub spread: f64,
}

/// Runs of `f` go on past `reps` until they have taken this long (short workloads get more
/// runs, so that their median means as much), up to [`MAX_RUNS`].
const MIN_SECS: f64 = 0.3;
const MAX_RUNS: usize = 200;

/// Times at least `reps` runs of `f` (more for short runs when `reps > 1`, see [`MIN_SECS`]),
/// after one warm-up run when `reps > 1`.
pub fn time_runs(reps: usize, mut f: impl FnMut() -> Result<(), LabError>) -> Result<Timing, LabError> {
    if reps > 1 {
        f()?;
    }
    let mut t = Vec::with_capacity(reps);
    let mut total = 0.0;
    while t.len() < reps.max(1) || (reps > 1 && total < MIN_SECS && t.len() < MAX_RUNS) {
        let start = Instant::now();
        f()?;
        let secs = start.elapsed().as_secs_f64();
        t.push(secs);
        total += secs;
    }
    t.sort_by(f64::total_cmp);
    let median = t[t.len() / 2];
    Ok(Timing {
        median,
        spread: (t[(3 * t.len()) / 4] - t[t.len() / 4]) / median.max(1e-12),
    })
}

/// Median wall time of `reps` runs of `f` (see [`time_runs`]).
pub fn median_secs(reps: usize, f: impl FnMut() -> Result<(), LabError>) -> Result<f64, LabError> {
    Ok(time_runs(reps, f)?.median)
}

/// Runs `f` in `pool`, or in the global pool when `None`.
pub fn within<R: Send>(pool: Option<&rayon::ThreadPool>, f: impl FnOnce() -> R + Send) -> R {
    match pool {
        Some(p) => p.install(f),
        None => f(),
    }
}
