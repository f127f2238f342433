//! The growth policy: a grid trained coarse to fine, resampled to the next stage's nodes per
//! axis when the budget's fraction reaches it ([`growth_stages`]), with a fresh Adam (its
//! moments belong to the old lattice).

use fogray_tape::optim::Adam;
use fogray_tape::Float;

use crate::error::FitError;
use crate::model::RadianceField;
use crate::schedule::growth_stages;
use crate::settings::FitSettings;
use crate::trainer::policy::{StepContext, StepPolicy};

/// Where a growing fit is among its stages.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Growth {
    /// `(fraction of the budget, nodes per axis)` from which each stage trains.
    stages: Vec<(f64, usize)>,
    /// The stage the model is at.
    stage: usize,
    /// For a model pruned by the occupancy grid: the step of the grid's first refresh. Such a
    /// model grows to stage k no sooner than k first refreshes in, or a short budget's growth
    /// would come before the first refresh and keep the whole lattice. (A function of the step
    /// alone, so that a resumed fit grows where the uninterrupted one did.)
    first_refresh: Option<usize>,
}

impl Growth {
    /// The stages of `settings`, at `stage` (0 for a fresh fit, a checkpoint's for a resumed
    /// one), for a model of `nodes` per axis; `first_refresh` as [`Growth`] keeps it.
    ///
    /// Errors: [`FitError::Config`] if `nodes` is not the nodes of `stage`.
    pub(crate) fn new(
        settings: &FitSettings,
        stage: usize,
        nodes: usize,
        first_refresh: Option<usize>,
    ) -> Result<Self, FitError> {
        let stages = growth_stages(settings);
        if stages.get(stage).map(|s| s.1) != Some(nodes) {
            return Err(FitError::Config(format!(
                "the saved grid ({nodes} nodes per axis, growth stage {stage}) is not a stage of this fit's --grid {}",
                settings.grid
            )));
        }
        Ok(Growth {
            stages,
            stage,
            first_refresh,
        })
    }

    /// The nodes per axis a fresh fit of `settings` starts with.
    pub(crate) fn first_nodes(settings: &FitSettings) -> usize {
        growth_stages(settings)[0].1
    }

    /// The stage the model is at (a checkpoint saves it).
    pub(crate) fn stage(&self) -> usize {
        self.stage
    }

    /// Whether the next stage is due at `fraction` of the budget and step `step`.
    fn due(&self, fraction: f64, step: usize) -> bool {
        let next = self.stage + 1;
        next < self.stages.len()
            && fraction >= self.stages[next].0
            && self.first_refresh.is_none_or(|first| step >= next * first)
    }
}

impl<F: Float, M: RadianceField<F>> StepPolicy<F, M> for Growth {
    fn before_step(&mut self, at: &mut StepContext<'_, F, M>) -> Result<(), FitError> {
        if !self.due(at.fraction, at.step) {
            return Ok(());
        }
        self.stage += 1;
        *at.model = at.model.resampled(self.stages[self.stage].1, at.occupancy.as_ref())?;
        if let Some(grid) = at.occupancy.as_mut() {
            grid.set_known_cells(at.model.known_cells(grid)?)?;
        }
        *at.optimiser = Adam::new(at.optimiser.config())?;
        Ok(())
    }
}
