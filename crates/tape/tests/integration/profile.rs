//! The tape's op profile: what it counts, what it leaves alone, and that it changes no value.

use std::time::Instant;

use fogray_tape::{CustomOp, OpError, Tape, TapeError};
use ndarray::{arr1, ArrayD, ArrayViewD};

/// One step of `sum(exp(x) * c)` with `x` a param and `c` a constant, plus an op on constants
/// alone (recorded for no backward); returns the gradient of `x`.
fn step(tape: &mut Tape<f64>) -> Result<Vec<f64>, TapeError> {
    tape.clear();
    let x = tape.param(arr1(&[0.5, -1.0, 2.0]));
    let c = tape.constant(arr1(&[1.0, 2.0, 3.0]));
    let c2 = tape.square(c)?; // constants only: a forward, no backward
    let y = tape.exp(x)?;
    let z = tape.mul(y, c2)?;
    let s = tape.sum(z)?;
    let grads = tape.backward(s)?;
    let g = grads.get(x).expect("x is a param").iter().copied().collect();
    tape.recycle(grads);
    Ok(g)
}

#[test]
fn counts_each_ops_forwards_and_backward_rules_across_steps() -> Result<(), TapeError> {
    let mut tape = Tape::<f64>::new();
    assert_eq!(tape.profile(), None, "off by default");
    tape.set_profiling(true);
    for _ in 0..3 {
        step(&mut tape)?;
    }
    let p = tape.profile().expect("profiling is on");
    let calls = |name: &str| p.get(name).map(|t| (t.forward_calls, t.backward_calls));
    assert_eq!(calls("exp"), Some((3, 3)));
    assert_eq!(calls("mul"), Some((3, 3)));
    assert_eq!(calls("sum"), Some((3, 3)));
    assert_eq!(calls("square"), Some((3, 0)), "an op on constants has no backward rule");
    assert_eq!(p.iter().count(), 4);
    // Rows by time hold the same ops, each at least as long as the next.
    let rows = p.by_time();
    assert_eq!(rows.len(), 4);
    assert!(rows.windows(2).all(|w| w[0].1.total() >= w[1].1.total()));
    assert_eq!(p.forward(), p.iter().map(|(_, t)| t.forward).sum());
    // Taking the profile starts the count again; switching it on again keeps the count.
    assert_eq!(tape.take_profile(), Some(p));
    assert!(tape.profile().expect("still on").is_empty());
    step(&mut tape)?;
    tape.set_profiling(true);
    assert_eq!(
        tape.profile().and_then(|p| p.get("exp")).map(|t| t.forward_calls),
        Some(1)
    );
    tape.set_profiling(false);
    assert_eq!(tape.take_profile(), None);
    Ok(())
}

#[test]
fn profiling_changes_no_value() -> Result<(), TapeError> {
    let mut plain = Tape::<f64>::new();
    let mut profiled = Tape::<f64>::new();
    profiled.set_profiling(true);
    for _ in 0..2 {
        let a = step(&mut plain)?;
        let b = step(&mut profiled)?;
        assert_eq!(
            a.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            b.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
    }
    Ok(())
}

#[test]
fn the_op_times_fit_inside_the_wall_time_around_them() -> Result<(), TapeError> {
    let mut tape = Tape::<f64>::new();
    tape.set_profiling(true);
    let started = Instant::now();
    for _ in 0..5 {
        step(&mut tape)?;
    }
    let wall = started.elapsed();
    let p = tape.profile().expect("on");
    assert!(
        p.forward() + p.backward() <= wall,
        "{:?} + {:?} > {wall:?}",
        p.forward(),
        p.backward()
    );
    Ok(())
}

/// An op that fails, or returns two outputs where one is wanted.
#[derive(Debug)]
struct Faulty {
    outputs: usize,
}

impl CustomOp<f64> for Faulty {
    type Saved = ();
    fn name(&self) -> &'static str {
        "faulty"
    }
    fn forward(&self, inputs: &[ArrayViewD<'_, f64>]) -> Result<(Vec<ArrayD<f64>>, ()), OpError> {
        if self.outputs == 0 {
            return Err(OpError::InvalidArgument("refused".into()));
        }
        Ok(((0..self.outputs).map(|_| inputs[0].to_owned()).collect(), ()))
    }
    fn backward(
        &self,
        _: &fogray_tape::BackwardCtx<'_, f64, ()>,
        _: &[Option<ArrayViewD<'_, f64>>],
    ) -> Result<Vec<Option<ArrayD<f64>>>, OpError> {
        Ok(vec![None])
    }
}

#[test]
fn a_failed_op_is_not_counted() {
    let mut tape = Tape::<f64>::new();
    tape.set_profiling(true);
    let x = tape.param(arr1(&[1.0, 2.0]));
    let y = tape.param(arr1(&[1.0, 2.0, 3.0]));
    assert!(tape.add(x, y).is_err(), "shapes that do not broadcast");
    assert!(tape.apply1(Faulty { outputs: 0 }, &[x]).is_err());
    assert!(tape.apply1(Faulty { outputs: 2 }, &[x]).is_err());
    assert_eq!(tape.len(), 2, "nothing pushed");
    assert!(tape.profile().expect("on").is_empty());
    // The same op succeeding is counted.
    tape.apply1(Faulty { outputs: 1 }, &[x]).expect("one output");
    assert_eq!(
        tape.profile().and_then(|p| p.get("faulty")).map(|t| t.forward_calls),
        Some(1)
    );
}
