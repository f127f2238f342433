//! The Blender / NeRF-synthetic format: a folder with `transforms_train.json` (required),
//! `transforms_val.json` and `transforms_test.json`, each with one `camera_angle_x`
//! (horizontal field of view, radians) and `frames` of `file_path` (relative to the folder,
//! `.png` appended when it has no extension) and `transform_matrix` (OpenGL camera-to-world).
//!
//! The image size is not in the file: it is the images' own, the same for a whole split.
//! Intrinsics: `fx = fy = W / (2 tan(camera_angle_x / 2))`, `cx = W / 2`, `cy = H / 2`.

use std::path::{Path, PathBuf};

use fogray_ops::LensDistortion;

use crate::error::DataError;
use crate::json::{self, Obj};
use crate::spec::{image_path, FrameSpec, Lens};

/// The Blender scene box, `[-1.5, 1.5]^3`: the synthetic scenes fit inside it.
pub const BLENDER_SCENE_BOX: ([f64; 3], [f64; 3]) = ([-1.5; 3], [1.5; 3]);

/// The split files of a Blender folder, in the order `train, val, test`.
pub(crate) const SPLITS: [&str; 3] = ["train", "val", "test"];

/// The path of a split's transforms file.
pub(crate) fn split_file(folder: &Path, split: &str) -> PathBuf {
    folder.join(format!("transforms_{split}.json"))
}

/// A parsed Blender transforms file: its frames, and its top-level `w` / `h` if present (only
/// used to size cameras read without their images).
pub(crate) struct BlenderFile {
    pub frames: Vec<FrameSpec>,
    pub size: Option<(usize, usize)>,
}

/// Reads the Blender transforms file `path`; image paths are relative to its folder.
pub(crate) fn read(path: &Path) -> Result<BlenderFile, DataError> {
    let root = json::read(path)?;
    let folder = path.parent().unwrap_or(Path::new("."));
    let top = Obj {
        path,
        map: &root,
        prefix: "",
    };
    let angle = Lens::read(top)?.angle_x.ok_or_else(|| top.missing("camera_angle_x"))?;
    let lens = Lens {
        angle_x: Some(angle),
        ..Lens::default()
    };
    let size = match (top.size("w")?, top.size("h")?) {
        (Some(w), Some(h)) => Some((w, h)),
        _ => None,
    };
    let frames = json::frames(path, &root)?
        .into_iter()
        .enumerate()
        .map(|(i, map)| {
            let prefix = format!("frames[{i}].");
            let frame = Obj {
                path,
                map,
                prefix: &prefix,
            };
            let file_path = frame.string("file_path")?.ok_or_else(|| frame.missing("file_path"))?;
            let pose = crate::pose::read_pose(frame, "transform_matrix")?;
            let (file, name) = image_path(folder, file_path, true);
            Ok(FrameSpec {
                transforms: path.to_path_buf(),
                key: format!("frames[{i}]"),
                name,
                file,
                pose,
                lens,
                distortion: LensDistortion::NONE,
                size: None,
            })
        })
        .collect::<Result<Vec<_>, DataError>>()?;
    Ok(BlenderFile { frames, size })
}

/// Whether the transforms file `path` (already known to exist) reads as Blender: named
/// `transforms_*.json`, with `camera_angle_x` and without `fl_x` at its top level. A file that
/// does not parse is left to the caller's reader to report.
pub(crate) fn looks_like_blender(path: &Path) -> bool {
    let named = path
        .file_name()
        .and_then(|n| n.to_str())
        .is_some_and(|n| n.starts_with("transforms_") && n.ends_with(".json"));
    if !named {
        return false;
    }
    match json::read(path) {
        Ok(root) => root.contains_key("camera_angle_x") && !root.contains_key("fl_x"),
        Err(_) => false,
    }
}
