//! The box a grid spans and the map from a position to the cell it falls in.
//!
//! Nodes are aligned with the box corners (PyTorch's `align_corners=True`): along an axis of
//! `n >= 2` nodes over `[min, max]`, node `i` sits at `min + i (max - min) / (n - 1)`. A
//! coordinate `p` in `[min, max]` maps to `u = (p - min) (n - 1) / (max - min)` in `[0, n - 1]`,
//! to the cell `i = min(floor(u), n - 2)` and the fraction `t = u - i` in `[0, 1]`: a
//! coordinate on an inner cell face (`u` an integer below `n - 1`) belongs to the cell above
//! it with `t = 0`, one on the max face to the last cell with `t = 1`. Outside `[min, max]`
//! (infinities included) there is no cell.

use crate::error::{Op, OpsError};
use crate::rays::Aabb;

/// An axis-aligned box in 2 or 3 dimensions, finite with `min < max` on every axis.
///
/// Axis 0 is x, axis 1 is y, axis 2 is z.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridBox {
    min: [f64; 3],
    max: [f64; 3],
    dims: usize,
}

impl GridBox {
    /// The box `[min[a], max[a]]` along each axis `a`.
    ///
    /// Errors: [`OpsError::Shape`] unless `min` and `max` both have 2 or 3 entries (the same
    /// number); [`OpsError::Box`] on an axis with a non-finite bound or `min >= max`.
    pub fn new(min: &[f64], max: &[f64]) -> Result<Self, OpsError> {
        if min.len() != max.len() || !(2..=3).contains(&min.len()) {
            return Err(OpsError::Shape {
                op: Op::GridField,
                what: "box",
                expected: "min and max with 2 or 3 coordinates each".into(),
                got: format!("{} and {}", min.len(), max.len()),
            });
        }
        let mut b = GridBox {
            min: [0.0; 3],
            max: [0.0; 3],
            dims: min.len(),
        };
        for (axis, (&lo, &hi)) in min.iter().zip(max).enumerate() {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(OpsError::Box {
                    op: Op::GridField,
                    axis,
                    min: lo,
                    max: hi,
                });
            }
            b.min[axis] = lo;
            b.max[axis] = hi;
        }
        Ok(b)
    }

    /// Number of axes (2 or 3).
    pub fn dims(&self) -> usize {
        self.dims
    }

    /// The lower corner.
    pub fn min(&self) -> &[f64] {
        &self.min[..self.dims]
    }

    /// The upper corner.
    pub fn max(&self) -> &[f64] {
        &self.max[..self.dims]
    }

    /// Whether `p` (one coordinate per axis) lies in the closed box; false for NaN.
    pub fn contains(&self, p: &[f64]) -> bool {
        p.len() == self.dims
            && p.iter()
                .zip(self.min())
                .zip(self.max())
                .all(|((&x, &lo), &hi)| lo <= x && x <= hi)
    }
}

/// The same box as the rays are clipped to, so that a renderer states its bounds once:
/// `GridField::new(bounds.into(), shape)`. Infallible: an [`Aabb`] is finite with `min < max`.
impl From<Aabb> for GridBox {
    fn from(b: Aabb) -> Self {
        GridBox {
            min: b.min(),
            max: b.max(),
            dims: 3,
        }
    }
}

/// The 3-D grid box as a box to clip rays to.
/// Errors: [`OpsError::Shape`] for a 2-D box.
impl TryFrom<GridBox> for Aabb {
    type Error = OpsError;

    fn try_from(b: GridBox) -> Result<Self, OpsError> {
        if b.dims != 3 {
            return Err(OpsError::Shape {
                op: Op::Rays,
                what: "box",
                expected: "3 axes to clip rays to".into(),
                got: format!("{} axes", b.dims),
            });
        }
        Aabb::new(b.min, b.max)
    }
}

/// One axis of a grid: where its nodes are.
#[derive(Debug, Clone, Copy)]
pub(crate) struct AxisMap {
    pub(crate) min: f64,
    pub(crate) max: f64,
    /// `(n - 1) / (max - min)`: cells per unit length, `du/dp`.
    pub(crate) scale: f64,
    /// `n - 2`, the index of the last cell.
    pub(crate) last_cell: usize,
    /// `n - 1` as a float: where `u` ends.
    end: f64,
    /// `last_cell` as a signed integer (see [`AxisMap::cell`]).
    last_signed: i64,
}

impl AxisMap {
    pub(crate) fn new(min: f64, max: f64, nodes: usize) -> Self {
        let cells = (nodes - 1) as f64;
        AxisMap {
            min,
            max,
            scale: cells / (max - min),
            last_cell: nodes - 2,
            end: cells,
            // A grid's values fit in memory, so an axis's node count fits in an i64.
            last_signed: (nodes - 2) as i64,
        }
    }

