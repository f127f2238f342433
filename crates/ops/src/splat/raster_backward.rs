//! The rasteriser's backward, pixel by pixel over the same splats the forward composited
//! (the first [`Raster::count`] entries of the tile's list, skipping the same ones).
//!
//! The transmittance before each splat is recomputed front to back as the forward made it (a
//! product, never a division by `1 - alpha`); then, back to front, `R`, the colour of what
//! lies behind a splat given that the ray gets past it, is carried as
//! `R <- R + alpha_k (c_k - R)` from `R = background`, and
//!
//! ```text
//! dC/dc_k     = T_k alpha_k
//! dC/dalpha_k = T_k (c_k - R_{k+1})          what it adds minus what it hides
//! ```
//!
//! Through `alpha = opacity g`, `g = exp(power)` (where the clamp at 0.99 is not in force:
//! a clamped alpha is a constant), `dalpha/dopacity = g`, `dalpha/dpower = alpha`, and the
//! power's derivatives in the 2-D mean and the conic. The gradient is for the opacity itself,
//! `[0, 1]` (the fused op chains it through its sigmoid).
//!
//! Each tile writes the contributions of its pixels into its own slice of a buffer with one
//! row per (tile, splat) entry, in pixel order; the rows are then summed per splat in list
//! order. The gradients are therefore the same for any thread count, bit for bit.

use rayon::prelude::*;

use super::project::Projection;
use super::raster::{centre, check_inputs, gather, hit, pack, tile_pixels, Packed, Raster};
use super::tiles::TileLists;
use crate::error::{Op, OpsError};

/// The gradients of a loss for the rasteriser's inputs, one entry per splat (zeros for
/// splats that no pixel composited).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RasterGradients {
    /// `dL/dmean2d`.
    pub mean2d: Vec<[f64; 2]>,
    /// `dL/dconic`, for `[a, b, c]` of `[[a, b], [b, c]]` (`b` counted once).
    pub conic: Vec<[f64; 3]>,
    /// `dL/dopacity` (of the opacity in `[0, 1]`).
    pub opacity: Vec<f64>,
    /// `dL/dcolor`.
    pub color: Vec<[f64; 3]>,
    /// `dL/dbackground`.
    pub background: [f64; 3],
}

/// One (tile, splat) entry's gradient: 2-D mean (2), conic (3), opacity (1), colour (3).
type Entry = [f64; 9];

/// A composited splat of one pixel, kept between the two sweeps.
#[derive(Debug, Clone, Copy)]
struct Step {
    k: usize,
    t: f64,
    hit: super::raster::Hit,
}

/// One pixel's backward, adding into `grads` (its tile's entries) and returning its
/// background gradient.
#[allow(clippy::too_many_arguments)]
fn pixel(
    colors: &[[f64; 3]],
    background: [f64; 3],
    local: &[Packed],
    count: usize,
    px: [f64; 2],
    g: [f64; 3],
    steps: &mut Vec<Step>,
    grads: &mut [Entry],
) -> f64 {
    steps.clear();
    let mut t = 1.0;
    for (k, p) in local[..count].iter().enumerate() {
        if let Some(h) = hit(p, px) {
            steps.push(Step { k, t, hit: h });
            t *= 1.0 - h.alpha;
        }
    }
    let mut behind = background;
    for s in steps.iter().rev() {
        let p = &local[s.k];
        let (alpha, c) = (s.hit.alpha, colors[p.index]);
        let e = &mut grads[s.k];
        let mut g_alpha = 0.0;
        for ch in 0..3 {
            e[6 + ch] += g[ch] * s.t * alpha;
            g_alpha += g[ch] * s.t * (c[ch] - behind[ch]);
            behind[ch] += alpha * (c[ch] - behind[ch]);
        }
        if s.hit.free {
            let g_power = g_alpha * alpha;
            let [a, b, cc] = p.conic;
            let [dx, dy] = s.hit.d;
            e[0] -= g_power * (a * dx + b * dy);
            e[1] -= g_power * (b * dx + cc * dy);
            e[2] -= g_power * 0.5 * dx * dx;
            e[3] -= g_power * dx * dy;
            e[4] -= g_power * 0.5 * dy * dy;
            e[5] += g_alpha * s.hit.gauss;
        }
    }
    t
}

