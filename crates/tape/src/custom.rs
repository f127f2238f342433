//! The public custom-op interface: supply a forward and a backward, the tape does the rest.
//!
//! Every built-in op of this crate is implemented through this same trait, so the interface
//! a user gets is the one every test exercises.
//!
//! ```
//! use fogray_tape::{BackwardCtx, CustomOp, OpError, Tape};
//! use ndarray::{ArrayD, ArrayViewD};
//!
//! /// y = x^3 elementwise; dy/dx = 3 x^2.
//! #[derive(Debug)]
//! struct Cube;
//!
//! impl CustomOp<f64> for Cube {
//!     type Saved = ();
//!     fn name(&self) -> &'static str { "cube" }
//!     fn forward(&self, inputs: &[ArrayViewD<'_, f64>]) -> Result<(Vec<ArrayD<f64>>, ()), OpError> {
//!         Ok((vec![inputs[0].mapv(|x| x * x * x)], ()))
//!     }
//!     fn backward(
//!         &self,
//!         ctx: &BackwardCtx<'_, f64, ()>,
//!         grads: &[Option<ArrayViewD<'_, f64>>],
//!     ) -> Result<Vec<Option<ArrayD<f64>>>, OpError> {
//!         let Some(g) = &grads[0] else { return Ok(vec![None]) };
//!         let x = ctx.input(0);
//!         Ok(vec![Some(g * &x.mapv(|x| 3.0 * x * x))])
//!     }
//! }
//!
//! let mut tape = Tape::<f64>::new();
//! let x = tape.param(ndarray::arr1(&[2.0]));
//! let y = tape.apply1(Cube, &[x])?;
//! let grads = tape.backward(y)?;
//! assert_eq!(grads.get(x).unwrap()[[0]], 12.0);
//! # Ok::<(), fogray_tape::TapeError>(())
//! ```

use std::fmt::Debug;

use ndarray::{ArrayD, ArrayViewD};

use crate::error::OpError;
use crate::float::Float;

/// An op whose forward and backward the implementor supplies
/// (the analogue of `torch.autograd.Function` or `jax.custom_vjp`).
///
/// Non-differentiable configuration (integer offsets, flags, thresholds) belongs in the op
/// value itself, not among the tape inputs.
pub trait CustomOp<F: Float>: Debug + Send + 'static {
    /// Residuals the backward needs beyond the inputs and outputs, which the tape keeps anyway.
    type Saved: Send + 'static;

    /// A short name used in every error message about this op.
    fn name(&self) -> &'static str;

    /// Computes the outputs (at least one) and the residuals from the input values.
    ///
    /// Must not assume anything about the inputs' memory layout (they may be strided views).
    /// An `Err` here leaves the tape unchanged.
    fn forward(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<(Vec<ArrayD<F>>, Self::Saved), OpError>;

    /// Computes the outputs alone, for an application the tape keeps no record of (recording
    /// is off, or no input needs a gradient): no backward will read residuals, so an op whose
    /// residuals cost time or memory to make can skip them here. The outputs must be those
    /// [`CustomOp::forward`] computes, bit for bit, and its errors the same.
    ///
    /// Defaults to [`CustomOp::forward`] with its residuals dropped.
    fn forward_only(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<Vec<ArrayD<F>>, OpError> {
        self.forward(inputs).map(|(outputs, _)| outputs)
    }

    /// Maps the upstream gradients to gradients of the inputs (a vector-Jacobian product).
    ///
    /// `grads[j]` is `None` when output `j` reached nothing that needs a gradient; at least one
    /// is `Some`. Return exactly one entry per input; an entry may be `None` (no contribution),
    /// and should be `None` where [`BackwardCtx::needs_input_grad`] is false. Each `Some` must
    /// have its input's shape: the tape checks both and names this op on a violation.
    /// Ops that cannot be differentiated return [`OpError::NotDifferentiable`].
    fn backward(
        &self,
        ctx: &BackwardCtx<'_, F, Self::Saved>,
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError>;

    /// Bytes held by the residuals, for [`Tape::stats`](crate::Tape::stats). Defaults to 0.
    fn saved_bytes(&self, _saved: &Self::Saved) -> usize {
        0
    }
}

/// What a backward may read: the op's inputs and outputs (straight from the tape, no copies),
/// its residuals, and which inputs need a gradient.
pub struct BackwardCtx<'a, F: Float, S> {
    pub(crate) inputs: &'a [ArrayViewD<'a, F>],
    pub(crate) outputs: &'a [ArrayViewD<'a, F>],
    pub(crate) needs: &'a [bool],
    pub(crate) saved: &'a S,
}

impl<'a, F: Float, S> BackwardCtx<'a, F, S> {
    /// The value of input `i`. Panics if `i` is not an input index of this op (a bug in the op).
    pub fn input(&self, i: usize) -> ArrayViewD<'a, F> {
        self.inputs[i].clone()
    }
    /// The value of output `j`. Panics if `j` is not an output index of this op.
    pub fn output(&self, j: usize) -> ArrayViewD<'a, F> {
        self.outputs[j].clone()
    }
    /// Number of inputs.
    pub fn num_inputs(&self) -> usize {
        self.inputs.len()
    }
    /// Whether the tape wants a gradient for input `i` (false for constants and detached values).
    pub fn needs_input_grad(&self, i: usize) -> bool {
        self.needs.get(i).copied().unwrap_or(false)
    }
    /// The residuals the forward saved.
    pub fn saved(&self) -> &'a S {
        self.saved
    }
}

/// Materialises an optional upstream gradient as zeros of `shape` when it is `None`,
/// for ops whose backward prefers a dense array.
pub fn grad_or_zeros<F: Float>(grad: &Option<ArrayViewD<'_, F>>, shape: &[usize]) -> ArrayD<F> {
    match grad {
        Some(g) => g.to_owned(),
        None => ArrayD::zeros(shape),
    }
}

/// The object-safe face of a recorded op application, stored on the tape.
pub(crate) trait Backward<F: Float>: Debug + Send {
    fn name(&self) -> &'static str;
    fn backward<'a>(
        &'a self,
        inputs: &'a [ArrayViewD<'a, F>],
        outputs: &'a [ArrayViewD<'a, F>],
        needs: &'a [bool],
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError>;
    fn saved_bytes(&self) -> usize;
}

/// Pairs an op with its residuals, hiding the associated type so records fit in one `Vec`.
pub(crate) struct Recorded<O, S> {
    pub(crate) op: O,
    pub(crate) saved: S,
}

impl<O: Debug, S> Debug for Recorded<O, S> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorded").field("op", &self.op).finish_non_exhaustive()
    }
}

impl<F: Float, O: CustomOp<F, Saved = S>, S: Send + 'static> Backward<F> for Recorded<O, S> {
    fn name(&self) -> &'static str {
        self.op.name()
    }
    fn backward<'a>(
        &'a self,
        inputs: &'a [ArrayViewD<'a, F>],
        outputs: &'a [ArrayViewD<'a, F>],
        needs: &'a [bool],
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
        let ctx = BackwardCtx {
            inputs,
            outputs,
            needs,
            saved: &self.saved,
        };
        self.op.backward(&ctx, grads)
    }
    fn saved_bytes(&self) -> usize {
        self.op.saved_bytes(&self.saved)
    }
}
