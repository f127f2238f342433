//! One ray's attenuation in f64: `tau_k`, `T_k` and `alpha_k`, computed the same way by the
//! forward and the backward, so that the backward can recompute them instead of keeping them.

use fogray_tape::Float;

use super::decay::{exp_neg_slice, one_minus_exp_neg_slice};

/// Reusable buffers for one ray at a time (one per block of rays, so allocation is amortised).
#[derive(Debug, Default)]
pub(crate) struct Attenuation {
    /// `tau_k = sigma_k delta_k` (exact in f64 for f32 inputs).
    tau: Vec<f64>,
    /// Optical depth before sample k, `k = 0..=len` (the last is the whole ray's).
    depth: Vec<f64>,
    /// `T_k = exp(-depth_k)`, `k = 0..=len`: from the running depth, never a product of
    /// `1 - alpha` (which drifts by one rounding per sample and underflows in f32).
    trans: Vec<f64>,
    /// `alpha_k = -expm1(-tau_k)`: `1 - exp(-tau)` is 0 for `tau < 1.1e-16`.
    alpha: Vec<f64>,
    /// `w_k = T_k alpha_k`.
    weights: Vec<f64>,
}

/// Whether every sigma and delta is finite and non-negative (a fold, not a search, so that it
/// vectorises: valid input, the common case, is read once at full speed).
pub(crate) fn valid_steps<F: Float>(sigma: &[F], delta: &[F]) -> bool {
    let in_domain = |v: F| v >= F::zero() && v.is_finite();
    let s = sigma.iter().fold(true, |ok, &v| ok & in_domain(v));
    let d = delta.iter().fold(true, |ok, &v| ok & in_domain(v));
    s & d
}

impl Attenuation {
    /// Fills the buffers for one ray. Values outside the domain (see [`valid_steps`]) give
    /// meaningless results, never a panic.
    pub(crate) fn compute<F: Float>(&mut self, sigma: &[F], delta: &[F]) {
        let len = sigma.len();
        self.tau.clear();
        self.tau
            .extend(sigma.iter().zip(delta).map(|(&s, &d)| s.as_f64() * d.as_f64()));
        self.depth.resize(len + 1, 0.0);
        // The one sequential chain of the forward: a single f64 addition per sample.
        let mut running = 0.0f64;
        for (d, &tau) in self.depth.iter_mut().zip(&self.tau) {
            *d = running;
            running += tau;
        }
        self.depth[len] = running;
        self.trans.resize(len + 1, 0.0);
        self.alpha.resize(len, 0.0);
        exp_neg_slice(&self.depth, &mut self.trans);
        one_minus_exp_neg_slice(&self.tau, &mut self.alpha);
        self.weights.clear();
        self.weights
            .extend(self.trans.iter().zip(&self.alpha).map(|(&t, &a)| t * a));
    }

    /// The first sample whose transmittance is below `min_transmittance` (early termination),
    /// or the ray's length.
    pub(crate) fn stop(&self, min_transmittance: f64) -> usize {
        let len = self.alpha.len();
        if min_transmittance <= 0.0 {
            return len;
        }
        self.trans[..len]
            .iter()
            .position(|&t| t < min_transmittance)
            .unwrap_or(len)
    }

    /// `T_k`, `k = 0..=len`.
    pub(crate) fn transmittance(&self) -> &[f64] {
        &self.trans
    }

    /// `alpha_k`, `k = 0..len`.
    pub(crate) fn alpha(&self) -> &[f64] {
        &self.alpha
    }

    /// `w_k = T_k alpha_k`, `k = 0..len`.
    pub(crate) fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// The optical depth before sample `k` (`k = len`: the whole ray's).
    pub(crate) fn depth_before(&self, k: usize) -> f64 {
        self.depth[k]
    }
}
