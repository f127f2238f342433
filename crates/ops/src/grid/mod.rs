//! A dense grid field: `C` channels per node of a regular grid over an axis-aligned box,
//! looked up at packed positions, bilinearly in 2-D (`[n, 2]` positions) and trilinearly in
//! 3-D (`[n, 3]`), as one fused op with a hand-written backward into the grid values and the
//! positions ([`GridField`]), and as a taped twin ([`twin::lookup`]).
//!
//! # Conventions
//!
//! - Storage is channels last: the grid values are `[n0, n1, n2, C]` (3-D) or `[n0, n1, C]`
//!   (2-D), row-major, axis 0 along x, axis 1 along y, axis 2 along z. The output is `[n, C]`.
//! - Nodes are aligned with the box corners (PyTorch's `align_corners=True`): node `i` of an
//!   axis with `n` nodes sits at `min + i (max - min) / (n - 1)`, so every axis needs at least
//!   2 nodes.
//! - A position outside the closed box (any coordinate below `min` or above `max`, infinities
//!   included) reads 0 in every channel and gets zero gradient; it adds nothing to the grid's
//!   gradient. A NaN coordinate is an error.
//! - A position exactly on an inner cell face belongs to the cell above it (fraction 0 there),
//!   one on the max face of the box to the last cell (fraction 1), in the forward and both
//!   backwards alike: its value is the face's interpolant (a node's value at a node), its grid
//!   gradient goes to the face's nodes only, and its position gradient, which jumps across
//!   faces, is that cell's one-sided derivative.
//!
//! # Numerics and speed, by design
//!
//! Each position's cell and weights are computed in f64 (also for f32 data) and rounded once.
//! The forward is parallel over fixed chunks of positions. The backward into the grid is a
//! scatter made deterministic by a fixed cut of the grid into tiles (slabs along x, rows along
//! y): each node's terms are summed in a fixed order, in f64, and rounded once, so the
//! gradient is bitwise the same for any number of threads (see `scatter.rs` in the source).
//! Nothing is saved between forward and backward: the backward recomputes cells and weights
//! from the inputs. The backward's working memory is kept by the field between calls
//! ([`GridField::release_buffers`]).
//!
//! ```
//! use fogray_ops::{GridBox, GridField};
//! use fogray_tape::Tape;
//! use ndarray::{arr2, Array4};
//!
//! // A 2x2x2 grid with one channel over the unit cube holding f(x, y, z) = x + 2y + 4z at its
//! // corners: trilinear interpolation reproduces the linear field everywhere in the box.
//! let field = GridField::new(GridBox::new(&[0.0; 3], &[1.0; 3])?, &[2, 2, 2, 1])?;
//! let values = Array4::from_shape_fn((2, 2, 2, 1), |(i, j, k, _)| (i + 2 * j + 4 * k) as f64);
//! let mut tape = Tape::<f64>::new();
//! let grid = tape.param(values);
//! let positions = tape.param(arr2(&[[0.25, 0.5, 0.75], [2.0, 0.0, 0.0]]));
//! let out = field.apply(&mut tape, grid, positions)?;
//! assert_eq!(tape.value(out)?[[0, 0]], 0.25 + 1.0 + 3.0);
//! assert_eq!(tape.value(out)?[[1, 0]], 0.0); // outside the box
//! let loss = tape.sum(out)?;
//! let grads = tape.backward(loss)?;
//! // d out / d position = the field's gradient (1, 2, 4) inside, zero outside.
//! assert_eq!(grads.get(positions).unwrap(), arr2(&[[1.0, 2.0, 4.0], [0.0, 0.0, 0.0]]).into_dyn());
//! // The corner (0, 0, 0) has weight 0.75 * 0.5 * 0.25.
//! assert_eq!(grads.get(grid).unwrap()[[0, 0, 0, 0]], 0.09375);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod backward;
mod config;
mod forward;
mod geometry;
mod op;
mod scatter;
mod scratch;
pub mod sparse;
pub mod twin;

pub use config::{GridField, GridGradientBuffers, GridGradients, GridWanted};
pub use geometry::GridBox;
pub use sparse::{NodeIndex, SparseGridField};
