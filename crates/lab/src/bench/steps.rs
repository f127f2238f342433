//! The timed steps: the fused op (two calls, into kept buffers, one pass per ray) and the taped
//! twins (fresh or on a reused tape), and one run of each with its outputs and peak memory.

use super::*;

pub(crate) fn to_f64<F: Float>(v: ArrayViewD<'_, F>) -> Vec<f64> {
    v.iter().map(|x| x.as_f64()).collect()
}

/// Colour and dL/dsigma of one run, and its peak extra bytes.
pub(crate) struct Outcome {
    pub(crate) color: Vec<f64>,
    pub(crate) grad_sigma: Vec<f64>,
    pub(crate) peak_extra: usize,
}

pub(crate) fn fused_run<F: Float>(op: &Composite, x: &Typed<F>, mem: &dyn Memory) -> Result<Outcome, LabError> {
    let views = x.views();
    mem.reset();
    let (outs, res) = op.evaluate(&views)?;
    let grads = op.vjp(&views, &res, &x.upstream(), SIGMA_AND_COLOR)?;
    let peak_extra = mem.peak_since_reset();
    let g = grads.sigma.as_ref().ok_or(LabError::Missing("no sigma gradient"))?;
    Ok(Outcome {
        color: to_f64(outs.color.view()),
        grad_sigma: to_f64(g.view()),
        peak_extra,
    })
}

/// The fused op's forward, and with `backward` its gradients for sigma and colour, each call
/// allocating what it returns.
pub fn fused_step<F: Float>(op: &Composite, x: &Typed<F>, backward: bool) -> Result<(), LabError> {
    let views = x.views();
    let (outs, res) = op.evaluate(&views)?;
    if backward {
        let g = op.vjp(&views, &res, &x.upstream(), SIGMA_AND_COLOR)?;
        black_box(g);
    }
    black_box(outs);
    Ok(())
}

/// Output and gradient buffers kept across fused runs (colour, opacity; dL/dsigma, dL/dcolour).
pub struct Buffers<F: Float> {
    color: ArrayD<F>,
    opacity: ArrayD<F>,
    grad_sigma: ArrayD<F>,
    grad_color: ArrayD<F>,
}

impl<F: Float> Buffers<F> {
    /// Zeroed buffers for the outputs and gradients of `x`.
    pub fn new(x: &Typed<F>) -> Self {
        let (n, rays) = (x.sigma.len(), x.grad_color.shape()[0]);
        Buffers {
            color: ArrayD::zeros(vec![rays, CHANNELS]),
            opacity: ArrayD::zeros(vec![rays]),
            grad_sigma: ArrayD::zeros(vec![n]),
            grad_color: ArrayD::zeros(vec![n, CHANNELS]),
        }
    }

    /// The output buffers and the gradient buffers (dL/dsigma, dL/dcolour).
    fn split(&mut self) -> (CompositeOutputBuffers<'_, F>, CompositeGradientBuffers<'_, F>) {
        let outputs = CompositeOutputBuffers::new(self.color.view_mut(), self.opacity.view_mut());
        let gradients = CompositeGradientBuffers {
            sigma: Some(self.grad_sigma.view_mut()),
            color: Some(self.grad_color.view_mut()),
            ..Default::default()
        };
        (outputs, gradients)
    }
}

/// The gradients every fused run asks for.
const SIGMA_AND_COLOR: CompositeWanted = CompositeWanted {
    sigma: true,
    delta: false,
    color: true,
    background: false,
    t: false,
};

/// [`fused_step`] through the `_into` API, forward and backward, into `b`.
pub fn fused_step_into<F: Float>(op: &Composite, x: &Typed<F>, b: &mut Buffers<F>) -> Result<(), LabError> {
    let views = x.views();
    let (mut outputs, mut gradients) = b.split();
    let res = op.evaluate_into(&views, &mut outputs)?;
    op.vjp_into(&views, &res, &x.upstream(), &mut gradients)?;
    black_box(&b.grad_sigma);
    Ok(())
}

