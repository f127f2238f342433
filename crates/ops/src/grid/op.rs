//! The grid field without a tape ([`GridField::evaluate`], [`GridField::vjp`]) and as a
//! [`CustomOp`] of the tape, met through the same public interface as any user's op.

use std::borrow::Cow;

use fogray_tape::buffer::scratch;
use fogray_tape::{BackwardCtx, CustomOp, Float, OpError};
use ndarray::{ArrayD, ArrayViewD, ArrayViewMutD, IxDyn};
use rayon::prelude::*;

use super::backward::position_gradient;
use super::config::{GridField, GridGradientBuffers, GridGradients, GridWanted};
use super::forward::{forward, CHUNK};
use super::geometry::Layout;
use super::scatter::grid_gradient;
use crate::error::{At, Op, OpsError};

/// The values of `x` in row-major order: borrowed when contiguous, copied otherwise.
pub(crate) fn flat<'a, F: Float>(x: &'a ArrayViewD<'_, F>) -> Cow<'a, [F]> {
    match x.as_slice() {
        Some(s) => Cow::Borrowed(s),
        None => Cow::Owned(x.iter().copied().collect()),
    }
}

pub(crate) fn array<F: Float>(op: Op, shape: &[usize], data: Vec<F>) -> Result<ArrayD<F>, OpsError> {
    ArrayD::from_shape_vec(IxDyn(shape), data).map_err(|e| OpsError::Shape {
        op,
        what: "output",
        expected: format!("{shape:?}"),
        got: e.to_string(),
    })
}

/// A caller's buffer as a flat slice: of shape `shape`, contiguous in standard order.
pub(crate) fn buffer<'a, F: Float>(
    what: &'static str,
    b: &'a mut ArrayViewMutD<'_, F>,
    shape: &[usize],
) -> Result<&'a mut [F], OpsError> {
    if b.shape() != shape {
        return Err(OpsError::Shape {
            op: Op::GridField,
            what,
            expected: format!("{shape:?}"),
            got: format!("{:?}", b.shape()),
        });
    }
    b.as_slice_mut().ok_or_else(|| OpsError::Shape {
        op: Op::GridField,
        what,
        expected: "a contiguous array in standard (row-major) order".into(),
        got: "a strided view".into(),
    })
}

/// Positions `[n, d]`, flat, and `n`.
///
/// Errors, naming `op`: another shape ([`OpsError::Shape`]), a NaN coordinate
/// ([`OpsError::Domain`], the first one).
pub(crate) fn check_positions<'a, F: Float>(
    op: Op,
    positions: &'a ArrayViewD<'_, F>,
    d: usize,
) -> Result<(Cow<'a, [F]>, usize), OpsError> {
    if positions.ndim() != 2 || positions.shape()[1] != d {
        return Err(OpsError::Shape {
            op,
            what: "positions",
            expected: format!("[n, {d}]"),
            got: format!("{:?}", positions.shape()),
        });
    }
    let positions = flat(positions);
    // By chunks: rayon's per-element search costs more than the lookups.
    let chunk = CHUNK * d;
    if let Some(c) = positions
        .par_chunks(chunk)
        .position_first(|c| c.iter().any(|x| x.is_nan()))
    {
        let i = c * chunk + positions[c * chunk..].iter().position(|x| x.is_nan()).unwrap_or(0);
        return Err(OpsError::domain(
            op,
            At::Entry {
                row: i / d,
                column: i % d,
            },
            "position",
            f64::NAN,
            "must not be NaN; outside the box, even infinite, reads zero",
        ));
    }
    let n = positions.len() / d;
    Ok((positions, n))
}

/// The checked inputs, flat.
pub(crate) struct Checked<'a, F: Float> {
    pub(crate) grid: Cow<'a, [F]>,
    pub(crate) positions: Cow<'a, [F]>,
    /// Number of positions.
    pub(crate) n: usize,
}

