//! The activation without a tape (into new arrays or the caller's buffers) and as a
//! [`CustomOp`] of the tape, met through the same public interface as any user's op.

use std::borrow::Cow;

use fogray_tape::buffer::scratch;
use fogray_tape::{BackwardCtx, CustomOp, Float, OpError};
use ndarray::{Array1, Array2, ArrayD, ArrayView2, ArrayViewD, ArrayViewMut2, Ix1, Ix2, IxDyn};
use rayon::prelude::*;

use super::config::{Activated, ActivatedGrads, ActivatedMut, DensityColor};
use super::kept::KeptDecays;
use super::kernel::{self, CHUNK};
use crate::error::{At, Op, OpsError};

/// The values of `x` in row-major order: borrowed when contiguous, copied otherwise.
fn flat<'a, F: Float, D: ndarray::Dimension>(x: &'a ndarray::ArrayView<'_, F, D>) -> Cow<'a, [F]> {
    match x.as_slice() {
        Some(s) => Cow::Borrowed(s),
        None => Cow::Owned(x.iter().copied().collect()),
    }
}

/// A NaN raw value (infinities are valid: they saturate).
fn nan_raw(row: usize, channel: usize) -> OpsError {
    OpsError::domain(
        Op::DensityColor,
        At::Entry { row, column: channel },
        "raw value",
        f64::NAN,
        "must not be NaN",
    )
}

/// `data` as a `[rows, cols]` array.
fn matrix<F: Float>(what: &'static str, rows: usize, cols: usize, data: Vec<F>) -> Result<Array2<F>, OpsError> {
    Array2::from_shape_vec((rows, cols), data).map_err(|e| OpsError::Shape {
        op: Op::DensityColor,
        what,
        expected: format!("[{rows}, {cols}]"),
        got: e.to_string(),
    })
}

/// Checks that `raw` is `[n, k]` with `k >= 2` and holds no NaN; returns `(n, k)`.
fn check_raw<F: Float>(raw: &ArrayView2<'_, F>) -> Result<(usize, usize), OpsError> {
    let (n, k) = raw.dim();
    if k < 2 {
        return Err(OpsError::shape_of(
            Op::DensityColor,
            "raw values",
            "[n, k] with k >= 2",
            raw.shape(),
        ));
    }
    let values = flat(raw);
    // A fold per chunk, not a search, so that valid input (the common case) is read at full
    // speed; the position is looked for only once a NaN is known to be there.
    let has_nan = values
        .par_chunks(CHUNK * k)
        .any(|c| c.iter().fold(false, |acc, x| acc | x.is_nan()));
    if has_nan {
        let i = values.iter().position(|x| x.is_nan()).unwrap_or(0);
        return Err(nan_raw(i / k, i % k));
    }
    Ok((n, k))
}

/// Checks the upstream gradients' shapes against `n` rows of `k` raw values.
fn check_upstream<F: Float>(upstream: &ActivatedGrads<'_, F>, n: usize, k: usize) -> Result<(), OpsError> {
    if let Some(g) = &upstream.sigma {
        if g.len() != n {
            return Err(OpsError::shape_of(
                Op::DensityColor,
                "sigma gradient",
                format!("[{n}]"),
                g.shape(),
            ));
        }
    }
    if let Some(g) = &upstream.color {
        if g.dim() != (n, k - 1) {
            return Err(OpsError::shape_of(
                Op::DensityColor,
                "color gradient",
                format!("[{n}, {}]", k - 1),
                g.shape(),
            ));
        }
    }
    Ok(())
}

impl DensityColor {
    /// The density and colour of every row of `raw` (`[n, k]`, `k >= 2`): `sigma` `[n]` and
    /// `color` `[n, k - 1]` (see the [module docs](super) for the forms and their accuracy).
    ///
    /// Errors: `raw` not `[n, k]` with `k >= 2` ([`OpsError::Shape`]), a NaN raw value
    /// ([`OpsError::Domain`], the first one).
    pub fn evaluate<F: Float>(&self, raw: ArrayView2<'_, F>) -> Result<Activated<F>, OpsError> {
        let (n, k) = check_raw(&raw)?;
        let (sigma, color) = self.forward_flat(&flat(&raw), n, k, None);
        Ok(Activated {
            sigma: Array1::from_vec(sigma),
            color: matrix("color", n, k - 1, color)?,
        })
    }

