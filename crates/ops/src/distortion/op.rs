//! The op without a tape ([`DistortionLoss::evaluate`], [`DistortionLoss::evaluate_rays`],
//! [`DistortionLoss::vjp`]) and as a [`CustomOp`] of the tape, met through the same public
//! interface as any user's op.

use std::borrow::Cow;

use fogray_tape::buffer::{flat, scratch};
use fogray_tape::{BackwardCtx, CustomOp, Float, OpError};
use ndarray::{Array1, ArrayD, ArrayView1, ArrayViewD, IxDyn};

use super::check::{check_shapes, check_values};
use super::config::DistortionLoss;
use super::kernel;
use crate::error::{Op, OpsError};

/// The three inputs, flat and checked.
struct Checked<'a, F: Float> {
    sigma: Cow<'a, [F]>,
    delta: Cow<'a, [F]>,
    t: Cow<'a, [F]>,
}

impl DistortionLoss {
    /// Checks the inputs' shapes only and returns them flat (the backward's inputs are the
    /// forward's, already checked).
    fn flatten<'a, F: Float>(
        &self,
        sigma: &'a ArrayViewD<'_, F>,
        delta: &'a ArrayViewD<'_, F>,
        t: &'a ArrayViewD<'_, F>,
    ) -> Result<Checked<'a, F>, OpsError> {
        check_shapes(
            &self.offsets,
            [("sigma", sigma.shape()), ("delta", delta.shape()), ("t", t.shape())],
        )?;
        Ok(Checked {
            sigma: flat(sigma),
            delta: flat(delta),
            t: flat(t),
        })
    }

    /// Checks the inputs (shapes, then values) and returns them flat.
    fn check<'a, F: Float>(
        &self,
        sigma: &'a ArrayViewD<'_, F>,
        delta: &'a ArrayViewD<'_, F>,
        t: &'a ArrayViewD<'_, F>,
    ) -> Result<Checked<'a, F>, OpsError> {
        let x = self.flatten(sigma, delta, t)?;
        check_values(&self.offsets, &x.sigma, &x.delta, &x.t)?;
        Ok(x)
    }

    /// The loss of `sigma`, `delta` and `t` (each `[n]`): the mean over the rays of `L_r`
    /// (see the [module docs](super)), computed in f64 and rounded once; 0 for no ray.
    ///
    /// Errors: an input not `[n]` ([`OpsError::Shape`]); a density that is negative,
    /// NaN or infinite, a step that is not finite and positive, a midpoint that is not finite
    /// or is below the previous one of its ray ([`OpsError::Domain`], naming the
    /// first ray and sample at fault).
    pub fn evaluate<F: Float>(
        &self,
        sigma: ArrayView1<'_, F>,
        delta: ArrayView1<'_, F>,
        t: ArrayView1<'_, F>,
    ) -> Result<F, OpsError> {
        let (sigma, delta, t) = (sigma.into_dyn(), delta.into_dyn(), t.into_dyn());
        let x = self.check(&sigma, &delta, &t)?;
        Ok(F::lit(kernel::mean_loss(&self.offsets, &x.sigma, &x.delta, &x.t)))
    }

    /// Each ray's loss `L_r` (`[R]`, 0 for an empty ray), each computed in f64 and rounded
    /// once; [`DistortionLoss::evaluate`] is their mean (taken in f64 before rounding).
    ///
    /// Errors: as [`DistortionLoss::evaluate`].
    pub fn evaluate_rays<F: Float>(
        &self,
        sigma: ArrayView1<'_, F>,
        delta: ArrayView1<'_, F>,
        t: ArrayView1<'_, F>,
    ) -> Result<Array1<F>, OpsError> {
        let (sigma, delta, t) = (sigma.into_dyn(), delta.into_dyn(), t.into_dyn());
        let x = self.check(&sigma, &delta, &t)?;
        let mut losses = vec![0.0; self.rays()];
        kernel::ray_losses(&self.offsets, &x.sigma, &x.delta, &x.t, &mut losses);
        Ok(losses.into_iter().map(F::lit).collect())
    }

    /// The gradient `dL/dsigma` (`[n]`) of a loss `L` that reads this op's value, given
    /// `upstream = dL/d(value)`, in closed form (see the [module docs](super)); `delta` and `t`
    /// get none.
    ///
    /// Errors: as [`DistortionLoss::evaluate`].
    pub fn vjp<F: Float>(
        &self,
        sigma: ArrayView1<'_, F>,
        delta: ArrayView1<'_, F>,
        t: ArrayView1<'_, F>,
        upstream: F,
    ) -> Result<Array1<F>, OpsError> {
        let (sigma, delta, t) = (sigma.into_dyn(), delta.into_dyn(), t.into_dyn());
        let x = self.check(&sigma, &delta, &t)?;
        Ok(Array1::from_vec(self.backward_flat(&x, upstream.as_f64())))
    }

    /// The backward on checked flat input.
    fn backward_flat<F: Float>(&self, x: &Checked<'_, F>, upstream: f64) -> Vec<F> {
        // The kernel writes every value of every ray: no zeros first.
        let mut g = scratch(x.sigma.len());
        kernel::backward(&self.offsets, &x.sigma, &x.delta, &x.t, upstream, &mut g);
        g
    }
}

/// The op's three inputs, `[sigma, delta, t]`.
fn three<'i, 'a, F: Float>(inputs: &'i [ArrayViewD<'a, F>]) -> Result<&'i [ArrayViewD<'a, F>; 3], OpError> {
    inputs
        .try_into()
        .map_err(|_| OpError::InvalidArgument(format!("takes 3 inputs (sigma, delta, t), got {}", inputs.len())))
}

impl<F: Float> CustomOp<F> for DistortionLoss {
    /// Nothing: the backward recomputes the weights and the sums from the inputs, so that its
    /// gradient is bitwise that of [`DistortionLoss::vjp`].
    type Saved = ();

    fn name(&self) -> &'static str {
        Op::DistortionLoss.name()
    }

    fn forward(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<(Vec<ArrayD<F>>, ()), OpError> {
        let [sigma, delta, t] = three(inputs)?;
        let x = self.check(sigma, delta, t)?;
        let loss = F::lit(kernel::mean_loss(&self.offsets, &x.sigma, &x.delta, &x.t));
        Ok((vec![ArrayD::from_elem(IxDyn(&[]), loss)], ()))
    }

    fn backward(
        &self,
        ctx: &BackwardCtx<'_, F, ()>,
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
        // No gradient for delta and t: they are constants of the op.
        let Some(g) = grads.first().and_then(Option::as_ref) else {
            return Ok(vec![None, None, None]);
        };
        if !ctx.needs_input_grad(0) {
            return Ok(vec![None, None, None]);
        }
        let upstream = match g.ndim() {
            0 => g.iter().next().map_or(0.0, |v| v.as_f64()),
            _ => {
                return Err(OpError::from(OpsError::shape_of(
                    Op::DistortionLoss,
                    "loss gradient",
                    "[] (a 0-d value)",
                    g.shape(),
                )))
            }
        };
        let (sigma, delta, t) = (ctx.input(0), ctx.input(1), ctx.input(2));
        // The inputs were checked by the forward: only flattened again here.
        let x = self.flatten(&sigma, &delta, &t)?;
        let g = self.backward_flat(&x, upstream);
        let g = ArrayD::from_shape_vec(IxDyn(sigma.shape()), g).map_err(|e| OpError::InvalidArgument(e.to_string()))?;
        Ok(vec![Some(g), None, None])
    }
}
