//! What a path given to [`load`](crate::load) names: a Blender folder, an instant-ngp /
//! nerfstudio folder, or a transforms file of either.

use std::path::{Path, PathBuf};

use crate::blender::{looks_like_blender, split_file};
use crate::error::DataError;

/// The dataset a path names.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Source {
    /// A Blender folder (its `transforms_train.json` exists).
    BlenderFolder(PathBuf),
    /// A single `transforms_*.json` of a Blender folder.
    BlenderFile(PathBuf),
    /// An instant-ngp / nerfstudio transforms file.
    Ngp(PathBuf),
}

/// Resolves `path`: a folder with `transforms.json` is instant-ngp (that file wins over
/// Blender split files beside it, as the tools that write both mean it to); a folder with
/// `transforms_train.json` is Blender; a file `transforms_*.json` with `camera_angle_x` and no
/// `fl_x` is Blender; any other file is instant-ngp.
///
/// Errors: a path that does not exist, a folder with neither file.
pub(crate) fn resolve(path: &Path) -> Result<Source, DataError> {
    let meta = std::fs::metadata(path).map_err(|e| DataError::io(path, e))?;
    if meta.is_dir() {
        let ngp = path.join("transforms.json");
        if ngp.is_file() {
            return Ok(Source::Ngp(ngp));
        }
        if split_file(path, "train").is_file() {
            return Ok(Source::BlenderFolder(path.to_path_buf()));
        }
        return Err(DataError::NoTransforms {
            path: path.to_path_buf(),
        });
    }
    if looks_like_blender(path) {
        Ok(Source::BlenderFile(path.to_path_buf()))
    } else {
        Ok(Source::Ngp(path.to_path_buf()))
    }
}
