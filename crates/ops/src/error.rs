//! The ops' one error type: [`OpsError`] names the op it came from, and the ray and sample
//! (or row, or cell) at fault where there is one.

use std::fmt;

use fogray_tape::{OffsetsError, OpError, TapeError};
use thiserror::Error;

/// The op (or family of constructors) an [`OpsError`] came from. Its [`name`](Op::name) is
/// the one the tape reports, so an error reads the same whether it came through a tape or not.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Op {
    /// The emission-absorption composite ([`Composite`](crate::Composite)).
    Composite,
    /// The composite fused with its MSE against target colours.
    CompositeMse,
    /// The hard "first hit" renderer ([`hard::first_hit`](crate::hard::first_hit)).
    FirstHit,
    /// The distortion loss ([`DistortionLoss`](crate::DistortionLoss)) and its twin.
    DistortionLoss,
    /// A dense grid field ([`GridField`](crate::GridField)) and its box ([`GridBox`](crate::GridBox)).
    GridField,
    /// A sparse grid field ([`SparseGridField`](crate::SparseGridField)) and its
    /// [`NodeIndex`](crate::NodeIndex).
    SparseGridField,
    /// The density/colour activation ([`DensityColor`](crate::DensityColor)).
    DensityColor,
    /// The spherical-harmonics colour ([`ShColor`](crate::ShColor)).
    ShColor,
    /// The total-variation prior on a dense grid.
    TotalVariation,
    /// The total-variation prior on a sparse grid.
    SparseTotalVariation,
    /// Cameras, boxes, orbits and batches of rays ([`rays`](crate::rays)).
    Rays,
    /// The samplers and their packed samples ([`sample`](crate::sample)).
    Sample,
    /// The occupancy grid ([`OccupancyGrid`](crate::sample::OccupancyGrid)).
    Occupancy,
    /// The scene contraction and the framing of its inner region from cameras
    /// ([`space`](crate::space)).
    Contraction,
    /// 3D Gaussian splatting: projection, binning, rasterisation and the fused
    /// [`SplatRender`](crate::splat::SplatRender).
    Splat,
}

impl Op {
    /// The op's name, as the tape and the messages write it (`"composite"`, `"grid_field"`...).
    pub fn name(self) -> &'static str {
        match self {
            Op::Composite => "composite",
            Op::CompositeMse => "composite_mse",
            Op::FirstHit => "first_hit",
            Op::DistortionLoss => "distortion_loss",
            Op::GridField => "grid_field",
            Op::SparseGridField => "sparse_grid_field",
            Op::DensityColor => "density_color",
            Op::ShColor => "sh_color",
            Op::TotalVariation => "total_variation",
            Op::SparseTotalVariation => "sparse_total_variation",
            Op::Rays => "rays",
            Op::Sample => "sample",
            Op::Occupancy => "occupancy",
            Op::Contraction => "contraction",
            Op::Splat => "splat",
        }
    }
}

impl fmt::Display for Op {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Where in the input a value outside its domain sits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum At {
    /// A single value, not one of many (a focal length, a box's near bound...).
    Value,
    /// A per-ray value (its interval, its weights, a background).
    Ray(usize),
    /// A sample of a ray (the sample's index within its ray).
    Sample {
        /// Ray index.
        ray: usize,
        /// Sample index within the ray.
        sample: usize,
    },
    /// A cell of the occupancy grid (its flat index).
    Cell(usize),
    /// An entry of a matrix input (a row is a sample or a position).
    Entry {
        /// Row.
        row: usize,
        /// Column (a channel, a coefficient, a coordinate).
        column: usize,
    },
}

/// The prefix of a message: empty for a single value, `"ray 0, sample 3: "` otherwise.
impl fmt::Display for At {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            At::Value => Ok(()),
            At::Ray(ray) => write!(f, "ray {ray}: "),
            At::Sample { ray, sample } => write!(f, "ray {ray}, sample {sample}: "),
            At::Cell(cell) => write!(f, "cell {cell}: "),
            At::Entry { row, column } => write!(f, "row {row}, column {column}: "),
        }
    }
}

