//! The forward kernel: one front-to-back pass per ray, every running sum in f64.

use fogray_tape::Float;
use rayon::prelude::*;

use super::config::Composite;
use super::layout::{blocks, take_front, Flat};

/// What the composite's forward keeps for its backward (`T_k`, `alpha_k`, `T_end` and the
/// stop index of each ray); opaque to users, visible only through the tape's memory stats.
#[derive(Debug, Clone)]
pub struct Residuals<F> {
    /// `[R * ch]`.
    pub(crate) color: Vec<F>,
    /// `[R]`.
    pub(crate) opacity: Vec<F>,
    /// `[R]`, empty without depth.
    pub(crate) depth: Vec<F>,
    /// `[n]`, empty unless weights were requested.
    pub(crate) weights: Vec<F>,
    /// Residuals: `T_k` before each sample `[n]`.
    pub(crate) transmittance: Vec<F>,
    /// Residuals: `alpha_k` `[n]` (0 for skipped samples).
    pub(crate) alpha: Vec<F>,
    /// Residuals: `T_end` per ray `[R]` (the residual `T_stop` with early termination).
    pub(crate) t_end: Vec<F>,
    /// Residuals: the first sample index (within its ray) that was skipped, or its length.
    pub(crate) stop: Vec<usize>,
}

/// Mutable outputs of one block of rays.
struct BlockOut<'a, F> {
    color: &'a mut [F],
    opacity: &'a mut [F],
    depth: &'a mut [F],
    weights: &'a mut [F],
    transmittance: &'a mut [F],
    alpha: &'a mut [F],
    t_end: &'a mut [F],
    stop: &'a mut [usize],
}

/// Composites every ray; the flag is false if any sample value was invalid (NaN, infinite,
/// negative density or step), checked on the fly so that valid input costs no extra pass.
pub(crate) fn forward<F: Float>(op: &Composite, x: &Flat<'_, F>) -> (Residuals<F>, bool) {
    let (n, rays, ch) = (op.samples(), op.rays(), x.ch);
    let zero = F::zero();
    let mut out = Residuals {
        color: vec![zero; rays * ch],
        opacity: vec![zero; rays],
        depth: vec![zero; if op.depth { rays } else { 0 }],
        weights: vec![zero; if op.weights { n } else { 0 }],
        transmittance: vec![zero; n],
        alpha: vec![zero; n],
        t_end: vec![zero; rays],
        stop: vec![0; rays],
    };
    let blocks = blocks(&op.offsets);
    let mut work = Vec::with_capacity(blocks.len());
    {
        let (mut color, mut opacity, mut depth) = (&mut out.color[..], &mut out.opacity[..], &mut out.depth[..]);
        let (mut weights, mut trans, mut alpha) =
            (&mut out.weights[..], &mut out.transmittance[..], &mut out.alpha[..]);
        let (mut t_end, mut stop) = (&mut out.t_end[..], &mut out.stop[..]);
        for b in &blocks {
            let (nr, ns) = (b.rays.len(), b.samples.len());
            work.push((
                b.clone(),
                BlockOut {
                    color: take_front(&mut color, nr * ch),
                    opacity: take_front(&mut opacity, nr),
                    depth: take_front(&mut depth, if op.depth { nr } else { 0 }),
                    weights: take_front(&mut weights, if op.weights { ns } else { 0 }),
                    transmittance: take_front(&mut trans, ns),
                    alpha: take_front(&mut alpha, ns),
                    t_end: take_front(&mut t_end, nr),
                    stop: take_front(&mut stop, nr),
                },
            ));
        }
    }
    let valid = work
        .into_par_iter()
        .map(|(block, o)| {
            let mut acc = vec![0.0f64; ch];
            let mut valid = true;
            let s0 = block.samples.start;
            for (j, r) in block.rays.clone().enumerate() {
                let samples = op.offsets[r]..op.offsets[r + 1];
                let local = samples.start - s0..samples.end - s0;
                let result = forward_ray(
                    RayIn {
                        sigma: &x.sigma[samples.clone()],
                        delta: &x.delta[samples.clone()],
                        color: &x.color[samples.start * ch..samples.end * ch],
                        t: x.t.as_ref().map(|t| &t[samples.clone()]),
                        background: x.background_of(r),
                    },
                    op.min_transmittance,
                    &mut acc,
                    &mut o.transmittance[local.clone()],
                    &mut o.alpha[local.clone()],
                    if op.weights { Some(&mut o.weights[local]) } else { None },
                );
                for (c, &a) in acc.iter().enumerate() {
                    o.color[j * ch + c] = F::lit(a);
                }
                o.opacity[j] = F::lit(result.opacity);
                if op.depth {
                    o.depth[j] = F::lit(result.depth);
                }
                o.t_end[j] = F::lit(result.t_end);
                o.stop[j] = result.stop;
                valid &= result.valid;
            }
            valid
        })
        .reduce(|| true, |a, b| a && b);
    (out, valid)
}

