//! The model: a dense `N^3` grid over `[-1, 1]^3` of raw density and raw RGB, looked up
//! trilinearly by fogray-ops' grid field, activated (density `softplus(raw + shift)`, colour
//! `sigmoid(raw)`, view-independent) and composited over packed samples, either with the fused
//! ops or with their taped twins.
//!
//! ```
//! use fogray::ops::rays::{Aabb, RayBatch};
//! use fogray::ops::sample::{Spacing, Uniform};
//! use fogray::tape::Tape;
//! use fogray_grid::model::{GridModel, Method};
//! use ndarray::arr2;
//!
//! let model = GridModel::<f32>::new(8, -4.0)?;
//! let rays = RayBatch::new(arr2(&[[0.0f32, -3.0, 0.0]]), arr2(&[[0.0f32, 1.0, 0.0]]))?;
//! let clip = Aabb::new([-1.0; 3], [1.0; 3])?.clip(&rays);
//! let samples = Uniform::new(Spacing::Step(model.voxel() / 2.0))?.sample(&rays, &clip)?;
//! let mut tape = Tape::new();
//! let color = model.render(&mut tape, samples, [1.0, 1.0, 1.0], Method::Fused)?;
//! // A fresh grid is a thin grey fog: density softplus(-4) = 0.018 over a length of 2.
//! let c = tape.value(color)?[[0, 0]];
//! assert!(c > 0.98 && c < 1.0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use fogray::ops::activation::{twin, DensityColor};
use fogray::ops::sample::PackedSamples;
use fogray::ops::{twins, ActivationError, Composite, CompositeInputs, CompositeVars, GridBox, GridError, GridField};
use fogray::tape::params::{ParamId, Params};
use fogray::tape::{Float, Tape, TapeError, Var};
use ndarray::{Array1, Array2, Array4, ArrayView2, Ix2, IxDyn};

/// Channels of a raw grid value: density, then red, green, blue.
pub const CHANNELS: usize = 4;

/// The box the grid covers.
pub const BOUNDS: ([f64; 3], [f64; 3]) = ([-1.0; 3], [1.0; 3]);

fn param_error(e: fogray::tape::params::ParamError) -> GridError {
    GridError::Shape {
        what: "grid",
        expected: "the model's parameter, not lent to a tape".into(),
        got: e.to_string(),
    }
}

/// The activation's error in the model's error type: the model's API predates the fused
/// activation, and its callers only report these (a non-finite shift, a NaN in the grid).
fn field_error(e: &ActivationError) -> GridError {
    GridError::Shape {
        what: "density/colour activation",
        expected: "a finite shift and raw values without NaN".into(),
        got: e.to_string(),
    }
}

/// Which implementation of the grid lookup and the composite a render records.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// The fused ops (one record each, hand-written backwards).
    Fused,
    /// Their taped twins (built from tape primitives).
    Taped,
}

/// A dense grid of raw density and colour, its parameters kept in a [`Params`] store.
#[derive(Debug)]
pub struct GridModel<F: Float> {
    params: Params<F>,
    grid: ParamId,
    field: GridField,
    activation: DensityColor,
    nodes: usize,
}

impl<F: Float> GridModel<F> {
    /// A grid of `nodes^3` nodes (at least 2) over `[-1, 1]^3`, every raw value 0: density
    /// `softplus(shift)` and colour grey (0.5) everywhere.
    ///
    /// Errors ([`GridError`]): fewer than 2 nodes, more than memory can address, or a shift
    /// that is not finite.
    pub fn new(nodes: usize, shift: f64) -> Result<Self, GridError> {
        let field = GridField::new(GridBox::new(&BOUNDS.0, &BOUNDS.1)?, &[nodes, nodes, nodes, CHANNELS])?;
        let mut params = Params::new();
        let grid = params
            .add("grid", Array4::<F>::zeros((nodes, nodes, nodes, CHANNELS)))
            .map_err(|e| GridError::Shape {
                what: "grid",
                expected: "a new parameter".into(),
                got: e.to_string(),
            })?;
        Ok(GridModel {
            params,
            grid,
            field,
            activation: DensityColor::new(shift).map_err(|e| field_error(&e))?,
            nodes,
        })
    }