/// The gradients of a loss for the inputs of [`rasterize`](super::rasterize), given the
/// raster it made and `g_color`, the loss's gradient for each pixel's colour (see the
/// [module docs](self)).
///
/// Errors: arrays whose lengths differ from the projection's or the image's, or a raster that
/// these tiles did not make (a count beyond its tile's list) ([`OpsError::Shape`]).
pub fn rasterize_vjp(
    proj: &Projection,
    tiles: &TileLists,
    opacity: &[f64],
    colors: &[[f64; 3]],
    background: [f64; 3],
    raster: &Raster,
    g_color: &[[f64; 3]],
) -> Result<RasterGradients, OpsError> {
    let n = check_inputs(proj, tiles, opacity, colors)?;
    let pixels = tiles.width * tiles.height;
    for (what, len) in [
        ("colour gradient", g_color.len()),
        ("raster counts", raster.count.len()),
        ("raster transmittance", raster.transmittance.len()),
    ] {
        if len != pixels {
            return Err(OpsError::shape(Op::Splat, what, pixels.to_string(), len.to_string()));
        }
    }
    let packed = pack(proj, opacity);
    // Each tile's slice of the entry buffer.
    let mut entries: Vec<Entry> = vec![[0.0; 9]; tiles.splats.len()];
    let mut slices: Vec<&mut [Entry]> = Vec::with_capacity(tiles.tiles());
    let mut rest = entries.as_mut_slice();
    for t in 0..tiles.tiles() {
        let (head, tail) = rest.split_at_mut(tiles.offsets[t + 1] - tiles.offsets[t]);
        slices.push(head);
        rest = tail;
    }
    let bad_count = slices
        .into_par_iter()
        .enumerate()
        .map(|(t, grads)| {
            let local = gather(&packed, tiles.tile(t));
            let (rows, cols) = tile_pixels(tiles, t);
            let mut steps = Vec::new();
            let mut g_bg = [0.0; 3];
            for row in rows {
                for col in cols.clone() {
                    let p = row * tiles.width + col;
                    let count = raster.count[p] as usize;
                    if count > local.len() {
                        return Err(p);
                    }
                    let g = g_color[p];
                    let left = pixel(
                        colors,
                        background,
                        &local,
                        count,
                        centre(row, col),
                        g,
                        &mut steps,
                        grads,
                    );
                    for ch in 0..3 {
                        g_bg[ch] += g[ch] * left;
                    }
                }
            }
            Ok(g_bg)
        })
        .collect::<Vec<Result<[f64; 3], usize>>>();
    let mut out = RasterGradients {
        mean2d: vec![[0.0; 2]; n],
        conic: vec![[0.0; 3]; n],
        opacity: vec![0.0; n],
        color: vec![[0.0; 3]; n],
        background: [0.0; 3],
    };
    for r in bad_count {
        match r {
            Ok(g) => (0..3).for_each(|ch| out.background[ch] += g[ch]),
            Err(p) => {
                return Err(OpsError::shape(
                    Op::Splat,
                    "raster count",
                    format!("at most its tile's list length at pixel {p}"),
                    raster.count[p].to_string(),
                ))
            }
        }
    }
    for (e, &i) in entries.iter().zip(&tiles.splats) {
        let i = i as usize;
        out.mean2d[i][0] += e[0];
        out.mean2d[i][1] += e[1];
        (0..3).for_each(|j| out.conic[i][j] += e[2 + j]);
        out.opacity[i] += e[5];
        (0..3).for_each(|j| out.color[i][j] += e[6 + j]);
    }
    Ok(out)
}
