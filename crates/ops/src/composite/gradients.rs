//! The composite's gradients by name, for the calls without a tape: upstream gradients of the
//! outputs, which input gradients are wanted, and the input gradients (returned or written
//! into caller-owned buffers).

use fogray_tape::Float;
use ndarray::{ArrayD, ArrayViewD, ArrayViewMutD};

#[cfg(doc)]
use super::config::{Background, Composite};

/// Upstream gradients `dL/d output`, each of its output's shape (as in
/// [`CompositeOutputs`](super::CompositeOutputs)); `None` for an output the loss does not
/// read (its gradient is zero). `depth`, `weights` and `transmittance` may be given only for
/// an op built with that output.
#[derive(Debug, Clone)]
pub struct CompositeUpstream<'a, F> {
    /// `dL/dC`, `[R, ch]`.
    pub color: Option<ArrayViewD<'a, F>>,
    /// `dL/dopacity`, `[R]`.
    pub opacity: Option<ArrayViewD<'a, F>>,
    /// `dL/ddepth`, `[R]`.
    pub depth: Option<ArrayViewD<'a, F>>,
    /// `dL/dw`, `[n]`.
    pub weights: Option<ArrayViewD<'a, F>>,
    /// `dL/dT`, `[n]`.
    pub transmittance: Option<ArrayViewD<'a, F>>,
}

impl<F> Default for CompositeUpstream<'_, F> {
    /// No upstream gradient at all.
    fn default() -> Self {
        CompositeUpstream {
            color: None,
            opacity: None,
            depth: None,
            weights: None,
            transmittance: None,
        }
    }
}

impl<'a, F> CompositeUpstream<'a, F> {
    /// Only `dL/dC` (the common photometric loss).
    pub fn color(color: ArrayViewD<'a, F>) -> Self {
        CompositeUpstream {
            color: Some(color),
            ..Self::default()
        }
    }
}

/// Which input gradients [`Composite::vjp`] computes. `background` may be wanted only for an
/// op with a background, `t` only for one built [`Composite::with_depth`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CompositeWanted {
    /// `dL/dsigma`.
    pub sigma: bool,
    /// `dL/ddelta`.
    pub delta: bool,
    /// `dL/dcolor`.
    pub color: bool,
    /// `dL/dbackground`.
    pub background: bool,
    /// `dL/dt`.
    pub t: bool,
}

/// The input gradients of [`Composite::vjp`]: each `Some` exactly when it was wanted and some
/// upstream gradient reaches it (`None` otherwise: that gradient is zero), of its input's
/// shape (as in [`CompositeArrays`](super::CompositeArrays)).
#[derive(Debug, Clone, PartialEq)]
pub struct CompositeGradients<F> {
    /// `dL/dsigma`, `[n]`.
    pub sigma: Option<ArrayD<F>>,
    /// `dL/ddelta`, `[n]`.
    pub delta: Option<ArrayD<F>>,
    /// `dL/dcolor`, `[n, ch]`.
    pub color: Option<ArrayD<F>>,
    /// `dL/dbackground`, the background's shape (`[ch]` shared, `[R, ch]` per ray).
    pub background: Option<ArrayD<F>>,
    /// `dL/dt`, `[n]`.
    pub t: Option<ArrayD<F>>,
}

impl<F: Float> CompositeGradients<F> {
    /// Mutable views of the gradients present, to be written by [`Composite::vjp_into`] or
    /// [`Composite::evaluate_vjp_into`] (arrays kept from one step to the next).
    pub fn buffers(&mut self) -> CompositeGradientBuffers<'_, F> {
        CompositeGradientBuffers {
            sigma: self.sigma.as_mut().map(ArrayD::view_mut),
            delta: self.delta.as_mut().map(ArrayD::view_mut),
            color: self.color.as_mut().map(ArrayD::view_mut),
            background: self.background.as_mut().map(ArrayD::view_mut),
            t: self.t.as_mut().map(ArrayD::view_mut),
        }
    }
}

/// Caller-owned buffers for the input gradients of [`Composite::vjp_into`] and
/// [`Composite::evaluate_vjp_into`]: `Some` for each gradient wanted, of exactly its input's
/// shape, contiguous and row-major; `None` for the others. `background` only for an op with
/// a background, `t` only for one built [`Composite::with_depth`].
#[derive(Debug)]
pub struct CompositeGradientBuffers<'a, F> {
    /// `dL/dsigma`, `[n]`.
    pub sigma: Option<ArrayViewMutD<'a, F>>,
    /// `dL/ddelta`, `[n]`.
    pub delta: Option<ArrayViewMutD<'a, F>>,
    /// `dL/dcolor`, `[n, ch]`.
    pub color: Option<ArrayViewMutD<'a, F>>,
    /// `dL/dbackground`, the background's shape.
    pub background: Option<ArrayViewMutD<'a, F>>,
    /// `dL/dt`, `[n]`.
    pub t: Option<ArrayViewMutD<'a, F>>,
}

impl<F> Default for CompositeGradientBuffers<'_, F> {
    /// No gradient wanted.
    fn default() -> Self {
        CompositeGradientBuffers {
            sigma: None,
            delta: None,
            color: None,
            background: None,
            t: None,
        }
    }
}

impl<F> CompositeGradientBuffers<'_, F> {
    /// Which gradients these buffers ask for.
    pub fn wanted(&self) -> CompositeWanted {
        CompositeWanted {
            sigma: self.sigma.is_some(),
            delta: self.delta.is_some(),
            color: self.color.is_some(),
            background: self.background.is_some(),
            t: self.t.is_some(),
        }
    }
}
