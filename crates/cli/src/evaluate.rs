//! Runs a packed input through the fused op or a taped twin, in f32 or f64.

use fogray_ops::{twins, Background, Composite, CompositeInputs};
use fogray_tape::{Float, Tape};
use ndarray::{Array1, Array2};

use super::error::{CliError, InputError};
use super::input::Packed;

/// Which implementation of the composite.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum CompositeMethod {
    /// The fused op with its hand-written backward.
    Fused,
    /// The stable taped twin (exclusive cumsum of optical depth, exp, expm1).
    Taped,
    /// The naive taped twin (cumulative product of 1 - alpha).
    TapedNaive,
}

/// Gradients of `L = sum(grad_color * C) + sum(grad_depth * depth)`.
#[derive(Debug, Clone)]
pub struct InputGrads<F> {
    pub sigma: Vec<F>,
    pub delta: Vec<F>,
    /// `[n * ch]`.
    pub color: Vec<F>,
    /// `[R * ch]`.
    pub background: Vec<F>,
    /// `[n]`, when the input has `t`.
    pub t: Option<Vec<F>>,
}

/// The upstream gradients of a loss `L = sum(color * C) + sum(depth * D)`.
#[derive(Debug, Clone, Copy)]
pub struct Upstream<'a> {
    /// `dL/dC`, `[R * ch]`.
    pub color: &'a [f64],
    /// `dL/dD`, `[R]` (needs the input's `t`); `None` for no depth term.
    pub depth: Option<&'a [f64]>,
}

/// Which outputs to compute beyond colour, opacity and (with `t`) depth.
#[derive(Debug, Clone, Copy)]
pub struct Wanted<'a> {
    /// Weights and transmittance per sample.
    pub per_sample: bool,
    /// The input gradients for these upstream gradients.
    pub grads: Option<Upstream<'a>>,
}

/// Every output of one evaluation, flat.
#[derive(Debug, Clone)]
pub struct Evaluation<F> {
    /// `[R * ch]`.
    pub color: Vec<F>,
    pub opacity: Vec<F>,
    pub depth: Option<Vec<F>>,
    pub weights: Option<Vec<F>>,
    pub transmittance: Option<Vec<F>>,
    pub grads: Option<InputGrads<F>>,
}

fn cast<F: Float>(v: &[f64]) -> Vec<F> {
    v.iter().map(|&x| F::lit(x)).collect()
}

fn flat<F: Float>(v: ndarray::ArrayViewD<'_, F>) -> Vec<F> {
    v.iter().copied().collect()
}

/// Evaluates `p` with `method` in precision `F`, the outputs and gradients `want` asks for.
pub fn evaluate<F: Float>(p: &Packed, method: CompositeMethod, want: Wanted<'_>) -> Result<Evaluation<F>, CliError> {
    let (n, rays, ch) = (p.sigma.len(), p.offsets.len() - 1, p.ch);
    let mut tape = Tape::<F>::new();
    let sigma = tape.param(Array1::from(cast::<F>(&p.sigma)));
    let delta = tape.param(Array1::from(cast::<F>(&p.delta)));
    let color = tape.param(Array2::from_shape_vec((n, ch), cast::<F>(&p.color))?);
    let background = tape.param(Array2::from_shape_vec((rays, ch), cast::<F>(&p.background))?);
    let t = p.t.as_ref().map(|t| tape.param(Array1::from(cast::<F>(t))));
    let mut op = Composite::new(&p.offsets)?
        .background(Background::PerRay)
        .min_transmittance(p.min_transmittance)?;
    if want.per_sample {
        op = op.with_weights().with_transmittance();
    }
    if t.is_some() {
        op = op.with_depth();
    }
    if method != CompositeMethod::Fused && p.min_transmittance != 0.0 {
        return Err(InputError::MinTransmittanceNotFused.into());
    }
    let inputs = CompositeInputs {
        sigma,
        delta,
        color,
        background: Some(background),
        t,
    };
    let out = match method {
        CompositeMethod::Fused => op.apply(&mut tape, &inputs),
        CompositeMethod::Taped => twins::stable(&mut tape, &op, &inputs),
        CompositeMethod::TapedNaive => twins::naive(&mut tape, &op, &inputs),
    }?;
    let grads = match want.grads {
        None => None,
        Some(up) => {
            let array = |v: &[f64], shape: Vec<usize>| ndarray::ArrayD::from_shape_vec(shape, cast::<F>(v));
            let seed = array(up.color, vec![rays, ch])?;
            let g = match (up.depth, out.depth) {
                (Some(gd), Some(depth)) => {
                    // L = sum(gC * C) + sum(gD * D) (the same gradients as two seeded sweeps).
                    let gc = tape.constant(seed);
                    let gd = tape.constant(array(gd, vec![rays])?);
                    let loss = (|| {
                        let wc = tape.mul(out.color, gc)?;
                        let wd = tape.mul(depth, gd)?;
                        let (lc, ld) = (tape.sum(wc)?, tape.sum(wd)?);
                        let l = tape.add(lc, ld)?;
                        tape.backward(l)
                    })();
                    loss?
                }
                _ => tape.backward_with(out.color, seed)?,
            };
            let grad = |v| g.get_or_zeros(&tape, v).map(|a| flat(a.view()));
            Some(InputGrads {
                sigma: grad(sigma)?,
                delta: grad(delta)?,
                color: grad(color)?,
                background: grad(background)?,
                t: t.map(grad).transpose()?,
            })
        }
    };
    let value = |v| tape.value(v).map(flat);
    Ok(Evaluation {
        color: value(out.color)?,
        opacity: value(out.opacity)?,
        depth: out.depth.map(value).transpose()?,
        weights: out.weights.map(value).transpose()?,
        transmittance: out.transmittance.map(value).transpose()?,
        grads,
    })
}
