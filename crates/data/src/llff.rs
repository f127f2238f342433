//! LLFF captures (the NeRF paper's forward-facing scenes, LLFF's `imgs2poses.py` output): a
//! folder `DIR` with `poses_bounds.npy` and the photographs in `DIR/images` (and smaller
//! copies in `DIR/images_4`, `DIR/images_8`...).
//!
//! `poses_bounds.npy` holds an `(N, 17)` array of `'<f8'`: per image, a 3x5 matrix row-major
//! `[R | c | hwf]` then the near and far depth bounds. `R`'s columns are the camera's
//! **down, right and backward** axes in the world (LLFF's convention), `c` its centre, and
//! `hwf = (H, W, focal)` the height, width and focal length (pixels) of the images the poses
//! were computed for. fogray's camera (OpenCV axes: x right, y down, z forward) takes
//! `x = R[:, 1]`, `y = R[:, 0]`, `z = -R[:, 2]`.
//!
//! The world is COLMAP's (LLFF runs COLMAP and keeps its world), so it is normalised as
//! COLMAP's is ([`crate::world`]); the bounds are scaled with it.
//!
//! Row `i` goes with the `i`-th image of the folder read, in file-name order (files ending in
//! `.png`, `.jpg`, `.jpeg`, any case); a count that differs is an error. Intrinsics are scaled
//! to each picture's own size `w x h`: `fx = focal w / W`, `fy = focal h / H`, principal point
//! at the centre `(w / 2, h / 2)`; a picture whose shape is not `W x H` scaled (to a pixel) is
//! an error. Views: every eighth held out (`i % 8 == 0`).

use std::path::{Path, PathBuf};

use crate::capture::{choose, list_images, Capture, CaptureFrame, DepthBounds, FullSizeReason, ImageSource};
use crate::error::DataError;
use crate::npy::{self, shape};
use crate::picture::dimensions;
use crate::pose::{check, flip_yz};
use crate::spec::{FrameSpec, Lens};
use crate::world::{normalising, COLMAP_TURN};

/// The file of an LLFF capture.
pub(crate) const POSES_FILE: &str = "poses_bounds.npy";

/// Values per image in the file.
const COLUMNS: usize = 17;

/// One row of the file, checked.
struct Row {
    /// OpenCV camera-to-world, in the file's world.
    pose: [[f64; 4]; 4],
    height: f64,
    width: f64,
    focal: f64,
    near: f64,
    far: f64,
}

impl Row {
    fn read(path: &Path, i: usize, r: &[f64]) -> Result<Row, DataError> {
        let m = |row: usize, col: usize| r[row * 5 + col];
        let bad = |what: &str, value: f64, rule| DataError::BadValue {
            path: path.to_path_buf(),
            key: format!("row {i} {what}"),
            value,
            rule,
        };
        // Columns: 0 down, 1 right, 2 backward, 3 centre, 4 hwf.
        let mut pose = [[0.0, 0.0, 0.0, 0.0], [0.0; 4], [0.0; 4], [0.0, 0.0, 0.0, 1.0]];
        for (k, row) in pose.iter_mut().take(3).enumerate() {
            *row = [m(k, 1), m(k, 0), -m(k, 2), m(k, 3)];
        }
        check(&pose).map_err(|problem| DataError::BadMatrix {
            path: path.to_path_buf(),
            key: format!("row {i} pose"),
            problem,
        })?;
        let (height, width, focal) = (m(0, 4), m(1, 4), m(2, 4));
        for (what, side) in [("height", height), ("width", width)] {
            if !(side.is_finite() && (1.0..=u32::MAX as f64).contains(&side)) {
                return Err(bad(what, side, "must be from 1 to 2^32 - 1"));
            }
        }
        if !(focal.is_finite() && focal > 0.0) {
            return Err(bad("focal", focal, "a focal length must be positive and finite"));
        }
        let (near, far) = (r[15], r[16]);
        if !(near.is_finite() && near >= 0.0) {
            return Err(bad("near", near, "must be finite and not negative"));
        }
        if !(far.is_finite() && far >= near) {
            return Err(bad("far", far, "must be finite and not below near"));
        }
        Ok(Row {
            pose,
            height,
            width,
            focal,
            near,
            far,
        })
    }
}

