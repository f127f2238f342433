//! [`SplatModel`]: 3-D Gaussians whose five parameters live in one tape parameter store, so
//! that Adam steps them and a tape lends them to [`SplatRender`] without a copy. A splat's
//! colour is view dependent: spherical harmonics of the direction from the camera to its
//! mean, through the sigmoid ([`ShColor`], the grid's colour), evaluated on the tape before
//! the splats are drawn.

use fogray_ops::limits::{self, Bytes};
use fogray_ops::sh::ShColor;
use fogray_ops::splat::{SplatRender, SplatVars};
use fogray_ops::PinholeCamera;
use fogray_tape::params::{ParamId, Params};
use fogray_tape::{Float, Tape};
use ndarray::{Array1, Array2, ArrayViewD, Ix1, Ix2};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha12Rng;

use super::knn::mean_neighbour_distance;
use crate::error::FitError;

/// The opacity every splat starts with (3DGS's), stored as its logit.
pub(crate) const INITIAL_OPACITY: f64 = 0.1;

/// The splats' parameters as plain arrays, `n` rows each (shapes as [`SplatVars`], but for
/// the colour, which is spherical harmonics).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct SplatArraysOwned<F> {
    /// Means `[n, 3]`, world frame.
    pub means: Array2<F>,
    /// Log standard deviations `[n, 3]`.
    pub log_scales: Array2<F>,
    /// Quaternions `[n, 4]` (`w, x, y, z`, any non-zero length).
    pub quats: Array2<F>,
    /// Opacity logits `[n]`.
    pub opacity_logits: Array1<F>,
    /// Spherical-harmonics coefficients `[n, 3 B]`, `B = (degree + 1)^2`, channel-major as
    /// [`ShColor`] reads them (the colour is their sigmoid: 0 is grey).
    pub sh: Array2<F>,
}

/// The five parameters' ids in a [`SplatModel`]'s store.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct SplatIds {
    /// Means.
    pub means: ParamId,
    /// Log-scales.
    pub log_scales: ParamId,
    /// Quaternions.
    pub quats: ParamId,
    /// Opacity logits.
    pub opacity_logits: ParamId,
    /// Spherical-harmonics coefficients.
    pub sh: ParamId,
}

/// 3-D Gaussian splats as a trainable model (see the [module docs](super)).
#[derive(Debug)]
pub(crate) struct SplatModel<F: Float> {
    params: Params<F>,
    ids: SplatIds,
    colour: ShColor,
    /// Per splat, the sum of its mean-gradient norms since the last densification, and the
    /// number of steps whose gradient reached it (the views it was seen in).
    gradient_sum: Vec<f64>,
    seen: Vec<u32>,
}

/// Refuses `n` splats beyond `cap` or beyond the memory their copies need.
pub(crate) fn check_count(n: usize, cap: usize) -> Result<(), FitError> {
    if n > cap {
        return Err(FitError::TooManySplats { count: n, cap });
    }
    // At most 59 numbers a splat (degree 3), each held as value, gradient and Adam's two moments (and a spare
    // for the densification's new arrays).
    let need = Bytes::product(&[n as u64, 59, 8]).times(limits::PARAMETER_COPIES);
    Bytes::check(need, limits::available(), "splats", &format!("{n} splats"))?;
    Ok(())
}

impl<F: Float> SplatModel<F> {
    /// The model of `arrays`, whose colours are of spherical-harmonics degree `degree`.
    ///
    /// Errors: a degree above 3, rows that disagree in number or a wrong column count, a
    /// non-finite value ([`FitError::Config`]).
    pub(crate) fn new(arrays: SplatArraysOwned<F>, degree: usize) -> Result<Self, FitError> {
        let colour = ShColor::new(degree)?;
        let n = arrays.means.nrows();
        let shapes_ok = arrays.means.ncols() == 3
            && arrays.log_scales.dim() == (n, 3)
            && arrays.quats.dim() == (n, 4)
            && arrays.opacity_logits.len() == n
            && arrays.sh.dim() == (n, colour.coefficient_count());
        if !shapes_ok {
            return Err(FitError::Config(format!(
                "splat arrays of {n} means disagree in shape (degree {degree}: {} colour coefficients)",
                colour.coefficient_count()
            )));
        }
        let finite = arrays.means.iter().chain(&arrays.log_scales).chain(&arrays.quats);
        if !finite
            .chain(&arrays.opacity_logits)
            .chain(&arrays.sh)
            .all(|v| v.is_finite())
        {
            return Err(FitError::Config("a splat parameter is not finite".into()));
        }
        let mut params = Params::new();
        let ids = SplatIds {
            means: params.add("means", arrays.means)?,
            log_scales: params.add("log_scales", arrays.log_scales)?,
            quats: params.add("quats", arrays.quats)?,
            opacity_logits: params.add("opacity_logits", arrays.opacity_logits)?,
            sh: params.add("sh", arrays.sh)?,
        };
        Ok(SplatModel {
            params,
            ids,
            colour,
            gradient_sum: vec![0.0; n],
            seen: vec![0; n],
        })
    }

