//! The dense grid: `N^3` nodes over the scene's box (`[-1, 1]^3` unless the settings name
//! another) of raw density and raw RGB, looked up
//! trilinearly by fogray-ops' grid field, activated (density `softplus(raw + shift)`, colour
//! `sigmoid(raw)`, view-independent) and composited over packed samples, either with the fused
//! ops or with their taped twins; a total-variation prior on the raw grid joins the training
//! loss. It suits small scenes: its memory and a step's cost grow with `N^3`.
//!
//! ```
//! use fogray_fit::dense::DenseGrid;
//! use fogray_fit::model::{RadianceField, RenderWanted};
//! use fogray_fit::settings::{FitSettings, Method};
//! use fogray_ops::rays::RayBatch;
//! use fogray_ops::sample::{Spacing, Uniform};
//! use fogray_tape::Tape;
//! use ndarray::arr2;
//!
//! let model = DenseGrid::<f32>::fresh(&FitSettings::default(), 8)?;
//! let rays = RayBatch::new(arr2(&[[0.0f32, -3.0, 0.0]]), arr2(&[[0.0f32, 1.0, 0.0]]))?;
//! let clip = model.bounds().clip(&rays);
//! let samples = Uniform::new(Spacing::Step(model.sample_step()))?.sample(&rays, &clip)?;
//! let mut tape = Tape::new();
//! let out = model.render(&mut tape, &rays, samples, [1.0; 3], Method::Fused, RenderWanted::default())?;
//! // A fresh grid is a thin grey fog: density softplus(-4) = 0.018 over a length of 2.
//! let c = tape.value(out.color)?[[0, 0]];
//! assert!(c > 0.98 && c < 1.0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use fogray_ops::prior::TotalVariation;
use fogray_ops::rays::{Aabb, RayBatch};
use fogray_ops::sample::{OccupancyGrid, PackedSamples};
use fogray_ops::space::Contraction;
use fogray_ops::{CompositeVars, GridBox, GridField};
use fogray_tape::params::{ParamId, Params};
use fogray_tape::{Float, Tape, TapeError, Var};
use ndarray::{Array1, Array2, Array4, ArrayView2, IxDyn};

use crate::environment::{add_environment, copy_environment};
use crate::error::FitError;
use crate::grid_model::GridModel;
use crate::model::{RadianceField, RenderWanted, TrainingBackground, TrainingLoss};
use crate::settings::{FitSettings, Method, SceneBox};
use crate::shading::Shading;
use crate::space::FieldSpace;

/// The name of the raw grid `[N, N, N, 4]` in the parameter store (and in a checkpoint).
pub(crate) const GRID: &str = "grid";

/// A dense grid of raw density and colour, its parameters kept in a [`Params`] store.
#[derive(Debug)]
pub struct DenseGrid<F: Float> {
    params: Params<F>,
    grid: ParamId,
    field: GridField,
    shading: Shading,
    prior: TotalVariation,
    bounds: Aabb,
    nodes: usize,
    /// Weight of the distortion loss in the training objective (0: none).
    distortion: f64,
    /// The contraction its box is the image of, for a field of all of space.
    contraction: Option<Contraction>,
}

impl<F: Float> DenseGrid<F> {
    /// The same grid over the contracted cube of `contraction` (its box must be
    /// [`Contraction::cube`]); `None` for a field of its box.
    pub(crate) fn with_contraction(mut self, contraction: Option<Contraction>) -> Self {
        self.contraction = contraction;
        self
    }

    /// The same grid with the distortion loss (mip-NeRF 360's, over each training ray's
    /// sample weights) weighted by `weight` in its training objective.
    ///
    /// Errors: a weight that is negative or not finite.
    pub(crate) fn with_distortion(mut self, weight: f64) -> Result<Self, FitError> {
        if !(weight.is_finite() && weight >= 0.0) {
            return Err(FitError::Setting {
                flag: "--distortion",
                value: Some(weight.to_string()),
                rule: "must be finite and non-negative".into(),
            });
        }
        self.distortion = weight;
        Ok(self)
    }

