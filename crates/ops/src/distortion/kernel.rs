//! The op's forward and backward on flat slices, one ray at a time in f64, parallel over fixed
//! chunks of rays. Every value of a ray depends on that ray alone and is computed by the same
//! sequence of operations whichever thread runs it, and the per-ray losses are summed in ray
//! order after the parallel part, so the results are bitwise the same for any number of
//! threads.
//!
//! The weights are the composite's (`crate::math::exp`: `exp(-x)` and `-expm1(-x)`, to the
//! tier of the data's precision); the pairwise sum is carried by the two recurrences of the
//! [module docs](super), whose terms are all non-negative.

use fogray_tape::{Float, Offsets};
use rayon::prelude::*;

use crate::math::exp::{exp_neg, one_minus_exp_neg, single_tier};

/// Rays per parallel task: fixed, so results never depend on the thread count.
pub(crate) const RAYS_PER_CHUNK: usize = 256;

/// The first ray of every chunk.
fn chunk_starts(rays: usize) -> impl Iterator<Item = usize> {
    (0..rays).step_by(RAYS_PER_CHUNK)
}

/// `L_r` of one ray (its samples' `sigma`, `delta` and `t`, checked), in f64:
/// `2 sum_i w_i A_i + (1/3) sum_i w_i^2 delta_i` with `A_i = sum_{j<i} w_j (t_i - t_j)`
/// accumulated as `A_i = A_{i-1} + S_{<i} (t_i - t_{i-1})`.
#[inline(always)]
fn ray_loss<const SINGLE: bool, F: Float>(sigma: &[F], delta: &[F], t: &[F]) -> f64 {
    let (mut depth, mut s, mut a) = (0.0f64, 0.0f64, 0.0f64);
    let (mut pairs, mut own) = (0.0f64, 0.0f64);
    for k in 0..sigma.len() {
        let d = delta[k].as_f64();
        if k > 0 {
            a += s * (t[k].as_f64() - t[k - 1].as_f64());
        }
        let tau = sigma[k].as_f64() * d;
        let w = exp_neg::<SINGLE>(depth) * one_minus_exp_neg::<SINGLE>(tau);
        depth += tau;
        pairs += w * a;
        own += w * w * d;
        s += w;
    }
    2.0 * pairs + own / 3.0
}

/// Per-ray work space of the backward: weights, alphas, transmittance after each sample, and
/// the front-to-back sums `A_i`.
struct Scratch {
    w: Vec<f64>,
    alpha: Vec<f64>,
    after: Vec<f64>,
    a: Vec<f64>,
}

impl Scratch {
    fn new(len: usize) -> Self {
        Scratch {
            w: vec![0.0; len],
            alpha: vec![0.0; len],
            after: vec![0.0; len],
            a: vec![0.0; len],
        }
    }
}

/// `dL_r/dsigma` of one ray times `scale` (the upstream gradient over the number of rays),
/// into `out`: `g_i = scale (2 A_i + 2 B_i + (2/3) w_i delta_i)` and
/// `dL/dsigma_k = delta_k T_{k+1} (g_k - R_{k+1})` with `R` the back-to-front recurrence of
/// the [module docs](super).
#[inline(always)]
fn ray_grad<const SINGLE: bool, F: Float>(
    scale: f64,
    sigma: &[F],
    delta: &[F],
    t: &[F],
    out: &mut [F],
    s: &mut Scratch,
) {
    let n = sigma.len();
    let (w, alpha, after, a) = (&mut s.w[..n], &mut s.alpha[..n], &mut s.after[..n], &mut s.a[..n]);
    let (mut depth, mut sum, mut acc) = (0.0f64, 0.0f64, 0.0f64);
    for k in 0..n {
        let tau = sigma[k].as_f64() * delta[k].as_f64();
        alpha[k] = one_minus_exp_neg::<SINGLE>(tau);
        w[k] = exp_neg::<SINGLE>(depth) * alpha[k];
        depth += tau;
        after[k] = exp_neg::<SINGLE>(depth);
        if k > 0 {
            acc += sum * (t[k].as_f64() - t[k - 1].as_f64());
        }
        a[k] = acc;
        sum += w[k];
    }
    // Back to front: B_k = sum_{j>k} w_j (t_j - t_k) = B_{k+1} + S_{>k} (t_{k+1} - t_k), the
    // weight gradient g_k, and R_k = R_{k+1} + alpha_k (g_k - R_{k+1}).
    let (mut sum, mut b, mut r) = (0.0f64, 0.0f64, 0.0f64);
    for k in (0..n).rev() {
        let d = delta[k].as_f64();
        if k + 1 < n {
            b += sum * (t[k + 1].as_f64() - t[k].as_f64());
        }
        sum += w[k];
        let g = scale * (2.0 * (a[k] + b) + (2.0 / 3.0) * w[k] * d);
        let g_tau = after[k] * (g - r);
        r += alpha[k] * (g - r);
        out[k] = F::lit(d * g_tau);
    }
}

