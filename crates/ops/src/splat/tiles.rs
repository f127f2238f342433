//! Binning: each visible splat is listed in every 16x16 tile its screen radius touches, and
//! each tile's list is in front-to-back order (depth, then splat index, so that equal depths
//! are ordered the same way every time).
//!
//! Rather than sorting the `M` (tile, depth) pairs, the visible splats are sorted once by
//! (depth, index), `V` keys with `V <= M`, and then dealt into their tiles by a counting sort
//! in that order: every tile's list comes out sorted, and the one comparison sort is over the
//! smaller set. The total `M` is counted before anything of its size is allocated, and a count
//! above the caller's limit is an error ([`OpsError::TooManyIntersections`]).

use rayon::prelude::*;

use super::project::{Projection, CHUNK};
use crate::error::{Op, OpsError};
use crate::limits::{available, Bytes, SPLAT_INTERSECTION_BYTES, SPLAT_PIXEL_BYTES};

/// Tile side, in pixels.
pub const TILE: usize = 16;

/// The default bound on the total length of the tiles' lists: about 1.3 GB of backward
/// buffers at [`limits::SPLAT_INTERSECTION_BYTES`](crate::limits::SPLAT_INTERSECTION_BYTES)
/// each.
pub const DEFAULT_MAX_INTERSECTIONS: u64 = 1 << 24;

/// The splats of each tile, front to back, packed: tile `t` (row-major over the tile grid)
/// owns `splats[offsets[t]..offsets[t + 1]]`. Made by [`bin`] only, so that the rasteriser can
/// trust its packing.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct TileLists {
    pub(crate) width: usize,
    pub(crate) height: usize,
    /// The number of splats binned (indices are below it).
    pub(crate) n: usize,
    pub(crate) tiles_x: usize,
    pub(crate) tiles_y: usize,
    /// `tiles_x * tiles_y + 1` offsets into `splats`, starting at 0, never decreasing.
    pub(crate) offsets: Vec<usize>,
    pub(crate) splats: Vec<u32>,
}

impl TileLists {
    /// The image size binned for, `(width, height)`.
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// The number of splats binned (listed or not).
    pub fn splat_count(&self) -> usize {
        self.n
    }

    /// Tiles per row and rows of tiles.
    pub fn grid(&self) -> (usize, usize) {
        (self.tiles_x, self.tiles_y)
    }

    /// The total length of the lists: the number of (splat, tile) pairs.
    pub fn intersections(&self) -> usize {
        self.splats.len()
    }

    /// The number of tiles.
    pub fn tiles(&self) -> usize {
        self.tiles_x * self.tiles_y
    }

    /// The splats of tile `t`, front to back.
    pub fn tile(&self, t: usize) -> &[u32] {
        &self.splats[self.offsets[t]..self.offsets[t + 1]]
    }
}

/// The tiles `[x0, x1) x [y0, y1)` that a splat at `mean` with `radius` touches, clipped to the
/// grid (empty for radius 0 or a splat off the image).
#[inline]
fn rect(mean: [f64; 2], radius: u32, tiles_x: usize, tiles_y: usize) -> [usize; 4] {
    if radius == 0 {
        return [0; 4];
    }
    let (r, t) = (f64::from(radius), TILE as f64);
    // In f64 and clamped before the conversion: a mean far off the image cannot overflow.
    let lo = |c: f64, n: usize| ((c - r) / t).floor().clamp(0.0, n as f64) as usize;
    let hi = |c: f64, n: usize| ((c + r) / t).ceil().clamp(0.0, n as f64) as usize;
    let (x0, x1) = (lo(mean[0], tiles_x), hi(mean[0], tiles_x));
    let (y0, y1) = (lo(mean[1], tiles_y), hi(mean[1], tiles_y));
    if x0 >= x1 || y0 >= y1 {
        return [0; 4];
    }
    [x0, x1, y0, y1]
}

fn area(r: &[usize; 4]) -> u64 {
    ((r[1] - r[0]) * (r[3] - r[2])) as u64
}

/// Bins the splats of `proj` into the tiles of a `width x height` image (see the
/// [module docs](self)).
///
/// Errors: a projection whose arrays differ in length, more splats than a `u32` indexes
/// ([`OpsError::Shape`]); an empty image ([`OpsError::EmptyImage`]), or one whose per-pixel
/// buffers would not fit in the available memory ([`OpsError::Config`]); more (splat, tile)
/// pairs than `max_intersections`, or than the available memory holds at
/// [`SPLAT_INTERSECTION_BYTES`] each ([`OpsError::TooManyIntersections`]).
pub fn bin(proj: &Projection, width: usize, height: usize, max_intersections: u64) -> Result<TileLists, OpsError> {
    let n = proj.check_lengths()?;
    if width == 0 || height == 0 {
        return Err(OpsError::EmptyImage {
            op: Op::Splat,
            width,
            height,
        });
    }
    if u32::try_from(n).is_err() {
        return Err(OpsError::shape(Op::Splat, "splats", "at most 2^32 - 1", n.to_string()));
    }
    // The raster and its backward allocate per pixel: an image the machine cannot hold is
    // refused here, before any of it is allocated.
    let image = Bytes::product(&[width as u64, height as u64, SPLAT_PIXEL_BYTES]);
    if image > available() {
        return Err(OpsError::config(
            Op::Splat,
            "image size (pixels)",
            width as f64 * height as f64,
            "needs more memory than is available",
        ));
    }
    let (tiles_x, tiles_y) = (width.div_ceil(TILE), height.div_ceil(TILE));
    let mut rects = vec![[0usize; 4]; n];
    rects.par_chunks_mut(CHUNK).enumerate().for_each(|(chunk, rects)| {
        for (k, r) in rects.iter_mut().enumerate() {
            let i = chunk * CHUNK + k;
            *r = rect(proj.mean2d[i], proj.radius[i], tiles_x, tiles_y);
        }
    });
    let count = rects.par_iter().map(area).reduce(|| 0, u64::saturating_add);
    // The caller's bound, and the machine's memory at what each pair costs.
    let limit = max_intersections.min(available().0 / SPLAT_INTERSECTION_BYTES);
    if count > limit {
        return Err(OpsError::TooManyIntersections {
            op: Op::Splat,
            count,
            limit,
        });
    }
    // Front to back: depth (positive, so its bits order as the values do), then index. The
    // keys are distinct, so an unstable sort is deterministic.
    let mut order: Vec<(u64, u32)> = (0..n)
        .filter(|&i| area(&rects[i]) > 0)
        .map(|i| (proj.depth[i].to_bits(), i as u32))
        .collect();
    order.par_sort_unstable();

    let tiles = tiles_x * tiles_y;
    let mut offsets = vec![0usize; tiles + 1];
    for &(_, i) in &order {
        let [x0, x1, y0, y1] = rects[i as usize];
        for ty in y0..y1 {
            for c in &mut offsets[ty * tiles_x + x0 + 1..ty * tiles_x + x1 + 1] {
                *c += 1;
            }
        }
    }
    for t in 0..tiles {
        offsets[t + 1] += offsets[t];
    }
    let mut cursor = offsets[..tiles].to_vec();
    let mut splats = vec![0u32; offsets[tiles]];
    for &(_, i) in &order {
        let [x0, x1, y0, y1] = rects[i as usize];
        for ty in y0..y1 {
            for c in &mut cursor[ty * tiles_x + x0..ty * tiles_x + x1] {
                splats[*c] = i;
                *c += 1;
            }
        }
    }
    Ok(TileLists {
        width,
        height,
        n,
        tiles_x,
        tiles_y,
        offsets,
        splats,
    })
}
