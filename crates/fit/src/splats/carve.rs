//! Where splats start when the training pictures have alpha: inside the scene's visual hull.
//! A point that some training view sees over its background (alpha below one half at the
//! pixel it falls in) is empty space; the points no view rules out hold the object, and each
//! takes the mean colour of the pixels it falls in. What COLMAP's points are to a capture,
//! the alpha of a synthetic scene's pictures gives for the cost of projecting candidates.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha12Rng;
use rayon::prelude::*;

use crate::dataset::Dataset;
use crate::error::FitError;

/// Opacity below which a picture's pixel shows its background.
pub(crate) const EMPTY_ALPHA: f64 = 0.5;

/// Points of the visual hull and their colours.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct HullPoints {
    /// Positions (world frame).
    pub points: Vec<[f64; 3]>,
    /// The mean colour of the pixels each point falls in over the views that see it.
    pub colors: Vec<[f64; 3]>,
}

/// Up to `keep` points of `data`'s visual hull inside `bounds` (`[min, max]` corners): of
/// `candidates` points drawn uniformly from `seed`, those no training view sees over its
/// background, in draw order. `None` when a training view has no alpha (nothing to carve
/// with) or no candidate survives.
///
/// Errors: an empty or non-finite box ([`FitError::Config`]).
pub(crate) fn visual_hull(
    data: &Dataset,
    bounds: [[f64; 3]; 2],
    candidates: usize,
    keep: usize,
    seed: u64,
) -> Result<Option<HullPoints>, FitError> {
    let [lo, hi] = bounds;
    if (0..3).any(|a| !(lo[a].is_finite() && hi[a].is_finite() && lo[a] < hi[a])) {
        return Err(FitError::Config(format!(
            "the carving box {bounds:?} is empty or not finite"
        )));
    }
    if data.train.is_empty() || data.train.iter().any(|v| v.alpha.is_none()) {
        return Ok(None);
    }
    let mut rng = ChaCha12Rng::seed_from_u64(seed);
    let drawn: Vec<[f64; 3]> = (0..candidates)
        .map(|_| [0, 1, 2].map(|a| lo[a] + (hi[a] - lo[a]) * rng.gen::<f64>()))
        .collect();
    // Each candidate on its own: the same points for any thread count.
    let judged: Vec<Option<[f64; 3]>> = drawn.par_iter().map(|p| carve(data, *p)).collect();
    let mut hull = HullPoints {
        points: Vec::new(),
        colors: Vec::new(),
    };
    for (p, c) in drawn.iter().zip(judged) {
        if hull.points.len() == keep {
            break;
        }
        if let Some(c) = c {
            hull.points.push(*p);
            hull.colors.push(c);
        }
    }
    Ok((!hull.points.is_empty()).then_some(hull))
}

/// The mean colour of `p` over the views that see it inside their picture, or `None` if one
/// sees it over its background.
fn carve(data: &Dataset, p: [f64; 3]) -> Option<[f64; 3]> {
    let mut sum = [0.0; 3];
    let mut seen = 0usize;
    for view in &data.train {
        let alpha = view.alpha.as_ref()?;
        let Some([x, y]) = view.camera.project(p) else { continue };
        let [h, w] = view.size();
        if !(x >= 0.0 && y >= 0.0 && x < w as f64 && y < h as f64) {
            continue;
        }
        let (r, c) = (y as usize, x as usize);
        if alpha[[r, c]] < EMPTY_ALPHA {
            return None;
        }
        for (k, s) in sum.iter_mut().enumerate() {
            *s += view.image[[r, c, k]];
        }
        seen += 1;
    }
    (seen > 0).then(|| sum.map(|s| s / seen as f64))
}
