//! The attenuation of a pack of rays ([`super::lanes`]): [`super::attenuation`]'s `tau_k`,
//! `T_k`, `alpha_k` and `w_k`, lane by lane with the per-ray code's operations in its order,
//! so every value is bitwise the per-ray one.

use fogray_tape::Float;

use super::lanes::{splat, zip_with, Lanes, LANES};
use crate::math::exp::{exp_neg, exp_neg_slice, one_minus_exp_neg, one_minus_exp_neg_slice, single_tier};

/// Samples per step when early termination may stop a ray (the per-ray code's chunk, so that
/// a pack stops computing where its last ray would).
const CHUNK: usize = 32;

/// Reusable `[sample][lane]` buffers of one pack (one set per block of rays).
#[derive(Debug, Default)]
pub(crate) struct PackAttenuation {
    tau: Vec<Lanes>,
    /// `k = 0..=len`.
    depth: Vec<Lanes>,
    /// `k = 0..=len`.
    trans: Vec<Lanes>,
    alpha: Vec<Lanes>,
    weights: Vec<Lanes>,
    /// Each lane's stop (see `Attenuation::stop`).
    stop: [usize; LANES],
}

/// The per-ray `exclusive_prefix_sums` in every lane: groups of four, the sums within a group
/// off the chain, in the same order.
#[inline(always)]
fn exclusive_prefix_sums(x: &[Lanes], out: &mut [Lanes], mut running: Lanes) -> Lanes {
    let add = |a: Lanes, b: Lanes| zip_with(a, b, |a, b| a + b);
    let mut groups = out.chunks_exact_mut(4);
    let mut terms = x.chunks_exact(4);
    for (o, t) in (&mut groups).zip(&mut terms) {
        let p1 = add(t[0], t[1]);
        let p2 = add(p1, t[2]);
        let p3 = add(p2, t[3]);
        o[0] = running;
        o[1] = add(running, t[0]);
        o[2] = add(running, p1);
        o[3] = add(running, p2);
        running = add(running, p3);
    }
    for (o, &t) in groups.into_remainder().iter_mut().zip(terms.remainder()) {
        *o = running;
        running = add(running, t);
    }
    running
}

impl PackAttenuation {
    /// Fills the buffers for [`LANES`] rays of `len` samples each, `sigma` and `delta` being
    /// their samples ray after ray (`LANES * len` values). With `min_transmittance > 0`, stops
    /// computing after the chunk in which the last lane's transmittance falls below it.
    #[inline(always)]
    pub(crate) fn compute<F: Float>(&mut self, sigma: &[F], delta: &[F], len: usize, min_transmittance: f64) {
        debug_assert_eq!(sigma.len(), LANES * len);
        self.tau.resize(len, splat(0.0));
        self.alpha.resize(len, splat(0.0));
        self.weights.resize(len, splat(0.0));
        self.depth.resize(len + 1, splat(0.0));
        self.trans.resize(len + 1, splat(0.0));
        self.stop = [len; LANES];
        // Transposed: lane l's sample k at [k][l].
        for (l, (s, d)) in sigma.chunks_exact(len).zip(delta.chunks_exact(len)).enumerate() {
            for ((t, &s), &d) in self.tau.iter_mut().zip(s).zip(d) {
                t[l] = s.as_f64() * d.as_f64();
            }
        }
        let single = single_tier::<F>();
        let chunk = if min_transmittance > 0.0 { CHUNK } else { len.max(1) };
        let mut running = splat(0.0);
        let mut stopped = [false; LANES];
        let mut start = 0;
        while start < len {
            let end = (start + chunk).min(len);
            let part = start..end;
            running = exclusive_prefix_sums(&self.tau[part.clone()], &mut self.depth[part.clone()], running);
            let (depth, trans) = (
                self.depth[part.clone()].as_flattened(),
                self.trans[part.clone()].as_flattened_mut(),
            );
            let (tau, alpha) = (
                self.tau[part.clone()].as_flattened(),
                self.alpha[part.clone()].as_flattened_mut(),
            );
            if single {
                exp_neg_slice::<true>(depth, trans);
                one_minus_exp_neg_slice::<true>(tau, alpha);
            } else {
                exp_neg_slice::<false>(depth, trans);
                one_minus_exp_neg_slice::<false>(tau, alpha);
            }
            for ((w, &t), &a) in self.weights[part.clone()]
                .iter_mut()
                .zip(&self.trans[part.clone()])
                .zip(&self.alpha[part.clone()])
            {
                *w = zip_with(t, a, |t, a| t * a);
            }
            if min_transmittance > 0.0 {
                for (l, done) in stopped.iter_mut().enumerate() {
                    if !*done {
                        if let Some(k) = self.trans[part.clone()].iter().position(|t| t[l] < min_transmittance) {
                            self.stop[l] = start + k;
                            *done = true;
                        }
                    }
                }
                if stopped.iter().all(|&s| s) {
                    return;
                }
            }
            start = end;
        }
        self.depth[len] = running;
        // A loop, not a closure, so that the exponential is compiled with the caller's features.
        for (t, &d) in self.trans[len].iter_mut().zip(&running) {
            *t = if single {
                exp_neg::<true>(d)
            } else {
                exp_neg::<false>(d)
            };
        }
    }

