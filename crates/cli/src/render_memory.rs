//! `fogray render`'s frames checked against the machine's memory before anything is built:
//! the list of views (as long as `--orbit`, or the cameras file's frames) and the largest
//! frame's pixels, with the chunk of rays the model renders at a time
//! ([`fogray_ops::limits`] counts the bytes). A size the machine cannot hold is refused in
//! one line naming the flag or the file, instead of aborting on a failed allocation.

use std::path::Path;

use fogray_fit::checkpoint::ModelInfo;
use fogray_fit::render::CHUNK;
use fogray_ops::limits::{self, Bytes, GridShape};
use fogray_ops::{Intrinsics, PinholeCamera};

use crate::error::CliError;

/// Bytes a render of `frames` frames, the largest `width x height`, from the model `info`
/// describes holds at its peak.
pub fn render_need(info: &ModelInfo, frames: usize, [width, height]: [usize; 2]) -> Bytes {
    let grid = GridShape {
        nodes: info.nodes.max(info.settings.grid),
        channels: limits::grid_channels(info.settings.sh_degree),
        float_bytes: info.settings.precision.bytes(),
    };
    let rays = CHUNK.min(width.saturating_mul(height));
    limits::render_bytes(frames, width, height).plus(grid.render_chunk_bytes(rays))
}

/// Checks an orbit of `frames` frames of intrinsics `k` before its cameras are built.
///
/// Errors: [`CliError::TooLarge`] naming `--orbit` and the size.
pub fn check_orbit(info: &ModelInfo, frames: usize, k: &Intrinsics) -> Result<(), CliError> {
    let need = render_need(info, frames, [k.width, k.height]);
    let what = format!("--orbit {frames} at {}x{}", k.width, k.height);
    Ok(Bytes::check(
        need,
        limits::available(),
        &what,
        "the frames' cameras and a frame's pixels",
    )?)
}

/// Checks the frames of the cameras file `file` (none: an orbit, checked already).
///
/// Errors: [`CliError::TooLarge`] naming the file, the frame count and the largest frame.
pub fn check_cameras<'a>(
    info: &ModelInfo,
    file: Option<&Path>,
    cameras: impl Iterator<Item = &'a PinholeCamera>,
) -> Result<(), CliError> {
    let Some(file) = file else {
        return Ok(());
    };
    let (mut frames, mut largest) = (0usize, [0usize; 2]);
    for camera in cameras {
        let k = camera.intrinsics();
        frames += 1;
        if k.width.saturating_mul(k.height) > largest[0].saturating_mul(largest[1]) {
            largest = [k.width, k.height];
        }
    }
    let need = render_need(info, frames, largest);
    let what = format!(
        "{}: {frames} frames, the largest {}x{},",
        fogray_data::shown(file),
        largest[0],
        largest[1]
    );
    Ok(Bytes::check(need, limits::available(), &what, "rendering")?)
}
