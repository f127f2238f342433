//! The occupancy grid's coarse level: which blocks of `BLOCK^3` cells hold at least one
//! occupied cell, so that the marcher crosses an empty block in one step.

/// Cells per block edge, as a shift: 4 cells (blocks at the grid's upper faces may be
/// thinner when the resolution is not a multiple of 4).
pub(crate) const BLOCK_SHIFT: u32 = 2;

/// One bit per block, set when some cell of the block is occupied; block `(bx, by, bz)` (cells
/// `b * 4 .. b * 4 + 4` along each axis) is stored at `(bx * n + by) * n + bz` for `n` blocks
/// per axis. Derived from the cell bits alone, so it is rebuilt (never saved) whenever they
/// change.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Blocks {
    per_axis: usize,
    bits: Vec<u64>,
}

impl Blocks {
    /// The blocks of an `r^3` grid whose cell `i` (linear index `(ix * r + iy) * r + iz`) is
    /// occupied when bit `i % 64` of `cells[i / 64]` is set.
    pub(crate) fn from_cells(resolution: usize, cells: &[u64]) -> Blocks {
        let per_axis = resolution.div_ceil(1 << BLOCK_SHIFT);
        let mut bits = vec![0u64; per_axis.pow(3).div_ceil(64)];
        let r = resolution;
        for (w, &word) in cells.iter().enumerate() {
            let mut rest = word;
            // Only the set bits: an empty word costs one test.
            while rest != 0 {
                let i = w * 64 + rest.trailing_zeros() as usize;
                rest &= rest - 1;
                let b = [i / (r * r), i / r % r, i % r].map(|c| c >> BLOCK_SHIFT);
                let block = (b[0] * per_axis + b[1]) * per_axis + b[2];
                bits[block / 64] |= 1 << (block % 64);
            }
        }
        Blocks { per_axis, bits }
    }

    /// Whether the block holding cell `c` (each index in `0..r`) has no occupied cell.
    #[inline]
    pub(crate) fn is_empty_at(&self, c: [i64; 3]) -> bool {
        let n = self.per_axis;
        let b = c.map(|i| i as usize >> BLOCK_SHIFT);
        let block = (b[0] * n + b[1]) * n + b[2];
        self.bits[block / 64] >> (block % 64) & 1 == 0
    }
}
