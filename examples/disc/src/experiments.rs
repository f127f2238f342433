//! The lesson's experiments as functions returning numbers (the CLI prints and plots them).

use std::collections::BTreeSet;

use fogray::tape::{Tape, TapeError};
use serde::Serialize;

use crate::adam::Adam;
use crate::error::DiscError;
use crate::hard;
use crate::setup::Setup;
use crate::soft::{self, Compositor};

/// The hard loss over the lesson's 1 mm sweep of the offset.
#[derive(Debug, Clone, Serialize)]
pub struct Staircase {
    /// Distinct loss values with ties (exactly tangent rays) treated consistently.
    pub distinct_values: usize,
    /// Distinct loss values with the plain floating-point tangency test, which splits ties.
    pub distinct_values_plain: usize,
    /// Fraction of the 1 mm steps that leave the loss unchanged.
    pub unchanged_fraction: f64,
    /// Offsets where the plain test and the consistent one disagree.
    pub tie_offsets: Vec<f64>,
    /// The sweep: offsets and losses.
    pub x: Vec<f64>,
    pub loss: Vec<f64>,
}

/// Offsets `from, from + step, ..., to` computed as `from + i step` from integers, so that
/// 1 mm steps land exactly on the values a reader expects (x = -1.325 is `-1325 / 1000`).
pub fn grid(from_mm: i64, to_mm: i64, step_mm: i64) -> Vec<f64> {
    (0..=((to_mm - from_mm) / step_mm))
        .map(|i| (from_mm + i * step_mm) as f64 / 1000.0)
        .collect()
}

/// The hard sweep of x over [-1.6, 1.6] in 1 mm steps.
pub fn staircase(setup: &Setup) -> Staircase {
    let x = grid(-1600, 1600, 1);
    let r = setup.scene.radius;
    let count = |f: fn(&crate::scene::Ray, f64, f64) -> bool| -> Vec<usize> {
        x.iter()
            .map(|&cx| hard::mismatches(&setup.rays, cx, r, &setup.truth, f))
            .collect()
    };
    let consistent = count(hard::hits);
    let plain = count(hard::hits_plain);
    let distinct = |v: &[usize]| v.iter().collect::<BTreeSet<_>>().len();
    let unchanged = consistent.windows(2).filter(|w| w[0] == w[1]).count();
    let tie_offsets = x
        .iter()
        .zip(consistent.iter().zip(&plain))
        .filter(|(_, (a, b))| a != b)
        .map(|(&x, _)| x)
        .collect();
    Staircase {
        distinct_values: distinct(&consistent),
        distinct_values_plain: distinct(&plain),
        unchanged_fraction: unchanged as f64 / (x.len() - 1) as f64,
        tie_offsets,
        loss: x.iter().map(|&cx| setup.hard_loss(cx)).collect(),
        x,
    }
}

/// Soft and hard losses and slopes over a range of offsets, with its minima.
#[derive(Debug, Clone, Serialize)]
pub struct Landscape {
    pub tau: f64,
    pub x: Vec<f64>,
    pub soft_loss: Vec<f64>,
    pub soft_slope: Vec<f64>,
    pub hard_loss: Vec<f64>,
    /// Local minima of the soft loss (interior grid points).
    pub minima: Vec<f64>,
    /// Minima more than 0.25 m from the truth.
    pub false_valleys: Vec<f64>,
    /// Whether the soft loss at the truth exceeds both neighbours.
    pub truth_is_local_max: bool,
}

/// The landscape over `x` (the lesson's: [-3, 3] in 0.01 m steps) at softness `tau`.
/// `progress` is called once per point.
pub fn landscape(setup: &Setup, tau: f64, x: &[f64], progress: &(dyn Fn() + Sync)) -> Result<Landscape, TapeError> {
    use rayon::prelude::*;
    let evals: Vec<soft::SoftEval> = x
        .par_iter()
        .map(|&cx| {
            let e = setup.soft(cx, tau);
            progress();
            e
        })
        .collect::<Result<_, _>>()?;
    let soft_loss: Vec<f64> = evals.iter().map(|e| e.loss).collect();
    let mut minima = Vec::new();
    for i in 1..x.len().saturating_sub(1) {
        if soft_loss[i] < soft_loss[i - 1] && soft_loss[i] <= soft_loss[i + 1] {
            minima.push(x[i]);
        }
    }
    let false_valleys = minima.iter().copied().filter(|m: &f64| m.abs() > 0.25).collect();
    let truth_is_local_max = x.iter().position(|&v| v.abs() < 1e-12).is_some_and(|i| {
        i > 0 && i + 1 < x.len() && soft_loss[i] > soft_loss[i - 1] && soft_loss[i] > soft_loss[i + 1]
    });
    Ok(Landscape {
        tau,
        soft_slope: evals.iter().map(|e| e.slope).collect(),
        hard_loss: x.iter().map(|&cx| setup.hard_loss(cx)).collect(),
        x: x.to_vec(),
        soft_loss,
        minima,
        false_valleys,
        truth_is_local_max,
    })
}