    /// A grid of `nodes^3` nodes (at least 2) over `scene_box`, every raw value 0: density
    /// `softplus(shift)` and colour grey (0.5) everywhere; `smoothness` weighs its
    /// total-variation prior (0 for none).
    ///
    /// Errors: fewer than 2 nodes, more than memory can address, a bad box, a shift that is
    /// not finite, a smoothness that is negative or not finite.
    pub fn new(scene_box: SceneBox, nodes: usize, shift: f64, smoothness: f64) -> Result<Self, FitError> {
        Self::with_shading(scene_box, nodes, Shading::new(shift, 0)?, smoothness)
    }

    /// The grid of [`DenseGrid::new`] with a view-dependent colour: spherical harmonics of
    /// `degree` 1 to 3 ([`ShColor`]), `3 (degree + 1)^2` coefficients a node after the density,
    /// all 0 (grey from every direction); degree 0 is [`DenseGrid::new`]'s view-independent
    /// colour.
    ///
    /// Errors: as [`DenseGrid::new`], and a degree above 3.
    #[cfg(test)]
    pub(crate) fn view_dependent(
        scene_box: SceneBox,
        nodes: usize,
        shift: f64,
        smoothness: f64,
        degree: usize,
    ) -> Result<Self, FitError> {
        Self::with_shading(scene_box, nodes, Shading::new(shift, degree)?, smoothness)
    }

    fn with_shading(scene_box: SceneBox, nodes: usize, shading: Shading, smoothness: f64) -> Result<Self, FitError> {
        scene_box.check()?;
        let channels = shading.channels();
        let field = GridField::new(
            GridBox::new(&scene_box.min, &scene_box.max)?,
            &[nodes, nodes, nodes, channels],
        )?;
        let mut params = Params::new();
        let grid = params.add(GRID, Array4::<F>::zeros((nodes, nodes, nodes, channels)))?;
        add_environment(&mut params, &shading)?;
        let prior = TotalVariation::new(smoothness).map_err(|source| FitError::SettingOp { flag: "--tv", source })?;
        Ok(DenseGrid {
            bounds: Aabb::new(scene_box.min, scene_box.max)?,
            params,
            grid,
            field,
            shading,
            prior,
            nodes,
            distortion: 0.0,
            contraction: None,
        })
    }

    /// Channels of a raw value: the density, then the colour's (3, or the spherical
    /// harmonics' coefficients).
    pub(crate) fn channels(&self) -> usize {
        self.shading.channels()
    }

    /// The box the grid covers.
    pub(crate) fn scene_box(&self) -> SceneBox {
        SceneBox {
            min: self.bounds.min(),
            max: self.bounds.max(),
        }
    }

    /// The raw grid's id in the store.
    pub fn grid_id(&self) -> ParamId {
        self.grid
    }

    /// The raw values `[m, C]` at `positions` (`[m, 3]`), looked up without a tape.
    fn raw_values(&self, positions: ArrayView2<'_, F>) -> Result<ndarray::ArrayD<F>, FitError> {
        let grid = self.params.get(self.grid)?;
        Ok(self.field.evaluate(&grid, &positions.into_dyn())?)
    }
}

impl<F: Float> RadianceField<F> for DenseGrid<F> {
    const KIND: &'static str = "dense-grid";

    fn fresh(settings: &FitSettings, nodes: usize) -> Result<Self, FitError> {
        Ok(
            DenseGrid::with_shading(settings.model_box(), nodes, Shading::of(settings)?, settings.tv)?
                .with_distortion(settings.distortion)?
                .with_contraction(settings.field_space()?.contraction()),
        )
    }

