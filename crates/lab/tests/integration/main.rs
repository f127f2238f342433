//! fogray-lab's integration tests, one module per topic, in one binary (add a module here,
//! not a file beside this one).

mod bench;
mod common;
mod sweep;
