//! The backward kernel: one back-to-front pass per ray over `T_k` and `alpha_k` (recomputed),
//! with "what it adds minus what it hides" carried as the recurrence `R_k` of the module docs.

use fogray_tape::Float;
use multiversion::multiversion;
use rayon::prelude::*;

use super::attenuation::{grow, Attenuation};
use super::config::Composite;
use super::forward::Residuals;
use super::layout::{blocks, take_front, Block, Flat, Ray};
use super::rows::{add_row_dots, outer_product};
use super::suffix::adds_minus_hides;
use crate::prefetch::prefetch_span;

/// Upstream gradients as flat slices (`None`: that output reached nothing).
pub(crate) struct Upstream<'a, F> {
    /// `[R * ch]`.
    pub color: Option<&'a [F]>,
    /// `[R]`.
    pub opacity: Option<&'a [F]>,
    /// `[R]`.
    pub depth: Option<&'a [F]>,
    /// `[n]`.
    pub weights: Option<&'a [F]>,
    /// `[n]`.
    pub transmittance: Option<&'a [F]>,
}

impl<F: Float> Upstream<'_, F> {
    /// Ray `r`'s share (`samples` are its global sample indices).
    #[inline(always)]
    pub(crate) fn of_ray(&self, r: usize, samples: std::ops::Range<usize>, ch: usize) -> RayUpstream<'_, F> {
        RayUpstream {
            color: self.color.map(|g| &g[r * ch..(r + 1) * ch]),
            opacity: self.opacity.map_or(0.0, |v| v[r].as_f64()),
            depth: self.depth.map_or(0.0, |v| v[r].as_f64()),
            weights: self.weights.map(|g| &g[samples.clone()]),
            transmittance: self.transmittance.map(|g| &g[samples]),
        }
    }
}

/// One ray's upstream gradients.
pub(crate) struct RayUpstream<'a, F> {
    /// `[ch]`.
    pub color: Option<&'a [F]>,
    pub opacity: f64,
    pub depth: f64,
    /// `[len]`.
    pub weights: Option<&'a [F]>,
    /// `[len]`.
    pub transmittance: Option<&'a [F]>,
}

/// Which input gradients to produce: colour and background only with an upstream colour
/// gradient, t only with an upstream depth gradient (`Prepared::wanted` builds it so).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Wanted {
    pub sigma: bool,
    pub delta: bool,
    pub color: bool,
    pub background: bool,
    pub t: bool,
}

/// Input gradients, flat, of all rays or of one block; a slice is empty when it was not wanted,
/// else of its input's length (the background's per ray, `[R * ch]`: the caller sums it for a
/// shared background).
pub(crate) struct InputGrads<'a, F> {
    pub sigma: &'a mut [F],
    pub delta: &'a mut [F],
    pub color: &'a mut [F],
    pub background: &'a mut [F],
    pub t: &'a mut [F],
}

impl<'a, F> InputGrads<'a, F> {
    /// Asks for the cache lines of the wanted gradients of the block's samples `local` (see
    /// [`Flat::request`](super::layout::Flat::request)).
    #[inline(always)]
    pub(crate) fn request(&self, local: std::ops::Range<usize>, ch: usize) {
        // Unwanted gradients are empty slices: nothing is asked for.
        prefetch_span(self.sigma, local.clone());
        prefetch_span(self.delta, local.clone());
        prefetch_span(self.color, local.start * ch..local.end * ch);
        prefetch_span(self.t, local);
    }

    /// One `InputGrads` per block, in block order (each empty where not wanted).
    pub(crate) fn split(self, blocks: &[Block], want: Wanted, ch: usize) -> Vec<InputGrads<'a, F>> {
        let InputGrads {
            sigma: mut s,
            delta: mut d,
            color: mut c,
            background: mut bg,
            mut t,
        } = self;
        let part = |w: bool, len: usize| if w { len } else { 0 };
        blocks
            .iter()
            .map(|b| {
                let (nr, ns) = (b.rays.len(), b.samples.len());
                InputGrads {
                    sigma: take_front(&mut s, part(want.sigma, ns)),
                    delta: take_front(&mut d, part(want.delta, ns)),
                    color: take_front(&mut c, part(want.color, ns * ch)),
                    background: take_front(&mut bg, part(want.background, nr * ch)),
                    t: take_front(&mut t, part(want.t, ns)),
                }
            })
            .collect()
    }
}

