//! The sparse grid: a lattice of `N^3` nodes over the scene's box of which only those near
//! matter are stored ([`SparseGridField`]: packed rows of raw density and colour, an index
//! from each node to its row), shaded and composited as the dense grid is. It grows coarse to
//! fine like the dense grid, and each growth prunes: the new lattice keeps the nodes within
//! a few occupancy cells of an occupied one (the dilation lets surfaces still move),
//! so the parameters, their gradient, Adam's moments and a step's scatter grow with the nodes
//! kept, not with `N^3`; only the index (4 bytes a node) spans the lattice.
//!
//! A node that is not stored reads raw 0 (the fresh grid's thin fog, below the occupancy
//! threshold): the occupancy grid marks pruned space empty at its next refresh and the
//! samplers skip it. The first stage keeps every node. Its total-variation prior
//! ([`SparseTotalVariation`]) takes the pairs of neighbouring nodes that are both stored.
//!
//! ```
//! use fogray_fit::sparse::SparseGrid;
//! use fogray_fit::model::RadianceField;
//! use fogray_fit::settings::FitSettings;
//!
//! let model = SparseGrid::<f32>::fresh(&FitSettings::default(), 8)?;
//! assert_eq!(model.kept(), 8 * 8 * 8); // the first stage keeps every node
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use fogray_ops::grid::{NodeIndex, SparseGridField};
use fogray_ops::prior::{SparseTotalVariation, TotalVariation};
use fogray_ops::rays::{Aabb, RayBatch};
use fogray_ops::sample::{KnownCells, OccupancyGrid, PackedSamples};
use fogray_ops::space::Contraction;
use fogray_ops::{CompositeVars, GridBox};
use fogray_tape::params::{ParamId, Params};
use fogray_tape::{Float, Tape, TapeError, Var};
use ndarray::{Array1, Array2, ArrayView2};

use crate::environment::{add_environment, copy_environment};
use crate::error::FitError;
use crate::grid_model::GridModel;
use crate::model::{RadianceField, RenderWanted, TrainingBackground, TrainingLoss};
use crate::settings::{FitSettings, Method, SceneBox};
use crate::shading::Shading;
use crate::space::FieldSpace;

/// The name of the packed raw values `[kept, C]` in the parameter store and a checkpoint.
pub(crate) const DATA: &str = "sparse_grid";

/// The name of the kept-node mask `[N, N, N]` in a checkpoint.
pub(crate) const KEPT: &str = "sparse_grid.kept";

/// Occupancy cells around an occupied one whose nodes a growth keeps.
pub(crate) const DILATION: usize = 2;

/// A sparse grid of raw density and colour, its packed values kept in a [`Params`] store.
#[derive(Debug)]
pub struct SparseGrid<F: Float> {
    params: Params<F>,
    data: ParamId,
    field: SparseGridField,
    shading: Shading,
    prior: SparseTotalVariation,
    bounds: Aabb,
    nodes: usize,
    /// Weight of the distortion loss in the training objective (0: none).
    distortion: f64,
    /// The contraction its box is the image of, for a field of all of space.
    contraction: Option<Contraction>,
}

/// Where node `i` of `nodes` sits along axis `a` of `scene_box`.
fn node_position(scene_box: &SceneBox, nodes: usize, a: usize, i: usize) -> f64 {
    let (lo, hi) = (scene_box.min[a], scene_box.max[a]);
    lo + i as f64 * (hi - lo) / (nodes - 1) as f64
}

impl<F: Float> SparseGrid<F> {
    /// The same grid over the contracted cube of `contraction` (its box must be
    /// [`Contraction::cube`]); `None` for a field of its box.
    pub(crate) fn with_contraction(mut self, contraction: Option<Contraction>) -> Self {
        self.contraction = contraction;
        self
    }

    /// The same grid with the distortion loss (mip-NeRF 360's, over each training ray's
    /// sample weights) weighted by `weight` in its training objective.
    ///
    /// Errors: a weight that is negative or not finite.
    pub(crate) fn with_distortion(mut self, weight: f64) -> Result<Self, FitError> {
        if !(weight.is_finite() && weight >= 0.0) {
            return Err(FitError::Setting {
                flag: "--distortion",
                value: Some(weight.to_string()),
                rule: "must be finite and non-negative".into(),
            });
        }
        self.distortion = weight;
        Ok(self)
    }

