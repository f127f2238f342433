//! Work written once, generic over the model and its float type, run with the types that a
//! fit's settings (its [`Precision`] and [`ModelKind`]) or a model file's kind name: the one
//! place where the pipeline's model types are listed, so that a command line, an example and
//! a sweep dispatch the same way.
//!
//! A model kind is of one of two classes: a field of density and colour marched along rays
//! ([`RadianceField`]: what every command that renders, meshes or resumes a model file
//! handles, run by [`with_field_kind`]), or the splats, drawn by projection, which only a fit's
//! session runs. A [`FieldKind`] is the one check: from a fit's [`ModelKind`] by `try_from`,
//! which refuses the splats, or from a model file's kind name by [`FieldKind::of_kind`]; so
//! that work on fields is never asked of them, [`with_field_kind`] takes only a `FieldKind`
//! and has nothing left to refuse.
//!
//! ```
//! use fogray_fit::dispatch::{with_field_kind, FieldKind, FieldWork};
//! use fogray_fit::model::RadianceField;
//! use fogray_fit::settings::{ModelKind, Precision};
//! use fogray_tape::Float;
//!
//! /// The kind name of the model type, and the bytes of its float.
//! struct Describe;
//!
//! impl FieldWork for Describe {
//!     type Output = (&'static str, usize);
//!     fn run<F: Float, M: RadianceField<F>>(self) -> Self::Output {
//!         (M::KIND, std::mem::size_of::<F>())
//!     }
//! }
//!
//! let sparse = FieldKind::try_from(ModelKind::Sparse)?;
//! assert_eq!(with_field_kind(Precision::F64, sparse, Describe), ("sparse-grid", 8));
//! assert!(FieldKind::try_from(ModelKind::Splats).is_err());
//! let kind = FieldKind::of_kind("dense-grid").ok_or("not a field's kind")?;
//! assert_eq!(with_field_kind(Precision::F32, kind, Describe), ("dense-grid", 4));
//! assert_eq!(FieldKind::of_kind("splats"), None);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use fogray_tape::Float;

use crate::dense::DenseGrid;
use crate::error::FitError;
use crate::model::RadianceField;
use crate::settings::{ModelKind, Precision};
use crate::sparse::SparseGrid;

/// The model kinds that are fields marched along rays: what a model file holds
/// ([`FieldKind::of_kind`]), run by [`with_field_kind`] with no error left to give.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FieldKind {
    /// [`DenseGrid`].
    Dense,
    /// [`SparseGrid`].
    Sparse,
}

/// Work to run with one field type `M` in one float type `F`.
pub trait FieldWork {
    /// What the work gives (a `Result` for work that can fail).
    type Output;
    /// Does the work with models of type `M` in `F`.
    fn run<F: Float, M: RadianceField<F>>(self) -> Self::Output;
}

/// Work to run in one float type `F` (a model class that is not a field, such as the splats).
pub(crate) trait FloatWork {
    /// What the work gives.
    type Output;
    /// Does the work in `F`.
    fn run<F: Float>(self) -> Self::Output;
}

/// Runs `work` with the field type of `kind` in the float type of `precision`.
pub fn with_field_kind<W: FieldWork>(precision: Precision, kind: FieldKind, work: W) -> W::Output {
    match (precision, kind) {
        (Precision::F32, FieldKind::Dense) => work.run::<f32, DenseGrid<f32>>(),
        (Precision::F64, FieldKind::Dense) => work.run::<f64, DenseGrid<f64>>(),
        (Precision::F32, FieldKind::Sparse) => work.run::<f32, SparseGrid<f32>>(),
        (Precision::F64, FieldKind::Sparse) => work.run::<f64, SparseGrid<f64>>(),
    }
}

/// Runs `work` in the float type of `precision`.
pub(crate) fn with_float<W: FloatWork>(precision: Precision, work: W) -> W::Output {
    match precision {
        Precision::F32 => work.run::<f32>(),
        Precision::F64 => work.run::<f64>(),
    }
}

impl ModelKind {
    /// The field kind of a model marched along rays; `None` for the splats.
    pub(crate) fn field(self) -> Option<FieldKind> {
        match self {
            ModelKind::Dense => Some(FieldKind::Dense),
            ModelKind::Sparse => Some(FieldKind::Sparse),
            ModelKind::Splats => None,
        }
    }
}

impl TryFrom<ModelKind> for FieldKind {
    type Error = FitError;

    /// The field kind of a model marched along rays. Errors: [`FitError::NotAField`] for the
    /// splats.
    fn try_from(kind: ModelKind) -> Result<FieldKind, FitError> {
        kind.field().ok_or(FitError::NotAField(kind))
    }
}

impl FieldKind {
    /// The field kind whose model type has [`RadianceField::KIND`] `kind` (a model file's
    /// `model` entry, [`ModelInfo::kind`](crate::checkpoint::ModelInfo::kind)); `None` for a
    /// kind the pipeline does not know as a field, the splats' included (a splat fit is saved
    /// as a 3DGS PLY file, never as a model file).
    pub fn of_kind(kind: &str) -> Option<FieldKind> {
        [FieldKind::Dense, FieldKind::Sparse]
            .into_iter()
            .find(|&f| with_field_kind(Precision::F32, f, KindName) == kind)
    }
}

/// [`RadianceField::KIND`] of the model type.
struct KindName;

impl FieldWork for KindName {
    type Output = &'static str;
    fn run<F: Float, M: RadianceField<F>>(self) -> &'static str {
        M::KIND
    }
}
