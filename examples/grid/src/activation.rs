//! The model's activations: raw grid values `[n, 4]` to a density `softplus(raw_0 + shift)`
//! `[n]` and a colour `sigmoid(raw_1..4)` `[n, 3]`, as one fused op written through the
//! tape's public [`CustomOp`] interface (the way a user adds an op of their own), and as a
//! taped twin built from the tape's own ops to check it against and to time.
//!
//! Both forms are stable for any finite raw value: `softplus(x) = max(x, 0) + ln_1p(e^-|x|)`
//! and `sigmoid(x) = e^min(x, 0) / (1 + e^-|x|)` never overflow.
//!
//! ```
//! use fogray::tape::Tape;
//! use fogray_grid::activation::Activation;
//! use ndarray::arr2;
//!
//! let mut tape = Tape::<f64>::new();
//! let raw = tape.param(arr2(&[[0.0, 0.0, 50.0, -50.0]]));
//! let out = Activation { shift: 0.0 }.apply(&mut tape, raw)?;
//! assert!((tape.value(out.sigma)?[[0]] - 2f64.ln()).abs() < 1e-15); // softplus(0) = ln 2
//! assert_eq!(tape.value(out.color)?[[0, 0]], 0.5);
//! assert!(tape.value(out.color)?[[0, 2]] < 1e-21);
//! # Ok::<(), fogray::tape::TapeError>(())
//! ```

use fogray::tape::{BackwardCtx, CustomOp, Float, OpError, Tape, TapeError, Var};
use ndarray::{ArrayD, ArrayViewD, IxDyn};
use rayon::prelude::*;

/// Channels of a raw grid value: density, then red, green, blue.
pub const CHANNELS: usize = 4;

/// The activations, with the density's shift (raw 0 means density `softplus(shift)`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Activation {
    /// Added to the raw density before the softplus.
    pub shift: f64,
}

/// The density `[n]` and colour `[n, 3]` on the tape.
#[derive(Debug, Clone, Copy)]
pub struct Activated {
    /// `softplus(raw_0 + shift)`, `[n]`.
    pub sigma: Var,
    /// `sigmoid(raw_1..4)`, `[n, 3]`.
    pub color: Var,
}

/// `ln(1 + e^x)` without overflow.
pub fn softplus(x: f64) -> f64 {
    x.max(0.0) + (-x.abs()).exp().ln_1p()
}

/// `1 / (1 + e^-x)` without overflow.
pub fn sigmoid(x: f64) -> f64 {
    x.min(0.0).exp() / (1.0 + (-x.abs()).exp())
}

fn check_raw(shape: &[usize]) -> Result<usize, OpError> {
    match shape {
        [n, CHANNELS] => Ok(*n),
        _ => Err(OpError::InvalidArgument(format!(
            "raw grid values must be [n, {CHANNELS}], got {shape:?}"
        ))),
    }
}

impl<F: Float> CustomOp<F> for Activation {
    type Saved = ();

    fn name(&self) -> &'static str {
        "activation"
    }

    fn forward(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<(Vec<ArrayD<F>>, ()), OpError> {
        let n = check_raw(inputs[0].shape())?;
        let raw = contiguous(&inputs[0]);
        let (mut sigma, mut color) = (vec![F::zero(); n], vec![F::zero(); 3 * n]);
        sigma
            .par_chunks_mut(CHUNK)
            .zip(color.par_chunks_mut(3 * CHUNK))
            .zip(raw.par_chunks(CHANNELS * CHUNK))
            .for_each(|((s, c), r)| {
                for ((s, c), r) in s.iter_mut().zip(c.chunks_exact_mut(3)).zip(r.chunks_exact(CHANNELS)) {
                    *s = F::lit(softplus(r[0].as_f64() + self.shift));
                    for k in 0..3 {
                        c[k] = F::lit(sigmoid(r[k + 1].as_f64()));
                    }
                }
            });
        let shape =
            |s: &[usize], v| ArrayD::from_shape_vec(IxDyn(s), v).map_err(|e| OpError::InvalidArgument(e.to_string()));
        Ok((vec![shape(&[n], sigma)?, shape(&[n, 3], color)?], ()))
    }

    fn backward(
        &self,
        ctx: &BackwardCtx<'_, F, ()>,
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
        if !ctx.needs_input_grad(0) {
            return Ok(vec![None]);
        }
        let raw_view = ctx.input(0);
        let n = check_raw(raw_view.shape())?;
        let raw = contiguous(&raw_view);
        let color_view = ctx.output(1);
        let color = contiguous(&color_view);
        let g_sigma = grads[0].as_ref().map(contiguous);
        let g_color = grads[1].as_ref().map(contiguous);
        let mut g = vec![F::zero(); CHANNELS * n];
        g.par_chunks_mut(CHANNELS * CHUNK).enumerate().for_each(|(chunk, g)| {
            for (k, g) in g.chunks_exact_mut(CHANNELS).enumerate() {
                let i = chunk * CHUNK + k;
                if let Some(gs) = &g_sigma {
                    // d softplus(x) / dx = sigmoid(x).
                    g[0] = gs[i] * F::lit(sigmoid(raw[CHANNELS * i].as_f64() + self.shift));
                }
                if let Some(gc) = &g_color {
                    // d sigmoid(x) / dx = s (1 - s), from the output s.
                    for c in 0..3 {
                        let s = color[3 * i + c];
                        g[c + 1] = gc[3 * i + c] * s * (F::one() - s);
                    }
                }
            }
        });
        let g =
            ArrayD::from_shape_vec(IxDyn(&[n, CHANNELS]), g).map_err(|e| OpError::InvalidArgument(e.to_string()))?;
        Ok(vec![Some(g)])
    }
}

