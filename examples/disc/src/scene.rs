//! The scene of the disc experiment: a disc photographed by cameras on a ring, and the rays
//! and samples of every pixel. Every parameter is a flag whose default is the setup
//! reconstructed from the lesson's figures (`docs/disc.md` gives it in full).

use clap::Args;

use crate::error::DiscError;

/// The scene's parameters.
#[derive(Debug, Clone, Args)]
pub struct Scene {
    /// Number of cameras on the ring (at 90 + 360 k / n degrees).
    #[arg(long, default_value_t = 6)]
    pub cameras: usize,
    /// Pixels per camera.
    #[arg(long, default_value_t = 48)]
    pub pixels: usize,
    /// Half-width of the image line at unit focal distance.
    #[arg(long, default_value_t = 0.6)]
    pub half_width: f64,
    /// Radius of the disc, true and model (m).
    #[arg(long, default_value_t = 1.0)]
    pub radius: f64,
    /// Radius of the camera ring (m).
    #[arg(long, default_value_t = 5.0)]
    pub ring_radius: f64,
    /// Optical thickness across the soft sheet.
    #[arg(long, default_value_t = 6.0)]
    pub kappa: f64,
    /// Softness: the width of the Gaussian sheet (m).
    #[arg(long, default_value_t = 0.15)]
    pub tau: f64,
    /// Samples per ray.
    #[arg(long, default_value_t = 64)]
    pub samples: usize,
    /// Start of the sampled depth range (m).
    #[arg(long, default_value_t = 3.0)]
    pub t0: f64,
    /// End of the sampled depth range (m).
    #[arg(long, default_value_t = 7.0)]
    pub t1: f64,
    /// Colour of the disc, as r,g,b.
    #[arg(long, value_delimiter = ',', default_values_t = [0.95, 0.55, 0.15])]
    pub disc_color: Vec<f64>,
    /// Colour of the background, as r,g,b (default 247/255 in each channel).
    #[arg(long, value_delimiter = ',', default_values_t = [247.0 / 255.0; 3])]
    pub background: Vec<f64>,
    /// Where the soft renderer samples each ray: evenly on [t0, t1], or only within
    /// band-k * tau of the model circle.
    #[arg(long, value_enum, default_value = "uniform")]
    pub sampling: crate::sampling::Sampling,
    /// Half-width of the sampled band, in units of tau (with --sampling band).
    #[arg(long, default_value_t = 6.0)]
    pub band_k: f64,
}

impl Default for Scene {
    fn default() -> Self {
        Scene {
            cameras: 6,
            pixels: 48,
            half_width: 0.6,
            radius: 1.0,
            ring_radius: 5.0,
            kappa: 6.0,
            tau: 0.15,
            samples: 64,
            t0: 3.0,
            t1: 7.0,
            disc_color: vec![0.95, 0.55, 0.15],
            background: vec![247.0 / 255.0; 3],
            sampling: crate::sampling::Sampling::Uniform,
            band_k: 6.0,
        }
    }
}

/// A ray in the (x, z) plane: origin and unit direction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    pub origin: [f64; 2],
    pub dir: [f64; 2],
}

