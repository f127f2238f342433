//! One ray's attenuation in f64: `tau_k`, `T_k` and `alpha_k`, computed the same way by the
//! forward and the backward, so that the backward can recompute them instead of keeping them.

use fogray_tape::Float;

use crate::math::exp::{exp_neg, exp_neg_slice, one_minus_exp_neg, one_minus_exp_neg_slice, single_tier};

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
    /// See [`Attenuation::stop`].
    stop: usize,
    /// The ray's length: the buffers only grow (see [`grow`]), and may be longer.
    len: usize,
    /// Whether `alpha[len]` holds the whole ray's opacity `-expm1(-depth[len])` (see
    /// [`Attenuation::compute_whole`]).
    opacity_after: bool,
}

/// Samples per step when early termination may stop a ray: a multiple of the prefix sums'
/// group of 4, so that the values are bitwise those of the ray taken whole.
const CHUNK: usize = 32;

/// Values a step of the exponentials' vector loops: a whole AVX-512 register of f64.
const STEP: usize = 8;

/// Makes `v` at least `n` long. Scratch buffers only grow: resized to each ray's length, they
/// cleared their new tails ray after ray when lengths change (a `memset` in every profile of
/// rays of random lengths).
#[inline(always)]
pub(crate) fn grow(v: &mut Vec<f64>, n: usize) {
    if v.len() < n {
        v.resize(n, 0.0);
    }
}

/// `out[k] = running + sum_{j<k} x[j]`; returns the new running total. Four samples at a time: the sums within a
/// group are off the chain, which carries one addition per group instead of one per sample
/// (each `out[k]` is then the running total plus at most three terms, as accurate as the
/// one-at-a-time sum).
#[inline(always)]
fn exclusive_prefix_sums(x: &[f64], out: &mut [f64], mut running: f64) -> f64 {
    let mut groups = out.chunks_exact_mut(4);
    let mut terms = x.chunks_exact(4);
    for (o, t) in (&mut groups).zip(&mut terms) {
        let p1 = t[0] + t[1];
        let p2 = p1 + t[2];
        let p3 = p2 + t[3];
        o[0] = running;
        o[1] = running + t[0];
        o[2] = running + p1;
        o[3] = running + p2;
        running += p3;
    }
    for (o, &t) in groups.into_remainder().iter_mut().zip(terms.remainder()) {
        *o = running;
        running += t;
    }
    running
}

/// Whether every sigma and delta is finite and non-negative (a fold, not a search, so that it
/// vectorises: valid input, the common case, is read once at full speed).
#[inline(always)]
pub(crate) fn valid_steps<F: Float>(sigma: &[F], delta: &[F]) -> bool {
    // Two comparisons and no branch: NaN fails both, infinity the second.
    let (zero, max) = (F::zero(), F::max_value());
    let in_domain = |v: F| (v >= zero) & (v <= max);
    let s = sigma.iter().fold(true, |ok, &v| ok & in_domain(v));
    let d = delta.iter().fold(true, |ok, &v| ok & in_domain(v));
    s & d
}

impl Attenuation {
    /// Buffers for rays of up to `len` samples, allocated once (they would otherwise grow by
    /// reallocation as longer rays come).
    pub(crate) fn for_rays(len: usize) -> Self {
        let room = (len + 1).next_multiple_of(STEP);
        let buffer = || Vec::with_capacity(room);
        Attenuation {
            tau: buffer(),
            depth: buffer(),
            trans: buffer(),
            alpha: buffer(),
            weights: buffer(),
            ..Self::default()
        }
    }

    /// Fills the buffers for one ray, up to its stop: with `min_transmittance > 0`, samples are
    /// taken [`CHUNK`] at a time and nothing is computed past the chunk where the transmittance
    /// first falls below it (so early termination saves the work it promises). Values outside
    /// the domain (see [`valid_steps`]) give meaningless results, never a panic.
    #[inline(always)]
    pub(crate) fn compute<F: Float>(&mut self, sigma: &[F], delta: &[F], min_transmittance: f64) {
        if min_transmittance > 0.0 || sigma.len() % STEP == 0 {
            self.compute_in_parts(sigma, delta, min_transmittance);
        } else {
            self.compute_whole(sigma, delta);
        }
    }

