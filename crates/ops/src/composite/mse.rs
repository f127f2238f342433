//! The composite and a mean squared error against target colours as one op of the tape
//! ([`Composite::apply_mse`]): a training step's render and photometric loss, whose forward
//! already computes the input gradients in one pass per ray
//! ([`Composite::evaluate_vjp_into`]) and whose backward hands them over.
//!
//! The numbers are those of the composite followed by the tape's `sub`, `square` and `mean`,
//! bit for bit: the loss is summed by the same reduction, and `dL/dC = (1/m) (x + x)` with
//! `x = C - target` and `m` the number of colour values is what the three ops' backwards
//! produce for an upstream gradient of 1. The gradients made in the forward are for that
//! upstream gradient: the loss backpropagated directly or through sums (a prior added to it).
//! Any other upstream gradient, or a second backward sweep over the same tape, recomputes them
//! through the two calls with the chain's own `dL/dC`, which gives the chain's bits again.

use std::sync::Mutex;

use fogray_tape::buffer::{flat, scratch};
use fogray_tape::{BackwardCtx, CustomOp, Float, OpError, Tape, TapeError, Var};
use ndarray::{ArrayD, ArrayViewD, IxDyn, Zip};

use super::arrays::{CompositeArrays, CompositeOutputBuffers};
use super::config::{Composite, CompositeInputs};
use super::gradients::{CompositeGradients, CompositeUpstream, CompositeWanted};
use super::tape_order::{self, ByInput};
use crate::error::{Op, OpsError};

/// The op on the tape: the composite, and the gradients its forward computes.
#[derive(Debug, Clone)]
struct CompositeMse {
    composite: Composite,
    wanted: CompositeWanted,
}

/// What the backward reads: the forward's gradients until a backward takes them, and the
/// residuals `C - target` (`[R, ch]`), from which any upstream gradient's `dL/dC` follows.
#[derive(Debug)]
pub(crate) struct MseResiduals<F> {
    gradients: Mutex<Option<CompositeGradients<F>>>,
    residual: ArrayD<F>,
}

/// The composite's checks, run by this op, report this op: its name is the one the tape gives.
fn in_mse(e: OpsError) -> OpError {
    e.in_op(Op::CompositeMse).into()
}

fn config_error(reason: &str) -> TapeError {
    TapeError::InvalidArgument {
        op: "composite_mse",
        reason: reason.into(),
    }
}

impl Composite {
    /// Records the composite's colour and its mean squared error against `target` (`[R, ch]`)
    /// as one op on `tape`, and returns the loss, a 0-d value:
    /// `L = mean over rays r and channels c of (C[r, c] - target[r, c])^2`.
    ///
    /// The loss and every gradient are bitwise those of [`Composite::apply`] followed by
    /// `tape.sub(color, target)`, `tape.square` and `tape.mean`, for any upstream gradient.
    /// It is faster when the loss is backpropagated with an upstream gradient of exactly 1
    /// (`tape.backward(loss)`, or a sum such as `loss + prior`), once per recording: the
    /// forward then computes the gradients together with the colours, in one pass per ray,
    /// and the backward hands them over. Otherwise the backward recomputes them through the
    /// composite's forward and backward. Without a record (under `no_grad`, or when no input
    /// needs a gradient) it renders and sums alone.
    ///
    /// The op must output colour and opacity alone (no depth, weights or transmittance: the
    /// loss reads the colour only). The inputs are as for [`Composite::apply`].
    ///
    /// Errors: an op with extra outputs, an input missing or superfluous for the
    /// configuration, shapes that do not fit the packing, `target` not `[R, ch]` or empty,
    /// or invalid values (each names the ray and sample); the tape is unchanged.
    ///
    /// ```
    /// use fogray_ops::{Composite, CompositeInputs};
    /// use fogray_tape::Tape;
    /// use ndarray::{arr1, arr2, Array2};
    ///
    /// let op = Composite::new(&[0, 2, 3])?;
    /// let mut tape = Tape::<f64>::new();
    /// let sigma = tape.param(arr1(&[0.5, 2.0, 1.0]));
    /// let inputs = CompositeInputs {
    ///     sigma,
    ///     delta: tape.constant(arr1(&[0.5, 0.5, 0.5])),
    ///     color: tape.constant(Array2::from_elem((3, 3), 0.25)),
    ///     background: Some(tape.constant(arr1(&[1.0, 1.0, 1.0]))),
    ///     t: None,
    /// };
    /// let target = tape.constant(arr2(&[[0.3, 0.3, 0.3], [0.9, 0.9, 0.9]]));
    /// let loss = op.apply_mse(&mut tape, &inputs, target)?;
    /// let fast = tape.backward(loss)?;
    ///
    /// // The same numbers as the chain of four ops.
    /// let color = op.apply(&mut tape, &inputs)?.color;
    /// let error = tape.sub(color, target)?;
    /// let squared = tape.square(error)?;
    /// let chain = tape.mean(squared)?;
    /// assert_eq!(tape.value(loss)?, tape.value(chain)?);
    /// assert_eq!(fast.get(sigma), tape.backward(chain)?.get(sigma));
    /// # Ok::<(), fogray_tape::TapeError>(())
    /// ```
    pub fn apply_mse<F: Float>(
        &self,
        tape: &mut Tape<F>,
        inputs: &CompositeInputs,
        target: Var,
    ) -> Result<Var, TapeError> {
        if self.depth || self.weights || self.transmittance {
            return Err(config_error(
                "the loss reads the colour alone: build the op without depth, weights or transmittance",
            ));
        }
        self.check_tape_inputs("composite_mse", inputs)?;
        let needs = |v: Option<Var>| v.map_or(Ok(false), |v| tape.needs_grad(v));
        let wanted = CompositeWanted {
            sigma: needs(Some(inputs.sigma))?,
            delta: needs(Some(inputs.delta))?,
            color: needs(Some(inputs.color))?,
            background: needs(inputs.background)?,
            t: false,
        };
        let op = CompositeMse {
            composite: self.clone(),
            wanted,
        };
        let mut vars = ByInput {
            sigma: inputs.sigma,
            delta: inputs.delta,
            color: inputs.color,
            background: inputs.background,
            t: None,
        }
        .into_tape();
        vars.push(target);
        tape.apply1(op, &vars)
    }
}