/// `L_r` of every ray into `losses` (`R` values, f64), from checked inputs.
pub(crate) fn ray_losses<F: Float>(offsets: &Offsets, sigma: &[F], delta: &[F], t: &[F], losses: &mut [f64]) {
    losses
        .par_chunks_mut(RAYS_PER_CHUNK)
        .enumerate()
        .for_each(|(chunk, losses)| {
            let r0 = chunk * RAYS_PER_CHUNK;
            for (i, l) in losses.iter_mut().enumerate() {
                let samples = offsets[r0 + i]..offsets[r0 + i + 1];
                let (s, d, t) = (&sigma[samples.clone()], &delta[samples.clone()], &t[samples]);
                *l = if single_tier::<F>() {
                    ray_loss::<true, F>(s, d, t)
                } else {
                    ray_loss::<false, F>(s, d, t)
                };
            }
        });
}

/// The mean of the per-ray losses, summed in ray order (0 for no ray), in f64.
pub(crate) fn mean_loss<F: Float>(offsets: &Offsets, sigma: &[F], delta: &[F], t: &[F]) -> f64 {
    let rays = offsets.segments();
    if rays == 0 {
        return 0.0;
    }
    let mut losses = vec![0.0; rays];
    ray_losses(offsets, sigma, delta, t, &mut losses);
    losses.iter().sum::<f64>() / rays as f64
}

/// `dL/dsigma` of the mean loss times `upstream` into `g_sigma` (`[n]`), from checked inputs.
pub(crate) fn backward<F: Float>(
    offsets: &Offsets,
    sigma: &[F],
    delta: &[F],
    t: &[F],
    upstream: f64,
    g_sigma: &mut [F],
) {
    let rays = offsets.segments();
    if rays == 0 {
        return;
    }
    let scale = upstream / rays as f64;
    // The chunks' disjoint pieces of the gradient, in order.
    let mut rest = g_sigma;
    let pieces: Vec<(usize, &mut [F])> = chunk_starts(rays)
        .map(|r0| {
            let r1 = (r0 + RAYS_PER_CHUNK).min(rays);
            let (head, tail) = std::mem::take(&mut rest).split_at_mut(offsets[r1] - offsets[r0]);
            rest = tail;
            (r0, head)
        })
        .collect();
    pieces.into_par_iter().for_each(|(r0, piece)| {
        let r1 = (r0 + RAYS_PER_CHUNK).min(rays);
        let longest = (r0..r1).map(|r| offsets[r + 1] - offsets[r]).max().unwrap_or(0);
        let mut scratch = Scratch::new(longest);
        let base = offsets[r0];
        for r in r0..r1 {
            let samples = offsets[r]..offsets[r + 1];
            let out = &mut piece[samples.start - base..samples.end - base];
            let (s, d, t) = (&sigma[samples.clone()], &delta[samples.clone()], &t[samples]);
            if single_tier::<F>() {
                ray_grad::<true, F>(scale, s, d, t, out, &mut scratch);
            } else {
                ray_grad::<false, F>(scale, s, d, t, out, &mut scratch);
            }
        }
    });
}
