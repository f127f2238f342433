//! The rasteriser's forward: every pixel composites its tile's splats front to back,
//!
//! ```text
//! d = mean2d - (col + 0.5, row + 0.5)
//! alpha = min(0.99, opacity exp(-d^T conic d / 2))     skipped below 1/255
//! C = sum_i T_i alpha_i c_i + T_end background,   T_{i+1} = T_i (1 - alpha_i),  T_0 = 1
//! ```
//!
//! and stops before the splat that would take the transmittance below `1e-4` (3D Gaussian
//! splatting's rule: what is left behind is that splat's and the background's, at most `1e-4`
//! of the pixel). The pixel's count of list entries read ([`Raster::count`]) is kept, so that
//! the backward reads exactly the same splats. The alpha clamp keeps every splat from hiding
//! all behind it (`1 - alpha >= 0.01`), which keeps the transmittance a product of factors
//! far from 0. Work is parallel over tiles; each pixel is computed by one sequence of f64
//! operations whichever thread runs it, so the image is the same for any thread count.

use rayon::prelude::*;

use super::project::Projection;
use super::tiles::{TileLists, TILE};
use crate::error::{Op, OpsError};

/// The largest alpha a splat may have.
pub const ALPHA_MAX: f64 = 0.99;
/// Splats fainter than this at a pixel are skipped there.
pub const ALPHA_MIN: f64 = 1.0 / 255.0;
/// A pixel stops before the splat that would take its transmittance below this.
pub const T_MIN: f64 = 1e-4;

/// A rendered image and what its backward needs, row-major, pixel `row * width + col`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Raster {
    /// The colour of each pixel.
    pub color: Vec<[f64; 3]>,
    /// The transmittance left at each pixel (the background's weight).
    pub transmittance: Vec<f64>,
    /// The number of entries of its tile's list each pixel read up to and including the last
    /// splat it composited (0 if none).
    pub count: Vec<u32>,
}

/// A splat as one pixel sees it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Hit {
    /// The clamped alpha.
    pub(crate) alpha: f64,
    /// `exp(power)`, the Gaussian's value.
    pub(crate) gauss: f64,
    /// `mean2d - pixel`.
    pub(crate) d: [f64; 2],
    /// Whether `opacity gauss` is below [`ALPHA_MAX`] (else alpha is the constant clamp).
    pub(crate) free: bool,
}

/// What a pixel reads of a splat, packed together (one or two cache lines rather than four
/// arrays), and gathered per tile in list order so that a tile's pixels stream through it.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Packed {
    pub(crate) mean: [f64; 2],
    pub(crate) conic: [f64; 3],
    pub(crate) opacity: f64,
    /// A power below this gives an alpha below [`ALPHA_MIN`] for certain: the exponential
    /// is then not computed. It sits a margin below `ln(ALPHA_MIN / opacity)`, far wider
    /// than the rounding of either side, and powers between it and the exact bound take the
    /// exact test, so the skip decides nothing the exact test would decide otherwise.
    pub(crate) cutoff: f64,
    /// The splat's index.
    pub(crate) index: usize,
}

/// How far below the exact bound [`Packed::cutoff`] sits.
const CUTOFF_MARGIN: f64 = 1e-6;

/// Every splat of `proj` packed with its opacity (in parallel, each on its own).
pub(crate) fn pack(proj: &Projection, opacity: &[f64]) -> Vec<Packed> {
    (0..proj.len())
        .into_par_iter()
        .with_min_len(1024)
        .map(|i| Packed {
            mean: proj.mean2d[i],
            conic: proj.conic[i],
            opacity: opacity[i],
            // ln of +inf (opacity 0) skips every pixel; NaN (never from a checked opacity)
            // compares false and leaves the exact test to decide.
            cutoff: (ALPHA_MIN / opacity[i]).ln() - CUTOFF_MARGIN,
            index: i,
        })
        .collect()
}

/// The packed splats of a tile's list, in order.
pub(crate) fn gather(packed: &[Packed], list: &[u32]) -> Vec<Packed> {
    list.iter().map(|&i| packed[i as usize]).collect()
}