impl Scene {
    /// Checks the parameters; the message says which is wrong.
    pub fn validate(&self) -> Result<(), DiscError> {
        let positive = [
            ("cameras", self.cameras as f64),
            ("pixels", self.pixels as f64),
            ("samples", self.samples as f64),
            ("half-width", self.half_width),
            ("radius", self.radius),
            ("ring-radius", self.ring_radius),
            ("kappa", self.kappa),
            ("tau", self.tau),
            ("band-k", self.band_k),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(DiscError::Setting {
                    name,
                    value: v,
                    rule: "positive and finite",
                });
            }
        }
        if !(self.t0.is_finite() && self.t1.is_finite() && self.t0 < self.t1) {
            return Err(DiscError::Interval {
                t0: self.t0,
                t1: self.t1,
            });
        }
        if self.disc_color.len() != self.background.len() || self.disc_color.is_empty() {
            return Err(DiscError::Usage(
                "--disc-color and --background need the same number of channels",
            ));
        }
        if self.disc_color.iter().chain(&self.background).any(|c| !c.is_finite()) {
            return Err(DiscError::Usage("colours must be finite"));
        }
        Ok(())
    }

    /// Number of colour channels.
    pub fn channels(&self) -> usize {
        self.disc_color.len()
    }

    /// The camera at angle 90 + 360 k / n degrees: its position (x, z).
    pub fn camera(&self, k: usize) -> [f64; 2] {
        let a = (90.0 + 360.0 * k as f64 / self.cameras as f64).to_radians();
        [self.ring_radius * a.cos(), self.ring_radius * a.sin()]
    }

    /// Pixel `j`'s ray of camera `k`: direction `f + h ((2j + 1)/n - 1) r`, normalised, with
    /// `f` the forward unit vector (towards the origin) and `r = (f_z, -f_x)`.
    pub fn ray(&self, k: usize, j: usize) -> Ray {
        let o = self.camera(k);
        let norm = (o[0] * o[0] + o[1] * o[1]).sqrt();
        let f = [-o[0] / norm, -o[1] / norm];
        let r = [f[1], -f[0]];
        let s = self.half_width * ((2 * j + 1) as f64 / self.pixels as f64 - 1.0);
        let d = [f[0] + s * r[0], f[1] + s * r[1]];
        let len = (d[0] * d[0] + d[1] * d[1]).sqrt();
        Ray {
            origin: o,
            dir: [d[0] / len, d[1] / len],
        }
    }

    /// Every pixel's ray, camera by camera.
    pub fn rays(&self) -> Vec<Ray> {
        (0..self.cameras)
            .flat_map(|k| (0..self.pixels).map(move |j| self.ray(k, j)))
            .collect()
    }

    /// Sample step (m).
    pub fn delta(&self) -> f64 {
        (self.t1 - self.t0) / self.samples as f64
    }

    /// Depth of sample `i` of a ray: the midpoint of its segment.
    pub fn sample_t(&self, i: usize) -> f64 {
        self.t0 + (i as f64 + 0.5) * self.delta()
    }

    /// The soft sheet's density at distance `d` from the model centre, for softness `tau`.
    pub fn density(&self, d: f64, tau: f64) -> f64 {
        let z = (d - self.radius) / tau;
        self.kappa / (tau * (2.0 * std::f64::consts::PI).sqrt()) * (-0.5 * z * z).exp()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camera_zero_looks_down_the_z_axis_and_pixels_are_symmetric() {
        let s = Scene::default();
        let c = s.camera(0);
        assert!(c[0].abs() < 1e-15 && (c[1] - 5.0).abs() < 1e-15);
        // Pixel j and 47 - j mirror each other about the view axis.
        let (a, b) = (s.ray(0, 10), s.ray(0, 37));
        assert!((a.dir[0] + b.dir[0]).abs() < 1e-15 && (a.dir[1] - b.dir[1]).abs() < 1e-15);
        // For 48 pixels the offset is 0.025 (j - 23.5): pixel 47 at 0.5875 to the right.
        let last = s.ray(0, 47);
        assert!(
            (last.dir[0] / -last.dir[1] - (-0.5875)).abs() < 1e-12
                || (last.dir[0] / -last.dir[1] - 0.5875).abs() < 1e-12
        );
    }

    #[test]
    fn the_sheet_integrates_to_kappa() {
        let s = Scene::default();
        for tau in [0.05, 0.15, 0.6] {
            let h = 1e-4;
            let total: f64 = (0..200_000)
                .map(|i| s.density(-9.0 + (i as f64 + 0.5) * h, tau) * h)
                .sum();
            assert!((total - 6.0).abs() < 1e-6, "tau {tau}: {total}");
        }
    }
}
