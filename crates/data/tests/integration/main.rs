//! The integration tests of fogray-data, as one binary.

mod common;
mod decode;
mod downscale;
mod errors;
mod lego;
mod projection;
mod roundtrip;
mod scene_box;
