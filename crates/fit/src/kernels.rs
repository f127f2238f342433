//! The fused-or-taped choice, made once: [`Method::kernels`] gives the value that records
//! every op a model uses (the composite and its loss, the activation, the spherical-harmonics
//! colour, the distortion loss, the grid lookups), either as fogray-ops' fused ops with their
//! hand-written backwards or as their taped twins built from tape primitives. A model records
//! through [`Kernels`] and never asks which it has.

use fogray_ops::activation::twin;
use fogray_ops::{
    twins, ActivatedVars, Composite, CompositeInputs, CompositeVars, DensityColor, DistortionLoss, GridField, ShColor,
    SparseGridField,
};
use fogray_tape::{Float, Tape, TapeError, Var};

use crate::settings::Method;

/// The ops a model records, with their arguments as the fused ops take them.
pub(crate) trait Kernels<F: Float> {
    /// The composite's colour, opacity and (if configured) depth: [`Composite::apply`].
    fn composite(
        &self,
        tape: &mut Tape<F>,
        op: &Composite,
        inputs: &CompositeInputs,
    ) -> Result<CompositeVars, TapeError>;
    /// The mean squared error of the composite's colour against `target`:
    /// [`Composite::apply_mse`].
    fn composite_mse(
        &self,
        tape: &mut Tape<F>,
        op: &Composite,
        inputs: &CompositeInputs,
        target: Var,
    ) -> Result<Var, TapeError>;
    /// Density and view-independent colour from raw values: [`DensityColor::apply`].
    fn density_color(&self, tape: &mut Tape<F>, op: &DensityColor, raw: Var) -> Result<ActivatedVars, TapeError>;
    /// Colour from spherical-harmonics coefficients and directions: [`ShColor::apply`].
    fn sh_color(&self, tape: &mut Tape<F>, op: &ShColor, coefficients: Var, directions: Var) -> Result<Var, TapeError>;
    /// mip-NeRF 360's distortion loss of the samples' weights: [`DistortionLoss::apply`].
    fn distortion(
        &self,
        tape: &mut Tape<F>,
        op: &DistortionLoss,
        sigma: Var,
        delta: Var,
        t: Var,
    ) -> Result<Var, TapeError>;
    /// The dense grid's trilinear lookup: [`GridField::apply`].
    fn grid_lookup(&self, tape: &mut Tape<F>, field: &GridField, grid: Var, positions: Var) -> Result<Var, TapeError>;
    /// The sparse grid's trilinear lookup: [`SparseGridField::apply`].
    fn sparse_lookup(
        &self,
        tape: &mut Tape<F>,
        field: &SparseGridField,
        data: Var,
        positions: Var,
    ) -> Result<Var, TapeError>;
}

/// fogray-ops' fused ops: one record each, hand-written backwards.
struct Fused;

/// The ops' taped twins: the same values and gradients from tape primitives (the composite's
/// stable twin: transmittance from the running optical depth).
struct Taped;

impl Method {
    /// The kernels of this method.
    pub(crate) fn kernels<F: Float>(self) -> &'static dyn Kernels<F> {
        match self {
            Method::Fused => &Fused,
            Method::Taped => &Taped,
        }
    }
}

impl<F: Float> Kernels<F> for Fused {
    fn composite(
        &self,
        tape: &mut Tape<F>,
        op: &Composite,
        inputs: &CompositeInputs,
    ) -> Result<CompositeVars, TapeError> {
        op.apply(tape, inputs)
    }
    fn composite_mse(
        &self,
        tape: &mut Tape<F>,
        op: &Composite,
        inputs: &CompositeInputs,
        target: Var,
    ) -> Result<Var, TapeError> {
        op.apply_mse(tape, inputs, target)
    }
    fn density_color(&self, tape: &mut Tape<F>, op: &DensityColor, raw: Var) -> Result<ActivatedVars, TapeError> {
        op.apply(tape, raw)
    }
    fn sh_color(&self, tape: &mut Tape<F>, op: &ShColor, coefficients: Var, directions: Var) -> Result<Var, TapeError> {
        op.apply(tape, coefficients, directions)
    }
    fn distortion(
        &self,
        tape: &mut Tape<F>,
        op: &DistortionLoss,
        sigma: Var,
        delta: Var,
        t: Var,
    ) -> Result<Var, TapeError> {
        op.apply(tape, sigma, delta, t)
    }
    fn grid_lookup(&self, tape: &mut Tape<F>, field: &GridField, grid: Var, positions: Var) -> Result<Var, TapeError> {
        field.apply(tape, grid, positions)
    }
    fn sparse_lookup(
        &self,
        tape: &mut Tape<F>,
        field: &SparseGridField,
        data: Var,
        positions: Var,
    ) -> Result<Var, TapeError> {
        field.apply(tape, data, positions)
    }
}

impl<F: Float> Kernels<F> for Taped {
    fn composite(
        &self,
        tape: &mut Tape<F>,
        op: &Composite,
        inputs: &CompositeInputs,
    ) -> Result<CompositeVars, TapeError> {
        twins::stable(tape, op, inputs)
    }
    /// The stable twin's colour, then `sub`, `square` and `mean`.
    fn composite_mse(
        &self,
        tape: &mut Tape<F>,
        op: &Composite,
        inputs: &CompositeInputs,
        target: Var,
    ) -> Result<Var, TapeError> {
        let color = twins::stable(tape, op, inputs)?.color;
        let residual = tape.sub(color, target)?;
        let squared = tape.square(residual)?;
        tape.mean(squared)
    }
    fn density_color(&self, tape: &mut Tape<F>, op: &DensityColor, raw: Var) -> Result<ActivatedVars, TapeError> {
        twin::density_color(tape, op, raw)
    }
    fn sh_color(&self, tape: &mut Tape<F>, op: &ShColor, coefficients: Var, directions: Var) -> Result<Var, TapeError> {
        fogray_ops::sh::twin::sh_color(tape, op, coefficients, directions)
    }
    fn distortion(
        &self,
        tape: &mut Tape<F>,
        op: &DistortionLoss,
        sigma: Var,
        delta: Var,
        t: Var,
    ) -> Result<Var, TapeError> {
        fogray_ops::distortion::twin::distortion_loss(tape, op, sigma, delta, t)
    }
    fn grid_lookup(&self, tape: &mut Tape<F>, field: &GridField, grid: Var, positions: Var) -> Result<Var, TapeError> {
        fogray_ops::grid::twin::lookup(tape, field, grid, positions)
    }
    fn sparse_lookup(
        &self,
        tape: &mut Tape<F>,
        field: &SparseGridField,
        data: Var,
        positions: Var,
    ) -> Result<Var, TapeError> {
        fogray_ops::grid::sparse::twin::lookup(tape, field, data, positions)
    }
}
