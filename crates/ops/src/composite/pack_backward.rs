//! The backward of a pack of rays ([`super::lanes`]): `backward_ray` in every lane, the
//! back-to-front chain of each lane taken in the per-ray code's groups of four (bitwise the
//! per-ray values). Packs whose rays stop at different samples (early termination) go ray by
//! ray instead: the groups of four are counted from each ray's stop.

use fogray_tape::Float;

use super::backward::{InputGrads, RayUpstream, Wanted};
use super::lanes::{from_lanes, splat, to_lanes, zip_with, Lanes, Unit, LANES};
use super::layout::{Flat, Ray};
use super::pack_attenuation::PackAttenuation;
use super::rows::{add_row_dots, outer_product};

/// Per-block buffers of the pack backward, reused pack after pack.
#[derive(Default)]
pub(crate) struct PackScratch {
    value: Vec<Lanes>,
    d_tau: Vec<Lanes>,
    /// Ray-major values of the pack (`2 LANES len`: the values, then dL/dtau and the weights).
    per_ray: Vec<f64>,
    /// Each ray's upstream colour gradient in f64, `[LANES][ch]`.
    g_color_per_ray: Vec<f64>,
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
    let one_minus = |a: Lanes| zip_with(splat(1.0), a, |one, a| one - a);
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
        for (c, gc) in g_color.iter().enumerate() {
            for l in 0..LANES {
                o.background[(j + l) * ch + c] = F::lit(t_end[l] * gc[l]);
            }
        }
    }

    let PackScratch {
        value,
        d_tau,
        per_ray,
        g_color_per_ray,
    } = scratch;
    // What each sample is worth (element-wise), per ray by the per-ray code, then into lanes.
    g_color_per_ray.clear();
    for gl in g.iter() {
        g_color_per_ray.extend(gl.color.into_iter().flatten().map(|&v| f(v)));
    }
    per_ray.resize(2 * LANES * len, 0.0);
    for l in 0..LANES {
        let v = &mut per_ray[l * stop..(l + 1) * stop];
        let ray = samples.start + l * len..samples.start + (l + 1) * len;
        v.fill(g[l].opacity);
        if let Some(t) = &x.t {
            for (v, &t) in v.iter_mut().zip(&t[ray.clone()]) {
                *v += g[l].depth * f(t);
            }
        }
        if let Some(gw) = g[l].weights {
            for (v, &gw) in v.iter_mut().zip(gw) {
                *v += f(gw);
            }
        }
        if has_color {
            add_row_dots(&x.color[ray.start * ch..], &g_color_per_ray[l * ch..(l + 1) * ch], v);
        }
    }
    value.resize(stop, splat(0.0));
    if stop > 0 {
        to_lanes(&per_ray[..LANES * stop], stop, value);
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

    // Back to rays: dL/dtau and the weights, ray-major, each ray `stop` long.
    let lane = |l: usize| local + l * len..local + l * len + stop;
    let skipped = |l: usize| local + l * len + stop..local + (l + 1) * len;
    let (d_tau_per_ray, weights_per_ray) = per_ray.split_at_mut(LANES * stop);
    if stop > 0 {
        from_lanes(d_tau, stop, d_tau_per_ray);
    }
    if want.sigma {
        let delta = &x.delta[samples.clone()];
        for l in 0..LANES {
            let (d_tau, delta) = (&d_tau_per_ray[l * stop..(l + 1) * stop], &delta[l * len..]);
            for ((out, &d), &dt) in o.sigma[lane(l)].iter_mut().zip(delta).zip(d_tau) {
                *out = F::lit(f(d) * dt);
            }
            o.sigma[skipped(l)].fill(F::zero());
        }
    }
    if want.delta {
        let sigma = &x.sigma[samples.clone()];
        for l in 0..LANES {
            let (d_tau, sigma) = (&d_tau_per_ray[l * stop..(l + 1) * stop], &sigma[l * len..]);
            for ((out, &s), &dt) in o.delta[lane(l)].iter_mut().zip(sigma).zip(d_tau) {
                *out = F::lit(f(s) * dt);
            }
            o.delta[skipped(l)].fill(F::zero());
        }
    }
    if want.color || want.t {
        let weights_per_ray = &mut weights_per_ray[..LANES * stop];
        if stop > 0 {
            from_lanes(&weights[..stop], stop, weights_per_ray);
        }
        for l in 0..LANES {
            let w = &weights_per_ray[l * stop..(l + 1) * stop];
            if want.color {
                let gc = &g_color_per_ray[l * ch..(l + 1) * ch];
                outer_product(w, gc, &mut o.color[lane(l).start * ch..lane(l).end * ch]);
                o.color[skipped(l).start * ch..skipped(l).end * ch].fill(F::zero());
            }
            if want.t {
                let g_depth = g[l].depth;
                for (out, &w) in o.t[lane(l)].iter_mut().zip(w) {
                    *out = F::lit(w * g_depth);
                }
                o.t[skipped(l)].fill(F::zero());
            }
        }
    }
}
