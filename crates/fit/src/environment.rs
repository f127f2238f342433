//! A background the fit learns, for captures without alpha (phone photographs): what lies
//! beyond the scene's box is seen as an environment at infinity, a colour that depends on the
//! ray's direction alone, `sigmoid(sum_b k[c B + b] Y_b(d))` with the spherical harmonics of
//! a degree from 0 to 3 (`FitSettings::background_degree`; [`ShColor`], one set of
//! coefficients for the whole scene, learned with the grid). Without it such a capture's
//! background must be painted into the box (haze at its walls) or stays an error the fit
//! cannot remove.

use fogray_ops::ShColor;
use fogray_tape::params::Params;
use fogray_tape::{Float, Tape, TapeError, Var};
use ndarray::{Array2, ArrayView2};

use crate::error::FitError;
use crate::shading::Shading;

/// The name of the coefficients `[1, 3 (degree + 1)^2]` in a model's parameter store and a
/// checkpoint.
pub(crate) const ENVIRONMENT: &str = "environment";

/// The learned background's colour model (its coefficients are a model's parameter).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Environment {
    colour: ShColor,
}

impl Environment {
    /// The environment of spherical harmonics of `degree`: 0 (one colour from every
    /// direction) to 3. Degree 2 holds a sky brighter than the ground and a window on one
    /// side; 3 follows a room's walls a little further (reports/grid/capture.md).
    ///
    /// Errors: [`FitError::SettingOp`] for a degree above 3, naming the flag.
    pub(crate) fn new(degree: usize) -> Result<Self, FitError> {
        let colour = ShColor::new(degree).map_err(|source| FitError::SettingOp {
            flag: "--background-degree",
            source,
        })?;
        Ok(Environment { colour })
    }

    /// Values of its coefficients: 3 channels of `(degree + 1)^2`.
    pub(crate) fn coefficient_count(&self) -> usize {
        self.colour.coefficient_count()
    }

    /// Records the colour `[R, 3]` behind each of `R` rays of unit `directions` (`[R, 3]`, a
    /// constant) for the coefficients `coefficients` (`[1, 3 B]`, on the tape): each ray reads
    /// the same row, so the backward sums the rays' gradients into it.
    ///
    /// Errors: from the ops (coefficients not `[1, 3 B]`, a direction that is not a unit
    /// vector).
    pub(crate) fn record<F: Float>(
        &self,
        tape: &mut Tape<F>,
        coefficients: Var,
        directions: ArrayView2<'_, F>,
    ) -> Result<Var, TapeError> {
        let rows = tape.gather(coefficients, &vec![0; directions.nrows()])?;
        let directions = tape.constant(directions.to_owned());
        self.colour.apply(tape, rows, directions)
    }

    /// The colour `[R, 3]` seen along unit `directions` (`[R, 3]`) for `coefficients`
    /// (`[1, 3 B]`), without a tape.
    ///
    /// Errors: [`FitError::Config`] for coefficients not `[1, 3 B]`; the op's errors.
    #[cfg(test)]
    pub(crate) fn colors<F: Float>(
        &self,
        coefficients: ArrayView2<'_, F>,
        directions: ArrayView2<'_, F>,
    ) -> Result<Array2<F>, FitError> {
        if coefficients.dim() != (1, self.coefficient_count()) {
            return Err(FitError::Config(format!(
                "environment coefficients: expected [1, {}], got {:?}",
                self.coefficient_count(),
                coefficients.shape()
            )));
        }
        let row = coefficients.row(0);
        let rows = Array2::from_shape_fn((directions.nrows(), row.len()), |(_, k)| row[k]);
        Ok(self.colour.evaluate(rows.view(), directions).map_err(TapeError::from)?)
    }
}

/// Adds the coefficients of `shading`'s learned background to `params` as [`ENVIRONMENT`],
/// all 0 (grey from every direction); nothing for a shading without one. A model finds them
/// again by that name.
///
/// Errors: the store already has a parameter of that name.
pub(crate) fn add_environment<F: Float>(params: &mut Params<F>, shading: &Shading) -> Result<(), FitError> {
    if let Some(e) = shading.environment {
        params.add(ENVIRONMENT, Array2::<F>::zeros((1, e.coefficient_count())))?;
    }
    Ok(())
}

/// The learned background's coefficients in `params` lent to `tape`; `None` for a model
/// without one.
///
/// Errors: from the tape.
pub(crate) fn environment_on_tape<F: Float>(tape: &mut Tape<F>, params: &Params<F>) -> Result<Option<Var>, TapeError> {
    params.id(ENVIRONMENT).map(|id| tape.param_from(params, id)).transpose()
}

/// A grown model keeps the background it learned: `from`'s coefficients into `to`'s.
///
/// Errors: one store has them and the other not.
pub(crate) fn copy_environment<F: Float>(from: &Params<F>, to: &mut Params<F>) -> Result<(), FitError> {
    match (from.id(ENVIRONMENT), to.id(ENVIRONMENT)) {
        (None, None) => Ok(()),
        (Some(a), Some(b)) => {
            let values = from.get(a)?.to_owned();
            to.get_mut(b)?.assign(&values);
            Ok(())
        }
        _ => Err(FitError::Config(
            "a grown model must keep the learned background exactly when the model had one".into(),
        )),
    }
}

#[cfg(test)]
mod tests;
