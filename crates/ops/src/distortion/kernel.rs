//! The op's forward and backward on flat slices, one ray at a time in f64, parallel over fixed
//! chunks of rays. Every value of a ray depends on that ray alone and is computed by the same
//! sequence of operations whichever thread runs it, and the per-ray losses are summed in ray
//! order after the parallel part, so the results are bitwise the same for any number of
//! threads.
//!
//! The weights are the composite's (`crate::math::exp`: `exp(-x)` and `-expm1(-x)` over a
//! ray's slices, to the tier of the data's precision); the pairwise sum is carried by the two
//! recurrences of the [module docs](super), whose terms are all non-negative. Each chunk is
//! compiled for the vector units (multiversion), as the composite's and the activation's are.

use fogray_tape::{Float, Offsets};
use multiversion::multiversion;
use rayon::prelude::*;

use crate::math::exp::{exp_neg_slice, one_minus_exp_neg_slice, single_tier};

/// Rays per parallel task: fixed, so results never depend on the thread count.
pub(crate) const RAYS_PER_CHUNK: usize = 256;

/// The first ray of every chunk.
fn chunk_starts(rays: usize) -> impl Iterator<Item = usize> {
    (0..rays).step_by(RAYS_PER_CHUNK)
}

/// The rays of chunk `r0` (to the end of the rays).
fn chunk_rays(r0: usize, rays: usize) -> std::ops::Range<usize> {
    r0..(r0 + RAYS_PER_CHUNK).min(rays)
}

/// A chunk's work space, sized for its longest ray `n`: optical depths `tau` (`n`), running
/// depths before each sample and the total (`n + 1`), their transmittances `T_k` (`n + 1`:
/// `T_{k+1}` is the transmittance after sample `k`), alphas, weights and the front-to-back
/// sums `A_i` (`n`).
struct Scratch {
    tau: Vec<f64>,
    depth: Vec<f64>,
    trans: Vec<f64>,
    alpha: Vec<f64>,
    w: Vec<f64>,
    a: Vec<f64>,
}

impl Scratch {
    fn new(offsets: &[usize], rays: std::ops::Range<usize>) -> Self {
        let n = rays.map(|r| offsets[r + 1] - offsets[r]).max().unwrap_or(0);
        Scratch {
            tau: vec![0.0; n],
            depth: vec![0.0; n + 1],
            trans: vec![0.0; n + 1],
            alpha: vec![0.0; n],
            w: vec![0.0; n],
            a: vec![0.0; n],
        }
    }

    /// The weights of one ray of `n = sigma.len()` samples (and `tau`, `T`, `alpha`) into the
    /// first `n` (`n + 1`) entries: the exponentials run over whole slices, so that they
    /// vectorise.
    #[inline(always)]
    fn weights<const SINGLE: bool, F: Float>(&mut self, sigma: &[F], delta: &[F]) {
        let n = sigma.len();
        let mut depth = 0.0f64;
        self.depth[0] = 0.0;
        for k in 0..n {
            let tau = sigma[k].as_f64() * delta[k].as_f64();
            self.tau[k] = tau;
            depth += tau;
            self.depth[k + 1] = depth;
        }
        exp_neg_slice::<SINGLE>(&self.depth[..=n], &mut self.trans[..=n]);
        one_minus_exp_neg_slice::<SINGLE>(&self.tau[..n], &mut self.alpha[..n]);
        for k in 0..n {
            self.w[k] = self.trans[k] * self.alpha[k];
        }
    }
}