/// `dL/dC` of one colour value with residual `x = C - target`, given `scale = g / m` (the
/// loss's upstream gradient over the number of colour values), as the tape's `mean`, `square`
/// and `sub` backwards make it: `scale (x + x)`, 0 where `scale` is 0 (their strong-zero
/// product).
#[inline(always)]
fn color_gradient<F: Float>(scale: F, x: F) -> F {
    if scale == F::zero() {
        F::zero()
    } else {
        scale * (x + x)
    }
}

/// [`color_gradient`] of every residual for the loss's upstream gradient `g`.
fn color_upstream<F: Float>(residual: &ArrayD<F>, g: F) -> ArrayD<F> {
    let scale = g / F::lit(residual.len() as f64);
    residual.mapv(|x| color_gradient(scale, x))
}

impl CompositeMse {
    /// The composite's inputs, by name, and the target, from the tape's inputs.
    fn split<'a, F: Float>(
        &self,
        inputs: &[ArrayViewD<'a, F>],
    ) -> Result<(CompositeArrays<'a, F>, ArrayViewD<'a, F>), OpError> {
        let Some((target, composite)) = inputs.split_last() else {
            return Err(OpError::InvalidArgument("no inputs".into()));
        };
        let arrays = tape_order::arrays(&self.composite, composite).map_err(in_mse)?;
        let rays = self.composite.rays();
        let ch = arrays.color.shape().get(1).copied().unwrap_or(0);
        if target.shape() != [rays, ch] {
            return Err(OpsError::Shape {
                op: Op::CompositeMse,
                what: "target",
                expected: format!("[{rays}, {ch}] (one colour per ray)"),
                got: format!("{:?}", target.shape()),
            }
            .into());
        }
        if target.is_empty() {
            return Err(OpError::InvalidArgument(
                "the mean squared error of no colour values".into(),
            ));
        }
        Ok((arrays, target.clone()))
    }

    /// `C - target` and the loss, the mean of its squares, summed as the tape's `mean` sums.
    fn loss<F: Float>(color: &ArrayD<F>, target: &ArrayViewD<'_, F>) -> (ArrayD<F>, ArrayD<F>) {
        let residual = Zip::from(color).and(target).map_collect(|&c, &t| c - t);
        let squared = residual.mapv(|x| x * x);
        let loss = squared.sum() / F::lit(squared.len() as f64);
        (residual, ArrayD::from_elem(IxDyn(&[]), loss))
    }

    /// The gradients the tape wants, by recomputing the composite's forward and backward for
    /// the upstream colour gradient `d_color`.
    fn recompute<F: Float>(
        &self,
        arrays: &CompositeArrays<'_, F>,
        d_color: &ArrayD<F>,
    ) -> Result<CompositeGradients<F>, OpsError> {
        let (_, res) = self.composite.evaluate(arrays)?;
        self.composite
            .vjp(arrays, &res, &CompositeUpstream::color(d_color.view()), self.wanted)
    }
}

