//! The forward kernel: per ray, the attenuation (vectorised) and one front-to-back pass of
//! compositing, every running sum in f64.

use std::marker::PhantomData;

use fogray_tape::Float;
use multiversion::multiversion;
use rayon::prelude::*;

use super::attenuation::{valid_steps, Attenuation};
use super::config::Composite;
use super::layout::{blocks, take_front, Block, Flat, Ray};
use super::rows::weighted_column_sums;

/// What the composite's forward keeps for its backward: the stop index of each ray (its
/// length unless early termination cut it). `T_k` and `alpha_k` are recomputed by the backward
/// from sigma and delta (two vectorised exponentials per sample), so that the op's extra memory
/// is its outputs and gradients alone.
/// Opaque to users, visible only through the tape's memory stats.
#[derive(Debug, Clone)]
pub struct Residuals<F> {
    /// The first sample index (within its ray) that was skipped, or its length.
    pub(crate) stop: Vec<usize>,
    precision: PhantomData<F>,
}

/// The forward's outputs, flat, of all rays or of one block; each is empty when not configured.
pub(crate) struct Outputs<'a, F> {
    /// `[R * ch]`.
    pub color: &'a mut [F],
    /// `[R]`.
    pub opacity: &'a mut [F],
    /// `[R]`.
    pub depth: &'a mut [F],
    /// `[n]`.
    pub weights: &'a mut [F],
    /// `[n]`.
    pub transmittance: &'a mut [F],
}

impl<'a, F> Outputs<'a, F> {
    /// One `Outputs` per block, in block order (each empty where the op does not produce it).
    pub(crate) fn split(self, op: &Composite, blocks: &[Block], ch: usize) -> Vec<Outputs<'a, F>> {
        let Outputs {
            mut color,
            mut opacity,
            mut depth,
            mut weights,
            transmittance: mut trans,
        } = self;
        let part = |on: bool, len: usize| if on { len } else { 0 };
        blocks
            .iter()
            .map(|b| {
                let (nr, ns) = (b.rays.len(), b.samples.len());
                Outputs {
                    color: take_front(&mut color, nr * ch),
                    opacity: take_front(&mut opacity, nr),
                    depth: take_front(&mut depth, part(op.depth, nr)),
                    weights: take_front(&mut weights, part(op.weights, ns)),
                    transmittance: take_front(&mut trans, part(op.transmittance, ns)),
                }
            })
            .collect()
    }
}

/// Composites every ray; the flag is false if any sample value was invalid (NaN, infinite,
/// negative density or step), checked on the fly so that valid input costs no extra pass.
/// Every value of `out` is written (its lengths are the op's, checked by the caller).
pub(crate) fn forward<F: Float>(op: &Composite, x: &Flat<'_, F>, out: Outputs<'_, F>) -> (Residuals<F>, bool) {
    let rays = op.rays();
    let mut stop = vec![0; rays];
    let blocks = blocks(&op.offsets);
    let mut work = Vec::with_capacity(blocks.len());
    {
        let mut stop = &mut stop[..];
        for (b, o) in blocks.iter().zip(out.split(op, &blocks, x.ch)) {
            work.push((b.clone(), o, take_front(&mut stop, b.rays.len())));
        }
    }
    let valid = work
        .into_par_iter()
        .map(|(block, o, stop)| forward_block(op, x, &block, o, stop))
        .reduce(|| true, |a, b| a && b);
    let residuals = Residuals {
        stop,
        precision: PhantomData,
    };
    (residuals, valid)
}

/// Composites one block of rays into `o` and `stop`; false if any value was invalid. Compiled for the
/// vector units this machine has (chosen at run time), with the per-ray helpers inlined into
/// it: the crate itself is built for the baseline instruction set.
#[multiversion(targets("x86_64+avx512f+avx512dq+fma", "x86_64+avx2+fma", "aarch64+neon"))]
fn forward_block<'a, F: Float>(
    op: &Composite,
    x: &Flat<'a, F>,
    block: &Block,
    mut o: Outputs<'a, F>,
    stop: &'a mut [usize],
) -> bool {
    let mut acc = vec![0.0f64; x.ch];
    let mut att = Attenuation::for_rays(block.longest_ray(&op.offsets));
    let mut valid = true;
    for r in block.rays.clone() {
        // The next ray's inputs are asked for while this one is computed.
        if r + 1 < block.rays.end {
            x.request(block.ray(&op.offsets, r + 1).samples);
        }
        let ray = block.ray(&op.offsets, r);
        let result = composite_ray_into(op, x, &ray, &mut att, &mut acc, &mut o);
        stop[ray.in_block] = result.stop;
        valid &= result.valid;
    }
    valid
}

