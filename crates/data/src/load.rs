//! Loading a dataset: cameras and decoded images, split into train and test.

use std::path::{Path, PathBuf};

use fogray_ops::PinholeCamera;

use crate::blender::{self, split_file, BLENDER_SCENE_BOX, SPLITS};
use crate::capture::{self, DepthBounds, ImageSource, PointCloud};
use crate::colmap;
use crate::error::DataError;
use crate::llff;
use crate::ngp;
use crate::picture::{dimensions, Picture};
use crate::pictures::{decode_pictures, LoadProgress};
use crate::resolve::{resolve, Source};
use crate::spec::FrameSpec;
use crate::split::holdout;
use crate::world::WorldTransform;

/// How many missing image files an error lists by name (the count says how many in all).
pub(crate) const MISSING_LISTED: usize = 5;

/// How to load a dataset.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadOptions {
    /// Integer factor (at least 1) by which images are shrunk, each `downscale x downscale`
    /// block averaged (see [`downscale_picture`](crate::downscale_picture)), and intrinsics
    /// divided. Default 1. A COLMAP or LLFF capture whose `images_K` folder (`K` this factor)
    /// holds every picture is read from that folder as stored instead (see [`ImageSource`]).
    pub downscale: usize,
    /// RGB in `[0, 1]` that images with alpha are composited over. Default white.
    pub background: [f64; 3],
    /// Drop the frames whose image file does not exist (counted in
    /// [`SceneData::skipped`]) instead of failing (a COLMAP image registered but not on
    /// disk likewise). Default false.
    pub skip_missing: bool,
    /// Bytes per float of the copy the caller will make of every frame's colour and alpha once
    /// loaded (a fit's `f64` views: 8); 0, the default, for a caller that keeps the frames as
    /// they are. The copies are counted with the frames in the check of the machine's memory,
    /// so that frames whose copies cannot fit are refused before any is copied.
    pub copy_float_bytes: usize,
}

impl Default for LoadOptions {
    fn default() -> Self {
        LoadOptions {
            downscale: 1,
            background: [1.0; 3],
            skip_missing: false,
            copy_float_bytes: 0,
        }
    }
}

/// Which format a dataset was read as.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum Format {
    /// Blender / NeRF-synthetic: `transforms_{train,val,test}.json`.
    Blender,
    /// instant-ngp / nerfstudio: one `transforms.json`.
    InstantNgp,
    /// A COLMAP sparse model (`sparse/0`, `sparse` or `colmap/sparse/0`) beside `images/`.
    Colmap,
    /// LLFF: `poses_bounds.npy` beside `images/`.
    Llff,
}

/// One view: its camera and its image.
#[derive(Debug, Clone)]
pub struct Frame {
    /// `file_path` without folder and extension (`r_0` for `./train/r_0`).
    pub name: String,
    /// The image file read.
    pub file: PathBuf,
    /// The camera, its intrinsics downscaled with the image (OpenCV axes inside; see
    /// [`PinholeCamera`]).
    pub camera: PinholeCamera,
    /// The image, `camera.intrinsics().height x width`.
    pub picture: Picture,
    /// The depths at which the view sees the scene, where the format stores them (LLFF).
    pub depth_bounds: Option<DepthBounds>,
}

/// A loaded dataset.
#[derive(Debug, Clone)]
pub struct SceneData {
    /// The format it was read as.
    pub format: Format,
    /// The training views.
    pub train: Vec<Frame>,
    /// The held-out views.
    pub test: Vec<Frame>,
    /// The box (min, max corners, world coordinates) that holds the scene: `[-1.5, 1.5]^3`
    /// for Blender, from `aabb_scale` for instant-ngp (see the crate docs), `[-1, 1]^3` for
    /// COLMAP and LLFF ([`CAPTURE_SCENE_BOX`](crate::CAPTURE_SCENE_BOX)).
    pub scene_box: ([f64; 3], [f64; 3]),
    /// Frames dropped because their image file did not exist (only with
    /// [`LoadOptions::skip_missing`]).
    pub skipped: usize,
    /// The transform from the file's world to the cameras' (and the box's and points'):
    /// the identity for Blender and instant-ngp, the normalisation of a COLMAP or LLFF
    /// capture's arbitrary world (see the crate docs).
    pub world: WorldTransform,
    /// COLMAP's sparse points (`points3D`), in the cameras' world; `None` for the other
    /// formats or a model without a points file.
    pub points: Option<PointCloud>,
    /// Image files in a COLMAP capture's images folder that the model does not register
    /// (they are not read); 0 for the other formats.
    pub unregistered: usize,
    /// Where the pictures were read from, and why (a capture's `images` or `images_K`).
    pub images: ImageSource,
}