/// The slope of the hard loss: a central difference over 1e-6 m, which is exactly 0 on a
/// step of the staircase (the renderer's derivative almost everywhere).
pub fn hard_slope(setup: &Setup, x: f64) -> f64 {
    let h = 1e-6;
    (setup.hard_loss(x + h) - setup.hard_loss(x - h)) / (2.0 * h)
}

/// One ray through the soft model: density, transmittance and weights per sample.
#[derive(Debug, Clone, Serialize)]
pub struct RayProfile {
    pub camera: usize,
    pub pixel: usize,
    pub x: f64,
    pub tau: f64,
    pub t: Vec<f64>,
    pub sigma: Vec<f64>,
    pub transmittance: Vec<f64>,
    pub weights: Vec<f64>,
    /// Transmittance after the first crossing of the sheet (at the sparsest sample between
    /// the two density bumps), or after the ray if it crosses less than twice.
    pub t_after_first_crossing: f64,
    /// Share of the stopping probability in the ray's back half (samples past the middle).
    pub back_half_weight: f64,
}

/// The ray of `pixel` of `camera` through the sheet at offset `x` and softness `tau`.
pub fn ray_profile(setup: &Setup, camera: usize, pixel: usize, x: f64, tau: f64) -> Result<RayProfile, DiscError> {
    let scene = &setup.scene;
    if camera >= scene.cameras || pixel >= scene.pixels {
        return Err(DiscError::NoSuchPixel {
            camera,
            pixel,
            cameras: scene.cameras,
            pixels: scene.pixels,
        });
    }
    let ray = scene.ray(camera, pixel);
    let samples = match scene.sampling {
        crate::sampling::Sampling::Uniform => soft::Samples::uniform(scene, &[ray]),
        crate::sampling::Sampling::Band => crate::sampling::band(scene, &[ray], x, tau, scene.band_k),
    };
    let mut tape = Tape::new();
    let (_, out) = soft::render_on_tape(&mut tape, scene, &samples, x, tau, Compositor::Fused)?;
    let values = |v| tape.value(v).map(|a| a.iter().copied().collect::<Vec<f64>>());
    let weights = values(
        out.weights
            .ok_or(DiscError::Usage("the op was built without weights"))?,
    )?;
    let transmittance = values(
        out.transmittance
            .ok_or(DiscError::Usage("the op was built without transmittance"))?,
    )?;
    let sigma: Vec<f64> = samples
        .x
        .iter()
        .zip(&samples.z)
        .map(|(px, pz)| scene.density(((px - x).powi(2) + pz * pz).sqrt(), tau))
        .collect();
    let n = sigma.len();
    let peaks: Vec<usize> = (1..n.saturating_sub(1))
        .filter(|&i| sigma[i] > sigma[i - 1] && sigma[i] >= sigma[i + 1])
        .collect();
    let t_after_first_crossing = match peaks.as_slice() {
        [a, b, ..] => {
            let valley = (*a..=*b).min_by(|&i, &j| sigma[i].total_cmp(&sigma[j])).unwrap_or(*a);
            transmittance[valley]
        }
        _ => 1.0 - weights.iter().sum::<f64>(),
    };
    let total: f64 = weights.iter().sum();
    let back: f64 = weights[n / 2..].iter().sum();
    Ok(RayProfile {
        camera,
        pixel,
        x,
        tau,
        t: samples.t.clone(),
        sigma,
        transmittance,
        weights,
        t_after_first_crossing,
        back_half_weight: if total > 0.0 { back / total } else { 0.0 },
    })
}

/// Which renderer a fit descends on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Renderer {
    Soft,
    Hard,
}

/// A descent: where it went and where it ended.
#[derive(Debug, Clone, Serialize)]
pub struct Fit {
    pub renderer: Renderer,
    pub start: f64,
    pub end: f64,
    pub path: Vec<f64>,
    /// Softness used at each step (constant unless annealed).
    pub tau: Vec<f64>,
    /// Pixels of the final hard render that differ from the photographs.
    pub pixels_wrong: usize,
}

/// Adam from `start` at fixed softness `tau` (the lesson's descents).
pub fn fit(setup: &Setup, renderer: Renderer, start: f64, tau: f64, adam: &Adam) -> Result<Fit, TapeError> {
    let path = match renderer {
        Renderer::Soft => adam.descend(start, |x| setup.soft(x, tau).map(|e| e.slope))?,
        // The hard renderer's exact derivative is 0 almost everywhere.
        Renderer::Hard => adam.descend(start, |x| Ok(hard_slope(setup, x)))?,
    };
    let end = *path.last().unwrap_or(&start);
    Ok(Fit {
        renderer,
        start,
        end,
        tau: vec![tau; path.len()],
        pixels_wrong: hard::mismatches(&setup.rays, end, setup.scene.radius, &setup.truth, hard::hits),
        path,
    })
}
