//! Everything the experiments share: the scene, its rays and samples, and the photographs.

use std::borrow::Cow;

use fogray::tape::TapeError;

use crate::error::DiscError;
use crate::hard;
use crate::sampling::{self, Sampling};
use crate::scene::{Ray, Scene};
use crate::soft::{self, Compositor, Samples, SoftEval};

/// The scene with its rays, uniform samples and photographs (hard renders of the true disc).
#[derive(Debug, Clone)]
pub struct Setup {
    pub scene: Scene,
    pub rays: Vec<Ray>,
    pub samples: Samples,
    /// Whether each pixel of the photographs sees the disc.
    pub truth: Vec<bool>,
    /// The photographs, `[rays * ch]`.
    pub photo: Vec<f64>,
}

impl Setup {
    /// Builds the setup; errors if the scene's parameters are invalid.
    pub fn new(scene: Scene) -> Result<Setup, DiscError> {
        scene.validate()?;
        let rays = scene.rays();
        let samples = Samples::uniform(&scene, &rays);
        let truth: Vec<bool> = rays.iter().map(|r| hard::hits(r, 0.0, scene.radius)).collect();
        let photo = hard::render(&scene, &rays, 0.0, hard::hits);
        Ok(Setup {
            scene,
            rays,
            samples,
            truth,
            photo,
        })
    }

    /// The samples of every ray for the model at `x` with softness `tau`: the fixed uniform
    /// ones, or the band around the model circle.
    pub fn samples_for(&self, x: f64, tau: f64) -> Cow<'_, Samples> {
        match self.scene.sampling {
            Sampling::Uniform => Cow::Borrowed(&self.samples),
            Sampling::Band => Cow::Owned(sampling::band(&self.scene, &self.rays, x, tau, self.scene.band_k)),
        }
    }

    /// The soft loss, its slope (from the tape's backward through the fused op) and the image.
    pub fn soft(&self, x: f64, tau: f64) -> Result<SoftEval, TapeError> {
        soft::evaluate(
            &self.scene,
            &self.samples_for(x, tau),
            &self.photo,
            x,
            tau,
            Compositor::Fused,
        )
    }

    /// The hard loss at offset `x`.
    pub fn hard_loss(&self, x: f64) -> f64 {
        hard::loss(&hard::render(&self.scene, &self.rays, x, hard::hits), &self.photo)
    }
}
