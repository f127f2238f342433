//! Judging comparisons one at a time, `|fused - reference| <= atol + rtol |reference|`, and
//! keeping only what a report needs (counts and worst entries per input, the worst overall),
//! so that checking ten million elements holds no list of them.

use std::fmt;

use serde_json::{json, Value};

/// What the fused gradient is compared with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Against {
    /// The stable taped twin's gradient (f64), element by element.
    Twin,
    /// Finite differences of the fused op (f64): per element, or per random direction.
    FiniteDifferences,
}

impl Against {
    fn label(self) -> &'static str {
        match self {
            Against::Twin => "taped twin",
            Against::FiniteDifferences => "finite diff",
        }
    }
    fn key(self) -> &'static str {
        match self {
            Against::Twin => "taped_twin",
            Against::FiniteDifferences => "finite_differences",
        }
    }
}

/// Where a comparison was made.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Place {
    /// One element: a per-sample input (`sample`) or a per-ray one (`None`), and a channel
    /// for colours.
    Element {
        ray: usize,
        sample: Option<usize>,
        channel: Option<usize>,
    },
    /// A random direction through every input (fast mode).
    Direction(usize),
}

impl fmt::Display for Place {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Place::Element { ray, sample, channel } => {
                write!(f, "ray {ray}")?;
                if let Some(s) = sample {
                    write!(f, ", sample {s}")?;
                }
                if let Some(c) = channel {
                    write!(f, ", channel {c}")?;
                }
                Ok(())
            }
            Place::Direction(k) => write!(f, "direction {k}"),
        }
    }
}

/// One fused value beside its reference.
#[derive(Debug, Clone, Copy)]
pub struct Comparison {
    pub against: Against,
    /// `sigma`, `delta`, `color`, `background`, `t`, or `all inputs` for a direction.
    pub input: &'static str,
    pub place: Place,
    pub fused: f64,
    pub reference: f64,
    /// A one-sided finite difference (at sigma = 0 or delta = 0).
    pub one_sided: bool,
}

impl Comparison {
    fn diff(&self) -> f64 {
        (self.fused - self.reference).abs()
    }
    /// How many tolerances the difference is: above 1 fails (NaN and any difference under a
    /// zero tolerance count as infinitely many).
    fn excess(&self, atol: f64, rtol: f64) -> f64 {
        let (d, tol) = (self.diff(), atol + rtol * self.reference.abs());
        if d.is_nan() || (d > 0.0 && tol == 0.0) {
            f64::INFINITY
        } else if d == 0.0 {
            0.0
        } else {
            d / tol
        }
    }
    fn rank(&self, atol: f64, rtol: f64) -> (f64, f64) {
        let d = self.diff();
        (self.excess(atol, rtol), if d.is_nan() { f64::INFINITY } else { d })
    }
    fn describe(&self, atol: f64, rtol: f64) -> String {
        format!(
            "{:<11}  {} at {}{}: fused {:.9e}, reference {:.9e}, |diff| {:.3e} = {:.2e} tolerances",
            self.against.label(),
            self.input,
            self.place,
            if self.one_sided { " (one-sided)" } else { "" },
            self.fused,
            self.reference,
            self.diff(),
            self.excess(atol, rtol)
        )
    }
    fn to_json(self, atol: f64, rtol: f64) -> Value {
        let (ray, sample, channel, direction) = match self.place {
            Place::Element { ray, sample, channel } => (Some(ray), sample, channel, None),
            Place::Direction(k) => (None, None, None, Some(k)),
        };
        json!({
            "against": self.against.key(), "input": self.input, "ray": ray, "sample": sample,
            "channel": channel, "direction": direction, "fused": self.fused,
            "reference": self.reference, "abs_diff": self.diff(),
            "tolerances": self.excess(atol, rtol), "one_sided": self.one_sided,
        })
    }
}

/// The comparisons of one input against one reference.
#[derive(Debug, Clone)]
struct Summary {
    against: Against,
    input: &'static str,
    checked: usize,
    failing: usize,
    worst: Comparison,
}

/// Every comparison judged as it comes, and the `keep` worst kept.
#[derive(Debug)]
pub struct Tally {
    pub atol: f64,
    pub rtol: f64,
    keep: usize,
    summaries: Vec<Summary>,
    worst: Vec<Comparison>,
}

impl Tally {
    pub fn new(atol: f64, rtol: f64, keep: usize) -> Self {
        Tally {
            atol,
            rtol,
            keep,
            summaries: Vec::new(),
            worst: Vec::new(),
        }
    }

