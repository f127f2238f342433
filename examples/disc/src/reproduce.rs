//! `reproduce`: every figure of the lesson beside ours, and all the plots.

use std::path::Path;

use rayon::prelude::*;
use serde::Serialize;
use serde_json::{json, Value};

use crate::adam::Adam;
use crate::anneal::{fit_annealed, Schedule};
use crate::error::DiscError;
use crate::experiments::{self, grid, Fit, Renderer};
use crate::plots;
use crate::setup::Setup;

/// One figure: the lesson's printed value and ours.
#[derive(Debug, Clone, Serialize)]
pub struct Figure {
    pub id: &'static str,
    /// The lesson's value as printed (its digits decide what "agrees" means).
    #[serde(skip)]
    pub printed: &'static str,
    pub lesson: Value,
    pub ours: Value,
    /// What it is, for the table.
    #[serde(skip)]
    pub what: &'static str,
}

impl Figure {
    /// Whether ours, rounded to the lesson's printed digits, is the lesson's value.
    pub fn agrees(&self) -> bool {
        match (&self.lesson, &self.ours) {
            (Value::Number(l), Value::Number(o)) => {
                let decimals = self.printed.split('.').nth(1).map_or(0, str::len) as i32;
                let (l, o) = (l.as_f64().unwrap_or(f64::NAN), o.as_f64().unwrap_or(f64::NAN));
                (o - l).abs() <= 0.5 * 10f64.powi(-decimals) + 1e-12
            }
            (l, o) => l == o,
        }
    }
}

/// One landscape and the descents drawn on it.
pub type Panel = (experiments::Landscape, Vec<Fit>);

/// Everything `reproduce` computes.
#[derive(Debug, Clone, Serialize)]
pub struct Reproduction {
    pub figures: Vec<Figure>,
    pub staircase_distinct_plain: usize,
    pub staircase_tie_offsets: Vec<f64>,
    pub annealed: Vec<Fit>,
    pub fixed: Vec<Fit>,
}

