//! What a grid model does with its raw values once it has looked them up: the density and
//! colour activation (or view-dependent colour through spherical harmonics) and the
//! composite over the packed samples, fused or taped. The dense and the sparse grid differ
//! only in the lookup they pass in.

use fogray_ops::activation::DensityColor;
use fogray_ops::distortion::DistortionLoss;
use fogray_ops::rays::RayBatch;
use fogray_ops::sample::PackedSamples;
use fogray_ops::{Background, Composite, CompositeInputs, CompositeVars, ShColor};
use fogray_tape::{Float, Tape, TapeError, Var};
use ndarray::{Array1, Array2};

use crate::environment::Environment;
use crate::error::FitError;
use crate::model::{TrainingBackground, TrainingLoss};
use crate::settings::{FitSettings, Method};

/// Channels of a view-independent raw value: density, then red, green, blue.
pub(crate) const VIEW_INDEPENDENT_CHANNELS: usize = 4;

/// How raw values become density and colour.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Shading {
    /// The density's shift and the view-independent colour's sigmoid.
    pub activation: DensityColor,
    /// View-dependent colour: channels `1..` of a raw value are its coefficients.
    pub sh: Option<ShColor>,
    /// A learned background in place of the dataset's fixed one (its coefficients are the
    /// model's [`ENVIRONMENT`](crate::environment::ENVIRONMENT) parameter).
    pub environment: Option<Environment>,
}

/// What [`Shading::composite_inputs`] records.
#[derive(Debug)]
pub(crate) struct Shaded {
    /// The composite over the samples' rays.
    pub composite: Composite,
    /// Its inputs on the tape.
    pub inputs: CompositeInputs,
    /// The weighted distortion loss (a 0-d value), when it was asked for.
    pub distortion: Option<Var>,
}

impl Shaded {
    /// Records the composite (colour, opacity and the depth if it was asked for).
    ///
    /// Errors: from the ops.
    pub(crate) fn render<F: Float>(self, tape: &mut Tape<F>, method: Method) -> Result<CompositeVars, TapeError> {
        method.kernels().composite(tape, &self.composite, &self.inputs)
    }

    /// Records the training loss against `target` (`[R, 3]`): the mean squared error of the
    /// composite's colour ([`Kernels::composite_mse`](crate::kernels::Kernels::composite_mse));
    /// the objective adds the distortion loss and
    /// `prior`, where there are.
    ///
    /// Errors: from the ops.
    pub(crate) fn training_loss<F: Float>(
        self,
        tape: &mut Tape<F>,
        target: Var,
        method: Method,
        prior: Option<Var>,
    ) -> Result<TrainingLoss, TapeError> {
        let photometric = method
            .kernels()
            .composite_mse(tape, &self.composite, &self.inputs, target)?;
        let mut objective = photometric;
        for term in [self.distortion, prior].into_iter().flatten() {
            objective = tape.add(objective, term)?;
        }
        Ok(TrainingLoss { photometric, objective })
    }
}

impl Shading {
    /// The shading of density shift `shift` with spherical harmonics of `degree` (0:
    /// view-independent colour).
    ///
    /// Errors: a shift that is not finite, a degree above 3 ([`FitError::SettingOp`] naming the
    /// flag).
    pub(crate) fn new(shift: f64, degree: usize) -> Result<Self, FitError> {
        let sh = match degree {
            0 => None,
            d => Some(ShColor::new(d).map_err(|source| FitError::SettingOp {
                flag: "--sh-degree",
                source,
            })?),
        };
        Ok(Shading {
            activation: DensityColor::new(shift)?,
            sh,
            environment: None,
        })
    }

    /// The shading `settings` name: [`Shading::new`] of their shift and degree, with a learned
    /// background if they ask for one.
    ///
    /// Errors: as [`Shading::new`].
    pub(crate) fn of(settings: &FitSettings) -> Result<Self, FitError> {
        let environment = match settings.learn_background {
            true => Some(Environment::new(settings.background_degree)?),
            false => None,
        };
        Ok(Shading {
            environment,
            ..Shading::new(settings.shift, settings.sh_degree)?
        })
    }

    /// The density of raw values `raw` (`[m, C]`, as a grid field's lookup returns them).
    ///
    /// Errors: raw values that are not 2-d, a NaN density.
    pub(crate) fn densities<F: Float>(&self, raw: ndarray::ArrayD<F>) -> Result<ndarray::Array1<F>, FitError> {
        let raw = raw
            .into_dimensionality::<ndarray::Ix2>()
            .map_err(|e| FitError::Config(format!("raw values: {e}")))?;
        Ok(self.activation.density(raw.view())?)
    }

