//! The sparse grid field: its configuration, its tape-free forward and backward, and the
//! op the tape records.

use std::sync::Arc;

use fogray_tape::buffer::scratch;
use fogray_tape::{BackwardCtx, CustomOp, Float, OpError, Tape, TapeError, Var};
use ndarray::{ArrayD, ArrayViewD};

use super::super::geometry::{GridBox, Layout};
use super::super::op::{array, check_positions, flat};
use super::super::scratch::Scratch;
use super::super::{GridGradients, GridWanted};
use super::index::NodeIndex;
use super::kernels::{forward, position_gradient};
use super::scatter::data_gradient;
use crate::error::{Op, OpsError};

/// A 3-D grid of `C` channels over a [`GridBox`] that stores only the nodes its
/// [`NodeIndex`] keeps, as packed values `[kept, C]`, looked up trilinearly at packed
/// positions with the conventions of [`GridField`](crate::GridField); a node that is not
/// stored reads 0 (see the [module docs](super)).
///
/// Cheap to clone (the index is shared); like the dense field it keeps its backward's f64
/// sums between calls ([`SparseGridField::release_buffers`]).
#[derive(Debug, Clone, PartialEq)]
pub struct SparseGridField {
    bbox: GridBox,
    index: Arc<NodeIndex>,
    channels: usize,
    scratch: Scratch,
}

impl SparseGridField {
    /// The field over the 3-D box `bbox` of the nodes `index` keeps, `channels` per node.
    ///
    /// Errors ([`OpsError::Shape`]): a 2-D box, no channel, or more values than memory can
    /// address.
    pub fn new(bbox: GridBox, index: NodeIndex, channels: usize) -> Result<Self, OpsError> {
        if bbox.dims() != 3 {
            return Err(OpsError::Shape {
                op: Op::SparseGridField,
                what: "sparse grid box",
                expected: "3 axes".into(),
                got: format!("{} axes", bbox.dims()),
            });
        }
        if channels == 0
            || index
                .kept()
                .checked_mul(channels)
                .is_none_or(|v| v > isize::MAX as usize / 8)
        {
            return Err(OpsError::Shape {
                op: Op::SparseGridField,
                what: "sparse grid channels",
                expected: "at least one, and fewer values than memory can address".into(),
                got: channels.to_string(),
            });
        }
        Ok(SparseGridField {
            bbox,
            index: Arc::new(index),
            channels,
            scratch: Scratch::default(),
        })
    }

    /// The box.
    pub fn bbox(&self) -> &GridBox {
        &self.bbox
    }

    /// Which nodes are stored, and their rows.
    pub fn index(&self) -> &NodeIndex {
        &self.index
    }

    /// Channels per node (`C`).
    pub fn channels(&self) -> usize {
        self.channels
    }

    /// The packed values' shape, `[kept, C]`.
    pub fn data_shape(&self) -> [usize; 2] {
        [self.index.kept(), self.channels]
    }

    /// Drops the working memory the backward keeps between calls.
    pub fn release_buffers(&self) {
        self.scratch.release();
    }

    fn layout(&self) -> Layout<3> {
        Layout::<3>::new(&self.bbox, &self.index.nodes())
    }

    fn check_data<F: Float>(&self, data: &ArrayViewD<'_, F>) -> Result<(), OpsError> {
        if data.shape() != self.data_shape() {
            return Err(OpsError::Shape {
                op: Op::SparseGridField,
                what: "sparse grid values",
                expected: format!("{:?}", self.data_shape()),
                got: format!("{:?}", data.shape()),
            });
        }
        Ok(())
    }

    /// Looks the packed values `data` (`[kept, C]`) up at `positions` (`[n, 3]`): `[n, C]`.
    /// A position outside the box reads 0; a corner that is not stored adds nothing.
    ///
    /// Errors: the shapes do not fit ([`OpsError::Shape`]), a NaN coordinate
    /// ([`OpsError::Domain`], the first one).
    pub fn evaluate<F: Float>(
        &self,
        data: &ArrayViewD<'_, F>,
        positions: &ArrayViewD<'_, F>,
    ) -> Result<ArrayD<F>, OpsError> {
        self.check_data(data)?;
        let (positions, n) = check_positions(Op::SparseGridField, positions, 3)?;
        let mut out = scratch(n * self.channels);
        forward(
            &self.layout(),
            &self.index,
            &flat(data),
            &positions,
            self.channels,
            &mut out,
        );
        array(Op::SparseGridField, &[n, self.channels], out)
    }

    /// The gradients of a loss with `upstream = dL/doutput` (`[n, C]`) for the lookup of
    /// `data` at `positions`, those `wanted` (`grid` is the packed values' gradient,
    /// `[kept, C]`). Bitwise the same for any number of threads.
    ///
    /// Errors: as [`SparseGridField::evaluate`], and an upstream gradient not `[n, C]`.
    pub fn vjp<F: Float>(
        &self,
        data: &ArrayViewD<'_, F>,
        positions: &ArrayViewD<'_, F>,
        upstream: &ArrayViewD<'_, F>,
        wanted: GridWanted,
    ) -> Result<GridGradients<F>, OpsError> {
        self.check_data(data)?;
        let (positions, n) = check_positions(Op::SparseGridField, positions, 3)?;
        let ch = self.channels;
        if upstream.shape() != [n, ch] {
            return Err(OpsError::Shape {
                op: Op::SparseGridField,
                what: "upstream gradient",
                expected: format!("[{n}, {ch}]"),
                got: format!("{:?}", upstream.shape()),
            });
        }
        let upstream = flat(upstream);
        let layout = self.layout();
        let grid = if wanted.grid {
            let mut out = scratch(self.index.kept() * ch);
            data_gradient(&layout, &self.index, &positions, &upstream, ch, &mut out, &self.scratch);
            Some(array(Op::SparseGridField, &self.data_shape(), out)?)
        } else {
            None
        };
        let positions = if wanted.positions {
            let mut out = scratch(n * 3);
            position_gradient(&layout, &self.index, &flat(data), &positions, &upstream, ch, &mut out);
            Some(array(Op::SparseGridField, &[n, 3], out)?)
        } else {
            None
        };
        Ok(GridGradients { grid, positions })
    }

    /// Records the lookup of `data` (`[kept, C]`) at `positions` (`[n, 3]`) on `tape`; the
    /// output is `[n, C]`, its backward reaches the values and the positions.
    ///
    /// Errors (the tape is unchanged): as [`SparseGridField::evaluate`] (the [`OpsError`]
    /// inside [`TapeError::Op`]), or a stale handle.
    pub fn apply<F: Float>(&self, tape: &mut Tape<F>, data: Var, positions: Var) -> Result<Var, TapeError> {
        tape.apply1(self.clone(), &[data, positions])
    }
}

impl<F: Float> CustomOp<F> for SparseGridField {
    /// Nothing: the backward recomputes each position's cell from the inputs.
    type Saved = ();

    fn name(&self) -> &'static str {
        Op::SparseGridField.name()
    }

    fn forward(&self, inputs: &[ArrayViewD<'_, F>]) -> Result<(Vec<ArrayD<F>>, ()), OpError> {
        let [data, positions] = inputs else {
            return Err(OpError::InvalidArgument(format!(
                "takes 2 inputs, got {}",
                inputs.len()
            )));
        };
        Ok((vec![self.evaluate(data, positions)?], ()))
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
