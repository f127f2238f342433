//! What the training loop, the renderer and the checkpoints ask of a radiance field: its
//! parameters, how to record a render and a training loss on a tape, its density without a
//! tape (for the occupancy grid), and how it grows coarse to fine. [`DenseGrid`] is the first
//! implementation.
//!
//! [`DenseGrid`]: crate::dense::DenseGrid

use fogray_ops::rays::{Aabb, RayBatch};
use fogray_ops::sample::{KnownCells, OccupancyGrid, PackedSamples};
use fogray_ops::CompositeVars;
use fogray_tape::params::Params;
use fogray_tape::{Float, Tape, TapeError, Var};
use ndarray::{Array1, Array2, ArrayView2};

use crate::error::FitError;
use crate::settings::{FitSettings, Method};
use crate::space::FieldSpace;

/// What a training step records: the photometric loss alone (for the log) and the objective
/// the backward starts from (the loss plus the model's own priors).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TrainingLoss {
    /// `mean((C - target)^2)` over rays and channels, a 0-d value.
    pub photometric: Var,
    /// The photometric loss plus the model's priors, a 0-d value.
    pub objective: Var,
}

/// What a training loss composites its rays over.
#[derive(Debug, Clone, PartialEq)]
pub enum TrainingBackground<F> {
    /// One colour behind every ray (the dataset's background).
    Shared([f64; 3]),
    /// A colour behind each ray, `[R, 3]` in the rays' order (a random background per ray,
    /// with targets composited over the same colours).
    PerRay(Array2<F>),
}

/// Which outputs a render records beyond the colour.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RenderWanted {
    /// The unnormalised expected depth `sum w_k t_k` of each ray.
    pub depth: bool,
}

/// A radiance field the pipeline can fit, render and save (and hand, copied, to a viewer's
/// threads: [`crate::live`]).
pub trait RadianceField<F: Float>: Sized + Send + Sync + 'static {
    /// The name of the model in a checkpoint's metadata.
    const KIND: &'static str;

    /// Whether [`RadianceField::resampled`] keeps only what the occupancy grid marks occupied:
    /// the training loop then grows such a model only once the occupancy grid has been
    /// refreshed from the current stage (a growth before that would keep every node).
    const PRUNED_BY_OCCUPANCY: bool = false;

    /// A fresh model for `settings` with `nodes` per axis (a growth stage's resolution).
    ///
    /// Errors: a resolution or setting the model cannot take.
    fn fresh(settings: &FitSettings, nodes: usize) -> Result<Self, FitError>;

    /// The same field at `nodes` per axis (coarse-to-fine growth); a model that stores only
    /// the space a scene needs reads what is empty from `occupancy` (the fit's occupancy grid,
    /// refreshed from this model), others ignore it.
    ///
    /// Errors: as [`RadianceField::fresh`].
    fn resampled(&self, nodes: usize, occupancy: Option<&OccupancyGrid>) -> Result<Self, FitError>;

    /// Masks beyond the parameters that a checkpoint keeps to rebuild the model (a sparse
    /// grid's kept nodes), by name, one entry per lattice node; none by default.
    fn structure(&self) -> Vec<(&'static str, Vec<bool>)> {
        Vec::new()
    }

    /// The model of `settings` at `nodes` per axis, every parameter 0, rebuilt with the masks
    /// [`RadianceField::structure`] gave (looked up by name); [`RadianceField::fresh`] by
    /// default.
    ///
    /// Errors: as [`RadianceField::fresh`], and a mask that is missing or of the wrong size.
    fn with_structure(
        settings: &FitSettings,
        nodes: usize,
        structure: &dyn Fn(&str) -> Option<Vec<bool>>,
    ) -> Result<Self, FitError> {
        let _ = structure;
        Self::fresh(settings, nodes)
    }

    /// The cells of `occupancy` where this model's density is one known constant (a sparse
    /// grid's pruned space), so that a refresh evaluates only the others
    /// ([`OccupancyGrid::set_known_cells`]); none by default.
    ///
    /// Errors: from the density (a NaN density).
    fn known_cells(&self, occupancy: &OccupancyGrid) -> Result<Option<KnownCells>, FitError> {
        let _ = occupancy;
        Ok(None)
    }

    /// Nodes per axis.
    fn nodes(&self) -> usize;

    /// The box the field covers; it is empty outside.
    fn bounds(&self) -> Aabb;

    /// The space the field lives in and samples in: its box by default, or the contracted
    /// cube of an unbounded field ([`FieldSpace`]).
    fn space(&self) -> FieldSpace {
        FieldSpace::Box(self.bounds())
    }

    /// The spacing of samples along a ray that resolves the field (half a voxel for a grid).
    fn sample_step(&self) -> f64;

    /// The trainable parameters, by name (a checkpoint saves each under its name).
    fn params(&self) -> &Params<F>;

    /// The trainable parameters, for an optimiser's step or a checkpoint's load.
    fn params_mut(&mut self) -> &mut Params<F>;

    /// Records the render of `samples` of `rays` (whose directions a view-dependent colour
    /// reads) over `background`: colour `[R, 3]`, opacity `[R]` and, if wanted, the depth.
    /// The samples move onto the tape.
    ///
    /// Errors: from the ops (a tape error naming the op).
    fn render(
        &self,
        tape: &mut Tape<F>,
        rays: &RayBatch<F>,
        samples: PackedSamples<F>,
        background: [f64; 3],
        method: Method,
        wanted: RenderWanted,
    ) -> Result<CompositeVars, TapeError>;

    /// Records a training step's loss against `target` (`[R, 3]`) of the render over
    /// `background` (shared, or one per ray), with the parameters lent to the tape, so that the
    /// backward reaches them. The fused and taped methods record the same function.
    ///
    /// Errors: from the ops, or a target or per-ray background of the wrong shape.
    fn training_loss(
        &self,
        tape: &mut Tape<F>,
        rays: &RayBatch<F>,
        samples: PackedSamples<F>,
        background: TrainingBackground<F>,
        target: Var,
        method: Method,
    ) -> Result<TrainingLoss, TapeError>;

    /// The density at `positions` (`[m, 3]`), without a tape: for the occupancy grid, slices
    /// and meshes.
    ///
    /// Errors: from the ops, or a NaN density (a diverged fit).
    fn densities(&self, positions: ArrayView2<'_, F>) -> Result<Array1<F>, FitError>;

    /// The view-independent colour `[m, 3]` at `positions` (`[m, 3]`), without a tape: for a
    /// mesh's vertex colours, which no view direction goes with (with spherical harmonics,
    /// the degree-0 term through the colour activation).
    ///
    /// Errors: from the ops, or a NaN raw value (a diverged fit).
    fn base_colors(&self, positions: ArrayView2<'_, F>) -> Result<Array2<F>, FitError>;
}

#[cfg(test)]
mod tests;
