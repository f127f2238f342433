//! The op without a tape ([`ShColor::evaluate`], [`ShColor::vjp`]) and as a [`CustomOp`] of
//! the tape, met through the same public interface as any user's op.

use std::borrow::Cow;

use fogray_tape::buffer::scratch;
use fogray_tape::{BackwardCtx, CustomOp, Float, OpError};
use ndarray::{Array2, ArrayD, ArrayView2, ArrayViewD, Ix2, IxDyn};

use super::check::{check_shapes, check_values};
use super::config::ShColor;
use super::kernel;
use crate::error::{Op, OpsError};

/// The values of `x` in row-major order: borrowed when contiguous, copied otherwise.
fn flat<'a, F: Float>(x: &'a ArrayView2<'_, F>) -> Cow<'a, [F]> {
    match x.as_slice() {
        Some(s) => Cow::Borrowed(s),
        None => Cow::Owned(x.iter().copied().collect()),
    }
}

/// `data` as a `[rows, cols]` array.
fn matrix<F: Float>(what: &'static str, rows: usize, cols: usize, data: Vec<F>) -> Result<Array2<F>, OpsError> {
    Array2::from_shape_vec((rows, cols), data).map_err(|e| OpsError::Shape {
        op: Op::ShColor,
        what,
        expected: format!("[{rows}, {cols}]"),
        got: e.to_string(),
    })
}

impl ShColor {
    /// Checks the inputs (shapes, then values); returns `n`.
    fn check<F: Float>(&self, coeffs: &ArrayView2<'_, F>, directions: &ArrayView2<'_, F>) -> Result<usize, OpsError> {
        let n = check_shapes(self.degree(), self.basis_count(), coeffs, directions)?;
        check_values(coeffs, directions)?;
        Ok(n)
    }

    /// The colour `[n, 3]` of `coeffs` (`[n, 3 B]`) seen along `directions` (`[n, 3]`, unit
    /// vectors): `sigmoid(sum_b coeffs[i, c B + b] Y_b(d_i))`.
    ///
    /// Errors: coefficients not `[n, 3 B]` or directions not `[n, 3]`
    /// ([`OpsError::Shape`]), a NaN or infinite value ([`OpsError::Domain`]), a direction
    /// whose length is not 1 within `1e-3` ([`OpsError::NotUnit`]); the first fault by row.
    pub fn evaluate<F: Float>(
        &self,
        coeffs: ArrayView2<'_, F>,
        directions: ArrayView2<'_, F>,
    ) -> Result<Array2<F>, OpsError> {
        let n = self.check(&coeffs, &directions)?;
        let color = self.forward_flat(&flat(&coeffs), &flat(&directions), n);
        matrix("color", n, 3, color)
    }

    /// The gradient `dL/dcoeffs` `[n, 3 B]` of a loss `L` for the colour of `coeffs` along
    /// `directions` (as for [`ShColor::evaluate`]), given `dL/dcolor` `[n, 3]`:
    /// `g_color[i, c] sigmoid'(x_ic) Y_b(d_i)`, in closed form.
    ///
    /// Errors: as [`ShColor::evaluate`], and an upstream gradient that is
    /// not `[n, 3]`.
    pub fn vjp<F: Float>(
        &self,
        coeffs: ArrayView2<'_, F>,
        directions: ArrayView2<'_, F>,
        g_color: ArrayView2<'_, F>,
    ) -> Result<Array2<F>, OpsError> {
        let n = self.check(&coeffs, &directions)?;
        if g_color.dim() != (n, 3) {
            return Err(OpsError::shape_of(
                Op::ShColor,
                "color gradient",
                format!("[{n}, 3]"),
                g_color.shape(),
            ));
        }
        let g = self.backward_flat(&flat(&coeffs), &flat(&directions), &flat(&g_color));
        matrix("coefficient gradient", n, self.coefficient_count(), g)
    }

    /// The forward on checked flat input.
    fn forward_flat<F: Float>(&self, coeffs: &[F], directions: &[F], n: usize) -> Vec<F> {
        // The kernel writes every value: no zeros first.
        let mut color = scratch(n * 3);
        kernel::forward(self.basis_count(), coeffs, directions, &mut color);
        color
    }

    /// The backward on checked flat input and a checked upstream gradient.
    fn backward_flat<F: Float>(&self, coeffs: &[F], directions: &[F], g_color: &[F]) -> Vec<F> {
        let mut g = scratch(coeffs.len());
        kernel::backward(self.basis_count(), coeffs, directions, g_color, &mut g);
        g
    }
}

/// `x` as a 2-D view, or the shape error naming `what`.
fn two_d<'a, F: Float>(
    what: &'static str,
    expected: &str,
    x: &ArrayViewD<'a, F>,
) -> Result<ArrayView2<'a, F>, OpError> {
    x.clone()
        .into_dimensionality::<Ix2>()
        .map_err(|_| OpError::from(OpsError::shape_of(Op::ShColor, what, expected, x.shape())))
}

/// The op's two inputs as 2-D views.
fn inputs_2d<'a, F: Float>(inputs: &[ArrayViewD<'a, F>]) -> Result<(ArrayView2<'a, F>, ArrayView2<'a, F>), OpError> {
    let [coeffs, directions] = inputs else {
        return Err(OpError::InvalidArgument(format!(
            "takes 2 inputs, got {}",
            inputs.len()
        )));
    };
    Ok((
        two_d("coefficients", "[n, 3 (degree + 1)^2]", coeffs)?,
        two_d("directions", "[n, 3]", directions)?,
    ))
}

fn array<F: Float>(shape: &[usize], data: Vec<F>) -> Result<ArrayD<F>, OpError> {
    ArrayD::from_shape_vec(IxDyn(shape), data).map_err(|e| OpError::InvalidArgument(e.to_string()))
}

impl<F: Float> CustomOp<F> for ShColor {
    /// Nothing: the backward recomputes the basis and the sums from the inputs, so that its
    /// gradients are bitwise those of [`ShColor::vjp`].
    type Saved = ();

    fn name(&self) -> &'static str {
        Op::ShColor.name()
    }

    fn forward(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<(Vec<ArrayD<F>>, ()), OpError> {
        let (coeffs, directions) = inputs_2d(inputs)?;
        let n = self.check(&coeffs, &directions)?;
        let color = self.forward_flat(&flat(&coeffs), &flat(&directions), n);
        Ok((vec![array(&[n, 3], color)?], ()))
    }

    fn backward(
        &self,
        ctx: &BackwardCtx<'_, F, ()>,
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
        // No gradient for the directions: they are constants of the op.
        let Some(g_color) = grads.first().and_then(Option::as_ref) else {
            return Ok(vec![None, None]);
        };
        if !ctx.needs_input_grad(0) {
            return Ok(vec![None, None]);
        }
        let (coeffs, directions) = inputs_2d(&[ctx.input(0), ctx.input(1)])?;
        // The inputs were checked by the forward; the tape gives a gradient of the output's shape.
        let g_color = two_d("color gradient", "[n, 3]", g_color)?;
        if g_color.dim() != (coeffs.nrows(), 3) {
            return Err(OpError::from(OpsError::shape_of(
                Op::ShColor,
                "color gradient",
                format!("[{}, 3]", coeffs.nrows()),
                g_color.shape(),
            )));
        }
        let g = self.backward_flat(&flat(&coeffs), &flat(&directions), &flat(&g_color));
        Ok(vec![Some(array(coeffs.shape(), g)?), None])
    }
}