    pub fn add(&mut self, c: Comparison) {
        let (atol, rtol) = (self.atol, self.rtol);
        let rank = c.rank(atol, rtol);
        let fails = rank.0 > 1.0;
        match self
            .summaries
            .iter_mut()
            .find(|s| s.against == c.against && s.input == c.input)
        {
            Some(s) => {
                s.checked += 1;
                s.failing += usize::from(fails);
                if rank > s.worst.rank(atol, rtol) {
                    s.worst = c;
                }
            }
            None => self.summaries.push(Summary {
                against: c.against,
                input: c.input,
                checked: 1,
                failing: usize::from(fails),
                worst: c,
            }),
        }
        let full = self.worst.len() >= self.keep;
        if self.keep == 0 || (full && self.worst.last().is_some_and(|w| w.rank(atol, rtol) >= rank)) {
            return;
        }
        let at = self.worst.partition_point(|w| w.rank(atol, rtol) >= rank);
        self.worst.insert(at, c);
        self.worst.truncate(self.keep);
    }

    pub fn checked(&self) -> usize {
        self.summaries.iter().map(|s| s.checked).sum()
    }

    pub fn failing(&self) -> usize {
        self.summaries.iter().map(|s| s.failing).sum()
    }

    pub fn passed(&self) -> bool {
        self.failing() == 0
    }

    /// The table per input, the worst comparisons, and the verdict.
    pub fn text(&self) -> String {
        let mut out = format!(
            "{:<11}  {:<10} {:>9} {:>8}  {:<12} at\n",
            "against", "input", "checked", "failing", "worst |diff|"
        );
        for s in &self.summaries {
            out += &format!(
                "{:<11}  {:<10} {:>9} {:>8}  {:<12.3e} {}{}\n",
                s.against.label(),
                s.input,
                s.checked,
                s.failing,
                s.worst.diff(),
                s.worst.place,
                if s.worst.one_sided { " (one-sided)" } else { "" }
            );
        }
        out += &format!("worst {} by |diff| / (atol + rtol |reference|):\n", self.worst.len());
        for c in &self.worst {
            out += &format!("  {}\n", c.describe(self.atol, self.rtol));
        }
        out += &if self.passed() {
            format!("PASS: all {} comparisons within the tolerance", self.checked())
        } else {
            format!(
                "FAIL: {} of {} comparisons outside the tolerance",
                self.failing(),
                self.checked()
            )
        };
        out
    }

    /// The same as [`Tally::text`], as JSON fields.
    pub fn json(&self) -> Value {
        let inputs: Vec<Value> = self
            .summaries
            .iter()
            .map(|s| {
                json!({
                    "against": s.against.key(), "input": s.input, "checked": s.checked,
                    "failing": s.failing, "worst": s.worst.to_json(self.atol, self.rtol),
                })
            })
            .collect();
        let worst: Vec<Value> = self.worst.iter().map(|c| c.to_json(self.atol, self.rtol)).collect();
        json!({
            "passed": self.passed(), "checked": self.checked(), "failing": self.failing(),
            "atol": self.atol, "rtol": self.rtol, "inputs": inputs, "worst": worst,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(k: usize, fused: f64, reference: f64) -> Comparison {
        Comparison {
            against: Against::Twin,
            input: "sigma",
            place: Place::Element {
                ray: 0,
                sample: Some(k),
                channel: None,
            },
            fused,
            reference,
            one_sided: false,
        }
    }

    #[test]
    fn judges_each_entry_and_keeps_the_worst() {
        // atol 0.1, rtol 0.1: the tolerance at reference 1 is 0.2, at reference 10 it is 1.1.
        let mut t = Tally::new(0.1, 0.1, 2);
        t.add(at(0, 1.1, 1.0)); // 0.1 / 0.2 = 0.5 tolerances: passes
        t.add(at(1, 11.0, 10.0)); // 1 / 1.1: passes, though the largest |diff|
        t.add(at(2, 1.3, 1.0)); // 0.3 / 0.2 = 1.5: fails
        t.add(at(3, f64::NAN, 1.0)); // NaN fails, and ranks first
        assert_eq!((t.checked(), t.failing()), (4, 2));
        assert!(!t.passed());
        let worst: Vec<_> = t.worst.iter().map(|c| c.place).collect();
        assert_eq!(worst, [at(3, 0.0, 0.0).place, at(2, 0.0, 0.0).place]);
        // Under a zero tolerance only exact agreement passes.
        let mut zero = Tally::new(0.0, 0.0, 5);
        zero.add(at(0, 1.0, 1.0));
        assert!(zero.passed());
        zero.add(at(1, 1.0, 1.0 + f64::EPSILON));
        assert!(!zero.passed());
        assert!(zero.text().starts_with("against"));
        assert!(zero.text().ends_with("FAIL: 1 of 2 comparisons outside the tolerance"));
    }
}
