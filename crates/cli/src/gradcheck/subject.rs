//! The function `fogray gradcheck` differences and the gradient it checks, as one op on an f64
//! tape: the fused composite's forward in f64 (finite differences need f64), its backward in
//! the input's precision `S` at the same inputs (the gradient a user of that precision gets).

use std::marker::PhantomData;

use fogray_ops::{Composite, CompositeArrays, CompositeUpstream, CompositeWanted};
use fogray_tape::{BackwardCtx, CustomOp, Float, OpError, Tape, TapeError, Var};
use ndarray::{ArrayD, ArrayViewD};

/// The fused composite with its backward computed in precision `S`.
#[derive(Debug, Clone)]
pub struct Subject<S> {
    op: Composite,
    precision: PhantomData<fn() -> S>,
}

/// The composite's own error, whole: a caller reads it back typed through the tape.
fn op_error(e: fogray_ops::OpsError) -> OpError {
    OpError::typed(e)
}

fn cast<A: Float, B: Float>(x: &ArrayViewD<'_, A>) -> ArrayD<B> {
    x.mapv(|v| B::lit(v.as_f64()))
}

/// The subject's tape inputs by name: sigma, delta, colour, the per-ray background, then t
/// when the op has depth.
fn named<'a, T>(xs: &[ArrayViewD<'a, T>]) -> Result<CompositeArrays<'a, T>, OpError> {
    let [sigma, delta, color, background, rest @ ..] = xs else {
        return Err(OpError::InvalidArgument(format!(
            "takes sigma, delta, colour, background (and t), got {} inputs",
            xs.len()
        )));
    };
    let arrays = CompositeArrays::new(sigma.clone(), delta.clone(), color.clone()).with_background(background.clone());
    Ok(match rest {
        [] => arrays,
        [t] => arrays.with_t(t.clone()),
        _ => return Err(OpError::InvalidArgument(format!("too many inputs: {}", xs.len()))),
    })
}

impl<S: Float> CustomOp<f64> for Subject<S> {
    type Saved = ();

    fn name(&self) -> &'static str {
        "composite_under_check"
    }

    /// The outputs colour, opacity, then the depth when the op has it (no weights nor
    /// transmittance: [`loss`] does not read them).
    fn forward(&self, inputs: &[ArrayViewD<'_, f64>]) -> Result<(Vec<ArrayD<f64>>, ()), OpError> {
        let (outs, _) = self.op.evaluate(&named(inputs)?).map_err(op_error)?;
        let outs = [Some(outs.color), Some(outs.opacity), outs.depth]
            .into_iter()
            .flatten()
            .collect();
        Ok((outs, ()))
    }

    fn backward(
        &self,
        ctx: &BackwardCtx<'_, f64, ()>,
        grads: &[Option<ArrayViewD<'_, f64>>],
    ) -> Result<Vec<Option<ArrayD<f64>>>, OpError> {
        let xs: Vec<ArrayD<S>> = (0..ctx.num_inputs()).map(|i| cast(&ctx.input(i))).collect();
        let views: Vec<ArrayViewD<'_, S>> = xs.iter().map(ArrayD::view).collect();
        let inputs = named(&views)?;
        let (_, residuals) = self.op.evaluate(&inputs).map_err(op_error)?;
        let ups: Vec<Option<ArrayD<S>>> = grads.iter().map(|g| g.as_ref().map(cast)).collect();
        let up = |k: usize| ups.get(k).and_then(|g| g.as_ref().map(ArrayD::view));
        let upstream = CompositeUpstream {
            color: up(0),
            opacity: up(1),
            depth: up(2),
            ..Default::default()
        };
        let with_t = inputs.t.is_some();
        let wanted = CompositeWanted {
            sigma: ctx.needs_input_grad(0),
            delta: ctx.needs_input_grad(1),
            color: ctx.needs_input_grad(2),
            background: ctx.needs_input_grad(3),
            t: with_t && ctx.needs_input_grad(4),
        };
        let g = self.op.vjp(&inputs, &residuals, &upstream, wanted).map_err(op_error)?;
        let back = |g: Option<ArrayD<S>>| g.map(|g| cast(&g.view()));
        let mut out = vec![back(g.sigma), back(g.delta), back(g.color), back(g.background)];
        if with_t {
            out.push(back(g.t));
        }
        Ok(out)
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

#[cfg(test)]
mod tests {
    use super::*;
    use fogray_ops::{Op, OpsError};
    use ndarray::arr1;

    /// A negative density is the composite's error, readable whole through the tape (it was
    /// once flattened into a string).
    #[test]
    fn the_composites_error_comes_back_typed() {
        let mut tape = Tape::<f64>::new();
        let v = [
            tape.param(arr1(&[0.5, -1.0]).into_dyn()),
            tape.param(arr1(&[0.1, 0.1]).into_dyn()),
            tape.param(ndarray::Array2::from_elem((2, 3), 0.5).into_dyn()),
            tape.param(ndarray::Array2::from_elem((1, 3), 1.0).into_dyn()),
        ];
        let op = Composite::packed(fogray_tape::Offsets::new(&[0, 2]).unwrap());
        let color = ndarray::Array2::from_elem((1, 3), 1.0).into_dyn();
        let err = loss::<f64>(&mut tape, &v, &op, &color, None).unwrap_err();
        let typed = err
            .downcast_ref::<OpsError>()
            .unwrap_or_else(|| panic!("untyped: {err}"));
        assert_eq!(typed.op(), Op::Composite);
    }
}