    /// [`Attenuation::compute`] without early termination, for a ray whose length is not a
    /// whole number of [`STEP`]s. The exponentials run over whole steps, into the buffers'
    /// padding past the ray's values (scratch: computed, never read), where a loop over the
    /// ray itself would run its last `len % STEP` values one scalar polynomial at a time (on a
    /// ray of twenty samples, about as long as its vector part). The padding also has room for
    /// the ray's own `T_len` and opacity, from its whole optical depth, which then need no
    /// scalar polynomial either. Every value gets the same bits as in
    /// [`Attenuation::compute_in_parts`]: the same function of the same argument.
    #[inline(always)]
    fn compute_whole<F: Float>(&mut self, sigma: &[F], delta: &[F]) {
        let len = sigma.len();
        // The samples and one slot more (`T_len` in `trans`, the opacity in `alpha`), in whole
        // steps.
        let steps = (len + 1).next_multiple_of(STEP);
        for v in [&mut self.tau, &mut self.alpha, &mut self.depth, &mut self.trans] {
            grow(v, steps);
        }
        grow(&mut self.weights, len);
        self.len = len;
        self.stop = len;
        self.opacity_after = true;
        let (tau, alpha) = (&mut self.tau[..steps], &mut self.alpha[..steps]);
        let (depth, trans) = (&mut self.depth[..steps], &mut self.trans[..steps]);
        for ((t, &s), &d) in tau.iter_mut().zip(sigma).zip(delta) {
            *t = s.as_f64() * d.as_f64();
        }
        let total = exclusive_prefix_sums(&tau[..len], &mut depth[..len], 0.0);
        depth[len] = total;
        tau[len] = total;
        if single_tier::<F>() {
            exp_neg_slice::<true>(depth, trans);
            one_minus_exp_neg_slice::<true>(tau, alpha);
        } else {
            exp_neg_slice::<false>(depth, trans);
            one_minus_exp_neg_slice::<false>(tau, alpha);
        }
        for ((w, &t), &a) in self.weights[..len].iter_mut().zip(&*trans).zip(&*alpha) {
            *w = t * a;
        }
    }

    /// [`Attenuation::compute`] for a ray taken in parts of [`CHUNK`] samples (early
    /// termination), or whose length is a whole number of [`STEP`]s.
    #[inline(always)]
    fn compute_in_parts<F: Float>(&mut self, sigma: &[F], delta: &[F], min_transmittance: f64) {
        self.opacity_after = false;
        let len = sigma.len();
        for v in [&mut self.tau, &mut self.alpha, &mut self.weights] {
            grow(v, len);
        }
        grow(&mut self.depth, len + 1);
        grow(&mut self.trans, len + 1);
        self.len = len;
        self.stop = len;
        let single = single_tier::<F>();
        let chunk = if min_transmittance > 0.0 { CHUNK } else { len.max(1) };
        let mut running = 0.0f64;
        let mut start = 0;
        while start < len {
            let end = (start + chunk).min(len);
            let part = start..end;
            for ((t, &s), &d) in self.tau[part.clone()]
                .iter_mut()
                .zip(&sigma[part.clone()])
                .zip(&delta[part.clone()])
            {
                *t = s.as_f64() * d.as_f64();
            }
            running = exclusive_prefix_sums(&self.tau[part.clone()], &mut self.depth[part.clone()], running);
            if single {
                exp_neg_slice::<true>(&self.depth[part.clone()], &mut self.trans[part.clone()]);
                one_minus_exp_neg_slice::<true>(&self.tau[part.clone()], &mut self.alpha[part.clone()]);
            } else {
                exp_neg_slice::<false>(&self.depth[part.clone()], &mut self.trans[part.clone()]);
                one_minus_exp_neg_slice::<false>(&self.tau[part.clone()], &mut self.alpha[part.clone()]);
            }
            for ((w, &t), &a) in self.weights[part.clone()]
                .iter_mut()
                .zip(&self.trans[part.clone()])
                .zip(&self.alpha[part.clone()])
            {
                *w = t * a;
            }
            if min_transmittance > 0.0 {
                if let Some(k) = self.trans[part].iter().position(|&t| t < min_transmittance) {
                    // T_stop is computed (it is in this chunk); nothing behind it is read.
                    self.stop = start + k;
                    return;
                }
            }
            start = end;
        }
        self.depth[len] = running;
        self.trans[len] = if single {
            exp_neg::<true>(running)
        } else {
            exp_neg::<false>(running)
        };
    }

    /// The first sample whose transmittance is below the `min_transmittance` of the last
    /// [`Attenuation::compute`] (early termination), or the ray's length.
    pub(crate) fn stop(&self) -> usize {
        self.stop
    }

    /// `T_k`, `k = 0..=len`.
    pub(crate) fn transmittance(&self) -> &[f64] {
        &self.trans[..=self.len]
    }

    /// `alpha_k`, `k = 0..len`.
    pub(crate) fn alpha(&self) -> &[f64] {
        &self.alpha[..self.len]
    }

    /// `w_k = T_k alpha_k`, `k = 0..len`.
    pub(crate) fn weights(&self) -> &[f64] {
        &self.weights[..self.len]
    }