/// Rows per parallel task.
const CHUNK: usize = 4096;

/// The values in row-major order: borrowed when contiguous, copied otherwise.
fn contiguous<'a, F: Float>(x: &'a ArrayViewD<'_, F>) -> std::borrow::Cow<'a, [F]> {
    match x.as_slice() {
        Some(s) => std::borrow::Cow::Borrowed(s),
        None => std::borrow::Cow::Owned(x.iter().copied().collect()),
    }
}

impl Activation {
    /// Records the fused activation of `raw` (`[n, 4]`) on `tape`.
    ///
    /// Errors: `raw` not `[n, 4]` ([`TapeError`] naming the op), a stale handle.
    pub fn apply<F: Float>(&self, tape: &mut Tape<F>, raw: Var) -> Result<Activated, TapeError> {
        let out = tape.apply(*self, &[raw])?;
        Ok(Activated {
            sigma: out[0],
            color: out[1],
        })
    }

    /// The same activation from the tape's own ops (slice, reshape, add_scalar, softplus,
    /// sigmoid): five records instead of one, each a pass over memory.
    ///
    /// Errors: as [`Activation::apply`].
    pub fn taped<F: Float>(&self, tape: &mut Tape<F>, raw: Var) -> Result<Activated, TapeError> {
        let n = check_raw(tape.shape(raw)?).map_err(|e| TapeError::from_op("activation", e))?;
        let density = tape.slice(raw, 1, 0, 1)?;
        let density = tape.reshape(density, &[n])?;
        let x = tape.add_scalar(density, F::lit(self.shift))?;
        let sigma = tape.softplus(x)?;
        let x = tape.slice(raw, 1, 1, CHANNELS)?;
        let color = tape.sigmoid(x)?;
        Ok(Activated { sigma, color })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fogray::tape::{gradcheck, GradcheckOptions};
    use ndarray::Array2;

    fn raw() -> ArrayD<f64> {
        Array2::from_shape_fn((5, 4), |(i, c)| (i as f64 - 2.0) * 1.7 + c as f64 * 0.3 - 0.4).into_dyn()
    }

    #[test]
    fn stable_forms_match_the_definitions_and_survive_extremes() {
        for x in [-30.0, -2.0, -0.1, 0.0, 0.7, 5.0, 30.0] {
            assert!((softplus(x) - (1.0 + f64::exp(x)).ln()).abs() < 1e-14, "{x}");
            assert!((sigmoid(x) - 1.0 / (1.0 + f64::exp(-x))).abs() < 1e-15, "{x}");
        }
        // e^800 overflows: the textbook forms give inf and 0/inf = NaN territory.
        assert!((1.0 + f64::exp(800.0)).ln().is_infinite());
        assert_eq!(softplus(800.0), 800.0);
        assert_eq!(sigmoid(-800.0), 0.0);
        assert_eq!(sigmoid(800.0), 1.0);
        // For very negative x, softplus(x) = e^x to full precision, not 0.
        assert!((softplus(-40.0) / (-40f64).exp() - 1.0).abs() < 1e-15);
    }

    #[test]
    fn fused_and_taped_agree_and_pass_gradcheck() {
        let act = Activation { shift: -1.5 };
        let both = |fused: bool| {
            move |t: &mut Tape<f64>, v: &[Var]| {
                let a = if fused {
                    act.apply(t, v[0])?
                } else {
                    act.taped(t, v[0])?
                };
                // Weight the outputs differently so every gradient entry matters.
                let s = t.mul_scalar(a.sigma, 0.7)?;
                let s = t.sum(s)?;
                let c = t.square(a.color)?;
                let c = t.sum(c)?;
                t.add(s, c)
            }
        };
        for fused in [true, false] {
            let report = gradcheck(both(fused), &[raw()], &GradcheckOptions::default()).unwrap();
            assert!(report.passes(), "fused {fused}: {report}");
        }
        let mut tape = Tape::<f64>::new();
        let r = tape.param(raw());
        let (f, t) = (act.apply(&mut tape, r).unwrap(), act.taped(&mut tape, r).unwrap());
        for (a, b) in [(f.sigma, t.sigma), (f.color, t.color)] {
            let (a, b) = (tape.value(a).unwrap().to_owned(), tape.value(b).unwrap().to_owned());
            assert_eq!(a.shape(), b.shape());
            assert!(a.iter().zip(b.iter()).all(|(x, y)| (x - y).abs() < 1e-15));
        }
    }

    #[test]
    fn a_raw_array_of_the_wrong_width_is_an_error() {
        let mut tape = Tape::<f64>::new();
        let r = tape.param(Array2::<f64>::zeros((3, 3)));
        assert!(Activation { shift: 0.0 }.apply(&mut tape, r).is_err());
        assert!(Activation { shift: 0.0 }.taped(&mut tape, r).is_err());
    }
}