    /// The same field on a grid of `nodes^3` nodes: each new node takes the trilinear
    /// interpolation of this grid's raw values at its position (coarse-to-fine growth).
    ///
    /// Errors: as [`GridModel::new`].
    pub fn resampled(&self, nodes: usize) -> Result<Self, GridError> {
        let mut grown = GridModel::<F>::new(nodes, self.activation.shift())?;
        let spacing = grown.voxel();
        let at = |i: usize| F::lit(BOUNDS.0[0] + i as f64 * spacing);
        let positions = Array2::from_shape_fn((nodes * nodes * nodes, 3), |(p, axis)| match axis {
            0 => at(p / (nodes * nodes)),
            1 => at(p / nodes % nodes),
            _ => at(p % nodes),
        });
        let grid = self.params.get(self.grid).map_err(param_error)?;
        let raw = self.field.evaluate(&grid, &positions.view().into_dyn())?;
        let raw = raw
            .into_shape_with_order(IxDyn(&[nodes, nodes, nodes, CHANNELS]))
            .map_err(|e| GridError::Shape {
                what: "resampled grid",
                expected: format!("[{nodes}, {nodes}, {nodes}, {CHANNELS}]"),
                got: e.to_string(),
            })?;
        grown.params.get_mut(grown.grid).map_err(param_error)?.assign(&raw);
        Ok(grown)
    }

    /// Nodes per axis.
    pub fn nodes(&self) -> usize {
        self.nodes
    }

    /// The spacing of the nodes, `2 / (nodes - 1)`.
    pub fn voxel(&self) -> f64 {
        2.0 / (self.nodes - 1) as f64
    }

    /// The parameter store (one parameter, the raw grid `[N, N, N, 4]`).
    pub fn params(&self) -> &Params<F> {
        &self.params
    }

    /// The parameter store, for an optimiser's step.
    pub fn params_mut(&mut self) -> &mut Params<F> {
        &mut self.params
    }

    /// The raw grid's id in the store.
    pub fn grid_id(&self) -> ParamId {
        self.grid
    }

    /// Records the render of `samples` on `tape`: lends the grid to the tape (no copy) and
    /// renders it with [`GridModel::render_grid`]. Returns the colours `[R, 3]`, one row per
    /// ray of `samples`.
    ///
    /// Errors: from the ops (a tape error naming the op), or the grid already lent elsewhere.
    pub fn render(
        &self,
        tape: &mut Tape<F>,
        samples: PackedSamples<F>,
        background: [f64; 3],
        method: Method,
    ) -> Result<Var, TapeError> {
        let grid = tape.param_from(&self.params, self.grid)?;
        self.render_grid(tape, grid, samples, background, method)
    }

    /// Records the render of `samples` from the raw grid `grid` (a tape value of shape
    /// `[N, N, N, 4]`, this model's or any other): looks it up at the sample positions,
    /// activates and composites over `background`. Returns the colours `[R, 3]`.
    ///
    /// The samples move onto the tape ([`PackedSamples::into_tape`]): a training step's are
    /// megabytes, which a copy would spend the step's one-threaded part on.
    ///
    /// Errors: from the ops (a tape error naming the op).
    pub fn render_grid(
        &self,
        tape: &mut Tape<F>,
        grid: Var,
        samples: PackedSamples<F>,
        background: [f64; 3],
        method: Method,
    ) -> Result<Var, TapeError> {
        let (op, inputs) = self.composite_inputs(tape, grid, samples, background, method)?;
        let out = match method {
            Method::Fused => op.apply(tape, &inputs)?,
            Method::Taped => twins::stable(tape, &op, &inputs)?,
        };
        Ok(out.color)
    }

