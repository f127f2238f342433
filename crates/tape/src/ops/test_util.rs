//! Helpers shared by the op tests.

use ndarray::{ArrayD, ArrayViewD};

use crate::gradcheck::{gradcheck, GradcheckOptions};
use crate::{Result, Tape, Var};

/// Runs gradcheck in f64 with default options and panics with the report if it fails.
pub(crate) fn assert_gradcheck(name: &str, inputs: &[ArrayD<f64>], f: impl Fn(&mut Tape<f64>, &[Var]) -> Result<Var>) {
    let report = gradcheck(f, inputs, &GradcheckOptions::default()).unwrap_or_else(|e| panic!("{name}: {e}"));
    if let Err(r) = report.check(1e-6, 1e-5) {
        panic!("{name}: {r}");
    }
}

/// Asserts element-wise `|got - want| <= tol * max(1, |want|)`.
pub(crate) fn values_close(name: &str, got: ArrayViewD<'_, f64>, want: &[f64], tol: f64) {
    let got: Vec<f64> = got.iter().copied().collect();
    assert_eq!(got.len(), want.len(), "{name}: length");
    for (k, (g, w)) in got.iter().zip(want).enumerate() {
        assert!(
            (g - w).abs() <= tol * w.abs().max(1.0),
            "{name}[{k}]: got {g}, want {w}"
        );
    }
}
