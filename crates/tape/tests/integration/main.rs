//! The integration tests, one binary: each module is what was one test file, so that the
//! library's generic kernels are compiled once for all of them.

mod adam_state;
mod buffer_pool;
mod lifecycle;
mod optim;
mod params;
mod profile;