/// `L_r` of one ray (its samples' `sigma`, `delta` and `t`, checked), in f64:
/// `2 sum_i w_i A_i + (1/3) sum_i w_i^2 delta_i` with `A_i = sum_{j<i} w_j (t_i - t_j)`
/// accumulated as `A_i = A_{i-1} + S_{<i} (t_i - t_{i-1})`.
#[inline(always)]
fn ray_loss<const SINGLE: bool, F: Float>(sigma: &[F], delta: &[F], t: &[F], s: &mut Scratch) -> f64 {
    s.weights::<SINGLE, F>(sigma, delta);
    let w = &s.w[..sigma.len()];
    let (mut sum, mut a) = (0.0f64, 0.0f64);
    let (mut pairs, mut own) = (0.0f64, 0.0f64);
    for k in 0..w.len() {
        if k > 0 {
            a += sum * (t[k].as_f64() - t[k - 1].as_f64());
        }
        pairs += w[k] * a;
        own += w[k] * w[k] * delta[k].as_f64();
        sum += w[k];
    }
    2.0 * pairs + own / 3.0
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
    s.weights::<SINGLE, F>(sigma, delta);
    let (w, alpha, trans, a) = (&s.w[..n], &s.alpha[..n], &s.trans[..=n], &mut s.a[..n]);
    let (mut sum, mut acc) = (0.0f64, 0.0f64);
    for k in 0..n {
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
        let g_tau = trans[k + 1] * (g - r);
        r += alpha[k] * (g - r);
        out[k] = F::lit(d * g_tau);
    }
}

/// The losses of the rays `r0..` of one chunk into `losses`. Compiled for the vector units
/// this machine has (chosen at run time); the values do not depend on which: every fused
/// multiply-add is written as one, and the compiler contracts nothing else.
#[multiversion(targets("x86_64+avx512f+avx512dq+fma", "x86_64+avx2+fma", "aarch64+neon"))]
fn forward_chunk<F: Float>(offsets: &[usize], r0: usize, sigma: &[F], delta: &[F], t: &[F], losses: &mut [f64]) {
    let mut scratch = Scratch::new(offsets, r0..r0 + losses.len());
    for (i, l) in losses.iter_mut().enumerate() {
        let samples = offsets[r0 + i]..offsets[r0 + i + 1];
        let (s, d, t) = (&sigma[samples.clone()], &delta[samples.clone()], &t[samples]);
        *l = if single_tier::<F>() {
            ray_loss::<true, F>(s, d, t, &mut scratch)
        } else {
            ray_loss::<false, F>(s, d, t, &mut scratch)
        };
    }
}

/// The gradients of the rays `rays` of one chunk into `piece`, their samples (as
/// [`forward_chunk`]).
#[multiversion(targets("x86_64+avx512f+avx512dq+fma", "x86_64+avx2+fma", "aarch64+neon"))]
fn backward_chunk<F: Float>(
    offsets: &[usize],
    rays: std::ops::Range<usize>,
    sigma: &[F],
    delta: &[F],
    t: &[F],
    scale: f64,
    piece: &mut [F],
) {
    let mut scratch = Scratch::new(offsets, rays.clone());
    let base = offsets[rays.start];
    for r in rays {
        let samples = offsets[r]..offsets[r + 1];
        let out = &mut piece[samples.start - base..samples.end - base];
        let (s, d, t) = (&sigma[samples.clone()], &delta[samples.clone()], &t[samples]);
        if single_tier::<F>() {
            ray_grad::<true, F>(scale, s, d, t, out, &mut scratch);
        } else {
            ray_grad::<false, F>(scale, s, d, t, out, &mut scratch);
        }
    }
}

/// `L_r` of every ray into `losses` (`R` values, f64), from checked inputs.
pub(crate) fn ray_losses<F: Float>(offsets: &Offsets, sigma: &[F], delta: &[F], t: &[F], losses: &mut [f64]) {
    losses
        .par_chunks_mut(RAYS_PER_CHUNK)
        .enumerate()
        .for_each(|(chunk, losses)| forward_chunk(offsets, chunk * RAYS_PER_CHUNK, sigma, delta, t, losses));
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
    let pieces: Vec<(std::ops::Range<usize>, &mut [F])> = chunk_starts(rays)
        .map(|r0| {
            let chunk = chunk_rays(r0, rays);
            let len = offsets[chunk.end] - offsets[chunk.start];
            let (head, tail) = std::mem::take(&mut rest).split_at_mut(len);
            rest = tail;
            (chunk, head)
        })
        .collect();
    pieces
        .into_par_iter()
        .for_each(|(chunk, piece)| backward_chunk(offsets, chunk, sigma, delta, t, scale, piece));
}
