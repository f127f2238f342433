//! `fogray-grid fit`: the scene's photographs fitted through fogray-fit's session, resumable,
//! with its summary and pictures.

use super::*;

#[derive(Serialize)]
struct FitSummary<'a> {
    log: &'a [fogray::fit::train::LogEntry],
    final_test_psnr: f64,
    /// The mean of the held-out views' own PSNRs (the NeRF papers' convention), beside the
    /// PSNR of their pooled squared error.
    final_test_psnr_view_mean: f64,
    /// PSNR on as many training views as held-out ones (`training_views_psnr`).
    train_views_psnr: f64,
    seconds: f64,
    samples_per_ray_mean: f64,
    occupied_fraction: f64,
    /// With --profile.
    #[serde(skip_serializing_if = "Option::is_none")]
    profile: Option<fogray::fit::profile::ProfileTable>,
}

/// What a fit resumes from: the file and its metadata.
struct Resume {
    path: PathBuf,
    info: ModelInfo,
}

/// What a fit trains on, beside its settings: the scene and the cameras, as a checkpoint
/// keeps them.
struct Problem {
    scene: Scene,
    ring: RingArgs,
}

impl Problem {
    fn entries(&self) -> BTreeMap<String, String> {
        let mut m = self.ring.entries();
        m.insert("scene".into(), self.scene.to_json_pretty());
        m
    }
}

pub(crate) fn run_fit(args: FitArgs, given: &dyn Fn(&str) -> bool) -> Result<()> {
    let resume = match &args.resume {
        Some(path) => Some(Resume {
            path: path.clone(),
            info: checkpoint::read_info(path)?,
        }),
        None => None,
    };
    let (settings, problem) = match &resume {
        None => (
            args.settings,
            Problem {
                scene: args.scene.load()?,
                ring: args.ring,
            },
        ),
        Some(r) => resumed_settings(&args, r, given)?,
    };
    settings.check()?;
    let ring = problem.ring.ring()?;
    // Before training, so that a bad directory costs nothing.
    if let Some(dir) = &args.out {
        create_dir(dir)?;
    }
    let data = dataset(&problem.scene, &ring)?;
    let plan = SessionPlan {
        settings,
        resume: args.resume.clone(),
        save_model: args.save_model.clone(),
        save_on_interrupt: default_model_path(&args),
        entries: problem.entries(),
        tool: "fogray-grid".into(),
        progress_bar: !args.json,
        announce: true,
        live: None,
    };
    match session::run(&data, &plan)? {
        SessionOutcome::Interrupted { step, saved } => {
            eprintln!(
                "fogray-grid: interrupted after step {step}: the fit is saved to {} (continue it with --resume)",
                saved.display()
            );
            std::process::exit(fogray::fit::interrupt::INTERRUPTED_STATUS);
        }
        SessionOutcome::Finished(report) => report_fit(&args, &settings, &data, &report),
    }
}

/// A resumed fit's settings, scene and cameras: the file's, except those given on the command
/// line; --grid and --precision, if given, must be the file's.
fn resumed_settings(args: &FitArgs, resume: &Resume, given: &dyn Fn(&str) -> bool) -> Result<(FitSettings, Problem)> {
    let (settings, _) = session::resume_settings(&resume.path, &args.settings, given)?;
    let extra = &resume.info.extra;
    let file_ring = RingArgs::saved(extra, &resume.path)?;
    let pick = |id: &str, flag: usize, file: usize| if given(id) { flag } else { file };
    let ring = RingArgs {
        views: pick("views", args.ring.views, file_ring.views),
        test_views: pick("test_views", args.ring.test_views, file_ring.test_views),
        size: pick("size", args.ring.size, file_ring.size),
    };
    let scene = if given("scene") {
        args.scene.load()?
    } else {
        saved_scene(extra, &resume.path)?
    };
    Ok((settings, Problem { scene, ring }))
}

/// The scene saved in a checkpoint's entries.
pub(crate) fn saved_scene(extra: &BTreeMap<String, String>, path: &Path) -> Result<Scene> {
    let text = extra
        .get("scene")
        .with_context(|| format!("{} is not a fogray-grid model: no scene", path.display()))?;
    Scene::from_json(text).with_context(|| format!("{}: the saved scene", path.display()))
}

/// Where an interrupted fit is saved without --save-model.
fn default_model_path(args: &FitArgs) -> PathBuf {
    let name = "fogray-grid-model.safetensors";
    match &args.out {
        Some(dir) => dir.join(name),
        None => PathBuf::from(name),
    }
}

fn report_fit(args: &FitArgs, settings: &FitSettings, data: &Dataset, report: &FitReport) -> Result<()> {
    if let Some(file) = &args.save_renders {
        let images = Images {
            images: report.held_out.iter().map(|v| nested(v.color.view())).collect(),
        };
        let text = serde_json::to_string(&images)?;
        // Whole or not at all, as every fogray writer.
        fogray_data::write_atomic(file, |w| w.write_all(text.as_bytes()))
            .with_context(|| format!("cannot write {}", file.display()))?;
    }
    if let Some(dir) = &args.out {
        for (t, render) in data.test.iter().zip(&report.held_out) {
            let path = dir.join(format!("test-view-{}.png", t.name));
            write_comparison_png(&path, t.image.view(), render.color.view(), 4.0, 4)?;
        }
        let label = format!(
            "{} {} {}",
            settings.method.name(),
            settings.precision.name(),
            settings.sampling.name()
        );
        plots::metric_curves(
            &dir.join("psnr"),
            &[plots::Curve {
                label,
                log: &report.log,
            }],
            plots::XAxis::Seconds,
            plots::Metric::Psnr,
            &[],
        )?;
    }
    let summary = FitSummary {
        log: &report.log,
        final_test_psnr: report.final_test_psnr,
        final_test_psnr_view_mean: report.final_test_psnr_view_mean,
        train_views_psnr: report.train_views_psnr,
        seconds: report.seconds,
        samples_per_ray_mean: report.samples_per_ray_mean,
        occupied_fraction: report.occupied_fraction,
        profile: args.profile.then(|| report.profile.clone()),
    };
    if args.json {
        return write_stdout(|w| Ok(serde_json::to_writer(w, &summary)?));
    }
    for e in &report.log {
        // Before the first step there is no training loss (NaN in the log, null in JSON).
        let loss = if e.train_loss.is_nan() {
            "-".to_string()
        } else {
            format!("{:.3e}", e.train_loss)
        };
        println!(
            "step {:>6}  {:>8.2} s  train loss {loss:>9}  test PSNR {:.2} dB",
            e.step, e.seconds, e.test_psnr
        );
    }
    println!(
        "final test PSNR {:.2} dB (mean of the views' {:.2}; {:.2} on as many training views) after {:.1} s of training; {:.1} samples per ray; {:.1} % of cells occupied",
        report.final_test_psnr,
        summary.final_test_psnr_view_mean,
        summary.train_views_psnr,
        report.seconds,
        report.samples_per_ray_mean,
        100.0 * report.occupied_fraction
    );
    if let Some(table) = &summary.profile {
        print!("{table}");
    }
    Ok(())
}
