//! The backward of a pack of rays ([`super::lanes`]): `backward_ray` in every lane, the
//! back-to-front chain of each lane taken in the per-ray code's groups of four (bitwise the
//! per-ray values). Packs whose rays stop at different samples (early termination) go ray by
//! ray instead: the groups of four are counted from each ray's stop.

use fogray_tape::Float;

use super::backward::{InputGrads, RayUpstream, Wanted};
use super::lanes::{splat, zip_with, Lanes, Unit, LANES};
use super::layout::{Flat, Ray};
use super::pack_attenuation::PackAttenuation;

/// Per-block buffers of the pack backward, reused pack after pack.
#[derive(Default)]
pub(crate) struct PackScratch {
    value: Vec<Lanes>,
    d_tau: Vec<Lanes>,
}

/// The per-ray `suffix::adds_minus_hides` in every lane: `out[k] = T_{k+1} (v_k - R_{k+1})`
/// with the same four-sample steps from the end and the same fused multiply-adds.
#[inline(always)]
fn adds_minus_hides(trans: &[Lanes], alpha: &[Lanes], value: &[Lanes], mut behind: Lanes, out: &mut [Lanes]) {
    let len = out.len();
    let (trans, alpha, value) = (&trans[..=len], &alpha[..len], &value[..len]);
    let mul = |a: Lanes, b: Lanes| zip_with(a, b, |a, b| a * b);
    let sub = |a: Lanes, b: Lanes| zip_with(a, b, |a, b| a - b);
    let fma = |a: Lanes, b: Lanes, c: Lanes| -> Lanes { std::array::from_fn(|l| a[l].mul_add(b[l], c[l])) };
    let one_minus = |a: Lanes| a.map(|a| 1.0 - a);
    let mut k = len;
    while k >= 4 {
        let (a, b, c, d) = (k - 4, k - 3, k - 2, k - 1);
        let (ua, ub, uc, ud) = (
            mul(alpha[a], value[a]),
            mul(alpha[b], value[b]),
            mul(alpha[c], value[c]),
            mul(alpha[d], value[d]),
        );
        let (ea, eb, ec, ed) = (
            one_minus(alpha[a]),
            one_minus(alpha[b]),
            one_minus(alpha[c]),
            one_minus(alpha[d]),
        );
        let (e_cd, a_c) = (mul(ec, ed), fma(ec, ud, uc));
        let (e_bd, a_b) = (mul(eb, e_cd), fma(eb, a_c, ub));
        let (e_ad, a_a) = (mul(ea, e_bd), fma(ea, a_b, ua));
        let r_d = fma(behind, ed, ud);
        let r_c = fma(behind, e_cd, a_c);
        let r_b = fma(behind, e_bd, a_b);
        out[d] = mul(trans[k], sub(value[d], behind));
        out[c] = mul(trans[d], sub(value[c], r_d));
        out[b] = mul(trans[c], sub(value[b], r_c));
        out[a] = mul(trans[b], sub(value[a], r_b));
        behind = fma(behind, e_ad, a_a);
        k = a;
    }
    while k >= 1 {
        let i = k - 1;
        out[i] = mul(trans[k], sub(value[i], behind));
        behind = fma(alpha[i], sub(value[i], behind), behind);
        k = i;
    }
}

