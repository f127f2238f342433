//! The grid field op's configuration (the box and the grid's shape) and how it is applied to
//! a tape.

use fogray_tape::{Float, Tape, TapeError, Var};

use super::geometry::GridBox;
use super::scratch::Scratch;
use crate::error::{Op, OpsError};

/// A dense grid of `C` channels over a [`GridBox`], looked up at packed positions: bilinear in
/// 2-D, trilinear in 3-D (see the [module docs](super) for the conventions).
///
/// Holds the box and the grid's shape; the grid values and the positions are tape values
/// passed to [`GridField::apply`] (or arrays passed to [`GridField::evaluate`]).
///
/// It also keeps the working memory of its backward into the grid between calls (about
/// `(D + C)` values per lookup, and 8 bytes per grid value for its f64 sums), shared with its
/// clones, so that a training loop's steps reuse it instead of faulting in fresh pages;
/// [`GridField::release_buffers`] gives it back.
#[derive(Debug, Clone, PartialEq)]
pub struct GridField {
    pub(crate) bbox: GridBox,
    /// `[n0, n1, (n2,) C]`.
    pub(crate) shape: Vec<usize>,
    pub(crate) scratch: Scratch,
}

/// Which gradients [`GridField::vjp`] computes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct GridWanted {
    /// The gradient of the grid values.
    pub grid: bool,
    /// The gradient of the positions.
    pub positions: bool,
}

/// The gradients [`GridField::vjp`] returns, each `Some` where it was wanted.
#[derive(Debug, Clone, PartialEq)]
pub struct GridGradients<F: Float> {
    /// `dL/dgrid`, the grid's shape.
    pub grid: Option<ndarray::ArrayD<F>>,
    /// `dL/dpositions`, `[n, D]`.
    pub positions: Option<ndarray::ArrayD<F>>,
}

/// Buffers [`GridField::vjp_into`] writes the gradients into: each `Some` is a gradient
/// wanted, a contiguous array in standard (row-major) order whose every value is overwritten.
#[derive(Debug)]
pub struct GridGradientBuffers<'a, F> {
    /// `dL/dgrid`, the grid's shape.
    pub grid: Option<ndarray::ArrayViewMutD<'a, F>>,
    /// `dL/dpositions`, `[n, D]`.
    pub positions: Option<ndarray::ArrayViewMutD<'a, F>>,
}

impl GridField {
    /// A field over `bbox` whose grid values have shape `shape`: `[n0, n1, n2, C]` for a 3-D
    /// box, `[n0, n1, C]` for a 2-D one (channels last; axis 0 along x).
    ///
    /// Errors ([`OpsError::Shape`]): `shape` without exactly one entry more than the box has
    /// axes, an axis with fewer than 2 nodes (zero included), no channel, or more values than
    /// memory can address.
    pub fn new(bbox: GridBox, shape: &[usize]) -> Result<Self, OpsError> {
        let dims = bbox.dims();
        let fail = |expected: String| OpsError::Shape {
            op: Op::GridField,
            what: "grid shape",
            expected,
            got: format!("{shape:?}"),
        };
        if shape.len() != dims + 1 {
            return Err(fail(format!("{} entries (nodes per axis, then channels)", dims + 1)));
        }
        if let Some(a) = shape[..dims].iter().position(|&n| n < 2) {
            return Err(fail(format!(
                "at least 2 nodes on every axis (axis {a} has {})",
                shape[a]
            )));
        }
        if shape[dims] == 0 {
            return Err(fail("at least one channel".into()));
        }
        let size = shape.iter().try_fold(1usize, |acc, &n| acc.checked_mul(n));
        if size.is_none_or(|s| s > isize::MAX as usize / 8) {
            return Err(fail("fewer values than memory can address".into()));
        }
        Ok(GridField {
            bbox,
            shape: shape.to_vec(),
            scratch: Scratch::default(),
        })
    }

    /// Drops the working memory the backward keeps between calls (for this field and its
    /// clones); the next backward allocates it again.
    pub fn release_buffers(&self) {
        self.scratch.release();
    }

    /// The box.
    pub fn bbox(&self) -> &GridBox {
        &self.bbox
    }

    /// Number of axes (2 or 3).
    pub fn dims(&self) -> usize {
        self.bbox.dims()
    }

    /// Nodes per axis.
    pub fn nodes(&self) -> &[usize] {
        &self.shape[..self.dims()]
    }

    /// Channels per node (`C`).
    pub fn channels(&self) -> usize {
        self.shape[self.dims()]
    }

    /// The grid values' shape, `[n0, n1, (n2,) C]`.
    pub fn shape(&self) -> &[usize] {
        &self.shape
    }

    /// Records the lookup of `grid` (of [`GridField::shape`]) at `positions` (`[n, D]`) on
    /// `tape`, through the tape's public custom-op interface; the output is `[n, C]`. Its
    /// backward gives the gradients of the grid values and of the positions, each where the
    /// tape needs it.
    ///
    /// Errors (the tape is unchanged): the shapes do not fit the op, or a position has a NaN
    /// coordinate (the [`OpsError`] itself inside [`TapeError::Op`], read back with
    /// [`TapeError::downcast_ref`]), or a
    /// handle is stale.
    pub fn apply<F: Float>(&self, tape: &mut Tape<F>, grid: Var, positions: Var) -> Result<Var, TapeError> {
        tape.apply1(self.clone(), &[grid, positions])
    }
}
