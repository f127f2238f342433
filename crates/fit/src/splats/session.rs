//! A session's fit with splats: what [`session::run`](crate::session::run) does for a grid
//! (progress, Ctrl-C, evaluations, the final report), for a [`SplatTrainer`], whose model is
//! drawn by projection and is saved as the PLY file 3DGS viewers open.

use fogray_tape::Float;

use super::carve::visual_hull;
use super::model::SplatModel;
use super::ply::write_ply;
use super::settings::SplatSettings;
use super::trainer::{render_view, SplatTrainer};
use super::undistort::undistorted;
use crate::dataset::Dataset;
use crate::error::FitError;
use crate::interrupt::StopFlag;
use crate::metrics::psnr;
use crate::session::{FitFigures, FitReport, SessionBar, SessionError, SessionOutcome, SessionPlan};
use crate::settings::FitSettings;
use crate::space::SpaceDecision;
use crate::trainer::run_budget;

/// Candidates drawn for each splat a visual hull keeps: enough for an object that fills a
/// twentieth of its box.
const HULL_CANDIDATES: usize = 20;

/// Training pixels a starting splat is given at least: more splats than the pictures can
/// tell apart fit each training view on its own and not the scene.
const PIXELS_PER_SPLAT: usize = 8;

/// How many splats a fit of `data` starts with: `most`, or fewer where the training pictures
/// have fewer pixels of the object (where alpha is at least one half; every pixel of a
/// picture without alpha) than [`PIXELS_PER_SPLAT`] for each; at least 1.
pub(crate) fn start_count(data: &Dataset, most: usize) -> usize {
    let pixels: usize = data
        .train
        .iter()
        .map(|v| match &v.alpha {
            Some(alpha) => alpha.iter().filter(|&&a| a >= super::carve::EMPTY_ALPHA).count(),
            None => v.size()[0] * v.size()[1],
        })
        .sum();
    (pixels / PIXELS_PER_SPLAT).clamp(1, most.max(1))
}

/// Where a random start puts its splats: the fit's inner region when its space was framed
/// from the cameras (a capture), else its box (`[min, max]` corners).
pub(crate) fn start_region(settings: &FitSettings) -> [[f64; 3]; 2] {
    match &settings.framing {
        Some(f) => [f.centre.map(|c| c - f.radius), f.centre.map(|c| c + f.radius)],
        None => {
            let b = settings.scene_box.unwrap_or(crate::settings::SceneBox::UNIT);
            [b.min, b.max]
        }
    }
}

/// Runs the splat fit `plan` describes on `data` (see the [module docs](self)).
///
/// Errors: a resumed splat fit (not supported yet), bad settings, the ops', a file that cannot
/// be written.
pub(crate) fn run<F: Float>(
    data: &Dataset,
    plan: &SessionPlan,
    space: &SpaceDecision,
    stop: &StopFlag,
) -> Result<SessionOutcome, SessionError> {
    if let Some(file) = &plan.resume {
        return Err(FitError::Config(format!(
            "{}: a splat fit cannot be resumed yet; start it afresh",
            file.display()
        ))
        .into());
    }
    let mut bar = SessionBar::new(plan, data);
    let settings = &plan.settings;
    // The op projects through a pinhole: pictures through a lens are resampled into theirs
    // (the held-out views too, which are then scored against their resampled pictures).
    let resampled = undistorted(data)?;
    let data = resampled.as_ref().unwrap_or(data);
    let splat_settings = SplatSettings::of_fit(settings);
    splat_settings.check()?;
    let region = start_region(settings);
    let n = start_count(data, splat_settings.initial_splats);
    let model = match visual_hull(data, region, n.saturating_mul(HULL_CANDIDATES), n, settings.seed)? {
        Some(hull) => SplatModel::<F>::from_points(
            &hull.points,
            &hull.colors,
            splat_settings.degree,
            splat_settings.max_splats,
        )?,
        None => SplatModel::<F>::random(
            region,
            n,
            splat_settings.degree,
            settings.seed,
            splat_settings.max_splats,
        )?,
    };
    let mut trainer = SplatTrainer::new(data, &splat_settings, model)?;
    let save_path = plan
        .save_model
        .clone()
        .unwrap_or_else(|| plan.save_on_interrupt.with_extension("ply"));
    let run = run_budget(&mut trainer, settings.evaluations, Some(stop.flag()), &mut |p, t| {
        let splats = t.model().len();
        bar.on_step(
            p,
            0,
            || (format!("{splats} splats on "), String::new(), save_path.clone()),
            format!("step {}, {splats} splats", p.step),
        )
    })?;
    bar.finish();
    let Some(last) = run.last else {
        write_ply(&save_path, trainer.model())?;
        return Ok(SessionOutcome::Interrupted {
            step: trainer.steps(),
            saved: save_path,
        });
    };
    let train_views_psnr = training_views_psnr(trainer.model(), data)?;
    let profile = trainer.profile().table();
    let (seconds, steps) = (trainer.seconds(), trainer.steps());
    let model = trainer.into_model();
    if let Some(path) = &plan.save_model {
        write_ply(path, &model)?;
    }
    let fit = FitFigures {
        train_views_psnr,
        seconds,
        steps,
        // Splats draw no rays and keep no occupancy grid.
        samples_per_ray_mean: f64::NAN,
        occupied_fraction: f64::NAN,
        profile,
        parameters: model.parameter_count(),
        saved: plan.save_model.clone(),
    };
    Ok(SessionOutcome::Finished(Box::new(FitReport::of(
        data,
        plan,
        space,
        run.log,
        last,
        fit,
        bar.first_step_seconds,
    )?)))
}

/// The PSNR of `model` on as many training views as `data` holds out (at least one), chosen
/// as the grid's are ([`Dataset::spread_training_views`]).
///
/// Errors: the ops'.
fn training_views_psnr<F: Float>(model: &SplatModel<F>, data: &Dataset) -> Result<f64, FitError> {
    let chosen = data.spread_training_views(data.test.len().max(1));
    let renders = chosen
        .iter()
        .map(|v| render_view(model, v, data.background).map(|r| r.color))
        .collect::<Result<Vec<_>, _>>()?;
    let r: Vec<_> = renders.iter().map(|a| a.view()).collect();
    let e: Vec<_> = chosen.iter().map(|v| v.image.view()).collect();
    Ok(psnr(&r, &e)?)
}