    /// The grid over `scene_box` of the lattice nodes `index` keeps (`nodes^3`), every raw
    /// value 0, with `shading`; `smoothness` weighs its total-variation prior (0 for none).
    ///
    /// Errors: a bad box, a lattice that is not `nodes^3`, a smoothness that is negative or
    /// not finite.
    pub(crate) fn new(
        scene_box: SceneBox,
        nodes: usize,
        index: NodeIndex,
        shading: Shading,
        smoothness: f64,
    ) -> Result<Self, FitError> {
        scene_box.check()?;
        if index.nodes() != [nodes; 3] {
            return Err(FitError::Config(format!(
                "sparse grid: an index of {:?} nodes for a lattice of {nodes}^3",
                index.nodes()
            )));
        }
        let channels = shading.channels();
        let field = SparseGridField::new(GridBox::new(&scene_box.min, &scene_box.max)?, index, channels)?;
        let mut params = Params::new();
        let data = params.add(DATA, Array2::<F>::zeros((field.index().kept(), channels)))?;
        add_environment(&mut params, &shading)?;
        let prior = TotalVariation::new(smoothness).map_err(|source| FitError::SettingOp { flag: "--tv", source })?;
        Ok(SparseGrid {
            params,
            data,
            prior: SparseTotalVariation::new(prior, &field),
            field,
            shading,
            bounds: Aabb::new(scene_box.min, scene_box.max)?,
            nodes,
            distortion: 0.0,
            contraction: None,
        })
    }

    /// Nodes stored.
    pub fn kept(&self) -> usize {
        self.field.index().kept()
    }

    /// Which lattice nodes are stored.
    pub(crate) fn index(&self) -> &NodeIndex {
        self.field.index()
    }

    /// The box the lattice covers.
    pub(crate) fn scene_box(&self) -> SceneBox {
        SceneBox {
            min: self.bounds.min(),
            max: self.bounds.max(),
        }
    }

    /// The same field on a lattice of `nodes^3` keeping the nodes `keep` marks: each kept
    /// node takes this grid's raw value at its position.
    ///
    /// Errors: a mask that is not one entry per node.
    pub(crate) fn resampled_onto(&self, nodes: usize, keep: &[bool]) -> Result<Self, FitError> {
        let scene_box = self.scene_box();
        let mut grown = SparseGrid::<F>::new(
            scene_box,
            nodes,
            NodeIndex::from_mask([nodes; 3], keep)?,
            self.shading,
            self.prior.weight(),
        )?
        .with_distortion(self.distortion)?
        .with_contraction(self.contraction);
        let kept = grown.index().kept_nodes();
        let positions = Array2::from_shape_fn((kept.len(), 3), |(r, a)| {
            let l = kept[r];
            let i = [l / (nodes * nodes), l / nodes % nodes, l % nodes][a];
            F::lit(node_position(&scene_box, nodes, a, i))
        });
        let data = self.params.get(self.data)?;
        let raw = self.field.evaluate(&data, &positions.view().into_dyn())?;
        grown.params.get_mut(grown.data)?.assign(&raw);
        copy_environment(&self.params, &mut grown.params)?;
        Ok(grown)
    }

    /// The raw values `[m, C]` at `positions` (`[m, 3]`), looked up without a tape.
    fn raw_values(&self, positions: ArrayView2<'_, F>) -> Result<ndarray::ArrayD<F>, FitError> {
        let data = self.params.get(self.data)?;
        Ok(self.field.evaluate(&data, &positions.into_dyn())?)
    }
}

