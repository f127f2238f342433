//! What `gradcheck` found: every compared pair, the worst of them, and a pass/fail rule.

use std::fmt;

use super::domain::Difference;

/// One comparison of an analytic derivative with its finite-difference estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct GradcheckEntry {
    /// Which input (`None` in fast mode, where a direction spans every input).
    pub input: Option<usize>,
    /// The element's multi-index (in fast mode: `[k]`, the direction's number; a direction's
    /// elements at or near an end of their domain are checked by a second, one-sided entry of
    /// the same number).
    pub index: Vec<usize>,
    /// Central finite difference.
    pub numeric: f64,
    /// The tape's value.
    pub analytic: f64,
    /// The formula of `numeric` (one-sided at an end of the input's domain).
    pub difference: Difference,
}

impl GradcheckEntry {
    /// `|analytic - numeric|`.
    pub fn abs_err(&self) -> f64 {
        (self.analytic - self.numeric).abs()
    }
    /// `|analytic - numeric| / max(|analytic|, |numeric|)` (0 when both are 0).
    pub fn rel_err(&self) -> f64 {
        let scale = self.analytic.abs().max(self.numeric.abs());
        if scale == 0.0 {
            0.0
        } else {
            self.abs_err() / scale
        }
    }
    /// Whether `|analytic - numeric| <= atol + rtol |numeric|` (the finite difference is the
    /// reference, as numpy's `allclose`); a NaN on either side fails.
    pub fn passes(&self, atol: f64, rtol: f64) -> bool {
        self.abs_err() <= atol + rtol * self.numeric.abs()
    }
}

/// The result of [`gradcheck`](crate::gradcheck()).
#[derive(Debug, Clone, PartialEq)]
pub struct GradcheckReport {
    /// Every comparison made.
    pub entries: Vec<GradcheckEntry>,
    /// Number of comparisons (elements, or directions in fast mode).
    pub checked: usize,
    /// Largest difference between two backward sweeps over the same tape (should be 0).
    pub reentrancy_diff: f64,
    /// The absolute tolerance of the options it was run with.
    pub atol: f64,
    /// The relative tolerance of the options it was run with.
    pub rtol: f64,
    /// The input names the options gave (possibly fewer than the inputs; see
    /// [`GradcheckReport::input_name`]).
    pub names: Vec<String>,
}

impl GradcheckReport {
    /// The comparison with the largest absolute error (NaN counts as largest).
    pub fn worst_abs(&self) -> Option<&GradcheckEntry> {
        self.worst_by(GradcheckEntry::abs_err)
    }
    /// The comparison with the largest relative error (NaN counts as largest).
    pub fn worst_rel(&self) -> Option<&GradcheckEntry> {
        self.worst_by(GradcheckEntry::rel_err)
    }

    /// The caller's name of input `i`, quoted (`"sigma"`), or its index (`2`) if it has none.
    pub fn input_name(&self, i: usize) -> String {
        match self.names.get(i) {
            Some(name) => format!("\"{name}\""),
            None => i.to_string(),
        }
    }

    /// Where `entry` was measured, in words: `input "sigma" at [3]` (full mode) or
    /// `direction 3 (all inputs)` (fast mode), with `, one-sided` after a one-sided difference.
    pub fn locate(&self, entry: &GradcheckEntry) -> String {
        let side = match entry.difference {
            Difference::Central => "",
            Difference::Forward => ", one-sided forward",
            Difference::Backward => ", one-sided backward",
        };
        match entry.input {
            Some(i) => format!("input {} at {:?}{side}", self.input_name(i), entry.index),
            None => format!(
                "direction {} (all inputs){side}",
                entry.index.first().copied().unwrap_or(0)
            ),
        }
    }

    fn worst_by(&self, key: impl Fn(&GradcheckEntry) -> f64) -> Option<&GradcheckEntry> {
        let k = |e: &GradcheckEntry| {
            let v = key(e);
            if v.is_nan() {
                f64::INFINITY
            } else {
                v
            }
        };
        self.entries.iter().max_by(|a, b| k(a).total_cmp(&k(b)))
    }

    /// `Ok` if every comparison passes `|a - n| <= atol + rtol |n|` and two backward sweeps
    /// agreed exactly; otherwise `Err` with the report, whose `Display` names the worst entry.
    pub fn check(&self, atol: f64, rtol: f64) -> Result<(), Box<GradcheckReport>> {
        let all = self.entries.iter().all(|e| e.passes(atol, rtol));
        if all && self.reentrancy_diff == 0.0 {
            Ok(())
        } else {
            Err(Box::new(GradcheckReport {
                atol,
                rtol,
                ..self.clone()
            }))
        }
    }

    /// [`GradcheckReport::check`] with the tolerances the report was made with.
    pub fn passes(&self) -> bool {
        self.check(self.atol, self.rtol).is_ok()
    }
}

impl fmt::Display for GradcheckReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let failing = self.entries.iter().filter(|e| !e.passes(self.atol, self.rtol)).count();
        writeln!(
            f,
            "gradcheck: {} checked, {failing} outside atol {:e} + rtol {:e}, reentrancy diff {:e}",
            self.checked, self.atol, self.rtol, self.reentrancy_diff
        )?;
        for (what, e) in [("worst abs", self.worst_abs()), ("worst rel", self.worst_rel())] {
            if let Some(e) = e {
                writeln!(
                    f,
                    "  {what}: {}: numeric {:.12e}, analytic {:.12e} (abs {:.3e}, rel {:.3e})",
                    self.locate(e),
                    e.numeric,
                    e.analytic,
                    e.abs_err(),
                    e.rel_err()
                )?;
            }
        }
        Ok(())
    }
}

impl std::error::Error for GradcheckReport {}
