//! The occupancy grid: a coarse bitfield over a box marking the cells where the scene may
//! have matter, kept from a decaying per-cell density estimate, so that the marcher
//! (`OccupancyGrid::march`) skips empty space.

use std::fmt::Display;

use fogray_tape::Float;
use ndarray::{Array1, Array2, Array3, ArrayView2, ArrayView3};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rayon::prelude::*;

use super::occupancy_config::{config_error, CellPoints, OccupancyConfig};
use crate::error::{At, Op, OpsError};
use crate::rays::Aabb;

/// The caller's density function failed (`problem` is its error) or returned something
/// unusable.
fn density_error(problem: String) -> OpsError {
    OpsError::Density {
        op: Op::Occupancy,
        problem,
    }
}

/// An axis of the grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GridAxis {
    /// x (the first cell index).
    X,
    /// y (the second).
    Y,
    /// z (the third).
    Z,
}

/// A plane of cells, for plotting: indexed by the two other axes in order (a slice across
/// y is `[ix, iz]`).
#[derive(Debug, Clone, PartialEq)]
pub struct OccupancySlice {
    /// Whether each cell is occupied.
    pub occupied: Array2<bool>,
    /// Each cell's density estimate.
    pub estimate: Array2<f32>,
}

/// What an [`OccupancyGrid`] has learnt, to be saved and given back to
/// [`OccupancyGrid::restore`]: each cell's density estimate and whether it is occupied (which
/// the estimate alone does not say before the first update, when every cell is occupied).
#[derive(Debug, Clone, PartialEq)]
pub struct OccupancyState {
    /// Each cell's density estimate `[r, r, r]`, indexed `[ix, iy, iz]`: finite, at least 0.
    pub estimate: Array3<f32>,
    /// Whether each cell is occupied `[r, r, r]`.
    pub occupied: Array3<bool>,
}

/// `r^3` cells over a box, cell `(ix, iy, iz)` covering
/// `min + (ix, iy, iz) * size .. min + (ix + 1, iy + 1, iz + 1) * size`, stored at
/// `(ix * r + iy) * r + iz`. Every cell starts occupied (nothing is known yet) with estimate 0.
#[derive(Debug, Clone, PartialEq)]
pub struct OccupancyGrid {
    pub(crate) bounds: Aabb,
    pub(crate) resolution: usize,
    pub(crate) cell: [f64; 3],
    estimate: Vec<f32>,
    bits: Vec<u64>,
    config: OccupancyConfig,
    known: Option<KnownCells>,
}

/// Cells whose density the caller knows without evaluating it: the same `density` at every
/// point of each cell marked (a sparse model's pruned space, which reads one constant). An
/// update takes that value for them and calls the density function only for the others, so
/// that a refresh costs what the unknown cells do; the result is the same, bit for bit, as
/// evaluating every cell.
#[derive(Debug, Clone, PartialEq)]
pub struct KnownCells {
    /// One entry per cell, in the grid's linear order (`[ix, iy, iz]`, z fastest): true where
    /// the density is known.
    pub cells: Vec<bool>,
    /// The density at every point of the marked cells: finite, at least 0.
    pub density: f64,
}

/// Cells per call of the density function (and per parallel task) in an update.
const CHUNK: usize = 4096;

/// The bits of `cells` cells, all occupied (no bit past the last cell, as after an update
/// or a restore).
fn every_cell(cells: usize) -> Vec<u64> {
    let mut bits = vec![u64::MAX; cells.div_ceil(64)];
    if cells % 64 != 0 {
        bits[cells / 64] = (1u64 << (cells % 64)) - 1;
    }
    bits
}

impl OccupancyGrid {
    /// `resolution^3` cells over `bounds`. Errors: `resolution` outside `1..=1024`.
    pub fn new(bounds: Aabb, resolution: usize, config: OccupancyConfig) -> Result<Self, OpsError> {
        if !(1..=1024).contains(&resolution) {
            return Err(config_error("resolution", resolution as f64, "must be in 1..=1024"));
        }
        let cells = resolution.pow(3);
        let (lo, hi) = (bounds.min(), bounds.max());
        Ok(OccupancyGrid {
            bounds,
            resolution,
            cell: std::array::from_fn(|a| (hi[a] - lo[a]) / resolution as f64),
            estimate: vec![0.0; cells],
            bits: every_cell(cells),
            config,
            known: None,
        })
    }

