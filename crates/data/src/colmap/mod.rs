//! COLMAP sparse models: a capture folder `DIR` with the model in `DIR/sparse/0`, `DIR/sparse`
//! or `DIR/colmap/sparse/0` (the first that holds `cameras.bin` or `cameras.txt`; binary
//! when `cameras.bin` is there, then `images.bin` and `points3D.bin` too, else the `.txt`
//! files) and the photographs in `DIR/images` under the names the model registers.
//!
//! - Cameras: SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL and OPENCV (OpenCV's
//!   radial-tangential lens, fogray's [`LensDistortion`](crate::LensDistortion)); other models are
//!   refused by name. One camera may serve every image, or each its own.
//! - Poses: COLMAP stores world-to-camera `x_cam = R(q) x + t` in OpenCV axes (x right, y
//!   down, z forward), so the camera centre is `-Rᵀ t`. The cameras are then moved into a
//!   normalised world ([`WorldTransform`](crate::WorldTransform), see
//!   [`crate::world`]); `points3D` (optional) is moved with them.
//! - Order and split: views ordered by image name, every eighth (`i % 8 == 0`) held out.
//! - Pictures: `DIR/images`, or `DIR/images_K` for a downscale of `K` when it holds every
//!   registered image at the full size divided by `K` (see [`ImageSource`]).

mod binary;
mod model;
mod text;

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

pub(crate) use model::ModelFiles;
use model::{Camera, Image, Point};

use crate::capture::{choose, count_unregistered, Capture, CaptureFrame, FullSizeReason, PointCloud};
use crate::error::DataError;
use crate::escape::escape_controls;
use crate::picture::dimensions;
use crate::pose::flip_yz;
use crate::spec::{FrameSpec, Lens};
use crate::world::{normalising, COLMAP_TURN};

/// Where a model is looked for below a capture folder, in order.
const MODEL_FOLDERS: [&str; 3] = ["sparse/0", "sparse", "colmap/sparse/0"];

/// The model files below the capture folder `dir`, if there is a model.
pub(crate) fn locate(dir: &Path) -> Option<ModelFiles> {
    MODEL_FOLDERS.iter().find_map(|sub| {
        let folder = dir.join(sub);
        [(true, "bin"), (false, "txt")].into_iter().find_map(|(binary, ext)| {
            let cameras = folder.join(format!("cameras.{ext}"));
            cameras.is_file().then(|| ModelFiles {
                cameras,
                images: folder.join(format!("images.{ext}")),
                points: folder.join(format!("points3D.{ext}")),
                binary,
            })
        })
    })
}

/// The capture in `dir` whose model is `files`, for `downscale`. With `for_load`, the points
/// are read, the unregistered images counted and the images folder required to exist;
/// without, only what cameras need is read.
pub(crate) fn capture(dir: &Path, files: &ModelFiles, downscale: usize, for_load: bool) -> Result<Capture, DataError> {
    let (cameras, mut images) = if files.binary {
        (binary::cameras(&files.cameras)?, binary::images(&files.images)?)
    } else {
        (text::cameras(&files.cameras)?, text::images(&files.images)?)
    };
    check_images(files, &cameras, &images)?;
    images.sort_by(|a, b| a.name.cmp(&b.name));
    let poses: Vec<_> = images.iter().map(Image::camera_to_world).collect();
    let world = normalising(&poses, COLMAP_TURN);

    let mut prescaled_files = Vec::new();
    let source = choose(dir, downscale, |folder| {
        prescaled(folder, downscale, &images, &cameras, &mut prescaled_files)
    })?;
    let (folder, factor) = (source.folder().unwrap_or(dir).to_path_buf(), source.prescaled());
    if for_load && !folder.is_dir() {
        return Err(DataError::MissingFolder {
            path: folder,
            what: "the capture's images",
        });
    }
    let frames = images
        .iter()
        .zip(&poses)
        .enumerate()
        .map(|(i, (image, pose))| {
            let camera = &cameras[&image.camera];
            let (file, size) = match prescaled_files.get(i) {
                Some(found) => found.clone(),
                None => (folder.join(&image.name), (camera.width, camera.height)),
            };
            let pose = flip_yz(world.apply_pose(*pose));
            CaptureFrame {
                spec: spec(&files.cameras, file, image, camera, pose, factor, size),
                bounds: None,
            }
        })
        .collect::<Vec<_>>();

    let (points, unregistered) = if for_load {
        let registered: HashSet<PathBuf> = frames.iter().map(|f| f.spec.file.clone()).collect();
        (read_points(files, &world)?, count_unregistered(&folder, &registered)?)
    } else {
        (None, 0)
    };
    Ok(Capture {
        frames,
        downscale: downscale / factor,
        source,
        world,
        points,
        unregistered,
        registry: files.images.clone(),
    })
}

