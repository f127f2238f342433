//! The integration tests, one binary: each module is what was one test file, so that the
//! library's generic kernels are compiled once for all of them.

mod cli;
mod common;
mod fused_vs_taped;
mod hard_cases;
mod into_buffers;
mod lesson_tables;
