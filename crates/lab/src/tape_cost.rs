//! What the tape itself costs, apart from any op's arithmetic: the time per recorded op (a
//! chain of one-element adds, forward and backward) and the time per byte of a large add
//! (forward and backward), in f32 and f64.

use std::hint::black_box;

use fogray_tape::{Float, Tape};
use ndarray::Array1;
use serde::Serialize;

use crate::bench::median_secs;
use crate::error::LabError;

/// One precision's tape costs (a JSON object of `"tape_overhead"`).
#[derive(Debug, Clone, Serialize)]
pub struct TapeCost {
    /// `"f32"` or `"f64"`.
    pub precision: &'static str,
    /// Forward record plus backward of one op on one-element values.
    pub ns_per_op: f64,
    /// `a + b` on large vectors, forward plus backward, per byte moved (read a and b, write
    /// the sum; read its gradient, write both input gradients: six values per element).
    pub ns_per_byte: f64,
    /// The same as bandwidth.
    pub gb_per_sec: f64,
    /// Elements of the large add.
    pub elements: usize,
}

/// Ops in the chain that measures the per-op cost.
const CHAIN: usize = 20_000;

fn per_op<F: Float>() -> Result<f64, LabError> {
    let run = || -> Result<(), LabError> {
        let mut tape = Tape::<F>::new();
        let x = tape.param(Array1::from(vec![F::lit(0.5)]).into_dyn());
        let mut y = x;
        for _ in 0..CHAIN {
            y = tape.add(y, x)?;
        }
        let s = tape.sum(y)?;
        black_box(tape.backward(s)?);
        Ok(())
    };
    Ok(median_secs(5, run)? / CHAIN as f64 * 1e9)
}

fn per_byte<F: Float>(elements: usize) -> Result<f64, LabError> {
    let a = Array1::from(vec![F::lit(0.25); elements]).into_dyn();
    let b = Array1::from(vec![F::lit(0.75); elements]).into_dyn();
    let g = Array1::from(vec![F::one(); elements]).into_dyn();
    let setup = || {
        let mut tape = Tape::<F>::new();
        let (x, y) = (tape.param(a.clone()), tape.param(b.clone()));
        (tape, x, y)
    };
    let base = median_secs(5, || {
        black_box(setup());
        Ok(())
    })?;
    let full = median_secs(5, || {
        let (mut tape, x, y) = setup();
        let z = tape.add(x, y)?;
        black_box(tape.backward_with(z, g.clone())?);
        Ok(())
    })?;
    let bytes = 6 * elements * std::mem::size_of::<F>();
    Ok((full - base).max(1e-12) / bytes as f64 * 1e9)
}

fn measure<F: Float>(elements: usize) -> Result<TapeCost, LabError> {
    let ns_per_byte = per_byte::<F>(elements)?;
    Ok(TapeCost {
        precision: F::NAME,
        ns_per_op: per_op::<F>()?,
        ns_per_byte,
        gb_per_sec: 1.0 / ns_per_byte,
        elements,
    })
}

/// The tape's costs in f32 and f64, in the global pool (the element-wise add of the large
/// values runs on all its threads; the 1-element ops on the calling one).
pub fn run(quick: bool) -> Result<Vec<TapeCost>, LabError> {
    let elements = if quick { 1 << 20 } else { 1 << 22 };
    Ok(vec![measure::<f32>(elements)?, measure::<f64>(elements)?])
}

/// The text lines of the report.
pub fn table(costs: &[TapeCost]) -> String {
    let mut s = String::from("\nthe tape itself (all threads):\n");
    for c in costs {
        s += &format!(
            "  {}: {:.0} ns per recorded op (forward + backward, 1-element values); \
             {:.2} ns per byte ({:.1} GB/s) on a {}-element add (forward + backward)\n",
            c.precision, c.ns_per_op, c.ns_per_byte, c.gb_per_sec, c.elements
        );
    }
    s
}
