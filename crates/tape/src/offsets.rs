//! Packed segments: `R + 1` offsets, segment `r` owning rows `offsets[r]..offsets[r+1]`.
//!
//! Packed rays are the one layout of every op on rays: a ray's samples are consecutive rows of
//! flat arrays, and the offsets say where each ray starts and ends. [`Offsets`] is that packing,
//! validated once (at least one entry, starting at 0, never decreasing) and shared cheaply
//! (cloning it copies a pointer), so the segment ops, the composite and the samplers that make
//! packings all speak the same checked type.
//!
//! ```
//! use fogray_tape::Offsets;
//!
//! let packing = Offsets::from_lengths([2, 0, 3]);
//! assert_eq!(packing.as_slice(), &[0, 2, 2, 5]);
//! assert_eq!((packing.segments(), packing.rows()), (3, 5));
//! assert_eq!(packing.range(2), Some(2..5));
//! assert_eq!(packing.locate(4), Some((2, 2))); // row 4 is the third row of segment 2
//! assert!(Offsets::new(&[0, 3, 2]).is_err());
//! ```

use std::ops::{Deref, Range};
use std::sync::Arc;

use thiserror::Error;

/// Why offsets are not a packing.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[non_exhaustive]
pub enum OffsetsError {
    /// No entry at all (a packing of no segment is `[0]`).
    #[error("offsets must hold at least one entry (0)")]
    Empty,
    /// The first entry is not 0.
    #[error("offsets must start at 0, got {0}")]
    Start(usize),
    /// A segment ends before it starts.
    #[error("offsets decrease at segment {segment}: {start} then {end}")]
    Decreasing {
        /// The segment.
        segment: usize,
        /// Its start.
        start: usize,
        /// Its end, below the start.
        end: usize,
    },
    /// The packing covers another number of rows than the array it is used with.
    #[error("the offsets end at {expected} rows, the input has {got}")]
    Rows {
        /// Rows the packing covers.
        expected: usize,
        /// Rows the input has.
        got: usize,
    },
}

/// A validated packing of rows into segments: `R + 1` offsets, segment `r` owning rows
/// `offsets[r]..offsets[r+1]` (at least one entry, starting at 0, never decreasing). The one
/// layout of packed rays: a ray's samples are consecutive rows of flat arrays. Cloning it
/// copies a pointer.
///
/// It dereferences to the offsets as a slice.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Offsets(Arc<[usize]>);

impl Offsets {
    /// Checks and keeps `offsets`: at least one entry, the first 0, never decreasing (empty
    /// segments are allowed).
    pub fn new(offsets: &[usize]) -> Result<Self, OffsetsError> {
        Self::check(offsets)?;
        Ok(Offsets(offsets.into()))
    }

    /// [`Offsets::new`] without copying the entries again.
    pub fn from_vec(offsets: Vec<usize>) -> Result<Self, OffsetsError> {
        Self::check(&offsets)?;
        Ok(Offsets(offsets.into()))
    }

    /// The packing of consecutive segments of the given lengths.
    pub fn from_lengths(lengths: impl IntoIterator<Item = usize>) -> Self {
        let mut offsets = vec![0];
        let mut end = 0usize;
        for len in lengths {
            end += len;
            offsets.push(end);
        }
        Offsets(offsets.into())
    }

    fn check(offsets: &[usize]) -> Result<(), OffsetsError> {
        match offsets.first() {
            None => return Err(OffsetsError::Empty),
            Some(&o) if o != 0 => return Err(OffsetsError::Start(o)),
            _ => {}
        }
        match offsets.windows(2).position(|w| w[1] < w[0]) {
            Some(segment) => Err(OffsetsError::Decreasing {
                segment,
                start: offsets[segment],
                end: offsets[segment + 1],
            }),
            None => Ok(()),
        }
    }

    /// Number of segments `R`.
    pub fn segments(&self) -> usize {
        self.0.len() - 1
    }

    /// Number of rows the packing covers (its last entry).
    pub fn rows(&self) -> usize {
        self.0[self.0.len() - 1]
    }

    /// The `R + 1` entries.
    pub fn as_slice(&self) -> &[usize] {
        &self.0
    }

    /// The rows of segment `r`, or `None` if there is no segment `r`.
    pub fn range(&self, r: usize) -> Option<Range<usize>> {
        (r < self.segments()).then(|| self.0[r]..self.0[r + 1])
    }

    /// The rows of every segment, in order.
    pub fn ranges(&self) -> impl ExactSizeIterator<Item = Range<usize>> + '_ {
        self.0.windows(2).map(|w| w[0]..w[1])
    }

    /// The segment that owns `row` and the row's index within it, or `None` past the end.
    pub fn locate(&self, row: usize) -> Option<(usize, usize)> {
        if row >= self.rows() {
            return None;
        }
        // The last segment that starts at or before `row` and is not empty owns it.
        let r = self.0.partition_point(|&o| o <= row) - 1;
        Some((r, row - self.0[r]))
    }

    /// `Ok` if the packing covers exactly `rows` rows.
    pub fn check_rows(&self, rows: usize) -> Result<(), OffsetsError> {
        if self.rows() == rows {
            Ok(())
        } else {
            Err(OffsetsError::Rows {
                expected: self.rows(),
                got: rows,
            })
        }
    }
}

impl Deref for Offsets {
    type Target = [usize];
    fn deref(&self) -> &[usize] {
        &self.0
    }
}

/// Compares the entries, so that tests can write `assert_eq!(s.offsets, vec![0, 3, 5])`.
impl PartialEq<Vec<usize>> for Offsets {
    fn eq(&self, other: &Vec<usize>) -> bool {
        *self.0 == **other
    }
}

impl AsRef<[usize]> for Offsets {
    fn as_ref(&self) -> &[usize] {
        &self.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn validation_names_what_is_wrong() {
        assert_eq!(Offsets::new(&[]), Err(OffsetsError::Empty));
        assert_eq!(Offsets::new(&[1, 2]), Err(OffsetsError::Start(1)));
        assert_eq!(
            Offsets::new(&[0, 2, 1]),
            Err(OffsetsError::Decreasing {
                segment: 1,
                start: 2,
                end: 1
            })
        );
        let none = Offsets::new(&[0]).unwrap();
        assert_eq!((none.segments(), none.rows()), (0, 0));
        assert_eq!(none.locate(0), None);
        assert_eq!(none.range(0), None);
    }

    #[test]
    fn locate_skips_empty_segments() {
        // Segments: [0, 2), [2, 2), [2, 2), [2, 5), [5, 5).
        let p = Offsets::new(&[0, 2, 2, 2, 5, 5]).unwrap();
        let expected = [(0, 0), (0, 1), (3, 0), (3, 1), (3, 2)];
        for (row, &want) in expected.iter().enumerate() {
            assert_eq!(p.locate(row), Some(want), "row {row}");
        }
        assert_eq!(p.locate(5), None);
        assert_eq!(p.ranges().collect::<Vec<_>>(), vec![0..2, 2..2, 2..2, 2..5, 5..5]);
        assert_eq!(p.check_rows(5), Ok(()));
        assert_eq!(p.check_rows(4), Err(OffsetsError::Rows { expected: 5, got: 4 }));
        assert_eq!(Offsets::from_lengths([2, 0, 0, 3, 0]), p);
    }
}