/// The cells of `occupancy` in which no lookup reaches a node that `index` keeps (its lattice
/// over `scene_box`), one entry per cell in the grid's order. A point in lattice cell `i` reads
/// nodes `i` and `i + 1` on each axis; each occupancy cell's range of nodes is widened by one
/// on each side against rounding, so a cell is only ever marked when it is surely empty.
pub(crate) fn cells_without_kept_nodes(
    index: &NodeIndex,
    scene_box: &SceneBox,
    occupancy: &OccupancyGrid,
) -> Vec<bool> {
    let n = index.nodes();
    let r = occupancy.resolution();
    let (lo, hi) = (occupancy.bounds().min(), occupancy.bounds().max());
    // Per axis, the lattice nodes a point of occupancy cell c can read: lo[c]..=hi[c].
    let ranges: [Vec<(usize, usize)>; 3] = std::array::from_fn(|a| {
        let spacing = (scene_box.max[a] - scene_box.min[a]) / (n[a] - 1) as f64;
        let cell = (hi[a] - lo[a]) / r as f64;
        (0..r)
            .map(|c| {
                let node = |x: f64| ((x - scene_box.min[a]) / spacing).floor();
                let first = node(lo[a] + c as f64 * cell) - 1.0;
                let last = node(lo[a] + (c + 1) as f64 * cell) + 2.0;
                let clamp = |v: f64| v.clamp(0.0, (n[a] - 1) as f64) as usize;
                (clamp(first), clamp(last))
            })
            .collect()
    });
    // A summed-volume table of the kept nodes: any kept node in a box in eight reads.
    let (nx, ny, nz) = (n[0] + 1, n[1] + 1, n[2] + 1);
    let mut table = vec![0u32; nx * ny * nz];
    let at = |x: usize, y: usize, z: usize| (x * ny + y) * nz + z;
    let mut kept = vec![false; n[0] * n[1] * n[2]];
    for l in index.kept_nodes() {
        kept[l] = true;
    }
    for x in 1..nx {
        for y in 1..ny {
            for z in 1..nz {
                let own = u32::from(kept[((x - 1) * n[1] + y - 1) * n[2] + z - 1]);
                table[at(x, y, z)] = own + table[at(x - 1, y, z)] + table[at(x, y - 1, z)] + table[at(x, y, z - 1)]
                    - table[at(x - 1, y - 1, z)]
                    - table[at(x - 1, y, z - 1)]
                    - table[at(x, y - 1, z - 1)]
                    + table[at(x - 1, y - 1, z - 1)];
            }
        }
    }
    (0..r * r * r)
        .map(|l| {
            let c = [l / (r * r), l / r % r, l % r];
            let (x0, x1) = ranges[0][c[0]];
            let (y0, y1) = ranges[1][c[1]];
            let (z0, z1) = ranges[2][c[2]];
            let (x1, y1, z1) = (x1 + 1, y1 + 1, z1 + 1);
            let count = table[at(x1, y1, z1)] + table[at(x0, y0, z1)] + table[at(x0, y1, z0)] + table[at(x1, y0, z0)]
                - table[at(x0, y1, z1)]
                - table[at(x1, y0, z1)]
                - table[at(x1, y1, z0)]
                - table[at(x0, y0, z0)];
            count == 0
        })
        .collect()
}

/// The nodes of a `nodes^3` lattice over `scene_box` within `dilation` cells (per axis) of an
/// occupied cell of `occupancy`: one entry per node, in linear order.
pub(crate) fn keep_near_occupied(
    scene_box: &SceneBox,
    nodes: usize,
    occupancy: &OccupancyGrid,
    dilation: usize,
) -> Vec<bool> {
    let r = occupancy.resolution();
    let mut near: Vec<bool> = (0..r * r * r)
        .map(|l| occupancy.is_occupied([l / (r * r), l / r % r, l % r]))
        .collect();
    // A box dilation is three passes of a running window, one along each axis.
    for stride in [r * r, r, 1] {
        let before = near.clone();
        for (l, n) in near.iter_mut().enumerate() {
            let i = l / stride % r;
            let (lo, hi) = (i.saturating_sub(dilation), (i + dilation).min(r - 1));
            *n = (lo..=hi).any(|j| before[l - i * stride + j * stride]);
        }
    }
    (0..nodes * nodes * nodes)
        .map(|l| {
            let i = [l / (nodes * nodes), l / nodes % nodes, l % nodes];
            let p = std::array::from_fn(|a| node_position(scene_box, nodes, a, i[a]));
            occupancy.cell_of(p).is_some_and(|[x, y, z]| near[(x * r + y) * r + z])
        })
        .collect()
}

impl<F: Float> RadianceField<F> for SparseGrid<F> {
    const KIND: &'static str = "sparse-grid";
    const PRUNED_BY_OCCUPANCY: bool = true;

    /// Every node of the lattice stored.
    fn fresh(settings: &FitSettings, nodes: usize) -> Result<Self, FitError> {
        let shading = Shading::of(settings)?;
        let contraction = settings.field_space()?.contraction();
        SparseGrid::new(
            settings.model_box(),
            nodes,
            NodeIndex::full([nodes; 3])?,
            shading,
            settings.tv,
        )?
        .with_distortion(settings.distortion)
        .map(|g| g.with_contraction(contraction))
    }

    /// Keeps the nodes within a few occupancy cells of a cell the fit's occupancy grid
    /// marks occupied: every node without an occupancy grid, or before its first refresh
    /// (when every cell is occupied, as nothing is known yet: a model that has barely started
    /// has no density above the threshold, and pruning by it would keep nothing).
    fn resampled(&self, nodes: usize, occupancy: Option<&OccupancyGrid>) -> Result<Self, FitError> {
        let keep = match occupancy {
            Some(g) => keep_near_occupied(&self.scene_box(), nodes, g, DILATION),
            None => vec![true; nodes * nodes * nodes],
        };
        self.resampled_onto(nodes, &keep)
    }