/// Why an op, a sampler or a constructor of this crate rejected its input or its
/// configuration. Nothing is computed, and nothing of the caller's is changed, when one is
/// returned.
///
/// Every case names its [`Op`], and the message begins with the op's name. Through a tape it
/// arrives inside [`TapeError::Op`], whole: `err.downcast_ref::<OpsError>()` gives back the op,
/// the ray and the sample. It converts into a [`TapeError`] (and an [`OpError`]), so `?` works
/// in a function that mixes tape calls and op calls.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum OpsError {
    /// The offsets are not a valid packing (must start at 0 and never decrease).
    #[error("{op}: offsets: {source}")]
    Offsets {
        /// The op.
        op: Op,
        /// What is wrong with them.
        source: OffsetsError,
    },
    /// An array's (or a grid's) length or shape does not fit the op's, or another input's.
    #[error("{op}: {what}: expected {expected}, got {got}")]
    Shape {
        /// The op.
        op: Op,
        /// Which input, output or setting.
        what: &'static str,
        /// What is required.
        expected: String,
        /// What was given.
        got: String,
    },
    /// A value outside its domain (NaN, infinite, a negative density or step, a zero focal
    /// length...).
    #[error("{op}: {at}{what} is {value} ({rule})")]
    Domain {
        /// The op.
        op: Op,
        /// Where it sits: the ray and sample, the row and column, the cell.
        at: At,
        /// Which input (`sigma`, `color[1]`, `background[0]`, `t_near`...).
        what: String,
        /// The offending value.
        value: f64,
        /// The rule it breaks.
        rule: &'static str,
    },
    /// A configuration value outside its domain (a step that is not positive, a degree
    /// above 3, a negative weight...).
    #[error("{op}: {what} is {value} ({rule})")]
    Config {
        /// The op.
        op: Op,
        /// Which setting.
        what: &'static str,
        /// The offending value.
        value: f64,
        /// The rule it breaks.
        rule: &'static str,
    },
    /// An optional input, upstream gradient, buffer or wanted gradient that the op's
    /// configuration requires and was not given, or that it has no use for and was given (a
    /// background with [`Background::None`](crate::Background::None), `t` without depth...).
    #[error("{op}: {what}: {problem}")]
    Mismatch {
        /// The op.
        op: Op,
        /// Which argument (`"background"`, `"t"`, `"depth buffer"`, ...).
        what: &'static str,
        /// What is wrong with it, given the configuration.
        problem: &'static str,
    },
    /// A box whose bounds are not finite or not increasing on some axis.
    #[error("{op}: box axis {axis}: [{min}, {max}] (must be finite with min < max)")]
    Box {
        /// The op.
        op: Op,
        /// Axis (0 = x, 1 = y, 2 = z).
        axis: usize,
        /// Lower bound given.
        min: f64,
        /// Upper bound given.
        max: f64,
    },
    /// An image with no pixel (`width` or `height` is 0).
    #[error("{op}: image size {width}x{height}: both must be at least 1")]
    EmptyImage {
        /// The op.
        op: Op,
        /// Pixels per row.
        width: usize,
        /// Rows.
        height: usize,
    },
    /// A pixel or camera index out of range.
    #[error("{op}: {what} {index} is out of range (must be below {len})")]
    OutOfRange {
        /// The op.
        op: Op,
        /// `"pixel"` or `"camera"`.
        what: &'static str,
        /// The index given.
        index: usize,
        /// The number of valid indices.
        len: usize,
    },
    /// A camera-to-world transform that cannot place a camera, or a `look_at` whose eye,
    /// target and up do not define a frame.
    #[error("{op}: {what}: {problem}")]
    Frame {
        /// The op.
        op: Op,
        /// `"camera-to-world transform"` or `"look_at"`.
        what: &'static str,
        /// What is wrong with it (the entry, the last row, the determinant, the vectors).
        problem: String,
    },
    /// A direction whose length is not 1 within `1e-3`.
    #[error("{op}: direction at row {row} has length {norm} (must be 1 within 1e-3)")]
    NotUnit {
        /// The op.
        op: Op,
        /// Row (sample).
        row: usize,
        /// Its Euclidean length.
        norm: f64,
    },
    /// More (splat, tile) pairs than the bound the op was given: the tiles' lists, and the
    /// backward's buffers that grow with them, would be allocated past it.
    #[error("{op}: {count} splat-tile intersections exceed the limit of {limit}")]
    TooManyIntersections {
        /// The op.
        op: Op,
        /// The number of pairs the splats make.
        count: u64,
        /// The bound.
        limit: u64,
    },
    /// The caller's density function failed or returned something unusable.
    #[error("{op}: density function: {problem}")]
    Density {
        /// The op.
        op: Op,
        /// The function's own error, or what is wrong with what it returned.
        problem: String,
    },
}

