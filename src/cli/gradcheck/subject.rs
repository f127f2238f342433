//! The function `fogray gradcheck` differences and the gradient it checks, as one op on an f64
//! tape: the fused composite's forward in f64 (finite differences need f64), its backward in
//! the input's precision `S` at the same inputs (the gradient a user of that precision gets).

use std::marker::PhantomData;

use fogray_ops::Composite;
use fogray_tape::{BackwardCtx, CustomOp, Float, OpError, Tape, TapeError, Var};
use ndarray::{ArrayD, ArrayViewD};

/// The fused composite with its backward computed in precision `S`.
#[derive(Debug, Clone)]
pub struct Subject<S> {
    op: Composite,
    precision: PhantomData<fn() -> S>,
}

fn op_error(e: fogray_ops::CompositeError) -> OpError {
    OpError::InvalidArgument(e.to_string())
}

fn cast<A: Float, B: Float>(x: &ArrayViewD<'_, A>) -> ArrayD<B> {
    x.mapv(|v| B::lit(v.as_f64()))
}

impl<S: Float> CustomOp<f64> for Subject<S> {
    type Saved = ();

    fn name(&self) -> &'static str {
        "composite_under_check"
    }

    fn forward(&self, inputs: &[ArrayViewD<'_, f64>]) -> Result<(Vec<ArrayD<f64>>, ()), OpError> {
        let (outs, _) = self.op.evaluate(inputs).map_err(op_error)?;
        Ok((outs, ()))
    }

    fn backward(
        &self,
        ctx: &BackwardCtx<'_, f64, ()>,
        grads: &[Option<ArrayViewD<'_, f64>>],
    ) -> Result<Vec<Option<ArrayD<f64>>>, OpError> {
        let xs: Vec<ArrayD<S>> = (0..ctx.num_inputs()).map(|i| cast(&ctx.input(i))).collect();
        let views: Vec<ArrayViewD<'_, S>> = xs.iter().map(ArrayD::view).collect();
        let (_, residuals) = self.op.evaluate(&views).map_err(op_error)?;
        let ups: Vec<Option<ArrayD<S>>> = grads.iter().map(|g| g.as_ref().map(cast)).collect();
        let up_views: Vec<Option<ArrayViewD<'_, S>>> = ups.iter().map(|g| g.as_ref().map(ArrayD::view)).collect();
        let needs: Vec<bool> = (0..xs.len()).map(|i| ctx.needs_input_grad(i)).collect();
        let g = self.op.vjp(&views, &residuals, &up_views, &needs).map_err(op_error)?;
        Ok(g.into_iter().map(|g| g.map(|g| cast(&g.view()))).collect())
    }
}

/// `L = sum(gC * C) + sum(gD * D)` of [`Subject`] on `tape`, with `v` = sigma, delta, colour,
/// per-ray background and (when `depth` is given) t. `op` must output colour, opacity and,
/// with `depth`, the depth.
pub fn loss<S: Float>(
    tape: &mut Tape<f64>,
    v: &[Var],
    op: &Composite,
    color: &ArrayD<f64>,
    depth: Option<&ArrayD<f64>>,
) -> Result<Var, TapeError> {
    let subject = Subject::<S> {
        op: op.clone(),
        precision: PhantomData,
    };
    let outs = tape.apply(subject, v)?;
    let gc = tape.constant(color.clone());
    let wc = tape.mul(outs[0], gc)?;
    let mut l = tape.sum(wc)?;
    if let Some(depth) = depth {
        let gd = tape.constant(depth.clone());
        let wd = tape.mul(outs[2], gd)?;
        let ld = tape.sum(wd)?;
        l = tape.add(l, ld)?;
    }
    Ok(l)
}
