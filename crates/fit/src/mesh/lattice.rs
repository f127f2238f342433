//! A model's density sampled on a regular lattice over its box, the input of marching cubes.

use fogray_ops::rays::Aabb;
use fogray_tape::Float;
use ndarray::Array2;

use super::MeshError;
use crate::error::FitError;
use crate::model::RadianceField;
use crate::space::FieldSpace;

/// Lattice nodes looked up at once: bounds the raw values a lookup holds (every channel of
/// every node) while leaving the lookup enough work to spread over the threads.
const CHUNK_NODES: usize = 1 << 18;

/// A density sampled at `nodes^3` points over a box: node `(i, j, k)` sits at
/// `min + (i, j, k) (max - min) / (nodes - 1)` (a grid model's own node positions when
/// `nodes` is its node count).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Lattice {
    pub(super) nodes: usize,
    pub(super) bounds: Aabb,
    /// Densities, node `(i, j, k)` at `(i nodes + j) nodes + k`.
    pub(super) values: Vec<f32>,
}

impl Lattice {
    /// The lattice of `nodes^3` densities `values` (node `(i, j, k)` at `(i nodes + j) nodes
    /// + k`) over `bounds`.
    ///
    /// Errors: fewer than 2 nodes ([`MeshError::Resolution`]), values that are not `nodes^3`
    /// or not finite ([`MeshError::Values`]).
    #[cfg(test)]
    pub(crate) fn new(nodes: usize, bounds: Aabb, values: Vec<f32>) -> Result<Self, MeshError> {
        if nodes < 2 {
            return Err(MeshError::Resolution(nodes));
        }
        if nodes.checked_pow(3) != Some(values.len()) {
            return Err(MeshError::Values(format!(
                "{} values for {nodes}^3 nodes",
                values.len()
            )));
        }
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(MeshError::Values(format!("value {i} is {}", values[i])));
        }
        Ok(Lattice { nodes, bounds, values })
    }

    /// `model`'s density at `nodes^3` points over its box, looked up without a tape a slab at
    /// a time.
    ///
    /// Errors: fewer than 2 nodes, a lattice larger than memory can hold
    /// ([`MeshError::Resolution`]), the model's (a NaN density).
    pub(crate) fn sample<F: Float, M: RadianceField<F>>(model: &M, nodes: usize) -> Result<Self, FitError> {
        let total = nodes
            .checked_pow(3)
            .filter(|&t| nodes >= 2 && t.checked_mul(4).is_some())
            .ok_or(MeshError::Resolution(nodes))?;
        // A field of all of space is meshed over its inner region, where the contraction is
        // the identity up to scale ([`crate::mesh::extract`] maps the vertices to the world).
        let bounds = match model.space() {
            FieldSpace::Box(bounds) => bounds,
            FieldSpace::Contracted(_) => Aabb::new([-1.0; 3], [1.0; 3])?,
        };
        let plane = nodes * nodes;
        let slabs = (CHUNK_NODES / plane).max(1);
        let mut values = Vec::new();
        // A lattice too large for memory is refused, not aborted on.
        values
            .try_reserve_exact(total)
            .map_err(|_| MeshError::Resolution(nodes))?;
        let mut lattice = Lattice {
            nodes,
            bounds,
            values: Vec::new(),
        };
        for first in (0..nodes).step_by(slabs) {
            let rows = slabs.min(nodes - first) * plane;
            let positions = Array2::from_shape_fn((rows, 3), |(r, a)| {
                let l = first * plane + r;
                let index = [l / plane, l / nodes % nodes, l % nodes][a];
                F::lit(lattice.coordinate(a, index as f64))
            });
            let sigma = model.densities(positions.view())?;
            values.extend(sigma.iter().map(|s| s.as_f64() as f32));
        }
        lattice.values = values;
        Ok(lattice)
    }

    /// The smallest and the largest density on the lattice.
    pub(crate) fn range(&self) -> (f64, f64) {
        self.values
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
                (lo.min(f64::from(v)), hi.max(f64::from(v)))
            })
    }

    /// The coordinate along axis `a` of the node at (possibly fractional, possibly outside)
    /// index `i`: the same expression as the grid models' node positions, so that node `i`
    /// of a lattice of a grid's own node count is that grid's node.
    pub(super) fn coordinate(&self, a: usize, i: f64) -> f64 {
        let (lo, hi) = (self.bounds.min()[a], self.bounds.max()[a]);
        lo + i * (hi - lo) / (self.nodes - 1) as f64
    }
}
