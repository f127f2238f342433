//! The integration tests, one binary: each module is what was one test file, so that the
//! library's generic kernels are compiled once for all of them.

mod composite_packs;
mod field;
mod grid_common;
mod grid_into;
mod grid_threads;
mod grid_twin;
mod grid_values;
mod prior;
