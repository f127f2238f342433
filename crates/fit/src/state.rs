//! Where a fit stands between two steps: the model, and the rest of what
//! [`Trainer::new`](crate::trainer::Trainer::new) needs to continue it exactly (Adam's moments, the step,
//! the training seconds, the growth stage, the position in the stream of random batches, the
//! occupancy grid). [`checkpoint`](crate::checkpoint) writes both to a file and reads them back.

use fogray_ops::sample::OccupancyState;
use fogray_tape::optim::AdamState;
use fogray_tape::Float;

/// A fit's state beyond its model.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainingState<F> {
    /// Steps done.
    pub step: usize,
    /// Training seconds so far (evaluations excluded).
    pub seconds: f64,
    /// The growth stage of the grid (0, or 0 to 2 for a growing grid: a quarter, half and all
    /// of the settings' nodes per axis).
    pub stage: usize,
    /// Words of the batch generator's stream (ChaCha12) used so far.
    pub batch_stream: u128,
    /// Adam's state per parameter, by name; empty before the stage's first step.
    pub adam: Vec<(String, AdamState<F>)>,
    /// The occupancy grid's state, for a fit with occupancy sampling.
    pub occupancy: Option<OccupancyState>,
}

/// The state of a fit that has not started.
impl<F> Default for TrainingState<F> {
    fn default() -> Self {
        TrainingState {
            step: 0,
            seconds: 0.0,
            stage: 0,
            batch_stream: 0,
            adam: Vec::new(),
            occupancy: None,
        }
    }
}

/// A fit to continue: its model and state.
#[derive(Debug)]
pub struct Start<F: Float, M> {
    /// The model, at the nodes per axis of `training.stage`.
    pub model: M,
    /// The rest of the fit's state.
    pub training: TrainingState<F>,
}