    /// Each lane's stop: the first sample whose transmittance is below the threshold, or `len`.
    pub(crate) fn stop(&self) -> [usize; LANES] {
        self.stop
    }

    /// `T_k`, `k = 0..=len` (valid up to each lane's stop).
    pub(crate) fn transmittance(&self) -> &[Lanes] {
        &self.trans
    }

    /// `alpha_k`, `k = 0..len`.
    pub(crate) fn alpha(&self) -> &[Lanes] {
        &self.alpha
    }

    /// `w_k = T_k alpha_k`, `k = 0..len`.
    pub(crate) fn weights(&self) -> &[Lanes] {
        &self.weights
    }

    /// Each lane's opacity, `-expm1` of its optical depth before its stop (as
    /// `Attenuation::opacity_before`).
    #[inline(always)]
    pub(crate) fn opacity<F: Float>(&self) -> Lanes {
        std::array::from_fn(|l| {
            let d = self.depth[self.stop[l]][l];
            if single_tier::<F>() {
                one_minus_exp_neg::<true>(d)
            } else {
                one_minus_exp_neg::<false>(d)
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::composite::attenuation::Attenuation;

    /// Rays whose lengths and densities differ per lane: every value against the per-ray code.
    fn check<F: Float>(len: usize, min_transmittance: f64) {
        let sigma: Vec<F> = (0..LANES * len)
            .map(|i| F::lit(((i * 37) % 23) as f64 * 0.21 + if i % 11 == 0 { 1e-9 } else { 0.0 }))
            .collect();
        let delta: Vec<F> = (0..LANES * len)
            .map(|i| F::lit(0.03 + (i % 5) as f64 * 0.011))
            .collect();
        let mut pack = PackAttenuation::default();
        pack.compute(&sigma, &delta, len, min_transmittance);
        let mut ray = Attenuation::default();
        for l in 0..LANES {
            let lane = l * len..(l + 1) * len;
            ray.compute(&sigma[lane.clone()], &delta[lane], min_transmittance);
            let stop = ray.stop();
            assert_eq!(pack.stop()[l], stop, "len {len} lane {l}");
            for k in 0..=stop {
                assert_eq!(
                    pack.transmittance()[k][l].to_bits(),
                    ray.transmittance()[k].to_bits(),
                    "T_{k}"
                );
            }
            for k in 0..stop {
                assert_eq!(pack.alpha()[k][l].to_bits(), ray.alpha()[k].to_bits(), "alpha_{k}");
                assert_eq!(pack.weights()[k][l].to_bits(), ray.weights()[k].to_bits(), "w_{k}");
            }
            assert_eq!(
                pack.opacity::<F>()[l].to_bits(),
                ray.opacity_before::<F>(stop).to_bits()
            );
        }
    }

    #[test]
    fn every_lane_is_bitwise_the_per_ray_attenuation_with_and_without_early_termination() {
        for len in [1, 2, 3, 4, 5, 7, 8, 31, 32, 33, 64, 100] {
            for threshold in [0.0, 1e-3, 0.2, 0.9] {
                check::<f32>(len, threshold);
                check::<f64>(len, threshold);
            }
        }
    }
}
