//! Tape life-cycle and contract tests: deep chains, clear/reuse, stale handles, recording
//! rules, gradient store semantics, and the custom-op contract.

use fogray_tape::{BackwardCtx, CustomOp, OpError, Tape, TapeError};
use ndarray::{arr1, ArrayD, ArrayViewD};

#[test]
fn a_chain_of_a_million_ops_runs_backward_without_recursion() {
    // y = x * 1.000001^(10^6), so dy/dx = 1.000001^(10^6) = e^(10^6 ln 1.000001) ~ 2.7182805.
    let mut t = Tape::<f64>::new();
    let x = t.param(arr1(&[1.0]));
    let mut y = x;
    for _ in 0..1_000_000 {
        y = t.mul_scalar(y, 1.000_001).unwrap();
    }
    let s = t.sum(y).unwrap();
    let g = t.backward(s).unwrap();
    let want = (1e6 * 1.000_001f64.ln()).exp();
    assert!((g.get(x).unwrap()[[0]] - want).abs() < 1e-9 * want);
    assert_eq!(t.stats().records, 1_000_001);
}

#[test]
fn clear_keeps_capacity_and_invalidates_old_handles() {
    let mut t = Tape::<f32>::new();
    let x = t.param(arr1(&[1.0f32, 2.0]));
    let y = t.square(x).unwrap();
    let s = t.sum(y).unwrap();
    let g_before = t.backward(s).unwrap();
    t.clear();
    assert_eq!(t.len(), 0);
    assert!(matches!(t.value(x), Err(TapeError::StaleVar { .. })));
    assert!(matches!(t.square(y), Err(TapeError::StaleVar { .. })));
    assert!(matches!(t.backward(s), Err(TapeError::StaleVar { .. })));
    // The old gradient store does not answer for the new tape's handles.
    let x2 = t.param(arr1(&[3.0f32, 4.0]));
    assert!(g_before.get(x2).is_none());
    // Reuse in a training-loop shape: same program, new values, correct gradient 2x.
    let y2 = t.square(x2).unwrap();
    let s2 = t.sum(y2).unwrap();
    let g = t.backward(s2).unwrap();
    assert_eq!(g.get(x2).unwrap().iter().copied().collect::<Vec<_>>(), vec![6.0, 8.0]);
}

#[test]
fn handles_from_another_tape_are_rejected() {
    let mut a = Tape::<f64>::new();
    let mut b = Tape::<f64>::new();
    let xa = a.param(arr1(&[1.0]));
    let _xb = b.param(arr1(&[1.0]));
    assert!(matches!(b.exp(xa), Err(TapeError::StaleVar { .. })));
}

#[test]
fn ops_on_constants_or_under_no_grad_record_nothing() {
    let mut t = Tape::<f64>::new();
    let c = t.constant(arr1(&[1.0, 2.0]));
    let e = t.exp(c).unwrap();
    assert_eq!(t.stats().records, 0);
    assert!(!t.needs_grad(e).unwrap());
    let x = t.param(arr1(&[1.0, 2.0]));
    let y = t.no_grad(|t| t.exp(x)).unwrap();
    assert_eq!(t.stats().records, 0);
    assert!(!t.needs_grad(y).unwrap());
    assert!(t.grad_enabled(), "no_grad restores recording");
    let d = t.detach(x).unwrap();
    let z = t.mul(d, x).unwrap();
    assert_eq!(t.stats().records, 1);
    // d(d * x)/dx = d (the detached copy gets no gradient of its own).
    let s = t.sum(z).unwrap();
    let g = t.backward(s).unwrap();
    assert_eq!(g.get(x).unwrap().iter().copied().collect::<Vec<_>>(), vec![1.0, 2.0]);
    assert!(g.get(d).is_none());
}

#[test]
fn never_reached_is_not_zero_and_retain_keeps_intermediates() {
    let mut t = Tape::<f64>::new();
    let x = t.param(arr1(&[3.0]));
    let unused = t.param(arr1(&[5.0]));
    let h = t.square(x).unwrap();
    t.retain(h).unwrap();
    let zeroed = t.mul_scalar(h, 0.0).unwrap();
    let s = t.sum(zeroed).unwrap();
    let g = t.backward(s).unwrap();
    assert!(g.get(unused).is_none(), "never reached");
    assert_eq!(g.get_or_zeros(&t, unused).unwrap(), arr1(&[0.0]).into_dyn());
    assert_eq!(g.get(x).unwrap()[[0]], 0.0, "reached, and zero");
    assert_eq!(g.get(h).unwrap()[[0]], 0.0, "retained intermediate");
    // Without retain, an intermediate's gradient is released.
    let h2 = t.exp(x).unwrap();
    let s2 = t.sum(h2).unwrap();
    let g2 = t.backward(s2).unwrap();
    assert!(g2.get(h2).is_none());
}