    /// Sets the cells whose density is known (or none: every cell evaluated), used by every
    /// update from now on.
    ///
    /// Errors (nothing changed): a mask that is not one entry per cell, a density that is
    /// negative or not finite.
    pub fn set_known_cells(&mut self, known: Option<KnownCells>) -> Result<(), OpsError> {
        if let Some(k) = &known {
            if k.cells.len() != self.estimate.len() {
                return Err(config_error(
                    "known cells",
                    k.cells.len() as f64,
                    "must be one entry per cell",
                ));
            }
            if !(k.density.is_finite() && k.density >= 0.0) {
                return Err(config_error("known density", k.density, "must be finite and >= 0"));
            }
        }
        self.known = known;
        Ok(())
    }

    /// The cells whose density is known, if set.
    pub fn known_cells(&self) -> Option<&KnownCells> {
        self.known.as_ref()
    }

    /// Cells per axis.
    pub fn resolution(&self) -> usize {
        self.resolution
    }

    /// The box.
    pub fn bounds(&self) -> Aabb {
        self.bounds
    }

    /// The configuration.
    pub fn config(&self) -> OccupancyConfig {
        self.config
    }

    fn index(&self, c: [usize; 3]) -> usize {
        (c[0] * self.resolution + c[1]) * self.resolution + c[2]
    }

    /// Whether cell `c` is occupied (false for a cell outside the grid).
    pub fn is_occupied(&self, c: [usize; 3]) -> bool {
        if c.iter().any(|&i| i >= self.resolution) {
            return false;
        }
        self.is_occupied_linear(self.index(c))
    }

    /// The occupancy bits, cell `i` (linear index, x slowest, z fastest) at bit `i % 64` of
    /// word `i / 64`; no bit set past the last cell.
    pub(crate) fn bits(&self) -> &[u64] {
        &self.bits
    }

    /// Whether the cell at linear index `i` is occupied. Panics if `i >= r^3`.
    pub(crate) fn is_occupied_linear(&self, i: usize) -> bool {
        self.bits[i / 64] >> (i % 64) & 1 == 1
    }

    /// The cell holding point `p` (points on the upper faces belong to the last cells), or
    /// `None` outside the box or for a non-finite point.
    pub fn cell_of(&self, p: [f64; 3]) -> Option<[usize; 3]> {
        if !self.bounds.contains(p) {
            return None;
        }
        let lo = self.bounds.min();
        // Inside the box the quotient is at least 0 (or -0.0), where a saturating cast is
        // `floor`: without the call, which x86-64's baseline makes to libm and which a march
        // pays at every piece it asks about.
        Some(std::array::from_fn(|a| {
            (((p[a] - lo[a]) / self.cell[a]) as usize).min(self.resolution - 1)
        }))
    }

    /// Whether point `p` lies in an occupied cell (false outside the box).
    pub fn is_occupied_at(&self, p: [f64; 3]) -> bool {
        self.cell_of(p).is_some_and(|c| self.is_occupied(c))
    }

    /// Marks every cell occupied, as a new grid is, keeping the estimates (the next update
    /// decides again from them).
    pub fn occupy_all(&mut self) {
        self.bits = every_cell(self.estimate.len());
    }

    /// The share of occupied cells, in `[0, 1]`.
    pub fn occupied_fraction(&self) -> f64 {
        // No bit past the last cell is ever set, so the words' counts are the cells'.
        let ones: u64 = self.bits.iter().map(|w| u64::from(w.count_ones())).sum();
        ones as f64 / self.estimate.len() as f64
    }

