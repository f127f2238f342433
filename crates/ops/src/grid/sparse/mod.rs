//! A sparse grid field: the nodes of a 3-D lattice that a scene needs, stored as packed rows
//! `[kept, C]` with an index from every node to its row ([`NodeIndex`], 4 bytes a node, as
//! Plenoxels stores its grid), looked up trilinearly as one fused op with a hand-written
//! backward ([`SparseGridField`]) and as a taped twin ([`twin::lookup`]).
//!
//! The conventions are the dense [`GridField`](crate::GridField)'s (nodes on the box
//! corners, channels last, 0 outside the box, the cell above on a face), and a node that is
//! not stored reads 0 in every channel and gets no gradient: the lookup equals the dense
//! grid's with the absent nodes set to 0. With every node kept the values are the dense
//! field's bit for bit, and the gradients agree to the last bits (the sums run in another
//! order).
//!
//! Memory and the cost of a step grow with the rows kept: the values, their gradient (and an
//! optimiser's moments) are `[kept, C]`; only the index spans the lattice. The backward into
//! the values sums in f64 and is bitwise the same for any number of threads (`scatter.rs`).
//!
//! ```
//! use fogray_ops::grid::{NodeIndex, SparseGridField};
//! use fogray_ops::GridBox;
//! use fogray_tape::Tape;
//! use ndarray::arr2;
//!
//! // A 2x2x2 lattice over the unit cube storing only the corners with x = 1, one channel.
//! let keep: Vec<bool> = (0..8).map(|l| l >= 4).collect();
//! let field = SparseGridField::new(GridBox::new(&[0.0; 3], &[1.0; 3])?, NodeIndex::from_mask([2, 2, 2], &keep)?, 1)?;
//! let mut tape = Tape::<f64>::new();
//! let data = tape.param(arr2(&[[1.0], [1.0], [1.0], [1.0]]));
//! let positions = tape.constant(arr2(&[[0.25, 0.5, 0.5]]));
//! let out = field.apply(&mut tape, data, positions)?;
//! // The absent x = 0 face reads 0: the value is the weight of the x = 1 face, 0.25.
//! assert_eq!(tape.value(out)?[[0, 0]], 0.25);
//! let grads = tape.backward(out)?;
//! assert_eq!(grads.get(data).unwrap()[[0, 0]], 0.25 * 0.25);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod field;
mod index;
mod kernels;
mod scatter;
pub mod twin;

pub use field::SparseGridField;
pub use index::NodeIndex;
