//! Forward, loss gradient and backward in one pass per ray, for a loss that sums a function of
//! each ray's colour (a photometric loss): the backward takes the attenuation the forward has
//! just computed, instead of recomputing its two exponentials per sample, and reads the ray's
//! inputs while they are still in cache, instead of from memory a second time.

use fogray_tape::Float;
use multiversion::multiversion;
use rayon::prelude::*;

use super::attenuation::Attenuation;
use super::backward::{backward_ray, InputGrads, RayUpstream, Scratch, Wanted};
use super::config::Composite;
use super::forward::{composite_ray_into, Outputs};
use super::layout::{blocks, Block, Flat};

/// `upstream(ray, colour, d_colour)` writes `dL/dC` of a ray from its colour as written to the
/// outputs.
pub(crate) trait ColorLoss<F>: Fn(usize, &[F], &mut [F]) + Sync {}
impl<F, U: Fn(usize, &[F], &mut [F]) + Sync> ColorLoss<F> for U {}

/// Composites every ray into `out` and writes the wanted input gradients into `grads`, with
/// the colour's upstream gradient from `upstream` (the other outputs have none); false if any
/// input value was invalid. Every value of the outputs and of the wanted gradients is written.
pub(crate) fn one_pass<F: Float>(
    op: &Composite,
    x: &Flat<'_, F>,
    out: Outputs<'_, F>,
    grads: InputGrads<'_, F>,
    want: Wanted,
    upstream: &impl ColorLoss<F>,
) -> bool {
    let blocks = blocks(&op.offsets);
    let outs = out.split(op, &blocks, x.ch);
    let grads = grads.split(&blocks, want, x.ch);
    let work: Vec<_> = blocks.iter().cloned().zip(outs).zip(grads).collect();
    work.into_par_iter()
        .map(|((block, o), g)| one_pass_block(op, x, &block, o, g, want, upstream))
        .reduce(|| true, |a, b| a && b)
}

/// One block of [`one_pass`], compiled for the vector units this machine has (as the forward's
/// and the backward's blocks are).
#[multiversion(targets("x86_64+avx512f+avx512dq+fma", "x86_64+avx2+fma", "aarch64+neon"))]
fn one_pass_block<'a, F: Float, U: ColorLoss<F>>(
    op: &Composite,
    x: &Flat<'a, F>,
    block: &Block,
    mut o: Outputs<'a, F>,
    mut g: InputGrads<'a, F>,
    want: Wanted,
    upstream: &U,
) -> bool {
    let ch = x.ch;
    let mut acc = vec![0.0f64; ch];
    let mut d_color = vec![F::zero(); ch];
    let longest = block.longest_ray(&op.offsets);
    let mut att = Attenuation::for_rays(longest);
    let mut scratch = Scratch::for_rays(longest);
    let mut valid = true;
    for r in block.rays.clone() {
        // The next ray's lines are asked for while this one is computed.
        if r + 1 < block.rays.end {
            let next = block.ray(&op.offsets, r + 1);
            x.request(next.samples);
            g.request(next.local, ch);
        }
        let ray = block.ray(&op.offsets, r);
        let result = composite_ray_into(op, x, &ray, &mut att, &mut acc, &mut o);
        valid &= result.valid;
        color_upstream(upstream, ray.index, ray.in_block, &o, &mut d_color);
        backward_ray(x, want, &ray, &att, only_color(&d_color), &mut scratch, &mut g);
    }
    valid
}

/// `dL/dC` of ray `r` (the block's `j`-th) into `d`, from its colour as written to `o`.
#[inline(always)]
fn color_upstream<F: Float, U: ColorLoss<F>>(upstream: &U, r: usize, j: usize, o: &Outputs<'_, F>, d: &mut [F]) {
    let ch = d.len();
    d.fill(F::zero());
    upstream(r, &o.color[j * ch..(j + 1) * ch], d);
}

/// A ray's upstream gradients when only its colour has one.
#[inline(always)]
fn only_color<F>(d_color: &[F]) -> RayUpstream<'_, F> {
    RayUpstream {
        color: Some(d_color),
        opacity: 0.0,
        depth: 0.0,
        weights: None,
        transmittance: None,
    }
}