/// Runs every experiment; `progress(n)` is told how much work is done.
pub fn run(
    setup: &Setup,
    adam: &Adam,
    schedule: &Schedule,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<(Reproduction, Vec<Panel>), DiscError> {
    let stairs = experiments::staircase(setup);
    let at = |x: f64, tau: f64| setup.soft(x, tau);
    let s15 = at(-1.5, 0.15)?;
    let s28 = at(-2.8, 0.15)?;
    let profile = experiments::ray_profile(setup, 0, 36, -1.5, 0.15)?;
    let soft_fit = |start: f64, tau: f64| experiments::fit(setup, Renderer::Soft, start, tau, adam);
    let (f15, f28, f45, f60) = (
        soft_fit(-1.5, 0.15)?,
        soft_fit(-2.8, 0.15)?,
        soft_fit(-2.8, 0.45)?,
        soft_fit(-2.8, 0.6)?,
    );
    let hard_fit = experiments::fit(setup, Renderer::Hard, -2.8, 0.15, adam)?;
    progress(10);
    let xs = grid(-3000, 3000, 10);
    let mut panels = Vec::new();
    for (tau, fits) in [
        (0.15, vec![f15.clone(), f28.clone()]),
        (0.3, vec![soft_fit(-2.8, 0.3)?]),
        (0.45, vec![f45.clone()]),
        (0.6, vec![f60.clone()]),
    ] {
        panels.push((experiments::landscape(setup, tau, &xs, &|| progress(1))?, fits));
    }
    let starts: Vec<f64> = (0..=24).map(|i| -3.0 + 0.25 * i as f64).collect();
    let annealed: Vec<Fit> = starts
        .par_iter()
        .map(|&s| {
            let f = fit_annealed(setup, s, schedule, adam);
            progress(schedule.anneal_steps as u64);
            f
        })
        .collect::<Result<_, _>>()?;
    let fixed: Vec<Fit> = starts
        .par_iter()
        .map(|&s| {
            let f = soft_fit(s, 0.15);
            progress(adam.steps as u64);
            f
        })
        .collect::<Result<_, _>>()?;
    let (l45, l60) = (&panels[2].0, &panels[3].0);
    let fig = |id, what, printed: &'static str, ours: Value| Figure {
        id,
        printed,
        lesson: serde_json::from_str(printed).unwrap_or(Value::Null),
        ours,
        what,
    };
    let figures = vec![
        fig(
            "staircase_distinct",
            "hard sweep: distinct loss values (exact ties; 59 with the textbook test)",
            "59",
            json!(stairs.distinct_values),
        ),
        fig(
            "staircase_unchanged_fraction",
            "hard sweep: fraction of 1 mm steps that change nothing",
            "0.964",
            json!(stairs.unchanged_fraction),
        ),
        fig(
            "soft_loss_at_-1.5",
            "x = -1.5, tau = 0.15: soft loss",
            "0.100",
            json!(s15.loss),
        ),
        fig(
            "soft_slope_at_-1.5",
            "x = -1.5: soft slope dE/dx",
            "-0.038",
            json!(s15.slope),
        ),
        fig(
            "hard_loss_at_-1.5",
            "x = -1.5: hard loss",
            "0.100",
            json!(setup.hard_loss(-1.5)),
        ),
        fig(
            "hard_slope_at_-1.5",
            "x = -1.5: hard slope",
            "0",
            json!(experiments::hard_slope(setup, -1.5)),
        ),
        fig(
            "pixel36_T_after_first_crossing",
            "camera 0 pixel 36: T after the first crossing",
            "0.0025",
            json!(profile.t_after_first_crossing),
        ),
        fig(
            "pixel36_back_half_weight",
            "camera 0 pixel 36: share of weight in the back half",
            "0.0024",
            json!(profile.back_half_weight),
        ),
        fig(
            "adam_soft_end_from_-1.5",
            "soft Adam from -1.5: distance of the end from the truth",
            "0.06",
            json!(f15.end.abs()),
        ),
        fig(
            "hard_loss_at_-2.8",
            "x = -2.8: hard loss",
            "0.139",
            json!(setup.hard_loss(-2.8)),
        ),
        fig(
            "soft_slope_at_-2.8",
            "x = -2.8: |soft slope|",
            "0.011",
            json!(s28.slope.abs()),
        ),
        fig(
            "adam_soft_end_from_-2.8",
            "soft Adam from -2.8: distance of the end from the truth",
            "0.19",
            json!(f28.end.abs()),
        ),
        fig(
            "adam_hard_end_from_-2.8",
            "hard Adam from -2.8: where it ends",
            "-2.8",
            json!(hard_fit.end),
        ),
        fig(
            "tau0.45_false_valleys",
            "tau = 0.45: false valleys",
            "2",
            json!(l45.false_valleys.len()),
        ),
        fig(
            "tau0.45_end_from_-2.8",
            "tau = 0.45: soft Adam from -2.8 ends at",
            "-1.3",
            json!(f45.end),
        ),
        fig(
            "tau0.6_truth_is_local_max",
            "tau = 0.6: the truth is a local maximum",
            "true",
            json!(l60.truth_is_local_max),
        ),
        fig(
            "tau0.6_end_from_-2.8",
            "tau = 0.6: distance of the end from the truth",
            "1.9",
            json!(f60.end.abs()),
        ),
    ];
    Ok((
        Reproduction {
            figures,
            staircase_distinct_plain: stairs.distinct_values_plain,
            staircase_tie_offsets: stairs.tie_offsets,
            annealed,
            fixed,
        },
        panels,
    ))
}

/// Total progress units of [`run`].
pub fn work(adam: &Adam, schedule: &Schedule) -> u64 {
    10 + 4 * 601 + 25 * (schedule.anneal_steps + adam.steps) as u64
}

/// Writes every plot of the reproduction into `dir`.
pub fn plot_all(
    setup: &Setup,
    dir: &Path,
    r: &Reproduction,
    panels: &[(experiments::Landscape, Vec<Fit>)],
) -> Result<Vec<String>, DiscError> {
    std::fs::create_dir_all(dir).map_err(DiscError::file("create", dir))?;
    plots::landscapes(dir, "landscape", panels)?;
    let profile = experiments::ray_profile(setup, 0, 36, -1.5, 0.15)?;
    plots::ray(dir, &profile)?;
    let pixels = setup.scene.pixels;
    let ch = setup.scene.channels();
    let cam = 0..pixels * ch;
    let soft_img = setup.soft(-1.5, 0.15)?.image;
    let hard_img = crate::hard::render(&setup.scene, &setup.rays, -1.5, crate::hard::hits);
    plots::strips(
        dir,
        &plots::Strips {
            camera: 0,
            x: -1.5,
            tau: 0.15,
            rows: [
                ("photograph (true disc)", &setup.photo[cam.clone()]),
                ("soft render", &soft_img[cam.clone()]),
                ("hard render", &hard_img[cam]),
            ],
            ch,
            marked: Some(36),
        },
    )?;
    plots::fits(dir, &r.annealed, &r.fixed)?;
    Ok(["landscape", "ray", "strips", "fits"]
        .iter()
        .flat_map(|s| {
            [
                format!("{}/{s}.svg", dir.display()),
                format!("{}/{s}.png", dir.display()),
            ]
        })
        .collect())
}