/// A camera of a transforms file, read without its image.
#[derive(Debug, Clone, PartialEq)]
pub struct NamedCamera {
    /// `file_path` without folder and extension.
    pub name: String,
    /// The camera.
    pub camera: PinholeCamera,
}

/// Loads the dataset at `path`: a folder, recognised by what it holds, in this order: a
/// `transforms.json` (instant-ngp / nerfstudio), a `transforms_train.json` (Blender), a COLMAP
/// model (`sparse/0`, `sparse` or `colmap/sparse/0` holding `cameras.bin` or `cameras.txt`),
/// a `poses_bounds.npy` (LLFF); or a transforms file (a `transforms_*.json` with
/// `camera_angle_x` and no `fl_x` loads its folder as Blender; any other as instant-ngp); or a
/// `poses_bounds.npy` (its folder as LLFF). Images are decoded in parallel.
///
/// Splits: Blender's train is `transforms_train.json`, its test `transforms_test.json`, else
/// `transforms_val.json`, else every eighth train frame (`i % 8 == 0`, then held out of
/// train); instant-ngp's, COLMAP's and LLFF's test is every eighth frame (COLMAP's and LLFF's
/// in image-name order) and their train the rest.
///
/// Pictures are checked against the machine's memory before any is decoded (see
/// [`fogray_ops::limits`]), and frames naming the same picture share one decoding.
///
/// Errors: see [`DataError`]; each names the file at fault: among them
/// [`DataError::TooLarge`] for pictures the machine cannot hold and
/// [`DataError::TooFewFrames`] for a dataset without a frame to train on and one to hold out.
pub fn load(path: &Path, options: &LoadOptions) -> Result<SceneData, DataError> {
    let scene = load_scene(path, options)?;
    if scene.train.is_empty() || scene.test.is_empty() {
        let named = match resolve(path)? {
            Source::Ngp(file) | Source::BlenderFile(file) => file,
            Source::BlenderFolder(folder) => split_file(&folder, "train"),
            #[allow(unreachable_patterns)] // the formats read from a folder
            _ => path.to_path_buf(),
        };
        return Err(DataError::TooFewFrames {
            path: named,
            frames: scene.train.len() + scene.test.len(),
            skipped: scene.skipped,
        });
    }
    Ok(scene)
}

/// [`load`], telling `progress` of each picture decoded (from the decoding threads; counted
/// per transforms file, or per Blender split), so that a command line can show how far a
/// load of many frames has come.
///
/// Errors: as [`load`].
pub fn load_with_progress(
    path: &Path,
    options: &LoadOptions,
    progress: impl Fn(LoadProgress) + Send + Sync + 'static,
) -> Result<SceneData, DataError> {
    crate::pictures::with_progress(std::sync::Arc::new(progress), || load(path, options))
}

/// [`load`] without its count of the frames.
fn load_scene(path: &Path, options: &LoadOptions) -> Result<SceneData, DataError> {
    check_downscale(path, options.downscale)?;
    match resolve(path)? {
        Source::BlenderFolder(folder) => load_blender(&folder, options),
        Source::BlenderFile(file) => load_blender(file.parent().unwrap_or(Path::new(".")), options),
        Source::Ngp(file) => {
            let parsed = ngp::read(&file)?;
            let (specs, skipped) = drop_missing(&file, parsed.frames, options.skip_missing)?;
            let frames = load_frames(&specs, options, false)?;
            let (train, test) = holdout(frames);
            Ok(SceneData {
                format: Format::InstantNgp,
                train,
                test,
                scene_box: parsed.scene_box,
                skipped,
                world: WorldTransform::IDENTITY,
                points: None,
                unregistered: 0,
                images: ImageSource::Listed,
            })
        }
        Source::Colmap { dir, model } => capture::load(
            colmap::capture(&dir, &model, options.downscale, true)?,
            options,
            Format::Colmap,
        ),
        Source::Llff(dir) => capture::load(llff::capture(&dir, options.downscale)?, options, Format::Llff),
    }
}

