//! The integration tests, one module per topic, in one binary (add a module here, not a file
//! beside this one). Without a CUDA driver and device the GPU tests skip with a message;
//! `FOGRAY_CUDA_REQUIRED=1` makes that a failure.

mod agreement;
mod bench;
mod common;
mod compile;
mod grid;
mod lego;
mod train;