/// Splat `p` at the pixel centre `px`, or `None` where it is skipped.
#[inline(always)]
pub(crate) fn hit(p: &Packed, px: [f64; 2]) -> Option<Hit> {
    let [a, b, c] = p.conic;
    let d = [p.mean[0] - px[0], p.mean[1] - px[1]];
    let power = -0.5 * (a * d[0] * d[0] + c * d[1] * d[1]) - b * d[0] * d[1];
    // A positive power only comes from rounding at a conic's edge of definiteness.
    if power > 0.0 || power < p.cutoff {
        return None;
    }
    let gauss = power.exp();
    let raw = p.opacity * gauss;
    let alpha = raw.min(ALPHA_MAX);
    (alpha >= ALPHA_MIN).then_some(Hit {
        alpha,
        gauss,
        d,
        free: raw < ALPHA_MAX,
    })
}

/// The pixels of tile `t`: `(row range, column range)`.
#[inline]
pub(crate) fn tile_pixels(tiles: &TileLists, t: usize) -> (std::ops::Range<usize>, std::ops::Range<usize>) {
    let (tx, ty) = (t % tiles.tiles_x, t / tiles.tiles_x);
    (
        ty * TILE..((ty + 1) * TILE).min(tiles.height),
        tx * TILE..((tx + 1) * TILE).min(tiles.width),
    )
}

/// The pixel centre of (`row`, `col`).
#[inline(always)]
pub(crate) fn centre(row: usize, col: usize) -> [f64; 2] {
    [col as f64 + 0.5, row as f64 + 0.5]
}

/// Checks that `proj`, `opacity`, `colors` and `tiles` describe the same splats.
pub(crate) fn check_inputs(
    proj: &Projection,
    tiles: &TileLists,
    opacity: &[f64],
    colors: &[[f64; 3]],
) -> Result<usize, OpsError> {
    let n = proj.check_lengths()?;
    for (what, len) in [
        ("opacities", opacity.len()),
        ("colours", colors.len()),
        ("tile lists' splats", tiles.n),
    ] {
        if len != n {
            return Err(OpsError::shape(Op::Splat, what, n.to_string(), len.to_string()));
        }
    }
    Ok(n)
}

/// One pixel: its colour, transmittance and count.
#[inline]
fn pixel(colors: &[[f64; 3]], background: [f64; 3], local: &[Packed], px: [f64; 2]) -> ([f64; 3], f64, u32) {
    let (mut t, mut color, mut count) = (1.0, [0.0; 3], 0);
    for (k, p) in local.iter().enumerate() {
        let Some(h) = hit(p, px) else { continue };
        let next = t * (1.0 - h.alpha);
        if next < T_MIN {
            break;
        }
        let w = t * h.alpha;
        for (o, c) in color.iter_mut().zip(colors[p.index]) {
            *o += w * c;
        }
        t = next;
        count = k as u32 + 1;
    }
    for (o, b) in color.iter_mut().zip(background) {
        *o += t * b;
    }
    (color, t, count)
}

/// Renders the splats of `proj` with `opacity` (in `[0, 1]`) and `colors` over `background`,
/// through the lists of `tiles` (see the [module docs](self)).
///
/// Errors: arrays whose lengths differ from the projection's ([`OpsError::Shape`]).
pub fn rasterize(
    proj: &Projection,
    tiles: &TileLists,
    opacity: &[f64],
    colors: &[[f64; 3]],
    background: [f64; 3],
) -> Result<Raster, OpsError> {
    check_inputs(proj, tiles, opacity, colors)?;
    let packed = pack(proj, opacity);
    let per_tile: Vec<Vec<([f64; 3], f64, u32)>> = (0..tiles.tiles())
        .into_par_iter()
        .map(|t| {
            let local = gather(&packed, tiles.tile(t));
            let (rows, cols) = tile_pixels(tiles, t);
            let mut out = Vec::with_capacity(TILE * TILE);
            for row in rows {
                for col in cols.clone() {
                    out.push(pixel(colors, background, &local, centre(row, col)));
                }
            }
            out
        })
        .collect();
    let pixels = tiles.width * tiles.height;
    let mut raster = Raster {
        color: vec![[0.0; 3]; pixels],
        transmittance: vec![0.0; pixels],
        count: vec![0; pixels],
    };
    for (t, out) in per_tile.into_iter().enumerate() {
        let (rows, cols) = tile_pixels(tiles, t);
        let mut values = out.into_iter();
        for row in rows {
            for col in cols.clone() {
                let p = row * tiles.width + col;
                if let Some((c, tr, k)) = values.next() {
                    (raster.color[p], raster.transmittance[p], raster.count[p]) = (c, tr, k);
                }
            }
        }
    }
    Ok(raster)
}
