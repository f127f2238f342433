//! [`Densify`]: 3DGS's adaptive density control as a [`StepPolicy`]. Every `densify_every`
//! steps while the budget's fraction is in `[densify_from, densify_until)`, a splat whose mean gradient is large is cloned
//! if it is small (under-reconstruction: a copy moves to fill the gap) or split into two
//! samples of itself with scales / 1.6 if it is large (over-reconstruction); then splats
//! nearly transparent or larger than a tenth of the scene are pruned.

use fogray_tape::Float;
use ndarray::{Array1, Array2};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha12Rng;

use super::model::{check_count, SplatArraysOwned, SplatModel};
use super::resize::resize;
use super::settings::SplatSettings;
use crate::error::FitError;
use crate::trainer::{StepContext, StepPolicy};

/// The factor a split divides its splat's scales by (3DGS's).
pub(crate) const SPLIT_SHRINK: f64 = 1.6;
/// Splats whose largest scale exceeds this fraction of the scene's extent are pruned.
pub(crate) const HUGE_FRACTION: f64 = 0.1;

/// Adaptive density control (see the [module docs](self)).
#[derive(Debug, Clone)]
pub(crate) struct Densify {
    settings: SplatSettings,
    extent: f64,
    rng: ChaCha12Rng,
}

fn sigmoid(x: f64) -> f64 {
    1.0 / (1.0 + (-x).exp())
}

/// `v` rotated by the unit quaternion along `q` (`w, x, y, z`).
fn rotate(q: [f64; 4], v: [f64; 3]) -> [f64; 3] {
    let n = q.iter().map(|c| c * c).sum::<f64>().sqrt().max(f64::MIN_POSITIVE);
    let [w, x, y, z] = q.map(|c| c / n);
    // v + 2 u x (u x v + w v), u = (x, y, z): no matrix needed.
    let u = [x, y, z];
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let c = cross(u, v);
    let t = [c[0] + w * v[0], c[1] + w * v[1], c[2] + w * v[2]];
    let d = cross(u, t);
    [v[0] + 2.0 * d[0], v[1] + 2.0 * d[1], v[2] + 2.0 * d[2]]
}

impl Densify {
    /// The policy for `settings` in a scene of extent `extent` (the radius the cameras span),
    /// drawing its split samples from `seed`.
    pub(crate) fn new(settings: &SplatSettings, extent: f64, seed: u64) -> Self {
        Densify {
            settings: *settings,
            extent,
            rng: ChaCha12Rng::seed_from_u64(seed),
        }
    }

    /// A standard normal sample (Box-Muller).
    fn normal(&mut self) -> f64 {
        let u: f64 = 1.0 - self.rng.gen::<f64>();
        let v: f64 = self.rng.gen();
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }

    /// Clones, splits and prunes once (the step's work, callable on its own).
    ///
    /// Errors: more splats than the cap's memory allows; the optimiser's state not of the
    /// model.
    pub(crate) fn densify<F: Float>(
        &mut self,
        model: &mut SplatModel<F>,
        optimiser: &mut fogray_tape::optim::Adam<F>,
    ) -> Result<(), FitError> {
        let a = model.arrays()?;
        let grads = model.mean_gradients();
        let n = a.means.nrows();
        let s = self.settings;
        let max_scale = |i: usize| {
            a.log_scales
                .row(i)
                .iter()
                .map(|v| v.as_f64())
                .fold(f64::MIN, f64::max)
                .exp()
        };
        let hot: Vec<usize> = (0..n)
            .filter(|&i| grads[i] >= s.grad_threshold && grads[i] > 0.0)
            .collect();
        // Growth is cut short at the cap: each hot splat adds one.
        let room = s.max_splats.saturating_sub(n);
        let hot = &hot[..hot.len().min(room)];
        // A splat as one row: mean 0..3, log-scale 3..6, quaternion 6..10, opacity logit 10,
        // colour coefficients 11.. .
        let width = 11 + a.sh.ncols();
        let row = |i: usize| -> Vec<f64> {
            let mut r = Vec::with_capacity(width);
            for p in [a.means.row(i), a.log_scales.row(i), a.quats.row(i)] {
                r.extend(p.iter().map(|v| v.as_f64()));
            }
            r.push(a.opacity_logits[i].as_f64());
            r.extend(a.sh.row(i).iter().map(|v| v.as_f64()));
            r
        };
        let mut rows: Vec<(Option<usize>, Vec<f64>)> = Vec::with_capacity(hot.len() * 2);
        let mut split = vec![false; n];
        for &i in hot {
            let r = row(i);
            if max_scale(i) <= s.dense_fraction * self.extent {
                rows.push((Some(i), r));
            } else {
                split[i] = true;
                for _ in 0..2 {
                    let z = [0, 1, 2].map(|k| self.normal() * r[3 + k].exp());
                    let d = rotate([r[6], r[7], r[8], r[9]], z);
                    let mut c = r.clone();
                    for k in 0..3 {
                        c[k] += d[k];
                        c[3 + k] -= SPLIT_SHRINK.ln();
                    }
                    rows.push((None, c));
                }
            }
        }
        let mut kept: Vec<(Option<usize>, Vec<f64>)> =
            (0..n).filter(|&i| !split[i]).map(|i| (Some(i), row(i))).collect();
        kept.append(&mut rows);
        let huge = HUGE_FRACTION * self.extent;
        kept.retain(|(_, r)| {
            sigmoid(r[10]) >= s.min_opacity && r[3..6].iter().fold(f64::MIN, |m, v| m.max(*v)).exp() <= huge
        });
        check_count(kept.len(), s.max_splats)?;
        let m = kept.len();
        let col = |k: usize, w: usize| Array2::from_shape_fn((m, w), |(i, j)| F::lit(kept[i].1[k + j]));
        let arrays = SplatArraysOwned {
            means: col(0, 3),
            log_scales: col(3, 3),
            quats: col(6, 4),
            opacity_logits: Array1::from_shape_fn(m, |i| F::lit(kept[i].1[10])),
            sh: col(11, width - 11),
        };
        let origin: Vec<Option<usize>> = kept.iter().map(|(o, _)| *o).collect();
        resize(model, optimiser, arrays, &origin)
    }
}

