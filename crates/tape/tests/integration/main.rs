//! The integration tests, one module per topic, in one binary: every test file would be a
//! crate of its own that compiles the libraries' generic kernels again (add a module here,
//! not a file beside this one).

mod adam_state;
mod buffer_pool;
mod lifecycle;
mod optim;
mod params;
mod profile;
