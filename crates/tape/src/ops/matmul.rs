//! Matrix product of two 2-D values, `[m, k] x [k, n] -> [m, n]`, through ndarray's
//! `general_mat_mul` (matrixmultiply's blocked kernels for f32 and f64). The backward is two
//! more products on transposed views, `dA = g B^T` and `dB = A^T g`, with no copy of either
//! transpose.
//!
//! With the broadcasting [`Tape::add`] of a `[n]` bias, a batch of rows through a dense layer
//! is `x W + b`. Fitting a small MLP (1 -> 32 -> 32 -> 1, tanh) to `sin x` on [-3, 3] with a
//! few lines of Adam:
//!
//! ```
//! use fogray_tape::{Result, Tape, Var};
//! use ndarray::{Array1, Array2, ArrayD};
//! use rand::{Rng, SeedableRng};
//!
//! /// The mean squared error of the MLP with weights `p` (W1, b1, W2, b2, W3, b3) on (x, y),
//! /// and its gradient with respect to each weight.
//! fn loss_and_grads(p: &[ArrayD<f64>], x: &Array2<f64>, y: &Array2<f64>) -> Result<(f64, Vec<ArrayD<f64>>)> {
//!     let mut t = Tape::new();
//!     let vars: Vec<Var> = p.iter().map(|w| t.param(w.clone())).collect();
//!     let mut h = t.constant(x.clone());
//!     for (layer, wb) in vars.chunks(2).enumerate() {
//!         let xw = t.matmul(h, wb[0])?; // [batch, fan_in] x [fan_in, fan_out]
//!         let z = t.add(xw, wb[1])?; // + b: the [fan_out] bias broadcast over the batch
//!         h = if layer < 2 { t.tanh(z)? } else { z };
//!     }
//!     let target = t.constant(y.clone());
//!     let r = t.sub(h, target)?;
//!     let sq = t.square(r)?;
//!     let loss = t.mean(sq)?;
//!     let g = t.backward(loss)?;
//!     let loss = t.value(loss)?[[]];
//!     Ok((loss, vars.iter().map(|&v| g.get(v).unwrap().to_owned()).collect()))
//! }
//!
//! let n = 64;
//! let x = Array2::from_shape_fn((n, 1), |(i, _)| -3.0 + 6.0 * i as f64 / (n - 1) as f64);
//! let y = x.mapv(f64::sin);
//! // Uniform weights of variance 1 / fan_in, zero biases.
//! let mut rng = rand::rngs::StdRng::seed_from_u64(0);
//! let mut p = Vec::new();
//! for (fan_in, fan_out) in [(1, 32), (32, 32), (32, 1)] {
//!     let s = (3.0 / fan_in as f64).sqrt();
//!     p.push(Array2::from_shape_fn((fan_in, fan_out), |_| rng.gen_range(-s..s)).into_dyn());
//!     p.push(Array1::<f64>::zeros(fan_out).into_dyn());
//! }
//! // Adam: first and second moments of each gradient, bias-corrected.
//! let (lr, b1, b2, eps) = (0.01, 0.9, 0.999, 1e-8);
//! let mut m: Vec<ArrayD<f64>> = p.iter().map(|w| ArrayD::zeros(w.shape())).collect();
//! let mut v = m.clone();
//! let (first, _) = loss_and_grads(&p, &x, &y)?;
//! let mut last = first;
//! for step in 1..=1000 {
//!     let (loss, grads) = loss_and_grads(&p, &x, &y)?;
//!     last = loss;
//!     for (((w, g), m), v) in p.iter_mut().zip(&grads).zip(&mut m).zip(&mut v) {
//!         *m = &*m * b1 + g * (1.0 - b1);
//!         *v = &*v * b2 + &(g * g) * (1.0 - b2);
//!         let (mc, vc) = (1.0 - b1.powi(step), 1.0 - b2.powi(step));
//!         *w -= &(&*m / mc / &(&*v / vc).mapv(|s| s.sqrt() + eps) * lr);
//!     }
//! }
//! assert!(last < first / 100.0, "loss {first} -> {last}");
//! # Ok::<(), fogray_tape::TapeError>(())
//! ```