fn load_blender(folder: &Path, options: &LoadOptions) -> Result<SceneData, DataError> {
    let mut skipped = 0;
    let mut load_split = |file: &Path| -> Result<Vec<Frame>, DataError> {
        let (specs, dropped) = drop_missing(file, blender::read(file)?.frames, options.skip_missing)?;
        skipped += dropped;
        load_frames(&specs, options, true)
    };
    let train = load_split(&split_file(folder, "train"))?;
    let held_out = ["test", "val"]
        .map(|s| split_file(folder, s))
        .into_iter()
        .find(|f| f.is_file());
    let (train, test) = match held_out {
        Some(file) => (train, load_split(&file)?),
        None => holdout(train),
    };
    Ok(SceneData {
        format: Format::Blender,
        train,
        test,
        scene_box: BLENDER_SCENE_BOX,
        skipped,
        world: WorldTransform::IDENTITY,
        points: None,
        unregistered: 0,
        images: ImageSource::Listed,
    })
}

fn check_downscale(path: &Path, downscale: usize) -> Result<(), DataError> {
    if downscale == 0 {
        return Err(DataError::BadDownscale {
            path: path.to_path_buf(),
            downscale,
            problem: "must be at least 1",
        });
    }
    Ok(())
}

/// `specs` less those whose image file does not exist, and how many those were; without
/// `skip`, any missing is an error listing the first few.
fn drop_missing(transforms: &Path, specs: Vec<FrameSpec>, skip: bool) -> Result<(Vec<FrameSpec>, usize), DataError> {
    let (present, missing): (Vec<_>, Vec<_>) = specs.into_iter().partition(|s| s.file.is_file());
    if !missing.is_empty() && !skip {
        return Err(DataError::MissingImages {
            path: transforms.to_path_buf(),
            count: missing.len(),
            first: missing.iter().take(MISSING_LISTED).map(|s| s.file.clone()).collect(),
        });
    }
    Ok((present, missing.len()))
}

/// Decodes, checks and downscales every frame's image (in parallel, each file once, within
/// the machine's memory: [`decode_pictures`]) and builds its camera.
/// With `same_size` (a Blender split) every image must have the first one's size; otherwise
/// each must match its frame's `w` / `h` where given.
pub(crate) fn load_frames(
    specs: &[FrameSpec],
    options: &LoadOptions,
    same_size: bool,
) -> Result<Vec<Frame>, DataError> {
    let factor = options.downscale;
    let decoded = decode_pictures(specs, factor, options.background, options.copy_float_bytes)?;
    let mut frames = Vec::with_capacity(specs.len());
    let mut first: Option<(&Path, (usize, usize))> = None;
    for (spec, (size, picture)) in specs.iter().zip(decoded) {
        check_size(spec, size, same_size, &mut first)?;
        frames.push(Frame {
            name: spec.name.clone(),
            file: spec.file.clone(),
            camera: spec.camera(size.0, size.1, factor)?,
            picture,
            depth_bounds: None,
        });
    }
    Ok(frames)
}

fn check_size<'a>(
    spec: &'a FrameSpec,
    size: (usize, usize),
    same_size: bool,
    first: &mut Option<(&'a Path, (usize, usize))>,
) -> Result<(), DataError> {
    if let Some(expected) = spec.size {
        if expected != size {
            return Err(DataError::SizeMismatch {
                path: spec.file.clone(),
                size,
                transforms: spec.transforms.clone(),
                expected,
            });
        }
    }
    if same_size {
        match first {
            None => *first = Some((&spec.file, size)),
            Some((path, first_size)) if *first_size != size => {
                return Err(DataError::MixedSizes {
                    path: spec.file.clone(),
                    size,
                    first: path.to_path_buf(),
                    first_size: *first_size,
                })
            }
            Some(_) => {}
        }
    }
    Ok(())
}

