//! The integration tests, one module per topic, in one binary: every test file would be a
//! crate of its own that compiles the libraries' generic kernels again (add a module here,
//! not a file beside this one).

mod cli;
mod common;
mod datasets;
mod exact;
mod fit;
mod persist;
mod persist_cli;
mod report;
mod report_cli;
mod scenes;