/// Errors: no images, an id or a name given twice, an image whose camera is not in `cameras`.
fn check_images(files: &ModelFiles, cameras: &HashMap<i64, Camera>, images: &[Image]) -> Result<(), DataError> {
    if images.is_empty() {
        return Err(DataError::NoFrames {
            path: files.images.clone(),
        });
    }
    let (mut ids, mut names) = (HashSet::new(), HashSet::new());
    for image in images {
        let twice = if !ids.insert(image.id) {
            Some(format!("image id {} appears twice", image.id))
        } else if !names.insert(image.name.as_str()) {
            Some(format!("image name `{}` appears twice", escape_controls(&image.name)))
        } else {
            None
        };
        if let Some(message) = twice {
            return Err(DataError::Malformed {
                path: files.images.clone(),
                at: format!("image {}", image.id),
                message,
            });
        }
        if !cameras.contains_key(&image.camera) {
            return Err(DataError::UnknownCamera {
                path: files.images.clone(),
                image: image.name.clone(),
                camera: image.camera,
                cameras: files.cameras.clone(),
            });
        }
    }
    Ok(())
}

/// Why `folder` (`images_K`) cannot serve the images, or `None` when it holds every one at
/// the full size divided by `K` (rounded either way), each file and its size pushed to
/// `found`. An image is looked for under its registered name, then with the extension `png`
/// (LLFF's `minify` and COLMAP-based scripts convert the smaller copies to PNG).
fn prescaled(
    folder: &Path,
    factor: usize,
    images: &[Image],
    cameras: &HashMap<i64, Camera>,
    found: &mut Vec<(PathBuf, (usize, usize))>,
) -> Result<Option<FullSizeReason>, DataError> {
    let locate = |image: &Image| -> Result<PathBuf, PathBuf> {
        let file = folder.join(&image.name);
        let png = file.with_extension("png");
        if file.is_file() {
            Ok(file)
        } else if png.is_file() {
            Ok(png)
        } else {
            Err(file)
        }
    };
    let (files, missing): (Vec<_>, Vec<_>) = images.iter().map(locate).partition(Result::is_ok);
    if let Some(Err(first)) = missing.first() {
        return Ok(Some(FullSizeReason::Incomplete {
            folder: folder.to_path_buf(),
            missing: missing.len(),
            first: first.clone(),
        }));
    }
    let divided = |actual: usize, full: usize| actual == full / factor || actual == full.div_ceil(factor);
    for (image, file) in images.iter().zip(files.into_iter().flatten()) {
        let size = dimensions(&file)?;
        let camera = &cameras[&image.camera];
        if !(divided(size.0, camera.width) && divided(size.1, camera.height)) {
            found.clear();
            return Ok(Some(FullSizeReason::OtherSize {
                file,
                size,
                full: (camera.width, camera.height),
            }));
        }
        found.push((file, size));
    }
    Ok(None)
}

/// The frame of `image`: its `file`, its normalised OpenGL `pose`, its camera's intrinsics
/// divided by `factor` (the folder's own downscale) for pictures of `size`.
fn spec(
    cameras_file: &Path,
    file: PathBuf,
    image: &Image,
    camera: &Camera,
    pose: [[f64; 4]; 4],
    factor: usize,
    size: (usize, usize),
) -> FrameSpec {
    let k = factor as f64;
    FrameSpec {
        transforms: cameras_file.to_path_buf(),
        key: format!("image `{}`", escape_controls(&image.name)),
        name: Path::new(&image.name)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| image.name.clone()),
        file,
        pose,
        lens: Lens {
            fl_x: Some(camera.fx / k),
            fl_y: Some(camera.fy / k),
            cx: Some(camera.cx / k),
            cy: Some(camera.cy / k),
            ..Lens::default()
        },
        distortion: camera.distortion,
        size: Some(size),
    }
}

/// The model's points moved into the normalised world; `None` without a points file.
fn read_points(files: &ModelFiles, world: &crate::WorldTransform) -> Result<Option<PointCloud>, DataError> {
    if !files.points.is_file() {
        return Ok(None);
    }
    let points: Vec<Point> = if files.binary {
        binary::points(&files.points)?
    } else {
        text::points(&files.points)?
    };
    Ok(Some(PointCloud {
        positions: points.iter().map(|p| world.apply_point(p.position)).collect(),
        colors: points.iter().map(|p| p.color).collect(),
    }))
}