    /// The density estimates `[r, r, r]`, indexed `[ix, iy, iz]`.
    pub fn estimate(&self) -> ArrayView3<'_, f32> {
        let r = self.resolution;
        ArrayView3::from_shape((r, r, r), &self.estimate).expect("r^3 estimates")
    }

    /// The grid's state (estimates and occupied cells), for [`OccupancyGrid::restore`].
    pub fn state(&self) -> OccupancyState {
        let r = self.resolution;
        OccupancyState {
            estimate: self.estimate().to_owned(),
            occupied: Array3::from_shape_fn((r, r, r), |(x, y, z)| self.is_occupied([x, y, z])),
        }
    }

    /// Replaces the estimates and occupied cells with `state` (from [`OccupancyGrid::state`]
    /// of a grid of the same resolution), so that a saved grid marches and updates exactly as
    /// the one it was taken from.
    ///
    /// Errors (the grid is unchanged then): either array not `[r, r, r]`, an estimate negative
    /// or not finite (named by linear cell index).
    pub fn restore(&mut self, state: &OccupancyState) -> Result<(), OpsError> {
        let r = self.resolution;
        for (what, shape) in [
            ("occupancy estimate", state.estimate.shape()),
            ("occupied cells", state.occupied.shape()),
        ] {
            if shape != [r, r, r] {
                return Err(OpsError::Shape {
                    op: Op::Occupancy,
                    what,
                    expected: format!("[{r}, {r}, {r}]"),
                    got: format!("{shape:?}"),
                });
            }
        }
        if let Some((i, &e)) = state
            .estimate
            .iter()
            .enumerate()
            .find(|(_, e)| !(e.is_finite() && **e >= 0.0))
        {
            return Err(OpsError::domain(
                Op::Occupancy,
                At::Cell(i),
                "occupancy estimate",
                f64::from(e),
                "must be finite and non-negative",
            ));
        }
        // Standard layout iteration is the grid's own order, (ix * r + iy) * r + iz.
        self.estimate = state.estimate.iter().copied().collect();
        self.bits.iter_mut().for_each(|w| *w = 0);
        for (i, _) in state.occupied.iter().enumerate().filter(|(_, &o)| o) {
            self.bits[i / 64] |= 1 << (i % 64);
        }
        Ok(())
    }

    /// The plane of cells with index `index` along `axis`. Errors: `index >= resolution`.
    pub fn slice(&self, axis: GridAxis, index: usize) -> Result<OccupancySlice, OpsError> {
        let r = self.resolution;
        if index >= r {
            return Err(OpsError::Shape {
                op: Op::Occupancy,
                what: "slice index",
                expected: format!("below the resolution {r}"),
                got: format!("{index}"),
            });
        }
        let cell = |i: usize, j: usize| match axis {
            GridAxis::X => [index, i, j],
            GridAxis::Y => [i, index, j],
            GridAxis::Z => [i, j, index],
        };
        Ok(OccupancySlice {
            occupied: Array2::from_shape_fn((r, r), |(i, j)| self.is_occupied(cell(i, j))),
            estimate: Array2::from_shape_fn((r, r), |(i, j)| self.estimate[self.index(cell(i, j))]),
        })
    }

    /// The centre or a random point of cell `i` (linear index).
    fn point(&self, i: usize, random: Option<&mut StdRng>) -> [f64; 3] {
        let r = self.resolution;
        let c = [i / (r * r), i / r % r, i % r];
        let lo = self.bounds.min();
        let mut frac = [0.5; 3];
        if let Some(rng) = random {
            frac = std::array::from_fn(|_| rng.gen::<f64>());
        }
        std::array::from_fn(|a| (c[a] as f64 + frac[a]).mul_add(self.cell[a], lo[a]))
    }

    /// The new density of each cell of `cells`: the largest the caller's function gives at
    /// the cell's points.
    fn densities<F, D, E>(
        &self,
        cells: std::ops::Range<usize>,
        density: &D,
        points: CellPoints,
    ) -> Result<Vec<f64>, OpsError>
    where
        F: Float,
        D: Fn(ArrayView2<'_, F>) -> Result<Array1<F>, E>,
        E: Display,
    {
        let (centre, seed) = match points {
            CellPoints::Centre => (true, None),
            CellPoints::Random { seed } => (false, Some(seed)),
            CellPoints::CentreAndRandom { seed } => (true, Some(seed)),
        };
        // One generator per chunk, seeded by the chunk's first cell: the same points
        // whatever the number of threads.
        let mut rng = seed.map(|s| StdRng::seed_from_u64(s ^ (cells.start as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)));
        let per_cell = usize::from(centre) + usize::from(seed.is_some());
        let known = |i: usize| self.known.as_ref().is_some_and(|k| k.cells[i]);
        let mut xyz = Vec::with_capacity(3 * per_cell * cells.len());
        for i in cells.clone() {
            if centre && !known(i) {
                xyz.extend(self.point(i, None).map(F::lit));
            }
            if let Some(rng) = rng.as_mut() {
                // A known cell's point is drawn too, so that the others' points do not depend
                // on which cells are known.
                let p = self.point(i, Some(rng));
                if !known(i) {
                    xyz.extend(p.map(F::lit));
                }
            }
        }
        let m = xyz.len() / 3;
        let sigma: Vec<f64> = if m == 0 {
            Vec::new()
        } else {
            let xyz = Array2::from_shape_vec((m, 3), xyz).expect("three coordinates per point");
            let sigma = density(xyz.view()).map_err(|e| density_error(e.to_string()))?;
            if sigma.len() != m {
                return Err(density_error(format!(
                    "returned {} densities for {m} points",
                    sigma.len()
                )));
            }
            sigma.iter().map(|s| s.as_f64()).collect()
        };
        let mut out = Vec::with_capacity(cells.len());
        let mut next = 0;
        for i in cells {
            if let Some(k) = self.known.as_ref().filter(|k| k.cells[i]) {
                out.push(k.density);
                continue;
            }
            let mut best = 0.0f64;
            next += per_cell;
            for &s in &sigma[next - per_cell..next] {
                if !(s.is_finite() && s >= 0.0) {
                    return Err(OpsError::domain(
                        Op::Occupancy,
                        At::Cell(i),
                        "density at a point",
                        s,
                        "must be finite and non-negative",
                    ));
                }
                best = best.max(s);
            }
            out.push(best);
        }
        Ok(out)
    }

    /// The refresh policy of a training loop (nerfacc's `update_every_n_steps`): after step
    /// `step` (counted from 1), calls [`OccupancyGrid::update`] with `density` at cell points
    /// `points` if the config's [`Refresh`](super::Refresh) says the step is due. Returns
    /// whether it refreshed.
    ///
    /// Errors: as [`OccupancyGrid::update`] (the grid is unchanged then).
    pub fn update_every_n_steps<F, D, E>(
        &mut self,
        step: usize,
        density: D,
        points: CellPoints,
    ) -> Result<bool, OpsError>
    where
        F: Float,
        D: Fn(ArrayView2<'_, F>) -> Result<Array1<F>, E> + Sync,
        E: Display,
    {
        if !self.config.refresh().is_due(step) {
            return Ok(false);
        }
        self.update(density, points)?;
        Ok(true)
    }

    /// Evaluates `density` (positions `[m, 3]` to densities `[m]`, e.g. a closure over a
    /// density grid) at `points` of every cell, sets `estimate = max(estimate * decay, new)`
    /// and marks the cells above the threshold occupied. Calls `density` on chunks of cells
    /// in parallel; the result does not depend on the number of threads.
    ///
    /// Errors (the grid is unchanged then): `density` failing, returning the wrong number of
    /// values, or a value that is negative or not finite (named by cell index).
    pub fn update<F, D, E>(&mut self, density: D, points: CellPoints) -> Result<(), OpsError>
    where
        F: Float,
        D: Fn(ArrayView2<'_, F>) -> Result<Array1<F>, E> + Sync,
        E: Display,
    {
        let cells = self.estimate.len();
        let chunks: Vec<Vec<f64>> = (0..cells.div_ceil(CHUNK))
            .into_par_iter()
            .map(|c| self.densities(c * CHUNK..((c + 1) * CHUNK).min(cells), &density, points))
            .collect::<Result<_, _>>()?;
        let decay = self.config.decay() as f32;
        let threshold = self.config.density_threshold();
        for (est, new) in self.estimate.iter_mut().zip(chunks.into_iter().flatten()) {
            // Densities beyond f32 saturate rather than become infinite.
            *est = (*est * decay).max(new.min(f64::from(f32::MAX)) as f32);
        }
        self.bits.iter_mut().for_each(|w| *w = 0);
        for (i, &est) in self.estimate.iter().enumerate() {
            if f64::from(est) > threshold {
                self.bits[i / 64] |= 1 << (i % 64);
            }
        }
        Ok(())
    }
}