    /// The view-independent colour `[m, 3]` of raw values `raw` (`[m, C]`, as a grid field's
    /// lookup returns them), for a mesh's vertex colours: with spherical harmonics, the
    /// degree-0 term alone through the colour activation, `sigmoid(Y_0 k_c0)` (the colour of
    /// the mean over all directions of the activation's input: the higher bands average to 0
    /// over the sphere); otherwise the view-independent colour itself, `sigmoid(raw_1..4)`.
    /// Each value is computed by the render's own ops, so it rounds as a render does.
    ///
    /// Errors: raw values that are not 2-d or have too few channels, a NaN value.
    pub(crate) fn base_colors<F: Float>(&self, raw: ndarray::ArrayD<F>) -> Result<Array2<F>, FitError> {
        let raw = raw
            .into_dimensionality::<ndarray::Ix2>()
            .map_err(|e| FitError::Config(format!("raw values: {e}")))?;
        if raw.ncols() != self.channels() {
            return Err(FitError::Config(format!(
                "raw values: {} channels, the shading's are {}",
                raw.ncols(),
                self.channels()
            )));
        }
        match &self.sh {
            None => Ok(self.activation.evaluate(raw.view())?.color),
            Some(sh) => {
                // Channel c's degree-0 coefficient is column 1 + c B; degree 0's one basis
                // function is a constant, so any unit direction gives the same colour.
                let b = sh.basis_count();
                let dc = Array2::from_shape_fn((raw.nrows(), 3), |(i, c)| raw[[i, 1 + c * b]]);
                let direction =
                    Array2::from_shape_fn((raw.nrows(), 3), |(_, a)| F::lit(if a == 2 { 1.0 } else { 0.0 }));
                let constant = ShColor::new(0).map_err(|e| FitError::Config(format!("degree 0: {e}")))?;
                constant
                    .evaluate(dc.view(), direction.view())
                    .map_err(|e| FitError::Config(format!("base colour: {e}")))
            }
        }
    }

    /// Channels of a raw value: the density, then the colour's (3, or the spherical
    /// harmonics' coefficients).
    pub(crate) fn channels(&self) -> usize {
        self.sh
            .map_or(VIEW_INDEPENDENT_CHANNELS, |sh| 1 + sh.coefficient_count())
    }

    /// Records `lookup` (sample positions `[n, 3]` to raw values `[n, C]`) of `samples` of
    /// `rays`, the activation and the colour, and returns the composite over the samples' rays
    /// (over `background`, shared or one per ray; with the depth if `depth`) with its inputs,
    /// and, if `distortion` is above 0, the distortion loss of the samples' weights times it.
    ///
    /// With a learned background, `environment` (its coefficients on the tape) stands in for a
    /// shared `background`; a per-ray background (random colours against pictures with alpha)
    /// is still composited over as given.
    #[allow(clippy::too_many_arguments)] // one call site each in the grid models' render and loss
    pub(crate) fn composite_inputs<F: Float>(
        &self,
        tape: &mut Tape<F>,
        rays: &RayBatch<F>,
        samples: PackedSamples<F>,
        background: TrainingBackground<F>,
        environment: Option<Var>,
        method: Method,
        depth: bool,
        distortion: f64,
        lookup: impl FnOnce(&mut Tape<F>, Var) -> Result<Var, TapeError>,
    ) -> Result<Shaded, TapeError> {
        // Each sample's view direction, its ray's (a constant: no gradient).
        let directions = self.sh.as_ref().map(|_| {
            let d = rays.directions();
            Array2::from_shape_fn((samples.len(), 3), |(k, a)| d[[samples.ray[k], a]])
        });
        let (vars, offsets) = samples.into_tape(tape);
        let raw = lookup(tape, vars.positions)?;
        // With spherical harmonics the activation sees the density and the first coefficient
        // (it needs a colour channel) and only its density is used.
        let activation_input = match &self.sh {
            Some(_) => tape.slice(raw, 1, 0, 2)?,
            None => raw,
        };
        let kernels = method.kernels();
        let activated = kernels.density_color(tape, &self.activation, activation_input)?;
        let color = match (&self.sh, directions) {
            (Some(sh), Some(directions)) => {
                let coefficients = tape.slice(raw, 1, 1, self.channels())?;
                let directions = tape.constant(directions);
                kernels.sh_color(tape, sh, coefficients, directions)?
            }
            _ => activated.color,
        };
        let (background, kind) = match (background, self.environment.zip(environment)) {
            (TrainingBackground::Shared(_), Some((learned, coefficients))) => (
                learned.record(tape, coefficients, rays.directions())?,
                Background::PerRay,
            ),
            (TrainingBackground::Shared(b), _) => (tape.constant(Array1::from_iter(b.map(F::lit))), Background::Shared),
            (TrainingBackground::PerRay(b), _) => (tape.constant(b), Background::PerRay),
        };
        let inputs = CompositeInputs {
            sigma: activated.sigma,
            delta: vars.delta,
            color,
            background: Some(background),
            t: depth.then_some(vars.t),
        };
        let distortion = if distortion > 0.0 {
            let op = DistortionLoss::packed(offsets.clone());
            let loss = kernels.distortion(tape, &op, activated.sigma, vars.delta, vars.t)?;
            Some(tape.mul_scalar(loss, F::lit(distortion))?)
        } else {
            None
        };
        let op = Composite::packed(offsets).background(kind);
        Ok(Shaded {
            composite: if depth { op.with_depth() } else { op },
            inputs,
            distortion,
        })
    }
}