/// The capture in `dir` (which holds [`POSES_FILE`]) for `downscale`: `images_K` when it holds
/// as many images as there are rows, else `images`.
pub(crate) fn capture(dir: &Path, downscale: usize) -> Result<Capture, DataError> {
    let path = dir.join(POSES_FILE);
    let array = npy::read_f64(&path)?;
    if !matches!(array.shape[..], [n, COLUMNS] if n > 0) {
        return Err(DataError::BadArray {
            path,
            what: "the shape",
            found: shape(&array.shape),
            expected: "(N, 17) with N at least 1",
        });
    }
    let rows = array
        .data
        .chunks_exact(COLUMNS)
        .enumerate()
        .map(|(i, r)| Row::read(&path, i, r))
        .collect::<Result<Vec<_>, _>>()?;
    let poses: Vec<_> = rows.iter().map(|r| r.pose).collect();
    let world = normalising(&poses, COLMAP_TURN);

    let mut prescaled_files = Vec::new();
    let source = choose(dir, downscale, |folder| {
        let files = list_images(folder)?;
        if files.len() != rows.len() {
            return Ok(Some(FullSizeReason::OtherCount {
                folder: folder.to_path_buf(),
                images: files.len(),
                poses: rows.len(),
            }));
        }
        prescaled_files = files;
        Ok(None)
    })?;
    let files = match &source {
        ImageSource::Prescaled { .. } => prescaled_files,
        _ => full_size_files(&path, source.folder().unwrap_or(dir), rows.len())?,
    };
    let frames = rows
        .iter()
        .zip(files)
        .enumerate()
        .map(|(i, (row, file))| frame(&path, i, row, file, &world))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Capture {
        frames,
        downscale: downscale / source.prescaled(),
        source,
        world,
        points: None,
        unregistered: 0,
        registry: path,
    })
}

/// The images of the full-size `folder`, one per row. Errors: no folder, another count.
fn full_size_files(path: &Path, folder: &Path, rows: usize) -> Result<Vec<PathBuf>, DataError> {
    if !folder.is_dir() {
        return Err(DataError::MissingFolder {
            path: folder.to_path_buf(),
            what: "the capture's images",
        });
    }
    let files = list_images(folder)?;
    if files.len() != rows {
        return Err(DataError::ImageCount {
            path: path.to_path_buf(),
            poses: rows,
            folder: folder.to_path_buf(),
            images: files.len(),
        });
    }
    Ok(files)
}

/// The frame of row `i` for the image `file`, its intrinsics scaled to the image's size.
fn frame(
    path: &Path,
    i: usize,
    row: &Row,
    file: PathBuf,
    world: &crate::WorldTransform,
) -> Result<CaptureFrame, DataError> {
    let (w, h) = dimensions(&file)?;
    // Within a pixel of the shape W x H scaled: |w H - h W| <= H + W.
    if ((w as f64) * row.height - (h as f64) * row.width).abs() > row.height + row.width {
        return Err(DataError::AspectMismatch {
            path: file,
            size: (w, h),
            poses: path.to_path_buf(),
            expected: (row.width, row.height),
        });
    }
    let name = file
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let spec = FrameSpec {
        transforms: path.to_path_buf(),
        key: format!("row {i}"),
        name,
        file,
        pose: flip_yz(world.apply_pose(row.pose)),
        lens: Lens {
            fl_x: Some(row.focal * w as f64 / row.width),
            fl_y: Some(row.focal * h as f64 / row.height),
            ..Lens::default()
        },
        distortion: fogray_ops::LensDistortion::NONE,
        size: Some((w, h)),
    };
    Ok(CaptureFrame {
        spec,
        bounds: Some(DepthBounds {
            near: row.near * world.scale,
            far: row.far * world.scale,
        }),
    })
}