/// One ray's inputs.
pub(crate) struct RayIn<'a, F> {
    pub sigma: &'a [F],
    pub delta: &'a [F],
    /// `[len * ch]`.
    pub(crate) color: &'a [F],
    pub t: Option<&'a [F]>,
    /// `[ch]`, or empty for a black background.
    pub background: &'a [F],
}

/// One ray's scalar results.
pub(crate) struct RayResult {
    pub(crate) opacity: f64,
    pub(crate) depth: f64,
    pub(crate) t_end: f64,
    pub(crate) stop: usize,
    /// Every sample's values are in their domain.
    pub(crate) valid: bool,
}

/// Composites one ray front to back. `color` (the f64 accumulator, `[ch]`) receives the pixel.
pub(crate) fn forward_ray<F: Float>(
    ray: RayIn<'_, F>,
    min_transmittance: f64,
    color: &mut [f64],
    transmittance: &mut [F],
    alpha: &mut [F],
    mut weights: Option<&mut [F]>,
) -> RayResult {
    let ch = color.len();
    color.fill(0.0);
    let len = ray.sigma.len();
    // The running optical depth, in f64: T_k = exp(-depth_before_k), never a product of 1 - alpha.
    let mut optical_depth = 0.0f64;
    let mut depth = 0.0f64;
    let mut stop = len;
    let mut valid = true;
    let domain = |s: f64| s >= 0.0 && s.is_finite();
    for k in 0..len {
        let t_k = (-optical_depth).exp();
        if t_k < min_transmittance {
            stop = k;
            break;
        }
        // The product of two f32 values is exact in f64; -expm1 keeps every digit at small tau.
        let (sigma, delta) = (ray.sigma[k].as_f64(), ray.delta[k].as_f64());
        valid &= domain(sigma) & domain(delta);
        let tau = sigma * delta;
        let a = -(-tau).exp_m1();
        let w = t_k * a;
        transmittance[k] = F::lit(t_k);
        alpha[k] = F::lit(a);
        if let Some(ws) = weights.as_deref_mut() {
            ws[k] = F::lit(w);
        }
        for (acc, &c) in color.iter_mut().zip(&ray.color[k * ch..(k + 1) * ch]) {
            valid &= c.is_finite();
            *acc += w * c.as_f64();
        }
        if let Some(t) = ray.t {
            valid &= t[k].is_finite();
            depth += w * t[k].as_f64();
        }
        optical_depth += tau;
    }
    let t_end = (-optical_depth).exp();
    // Skipped samples: empty space behind the stop, seen through the residual T_stop.
    for k in stop..len {
        // Not composited, but still checked: invalid input is an error wherever it is.
        valid &= domain(ray.sigma[k].as_f64()) & domain(ray.delta[k].as_f64());
        valid &= ray.color[k * ch..(k + 1) * ch].iter().all(|c| c.is_finite());
        valid &= ray.t.is_none_or(|t| t[k].is_finite());
        transmittance[k] = F::lit(t_end);
        alpha[k] = F::zero();
        if let Some(ws) = weights.as_deref_mut() {
            ws[k] = F::zero();
        }
    }
    for (acc, &bg) in color.iter_mut().zip(ray.background) {
        *acc += t_end * bg.as_f64();
    }
    RayResult {
        // Not 1 - T_end, which is 0 for a faint ray.
        opacity: -(-optical_depth).exp_m1(),
        depth,
        t_end,
        stop,
        valid,
    }
}
