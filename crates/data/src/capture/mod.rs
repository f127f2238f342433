//! Captures: a folder of photographs and the cameras a reconstruction found for them (COLMAP's
//! sparse model, LLFF's `poses_bounds.npy`). Unlike a transforms file, a capture's world is
//! the reconstruction's arbitrary one, so its cameras are moved into a normalised world
//! ([`WorldTransform`]), and its pictures come from a folder chosen for the downscale
//! ([`ImageSource`]).
//!
//! Both formats end here as [`FrameSpec`]s, so that decoding, size checks and camera building
//! are the transforms files' own.

mod folder;
mod geometry;

use std::path::PathBuf;

pub(crate) use folder::{choose, count_unregistered, list_images};
pub use folder::{FullSizeReason, ImageSource};
pub use geometry::{DepthBounds, PointCloud};

use crate::error::DataError;
use crate::load::{load_frames, Format, LoadOptions, NamedCamera, SceneData, MISSING_LISTED};
use crate::spec::FrameSpec;
use crate::split::holdout;
use crate::world::WorldTransform;

/// The scene box of a capture, in its normalised world: `[-1, 1]^3`, the cube the cameras'
/// centres were scaled into (nerfstudio's box for COLMAP scenes, `scene_scale` 1).
pub const CAPTURE_SCENE_BOX: ([f64; 3], [f64; 3]) = ([-1.0; 3], [1.0; 3]);

/// One view of a capture, its image not yet read.
pub(crate) struct CaptureFrame {
    /// Its image file, normalised pose, lens and image size (always known).
    pub spec: FrameSpec,
    /// LLFF's depth bounds, in the normalised world.
    pub bounds: Option<DepthBounds>,
}

/// A capture read, its images not yet decoded.
pub(crate) struct Capture {
    /// The views, ordered by image file name.
    pub frames: Vec<CaptureFrame>,
    /// The downscale still to apply to the pictures read and their cameras (1 when the
    /// pictures come from `images_K`).
    pub downscale: usize,
    /// The folder the pictures come from, and why.
    pub source: ImageSource,
    /// The file's world to the normalised one.
    pub world: WorldTransform,
    /// COLMAP's sparse points, normalised.
    pub points: Option<PointCloud>,
    /// Image files in the folder read that no view registers.
    pub unregistered: usize,
    /// The file that lists the views (`images.bin`, `poses_bounds.npy`), named when images are
    /// missing.
    pub registry: PathBuf,
}

/// Decodes the pictures of `capture` (in parallel) and splits its views: every eighth
/// (`i % 8 == 0`, in image-name order) held out. Registered images missing on disk are an
/// error, or with [`LoadOptions::skip_missing`] dropped (before the split) and counted.
pub(crate) fn load(capture: Capture, options: &LoadOptions, format: Format) -> Result<SceneData, DataError> {
    let (present, missing): (Vec<_>, Vec<_>) = capture.frames.into_iter().partition(|f| f.spec.file.is_file());
    if !missing.is_empty() && !options.skip_missing {
        return Err(DataError::MissingImages {
            path: capture.registry,
            count: missing.len(),
            first: missing
                .iter()
                .take(MISSING_LISTED)
                .map(|f| f.spec.file.clone())
                .collect(),
        });
    }
    let (specs, bounds): (Vec<_>, Vec<_>) = present.into_iter().map(|f| (f.spec, f.bounds)).unzip();
    let remaining = LoadOptions {
        downscale: capture.downscale,
        ..options.clone()
    };
    let frames = load_frames(&specs, &remaining, false)?
        .into_iter()
        .zip(bounds)
        .map(|(mut frame, bounds)| {
            frame.depth_bounds = bounds;
            frame
        })
        .collect();
    let (train, test) = holdout(frames);
    Ok(SceneData {
        format,
        train,
        test,
        scene_box: CAPTURE_SCENE_BOX,
        skipped: missing.len(),
        world: capture.world,
        points: capture.points,
        unregistered: capture.unregistered,
        images: capture.source,
    })
}

/// The cameras of every view of `capture`, in image-name order, without decoding any image.
pub(crate) fn cameras(capture: &Capture) -> Result<Vec<NamedCamera>, DataError> {
    capture
        .frames
        .iter()
        .map(|f| {
            let (w, h) = f.spec.size.ok_or_else(|| DataError::NoImageSize {
                path: capture.registry.clone(),
            })?;
            Ok(NamedCamera {
                name: f.spec.name.clone(),
                camera: f.spec.camera(w, h, capture.downscale)?,
            })
        })
        .collect()
}
