//! The integration tests, one binary: each module is what was one test file, so that the
//! library's generic kernels are compiled once for all of them.

mod cli;
mod common;
mod fit;
mod persist;
mod persist_cli;
mod report;
mod report_cli;
mod scenes;