#[test]
fn fan_out_accumulates() {
    // y = x*x + x  =>  dy/dx = 2x + 1 = 7 at x = 3.
    let mut t = Tape::<f32>::new();
    let x = t.param(arr1(&[3.0f32]));
    let xx = t.mul(x, x).unwrap();
    let y = t.add(xx, x).unwrap();
    let s = t.sum(y).unwrap();
    assert_eq!(t.backward(s).unwrap().get(x).unwrap()[[0]], 7.0);
}

#[test]
fn backward_needs_a_scalar_or_a_seed_of_the_right_shape() {
    let mut t = Tape::<f64>::new();
    let x = t.param(arr1(&[1.0, 2.0]));
    let y = t.exp(x).unwrap();
    assert_eq!(t.backward(y).unwrap_err(), TapeError::NotScalar { shape: vec![2] });
    assert!(matches!(
        t.backward_with(y, ArrayD::zeros(vec![3])),
        Err(TapeError::ShapeMismatch { .. })
    ));
    let g = t.backward_with(y, arr1(&[1.0, 0.0]).into_dyn()).unwrap();
    assert_eq!(g.get(x).unwrap()[[0]], 1.0f64.exp());
    assert_eq!(g.get(x).unwrap()[[1]], 0.0);
}

#[test]
fn stats_count_values_records_and_bytes() {
    let mut t = Tape::<f32>::new();
    let x = t.param(ArrayD::<f32>::zeros(vec![10]));
    let _y = t.exp(x).unwrap();
    let s = t.stats();
    assert_eq!((s.values, s.records, s.value_bytes, s.saved_bytes), (2, 1, 80, 0));
}

/// A two-output op: (sum, product) of a vector, with an explicit residual, to exercise the
/// custom-op contract: multiple outputs, `Option` upstream gradients, `needs_input_grad`.
#[derive(Debug)]
struct SumAndProduct;

impl CustomOp<f64> for SumAndProduct {
    type Saved = f64; // the product, saved to show residuals reach backward