    /// `-expm1(-depth)` of the optical depth before sample `k` (`k = stop`: the ray's opacity,
    /// not `1 - T`, which is 0 for a faint ray), by the vectorised kernel's code (inlined, so
    /// that its fused multiply-adds are the caller's instructions, not library calls).
    #[inline(always)]
    pub(crate) fn opacity_before<F: Float>(&self, k: usize) -> f64 {
        if self.opacity_after && k == self.len {
            // `-expm1(-depth[len])`, computed in the vector loop by the same function.
            self.alpha[k]
        } else if single_tier::<F>() {
            one_minus_exp_neg::<true>(self.depth[k])
        } else {
            one_minus_exp_neg::<false>(self.depth[k])
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grouped_prefix_sums_equal_the_plain_ones_on_exact_data_for_every_length() {
        // Small integers: every partial sum is exact, so any grouping must agree exactly.
        for len in 0..23 {
            let x: Vec<f64> = (0..len).map(|k| ((k * 7) % 5) as f64).collect();
            let mut out = vec![f64::NAN; len];
            let total = exclusive_prefix_sums(&x, &mut out, 0.0);
            let mut want = 0.0;
            for k in 0..len {
                assert_eq!(out[k], want, "len {len} k {k}");
                want += x[k];
            }
            assert_eq!(total, want);
        }
    }

    /// Both ways of filling the buffers, for data of type `F`, on rays of every length up to a
    /// few steps: the same bits, the opacity included.
    fn whole_steps_agree_with_parts<F: Float>() {
        for len in 0..=3 * STEP + 1 {
            let sigma: Vec<F> = (0..len).map(|k| F::lit(0.03 + ((k * 37) % 11) as f64 * 0.4)).collect();
            let delta: Vec<F> = (0..len).map(|k| F::lit(0.01 + (k % 3) as f64 * 0.2)).collect();
            let mut whole = Attenuation::default();
            let mut parts = Attenuation::default();
            // Dirty buffers from a longer ray first: the padding must not leak into the values.
            whole.compute(&[F::lit(7.0); 50], &[F::lit(3.0); 50], 0.0);
            whole.compute(&sigma, &delta, 0.0);
            parts.compute_in_parts(&sigma, &delta, 0.0);
            assert_eq!(whole.opacity_after, len % STEP != 0, "len {len}");
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(whole.transmittance()), bits(parts.transmittance()), "len {len}");
            assert_eq!(bits(whole.alpha()), bits(parts.alpha()), "len {len}");
            assert_eq!(bits(whole.weights()), bits(parts.weights()), "len {len}");
            assert_eq!(whole.stop(), parts.stop());
            for k in 0..=len {
                assert_eq!(
                    whole.opacity_before::<F>(k).to_bits(),
                    parts.opacity_before::<F>(k).to_bits(),
                    "len {len} k {k}"
                );
            }
            assert!(len == 0 || whole.opacity_before::<F>(len) > 0.0);
        }
    }

    #[test]
    fn whole_steps_into_the_padding_give_the_bits_of_the_ray_in_parts() {
        whole_steps_agree_with_parts::<f32>();
        whole_steps_agree_with_parts::<f64>();
    }

    #[test]
    fn chunked_early_termination_gives_the_whole_ray_values_bitwise_up_to_the_stop() {
        let sigma: Vec<f32> = (0..203).map(|k| 0.05 + (k % 9) as f32 * 0.03).collect();
        let delta = vec![0.25f32; sigma.len()];
        let mut whole = Attenuation::default();
        whole.compute(&sigma, &delta, 0.0);
        assert_eq!(whole.stop(), sigma.len());
        // A threshold never reached: chunked, yet the same bits everywhere.
        let mut chunked = Attenuation::default();
        chunked.compute(&sigma, &delta, 1e-300);
        assert_eq!(chunked.stop(), sigma.len());
        assert_eq!(chunked.transmittance(), whole.transmittance());
        assert_eq!(chunked.alpha(), whole.alpha());
        // A threshold reached mid-ray: the stop is the first T below it, the values agree
        // up to it and T_stop is there.
        let mut early = Attenuation::default();
        early.compute(&sigma, &delta, 1e-2);
        let want = whole.transmittance().iter().position(|&t| t < 1e-2).unwrap();
        assert_eq!(early.stop(), want);
        assert_eq!(early.transmittance()[..=want], whole.transmittance()[..=want]);
        assert_eq!(early.weights()[..want], whole.weights()[..want]);
    }

    #[test]
    fn grouped_prefix_sums_stay_within_a_few_roundings_of_a_compensated_sum() {
        let x: Vec<f64> = (0..100_000).map(|k| 1e-3 * (1.0 + (k as f64 * 0.61).sin())).collect();
        let mut out = vec![0.0; x.len()];
        exclusive_prefix_sums(&x, &mut out, 0.0);
        // Kahan-compensated reference.
        let (mut sum, mut comp) = (0.0f64, 0.0f64);
        for (k, &v) in x.iter().enumerate() {
            assert!((out[k] - sum).abs() <= 1e-13 * sum.max(1e-300), "k {k}");
            let y = v - comp;
            let t = sum + y;
            comp = (t - sum) - y;
            sum = t;
        }
    }
}