impl<F: Float> StepPolicy<F, SplatModel<F>> for Densify {
    fn after_step(&mut self, at: &mut StepContext<'_, F, SplatModel<F>>) -> Result<(), FitError> {
        let s = self.settings;
        let due = at.fraction >= s.densify_from && at.fraction < s.densify_until && at.step % s.densify_every == 0;
        if due {
            self.densify(at.model, at.optimiser)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fogray_tape::optim::{Adam, AdamConfig};
    use ndarray::{arr1, arr2};

    fn model(log_scale: f64, logits: [f64; 3]) -> SplatModel<f64> {
        SplatModel::new(
            SplatArraysOwned {
                means: arr2(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),
                log_scales: Array2::from_elem((3, 3), log_scale),
                quats: arr2(&[[1.0, 0.0, 0.0, 0.0]; 3]),
                opacity_logits: arr1(&logits),
                sh: Array2::zeros((3, 3)),
            },
            0,
        )
        .unwrap()
    }

    fn hot_first(m: &mut SplatModel<f64>) {
        // Splat 0 sees a large gradient, 1 a small one, 2 none.
        m.observe(arr2(&[[1e-3, 0.0, 0.0], [1e-6, 0.0, 0.0], [0.0; 3]]).into_dyn().view())
            .unwrap();
    }

    #[test]
    fn a_small_splat_with_a_large_gradient_is_cloned() {
        let mut m = model(0.001f64.ln(), [0.0; 3]);
        hot_first(&mut m);
        let mut adam = Adam::new(AdamConfig::default()).unwrap();
        Densify::new(&SplatSettings::default(), 1.0, 0)
            .densify(&mut m, &mut adam)
            .unwrap();
        let a = m.arrays().unwrap();
        assert_eq!(a.means.nrows(), 4);
        assert_eq!(a.means.row(3), a.means.row(0));
        assert_eq!(m.mean_gradients(), vec![0.0; 4], "statistics restart");
    }

    #[test]
    fn a_large_splat_with_a_large_gradient_is_split_into_two_smaller_ones() {
        // Scale 0.05 > 0.01 x extent 1 (dense), < 0.1 (not huge).
        let mut m = model(0.05f64.ln(), [0.0; 3]);
        hot_first(&mut m);
        let mut adam = Adam::new(AdamConfig::default()).unwrap();
        Densify::new(&SplatSettings::default(), 1.0, 0)
            .densify(&mut m, &mut adam)
            .unwrap();
        let a = m.arrays().unwrap();
        assert_eq!(a.means.nrows(), 4, "one removed, two added");
        for i in 2..4 {
            assert!((a.log_scales[[i, 0]] - (0.05f64 / 1.6).ln()).abs() < 1e-12);
            let d: f64 = a.means.row(i).iter().map(|v| v * v).sum::<f64>().sqrt();
            assert!(d > 0.0 && d < 0.5, "a sample near splat 0: {d}");
        }
    }

    #[test]
    fn transparent_and_huge_splats_are_pruned() {
        let mut m = model(0.001f64.ln(), [0.0, -10.0, 0.0]);
        let mut adam = Adam::new(AdamConfig::default()).unwrap();
        Densify::new(&SplatSettings::default(), 1.0, 0)
            .densify(&mut m, &mut adam)
            .unwrap();
        assert_eq!(m.len(), 2, "opacity sigmoid(-10) < 0.005");
        let mut m = model(0.5f64.ln(), [0.0; 3]);
        Densify::new(&SplatSettings::default(), 1.0, 0)
            .densify(&mut m, &mut adam)
            .unwrap();
        assert_eq!(m.len(), 0, "scale 0.5 > 0.1 x extent");
    }

    #[test]
    fn growth_stops_at_the_cap() {
        let mut m = model(0.001f64.ln(), [0.0; 3]);
        hot_first(&mut m);
        let mut adam = Adam::new(AdamConfig::default()).unwrap();
        let settings = SplatSettings {
            max_splats: 3,
            ..SplatSettings::default()
        };
        Densify::new(&settings, 1.0, 0).densify(&mut m, &mut adam).unwrap();
        assert_eq!(m.len(), 3);
    }

    #[test]
    fn rotation_by_a_quarter_turn_about_z() {
        let h = std::f64::consts::FRAC_PI_4;
        let r = rotate([h.cos(), 0.0, 0.0, h.sin()], [1.0, 0.0, 0.0]);
        assert!((r[0]).abs() < 1e-12 && (r[1] - 1.0).abs() < 1e-12 && r[2].abs() < 1e-12);
    }
}
