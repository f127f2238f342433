//! The forward of a pack of rays ([`super::lanes`]): `forward_ray`'s compositing in every lane,
//! each lane summing its own ray in the per-ray order (bitwise the per-ray values): the
//! attenuation across the lanes, the colour and depth sums by the per-ray code on each ray.

use fogray_tape::Float;

use super::attenuation::valid_steps;
use super::config::Composite;
use super::forward::{all_finite, Outputs};
use super::lanes::{from_lanes, Lanes, Unit, LANES};
use super::layout::{Flat, Ray};
use super::pack_attenuation::PackAttenuation;
use super::rows::weighted_column_sums;

/// Per-block buffers of the pack forward.
#[derive(Debug, Default)]
pub(crate) struct ForwardScratch {
    /// The pack's weights, ray-major.
    weights: Vec<f64>,
    /// One ray's colour.
    acc: Vec<f64>,
}

/// Composites the pack of [`LANES`] rays of `len` samples starting at `first` into its block's
/// outputs `o`, leaving its attenuation in `att`; returns each lane's stop and whether every
/// input value of the pack was in its domain.
#[inline(always)]
pub(crate) fn forward_pack<F: Float>(
    op: &Composite,
    x: &Flat<'_, F>,
    first: &Ray,
    len: usize,
    att: &mut PackAttenuation,
    scratch: &mut ForwardScratch,
    o: &mut Outputs<'_, F>,
) -> ([usize; LANES], bool) {
    let ch = x.ch;
    let samples = Unit::pack_samples(first, len);
    let (sigma, delta) = (&x.sigma[samples.clone()], &x.delta[samples.clone()]);
    let color = &x.color[samples.start * ch..samples.end * ch];
    let t = x.t.as_ref().map(|t| &t[samples.clone()]);
    // The pack's rays are contiguous: one check over all of them.
    let valid = valid_steps(sigma, delta) & all_finite(color) & t.is_none_or(all_finite);
    att.compute(sigma, delta, len, op.min_transmittance);
    scratch.weights.resize(LANES * len, 0.0);
    scratch.acc.resize(ch, 0.0);
    let stop = att.stop();
    let t_end: Lanes = std::array::from_fn(|l| att.transmittance()[stop[l]][l]);
    // The colour and depth sums per ray, ray-major, by the per-ray code itself.
    from_lanes(att.weights(), len, &mut scratch.weights);
    let j = first.in_block;
    let opacity = att.opacity::<F>();
    for l in 0..LANES {
        let w = &scratch.weights[l * len..l * len + stop[l]];
        let acc = &mut scratch.acc[..ch];
        acc.fill(0.0);
        weighted_column_sums(&color[l * len * ch..], w, acc);
        for (a, &bg) in acc.iter_mut().zip(x.background_of(first.index + l)) {
            *a += t_end[l] * bg.as_f64();
        }
        for (out, &a) in o.color[(j + l) * ch..(j + l + 1) * ch].iter_mut().zip(acc.iter()) {
            *out = F::lit(a);
        }
        o.opacity[j + l] = F::lit(opacity[l]);
        if let Some(t) = t {
            let depth = w.iter().zip(&t[l * len..]).fold(0.0, |d, (&w, &t)| d + w * t.as_f64());
            if op.depth {
                o.depth[j + l] = F::lit(depth);
            }
        }
    }
    let local = first.local.start;
    if op.transmittance {
        for (l, &stop) in stop.iter().enumerate() {
            for k in 0..len {
                let v = if k < stop { att.transmittance()[k][l] } else { t_end[l] };
                o.transmittance[local + l * len + k] = F::lit(v);
            }
        }
    }
    if op.weights {
        for (l, &stop) in stop.iter().enumerate() {
            for k in 0..len {
                let v = if k < stop {
                    F::lit(att.weights()[k][l])
                } else {
                    F::zero()
                };
                o.weights[local + l * len + k] = v;
            }
        }
    }
    (stop, valid)
}