/// `$body` with `$op` bound to the op field of `$error` (every variant has one), so that the
/// list of variants is written once.
macro_rules! with_op {
    ($error:expr, $op:ident => $body:expr) => {
        match $error {
            OpsError::Offsets { $op, .. }
            | OpsError::Shape { $op, .. }
            | OpsError::Domain { $op, .. }
            | OpsError::Config { $op, .. }
            | OpsError::Mismatch { $op, .. }
            | OpsError::Box { $op, .. }
            | OpsError::EmptyImage { $op, .. }
            | OpsError::OutOfRange { $op, .. }
            | OpsError::Frame { $op, .. }
            | OpsError::NotUnit { $op, .. }
            | OpsError::Density { $op, .. }
            | OpsError::TooManyIntersections { $op, .. } => $body,
        }
    };
}

impl OpsError {
    /// The op the error came from.
    pub fn op(&self) -> Op {
        with_op!(self, op => *op)
    }

    /// The same error, naming `to` instead: a check shared by two ops (the composite's, run by
    /// the fused composite + MSE) reports the op that ran it.
    pub(crate) fn in_op(mut self, to: Op) -> Self {
        with_op!(&mut self, op => *op = to);
        self
    }

    /// A shape error (the shorthand every check uses).
    pub(crate) fn shape(op: Op, what: &'static str, expected: impl Into<String>, got: impl Into<String>) -> Self {
        OpsError::Shape {
            op,
            what,
            expected: expected.into(),
            got: got.into(),
        }
    }

    /// A shape error naming the shape given (`got`, printed as `[a, b]`).
    pub(crate) fn shape_of(op: Op, what: &'static str, expected: impl Into<String>, got: &[usize]) -> Self {
        OpsError::shape(op, what, expected, format!("{got:?}"))
    }

    /// A configuration error.
    pub(crate) fn config(op: Op, what: &'static str, value: f64, rule: &'static str) -> Self {
        OpsError::Config { op, what, value, rule }
    }

    /// A value outside its domain.
    pub(crate) fn domain(op: Op, at: At, what: impl Into<String>, value: f64, rule: &'static str) -> Self {
        OpsError::Domain {
            op,
            at,
            what: what.into(),
            value,
            rule,
        }
    }
}

/// The error whole, for a custom op's forward or backward to report.
impl From<OpsError> for OpError {
    fn from(e: OpsError) -> Self {
        OpError::typed(e)
    }
}

/// The error whole inside [`TapeError::Op`], under its op's name.
impl From<OpsError> for TapeError {
    fn from(e: OpsError) -> Self {
        TapeError::from_op(e.op().name(), OpError::typed(e))
    }
}

#[cfg(test)]
mod tests;