    /// Splats at `points` with `colors` (RGB in `[0, 1]`, one per point, the same from every
    /// direction), each round with the standard deviation of its mean distance to its 3
    /// nearest neighbours (at least `1e-7`, so that coincident points keep a finite
    /// log-scale), opacity [`INITIAL_OPACITY`], colours of spherical-harmonics degree
    /// `degree`. At most `cap` points.
    ///
    /// Errors: no point, more than `cap` points or too many for memory
    /// ([`FitError::TooManySplats`], [`FitError::TooLarge`]), colours not one per point or a
    /// non-finite coordinate ([`FitError::Config`]).
    pub(crate) fn from_points(
        points: &[[f64; 3]],
        colors: &[[f64; 3]],
        degree: usize,
        cap: usize,
    ) -> Result<Self, FitError> {
        let n = points.len();
        if n == 0 || colors.len() != n {
            return Err(FitError::Config(format!(
                "splats from {n} points need at least one point and a colour each ({} colours)",
                colors.len()
            )));
        }
        check_count(n, cap)?;
        if points.iter().flatten().any(|v| !v.is_finite()) {
            return Err(FitError::Config("a point's coordinate is not finite".into()));
        }
        let scales = mean_neighbour_distance(points);
        let logit = |p: f64| (p / (1.0 - p)).ln();
        let basis = ShColor::new(degree)?.basis_count();
        // sigmoid(C0 k) = c: the degree-0 coefficient k = logit(c) / C0, kept off the
        // sigmoid's flat ends.
        let dc = |c: f64| logit(c.clamp(0.02, 0.98)) / fogray_ops::sh::basis::C0;
        Self::new(
            SplatArraysOwned {
                means: Array2::from_shape_fn((n, 3), |(i, a)| F::lit(points[i][a])),
                log_scales: Array2::from_shape_fn((n, 3), |(i, _)| F::lit(scales[i].max(1e-7).ln())),
                quats: Array2::from_shape_fn((n, 4), |(_, a)| F::lit(if a == 0 { 1.0 } else { 0.0 })),
                opacity_logits: Array1::from_elem(n, F::lit(logit(INITIAL_OPACITY))),
                sh: Array2::from_shape_fn((n, 3 * basis), |(i, k)| {
                    F::lit(if k % basis == 0 { dc(colors[i][k / basis]) } else { 0.0 })
                }),
            },
            degree,
        )
    }

    /// `n` splats uniformly at random in the box `bounds` (`[min, max]` corners), grey,
    /// otherwise as [`SplatModel::from_points`], drawn from `seed`.
    ///
    /// Errors: those of [`SplatModel::from_points`], and an empty or non-finite box.
    pub(crate) fn random(
        bounds: [[f64; 3]; 2],
        n: usize,
        degree: usize,
        seed: u64,
        cap: usize,
    ) -> Result<Self, FitError> {
        let [lo, hi] = bounds;
        if (0..3).any(|a| !(lo[a].is_finite() && hi[a].is_finite() && lo[a] < hi[a])) {
            return Err(FitError::Config(format!(
                "the splats' box {bounds:?} is empty or not finite"
            )));
        }
        check_count(n, cap)?;
        let mut rng = ChaCha12Rng::seed_from_u64(seed);
        let points: Vec<[f64; 3]> = (0..n)
            .map(|_| [0, 1, 2].map(|a| lo[a] + (hi[a] - lo[a]) * rng.gen::<f64>()))
            .collect();
        Self::from_points(&points, &vec![[0.5; 3]; n], degree, cap)
    }

    /// How many splats.
    pub(crate) fn len(&self) -> usize {
        self.seen.len()
    }

    /// Adds one step's gradient of the means `[n, 3]` to the statistics densification reads:
    /// its norm per splat, counted only where it is non-zero (the splat was seen).
    ///
    /// The op's backward gives the gradient of the 3-D means, not of the projected 2-D ones
    /// that 3DGS thresholds; its norm is the 2-D one times about `focal / depth`.
    ///
    /// Errors: a gradient of another shape ([`FitError::Config`]).
    pub(crate) fn observe(&mut self, means_gradient: ArrayViewD<'_, F>) -> Result<(), FitError> {
        if means_gradient.shape() != [self.len(), 3] {
            return Err(FitError::Config(format!(
                "a means gradient {:?} for {} splats",
                means_gradient.shape(),
                self.len()
            )));
        }
        for (i, row) in means_gradient.outer_iter().enumerate() {
            let norm = row.iter().map(|g| g.as_f64().powi(2)).sum::<f64>().sqrt();
            if norm > 0.0 {
                self.gradient_sum[i] += norm;
                self.seen[i] += 1;
            }
        }
        Ok(())
    }

