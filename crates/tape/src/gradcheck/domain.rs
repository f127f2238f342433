//! Where an input may be evaluated, and which finite difference stays there.
//!
//! A central difference steps to `x - h` and `x + h`; for a function defined only on
//! `x >= 0` (a density, a length) it steps outside at `x = 0`, the most common value. The
//! second-order one-sided formulas
//!
//! ```text
//! forward:  f'(x) = (-3 f(x) + 4 f(x + h) - f(x + 2h)) / 2h + O(h^2)
//! backward: f'(x) = ( 3 f(x) - 4 f(x - h) + f(x - 2h)) / 2h + O(h^2)
//! ```
//!
//! (Taylor expansions of `f(x + h)` and `f(x + 2h)` to third order: the `f''` terms cancel)
//! keep the accuracy order of the central one and only step inward.

use crate::error::{Result, TapeError};

/// The closed interval `[lower, upper]` an input's elements may take (either end infinite).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Domain {
    /// Smallest allowed value (`-inf` when unbounded below).
    pub lower: f64,
    /// Largest allowed value (`+inf` when unbounded above).
    pub upper: f64,
}

impl Default for Domain {
    fn default() -> Self {
        Domain::REAL
    }
}

impl Domain {
    /// Every real number: central differences everywhere.
    pub const REAL: Domain = Domain {
        lower: f64::NEG_INFINITY,
        upper: f64::INFINITY,
    };

    /// `[lower, +inf)`, e.g. `Domain::at_least(0.0)` for a density.
    pub fn at_least(lower: f64) -> Domain {
        Domain {
            lower,
            upper: f64::INFINITY,
        }
    }

    /// `(-inf, upper]`.
    pub fn at_most(upper: f64) -> Domain {
        Domain {
            lower: f64::NEG_INFINITY,
            upper,
        }
    }

    /// Whether `x` lies in the interval.
    pub fn contains(&self, x: f64) -> bool {
        self.lower <= x && x <= self.upper
    }

    /// An error unless the ends are ordered and not NaN.
    pub(crate) fn validate(&self, input: &str) -> Result<()> {
        if self.lower <= self.upper {
            Ok(())
        } else {
            Err(invalid(format!(
                "{input}: domain [{}, {}] is empty",
                self.lower, self.upper
            )))
        }
    }

    /// The formula that differences `x` with step `h` without leaving the domain: central when
    /// `x +- h` are inside, else the one-sided formula that steps away from the near end.
    /// `at` names the element for the error (`x` outside, or a domain narrower than `2h`).
    pub(crate) fn difference(&self, x: f64, h: f64, at: impl Fn() -> String) -> Result<Difference> {
        if !self.contains(x) {
            return Err(invalid(format!(
                "{} is {x}, outside its domain [{}, {}]",
                at(),
                self.lower,
                self.upper
            )));
        }
        if self.contains(x - h) && self.contains(x + h) {
            Ok(Difference::Central)
        } else if self.contains(x + 2.0 * h) {
            Ok(Difference::Forward)
        } else if self.contains(x - 2.0 * h) {
            Ok(Difference::Backward)
        } else {
            Err(invalid(format!(
                "{}: its domain [{}, {}] is narrower than two steps of {h}",
                at(),
                self.lower,
                self.upper
            )))
        }
    }

    /// The sign a random direction must take at `x` so that steps `x + s d` with
    /// `0 <= s <= 2h`, `|d| <= 1`, stay inside: `Some(1.0)` (inward from the lower end),
    /// `Some(-1.0)` (from the upper end), `None` (either sign). `at` names the element.
    pub(crate) fn inward_sign(&self, x: f64, h: f64, at: impl Fn() -> String) -> Result<Option<f64>> {
        let reach = 2.0 * h;
        match (self.contains(x - reach), self.contains(x + reach)) {
            (true, true) => Ok(None),
            (false, true) if self.contains(x) => Ok(Some(1.0)),
            (true, false) if self.contains(x) => Ok(Some(-1.0)),
            // Outside, or both ends within reach: the difference formula reports which.
            _ => self.difference(x, reach, at).map(|_| None),
        }
    }
}