/// Composites `ray` into its block's outputs `o`; `att` keeps its attenuation (for a backward
/// that follows at once), `acc` is scratch of `ch` values.
#[inline(always)]
pub(crate) fn composite_ray_into<F: Float>(
    op: &Composite,
    x: &Flat<'_, F>,
    ray: &Ray,
    att: &mut Attenuation,
    acc: &mut [f64],
    o: &mut Outputs<'_, F>,
) -> RayResult {
    let (ch, r, j) = (x.ch, ray.index, ray.in_block);
    let (samples, local) = (ray.samples.clone(), ray.local.clone());
    let result = forward_ray(
        RayIn {
            sigma: &x.sigma[samples.clone()],
            delta: &x.delta[samples.clone()],
            color: &x.color[samples.start * ch..samples.end * ch],
            t: x.t.as_ref().map(|t| &t[samples.clone()]),
            background: x.background_of(r),
        },
        op.min_transmittance,
        att,
        acc,
        RayOut {
            transmittance: op.transmittance.then(|| &mut o.transmittance[local.clone()]),
            weights: op.weights.then(|| &mut o.weights[local]),
        },
    );
    for (c, &a) in acc.iter().enumerate() {
        o.color[j * ch + c] = F::lit(a);
    }
    o.opacity[j] = F::lit(result.opacity);
    if op.depth {
        o.depth[j] = F::lit(result.depth);
    }
    result
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

/// Whether no value is NaN or infinite, without a branch per value (so that it vectorises).
#[inline(always)]
pub(crate) fn all_finite<F: Float>(v: &[F]) -> bool {
    let max = F::max_value();
    v.iter().fold(true, |ok, &x| ok & (x.abs() <= max))
}

/// One ray's optional per-sample outputs.
pub(crate) struct RayOut<'a, F> {
    pub transmittance: Option<&'a mut [F]>,
    pub weights: Option<&'a mut [F]>,
}

/// One ray's scalar results.
pub(crate) struct RayResult {
    pub(crate) opacity: f64,
    pub(crate) depth: f64,
    pub(crate) stop: usize,
    /// Every sample's values are in their domain.
    pub(crate) valid: bool,
}

/// Composites one ray front to back. `color` (the f64 accumulator, `[ch]`) receives the pixel.
#[inline(always)]
pub(crate) fn forward_ray<F: Float>(
    ray: RayIn<'_, F>,
    min_transmittance: f64,
    att: &mut Attenuation,
    color: &mut [f64],
    out: RayOut<'_, F>,
) -> RayResult {
    let len = ray.sigma.len();
    let mut valid = valid_steps(ray.sigma, ray.delta);
    att.compute(ray.sigma, ray.delta, min_transmittance);
    let stop = att.stop();
    let (trans, weights) = (att.transmittance(), att.weights());
    let t_end = trans[stop];
    color.fill(0.0);
    weighted_column_sums(ray.color, &weights[..stop], color);
    let depth = ray.t.map_or(0.0, |t| {
        weights[..stop]
            .iter()
            .zip(t)
            .fold(0.0, |d, (&w, &t)| d + w * t.as_f64())
    });
    // Checked for every sample, composited or skipped: invalid input is an error wherever it is.
    valid &= all_finite(ray.color);
    valid &= ray.t.is_none_or(all_finite);
    // Skipped samples are empty space behind the stop, seen through the residual T_stop.
    if let Some(ts) = out.transmittance {
        for (k, t) in ts.iter_mut().enumerate() {
            *t = F::lit(if k < stop { trans[k] } else { t_end });
        }
    }
    if let Some(ws) = out.weights {
        for (k, w) in ws.iter_mut().enumerate() {
            *w = if k < stop { F::lit(weights[k]) } else { F::zero() };
        }
    }
    for (acc, &bg) in color.iter_mut().zip(ray.background) {
        *acc += t_end * bg.as_f64();
    }
    debug_assert!(stop <= len);
    RayResult {
        // Not 1 - T_end, which is 0 for a faint ray.
        opacity: att.opacity_before::<F>(stop),
        depth,
        stop,
        valid,
    }
}