/// Every value of the wanted gradients in `out` is written (zero behind a ray's stop); a
/// gradient may be wanted only if its upstream exists (see [`Wanted`]'s construction).
pub(crate) fn backward<F: Float>(
    op: &Composite,
    x: &Flat<'_, F>,
    saved: &Residuals<F>,
    g: &Upstream<'_, F>,
    want: Wanted,
    out: InputGrads<'_, F>,
) {
    let blocks = blocks(&op.offsets);
    let work: Vec<_> = blocks.iter().cloned().zip(out.split(&blocks, want, x.ch)).collect();
    work.into_par_iter()
        .for_each(|(block, o)| backward_block(op, x, saved, g, want, &block, o));
}

/// The backward of one block of rays into `o`, compiled for the vector units this machine has
/// (see the forward's `forward_block`).
#[multiversion(targets("x86_64+avx512f+avx512dq+fma", "x86_64+avx2+fma", "aarch64+neon"))]
fn backward_block<'a, F: Float>(
    op: &Composite,
    x: &Flat<'a, F>,
    saved: &Residuals<F>,
    g: &Upstream<'a, F>,
    want: Wanted,
    block: &Block,
    mut o: InputGrads<'a, F>,
) {
    let longest = block.longest_ray(&op.offsets);
    let mut scratch = Scratch::for_rays(longest);
    let mut att = Attenuation::for_rays(longest);
    for r in block.rays.clone() {
        // The next ray's lines are asked for while this one is computed.
        if r + 1 < block.rays.end {
            let next = block.ray(&op.offsets, r + 1);
            x.request(next.samples);
            o.request(next.local, x.ch);
        }
        let ray = block.ray(&op.offsets, r);
        one_ray(op, x, saved, g, want, ray, &mut att, &mut scratch, &mut o);
    }
}

/// The backward of one ray (recomputing its attenuation) into its block's `o`. A function, not
/// a closure: a closure would not inherit `backward_block`'s target features.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn one_ray<'a, F: Float>(
    op: &Composite,
    x: &Flat<'a, F>,
    saved: &Residuals<F>,
    g: &Upstream<'a, F>,
    want: Wanted,
    ray: Ray,
    att: &mut Attenuation,
    scratch: &mut Scratch,
    o: &mut InputGrads<'a, F>,
) {
    // The forward's T_k and alpha_k, recomputed by the same code: bitwise the same values.
    let (sigma, delta) = (&x.sigma[ray.samples.clone()], &x.delta[ray.samples.clone()]);
    att.compute(sigma, delta, op.min_transmittance);
    debug_assert_eq!(saved.stop[ray.index], att.stop(), "the same code gives the same stop");
    let up = g.of_ray(ray.index, ray.samples.clone(), x.ch);
    backward_ray(x, want, &ray, att, up, scratch, o);
}

/// Per-block buffers of the backward, reused ray after ray (built by [`Scratch::for_rays`]).
pub(crate) struct Scratch {
    /// What sample k is worth if the ray stops there: `g_C . c_k + g_O + g_D t_k + g_w_k`.
    value: Vec<f64>,
    /// `dL/dtau_k`.
    d_tau: Vec<f64>,
    /// The upstream colour gradient in f64.
    g_color: Vec<f64>,
}

impl Scratch {
    /// Buffers for rays of up to `len` samples, allocated once.
    pub(crate) fn for_rays(len: usize) -> Self {
        Scratch {
            value: Vec::with_capacity(len),
            d_tau: Vec::with_capacity(len),
            g_color: Vec::new(),
        }
    }
}

