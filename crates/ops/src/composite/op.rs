//! The composite as a [`CustomOp`] of the tape: the only way it meets the tape is the same
//! public interface any user's op goes through.

use std::borrow::Cow;

use fogray_tape::{BackwardCtx, CustomOp, Float, OpError};
use ndarray::{ArrayD, ArrayViewD, IxDyn};

use super::backward::{backward, Upstream, Wanted};
use super::config::{Background, Composite};
use super::forward::{forward, Residuals};
use super::layout::validate;

fn array<F: Float>(shape: &[usize], data: Vec<F>) -> Result<ArrayD<F>, OpError> {
    ArrayD::from_shape_vec(IxDyn(shape), data).map_err(|e| OpError::InvalidArgument(e.to_string()))
}

fn flat<'a, F: Float>(g: &'a Option<ArrayViewD<'_, F>>) -> Option<Cow<'a, [F]>> {
    g.as_ref().map(|g| match g.as_slice() {
        Some(s) => Cow::Borrowed(s),
        None => Cow::Owned(g.iter().copied().collect()),
    })
}

impl<F: Float> CustomOp<F> for Composite {
    /// `T_k`, `alpha_k`, `T_end` and the stop index of each ray: the backward is one pass
    /// with no exponential recomputed.
    type Saved = Residuals<F>;

    fn name(&self) -> &'static str {
        "composite"
    }

    fn forward(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<(Vec<ArrayD<F>>, Residuals<F>), OpError> {
        let x = validate(self, inputs).map_err(|e| OpError::InvalidArgument(e.to_string()))?;
        let mut fwd = forward(self, &x);
        let (n, rays) = (self.samples(), self.rays());
        let mut outs = vec![
            array(&[rays, x.ch], std::mem::take(&mut fwd.color))?,
            array(&[rays], std::mem::take(&mut fwd.opacity))?,
        ];
        if self.depth {
            outs.push(array(&[rays], std::mem::take(&mut fwd.depth))?);
        }
        if self.weights {
            outs.push(array(&[n], std::mem::take(&mut fwd.weights))?);
        }
        if self.transmittance {
            outs.push(array(&[n], fwd.transmittance.clone())?);
        }
        Ok((outs, fwd))
    }

    fn backward(
        &self,
        ctx: &BackwardCtx<'_, F, Residuals<F>>,
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
        let inputs: Vec<ArrayViewD<'_, F>> = (0..ctx.num_inputs()).map(|i| ctx.input(i)).collect();
        let x = validate(self, &inputs).map_err(|e| OpError::InvalidArgument(e.to_string()))?;
        let mut slot = 2..grads.len();
        let mut next = |on: bool| if on { slot.next() } else { None };
        let (depth_at, weights_at, trans_at) = (next(self.depth), next(self.weights), next(self.transmittance));
        let (gc, go) = (flat(&grads[0]), flat(&grads[1]));
        let pick = |at: Option<usize>| at.and_then(|i| flat(&grads[i]));
        let (gd, gw, gt) = (pick(depth_at), pick(weights_at), pick(trans_at));
        let has_bg = self.background != Background::None;
        let bg_at = 3;
        let t_at = 3 + usize::from(has_bg);
        let want = Wanted {
            sigma: ctx.needs_input_grad(0),
            delta: ctx.needs_input_grad(1),
            color: ctx.needs_input_grad(2) && gc.is_some(),
            background: has_bg && ctx.needs_input_grad(bg_at) && gc.is_some(),
            t: self.depth && ctx.needs_input_grad(t_at) && gd.is_some(),
        };
        let upstream = Upstream {
            color: gc.as_deref(),
            opacity: go.as_deref(),
            depth: gd.as_deref(),
            weights: gw.as_deref(),
            transmittance: gt.as_deref(),
        };
        let g = backward(self, &x, ctx.saved(), &upstream, want);
        let (n, rays, ch) = (self.samples(), self.rays(), x.ch);
        let mut out: Vec<Option<ArrayD<F>>> = vec![
            want.sigma.then(|| array(&[n], g.sigma)).transpose()?,
            want.delta.then(|| array(&[n], g.delta)).transpose()?,
            want.color.then(|| array(&[n, ch], g.color)).transpose()?,
        ];
        if has_bg {
            let bg = match self.background {
                Background::PerRay => want.background.then(|| array(&[rays, ch], g.background)).transpose()?,
                _ => want
                    .background
                    .then(|| {
                        // Summed in ray order, so the result does not depend on the thread count.
                        let mut total = vec![0.0f64; ch];
                        for row in g.background.chunks_exact(ch) {
                            for (t, &v) in total.iter_mut().zip(row) {
                                *t += v.as_f64();
                            }
                        }
                        array(&[ch], total.into_iter().map(F::lit).collect())
                    })
                    .transpose()?,
            };
            out.push(bg);
        }
        if self.depth {
            out.push(want.t.then(|| array(&[n], g.t)).transpose()?);
        }
        Ok(out)
    }

    fn saved_bytes(&self, saved: &Residuals<F>) -> usize {
        let floats = saved.transmittance.len() + saved.alpha.len() + saved.t_end.len();
        floats * std::mem::size_of::<F>() + saved.stop.len() * std::mem::size_of::<usize>()
    }
}
