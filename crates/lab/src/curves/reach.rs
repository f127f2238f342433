//! A fit's log read as a curve: test PSNR between evaluations is taken as linear in training
//! time (and the steps and samples as linear in it too), so that "the PSNR at 30 s" and "the
//! time to reach 25 dB" can be read between two evaluations.

use serde::Serialize;

use fogray_fit::train::LogEntry;

use super::CurveError;

/// Where a curve first reaches a test PSNR, interpolated between the two evaluations around
/// the crossing.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Reach {
    /// Training seconds.
    pub seconds: f64,
    /// Steps (fractional between evaluations).
    pub steps: f64,
    /// Training samples drawn so far.
    pub samples: f64,
}

impl Reach {
    fn at(e: &LogEntry) -> Reach {
        Reach {
            seconds: e.seconds,
            steps: e.step as f64,
            samples: e.samples as f64,
        }
    }

    /// Mean samples per training ray up to here, for `batch` rays per step; `None` at step 0.
    pub fn samples_per_ray(&self, batch: usize) -> Option<f64> {
        (self.steps > 0.0 && batch > 0).then(|| self.samples / (self.steps * batch as f64))
    }
}

/// A log fit to read: not empty, times finite and non-decreasing, no NaN PSNR.
pub(crate) fn check(log: &[LogEntry]) -> Result<(), CurveError> {
    if log.is_empty() {
        return Err(CurveError::Log("the log is empty".into()));
    }
    for (i, e) in log.iter().enumerate() {
        if !e.seconds.is_finite() || e.test_psnr.is_nan() {
            return Err(CurveError::Log(format!(
                "entry {i}: seconds {} and test PSNR {} must be numbers",
                e.seconds, e.test_psnr
            )));
        }
        if i > 0 && (e.seconds < log[i - 1].seconds || e.step < log[i - 1].step) {
            return Err(CurveError::Log(format!("entry {i} goes back in time")));
        }
    }
    Ok(())
}

/// `a + f (b - a)` that keeps an infinite end exact.
fn lerp(a: f64, b: f64, f: f64) -> f64 {
    if f <= 0.0 {
        a
    } else if f >= 1.0 {
        b
    } else {
        a + f * (b - a)
    }
}

/// The test PSNR at `seconds` of training, linear between the evaluations around it; `None`
/// before the first evaluation or after the last (the run did not get there).
///
/// Errors: [`CurveError::Log`] for an empty log, a non-finite time, a NaN PSNR, or times or
/// steps that decrease.
pub fn psnr_at(log: &[LogEntry], seconds: f64) -> Result<Option<f64>, CurveError> {
    check(log)?;
    let Some(after) = log.iter().position(|e| e.seconds >= seconds) else {
        return Ok(None);
    };
    if after == 0 {
        return Ok((log[0].seconds == seconds).then_some(log[0].test_psnr));
    }
    let (a, b) = (&log[after - 1], &log[after]);
    let f = (seconds - a.seconds) / (b.seconds - a.seconds);
    Ok(Some(lerp(a.test_psnr, b.test_psnr, f)))
}

/// Where the curve first reaches `psnr` (at or above): between the last evaluation below it and
/// the first at or above it, linear in PSNR; `None` if no evaluation reaches it.
///
/// Errors: as [`psnr_at`].
pub fn reach(log: &[LogEntry], psnr: f64) -> Result<Option<Reach>, CurveError> {
    check(log)?;
    let Some(i) = log.iter().position(|e| e.test_psnr >= psnr) else {
        return Ok(None);
    };
    if i == 0 || log[i].test_psnr.is_infinite() {
        return Ok(Some(Reach::at(&log[i])));
    }
    let (a, b) = (&log[i - 1], &log[i]);
    let f = (psnr - a.test_psnr) / (b.test_psnr - a.test_psnr);
    Ok(Some(Reach {
        seconds: lerp(a.seconds, b.seconds, f),
        steps: lerp(a.step as f64, b.step as f64, f),
        samples: lerp(a.samples as f64, b.samples as f64, f),
    }))
}

/// The last evaluation's test PSNR. Errors: as [`psnr_at`].
pub fn final_psnr(log: &[LogEntry]) -> Result<f64, CurveError> {
    check(log)?;
    Ok(log[log.len() - 1].test_psnr)
}
