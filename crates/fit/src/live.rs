//! A fit watched while it trains: the one hook through which a session tells a watcher (a
//! viewer's page) how far the fit is and, when the watcher asks, hands it a copy of the model.
//!
//! The watcher lives on other threads and knows nothing of the trainer; the trainer knows
//! nothing of the watcher but [`LiveSink`]. A copy of the model costs memory and time, so the
//! session makes one only when [`LiveSink::wants_model`] says so, at a step boundary (never
//! one a step by default), and once at the end: the model the fit leaves, as it is saved.

use std::marker::PhantomData;
use std::sync::Arc;

use fogray_ops::sample::OccupancyGrid;
use fogray_ops::PinholeCamera;
use fogray_tape::Float;
use ndarray::Array3;

use crate::dataset::camera_rays;
use crate::error::FitError;
use crate::interrupt::StopFlag;
use crate::model::RadianceField;
use crate::render::{render_picture, RenderOptions};
use crate::settings::FitSettings;
use crate::train::{LogEntry, Progress};

/// A copy of the model as it stood after a step, that renders a camera (from any thread).
pub trait LiveModel: Send + Sync {
    /// The steps the fit had done.
    fn step(&self) -> usize;
    /// Nodes per axis (a growing fit's stage then), for a render's memory check.
    fn nodes(&self) -> usize;
    /// The colour `[H][W][3]` (unclamped) seen from `camera`, rendered as
    /// [`render_picture`] renders the saved model with the saved occupancy grid.
    ///
    /// Errors: the renderer's.
    fn render(&self, camera: &PinholeCamera, options: &RenderOptions) -> Result<Array3<f64>, FitError>;
}

/// What watches a fit. Called from the training thread: each method should return at once
/// (store and signal; render elsewhere).
pub trait LiveSink: Send + Sync {
    /// Whether a fresh copy of the model is wanted: asked after every step, so it should be
    /// one atomic load.
    fn wants_model(&self) -> bool;
    /// After every step.
    fn step(&self, progress: Progress);
    /// After every evaluation of the held-out views, as it is made.
    fn evaluated(&self, entry: &LogEntry);
    /// A copy of the model: when one was wanted, and once when the loop ends.
    fn model(&self, model: Arc<dyn LiveModel>);
    /// The loop has ended (its budget spent, or stopped), after the last [`LiveSink::model`]:
    /// `log` is the fit's log as its report gives it.
    fn finished(&self, log: &[LogEntry], interrupted: bool);
}

/// A session's watcher ([`SessionPlan::live`](crate::session::SessionPlan::live)), with the
/// flag that stops the fit: the watcher's own, since a process has one Ctrl-C handler and a
/// watcher that outlives the fit needs it too.
#[derive(Clone)]
pub struct LiveHook {
    /// The watcher.
    pub sink: Arc<dyn LiveSink>,
    /// Stops the fit (after the step under way, saved as on Ctrl-C) when raised: for
    /// [`StopFlag::on_ctrl_c`].
    pub stop: StopFlag,
}

impl std::fmt::Debug for LiveHook {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveHook")
            .field("stop", &self.stop)
            .finish_non_exhaustive()
    }
}

/// A model copied with its occupancy grid.
struct Snapshot<F, M> {
    model: M,
    occupancy: Option<OccupancyGrid>,
    step: usize,
    float: PhantomData<fn() -> F>,
}

impl<F: Float, M: RadianceField<F>> LiveModel for Snapshot<F, M> {
    fn step(&self) -> usize {
        self.step
    }

    fn nodes(&self) -> usize {
        self.model.nodes()
    }

    fn render(&self, camera: &PinholeCamera, options: &RenderOptions) -> Result<Array3<f64>, FitError> {
        let k = camera.intrinsics();
        let (origins, directions) = camera_rays(camera);
        let picture = render_picture(
            &self.model,
            self.occupancy.as_ref(),
            &origins,
            &directions,
            [k.height, k.width],
            options,
        )?;
        Ok(picture.color)
    }
}

/// A copy of `model` (rebuilt from its structure, as a checkpoint's load rebuilds it, and its
/// parameters copied by name) and of `occupancy`, at `step`.
///
/// Errors: a model its own structure does not rebuild (a parameter missing or of another
/// shape), which a checkpoint could not load either.
pub(crate) fn snapshot<F: Float, M: RadianceField<F>>(
    model: &M,
    occupancy: Option<&OccupancyGrid>,
    settings: &FitSettings,
    step: usize,
) -> Result<Arc<dyn LiveModel>, FitError> {
    let structure = model.structure();
    let mask = |name: &str| structure.iter().find(|(n, _)| *n == name).map(|(_, m)| m.clone());
    let mut copy = M::with_structure(settings, model.nodes(), &mask)?;
    let ids: Vec<_> = copy.params().ids().collect();
    for id in ids {
        let name = copy.params().name(id)?.to_string();
        let source = model
            .params()
            .id(&name)
            .ok_or_else(|| FitError::Config(format!("a copy of the model has a parameter {name:?} it lacks")))?;
        let value = model.params().get(source)?;
        let mut target = copy.params_mut().get_mut(id)?;
        if target.shape() != value.shape() {
            return Err(FitError::Config(format!(
                "a copy of the model's parameter {name:?} is {:?}, not {:?}",
                target.shape(),
                value.shape()
            )));
        }
        target.assign(&value);
    }
    Ok(Arc::new(Snapshot {
        model: copy,
        occupancy: occupancy.cloned(),
        step,
        float: PhantomData::<fn() -> F>,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dense::DenseGrid;
    use crate::sparse::SparseGrid;
    use fogray_ops::Intrinsics;

    /// A copy renders what the model renders, bit for bit, and no longer follows it.
    fn copy_renders_as_the_model<M: RadianceField<f32>>() {
        let settings = FitSettings {
            grid: 6,
            ..FitSettings::default()
        };
        let mut model = M::fresh(&settings, 6).unwrap();
        // Parameters of a known pattern, so that the picture is not a constant.
        let ids: Vec<_> = model.params().ids().collect();
        for id in &ids {
            let mut v = model.params_mut().get_mut(*id).unwrap();
            for (i, x) in v.iter_mut().enumerate() {
                *x = ((i % 7) as f32 - 2.0) * 0.5;
            }
        }
        let copy = snapshot(&model, None, &settings, 3).unwrap();
        assert_eq!((copy.step(), copy.nodes()), (3, 6));
        let k = Intrinsics::from_vertical_fov(7, 5, 0.8).unwrap();
        let camera = PinholeCamera::look_at(k, [2.5, 0.5, 0.7], [0.0; 3], [0.0, 0.0, 1.0]).unwrap();
        let options = RenderOptions::default();
        let (o, d) = camera_rays(&camera);
        let direct = render_picture(&model, None, &o, &d, [5, 7], &options).unwrap().color;
        let copied = copy.render(&camera, &options).unwrap();
        assert_eq!(copied, direct);
        assert!(direct.iter().any(|&v| (v - direct[[0, 0, 0]]).abs() > 1e-3));
        // The model trains on; the copy keeps what it had.
        for id in &ids {
            model.params_mut().get_mut(*id).unwrap().fill(0.0);
        }
        assert_eq!(copy.render(&camera, &options).unwrap(), direct);
    }

    #[test]
    fn a_copy_of_a_dense_grid_renders_as_it_did() {
        copy_renders_as_the_model::<DenseGrid<f32>>();
    }

    #[test]
    fn a_copy_of_a_sparse_grid_renders_as_it_did() {
        copy_renders_as_the_model::<SparseGrid<f32>>();
    }
}
