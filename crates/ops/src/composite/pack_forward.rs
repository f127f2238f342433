//! The forward of a pack of rays ([`super::lanes`]): `forward_ray`'s compositing in every lane,
//! each lane summing its own ray in the per-ray order (bitwise the per-ray values).

use fogray_tape::Float;

use super::attenuation::valid_steps;
use super::config::Composite;
use super::forward::{all_finite, Outputs};
use super::lanes::{splat, zip_with, Lanes, Unit, LANES};
use super::layout::{Flat, Ray};
use super::pack_attenuation::PackAttenuation;

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
    let stop = att.stop();
    let t_end: Lanes = std::array::from_fn(|l| att.transmittance()[stop[l]][l]);
    let mut acc = vec![splat(0.0); ch];
    match ch {
        1 => column_sums::<F, 1>(color, len, att.weights(), stop, &mut acc),
        2 => column_sums::<F, 2>(color, len, att.weights(), stop, &mut acc),
        3 => column_sums::<F, 3>(color, len, att.weights(), stop, &mut acc),
        4 => column_sums::<F, 4>(color, len, att.weights(), stop, &mut acc),
        _ => column_sums::<F, 0>(color, len, att.weights(), stop, &mut acc),
    }
    let j = first.in_block;
    for (c, a) in acc.iter_mut().enumerate() {
        for l in 0..LANES {
            let bg = x.background_of(first.index + l).get(c).map(|b| b.as_f64());
            if let Some(bg) = bg {
                a[l] += t_end[l] * bg;
            }
            o.color[(j + l) * ch + c] = F::lit(a[l]);
        }
    }
    let opacity = att.opacity::<F>();
    for l in 0..LANES {
        o.opacity[j + l] = F::lit(opacity[l]);
    }
    if let Some(t) = t {
        let mut depth = splat(0.0);
        for (k, w) in att.weights().iter().enumerate() {
            let tk: Lanes = std::array::from_fn(|l| t[l * len + k].as_f64());
            for l in 0..LANES {
                // As the per-ray fold: a product and a sum, no fused multiply-add.
                depth[l] = if k < stop[l] { depth[l] + w[l] * tk[l] } else { depth[l] };
            }
        }
        if op.depth {
            for l in 0..LANES {
                o.depth[j + l] = F::lit(depth[l]);
            }
        }
    }
    let local = first.local.start;
    if op.transmittance {
        for l in 0..LANES {
            for k in 0..len {
                let v = if k < stop[l] { att.transmittance()[k][l] } else { t_end[l] };
                o.transmittance[local + l * len + k] = F::lit(v);
            }
        }
    }
    if op.weights {
        for l in 0..LANES {
            for k in 0..len {
                let v = if k < stop[l] { F::lit(att.weights()[k][l]) } else { F::zero() };
                o.weights[local + l * len + k] = v;
            }
        }
    }
    (stop, valid)
}

/// `acc[c] = 0 + sum_{k < stop} w_k color_k[c]` in every lane, with `rows::weighted_column_sums`'
/// order: sample k into partial sum `k % 4` by a fused multiply-add, the partials added pairwise.
/// `CH` is the channel count, or 0 for "the run-time count".
#[inline(always)]
fn column_sums<F: Float, const CH: usize>(
    color: &[F],
    len: usize,
    w: &[Lanes],
    stop: [usize; LANES],
    acc: &mut [Lanes],
) {
    let ch = if CH == 0 { acc.len() } else { CH };
    // Lanes that run to their end (the usual case) need no per-sample test.
    let whole = stop.iter().all(|&s| s == len);
    for c in 0..ch {
        let mut part = [splat(0.0); 4];
        for (k, wk) in w.iter().enumerate() {
            let value: Lanes = std::array::from_fn(|l| color[(l * len + k) * ch + c].as_f64());
            let p = &mut part[k % 4];
            *p = if whole {
                std::array::from_fn(|l| wk[l].mul_add(value[l], p[l]))
            } else {
                std::array::from_fn(|l| if k < stop[l] { wk[l].mul_add(value[l], p[l]) } else { p[l] })
            };
        }
        let add = |a: Lanes, b: Lanes| zip_with(a, b, |a, b| a + b);
        acc[c] = add(acc[c], add(add(part[0], part[1]), add(part[2], part[3])));
    }
}
