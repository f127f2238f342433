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
use super::lanes::{Unit, LANES};
use super::layout::{blocks, Block, Flat};
use super::pack_attenuation::PackAttenuation;
use super::pack_backward::{backward_pack, PackScratch};
use super::pack_forward::{forward_pack, ForwardScratch};

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
    let mut d_color = vec![F::zero(); ch * LANES];
    let longest = block.longest_ray(&op.offsets);
    let mut att = Attenuation::for_rays(longest);
    let mut scratch = Scratch::for_rays(longest);
    let mut pack = PackAttenuation::default();
    let mut pack_forward = ForwardScratch::default();
    let mut pack_scratch = PackScratch::default();
    let mut valid = true;
    let mut units = block.units(&op.offsets, op.packs).peekable();
    while let Some(unit) = units.next() {
        // The next unit's lines are asked for while this one is computed.
        if let Some((samples, local)) = units.peek().map(Unit::spans) {
            x.request(samples);
            g.request(local, ch);
        }
        match unit {
            Unit::Single(ray) => {
                let result = composite_ray_into(op, x, &ray, &mut att, &mut acc, &mut o);
                valid &= result.valid;
                let d_color = &mut d_color[..ch];
                color_upstream(upstream, ray.index, ray.in_block, &o, d_color);
                backward_ray(x, want, &ray, &att, only_color(d_color), &mut scratch, &mut g);
            }
            Unit::Pack { first, len } => {
                let (stops, ok) = forward_pack(op, x, &first, len, &mut pack, &mut pack_forward, &mut o);
                valid &= ok;
                for (l, d) in d_color.chunks_exact_mut(ch).enumerate() {
                    color_upstream(upstream, first.index + l, first.in_block + l, &o, d);
                }
                if stops.iter().all(|&s| s == stops[0]) {
                    let up = std::array::from_fn(|l| only_color(&d_color[l * ch..(l + 1) * ch]));
                    backward_pack(x, want, &first, len, &pack, &up, &mut pack_scratch, &mut g);
                } else {
                    // Lanes that stop apart count their groups of four from different samples:
                    // ray by ray, the attenuation recomputed (bitwise the same).
                    for (l, d) in d_color.chunks_exact(ch).enumerate() {
                        let ray = block.ray(&op.offsets, first.index + l);
                        att.compute(
                            &x.sigma[ray.samples.clone()],
                            &x.delta[ray.samples.clone()],
                            op.min_transmittance,
                        );
                        backward_ray(x, want, &ray, &att, only_color(d), &mut scratch, &mut g);
                    }
                }
            }
        }
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