impl<F: Float> CustomOp<F> for CompositeMse {
    type Saved = MseResiduals<F>;

    fn name(&self) -> &'static str {
        Op::CompositeMse.name()
    }

    fn forward(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<(Vec<ArrayD<F>>, MseResiduals<F>), OpError> {
        let (arrays, target) = self.split(inputs)?;
        let (rays, ch) = (self.composite.rays(), target.shape()[1]);
        let target_values = flat(&target);
        let scale = F::one() / F::lit((rays * ch) as f64);
        let upstream = |ray: usize, c: &[F], d: &mut [F]| {
            for ((d, &c), &t) in d.iter_mut().zip(c).zip(&target_values[ray * ch..(ray + 1) * ch]) {
                *d = color_gradient(scale, c - t);
            }
        };
        // Every value of the outputs and of the wanted gradients is written.
        let buffer = |shape: &[usize]| {
            ArrayD::from_shape_vec(IxDyn(shape), scratch::<F>(shape.iter().product()))
                .map_err(|e| OpError::InvalidArgument(e.to_string()))
        };
        let (mut color, mut opacity) = (buffer(&[rays, ch])?, buffer(&[rays])?);
        let like = |on: bool, x: Option<&ArrayViewD<'_, F>>| match (on, x) {
            (true, Some(x)) => buffer(x.shape()).map(Some),
            _ => Ok(None),
        };
        let w = self.wanted;
        let mut gradients = CompositeGradients {
            sigma: like(w.sigma, Some(&arrays.sigma))?,
            delta: like(w.delta, Some(&arrays.delta))?,
            color: like(w.color, Some(&arrays.color))?,
            background: like(w.background, arrays.background.as_ref())?,
            t: None,
        };
        self.composite
            .evaluate_vjp_into(
                &arrays,
                upstream,
                &mut CompositeOutputBuffers::new(color.view_mut(), opacity.view_mut()),
                &mut gradients.buffers(),
            )
            .map_err(in_mse)?;
        let (residual, loss) = Self::loss(&color, &target);
        let saved = MseResiduals {
            gradients: Mutex::new(Some(gradients)),
            residual,
        };
        Ok((vec![loss], saved))
    }

    /// The loss alone: the composite's forward, no gradients.
    fn forward_only(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<Vec<ArrayD<F>>, OpError> {
        let (arrays, target) = self.split(inputs)?;
        let (outputs, _) = self.composite.evaluate(&arrays).map_err(in_mse)?;
        Ok(vec![Self::loss(&outputs.color, &target).1])
    }

    fn backward(
        &self,
        ctx: &BackwardCtx<'_, F, MseResiduals<F>>,
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
        let n = ctx.num_inputs();
        let Some(Some(&g)) = grads.first().map(|g| g.as_ref().and_then(|g| g.iter().next())) else {
            return Ok(vec![None; n]);
        };
        let saved = ctx.saved();
        let made = if g == F::one() {
            // A poisoned lock only means another sweep panicked; the data is whole either way.
            saved.gradients.lock().unwrap_or_else(|e| e.into_inner()).take()
        } else {
            None
        };
        // dL/dC, computed once if the recomputation or the target's gradient reads it.
        let mut d_color = None;
        let gradients = match made {
            Some(gradients) => gradients,
            None => {
                let d = d_color.insert(color_upstream(&saved.residual, g));
                let inputs: Vec<ArrayViewD<'_, F>> = (0..n).map(|i| ctx.input(i)).collect();
                let (arrays, _) = self.split(&inputs)?;
                self.recompute(&arrays, d).map_err(in_mse)?
            }
        };
        let mut out = tape_order::gradients_in_order(&self.composite, gradients);
        // The target's gradient, as the tape's `sub` gives it: the negated dL/dC.
        out.push(ctx.needs_input_grad(n - 1).then(|| {
            d_color
                .unwrap_or_else(|| color_upstream(&saved.residual, g))
                .mapv(|d| -d)
        }));
        Ok(out)
    }

    fn saved_bytes(&self, saved: &MseResiduals<F>) -> usize {
        let held = saved.gradients.lock().unwrap_or_else(|e| e.into_inner());
        let gradients = held.as_ref().map_or(0, |g| {
            [&g.sigma, &g.delta, &g.color, &g.background]
                .iter()
                .filter_map(|a| a.as_ref())
                .map(ArrayD::len)
                .sum()
        });
        (gradients + saved.residual.len()) * std::mem::size_of::<F>()
    }
}
