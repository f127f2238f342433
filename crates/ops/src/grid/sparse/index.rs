//! Which nodes of a sparse grid are stored, and where: an index from every node of the full
//! lattice to its row of the packed values, rows in node order.

use crate::error::{Op, OpsError};

/// The row of a node that is not stored.
const ABSENT: u32 = u32::MAX;

/// The stored nodes of an `n0 x n1 x n2` lattice: each kept node has a row of the packed
/// values `[kept, C]`, in the order of the nodes' linear index (`(i n1 + j) n2 + k`, x
/// slowest), so that the nodes of a layer along x are one run of rows.
///
/// It costs 4 bytes a node of the lattice (the index) and nothing per channel: the values,
/// their gradient and an optimiser's moments grow with the rows kept.
///
/// ```
/// use fogray_ops::grid::NodeIndex;
///
/// // Keep the nodes of a 3 x 2 x 2 lattice whose x index is not 1.
/// let keep: Vec<bool> = (0..12).map(|l| l / 4 != 1).collect();
/// let index = NodeIndex::from_mask([3, 2, 2], &keep)?;
/// assert_eq!(index.kept(), 8);
/// assert_eq!(index.row([0, 1, 1]), Some(3));
/// assert_eq!(index.row([1, 0, 0]), None);
/// assert_eq!(index.row([2, 0, 0]), Some(4));
/// # Ok::<(), fogray_ops::OpsError>(())
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct NodeIndex {
    nodes: [usize; 3],
    /// Each node's row, [`ABSENT`] if it is not stored.
    rows: Vec<u32>,
    /// The first row of each node layer along x, and the number of rows at the end
    /// (`n0 + 1` entries).
    layer_starts: Vec<usize>,
}

impl NodeIndex {
    /// The nodes of an `nodes[0] x nodes[1] x nodes[2]` lattice for which `keep` (one entry
    /// per node, in linear order) is true.
    ///
    /// Errors ([`OpsError::Shape`]): an axis with fewer than 2 nodes, a mask of another
    /// length, or more kept nodes than a `u32` row number holds.
    pub fn from_mask(nodes: [usize; 3], keep: &[bool]) -> Result<Self, OpsError> {
        let fail = |what: &'static str, expected: String, got: String| OpsError::Shape {
            op: Op::SparseGridField,
            what,
            expected,
            got,
        };
        if let Some(a) = nodes.iter().position(|&n| n < 2) {
            return Err(fail(
                "sparse grid nodes",
                "at least 2 nodes on every axis".into(),
                format!("{nodes:?} (axis {a})"),
            ));
        }
        let total = nodes
            .iter()
            .try_fold(1usize, |acc, &n| acc.checked_mul(n))
            .filter(|&t| t <= isize::MAX as usize / 4)
            .ok_or_else(|| {
                fail(
                    "sparse grid nodes",
                    "a lattice memory can index".into(),
                    format!("{nodes:?}"),
                )
            })?;
        if keep.len() != total {
            return Err(fail(
                "keep mask",
                format!("{total} entries (one per node)"),
                keep.len().to_string(),
            ));
        }
        let kept = keep.iter().filter(|&&k| k).count();
        if kept >= ABSENT as usize {
            return Err(fail(
                "keep mask",
                format!("fewer than {ABSENT} kept nodes"),
                kept.to_string(),
            ));
        }
        let mut rows = Vec::with_capacity(total);
        let mut layer_starts = Vec::with_capacity(nodes[0] + 1);
        let layer = nodes[1] * nodes[2];
        let mut next = 0u32;
        for (l, &k) in keep.iter().enumerate() {
            if l % layer == 0 {
                layer_starts.push(next as usize);
            }
            rows.push(if k {
                next += 1;
                next - 1
            } else {
                ABSENT
            });
        }
        layer_starts.push(next as usize);
        Ok(NodeIndex {
            nodes,
            rows,
            layer_starts,
        })
    }

    /// Every node of the lattice kept (the dense grid, stored as a sparse one).
    ///
    /// Errors: as [`NodeIndex::from_mask`].
    pub fn full(nodes: [usize; 3]) -> Result<Self, OpsError> {
        let total = nodes
            .iter()
            .try_fold(1usize, |acc, &n| acc.checked_mul(n))
            .unwrap_or(usize::MAX);
        if total > isize::MAX as usize / 4 {
            return NodeIndex::from_mask(nodes, &[]);
        }
        NodeIndex::from_mask(nodes, &vec![true; total])
    }

    /// Nodes per axis of the lattice.
    pub fn nodes(&self) -> [usize; 3] {
        self.nodes
    }

    /// Number of stored nodes (rows of the packed values).
    pub fn kept(&self) -> usize {
        self.layer_starts[self.nodes[0]]
    }

    /// The row of node `[i, j, k]`, or `None` if it is not stored or lies off the lattice.
    pub fn row(&self, node: [usize; 3]) -> Option<usize> {
        if (0..3).any(|a| node[a] >= self.nodes[a]) {
            return None;
        }
        self.row_at((node[0] * self.nodes[1] + node[1]) * self.nodes[2] + node[2])
    }

    /// The row of the node with linear index `linear` (in range).
    #[inline(always)]
    pub(crate) fn row_at(&self, linear: usize) -> Option<usize> {
        let r = self.rows[linear];
        (r != ABSENT).then_some(r as usize)
    }

    /// The first row of node layer `i` along x (`i = n0` gives the number of rows).
    pub(crate) fn layer_start(&self, i: usize) -> usize {
        self.layer_starts[i]
    }

    /// The linear index of each row's node, in row order.
    pub fn kept_nodes(&self) -> Vec<usize> {
        self.rows
            .iter()
            .enumerate()
            .filter(|(_, &r)| r != ABSENT)
            .map(|(l, _)| l)
            .collect()
    }

    /// Bytes the index itself takes (4 a node of the lattice).
    pub fn index_bytes(&self) -> usize {
        self.rows.len() * std::mem::size_of::<u32>() + self.layer_starts.len() * std::mem::size_of::<usize>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layers_start_where_their_rows_do() {
        // 3 x 2 x 2: keep node 1 of layer 0, nothing of layer 1, all of layer 2.
        let mut keep = vec![false; 12];
        keep[1] = true;
        keep[8..].iter_mut().for_each(|k| *k = true);
        let index = NodeIndex::from_mask([3, 2, 2], &keep).unwrap();
        assert_eq!(index.layer_starts, vec![0, 1, 1, 5]);
        assert_eq!(index.kept(), 5);
        assert_eq!(index.kept_nodes(), vec![1, 8, 9, 10, 11]);
        assert_eq!(index.row([0, 0, 1]), Some(0));
        assert_eq!(index.row([2, 1, 1]), Some(4));
        assert_eq!(index.row([3, 0, 0]), None);
    }

    #[test]
    fn bad_lattices_and_masks_are_errors() {
        assert!(matches!(
            NodeIndex::full([1, 4, 4]),
            Err(OpsError::Shape {
                op: Op::SparseGridField,
                ..
            })
        ));
        assert!(matches!(
            NodeIndex::from_mask([2, 2, 2], &[true; 7]),
            Err(OpsError::Shape {
                op: Op::SparseGridField,
                what: "keep mask",
                ..
            })
        ));
        assert!(matches!(
            NodeIndex::full([usize::MAX / 2, 4, 4]),
            Err(OpsError::Shape {
                op: Op::SparseGridField,
                ..
            })
        ));
    }
}
