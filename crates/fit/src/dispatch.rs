//! Work written once, generic over the model and its float type, run with the types that a
//! fit's settings (its [`Precision`] and [`ModelKind`]) or a model file's kind name: the one
//! place where the pipeline's model types are listed, so that a command line, an example and
//! a sweep dispatch the same way.
//!
//! ```
//! use fogray_fit::dispatch::{with_model, ModelWork};
//! use fogray_fit::settings::{ModelKind, Precision};
//! use fogray_fit::RadianceField;
//! use fogray_tape::Float;
//!
//! /// The kind name of the model type, and the bytes of its float.
//! struct Describe;
//!
//! impl ModelWork for Describe {
//!     type Output = (&'static str, usize);
//!     fn run<F: Float, M: RadianceField<F>>(self) -> Self::Output {
//!         (M::KIND, std::mem::size_of::<F>())
//!     }
//!     fn run_splats<F: Float>(self) -> Self::Output {
//!         ("splats", std::mem::size_of::<F>())
//!     }
//! }
//!
//! assert_eq!(with_model(Precision::F64, ModelKind::Sparse, Describe), ("sparse-grid", 8));
//! assert_eq!(ModelKind::of_kind("dense-grid"), Some(ModelKind::Dense));
//! ```

use fogray_tape::Float;

use crate::dense::DenseGrid;
use crate::model::RadianceField;
use crate::settings::{ModelKind, Precision};
use crate::sparse::SparseGrid;
use crate::splats::SplatModel;

/// Work to run with one model type `M` in one float type `F`: a radiance field marched along
/// rays, or the splats, which are drawn by projection and have a work of their own.
pub trait ModelWork {
    /// What the work gives (a `Result` for work that can fail).
    type Output;
    /// Does the work with models of type `M` in `F`.
    fn run<F: Float, M: RadianceField<F>>(self) -> Self::Output;
    /// Does the work with [`SplatModel`]s in `F`.
    fn run_splats<F: Float>(self) -> Self::Output;
}

/// Runs `work` with the model type of `kind` in the float type of `precision`.
pub fn with_model<W: ModelWork>(precision: Precision, kind: ModelKind, work: W) -> W::Output {
    match (precision, kind) {
        (Precision::F32, ModelKind::Dense) => work.run::<f32, DenseGrid<f32>>(),
        (Precision::F64, ModelKind::Dense) => work.run::<f64, DenseGrid<f64>>(),
        (Precision::F32, ModelKind::Sparse) => work.run::<f32, SparseGrid<f32>>(),
        (Precision::F64, ModelKind::Sparse) => work.run::<f64, SparseGrid<f64>>(),
        (Precision::F32, ModelKind::Splats) => work.run_splats::<f32>(),
        (Precision::F64, ModelKind::Splats) => work.run_splats::<f64>(),
    }
}

impl ModelKind {
    /// The kind whose model type has [`RadianceField::KIND`] `kind` (a model file's `model`
    /// entry, [`ModelInfo::kind`](crate::checkpoint::ModelInfo::kind)); `None` for a kind the
    /// pipeline does not know.
    pub fn of_kind(kind: &str) -> Option<ModelKind> {
        [ModelKind::Dense, ModelKind::Sparse, ModelKind::Splats]
            .into_iter()
            .find(|k| with_model(Precision::F32, *k, KindName) == kind)
    }
}

/// [`RadianceField::KIND`] of the model type.
struct KindName;

impl ModelWork for KindName {
    type Output = &'static str;
    fn run<F: Float, M: RadianceField<F>>(self) -> &'static str {
        M::KIND
    }
    fn run_splats<F: Float>(self) -> &'static str {
        SplatModel::<F>::KIND
    }
}