/// The cameras of every frame at `path`, without decoding any image, downscaled by
/// `downscale`: a transforms file's frames, or a Blender folder's `train`, `val` and `test`
/// files in that order (an instant-ngp folder: its `transforms.json`), or a COLMAP or LLFF
/// capture's views in image-name order (the same cameras, in the same normalised world, as
/// [`load`] gives; a capture's registered images need not exist, LLFF's must).
///
/// Image sizes come from the file's `w` / `h` (instant-ngp, COLMAP), else from the header of
/// the image file (for Blender, the first existing image of each split file, whose size the
/// format says all its images share; for a capture read from `images_K` and for LLFF, each
/// image's), else, for Blender, the top-level `w` / `h`.
///
/// Errors: as [`load`], and [`DataError::NoImageSize`] where no size can be found.
pub fn load_cameras(path: &Path, downscale: usize) -> Result<Vec<NamedCamera>, DataError> {
    check_downscale(path, downscale)?;
    match resolve(path)? {
        Source::BlenderFolder(folder) => {
            let mut all = Vec::new();
            for split in SPLITS {
                let file = split_file(&folder, split);
                if split == "train" || file.is_file() {
                    all.extend(blender_cameras(&file, downscale)?);
                }
            }
            Ok(all)
        }
        Source::BlenderFile(file) => blender_cameras(&file, downscale),
        Source::Ngp(file) => ngp::read(&file)?
            .frames
            .iter()
            .map(|spec| {
                let (w, h) = match spec.size {
                    Some(size) => size,
                    None if spec.file.is_file() => dimensions(&spec.file)?,
                    None => return Err(DataError::NoImageSize { path: file.clone() }),
                };
                named(spec, w, h, downscale)
            })
            .collect(),
        Source::Colmap { dir, model } => capture::cameras(&colmap::capture(&dir, &model, downscale, false)?),
        Source::Llff(dir) => capture::cameras(&llff::capture(&dir, downscale)?),
    }
}

/// Which of a dataset's frames to take: all of them, the ones a fit trains on, or the ones it
/// holds out (`fogray render --split`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Split {
    /// Every frame, as [`load_cameras`] lists them.
    #[default]
    All,
    /// The frames [`load`] trains on.
    Train,
    /// The frames [`load`] holds out: a Blender folder's test split (else its val split, else
    /// every eighth train frame), every eighth frame of any other format (`i % 8 == 0`).
    Test,
}

/// The cameras of the frames of `split` at `path`, downscaled by `downscale`, in the order of
/// [`load_cameras`]; the train and test frames are those [`load`] trains on and holds out (a
/// Blender split file stands for its folder, as in [`load`]).
///
/// Errors: as [`load_cameras`].
pub fn load_split_cameras(path: &Path, downscale: usize, split: Split) -> Result<Vec<NamedCamera>, DataError> {
    if split == Split::All {
        return load_cameras(path, downscale);
    }
    check_downscale(path, downscale)?;
    let folder = match resolve(path)? {
        Source::BlenderFolder(folder) => Some(folder),
        Source::BlenderFile(file) => Some(file.parent().unwrap_or(Path::new(".")).to_path_buf()),
        _ => None,
    };
    let (train, test) = match folder {
        Some(folder) => {
            let train = blender_cameras(&split_file(&folder, "train"), downscale)?;
            match ["test", "val"]
                .map(|s| split_file(&folder, s))
                .into_iter()
                .find(|f| f.is_file())
            {
                Some(file) => (train, blender_cameras(&file, downscale)?),
                None => holdout(train),
            }
        }
        None => holdout(load_cameras(path, downscale)?),
    };
    Ok(if split == Split::Train { train } else { test })
}

fn blender_cameras(file: &Path, downscale: usize) -> Result<Vec<NamedCamera>, DataError> {
    let parsed = blender::read(file)?;
    let (w, h) = match parsed.frames.iter().find(|s| s.file.is_file()) {
        Some(spec) => dimensions(&spec.file)?,
        None => parsed.size.ok_or_else(|| DataError::NoImageSize {
            path: file.to_path_buf(),
        })?,
    };
    parsed.frames.iter().map(|spec| named(spec, w, h, downscale)).collect()
}

fn named(spec: &FrameSpec, w: usize, h: usize, downscale: usize) -> Result<NamedCamera, DataError> {
    Ok(NamedCamera {
        name: spec.name.clone(),
        camera: spec.camera(w, h, downscale)?,
    })
}