    /// Whether `p` lies in the axis's closed range (false for NaN).
    #[inline(always)]
    fn contains(&self, p: f64) -> bool {
        (p >= self.min) & (p <= self.max)
    }

    /// The cell and the fraction within it of coordinate `p`, or `None` outside the axis's
    /// range (or for NaN).
    #[cfg(test)]
    pub(crate) fn locate(&self, p: f64) -> Option<(usize, f64)> {
        self.contains(p).then(|| self.cell(p))
    }

    /// The cell and the fraction within it of a coordinate `p` in the axis's range.
    #[inline(always)]
    fn cell(&self, p: f64) -> (usize, f64) {
        debug_assert!(self.contains(p));
        // u >= 0 here (or NaN, from an infinite scale); rounding may carry the max face a
        // hair past n - 1, hence the clamp, which also turns a NaN into n - 1 (`f64::min`
        // returns the other operand): u is a finite number in [0, n - 1].
        let u = ((p - self.min) * self.scale).min(self.end);
        // SAFETY: u is finite and in [0, n - 1] (above), and n - 1 fits in an i64 (a grid's
        // values fit in memory), so the truncation is defined; it is floor(u). The checked
        // conversions cost a branchy sequence each, most of this function's time.
        let i = unsafe { u.to_int_unchecked::<i64>() }.min(self.last_signed);
        (i as usize, u - i as f64)
    }
}

/// Where a grid's nodes are: the box, the node counts and the strides of the channels-last
/// storage (`[n0, n1, n2, C]` or `[n0, n1, C]`, row-major).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Layout<const D: usize> {
    pub(crate) axes: [AxisMap; D],
    /// Node strides, in nodes (the last is 1).
    pub(crate) strides: [usize; D],
    /// Node offset of each of the `2^D` corners of a cell from its first node; corner `k`
    /// takes the upper node along axis `a` when bit `D - 1 - a` of `k` is set.
    pub(crate) corners: [usize; 8],
}

/// A position's cell: its first node (a linear node index), its index along each axis and the
/// fraction along each axis.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Cell<const D: usize> {
    pub(crate) node: usize,
    pub(crate) index: [usize; D],
    pub(crate) t: [f64; D],
}

impl<const D: usize> Layout<D> {
    pub(crate) fn new(bbox: &GridBox, nodes: &[usize]) -> Self {
        let axes = std::array::from_fn(|a| AxisMap::new(bbox.min[a], bbox.max[a], nodes[a]));
        let mut strides = [1; D];
        for a in (0..D.saturating_sub(1)).rev() {
            strides[a] = strides[a + 1] * nodes[a + 1];
        }
        let mut corners = [0; 8];
        for (k, c) in corners.iter_mut().enumerate().take(1 << D) {
            *c = (0..D).filter(|&a| k >> (D - 1 - a) & 1 == 1).map(|a| strides[a]).sum();
        }
        Layout { axes, strides, corners }
    }

    /// The cell of position `p`, or `None` if it lies outside the box.
    #[inline(always)]
    pub(crate) fn locate(&self, p: [f64; D]) -> Option<Cell<D>> {
        // One branch for the whole position (most lie inside).
        if !self
            .axes
            .iter()
            .zip(&p)
            .fold(true, |inside, (axis, &x)| inside & axis.contains(x))
        {
            return None;
        }
        let mut node = 0;
        let mut index = [0; D];
        let mut t = [0.0; D];
        for a in 0..D {
            let (i, f) = self.axes[a].cell(p[a]);
            node += i * self.strides[a];
            index[a] = i;
            t[a] = f;
        }
        Some(Cell { node, index, t })
    }
}

/// The `2^D` trilinear (bilinear) weights of a cell's corners, in the corner order of
/// [`Layout::corners`]: the product over axes of `t` (upper node) or `1 - t` (lower node).
#[inline(always)]
pub(crate) fn weights<const D: usize>(t: [f64; D]) -> [f64; 8] {
    let mut w = [0.0; 8];
    w[0] = 1.0;
    // Build up axis by axis: after axis a the first 2^(a+1) entries hold the partial products,
    // in the order where the earliest axis is the most significant bit.
    for (a, &ta) in t.iter().enumerate() {
        let m = 1 << a;
        for k in (0..m).rev() {
            w[2 * k + 1] = w[k] * ta;
            w[2 * k] = w[k] * (1.0 - ta);
        }
    }
    w
}