/// One ray's input gradients into `o` (its block's), from the ray's attenuation as the forward
/// computed it and its upstream gradients.
#[inline(always)]
pub(crate) fn backward_ray<F: Float>(
    x: &Flat<'_, F>,
    want: Wanted,
    ray: &Ray,
    att: &Attenuation,
    g: RayUpstream<'_, F>,
    scratch: &mut Scratch,
    o: &mut InputGrads<'_, F>,
) {
    let (r, j, samples) = (ray.index, ray.in_block, ray.samples.clone());
    let ch = x.ch;
    let f = |v: F| v.as_f64();
    let Scratch { value, d_tau, g_color } = scratch;
    let gc: Option<&[F]> = g.color;
    g_color.clear();
    if let Some(gc) = gc {
        g_color.extend(gc.iter().map(|&v| f(v)));
    }
    let (g_opacity, g_depth) = (g.opacity, g.depth);
    let bg = x.background_of(r);
    let (sigma, delta) = (&x.sigma[samples.clone()], &x.delta[samples.clone()]);
    let stop = att.stop();
    let (trans, alpha, weights) = (att.transmittance(), att.alpha(), att.weights());
    let t_end = trans[stop];
    let local = ray.local.start..ray.local.start + stop;

    if want.background {
        for (out, &g) in o.background[j * ch..(j + 1) * ch].iter_mut().zip(g_color.iter()) {
            *out = F::lit(t_end * g);
        }
    }

    grow(value, stop);
    grow(d_tau, stop);
    let (value, d_tau) = (&mut value[..stop], &mut d_tau[..stop]);
    value.fill(g_opacity);
    if let Some(t) = &x.t {
        for (v, &t) in value.iter_mut().zip(&t[samples.clone()]) {
            *v += g_depth * f(t);
        }
    }
    if let Some(gw) = g.weights {
        for (v, &gw) in value.iter_mut().zip(gw) {
            *v += f(gw);
        }
    }
    if gc.is_some() {
        add_row_dots(&x.color[samples.start * ch..], g_color, value);
    }

    // R: expected value of what lies behind, given the ray reaches it; starts at the background.
    let behind: f64 = g_color.iter().zip(bg).map(|(&g, &b)| g * f(b)).sum();
    // Every entry of `d_tau` is written below: no need to clear it first.
    adds_minus_hides(trans, alpha, value, behind, d_tau);
    if let Some(gt) = g.transmittance {
        // U: sum over later samples of gT_i T_i (skipped samples all see T_stop), a suffix sum.
        let mut hidden_t: f64 = gt[stop..].iter().map(|&v| f(v) * t_end).sum();
        for k in (0..stop).rev() {
            d_tau[k] -= hidden_t;
            hidden_t += f(gt[k]) * trans[k];
        }
    }

    // Samples skipped behind an early-termination stop have no gradient.
    let skipped = local.end..ray.local.end;
    if want.sigma {
        for ((out, &d), &dt) in o.sigma[local.clone()].iter_mut().zip(delta).zip(d_tau.iter()) {
            *out = F::lit(f(d) * dt);
        }
        o.sigma[skipped.clone()].fill(F::zero());
    }
    if want.delta {
        for ((out, &s), &dt) in o.delta[local.clone()].iter_mut().zip(sigma).zip(d_tau.iter()) {
            *out = F::lit(f(s) * dt);
        }
        o.delta[skipped.clone()].fill(F::zero());
    }
    if want.color {
        outer_product(
            &weights[..stop],
            g_color,
            &mut o.color[local.start * ch..local.end * ch],
        );
        o.color[skipped.start * ch..skipped.end * ch].fill(F::zero());
    }
    if want.t {
        for (out, &w) in o.t[local].iter_mut().zip(weights) {
            *out = F::lit(w * g_depth);
        }
        o.t[skipped].fill(F::zero());
    }
}
