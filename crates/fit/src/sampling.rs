//! Where a fit puts its samples: every `step` across the model's box, or only in the occupied
//! cells of an occupancy grid (its midpoint sampler).

use fogray_ops::rays::{Aabb, RayBatch};
use fogray_ops::sample::{Jitter, OccupancyConfig, OccupancyGrid, PackedSamples, Refresh, Spacing, Uniform};
use fogray_tape::Float;

use crate::error::FitError;

/// Samples `rays` every `step` across `bounds`, or keeps only the samples whose midpoints lie
/// in occupied cells of `occupancy` (its midpoint sampler: the march's pieces, less up to two
/// at each run of occupied cells, tested in vector lanes instead of a walk through every cell).
///
/// Errors: a step that is not finite and positive.
pub(crate) fn sample_rays<F: Float>(
    bounds: &Aabb,
    occupancy: Option<&OccupancyGrid>,
    rays: &RayBatch<F>,
    step: f64,
) -> Result<PackedSamples<F>, FitError> {
    let clip = bounds.clip(rays);
    Ok(match occupancy {
        None => Uniform::new(Spacing::Step(step))?.sample(rays, &clip)?,
        Some(g) => g.march_midpoints(rays, &clip, step, Jitter::None)?,
    })
}

/// When a fit refreshes its occupancy grid: from step 16, every 16 steps. Until the first
/// refresh every cell is occupied, and a step of the coarsest stage then samples the whole box
/// (several times the samples of a pruned step), so a warm-up as long as the occupancy grid's
/// default (64 steps) costs a minute's fit a good part of its budget. By step 16 Adam has
/// already raised the density where the views put matter, and on lego a fit first refreshed
/// there ends where one first refreshed at step 64 does, step for step.
pub(crate) const FIT_REFRESH: Refresh = Refresh { warmup: 16, every: 16 };

/// Cells per axis of a fit's occupancy grid at most: past it a cell spans several voxels, so
/// that its refresh (a density per cell) costs what a 128^3 grid's does however fine the
/// model.
pub(crate) const OCCUPANCY_CELLS_MAX: usize = 128;

/// An occupancy grid as a fit of `grid` nodes per axis over `bounds` keeps one: one cell per
/// voxel (up to [`OCCUPANCY_CELLS_MAX`] per axis), a cell occupied while a step of half the final voxel through it would stop at least
/// 1 % of the light (the final grid's half voxel sets the threshold, so it means the same at
/// every growth stage). Every cell is occupied until its first refresh, which
/// [`FIT_REFRESH`] times.
///
/// Errors: fewer than 2 nodes.
pub(crate) fn occupancy_grid(bounds: Aabb, grid: usize) -> Result<OccupancyGrid, FitError> {
    if grid < 2 {
        return Err(FitError::Setting {
            flag: "--grid",
            value: None,
            rule: "must be at least 2".into(),
        });
    }
    // The final stage's sample step (half its node spacing along the shortest side), as the
    // dense grid's: `1 / (grid - 1)` for [-1, 1]^3.
    let scene_box = crate::settings::SceneBox {
        min: bounds.min(),
        max: bounds.max(),
    };
    let final_step = scene_box.half_node_spacing(grid);
    Ok(OccupancyGrid::new(
        bounds,
        (grid - 1).min(OCCUPANCY_CELLS_MAX),
        OccupancyConfig::opacity(final_step, 0.01)?.with_refresh(FIT_REFRESH)?,
    )?)
}