fn invalid(reason: String) -> TapeError {
    TapeError::InvalidArgument {
        op: "gradcheck",
        reason,
    }
}

/// Which finite-difference formula produced an estimate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Difference {
    /// `(f(x + h) - f(x - h)) / 2h`.
    Central,
    /// `(-3 f(x) + 4 f(x + h) - f(x + 2h)) / 2h`, at a lower end of the domain.
    Forward,
    /// `(3 f(x) - 4 f(x - h) + f(x - 2h)) / 2h`, at an upper end of the domain.
    Backward,
}

impl Difference {
    /// The derivative estimate from the function's values at `x` (`f0`, used by the one-sided
    /// formulas only), one step and two steps away (`f1`, `f2`: `x + h`, `x + 2h` for
    /// [`Difference::Forward`], `x - h`, `x - 2h` for [`Difference::Backward`]; for
    /// [`Difference::Central`], `f1 = f(x + h)` and `f2 = f(x - h)`).
    pub(crate) fn estimate(self, f0: f64, f1: f64, f2: f64, h: f64) -> f64 {
        match self {
            Difference::Central => (f1 - f2) / (2.0 * h),
            Difference::Forward => (-3.0 * f0 + 4.0 * f1 - f2) / (2.0 * h),
            Difference::Backward => (3.0 * f0 - 4.0 * f1 + f2) / (2.0 * h),
        }
    }

    /// The two signed offsets (in steps) where the function is evaluated besides `x`.
    pub(crate) fn offsets(self) -> [f64; 2] {
        match self {
            Difference::Central => [1.0, -1.0],
            Difference::Forward => [1.0, 2.0],
            Difference::Backward => [-1.0, -2.0],
        }
    }

    /// Whether the formula is one-sided (and reads `f(x)` itself).
    pub fn one_sided(self) -> bool {
        self != Difference::Central
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formulas_are_exact_on_quadratics_and_pick_the_inward_side() {
        // f(x) = 3 x^2 - x + 2, f'(x) = 6 x - 1: every second-order formula is exact on it
        // (up to rounding).
        let f = |x: f64| 3.0 * x * x - x + 2.0;
        let (x, h) = (0.5, 1e-3);
        for d in [Difference::Central, Difference::Forward, Difference::Backward] {
            let [a, b] = d.offsets();
            let est = d.estimate(f(x), f(x + a * h), f(x + b * h), h);
            assert!((est - 2.0).abs() < 1e-9, "{d:?}: {est}");
        }
        let unit = Domain { lower: 0.0, upper: 1.0 };
        let at = || "x".to_string();
        assert_eq!(unit.difference(0.5, 1e-3, at).unwrap(), Difference::Central);
        assert_eq!(unit.difference(0.0, 1e-3, at).unwrap(), Difference::Forward);
        assert_eq!(unit.difference(1.0, 1e-3, at).unwrap(), Difference::Backward);
        assert!(unit
            .difference(1.5, 1e-3, at)
            .unwrap_err()
            .to_string()
            .contains("outside"));
        assert!(unit
            .difference(0.5, 0.6, at)
            .unwrap_err()
            .to_string()
            .contains("narrower"));
        assert_eq!(unit.inward_sign(1.5e-3, 1e-3, at).unwrap(), Some(1.0));
        assert_eq!(unit.inward_sign(1.0, 1e-3, at).unwrap(), Some(-1.0));
        assert_eq!(unit.inward_sign(0.5, 1e-3, at).unwrap(), None);
        assert!(Domain { lower: 1.0, upper: 0.0 }.validate("x").is_err());
        assert!(Domain {
            lower: f64::NAN,
            upper: 0.0
        }
        .validate("x")
        .is_err());
    }
}
