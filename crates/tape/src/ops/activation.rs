//! Activations and periodic functions of one input: `sigmoid`, `softplus`, `tanh`, `sin`, `cos`,
//! each a pair (f, df) in one table, in forms that stay exact where the textbook ones fail.
//!
//! With `e = exp(-|x|)`, which never overflows:
//! - `sigmoid(x) = 1 / (1 + e)` for `x >= 0` and `e / (1 + e)` below, so it saturates to
//!   exactly 0 and 1; its derivative `e / (1 + e)^2` keeps its digits in both tails, where
//!   `y (1 - y)` from a rounded `y = 1` is 0.
//! - `softplus(x) = max(x, 0) + ln_1p(e)`, so `softplus(x) = x` to the last bit once the
//!   correction is below half an ulp of `x`, and the tail below 0 is not rounded away;
//!   its derivative is `sigmoid(x)`, exactly `1/2` at 0.
//! - `tanh' = 4 sigmoid'(2x)` (which is `1 / cosh^2 x`), where `1 - tanh^2` is 0 in the tails.
//!
//! ```
//! use fogray_tape::Tape;
//! use ndarray::arr1;
//!
//! let mut tape = Tape::<f32>::new();
//! let x = tape.param(arr1(&[-1e4f32, 0.0, 1e4]));
//! let y = tape.softplus(x)?;
//! assert_eq!(tape.value(y)?.iter().copied().collect::<Vec<f32>>(), [0.0, std::f32::consts::LN_2, 1e4]);
//! let loss = tape.sum(y)?;
//! let grads = tape.backward(loss)?;
//! // softplus' = sigmoid: 0 and 1 in the tails, exactly 1/2 at 0.
//! assert_eq!(grads.get(x).unwrap().iter().copied().collect::<Vec<f32>>(), [0.0, 0.5, 1.0]);
//! # Ok::<(), fogray_tape::TapeError>(())
//! ```

use ndarray::{ArrayD, ArrayViewD};

use super::unary::{elementwise_backward, only_input};
use crate::buffer::map1;
use crate::custom::{BackwardCtx, CustomOp};
use crate::error::{OpError, Result};
use crate::float::Float;
use crate::tape::Tape;
use crate::var::Var;

/// Which activation or periodic function.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ActivationFn {
    /// The logistic `1 / (1 + e^-x)`, in (0, 1), exactly 0 or 1 when saturated;
    /// derivative `sigmoid(x) sigmoid(-x)`.
    Sigmoid,
    /// `ln(1 + e^x)`, a smooth `max(x, 0)`; derivative `sigmoid(x)`.
    Softplus,
    /// The hyperbolic tangent; derivative `1 / cosh^2 x`.
    Tanh,
    /// Sine (radians); derivative `cos x`.
    Sin,
    /// Cosine (radians); derivative `-sin x`.
    Cos,
}

impl ActivationFn {
    fn name(self) -> &'static str {
        match self {
            ActivationFn::Sigmoid => "sigmoid",
            ActivationFn::Softplus => "softplus",
            ActivationFn::Tanh => "tanh",
            ActivationFn::Sin => "sin",
            ActivationFn::Cos => "cos",
        }
    }

    fn f<F: Float>(self, x: F) -> F {
        match self {
            ActivationFn::Sigmoid => sigmoid(x),
            ActivationFn::Softplus => x.max(F::zero()) + (-x.abs()).exp().ln_1p(),
            ActivationFn::Tanh => x.tanh(),
            ActivationFn::Sin => x.sin(),
            ActivationFn::Cos => x.cos(),
        }
    }

    /// The derivative at `x` (none of these needs the output).
    fn df<F: Float>(self, x: F) -> F {
        match self {
            ActivationFn::Sigmoid => sigmoid_slope(x),
            ActivationFn::Softplus => sigmoid(x),
            ActivationFn::Tanh => F::lit(4.0) * sigmoid_slope(x + x),
            ActivationFn::Sin => x.cos(),
            ActivationFn::Cos => -x.sin(),
        }
    }
}

/// `1 / (1 + e^-x)` through `e = e^-|x|`, which is at most 1.
fn sigmoid<F: Float>(x: F) -> F {
    let one = F::one();
    let e = (-x.abs()).exp();
    if x >= F::zero() {
        one / (one + e)
    } else {
        e / (one + e)
    }
}

/// `sigmoid'(x) = e / (1 + e)^2` with `e = e^-|x|` (the derivative is even).
fn sigmoid_slope<F: Float>(x: F) -> F {
    let e = (-x.abs()).exp();
    let d = F::one() + e;
    e / (d * d)
}

/// An element-wise activation of one input (see [`ActivationFn`]).
#[derive(Debug, Clone, Copy)]
pub struct Activation(pub ActivationFn);

impl<F: Float> CustomOp<F> for Activation {
    type Saved = ();

    fn name(&self) -> &'static str {
        self.0.name()
    }

    fn forward(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<(Vec<ArrayD<F>>, ()), OpError> {
        let x = only_input(inputs)?;
        // One closure per function, chosen outside the loop.
        let y = match self.0 {
            ActivationFn::Sigmoid => map1(x, sigmoid),
            f => map1(x, |x| f.f(x)),
        };
        Ok((vec![y], ()))
    }

    fn backward(
        &self,
        ctx: &BackwardCtx<'_, F, ()>,
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
        let f = self.0;
        elementwise_backward(ctx, grads, |x, _| f.df(x))
    }
}

impl<F: Float> Tape<F> {
    fn activation(&mut self, x: Var, f: ActivationFn) -> Result<Var> {
        self.apply1(Activation(f), &[x])
    }
    /// The logistic `1 / (1 + e^-x)`, element-wise: in [0, 1] for every finite `x`, exactly 0
    /// or 1 where saturated, with a finite derivative everywhere.
    pub fn sigmoid(&mut self, x: Var) -> Result<Var> {
        self.activation(x, ActivationFn::Sigmoid)
    }
    /// `ln(1 + e^x)`, element-wise, without overflow (`x` itself once `e^-x` is below half an
    /// ulp of `x`); its derivative is `sigmoid(x)`, exactly 1/2 at 0.
    pub fn softplus(&mut self, x: Var) -> Result<Var> {
        self.activation(x, ActivationFn::Softplus)
    }
    /// The hyperbolic tangent, element-wise; derivative `1 / cosh^2 x`, accurate in the tails.
    pub fn tanh(&mut self, x: Var) -> Result<Var> {
        self.activation(x, ActivationFn::Tanh)
    }
    /// `sin x` (radians), element-wise.
    pub fn sin(&mut self, x: Var) -> Result<Var> {
        self.activation(x, ActivationFn::Sin)
    }
    /// `cos x` (radians), element-wise.
    pub fn cos(&mut self, x: Var) -> Result<Var> {
        self.activation(x, ActivationFn::Cos)
    }
}

#[cfg(test)]
mod tests;
