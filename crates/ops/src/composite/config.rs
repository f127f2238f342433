//! The composite's configuration (everything that is not differentiable) and how it is
//! applied to a tape.

use fogray_tape::{Float, Offsets, Tape, TapeError, Var};

use super::tape_order::{ByInput, ByOutput};
use crate::error::{Op, OpsError};

/// Where the background colour comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Background {
    /// No background input: rays that get through show black (all channels 0).
    None,
    /// One background `[ch]` for every ray.
    Shared,
    /// One background per ray, `[R, ch]`.
    PerRay,
}

/// The fused emission-absorption composite over packed rays (see the [module docs](super)).
///
/// Holds the ray packing and the options; the differentiable inputs are tape values passed to
/// [`Composite::apply`].
#[derive(Debug, Clone)]
pub struct Composite {
    pub(crate) offsets: Offsets,
    pub(crate) background: Background,
    pub(crate) min_transmittance: f64,
    pub(crate) depth: bool,
    pub(crate) weights: bool,
    pub(crate) transmittance: bool,
}

/// The tape values a composite reads. `sigma` and `delta` are `[n]`, `color` is `[n, ch]`,
/// `background` is `[ch]` (shared) or `[R, ch]` (per ray) and `t` is `[n]`.
#[derive(Debug, Clone, Copy)]
pub struct CompositeInputs {
    /// Density per sample (1/m), finite and non-negative.
    pub sigma: Var,
    /// Length per sample (m), finite and non-negative.
    pub delta: Var,
    /// Colour per sample, `[n, ch]` with `ch >= 1`, finite.
    pub color: Var,
    /// The background, required unless the op was built with [`Background::None`].
    pub background: Option<Var>,
    /// Sample depths, required with [`Composite::with_depth`], finite.
    pub t: Option<Var>,
}

/// The outputs of [`Composite::apply`].
#[derive(Debug, Clone, Copy)]
pub struct CompositeVars {
    /// Pixel colour `[R, ch]`.
    pub color: Var,
    /// Opacity `1 - T_end`, `[R]`.
    pub opacity: Var,
    /// Unnormalised expected depth `sum w_k t_k`, `[R]` (with [`Composite::with_depth`]).
    pub depth: Option<Var>,
    /// Stopping weights `w_k`, `[n]` (with [`Composite::with_weights`]).
    pub weights: Option<Var>,
    /// Transmittance `T_k` before each sample, `[n]` (with [`Composite::with_transmittance`]).
    pub transmittance: Option<Var>,
}

impl Composite {
    /// A composite over rays packed by `offsets` (`R + 1` entries, starting at 0, never
    /// decreasing; ray `r` owns samples `offsets[r]..offsets[r+1]`; empty rays are allowed).
    /// Defaults: shared background, exact (no early termination), outputs colour and opacity.
    pub fn new(offsets: &[usize]) -> Result<Self, OpsError> {
        Ok(Self::packed(Offsets::new(offsets).map_err(|source| {
            OpsError::Offsets {
                op: Op::Composite,
                source,
            }
        })?))
    }

    /// [`Composite::new`] over an already validated packing (for example a sampler's), which
    /// it shares instead of copying.
    /// Defaults: shared background, exact (no early termination), outputs colour and opacity.
    pub fn packed(offsets: Offsets) -> Self {
        Composite {
            offsets,
            background: Background::Shared,
            min_transmittance: 0.0,
            depth: false,
            weights: false,
            transmittance: false,
        }
    }

    /// Chooses where the background comes from.
    pub fn background(mut self, background: Background) -> Self {
        self.background = background;
        self
    }

    /// Early termination: samples from the first one whose transmittance is below `threshold`
    /// are treated as empty. `threshold` must be in `[0, 1]`; 0 (the default) is exact.
    pub fn min_transmittance(mut self, threshold: f64) -> Result<Self, OpsError> {
        if !(0.0..=1.0).contains(&threshold) {
            return Err(OpsError::config(
                Op::Composite,
                "min_transmittance",
                threshold,
                "must be in [0, 1]",
            ));
        }
        self.min_transmittance = threshold;
        Ok(self)
    }

    /// Also output the expected depth (needs the `t` input).
    pub fn with_depth(mut self) -> Self {
        self.depth = true;
        self
    }

    /// Also output the per-sample weights.
    pub fn with_weights(mut self) -> Self {
        self.weights = true;
        self
    }

    /// Also output the per-sample transmittance.
    pub fn with_transmittance(mut self) -> Self {
        self.transmittance = true;
        self
    }

    /// Number of rays.
    pub fn rays(&self) -> usize {
        self.offsets.len() - 1
    }

    /// Number of samples the packing expects.
    pub fn samples(&self) -> usize {
        self.offsets[self.offsets.len() - 1]
    }

    /// The packing.
    pub fn offsets(&self) -> &[usize] {
        &self.offsets
    }

    /// The packing, as the validated type (cloning it is cheap).
    pub fn packing(&self) -> &Offsets {
        &self.offsets
    }

    /// Checks that `inputs` hold a background exactly when the op has one and `t` exactly
    /// with depth; the error names the tape op `op` that was to be recorded.
    pub(super) fn check_tape_inputs(&self, op: &'static str, inputs: &CompositeInputs) -> Result<(), TapeError> {
        let misfit = |reason: &str| TapeError::InvalidArgument {
            op,
            reason: reason.into(),
        };
        match (self.background, inputs.background) {
            (Background::None, Some(_)) => return Err(misfit("a background was given to an op built without one")),
            (Background::Shared | Background::PerRay, None) => return Err(misfit("the op needs a background input")),
            _ => {}
        }
        match (self.depth, inputs.t) {
            (true, None) => Err(misfit("depth needs the t input")),
            (false, Some(_)) => Err(misfit("t was given but depth was not requested")),
            _ => Ok(()),
        }
    }

    /// Records the composite on `tape` through the tape's public custom-op interface.
    ///
    /// Errors: an input missing or superfluous for this configuration, shapes that do not fit
    /// the packing, or invalid values (each names the ray and sample); the tape is unchanged.
    pub fn apply<F: Float>(&self, tape: &mut Tape<F>, inputs: &CompositeInputs) -> Result<CompositeVars, TapeError> {
        self.check_tape_inputs("composite", inputs)?;
        let vars = ByInput {
            sigma: inputs.sigma,
            delta: inputs.delta,
            color: inputs.color,
            background: inputs.background,
            t: inputs.t,
        };
        let outs = tape.apply(self.clone(), &vars.into_tape())?;
        let outs = ByOutput::from_tape(self, outs)?;
        Ok(CompositeVars {
            color: outs.color,
            opacity: outs.opacity,
            depth: outs.depth,
            weights: outs.weights,
            transmittance: outs.transmittance,
        })
    }
}
