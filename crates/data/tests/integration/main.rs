//! The integration tests of fogray-data, as one binary.

mod capture_files;
mod colmap;
mod colmap_errors;
mod common;
mod decode;
mod downscale;
mod errors;
mod lego;
mod limits;
mod llff;
mod outputs;
mod projection;
mod roundtrip;
mod scene_box;
mod split;
