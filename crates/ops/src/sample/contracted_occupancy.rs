//! Occupancy in contracted space: the density an [`OccupancyGrid`] over the contracted cube
//! judges is scaled, cell by cell, by the world length a contracted step can stand for there.
//!
//! The grid's opacity criterion `sigma * step > -ln(1 - opacity)` assumes one step is one
//! length wherever it is taken. A contracted step `s` is `s r` of world inside the inner
//! region but up to about `s r m^2` at `m` inner radii out, so a density that is faint per
//! world unit can make every far sample opaque: judged with the inner step, the shell's
//! cells holding the sky or a far wall would be pruned and the light they stop lost. Feeding
//! the grid `sigma * stretch(cell)` instead (the optical depth per unit of contracted
//! length, at most, in that cell) keeps the criterion's meaning, "one step of the sampler
//! here is more than `opacity` opaque", with the grid's own
//! [`OccupancyConfig::opacity`](super::OccupancyConfig::opacity)`(sampler.step(), opacity)`.

use std::fmt::Display;

use fogray_tape::Float;
use ndarray::{Array1, ArrayView2};

use super::contracted::{check_cube, ContractedSampler};
use super::occupancy::OccupancyGrid;
use crate::error::OpsError;
use crate::space::{Contraction, CONTRACTED_HALF_WIDTH};

/// The per-cell stretch of an [`OccupancyGrid`] over the contracted cube, and the density
/// scaled by it for the grid's updates.
///
/// ```
/// use fogray_ops::sample::{CellPoints, ContractedOccupancy, ContractedSampler, OccupancyConfig, OccupancyGrid};
/// use fogray_ops::space::{Contraction, InnerRegion};
/// use ndarray::{Array1, ArrayView2};
///
/// let space = Contraction::new(InnerRegion::new([0.0; 3], 1.0)?)?;
/// let sampler = ContractedSampler::new(space, 4.0 / 64.0)?;
/// let config = OccupancyConfig::opacity(sampler.step(), 0.01)?;
/// let mut grid = OccupancyGrid::new(Contraction::cube(), 16, config)?;
/// let scale = ContractedOccupancy::new(&sampler, &grid)?;
/// // A thin haze everywhere: pruned inside, kept far out where a step is long.
/// let haze = |p: ArrayView2<'_, f64>| Ok::<_, std::convert::Infallible>(Array1::from_elem(p.nrows(), 0.05));
/// grid.update(scale.optical_density(haze), CellPoints::Centre)?;
/// assert!(!grid.is_occupied([8, 8, 8]) && grid.is_occupied([15, 8, 8]));
/// # Ok::<(), fogray_ops::OpsError>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContractedOccupancy {
    contraction: Contraction,
    resolution: usize,
    far_gap: f64,
}

impl ContractedOccupancy {
    /// The stretch of `grid`'s cells for `sampler`'s contraction (whose far gap caps the
    /// outermost cells: no piece reaches past it).
    /// Errors: `grid`'s box is not [`Contraction::cube`].
    pub fn new(sampler: &ContractedSampler, grid: &OccupancyGrid) -> Result<Self, OpsError> {
        check_cube(grid)?;
        Ok(ContractedOccupancy {
            contraction: *sampler.contraction(),
            resolution: grid.resolution(),
            far_gap: sampler.far_gap(),
        })
    }

    fn cell_size(&self) -> f64 {
        2.0 * CONTRACTED_HALF_WIDTH / self.resolution as f64
    }

    /// The most world length one unit of contracted length stands for in cell `cell`
    /// (indices clamped into the grid): [`Contraction::max_stretch`] at the cell's largest
    /// contracted L-infinity norm, capped at `2 - far_gap`. `r` in the cells of the inner
    /// region.
    pub fn cell_stretch(&self, cell: [usize; 3]) -> f64 {
        let h = self.cell_size();
        let norm = (0..3)
            .map(|a| {
                let lo = -CONTRACTED_HALF_WIDTH + cell[a].min(self.resolution - 1) as f64 * h;
                lo.abs().max((lo + h).abs())
            })
            .fold(0.0, f64::max);
        self.contraction
            .max_stretch(norm.min(CONTRACTED_HALF_WIDTH - self.far_gap))
    }

    /// [`cell_stretch`](Self::cell_stretch) of the cell holding contracted point `y` (a
    /// point outside the cube is given its nearest cell).
    pub fn stretch_at(&self, y: [f64; 3]) -> f64 {
        let h = self.cell_size();
        let cell = y.map(|v| {
            let i = ((v + CONTRACTED_HALF_WIDTH) / h).floor();
            if i > 0.0 {
                i as usize
            } else {
                0
            }
        });
        self.cell_stretch(cell)
    }

    /// `density` (contracted positions `[m, 3]` to densities per world unit `[m]`, the
    /// function an update of a plain grid takes) times each position's cell stretch: the
    /// function to give [`OccupancyGrid::update`] or
    /// [`OccupancyGrid::update_every_n_steps`] with a config of
    /// [`OccupancyConfig::opacity`](super::OccupancyConfig::opacity)`(sampler.step(), ..)`.
    /// A result of the wrong length is passed on unscaled, for the grid to report.
    pub fn optical_density<'a, F, D, E>(
        &'a self,
        density: D,
    ) -> impl Fn(ArrayView2<'_, F>) -> Result<Array1<F>, E> + Sync + 'a
    where
        F: Float,
        D: Fn(ArrayView2<'_, F>) -> Result<Array1<F>, E> + Sync + 'a,
        E: Display,
    {
        move |points: ArrayView2<'_, F>| {
            let mut sigma = density(points)?;
            if sigma.len() == points.nrows() && points.ncols() == 3 {
                for (s, p) in sigma.iter_mut().zip(points.rows()) {
                    let stretch = self.stretch_at([p[0].as_f64(), p[1].as_f64(), p[2].as_f64()]);
                    *s = F::lit(s.as_f64() * stretch);
                }
            }
            Ok(sigma)
        }
    }
}