    fn structure(&self) -> Vec<(&'static str, Vec<bool>)> {
        let mut keep = vec![false; self.nodes.pow(3)];
        for l in self.index().kept_nodes() {
            keep[l] = true;
        }
        vec![(KEPT, keep)]
    }

    fn with_structure(
        settings: &FitSettings,
        nodes: usize,
        structure: &dyn Fn(&str) -> Option<Vec<bool>>,
    ) -> Result<Self, FitError> {
        let keep = structure(KEPT).ok_or_else(|| FitError::Config(format!("no {KEPT:?} mask")))?;
        let shading = Shading::of(settings)?;
        let contraction = settings.field_space()?.contraction();
        SparseGrid::new(
            settings.model_box(),
            nodes,
            NodeIndex::from_mask([nodes; 3], &keep)?,
            shading,
            settings.tv,
        )?
        .with_distortion(settings.distortion)
        .map(|g| g.with_contraction(contraction))
    }

    /// The cells none of whose points' lookups reach a kept node: they read raw 0 everywhere,
    /// the density `softplus(shift)`.
    fn known_cells(&self, occupancy: &OccupancyGrid) -> Result<Option<KnownCells>, FitError> {
        let zero = ndarray::ArrayD::<F>::zeros(ndarray::IxDyn(&[1, self.shading.channels()]));
        let fog = self.shading.densities(zero)?[0].as_f64();
        let cells = cells_without_kept_nodes(self.index(), &self.scene_box(), occupancy);
        Ok(Some(KnownCells { cells, density: fog }))
    }

    fn nodes(&self) -> usize {
        self.nodes
    }

    fn bounds(&self) -> Aabb {
        self.bounds
    }

    fn space(&self) -> FieldSpace {
        match self.contraction {
            Some(c) => FieldSpace::Contracted(c),
            None => FieldSpace::Box(self.bounds),
        }
    }

    /// Half the lattice spacing along the box's shortest side, as the dense grid's.
    fn sample_step(&self) -> f64 {
        self.scene_box().half_node_spacing(self.nodes)
    }

    fn params(&self) -> &Params<F> {
        &self.params
    }

    fn params_mut(&mut self) -> &mut Params<F> {
        &mut self.params
    }

    fn render(
        &self,
        tape: &mut Tape<F>,
        rays: &RayBatch<F>,
        samples: PackedSamples<F>,
        background: [f64; 3],
        method: Method,
        wanted: RenderWanted,
    ) -> Result<CompositeVars, TapeError> {
        self.render_grid(tape, rays, samples, background, method, wanted)
    }

    fn training_loss(
        &self,
        tape: &mut Tape<F>,
        rays: &RayBatch<F>,
        samples: PackedSamples<F>,
        background: TrainingBackground<F>,
        target: Var,
        method: Method,
    ) -> Result<TrainingLoss, TapeError> {
        self.training_loss_grid(tape, rays, samples, background, target, method)
    }

    /// A position outside the box or among absent nodes reads raw 0 (density
    /// `softplus(shift)`).
    fn densities(&self, positions: ArrayView2<'_, F>) -> Result<Array1<F>, FitError> {
        self.shading.densities(self.raw_values(positions)?)
    }

    /// As [`RadianceField::densities`]: a position outside the box or among absent nodes reads
    /// raw 0 (grey).
    fn base_colors(&self, positions: ArrayView2<'_, F>) -> Result<Array2<F>, FitError> {
        self.shading.base_colors(self.raw_values(positions)?)
    }
}

impl<F: Float> GridModel<F> for SparseGrid<F> {
    fn values(&self) -> (&Params<F>, ParamId) {
        (&self.params, self.data)
    }

    fn shading(&self) -> &Shading {
        &self.shading
    }

    fn distortion(&self) -> f64 {
        self.distortion
    }

    fn lookup(&self, tape: &mut Tape<F>, data: Var, positions: Var, method: Method) -> Result<Var, TapeError> {
        method.kernels().sparse_lookup(tape, &self.field, data, positions)
    }

    fn prior(&self, tape: &mut Tape<F>, data: Var) -> Result<Option<Var>, TapeError> {
        if self.prior.weight() > 0.0 {
            Ok(Some(self.prior.apply(tape, data)?))
        } else {
            Ok(None)
        }
    }
}

#[cfg(test)]
mod tests;