/// The input gradients of the pack of [`LANES`] rays of `len` samples starting at `first`
/// into its block's `o`, from the pack's attenuation (every lane stopping at the same `stop`)
/// and each ray's upstream gradients `g`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn backward_pack<F: Float>(
    x: &Flat<'_, F>,
    want: Wanted,
    first: &Ray,
    len: usize,
    att: &PackAttenuation,
    g: &[RayUpstream<'_, F>; LANES],
    scratch: &mut PackScratch,
    o: &mut InputGrads<'_, F>,
) {
    let stop = att.stop()[0];
    debug_assert!(att.stop().iter().all(|&s| s == stop), "lanes stop together");
    let ch = x.ch;
    let f = |v: F| v.as_f64();
    let samples = Unit::pack_samples(first, len);
    let (j, local) = (first.in_block, first.local.start);
    let (trans, alpha, weights) = (att.transmittance(), att.alpha(), att.weights());
    let t_end = trans[stop];
    // g_color[c][l], 0 where a ray has no colour upstream (then no colour gradient is wanted).
    let g_color: Vec<Lanes> = (0..ch)
        .map(|c| std::array::from_fn(|l| g[l].color.map_or(0.0, |gc| f(gc[c]))))
        .collect();
    let has_color = g[0].color.is_some();

    if want.background {
        for c in 0..ch {
            for l in 0..LANES {
                o.background[(j + l) * ch + c] = F::lit(t_end[l] * g_color[c][l]);
            }
        }
    }

    let PackScratch { value, d_tau } = scratch;
    value.clear();
    value.resize(stop, std::array::from_fn(|l| g[l].opacity));
    if let Some(t) = &x.t {
        let t = &t[samples.clone()];
        let g_depth: Lanes = std::array::from_fn(|l| g[l].depth);
        for (k, v) in value.iter_mut().enumerate() {
            for l in 0..LANES {
                v[l] += g_depth[l] * f(t[l * len + k]);
            }
        }
    }
    if g[0].weights.is_some() {
        for (k, v) in value.iter_mut().enumerate() {
            for l in 0..LANES {
                v[l] += g[l].weights.map_or(0.0, |gw| f(gw[k]));
            }
        }
    }
    if has_color {
        let color = &x.color[samples.start * ch..samples.end * ch];
        for (k, v) in value.iter_mut().enumerate() {
            // As `rows::add_row_dots`: the dot from 0, channel after channel, then added.
            let mut s = splat(0.0);
            for (c, gc) in g_color.iter().enumerate() {
                for l in 0..LANES {
                    s[l] += gc[l] * f(color[(l * len + k) * ch + c]);
                }
            }
            *v = zip_with(*v, s, |v, s| v + s);
        }
    }

    // R starts at the background's value, summed as the per-ray code sums it.
    let behind: Lanes = std::array::from_fn(|l| {
        let bg = x.background_of(first.index + l);
        let gc = g[l].color.unwrap_or(&[]);
        gc.iter().zip(bg).map(|(&g, &b)| f(g) * f(b)).sum()
    });
    d_tau.resize(stop, splat(0.0));
    adds_minus_hides(trans, alpha, value, behind, d_tau);
    if g[0].transmittance.is_some() {
        for l in 0..LANES {
            let gt = g[l].transmittance.unwrap_or(&[]);
            let mut hidden_t: f64 = gt[stop..].iter().map(|&v| f(v) * t_end[l]).sum();
            for k in (0..stop).rev() {
                d_tau[k][l] -= hidden_t;
                hidden_t += f(gt[k]) * trans[k][l];
            }
        }
    }

    // Per lane, samples `local + l len ..` up to its stop, zero behind it.
    let lane = |l: usize| local + l * len..local + l * len + stop;
    let skipped = |l: usize| local + l * len + stop..local + (l + 1) * len;
    if want.sigma {
        let delta = &x.delta[samples.clone()];
        for l in 0..LANES {
            for (k, out) in o.sigma[lane(l)].iter_mut().enumerate() {
                *out = F::lit(f(delta[l * len + k]) * d_tau[k][l]);
            }
            o.sigma[skipped(l)].fill(F::zero());
        }
    }
    if want.delta {
        let sigma = &x.sigma[samples.clone()];
        for l in 0..LANES {
            for (k, out) in o.delta[lane(l)].iter_mut().enumerate() {
                *out = F::lit(f(sigma[l * len + k]) * d_tau[k][l]);
            }
            o.delta[skipped(l)].fill(F::zero());
        }
    }
    if want.color {
        for l in 0..LANES {
            let rows = &mut o.color[lane(l).start * ch..lane(l).end * ch];
            for (k, row) in rows.chunks_exact_mut(ch).enumerate() {
                for (c, out) in row.iter_mut().enumerate() {
                    *out = F::lit(weights[k][l] * g_color[c][l]);
                }
            }
            o.color[skipped(l).start * ch..skipped(l).end * ch].fill(F::zero());
        }
    }
    if want.t {
        for l in 0..LANES {
            let g_depth = g[l].depth;
            for (k, out) in o.t[lane(l)].iter_mut().enumerate() {
                *out = F::lit(weights[k][l] * g_depth);
            }
            o.t[skipped(l)].fill(F::zero());
        }
    }
}