impl GridField {
    /// Checks the shapes of the grid values and the positions, and the positions for NaN.
    pub(crate) fn check<'a, F: Float>(
        &self,
        grid: &'a ArrayViewD<'_, F>,
        positions: &'a ArrayViewD<'_, F>,
    ) -> Result<Checked<'a, F>, OpsError> {
        if grid.shape() != self.shape.as_slice() {
            return Err(OpsError::Shape {
                op: Op::GridField,
                what: "grid",
                expected: format!("{:?}", self.shape),
                got: format!("{:?}", grid.shape()),
            });
        }
        let (positions, n) = check_positions(Op::GridField, positions, self.dims())?;
        Ok(Checked {
            grid: flat(grid),
            n,
            positions,
        })
    }

    /// Looks the grid up at every position: `grid` has [`GridField::shape`], `positions` is
    /// `[n, D]` (D the box's axes), the result `[n, C]`. A position outside the box reads 0
    /// in every channel.
    ///
    /// Errors: the shapes do not fit ([`OpsError::Shape`]), a NaN coordinate
    /// ([`OpsError::Domain`], the first one).
    pub fn evaluate<F: Float>(
        &self,
        grid: &ArrayViewD<'_, F>,
        positions: &ArrayViewD<'_, F>,
    ) -> Result<ArrayD<F>, OpsError> {
        let x = self.check(grid, positions)?;
        // The forward writes every value, so no zeros first.
        let mut out = scratch(x.n * self.channels());
        self.forward_flat(&x, &mut out);
        array(Op::GridField, &[x.n, self.channels()], out)
    }

    /// [`GridField::evaluate`] into `out`, a buffer the caller keeps (`[n, C]`, contiguous in
    /// standard order; every value overwritten): a training loop then allocates nothing.
    ///
    /// Errors: as [`GridField::evaluate`], and an `out` of another shape or strided
    /// ([`OpsError::Shape`]); `out` is unchanged on error.
    pub fn evaluate_into<F: Float>(
        &self,
        grid: &ArrayViewD<'_, F>,
        positions: &ArrayViewD<'_, F>,
        out: &mut ArrayViewMutD<'_, F>,
    ) -> Result<(), OpsError> {
        let x = self.check(grid, positions)?;
        let out = buffer("output buffer", out, &[x.n, self.channels()])?;
        self.forward_flat(&x, out);
        Ok(())
    }

    fn forward_flat<F: Float>(&self, x: &Checked<'_, F>, out: &mut [F]) {
        let ch = self.channels();
        match self.dims() {
            2 => forward(
                &Layout::<2>::new(&self.bbox, self.nodes()),
                &x.grid,
                &x.positions,
                ch,
                out,
            ),
            _ => forward(
                &Layout::<3>::new(&self.bbox, self.nodes()),
                &x.grid,
                &x.positions,
                ch,
                out,
            ),
        }
    }

    /// The gradients of a loss `L` with `upstream = dL/doutput` (`[n, C]`) for the lookup of
    /// `grid` at `positions` (as for [`GridField::evaluate`]), those `wanted`.
    ///
    /// Out of the box, a position's gradient is zero and it adds nothing to the grid's. On a
    /// cell face the position gradient is that of the cell the position belongs to (see the
    /// [module docs](super)). The grid gradient is bitwise the same whatever the number of
    /// threads.
    ///
    /// Errors: as [`GridField::evaluate`], and an upstream gradient not of shape `[n, C]`.
    pub fn vjp<F: Float>(
        &self,
        grid: &ArrayViewD<'_, F>,
        positions: &ArrayViewD<'_, F>,
        upstream: &ArrayViewD<'_, F>,
        wanted: GridWanted,
    ) -> Result<GridGradients<F>, OpsError> {
        let (x, g) = self.check_vjp(grid, positions, upstream)?;
        // Both gradients are written whole, so no zeros first.
        let mut grid_out = wanted.grid.then(|| scratch(x.grid.len()));
        let mut positions_out = wanted.positions.then(|| scratch(x.positions.len()));
        self.gradients_flat(&x, &g, grid_out.as_deref_mut(), positions_out.as_deref_mut());
        Ok(GridGradients {
            grid: grid_out.map(|v| array(Op::GridField, &self.shape, v)).transpose()?,
            positions: positions_out
                .map(|v| array(Op::GridField, &[x.n, self.dims()], v))
                .transpose()?,
        })
    }

    /// [`GridField::vjp`] into buffers the caller keeps: the gradients wanted are those whose
    /// buffer is `Some` (the grid's shape, and `[n, D]`), every value overwritten. Gives the
    /// same bits as [`GridField::vjp`].
    ///
    /// Errors: as [`GridField::vjp`], and a buffer of another shape or strided
    /// ([`OpsError::Shape`]); no buffer is changed on error.
    pub fn vjp_into<F: Float>(
        &self,
        grid: &ArrayViewD<'_, F>,
        positions: &ArrayViewD<'_, F>,
        upstream: &ArrayViewD<'_, F>,
        out: &mut GridGradientBuffers<'_, F>,
    ) -> Result<(), OpsError> {
        let (x, g) = self.check_vjp(grid, positions, upstream)?;
        let GridGradientBuffers {
            grid: grid_out,
            positions: positions_out,
        } = out;
        // Every buffer is checked before any is written.
        let grid_out = grid_out
            .as_mut()
            .map(|b| buffer("grid gradient buffer", b, &self.shape))
            .transpose()?;
        let positions_out = positions_out
            .as_mut()
            .map(|b| buffer("position gradient buffer", b, &[x.n, self.dims()]))
            .transpose()?;
        self.gradients_flat(&x, &g, grid_out, positions_out);
        Ok(())
    }

    /// Checks the backward's inputs; the upstream gradient, flat.
    fn check_vjp<'a, F: Float>(
        &self,
        grid: &'a ArrayViewD<'_, F>,
        positions: &'a ArrayViewD<'_, F>,
        upstream: &'a ArrayViewD<'_, F>,
    ) -> Result<(Checked<'a, F>, Cow<'a, [F]>), OpsError> {
        let x = self.check(grid, positions)?;
        let ch = self.channels();
        if upstream.shape() != [x.n, ch] {
            return Err(OpsError::Shape {
                op: Op::GridField,
                what: "upstream gradient",
                expected: format!("[{}, {ch}]", x.n),
                got: format!("{:?}", upstream.shape()),
            });
        }
        Ok((x, flat(upstream)))
    }

    fn gradients_flat<F: Float>(
        &self,
        x: &Checked<'_, F>,
        upstream: &[F],
        grid_out: Option<&mut [F]>,
        positions_out: Option<&mut [F]>,
    ) {
        match self.dims() {
            2 => self.gradients(
                &Layout::<2>::new(&self.bbox, self.nodes()),
                x,
                upstream,
                grid_out,
                positions_out,
            ),
            _ => self.gradients(
                &Layout::<3>::new(&self.bbox, self.nodes()),
                x,
                upstream,
                grid_out,
                positions_out,
            ),
        }
    }

    fn gradients<F: Float, const D: usize>(
        &self,
        layout: &Layout<D>,
        x: &Checked<'_, F>,
        upstream: &[F],
        grid_out: Option<&mut [F]>,
        positions_out: Option<&mut [F]>,
    ) {
        let ch = self.channels();
        if let Some(out) = grid_out {
            grid_gradient(layout, &x.positions, upstream, ch, out, &self.scratch);
        }
        if let Some(out) = positions_out {
            position_gradient(layout, &x.grid, &x.positions, upstream, ch, out);
        }
    }
}

impl<F: Float> CustomOp<F> for GridField {
    /// Nothing: the backward recomputes each position's cell and weights from the inputs the
    /// tape keeps anyway.
    type Saved = ();

    fn name(&self) -> &'static str {
        Op::GridField.name()
    }

    fn forward(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<(Vec<ArrayD<F>>, ()), OpError> {
        let [grid, positions] = inputs else {
            return Err(OpError::InvalidArgument(format!(
                "takes 2 inputs, got {}",
                inputs.len()
            )));
        };
        Ok((vec![self.evaluate(grid, positions)?], ()))
    }

    fn backward(
        &self,
        ctx: &BackwardCtx<'_, F, ()>,
        grads: &[Option<ArrayViewD<'_, F>>],
    ) -> Result<Vec<Option<ArrayD<F>>>, OpError> {
        let Some(g) = &grads[0] else {
            return Ok(vec![None, None]);
        };
        let wanted = GridWanted {
            grid: ctx.needs_input_grad(0),
            positions: ctx.needs_input_grad(1),
        };
        let out = self.vjp(&ctx.input(0), &ctx.input(1), g, wanted)?;
        Ok(vec![out.grid, out.positions])
    }
}