    /// As [`DensityColor::evaluate`], into the caller's buffers: `out.sigma` must be `[n]` and
    /// `out.color` `[n, k - 1]` (any strides).
    ///
    /// Errors: as [`DensityColor::evaluate`], and buffers of the wrong shape; the buffers are
    /// unchanged then.
    pub fn evaluate_into<F: Float>(&self, raw: ArrayView2<'_, F>, out: ActivatedMut<'_, F>) -> Result<(), OpsError> {
        let (n, k) = check_raw(&raw)?;
        let ActivatedMut { mut sigma, mut color } = out;
        if sigma.len() != n {
            return Err(OpsError::shape_of(
                Op::DensityColor,
                "sigma",
                format!("[{n}]"),
                sigma.shape(),
            ));
        }
        if color.dim() != (n, k - 1) {
            return Err(OpsError::shape_of(
                Op::DensityColor,
                "color",
                format!("[{n}, {}]", k - 1),
                color.shape(),
            ));
        }
        let raw = flat(&raw);
        match (sigma.as_slice_mut(), color.as_slice_mut()) {
            (Some(s), Some(c)) => kernel::forward(self.shift(), k, &raw, s, c, None),
            _ => {
                let (s, c) = self.forward_flat(&raw, n, k, None);
                sigma.assign(&Array1::from_vec(s));
                for (o, v) in color.iter_mut().zip(c) {
                    *o = v;
                }
            }
        }
        Ok(())
    }

    /// The density alone, `softplus(raw_0 + shift)` `[n]`, of `raw` `[n, k]` (`k >= 1`
    /// here: the colour channels are not read), bitwise as [`DensityColor::evaluate`] gives it.
    ///
    /// Errors: `raw` with no column ([`OpsError::Shape`]), a NaN density
    /// ([`OpsError::Domain`]).
    pub fn density<F: Float>(&self, raw: ArrayView2<'_, F>) -> Result<Array1<F>, OpsError> {
        let (n, k) = raw.dim();
        if k == 0 {
            return Err(OpsError::shape_of(
                Op::DensityColor,
                "raw values",
                "[n, k] with k >= 1",
                raw.shape(),
            ));
        }
        if let Some(row) = raw.column(0).iter().position(|x| x.is_nan()) {
            return Err(nan_raw(row, 0));
        }
        let mut sigma = scratch(n);
        kernel::density(self.shift(), k, &flat(&raw), &mut sigma);
        Ok(Array1::from_vec(sigma))
    }

    /// The gradient `dL/draw` `[n, k]` of a loss `L` for the activation of `raw` (as for
    /// [`DensityColor::evaluate`]), given `upstream`: `dL/dsigma` `[n]` and `dL/dcolor`
    /// `[n, k - 1]`, each optional. `softplus' = sigmoid` and `sigmoid'(x) = e / (1 + e)^2`
    /// with `e = exp(-|x|)`, computed from `raw` (not from the outputs).
    ///
    /// Errors: as [`DensityColor::evaluate`], and upstream gradients of the wrong shape.
    pub fn vjp<F: Float>(
        &self,
        raw: ArrayView2<'_, F>,
        upstream: &ActivatedGrads<'_, F>,
    ) -> Result<Array2<F>, OpsError> {
        let (n, k) = check_raw(&raw)?;
        check_upstream(upstream, n, k)?;
        let g = self.backward_flat(&flat(&raw), k, upstream, None);
        matrix("raw gradient", n, k, g)
    }

    /// As [`DensityColor::vjp`], into the caller's buffer `g_raw` (`[n, k]`, any strides),
    /// every value of which is written.
    ///
    /// Errors: as [`DensityColor::vjp`], and a buffer of the wrong shape; it is unchanged then.
    pub fn vjp_into<F: Float>(
        &self,
        raw: ArrayView2<'_, F>,
        upstream: &ActivatedGrads<'_, F>,
        mut g_raw: ArrayViewMut2<'_, F>,
    ) -> Result<(), OpsError> {
        let (n, k) = check_raw(&raw)?;
        check_upstream(upstream, n, k)?;
        if g_raw.dim() != (n, k) {
            return Err(OpsError::shape_of(
                Op::DensityColor,
                "raw gradient",
                format!("[{n}, {k}]"),
                g_raw.shape(),
            ));
        }
        let raw = flat(&raw);
        let g_sigma = upstream.sigma.as_ref().map(flat);
        let g_color = upstream.color.as_ref().map(flat);
        match g_raw.as_slice_mut() {
            Some(out) => kernel::backward(self.shift(), k, &raw, g_sigma.as_deref(), g_color.as_deref(), out, None),
            None => {
                let g = self.backward_flat(&raw, k, upstream, None);
                for (o, v) in g_raw.iter_mut().zip(g) {
                    *o = v;
                }
            }
        }
        Ok(())
    }