/// [`fused_step_into`] in one pass per ray (`evaluate_vjp_into`), the upstream gradient of
/// each ray handed over by the callback.
pub fn fused_step_one_pass<F: Float>(op: &Composite, x: &Typed<F>, b: &mut Buffers<F>) -> Result<(), LabError> {
    let views = x.views();
    let upstream = x
        .grad_color
        .as_slice()
        .ok_or(LabError::Missing("upstream gradient not contiguous"))?;
    let (mut outputs, mut gradients) = b.split();
    op.evaluate_vjp_into(
        &views,
        |r, _, d: &mut [F]| d.copy_from_slice(&upstream[r * d.len()..(r + 1) * d.len()]),
        &mut outputs,
        &mut gradients,
    )?;
    black_box(&b.grad_sigma);
    Ok(())
}

/// Puts the inputs on a new tape (sigma and colour as params): the part of a taped run that is
/// the same for every method, timed separately and subtracted.
pub(crate) fn tape_with_inputs<F: Float>(x: &Typed<F>) -> (Tape<F>, CompositeInputs) {
    let mut tape = Tape::new();
    let inputs = put_inputs(&mut tape, x);
    (tape, inputs)
}

/// The inputs on `tape`: sigma and colour as parameters (gradients wanted), delta and the
/// background as constants.
pub fn put_inputs<F: Float>(tape: &mut Tape<F>, x: &Typed<F>) -> CompositeInputs {
    CompositeInputs {
        sigma: tape.param(x.sigma.clone()),
        delta: tape.constant(x.delta.clone()),
        color: tape.param(x.color.clone()),
        background: Some(tape.constant(x.background.clone())),
        t: None,
    }
}

pub(crate) fn twin<F: Float>(
    tape: &mut Tape<F>,
    op: &Composite,
    inputs: &CompositeInputs,
    naive: bool,
) -> Result<Var, LabError> {
    let out = if naive {
        twins::naive(tape, op, inputs)
    } else {
        twins::stable(tape, op, inputs)
    };
    Ok(out?.color)
}

/// The stable (or with `naive` the naive) taped twin on a new tape, forward and with `backward`
/// its backward from dL/dC.
pub fn taped_step<F: Float>(op: &Composite, x: &Typed<F>, naive: bool, backward: bool) -> Result<(), LabError> {
    let (mut tape, inputs) = tape_with_inputs(x);
    let color = twin(&mut tape, op, &inputs, naive)?;
    if backward {
        let g = tape.backward_with(color, x.grad_color.clone())?;
        black_box(g);
    }
    black_box(tape);
    Ok(())
}

/// [`taped_step`] on one tape kept across runs: cleared first, its gradients handed back to it
/// after use (a training loop's steady state).
pub fn taped_step_reused<F: Float>(
    op: &Composite,
    x: &Typed<F>,
    naive: bool,
    tape: &mut Tape<F>,
) -> Result<(), LabError> {
    tape.clear();
    let inputs = put_inputs(tape, x);
    let color = twin(tape, op, &inputs, naive)?;
    let g = tape.backward_with(color, x.grad_color.clone())?;
    black_box(g.get(inputs.sigma));
    tape.recycle(g);
    Ok(())
}

pub(crate) fn taped_run<F: Float>(
    op: &Composite,
    x: &Typed<F>,
    naive: bool,
    mem: &dyn Memory,
) -> Result<Outcome, LabError> {
    let (mut tape, inputs) = tape_with_inputs(x);
    mem.reset();
    let color = twin(&mut tape, op, &inputs, naive)?;
    let g = tape.backward_with(color, x.grad_color.clone())?;
    let peak_extra = mem.peak_since_reset();
    let gs = g.get(inputs.sigma).ok_or(LabError::Missing("no sigma gradient"))?;
    Ok(Outcome {
        color: to_f64(tape.value(color)?),
        grad_sigma: to_f64(gs),
        peak_extra,
    })
}
