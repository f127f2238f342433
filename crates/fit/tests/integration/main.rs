//! fogray-fit's integration tests, one module per topic, in one binary (every test file would
//! be a crate of its own that compiles the generic kernels again: add a module here, not a file
//! beside this one). They fit small synthetic datasets ([`common`]); the fits of a real scene
//! are the examples' tests.

mod background;
mod checkpoint;
mod common;
mod dense;
mod depth;
mod environment;
mod limits;
mod mesh;
mod metrics;
mod negative;
mod resume;
mod sparse;
mod train;