    /// Records the photometric loss of a training step: the render of `samples` from the raw
    /// grid `grid` (as [`GridModel::render_grid`]) and its mean squared error against `target`
    /// (`[R, 3]`), `mean((C - target)^2)`, a 0-d value. The fused method records the composite
    /// and the loss as one op ([`Composite::apply_mse`], one pass per ray for forward and
    /// backward); the taped one the stable twin, then `sub`, `square` and `mean`. Both give the
    /// same numbers up to the twins' rounding.
    ///
    /// Errors: as [`GridModel::render_grid`], and a target of the wrong shape.
    pub fn photometric_loss(
        &self,
        tape: &mut Tape<F>,
        grid: Var,
        samples: PackedSamples<F>,
        background: [f64; 3],
        target: Var,
        method: Method,
    ) -> Result<Var, TapeError> {
        let (op, inputs) = self.composite_inputs(tape, grid, samples, background, method)?;
        match method {
            Method::Fused => op.apply_mse(tape, &inputs, target),
            Method::Taped => {
                let color = twins::stable(tape, &op, &inputs)?.color;
                let residual = tape.sub(color, target)?;
                let squared = tape.square(residual)?;
                tape.mean(squared)
            }
        }
    }

    /// Records the lookup of `samples` in `grid` and the activation, and returns the composite
    /// over the samples' rays with its inputs (the background `background`, shared).
    fn composite_inputs(
        &self,
        tape: &mut Tape<F>,
        grid: Var,
        samples: PackedSamples<F>,
        background: [f64; 3],
        method: Method,
    ) -> Result<(Composite, CompositeInputs), TapeError> {
        let (vars, offsets) = samples.into_tape(tape);
        let raw = match method {
            Method::Fused => self.field.apply(tape, grid, vars.positions)?,
            Method::Taped => fogray::ops::grid::twin::lookup(tape, &self.field, grid, vars.positions)?,
        };
        let activated = match method {
            Method::Fused => self.activation.apply(tape, raw)?,
            Method::Taped => twin::density_color(tape, &self.activation, raw)?,
        };
        let inputs = CompositeInputs {
            sigma: activated.sigma,
            delta: vars.delta,
            color: activated.color,
            background: Some(tape.constant(Array1::from_iter(background.map(F::lit)))),
            t: None,
        };
        Ok((Composite::packed(offsets), inputs))
    }

    /// Records the render of `samples` with the fused ops, as [`GridModel::render`] does, and
    /// also the composite's expected depth `sum w_k t_k` of each ray (unnormalised; divide by
    /// the opacity for the depth given that the ray stops). Returns the composite's outputs:
    /// colour `[R, 3]`, opacity `[R]`, depth `[R]`.
    ///
    /// Errors: as [`GridModel::render`].
    pub fn render_with_depth(
        &self,
        tape: &mut Tape<F>,
        samples: PackedSamples<F>,
        background: [f64; 3],
    ) -> Result<CompositeVars, TapeError> {
        let grid = tape.param_from(&self.params, self.grid)?;
        let (vars, offsets) = samples.into_tape(tape);
        let raw = self.field.apply(tape, grid, vars.positions)?;
        let activated = self.activation.apply(tape, raw)?;
        let inputs = CompositeInputs {
            sigma: activated.sigma,
            delta: vars.delta,
            color: activated.color,
            background: Some(tape.constant(Array1::from_iter(background.map(F::lit)))),
            t: Some(vars.t),
        };
        Composite::packed(offsets).with_depth().apply(tape, &inputs)
    }

    /// The density at `positions` (`[m, 3]`), without a tape: for the occupancy grid and for
    /// slices. A position outside the box reads raw 0 (density `softplus(shift)`).
    ///
    /// Errors: as [`GridField::evaluate`], and a NaN raw density (a diverged fit).
    pub fn densities(&self, positions: ArrayView2<'_, F>) -> Result<Array1<F>, GridError> {
        let grid = self.params.get(self.grid).map_err(|e| GridError::Shape {
            what: "grid",
            expected: "the model's parameter".into(),
            got: e.to_string(),
        })?;
        let raw = self.field.evaluate(&grid, &positions.into_dyn())?;
        let raw = raw.into_dimensionality::<Ix2>().map_err(|e| GridError::Shape {
            what: "raw values",
            expected: format!("[m, {CHANNELS}]"),
            got: e.to_string(),
        })?;
        self.activation.density(raw.view()).map_err(|e| field_error(&e))
    }
}
