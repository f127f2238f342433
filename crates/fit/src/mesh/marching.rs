//! Marching cubes on a density sampled on a lattice: the surface where the density crosses a
//! level, as indexed triangles whose vertices are shared by every triangle that meets them
//! (one vertex per lattice edge the surface crosses), so that the surface is closed.
//!
//! The lattice is padded by one layer of empty nodes (density 0: a model is empty outside its
//! box), so a surface that reaches the box is closed by a cap just outside it. Corners are
//! numbered as in the classic table (`tables.rs`): 0 `(0,0,0)`, 1 `(1,0,0)`, 2
//! `(1,1,0)`, 3 `(0,1,0)`, 4 `(0,0,1)`, 5 `(1,0,1)`, 6 `(1,1,1)`, 7 `(0,1,1)` in `(x, y, z)`;
//! edges 0 to 3 join corners 0-1, 1-2, 2-3, 3-0, edges 4 to 7 corners 4-5, 5-6, 6-7, 7-4, and
//! edges 8 to 11 corners 0-4, 1-5, 2-6, 3-7. The cubes are visited one `x` slab at a time,
//! keeping the vertex indices of two planes of edges only, so memory beyond the lattice and
//! the mesh stays a few planes.

use super::tables::TRIANGLES;
use super::{Lattice, MeshError};

/// The density of the padding around the lattice (outside the model's box).
const EMPTY: f64 = 0.0;

/// How close to a lattice node a vertex may come, as a fraction of its edge: vertices on two
/// edges that meet at a node whose density is the level exactly stay apart, so that a reader
/// that merges vertices by position (as trimesh does) keeps the mesh closed.
const NODE_MARGIN: f64 = 1e-3;

/// No vertex on this edge.
const NONE: u32 = u32::MAX;

/// The most vertices a mesh may have: a PLY face's indices are signed 32-bit integers.
pub(crate) const MAX_VERTICES: usize = i32::MAX as usize;

/// The surface of a lattice: vertex positions and triangles of vertex indices, each triangle
/// counter-clockwise seen from outside (from where the density is below the level).
#[derive(Debug, Clone, PartialEq, Default)]
pub(crate) struct Surface {
    /// Vertex positions, in the lattice's units.
    pub positions: Vec<[f32; 3]>,
    /// Triangles, three indices into `positions` each.
    pub triangles: Vec<[u32; 3]>,
}

/// One plane `x = i` of the padded lattice: its densities and the vertex indices of its `y`
/// and `z` edges (from node `(j, k)` to `(j + 1, k)` and `(j, k + 1)`), `m x m`.
struct Plane {
    values: Vec<f64>,
    y_edges: Vec<u32>,
    z_edges: Vec<u32>,
}

/// The padded lattice, its geometry and the surface being built.
struct Builder<'a> {
    lattice: &'a Lattice,
    level: f64,
    /// Nodes per axis with the padding.
    m: usize,
    surface: Surface,
}

