//! The integration tests, one module per topic, in one binary: every test file would be a
//! crate of its own that compiles the libraries' generic kernels again (add a module here,
//! not a file beside this one).

mod activation;
mod composite_common;
mod composite_mse;
mod distortion;
mod grid_common;
mod grid_into;
mod grid_threads;
mod grid_twin;
mod grid_values;
mod hard_cases;
mod into_buffers;
mod op_names;
mod prior;
mod sh;
mod sparse_grid;
mod sparse_prior;
mod splat;
mod splat_common;
mod splat_grad;
mod splat_hard;