    fn name(&self) -> &'static str {
        "sum_and_product"
    }
    fn forward(&self, inputs: &[ArrayViewD<'_, f64>]) -> Result<(Vec<ArrayD<f64>>, f64), OpError> {
        let x = &inputs[0];
        let p = x.product();
        Ok((vec![arr1(&[x.sum()]).into_dyn(), arr1(&[p]).into_dyn()], p))
    }
    fn backward(
        &self,
        ctx: &BackwardCtx<'_, f64, f64>,
        grads: &[Option<ArrayViewD<'_, f64>>],
    ) -> Result<Vec<Option<ArrayD<f64>>>, OpError> {
        assert!(ctx.needs_input_grad(0));
        let x = ctx.input(0);
        let mut g = ArrayD::zeros(x.shape());
        if let Some(gs) = &grads[0] {
            g += gs[[0]];
        }
        if let Some(gp) = &grads[1] {
            // d prod / dx_i = prod / x_i (fine for this test's nonzero inputs)
            g = g + x.mapv(|xi| gp[[0]] * ctx.saved() / xi);
            assert_eq!(*ctx.saved(), ctx.output(1)[[0]]);
        }
        Ok(vec![Some(g)])
    }
    fn saved_bytes(&self, _: &f64) -> usize {
        8
    }
}

#[test]
fn multi_output_custom_op_with_unused_outputs() {
    let mut t = Tape::<f64>::new();
    let x = t.param(arr1(&[2.0, 3.0, 4.0]));
    let outs = t.apply(SumAndProduct, &[x]).unwrap();
    assert_eq!(t.stats().saved_bytes, 8);
    // Only the product is used: d prod/dx = (12, 8, 6).
    let s = t.sum(outs[1]).unwrap();
    let g = t.backward(s).unwrap();
    assert_eq!(
        g.get(x).unwrap().iter().copied().collect::<Vec<_>>(),
        vec![12.0, 8.0, 6.0]
    );
    // Both used: sum + product => 1 + (12, 8, 6).
    let both = t.add(outs[0], outs[1]).unwrap();
    let s2 = t.sum(both).unwrap();
    let g2 = t.backward(s2).unwrap();
    assert_eq!(
        g2.get(x).unwrap().iter().copied().collect::<Vec<_>>(),
        vec![13.0, 9.0, 7.0]
    );
    // Differentiating from one output directly (an output that is not the op's last).
    let g3 = t.backward(outs[0]).unwrap();
    assert_eq!(
        g3.get(x).unwrap().iter().copied().collect::<Vec<_>>(),
        vec![1.0, 1.0, 1.0]
    );
    // apply1 on a two-output op is an error that leaves the tape unchanged.
    let before = t.stats();
    assert!(matches!(
        t.apply1(SumAndProduct, &[x]),
        Err(TapeError::InvalidArgument {
            op: "sum_and_product",
            ..
        })
    ));
    assert_eq!(t.stats(), before);
}

/// Backward contract violations, each chosen by the op's field.
#[derive(Debug)]
enum Broken {
    TooFewGradients,
    WrongShape,
    NotDifferentiable,
    FailsInForward,
}

impl CustomOp<f32> for Broken {
    type Saved = ();
    fn name(&self) -> &'static str {
        "broken"
    }
    fn forward(&self, inputs: &[ArrayViewD<'_, f32>]) -> Result<(Vec<ArrayD<f32>>, ()), OpError> {
        match self {
            Broken::FailsInForward => Err(OpError::InvalidArgument("no thanks".into())),
            _ => Ok((vec![inputs[0].to_owned()], ())),
        }
    }
    fn backward(
        &self,
        _: &BackwardCtx<'_, f32, ()>,
        _: &[Option<ArrayViewD<'_, f32>>],
    ) -> Result<Vec<Option<ArrayD<f32>>>, OpError> {
        match self {
            Broken::TooFewGradients => Ok(vec![]),
            Broken::WrongShape => Ok(vec![Some(ArrayD::zeros(vec![5]))]),
            _ => Err(OpError::NotDifferentiable),
        }
    }
}

#[test]
fn the_tape_checks_what_a_backward_returns_and_names_the_op() {
    let run = |op: Broken| {
        let mut t = Tape::<f32>::new();
        let x = t.param(arr1(&[1.0f32, 2.0]));
        let y = t.apply1(op, &[x])?;
        let s = t.sum(y)?;
        t.backward(s).map(|_| ())
    };
    assert_eq!(
        run(Broken::TooFewGradients).unwrap_err(),
        TapeError::BadGradientCount {
            op: "broken",
            expected: 1,
            got: 0
        }
    );
    assert_eq!(
        run(Broken::WrongShape).unwrap_err(),
        TapeError::BadGradient {
            op: "broken",
            input: 0,
            expected: vec![2],
            got: vec![5]
        }
    );
    assert_eq!(
        run(Broken::NotDifferentiable).unwrap_err(),
        TapeError::Op {
            op: "broken",
            source: OpError::NotDifferentiable
        }
    );
    assert_eq!(
        run(Broken::FailsInForward).unwrap_err(),
        TapeError::InvalidArgument {
            op: "broken",
            reason: "no thanks".into()
        }
    );
    let msg = run(Broken::WrongShape).unwrap_err().to_string();
    assert!(msg.contains("broken") && msg.contains("[5]"), "{msg}");
}

#[test]
fn the_tape_is_send() {
    fn is_send<T: Send>() {}
    is_send::<Tape<f32>>();
    is_send::<Tape<f64>>();
}

/// Doubles its input; its forward (the one that makes residuals) and its outputs-alone
/// forward mark different outputs, so that a test sees which one ran.
#[derive(Debug)]
struct Marked;

impl CustomOp<f64> for Marked {
    type Saved = Vec<f64>;
    fn name(&self) -> &'static str {
        "marked"
    }
    fn forward(&self, inputs: &[ArrayViewD<'_, f64>]) -> Result<(Vec<ArrayD<f64>>, Vec<f64>), OpError> {
        let y = inputs[0].mapv(|x| 2.0 * x);
        Ok((vec![y, ArrayD::from_elem(vec![1], 1.0)], vec![7.0]))
    }
    fn forward_only(&self, inputs: &[ArrayViewD<'_, f64>]) -> Result<Vec<ArrayD<f64>>, OpError> {
        let y = inputs[0].mapv(|x| 2.0 * x);
        Ok(vec![y, ArrayD::from_elem(vec![1], 0.0)])
    }
    fn backward(
        &self,
        ctx: &BackwardCtx<'_, f64, Vec<f64>>,
        grads: &[Option<ArrayViewD<'_, f64>>],
    ) -> Result<Vec<Option<ArrayD<f64>>>, OpError> {
        assert_eq!(ctx.saved(), &[7.0], "the residuals of `forward`");
        Ok(vec![grads[0].as_ref().map(|g| g.mapv(|g| 2.0 * g))])
    }
}

#[test]
fn an_application_without_a_record_runs_the_outputs_alone_forward() {
    // 1 in the marker output: `forward` ran (its residuals kept); 0: `forward_only` ran.
    let marker = |t: &Tape<f64>, outputs: &[fogray_tape::Var]| t.value(outputs[1]).unwrap()[[0]];
    let mut t = Tape::<f64>::new();
    let x = t.param(arr1(&[1.5, -2.0]));
    let recorded = t.apply(Marked, &[x]).unwrap();
    assert_eq!((marker(&t, &recorded), t.stats().records), (1.0, 1));
    let s = t.sum(recorded[0]).unwrap();
    let g = t.backward(s).unwrap();
    assert_eq!(g.get(x).unwrap().iter().copied().collect::<Vec<_>>(), vec![2.0, 2.0]);

    for (case, outputs) in [
        ("under no_grad", t.no_grad(|t| t.apply(Marked, &[x])).unwrap()),
        ("on a constant", {
            let c = t.constant(arr1(&[1.5, -2.0]));
            t.apply(Marked, &[c]).unwrap()
        }),
        ("on a detached value", {
            let d = t.detach(x).unwrap();
            t.apply(Marked, &[d]).unwrap()
        }),
    ] {
        assert_eq!(marker(&t, &outputs), 0.0, "{case}");
        assert_eq!(
            t.value(outputs[0]).unwrap().iter().copied().collect::<Vec<_>>(),
            vec![3.0, -4.0],
            "{case}"
        );
    }
    // Only the first application (and the sum) left a record.
    assert_eq!(t.stats().records, 2);
}

/// An op that overrides nothing but `forward`: without a record its outputs are `forward`'s.
#[derive(Debug)]
struct Plain;

impl CustomOp<f64> for Plain {
    type Saved = ();
    fn name(&self) -> &'static str {
        "plain"
    }
    fn forward(&self, inputs: &[ArrayViewD<'_, f64>]) -> Result<(Vec<ArrayD<f64>>, ()), OpError> {
        if inputs[0].iter().any(|x| x.is_nan()) {
            return Err(OpError::InvalidArgument("NaN input".into()));
        }
        Ok((vec![inputs[0].mapv(|x| x + 1.0)], ()))
    }
    fn backward(
        &self,
        _ctx: &BackwardCtx<'_, f64, ()>,
        grads: &[Option<ArrayViewD<'_, f64>>],
    ) -> Result<Vec<Option<ArrayD<f64>>>, OpError> {
        Ok(vec![grads[0].as_ref().map(|g| g.to_owned())])
    }
}

#[test]
fn the_default_outputs_alone_forward_is_the_forward_with_its_errors() {
    let mut t = Tape::<f64>::new();
    let x = t.param(arr1(&[1.0, 2.0]));
    let y = t.no_grad(|t| t.apply1(Plain, &[x])).unwrap();
    assert_eq!(t.value(y).unwrap().iter().copied().collect::<Vec<_>>(), vec![2.0, 3.0]);
    let before = t.len();
    let bad = t.constant(arr1(&[f64::NAN]));
    let e = t.no_grad(|t| t.apply1(Plain, &[bad])).unwrap_err();
    assert!(
        e.to_string().contains("plain") && e.to_string().contains("NaN input"),
        "{e}"
    );
    assert_eq!(t.len(), before + 1, "a failed forward pushes nothing");
}