impl Builder<'_> {
    /// The density of padded node `(i, j, k)` (indices 1 to `n` are the lattice's).
    fn value(&self, i: usize, j: usize, k: usize) -> f64 {
        let n = self.lattice.nodes;
        if i == 0 || j == 0 || k == 0 || i > n || j > n || k > n {
            EMPTY
        } else {
            f64::from(self.lattice.values[((i - 1) * n + (j - 1)) * n + (k - 1)])
        }
    }

    /// The position of padded node `(i, j, k)`.
    fn position(&self, node: [usize; 3]) -> [f64; 3] {
        std::array::from_fn(|a| self.lattice.coordinate(a, node[a] as f64 - 1.0))
    }

    /// The vertex on the edge from node `a` (density `va`) to node `b` (density `vb`) if the
    /// surface crosses it.
    fn vertex(&mut self, a: [usize; 3], va: f64, b: [usize; 3], vb: f64) -> Result<u32, MeshError> {
        if (va < self.level) == (vb < self.level) {
            return Ok(NONE);
        }
        let mu = ((self.level - va) / (vb - va)).clamp(NODE_MARGIN, 1.0 - NODE_MARGIN);
        let (pa, pb) = (self.position(a), self.position(b));
        let index = self.surface.positions.len();
        if index >= MAX_VERTICES {
            return Err(MeshError::TooLarge { vertices: index + 1 });
        }
        self.surface
            .positions
            .push(std::array::from_fn(|d| (pa[d] + mu * (pb[d] - pa[d])) as f32));
        Ok(index as u32)
    }

    /// Plane `i`: its densities, then the vertices of its `y` and `z` edges.
    fn plane(&mut self, i: usize, plane: &mut Plane) -> Result<(), MeshError> {
        let m = self.m;
        for j in 0..m {
            for k in 0..m {
                plane.values[j * m + k] = self.value(i, j, k);
            }
        }
        for j in 0..m {
            for k in 0..m {
                let v = plane.values[j * m + k];
                plane.y_edges[j * m + k] = if j + 1 < m {
                    self.vertex([i, j, k], v, [i, j + 1, k], plane.values[(j + 1) * m + k])?
                } else {
                    NONE
                };
                plane.z_edges[j * m + k] = if k + 1 < m {
                    self.vertex([i, j, k], v, [i, j, k + 1], plane.values[j * m + k + 1])?
                } else {
                    NONE
                };
            }
        }
        Ok(())
    }

    /// The triangles of the cubes between planes `i` (`lo`) and `i + 1` (`hi`), with the
    /// vertices of the `x` edges between them `x_edges`.
    fn cubes(&mut self, lo: &Plane, hi: &Plane, x_edges: &[u32]) {
        let m = self.m;
        for j in 0..m - 1 {
            for k in 0..m - 1 {
                let at = |dj: usize, dk: usize| (j + dj) * m + k + dk;
                let corners = [
                    lo.values[at(0, 0)],
                    hi.values[at(0, 0)],
                    hi.values[at(1, 0)],
                    lo.values[at(1, 0)],
                    lo.values[at(0, 1)],
                    hi.values[at(0, 1)],
                    hi.values[at(1, 1)],
                    lo.values[at(1, 1)],
                ];
                let case = corners
                    .iter()
                    .enumerate()
                    .fold(0, |c, (bit, &v)| if v < self.level { c | 1 << bit } else { c });
                if case == 0 || case == 255 {
                    continue;
                }
                let edges = [
                    x_edges[at(0, 0)],
                    hi.y_edges[at(0, 0)],
                    x_edges[at(1, 0)],
                    lo.y_edges[at(0, 0)],
                    x_edges[at(0, 1)],
                    hi.y_edges[at(0, 1)],
                    x_edges[at(1, 1)],
                    lo.y_edges[at(0, 1)],
                    lo.z_edges[at(0, 0)],
                    hi.z_edges[at(0, 0)],
                    hi.z_edges[at(1, 0)],
                    lo.z_edges[at(1, 0)],
                ];
                for t in TRIANGLES[case].chunks_exact(3).take_while(|t| t[0] >= 0) {
                    // The table's triangles are counter-clockwise seen from outside.
                    self.surface
                        .triangles
                        .push([t[0], t[1], t[2]].map(|e| edges[e as usize]));
                }
            }
        }
    }
}

/// The surface where `lattice`'s density crosses `level`: the boundary of the region where
/// the density is at least `level`.
///
/// Errors: a level that is not above 0 or not finite ([`MeshError::Level`] without a
/// range: the padding is empty, so such a surface would enclose all space), more vertices than
/// a PLY file can index ([`MeshError::TooLarge`]).
pub(crate) fn march(lattice: &Lattice, level: f64) -> Result<Surface, MeshError> {
    if !(level.is_finite() && level > EMPTY) {
        return Err(MeshError::Level {
            level,
            opacity: None,
            range: None,
        });
    }
    let m = lattice.nodes + 2;
    let mut builder = Builder {
        lattice,
        level,
        m,
        surface: Surface::default(),
    };
    let fresh = || Plane {
        values: vec![EMPTY; m * m],
        y_edges: vec![NONE; m * m],
        z_edges: vec![NONE; m * m],
    };
    let (mut lo, mut hi) = (fresh(), fresh());
    let mut x_edges = vec![NONE; m * m];
    builder.plane(0, &mut lo)?;
    for i in 0..m - 1 {
        builder.plane(i + 1, &mut hi)?;
        for j in 0..m {
            for k in 0..m {
                let l = j * m + k;
                x_edges[l] = builder.vertex([i, j, k], lo.values[l], [i + 1, j, k], hi.values[l])?;
            }
        }
        builder.cubes(&lo, &hi, &x_edges);
        std::mem::swap(&mut lo, &mut hi);
    }
    Ok(builder.surface)
}
