//! The backward kernel: one back-to-front pass per ray over the saved `T_k` and `alpha_k`,
//! with "what it adds minus what it hides" carried as the recurrence `R_k` of the module docs.

use fogray_tape::Float;
use rayon::prelude::*;

use super::config::Composite;
use super::forward::Residuals;
use super::layout::{blocks, take_front, Flat};

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

/// Which input gradients to produce.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Wanted {
    pub sigma: bool,
    pub delta: bool,
    pub color: bool,
    pub background: bool,
    pub t: bool,
}

/// Input gradients; a vector is empty when it was not wanted.
pub(crate) struct InputGrads<F> {
    pub sigma: Vec<F>,
    pub delta: Vec<F>,
    pub color: Vec<F>,
    /// Per ray `[R * ch]`; the caller sums it for a shared background.
    pub background: Vec<F>,
    pub t: Vec<F>,
}

struct BlockOut<'a, F> {
    sigma: &'a mut [F],
    delta: &'a mut [F],
    color: &'a mut [F],
    background: &'a mut [F],
    t: &'a mut [F],
}

fn sized<F: Float>(want: bool, len: usize) -> Vec<F> {
    vec![F::zero(); if want { len } else { 0 }]
}

pub(crate) fn backward<F: Float>(
    op: &Composite,
    x: &Flat<'_, F>,
    saved: &Residuals<F>,
    g: &Upstream<'_, F>,
    want: Wanted,
) -> InputGrads<F> {
    let (n, rays, ch) = (op.samples(), op.rays(), x.ch);
    let mut out = InputGrads {
        sigma: sized(want.sigma, n),
        delta: sized(want.delta, n),
        color: sized(want.color, n * ch),
        background: sized(want.background, rays * ch),
        t: sized(want.t, n),
    };
    let blocks = blocks(&op.offsets);
    let mut work = Vec::with_capacity(blocks.len());
    {
        let (mut s, mut d, mut c) = (&mut out.sigma[..], &mut out.delta[..], &mut out.color[..]);
        let (mut bg, mut t) = (&mut out.background[..], &mut out.t[..]);
        for b in &blocks {
            let (nr, ns) = (b.rays.len(), b.samples.len());
            let part = |w: bool, len: usize| if w { len } else { 0 };
            work.push((
                b.clone(),
                BlockOut {
                    sigma: take_front(&mut s, part(want.sigma, ns)),
                    delta: take_front(&mut d, part(want.delta, ns)),
                    color: take_front(&mut c, part(want.color, ns * ch)),
                    background: take_front(&mut bg, part(want.background, nr * ch)),
                    t: take_front(&mut t, part(want.t, ns)),
                },
            ));
        }
    }
    work.into_par_iter().for_each(|(block, mut o)| {
        for (j, r) in block.rays.clone().enumerate() {
            let ray = Ray {
                index: r,
                samples: op.offsets[r]..op.offsets[r + 1],
                block_start: block.samples.start,
                in_block: j,
            };
            backward_ray(x, saved, g, want, ray, &mut o);
        }
    });
    out
}

/// Where a ray sits: its index, its global samples, and its place in its block.
struct Ray {
    index: usize,
    samples: std::ops::Range<usize>,
    block_start: usize,
    in_block: usize,
}

fn backward_ray<F: Float>(
    x: &Flat<'_, F>,
    saved: &Residuals<F>,
    g: &Upstream<'_, F>,
    want: Wanted,
    ray: Ray,
    o: &mut BlockOut<'_, F>,
) {
    let Ray {
        index: r,
        samples,
        block_start,
        in_block: j,
    } = ray;
    let ch = x.ch;
    let f = |v: F| v.as_f64();
    let gc: Option<&[F]> = g.color.map(|gc| &gc[r * ch..(r + 1) * ch]);
    let g_opacity = g.opacity.map_or(0.0, |v| f(v[r]));
    let g_depth = g.depth.map_or(0.0, |v| f(v[r]));
    let bg = x.background_of(r);
    let t_end = f(saved.t_end[r]);
    let stop = samples.start + saved.stop[r];

    if want.background {
        if let Some(gc) = gc {
            for (out, &g) in o.background[j * ch..(j + 1) * ch].iter_mut().zip(gc) {
                *out = F::lit(t_end * f(g));
            }
        }
    }
    // R: expected value of what lies behind, given the ray reaches it; starts at the background.
    let mut behind = gc.map_or(0.0, |gc| gc.iter().zip(bg).map(|(&g, &b)| f(g) * f(b)).sum());
    // U: sum over later samples of gT_i T_i (skipped samples all see T_stop).
    let mut hidden_t = g
        .transmittance
        .map_or(0.0, |gt| gt[stop..samples.end].iter().map(|&v| f(v) * t_end).sum());
    let mut t_next = t_end;
    for k in (samples.start..stop).rev() {
        let local = k - block_start;
        let (t_k, a) = (f(saved.transmittance[k]), f(saved.alpha[k]));
        let color_k = &x.color[k * ch..(k + 1) * ch];
        let mut value = g_opacity;
        if let Some(gc) = gc {
            value += gc.iter().zip(color_k).map(|(&g, &c)| f(g) * f(c)).sum::<f64>();
        }
        if let Some(t) = &x.t {
            value += g_depth * f(t[k]);
        }
        if let Some(gw) = g.weights {
            value += f(gw[k]);
        }
        // What sample k adds minus what it hides, per unit of optical depth.
        let d_tau = t_next * (value - behind) - hidden_t;
        if want.sigma {
            o.sigma[local] = F::lit(f(x.delta[k]) * d_tau);
        }
        if want.delta {
            o.delta[local] = F::lit(f(x.sigma[k]) * d_tau);
        }
        let w = t_k * a;
        if want.color {
            if let Some(gc) = gc {
                for (out, &g) in o.color[local * ch..(local + 1) * ch].iter_mut().zip(gc) {
                    *out = F::lit(w * f(g));
                }
            }
        }
        if want.t {
            o.t[local] = F::lit(w * g_depth);
        }
        behind += a * (value - behind);
        if let Some(gt) = g.transmittance {
            hidden_t += f(gt[k]) * t_k;
        }
        t_next = t_k;
    }
}