/// `dw_k / dt_a` for every corner `k`: the weight with axis `a`'s factor replaced by `+1`
/// (upper node) or `-1` (lower node).
#[inline(always)]
pub(crate) fn weight_derivatives<const D: usize>(t: [f64; D], a: usize) -> [f64; 8] {
    let mut s = t;
    // With t_a -> the factor is t_a or 1 - t_a; its derivative is +1 or -1, which is the
    // weight at t_a = 1 minus the weight at t_a = 0.
    s[a] = 1.0;
    let hi = weights(s);
    s[a] = 0.0;
    let lo = weights(s);
    std::array::from_fn(|k| hi[k] - lo[k])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn locate_on_faces_and_outside() {
        // 5 nodes over [0, 4]: node i at i, cells of length 1.
        let axis = AxisMap::new(0.0, 4.0, 5);
        assert_eq!(axis.locate(0.0), Some((0, 0.0)));
        assert_eq!(axis.locate(2.0), Some((2, 0.0))); // inner face: the cell above, t = 0
        assert_eq!(axis.locate(2.5), Some((2, 0.5)));
        assert_eq!(axis.locate(4.0), Some((3, 1.0))); // max face: the last cell, t = 1
        assert_eq!(axis.locate(-1e-300), None);
        assert_eq!(axis.locate(4.000000000000001), None);
        assert_eq!(axis.locate(f64::INFINITY), None);
        assert_eq!(axis.locate(f64::NAN), None);
        // A box too thin for its scale to be finite: (p - min) * scale is NaN at p = min,
        // which the clamp turns into n - 1, a cell in range (the unchecked conversion needs
        // a finite u in [0, n - 1]).
        let thin = AxisMap::new(0.0, 5e-324, 3);
        assert_eq!(thin.scale, f64::INFINITY);
        assert_eq!(thin.locate(0.0), Some((1, 1.0)));
        assert_eq!(thin.locate(5e-324), Some((1, 1.0)));
    }

    #[test]
    fn boxes_convert_both_ways_and_a_flat_one_is_refused() {
        let aabb = Aabb::new([-1.0, -2.0, 0.5], [1.0, 2.0, 3.0]).unwrap();
        let grid = GridBox::from(aabb);
        assert_eq!(
            (grid.dims(), grid.min(), grid.max()),
            (3, &[-1.0, -2.0, 0.5][..], &[1.0, 2.0, 3.0][..])
        );
        assert_eq!(Aabb::try_from(grid).unwrap(), aabb);
        assert_eq!(grid, GridBox::new(&[-1.0, -2.0, 0.5], &[1.0, 2.0, 3.0]).unwrap());
        let flat = GridBox::new(&[0.0, 0.0], &[1.0, 1.0]).unwrap();
        assert!(matches!(
            Aabb::try_from(flat),
            Err(OpsError::Shape { op: Op::Rays, .. })
        ));
    }

    #[test]
    fn weights_are_products_and_sum_to_one() {
        let t = [0.25, 0.5, 0.125];
        let w = weights(t);
        // Corner 0b101: upper x, lower y, upper z.
        assert_eq!(w[0b101], 0.25 * 0.5 * 0.125);
        assert_eq!(w[0b010], 0.75 * 0.5 * 0.875);
        assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-15);
        // d w_{0b101} / d t_y = -(t_x t_z) (lower y).
        assert_eq!(weight_derivatives(t, 1)[0b101], -(0.25 * 0.125));
        let w2 = weights([0.25, 0.5]);
        assert_eq!(&w2[..4], &[0.375, 0.375, 0.125, 0.125]);
    }

    #[test]
    fn corners_follow_the_strides() {
        let bbox = GridBox::new(&[0.0; 3], &[1.0; 3]).unwrap();
        let l = Layout::<3>::new(&bbox, &[4, 3, 2]);
        assert_eq!(l.strides, [6, 2, 1]);
        assert_eq!(&l.corners, &[0, 1, 2, 3, 6, 7, 8, 9]);
    }

    #[test]
    fn bad_boxes_are_errors() {
        assert!(matches!(
            GridBox::new(&[0.0, 1.0], &[1.0, 1.0]),
            Err(OpsError::Box {
                op: Op::GridField,
                axis: 1,
                ..
            })
        ));
        assert!(matches!(
            GridBox::new(&[0.0, 2.0], &[1.0, 1.0]),
            Err(OpsError::Box {
                op: Op::GridField,
                axis: 1,
                ..
            })
        ));
        assert!(matches!(
            GridBox::new(&[f64::NAN, 0.0], &[1.0, 1.0]),
            Err(OpsError::Box {
                op: Op::GridField,
                axis: 0,
                ..
            })
        ));
        assert!(matches!(
            GridBox::new(&[0.0, 0.0], &[1.0, f64::INFINITY]),
            Err(OpsError::Box { op: Op::GridField, .. })
        ));
        assert!(matches!(
            GridBox::new(&[0.0], &[1.0]),
            Err(OpsError::Shape { op: Op::GridField, .. })
        ));
        assert!(matches!(
            GridBox::new(&[0.0; 3], &[1.0; 2]),
            Err(OpsError::Shape { op: Op::GridField, .. })
        ));
    }
}
