//! The composite's inputs and outputs as named arrays, for the calls without a tape
//! ([`Composite::evaluate`] and the calls into caller-owned buffers).

use fogray_tape::Float;
use ndarray::{ArrayD, ArrayViewD, ArrayViewMutD};

#[cfg(doc)]
use super::config::{Background, Composite};

/// The arrays a composite reads: `sigma` and `delta` are `[n]`, `color` is `[n, ch]` with
/// `ch >= 1`, `background` is `[ch]` ([`Background::Shared`]) or `[R, ch]`
/// ([`Background::PerRay`]) and `t` is `[n]`, `n` being where the op's offsets end.
///
/// `background` must be given exactly when the op has one (not [`Background::None`]), `t`
/// exactly when it was built [`Composite::with_depth`].
#[derive(Debug, Clone)]
pub struct CompositeArrays<'a, F> {
    /// Density per sample (1/m), finite and non-negative.
    pub sigma: ArrayViewD<'a, F>,
    /// Length per sample (m), finite and non-negative.
    pub delta: ArrayViewD<'a, F>,
    /// Colour per sample, `[n, ch]`, finite.
    pub color: ArrayViewD<'a, F>,
    /// The background colour, finite.
    pub background: Option<ArrayViewD<'a, F>>,
    /// Sample depths, finite.
    pub t: Option<ArrayViewD<'a, F>>,
}

impl<'a, F> CompositeArrays<'a, F> {
    /// The three inputs every composite reads, with no background and no depths.
    pub fn new(sigma: ArrayViewD<'a, F>, delta: ArrayViewD<'a, F>, color: ArrayViewD<'a, F>) -> Self {
        CompositeArrays {
            sigma,
            delta,
            color,
            background: None,
            t: None,
        }
    }

    /// With the background (for an op that has one).
    pub fn with_background(mut self, background: ArrayViewD<'a, F>) -> Self {
        self.background = Some(background);
        self
    }

    /// With the sample depths (for an op built [`Composite::with_depth`]).
    pub fn with_t(mut self, t: ArrayViewD<'a, F>) -> Self {
        self.t = Some(t);
        self
    }
}

/// What [`Composite::evaluate`] returns: `color` and `opacity` always, the others exactly when
/// the op was built with them.
#[derive(Debug, Clone, PartialEq)]
pub struct CompositeOutputs<F> {
    /// Pixel colour `[R, ch]`.
    pub color: ArrayD<F>,
    /// Opacity `[R]`.
    pub opacity: ArrayD<F>,
    /// Unnormalised expected depth `[R]` ([`Composite::with_depth`]).
    pub depth: Option<ArrayD<F>>,
    /// Stopping weights `[n]` ([`Composite::with_weights`]).
    pub weights: Option<ArrayD<F>>,
    /// Transmittance before each sample `[n]` ([`Composite::with_transmittance`]).
    pub transmittance: Option<ArrayD<F>>,
}

impl<F: Float> CompositeOutputs<F> {
    /// Mutable views of every output, to be written by [`Composite::evaluate_into`] (arrays
    /// kept from one step to the next).
    pub fn buffers(&mut self) -> CompositeOutputBuffers<'_, F> {
        CompositeOutputBuffers {
            color: self.color.view_mut(),
            opacity: self.opacity.view_mut(),
            depth: self.depth.as_mut().map(ArrayD::view_mut),
            weights: self.weights.as_mut().map(ArrayD::view_mut),
            transmittance: self.transmittance.as_mut().map(ArrayD::view_mut),
        }
    }
}

/// Caller-owned buffers for the outputs of [`Composite::evaluate_into`] and
/// [`Composite::evaluate_vjp_into`]: each of exactly its output's shape (as in
/// [`CompositeOutputs`]), contiguous and row-major; `depth`, `weights` and `transmittance`
/// given exactly when the op was built with them.
#[derive(Debug)]
pub struct CompositeOutputBuffers<'a, F> {
    /// `[R, ch]`.
    pub color: ArrayViewMutD<'a, F>,
    /// `[R]`.
    pub opacity: ArrayViewMutD<'a, F>,
    /// `[R]`.
    pub depth: Option<ArrayViewMutD<'a, F>>,
    /// `[n]`.
    pub weights: Option<ArrayViewMutD<'a, F>>,
    /// `[n]`.
    pub transmittance: Option<ArrayViewMutD<'a, F>>,
}

impl<'a, F> CompositeOutputBuffers<'a, F> {
    /// Buffers for the colour and the opacity only (an op with no optional output).
    pub fn new(color: ArrayViewMutD<'a, F>, opacity: ArrayViewMutD<'a, F>) -> Self {
        CompositeOutputBuffers {
            color,
            opacity,
            depth: None,
            weights: None,
            transmittance: None,
        }
    }
}
