//! How a trainer fits ([`TrainerSettings`], [`OccupancySettings`]), what it trains on
//! ([`TrainingRays`]), and the checks of both before anything is uploaded.

use crate::buffers::check_len;
use crate::error::CudaError;
use crate::sh::MAX_SH_DEGREE;

/// An occupancy grid over the box that the samples skip where it is empty, as `fogray fit`'s:
/// each cell keeps a density estimate, `max(estimate * decay, fresh)` at every refresh, where
/// `fresh` is the larger density at the cell's centre and at a random point in it; a cell is
/// occupied while its estimate exceeds `density`. Every cell is occupied until the first
/// refresh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OccupancySettings {
    /// Cells per axis.
    pub cells: usize,
    /// The density above which a cell is occupied.
    pub density: f64,
    /// Refresh every this many steps (the first after as many).
    pub every: u64,
    /// The estimate's decay per refresh, in [0, 1].
    pub decay: f64,
}

/// The training pixels, each `[R, ...]` in the same order.
#[derive(Debug, Clone, Copy)]
pub struct TrainingRays<'a> {
    /// Ray origins `[R, 3]`.
    pub origins: &'a [f32],
    /// Unit ray directions `[R, 3]`.
    pub directions: &'a [f32],
    /// The pixels' colours `[R, 3]`, composited over [`TrainerSettings::background`] where
    /// their picture had alpha.
    pub colors: &'a [f32],
    /// The pixels' opacities `[R]` (1 for a picture without alpha), if any picture had alpha:
    /// with [`TrainerSettings::random_background`], each training ray is composited over a
    /// random colour and its target recomposited over the same colour.
    pub alpha: Option<&'a [f32]>,
}

/// How a [`DenseGridTrainer`](crate::DenseGridTrainer) fits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrainerSettings {
    /// The box the grid spans: (min, max corners).
    pub scene_box: ([f64; 3], [f64; 3]),
    /// Nodes per axis of the grid.
    pub nodes: usize,
    /// Samples per ray, spread evenly over its chord through the box.
    pub samples_per_ray: usize,
    /// Rays per step.
    pub batch: usize,
    /// The density's shift: raw 0 is density `softplus(shift)`.
    pub shift: f64,
    /// Colour through spherical harmonics of this degree (1 to 3: `1 + 3 (degree + 1)^2`
    /// values a node), or 0: one colour from every direction (4 values a node).
    pub sh_degree: usize,
    /// The background colour behind every ray (and behind the targets' transparent pixels).
    pub background: [f32; 3],
    /// With the rays' alpha given: train each ray over a uniform random colour of its own,
    /// so that the grid cannot paint the background into the scene.
    pub random_background: bool,
    /// The weight of mip-NeRF 360's distortion loss (the mean over the batch's rays of
    /// `sum_ij w_i w_j |t_i - t_j| + (1/3) sum_i w_i^2 delta_i`, distances along the ray) in the
    /// objective; 0: none.
    pub distortion: f64,
    /// Skip the samples in empty cells of an occupancy grid (training and renders), or keep
    /// every sample.
    pub occupancy: Option<OccupancySettings>,
    /// Seed of the batches.
    pub seed: u64,
}

/// Checks `data`'s shapes and `settings`' ranges, and gives the number of training rays.
///
/// Errors: the shape and settings errors of
/// [`DenseGridTrainer::new`](crate::DenseGridTrainer::new).
pub(super) fn check(settings: &TrainerSettings, data: &TrainingRays<'_>) -> Result<usize, CudaError> {
    let rays = data.origins.len() / 3;
    if rays == 0 || data.origins.len() != 3 * rays {
        return Err(CudaError::Shape {
            what: "ray origins ([R, 3], R >= 1)",
            expected: 3 * rays.max(1),
            got: data.origins.len(),
        });
    }
    for (what, v) in [
        ("ray directions ([R, 3])", data.directions),
        ("colours ([R, 3])", data.colors),
    ] {
        if v.len() != 3 * rays {
            return Err(CudaError::Shape {
                what,
                expected: 3 * rays,
                got: v.len(),
            });
        }
    }
    if let Some(a) = data.alpha {
        check_len("opacities ([R])", rays, a.len())?;
    }
    if settings.batch == 0 || settings.samples_per_ray == 0 {
        return Err(CudaError::InvalidSettings(format!(
            "{} rays a step and {} samples a ray (each at least 1)",
            settings.batch, settings.samples_per_ray
        )));
    }
    if settings.sh_degree > MAX_SH_DEGREE {
        return Err(CudaError::InvalidSettings(format!(
            "spherical harmonics of degree {} (at most {MAX_SH_DEGREE})",
            settings.sh_degree
        )));
    }
    if let Some((channel, &v)) = settings.background.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(CudaError::InvalidBackground {
            channel,
            value: f64::from(v),
        });
    }
    if !(settings.distortion.is_finite() && settings.distortion >= 0.0) {
        return Err(CudaError::InvalidSettings(format!(
            "distortion weight {} (finite, at least 0)",
            settings.distortion
        )));
    }
    if let Some(o) = settings.occupancy {
        if o.cells == 0 || o.every == 0 || !(o.density.is_finite() && (0.0..=1.0).contains(&o.decay)) {
            return Err(CudaError::InvalidSettings(format!(
                "occupancy {o:?}: at least one cell and one step between refreshes, a finite density, a decay in [0, 1]"
            )));
        }
    }
    Ok(rays)
}