use ndarray::linalg::general_mat_mul;
use ndarray::{Array2, ArrayD, ArrayView2, ArrayViewD, Ix2};

use crate::buffer::zeroed;
use crate::custom::{BackwardCtx, CustomOp};
use crate::error::{OpError, Result};
use crate::float::Float;
use crate::tape::Tape;
use crate::var::Var;

/// `a b` for `a` of shape `[m, k]` and `b` of shape `[k, n]`.
#[derive(Debug, Clone, Copy, Default)]
pub struct Matmul;

/// The two inputs as matrices, or the error that says which is not one or why they disagree.
fn matrices<'a, F: Float>(inputs: &[ArrayViewD<'a, F>]) -> Result<(ArrayView2<'a, F>, ArrayView2<'a, F>), OpError> {
    let [a, b] = inputs else {
        return Err(OpError::InvalidArgument(format!(
            "takes 2 inputs, got {}",
            inputs.len()
        )));
    };
    let matrix = |x: &ArrayViewD<'a, F>, which: &str| {
        x.clone()
            .into_dimensionality::<Ix2>()
            .map_err(|_| OpError::InvalidArgument(format!("needs 2-D inputs, {which} has shape {:?}", x.shape())))
    };
    let (a2, b2) = (matrix(a, "the left")?, matrix(b, "the right")?);
    if a2.ncols() != b2.nrows() {
        return Err(OpError::ShapeMismatch {
            lhs: a.shape().to_vec(),
            rhs: b.shape().to_vec(),
        });
    }
    Ok((a2, b2))
}

/// `a b` into a buffer from [`crate::buffer`] (zeroed, so a product over `k = 0` is zeros).
fn product<F: Float>(a: &ArrayView2<'_, F>, b: &ArrayView2<'_, F>) -> Result<ArrayD<F>, OpError> {
    let (m, n) = (a.nrows(), b.ncols());
    let mut out = Array2::from_shape_vec((m, n), zeroed(m * n)).map_err(|e| OpError::InvalidArgument(e.to_string()))?;
    general_mat_mul(F::one(), a, b, F::zero(), &mut out);
    Ok(out.into_dyn())
}

impl<F: Float> CustomOp<F> for Matmul {
    type Saved = ();

    fn name(&self) -> &'static str {
        "matmul"
    }

    fn forward(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<(Vec<ArrayD<F>>, ()), OpError> {
        let (a, b) = matrices(inputs)?;
        Ok((vec![product(&a, &b)?], ()))
    }

    fn backward(
        &self,
        ctx: &BackwardCtx<'_, F, ()>,
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
        let Some(g) = &grads[0] else {
            return Ok(vec![None, None]);
        };
        let (a, b) = matrices(&[ctx.input(0), ctx.input(1)])?;
        let g = g
            .view()
            .into_dimensionality::<Ix2>()
            .map_err(|e| OpError::InvalidArgument(e.to_string()))?;
        let da = if ctx.needs_input_grad(0) {
            Some(product(&g, &b.t())?)
        } else {
            None
        };
        let db = if ctx.needs_input_grad(1) {
            Some(product(&a.t(), &g)?)
        } else {
            None
        };
        Ok(vec![da, db])
    }
}

impl<F: Float> Tape<F> {
    /// The matrix product `a b` of `a` with shape `[m, k]` and `b` with shape `[k, n]`: an
    /// `[m, n]` value. Add a `[n]` bias with the broadcasting [`Tape::add`].
    ///
    /// Errors: [`TapeError::InvalidArgument`](crate::TapeError::InvalidArgument) if either is not
    /// 2-D, [`TapeError::ShapeMismatch`](crate::TapeError::ShapeMismatch) (with both shapes) if
    /// the inner dimensions differ; the tape is unchanged.
    pub fn matmul(&mut self, a: Var, b: Var) -> Result<Var> {
        self.apply1(Matmul, &[a, b])
    }
}

#[cfg(test)]
mod tests;