    /// The forward on checked flat input: `(sigma, color)`, with every value's decay written
    /// into `kept` (`n k` values) if given.
    fn forward_flat<F: Float>(&self, raw: &[F], n: usize, k: usize, kept: Option<&mut [f64]>) -> (Vec<F>, Vec<F>) {
        // The kernel writes every value: no zeros first.
        let (mut sigma, mut color) = (scratch(n), scratch(n * (k - 1)));
        kernel::forward(self.shift(), k, raw, &mut sigma, &mut color, kept);
        (sigma, color)
    }

    /// The backward on checked flat input and checked upstream gradients, from the forward's
    /// kept decays if given.
    fn backward_flat<F: Float>(
        &self,
        raw: &[F],
        k: usize,
        upstream: &ActivatedGrads<'_, F>,
        kept: Option<&[f64]>,
    ) -> Vec<F> {
        let g_sigma = upstream.sigma.as_ref().map(flat);
        let g_color = upstream.color.as_ref().map(flat);
        let mut g = scratch(raw.len());
        kernel::backward(
            self.shift(),
            k,
            raw,
            g_sigma.as_deref(),
            g_color.as_deref(),
            &mut g,
            kept,
        );
        g
    }
}

/// `x` as a 2-D view, or the shape error.
fn two_d<'a, F: Float>(x: &ArrayViewD<'a, F>) -> Result<ArrayView2<'a, F>, OpError> {
    x.clone().into_dimensionality::<Ix2>().map_err(|_| {
        OpError::from(OpsError::shape_of(
            Op::DensityColor,
            "raw values",
            "[n, k] with k >= 2",
            x.shape(),
        ))
    })
}

/// The op's one input as `[n, k]` raw values, checked, with `n` and `k`.
fn checked_input<'a, F: Float>(inputs: &[ArrayViewD<'a, F>]) -> Result<(ArrayView2<'a, F>, usize, usize), OpError> {
    let [raw] = inputs else {
        return Err(OpError::InvalidArgument(format!("takes 1 input, got {}", inputs.len())));
    };
    let raw = two_d(raw)?;
    let (n, k) = check_raw(&raw)?;
    Ok((raw, n, k))
}

fn array<F: Float>(shape: &[usize], data: Vec<F>) -> Result<ArrayD<F>, OpError> {
    ArrayD::from_shape_vec(IxDyn(shape), data).map_err(|e| OpError::InvalidArgument(e.to_string()))
}

impl<F: Float> CustomOp<F> for DensityColor {
    /// Every value's decay `exp(-|x|)`, in f64 (8 bytes a raw value): the backward then needs
    /// no exponential, and its gradients are bitwise those recomputed from the raw values.
    type Saved = KeptDecays;

    fn name(&self) -> &'static str {
        Op::DensityColor.name()
    }

    fn saved_bytes(&self, saved: &KeptDecays) -> usize {
        saved.bytes()
    }

    fn forward(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<(Vec<ArrayD<F>>, KeptDecays), OpError> {
        let (raw, n, k) = checked_input(inputs)?;
        // Every value is written by the kernel.
        let mut kept = KeptDecays::with_len(n * k);
        let (sigma, color) = self.forward_flat(&flat(&raw), n, k, Some(kept.values_mut()));
        Ok((vec![array(&[n], sigma)?, array(&[n, k - 1], color)?], kept))
    }

    /// The same outputs, bit for bit, without keeping the decays: no backward will read them.
    fn forward_only(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<Vec<ArrayD<F>>, OpError> {
        let (raw, n, k) = checked_input(inputs)?;
        let (sigma, color) = self.forward_flat(&flat(&raw), n, k, None);
        Ok(vec![array(&[n], sigma)?, array(&[n, k - 1], color)?])
    }

    fn backward(
        &self,
        ctx: &BackwardCtx<'_, F, KeptDecays>,
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
        if !ctx.needs_input_grad(0) || grads.iter().all(Option::is_none) {
            return Ok(vec![None]);
        }
        let input = ctx.input(0);
        let raw = two_d(&input)?;
        let (n, k) = raw.dim();
        // The raw values were checked by the forward; the tape gives gradients of the
        // outputs' shapes.
        let sigma = match &grads[0] {
            Some(g) => Some(
                g.view()
                    .into_dimensionality::<Ix1>()
                    .map_err(|e| OpError::InvalidArgument(e.to_string()))?,
            ),
            None => None,
        };
        let color = match &grads[1] {
            Some(g) => Some(
                g.view()
                    .into_dimensionality::<Ix2>()
                    .map_err(|e| OpError::InvalidArgument(e.to_string()))?,
            ),
            None => None,
        };
        let upstream = ActivatedGrads { sigma, color };
        check_upstream(&upstream, n, k)?;
        let g = self.backward_flat(&flat(&raw), k, &upstream, Some(ctx.saved().values()));
        Ok(vec![Some(array(&[n, k], g)?)])
    }
}