    /// Each new node takes the trilinear interpolation of this grid's raw values at its
    /// position.
    fn resampled(&self, nodes: usize, _occupancy: Option<&OccupancyGrid>) -> Result<Self, FitError> {
        let scene_box = self.scene_box();
        let mut grown = DenseGrid::<F>::with_shading(scene_box, nodes, self.shading, self.prior.weight())?
            .with_distortion(self.distortion)?
            .with_contraction(self.contraction);
        let channels = self.channels();
        let at = |i: usize, axis: usize| {
            let (lo, hi) = (scene_box.min[axis], scene_box.max[axis]);
            let spacing = (hi - lo) / (nodes - 1) as f64;
            F::lit(lo + i as f64 * spacing)
        };
        let positions = Array2::from_shape_fn((nodes * nodes * nodes, 3), |(p, axis)| match axis {
            0 => at(p / (nodes * nodes), 0),
            1 => at(p / nodes % nodes, 1),
            _ => at(p % nodes, 2),
        });
        let grid = self.params.get(self.grid)?;
        let raw = self.field.evaluate(&grid, &positions.view().into_dyn())?;
        let raw = raw
            .into_shape_with_order(IxDyn(&[nodes, nodes, nodes, channels]))
            .map_err(|e| FitError::Config(format!("resampled grid: {e}")))?;
        grown.params.get_mut(grown.grid)?.assign(&raw);
        copy_environment(&self.params, &mut grown.params)?;
        Ok(grown)
    }

    fn nodes(&self) -> usize {
        self.nodes
    }

    fn bounds(&self) -> Aabb {
        self.bounds
    }

    fn space(&self) -> FieldSpace {
        match self.contraction {
            Some(c) => FieldSpace::Contracted(c),
            None => FieldSpace::Box(self.bounds),
        }
    }

    /// Half the spacing of the nodes along the box's shortest side (`1 / (nodes - 1)` for
    /// `[-1, 1]^3`).
    fn sample_step(&self) -> f64 {
        self.scene_box().half_node_spacing(self.nodes)
    }

    fn params(&self) -> &Params<F> {
        &self.params
    }

    fn params_mut(&mut self) -> &mut Params<F> {
        &mut self.params
    }

    fn render(
        &self,
        tape: &mut Tape<F>,
        rays: &RayBatch<F>,
        samples: PackedSamples<F>,
        background: [f64; 3],
        method: Method,
        wanted: RenderWanted,
    ) -> Result<CompositeVars, TapeError> {
        self.render_grid(tape, rays, samples, background, method, wanted)
    }

    /// The fused method records the composite and the loss as one op
    /// ([`Composite::apply_mse`](fogray_ops::Composite::apply_mse), one pass per ray for forward and backward); the taped one
    /// the stable twin, then `sub`, `square` and `mean`.
    fn training_loss(
        &self,
        tape: &mut Tape<F>,
        rays: &RayBatch<F>,
        samples: PackedSamples<F>,
        background: TrainingBackground<F>,
        target: Var,
        method: Method,
    ) -> Result<TrainingLoss, TapeError> {
        self.training_loss_grid(tape, rays, samples, background, target, method)
    }

    /// A position outside the box reads raw 0 (density `softplus(shift)`).
    fn densities(&self, positions: ArrayView2<'_, F>) -> Result<Array1<F>, FitError> {
        self.shading.densities(self.raw_values(positions)?)
    }

    /// A position outside the box reads raw 0 (grey).
    fn base_colors(&self, positions: ArrayView2<'_, F>) -> Result<Array2<F>, FitError> {
        self.shading.base_colors(self.raw_values(positions)?)
    }
}

impl<F: Float> GridModel<F> for DenseGrid<F> {
    fn values(&self) -> (&Params<F>, ParamId) {
        (&self.params, self.grid)
    }

    fn shading(&self) -> &Shading {
        &self.shading
    }

    fn distortion(&self) -> f64 {
        self.distortion
    }

    fn lookup(&self, tape: &mut Tape<F>, grid: Var, positions: Var, method: Method) -> Result<Var, TapeError> {
        method.kernels().grid_lookup(tape, &self.field, grid, positions)
    }

    fn prior(&self, tape: &mut Tape<F>, grid: Var) -> Result<Option<Var>, TapeError> {
        if self.prior.weight() > 0.0 {
            Ok(Some(self.prior.apply(tape, grid)?))
        } else {
            Ok(None)
        }
    }
}

#[cfg(test)]
pub(crate) mod tests;