    /// Each splat's mean gradient norm over the steps that saw it (0 if none did).
    pub(crate) fn mean_gradients(&self) -> Vec<f64> {
        self.gradient_sum
            .iter()
            .zip(&self.seen)
            .map(|(&s, &k)| if k == 0 { 0.0 } else { s / f64::from(k) })
            .collect()
    }

    /// The parameter store (for the optimiser and checkpoints).
    pub(crate) fn params(&self) -> &Params<F> {
        &self.params
    }

    /// The parameter store, mutable (for the optimiser's step).
    pub(crate) fn params_mut(&mut self) -> &mut Params<F> {
        &mut self.params
    }

    /// The five parameters' ids.
    pub(crate) fn ids(&self) -> SplatIds {
        self.ids
    }

    /// Trainable values: 11 a splat and its colour coefficients.
    pub(crate) fn parameter_count(&self) -> usize {
        self.len() * (11 + self.colour.coefficient_count())
    }

    /// The colours' spherical-harmonics degree.
    pub(crate) fn degree(&self) -> usize {
        self.colour.degree()
    }

    /// A copy of the parameters as arrays.
    ///
    /// Errors: [`FitError::Param`] if a parameter is lent to a tape that was not cleared.
    pub(crate) fn arrays(&self) -> Result<SplatArraysOwned<F>, FitError> {
        let two = |id| -> Result<Array2<F>, FitError> {
            let v = self.params.get(id)?.to_owned();
            v.into_dimensionality::<Ix2>()
                .map_err(|e| FitError::Config(format!("a splat parameter lost its shape: {e}")))
        };
        let logits = self.params.get(self.ids.opacity_logits)?.to_owned();
        Ok(SplatArraysOwned {
            means: two(self.ids.means)?,
            log_scales: two(self.ids.log_scales)?,
            quats: two(self.ids.quats)?,
            opacity_logits: logits
                .into_dimensionality::<Ix1>()
                .map_err(|e| FitError::Config(format!("a splat parameter lost its shape: {e}")))?,
            sh: two(self.ids.sh)?,
        })
    }

    /// The unit directions `[n, 3]` from `centre` to each mean (a mean at the centre looks
    /// along +z: any unit vector will do where no ray reaches).
    pub(crate) fn directions_from(&self, centre: [f64; 3]) -> Result<Array2<F>, FitError> {
        let means = self.params.get(self.ids.means)?;
        let n = self.len();
        let mut out = Array2::<F>::zeros((n, 3));
        for (i, mut row) in out.outer_iter_mut().enumerate() {
            let d = [0, 1, 2].map(|a| means[[i, a]].as_f64() - centre[a]);
            let norm = d.iter().map(|v| v * v).sum::<f64>().sqrt();
            let unit = if norm > 0.0 && norm.is_finite() {
                d.map(|v| v / norm)
            } else {
                [0.0, 0.0, 1.0]
            };
            for a in 0..3 {
                row[a] = F::lit(unit[a]);
            }
        }
        Ok(out)
    }

    /// Lends the parameters to `tape` (gradients flow back to this store) and records the
    /// colours seen from `centre` (a camera's): the op's inputs.
    ///
    /// Errors: [`FitError::Tape`] if a parameter is of another store.
    pub(crate) fn vars(&self, tape: &mut Tape<F>, centre: [f64; 3]) -> Result<SplatVars, FitError> {
        let sh = tape.param_from(&self.params, self.ids.sh)?;
        let directions = tape.constant(self.directions_from(centre)?);
        Ok(SplatVars {
            means: tape.param_from(&self.params, self.ids.means)?,
            log_scales: tape.param_from(&self.params, self.ids.log_scales)?,
            quats: tape.param_from(&self.params, self.ids.quats)?,
            opacity_logits: tape.param_from(&self.params, self.ids.opacity_logits)?,
            colors: self.colour.apply(tape, sh, directions)?,
        })
    }

    /// The image `[height * width, 3]` (row-major pixels) of the splats from `camera` over
    /// `background`, without a tape.
    ///
    /// Errors: those of [`SplatRender`] (a distorted camera, too many tile intersections).
    pub(crate) fn render(&self, camera: &PinholeCamera, background: [f64; 3]) -> Result<Array2<F>, FitError> {
        let op = SplatRender::new(camera, background)?;
        let mut tape = Tape::<F>::new();
        let vars = self.vars(&mut tape, camera.centre())?;
        let image = op.apply(&mut tape, &vars)?;
        let out = tape.value(image)?.to_owned();
        tape.clear();
        out.into_dimensionality::<Ix2>()
            .map_err(|e| FitError::Config(format!("the splat image lost its shape: {e}")))
    }
}
