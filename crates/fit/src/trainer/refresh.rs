//! The occupancy policy: after each step the occupancy grid is refreshed from the model's
//! density when its [`Refresh`](fogray_ops::sample::Refresh) says the step is due, at the
//! cells' centres and one random point each (the random points drawn from the step number, so
//! that a resumed fit refreshes as the uninterrupted one did).

use fogray_ops::sample::CellPoints;
use fogray_tape::Float;

use crate::error::FitError;
use crate::model::RadianceField;
use crate::trainer::policy::{StepContext, StepPolicy};

/// Refreshes the occupancy grid when due; never leaves it empty.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(crate) struct OccupancyRefresh;

impl<F: Float, M: RadianceField<F>> StepPolicy<F, M> for OccupancyRefresh {
    fn after_step(&mut self, at: &mut StepContext<'_, F, M>) -> Result<(), FitError> {
        let Some(grid) = at.occupancy.as_mut() else {
            return Ok(());
        };
        let model = &*at.model;
        let points = CellPoints::CentreAndRandom { seed: at.step as u64 };
        let refreshed = grid.update_every_n_steps(at.step, |p| model.densities(p), points)?;
        // A refresh before any density has reached the threshold (a slow learning rate, a
        // faint scene) would empty every cell, and a grid with no sample left never trains
        // again: until some cell is above the threshold, every cell stays occupied.
        if refreshed && grid.occupied_fraction() == 0.0 {
            grid.occupy_all();
        }
        Ok(())
    }
}
