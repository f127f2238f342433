//! The composite without a tape ([`Composite::evaluate`], [`Composite::vjp`]) and as a
//! [`CustomOp`] of the tape: the only way it meets the tape is the same public interface any
//! user's op goes through.

use std::borrow::Cow;

use fogray_tape::{BackwardCtx, CustomOp, Float, OpError};
use ndarray::{ArrayD, ArrayViewD, IxDyn};

use super::backward::{backward, Upstream, Wanted};
use super::config::{Background, Composite};
use super::forward::{forward, Residuals};
use super::layout::{check_background, check_values, flatten};
use crate::error::CompositeError;

fn array<F: Float>(shape: &[usize], data: Vec<F>) -> Result<ArrayD<F>, CompositeError> {
    ArrayD::from_shape_vec(IxDyn(shape), data).map_err(|e| CompositeError::Shape {
        what: "output",
        expected: format!("{shape:?}"),
        got: e.to_string(),
    })
}

fn flat<'a, F: Float>(g: &'a Option<ArrayViewD<'_, F>>) -> Option<Cow<'a, [F]>> {
    g.as_ref().map(|g| match g.as_slice() {
        Some(s) => Cow::Borrowed(s),
        None => Cow::Owned(g.iter().copied().collect()),
    })
}

impl Composite {
    /// The forward pass without a tape: the outputs in the order of [`Composite::apply`]
    /// (colour, opacity, then depth, weights, transmittance as configured) and the residuals
    /// that [`Composite::vjp`] needs.
    ///
    /// `inputs` are sigma `[n]`, delta `[n]`, color `[n, ch]`, then the background unless
    /// [`Background::None`], then t with depth. Errors name the ray and sample at fault.
    pub fn evaluate<F: Float>(
        &self,
        inputs: &[ArrayViewD<'_, F>],
    ) -> Result<(Vec<ArrayD<F>>, Residuals<F>), CompositeError> {
        let x = flatten(self, inputs)?;
        check_background(&x)?;
        let (mut fwd, valid) = forward(self, &x);
        if !valid {
            // Find and name the first offending value; no output is returned.
            check_values(self, &x)?;
        }
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
            outs.push(array(&[n], std::mem::take(&mut fwd.transmittance))?);
        }
        Ok((outs, fwd))
    }

    /// The backward pass without a tape: gradients of the inputs (in the order of
    /// [`Composite::evaluate`]) from upstream gradients of the outputs (`None` for an unused
    /// output), for the inputs whose `needs` entry is true.
    ///
    /// `inputs` and `residuals` must be those of the matching [`Composite::evaluate`] call;
    /// shapes are checked, values are not checked again.
    pub fn vjp<F: Float>(
        &self,
        inputs: &[ArrayViewD<'_, F>],
        residuals: &Residuals<F>,
        grads: &[Option<ArrayViewD<'_, F>>],
        needs: &[bool],
    ) -> Result<Vec<Option<ArrayD<F>>>, CompositeError> {
        let x = flatten(self, inputs)?;
        let outputs = 2 + usize::from(self.depth) + usize::from(self.weights) + usize::from(self.transmittance);
        let (n, rays, ch) = (self.samples(), self.rays(), x.ch);
        if grads.len() != outputs || needs.len() != inputs.len() || residuals.stop.len() != rays {
            return Err(CompositeError::Shape {
                what: "vjp arguments",
                expected: format!(
                    "{outputs} upstream gradients, {} needs, residuals of {rays} rays",
                    inputs.len()
                ),
                got: format!(
                    "{} gradients, {} needs, residuals of {} rays",
                    grads.len(),
                    needs.len(),
                    residuals.stop.len()
                ),
            });
        }
        let mut slot = 2..grads.len();
        let mut next = |on: bool| if on { slot.next() } else { None };
        let (depth_at, weights_at, trans_at) = (next(self.depth), next(self.weights), next(self.transmittance));
        let (gc, go) = (flat(&grads[0]), flat(&grads[1]));
        let pick = |at: Option<usize>| at.and_then(|i| flat(&grads[i]));
        let (gd, gw, gt) = (pick(depth_at), pick(weights_at), pick(trans_at));
        let expect = [
            (gc.as_deref(), rays * ch),
            (go.as_deref(), rays),
            (gd.as_deref(), rays),
            (gw.as_deref(), n),
            (gt.as_deref(), n),
        ];
        if let Some((g, len)) = expect.iter().find(|(g, len)| g.is_some_and(|g| g.len() != *len)) {
            return Err(CompositeError::Shape {
                what: "upstream gradient",
                expected: format!("{len} values"),
                got: format!("{}", g.map_or(0, <[F]>::len)),
            });
        }
        let has_bg = self.background != Background::None;
        let bg_at = 3;
        let t_at = 3 + usize::from(has_bg);
        let want = Wanted {
            sigma: needs[0],
            delta: needs[1],
            color: needs[2] && gc.is_some(),
            background: has_bg && needs[bg_at] && gc.is_some(),
            t: self.depth && needs[t_at] && gd.is_some(),
        };
        let upstream = Upstream {
            color: gc.as_deref(),
            opacity: go.as_deref(),
            depth: gd.as_deref(),
            weights: gw.as_deref(),
            transmittance: gt.as_deref(),
        };
        let g = backward(self, &x, residuals, &upstream, want);
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
}

fn op_error(e: CompositeError) -> OpError {
    OpError::InvalidArgument(e.to_string())
}

impl<F: Float> CustomOp<F> for Composite {
    /// The stop index of each ray; the backward recomputes `T_k` and `alpha_k` from the
    /// inputs the tape keeps anyway.
    type Saved = Residuals<F>;

    fn name(&self) -> &'static str {
        "composite"
    }

    fn forward(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<(Vec<ArrayD<F>>, Residuals<F>), OpError> {
        self.evaluate(inputs).map_err(op_error)
    }

    fn backward(
        &self,
        ctx: &BackwardCtx<'_, F, Residuals<F>>,
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
        let inputs: Vec<ArrayViewD<'_, F>> = (0..ctx.num_inputs()).map(|i| ctx.input(i)).collect();
        let needs: Vec<bool> = (0..inputs.len()).map(|i| ctx.needs_input_grad(i)).collect();
        self.vjp(&inputs, ctx.saved(), grads, &needs).map_err(op_error)
    }

    fn saved_bytes(&self, saved: &Residuals<F>) -> usize {
        saved.stop.len() * std::mem::size_of::<usize>()
    }
}
