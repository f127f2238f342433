//! What a path given to [`load`](crate::load) names: a Blender folder, an instant-ngp /
//! nerfstudio folder, or a transforms file of either; a COLMAP capture folder; an LLFF capture
//! folder or its `poses_bounds.npy`.

use std::path::{Path, PathBuf};

use crate::blender::{looks_like_blender, split_file};
use crate::colmap::{self, ModelFiles};
use crate::error::DataError;
use crate::llff::POSES_FILE;

/// The dataset a path names.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Source {
    /// A Blender folder (its `transforms_train.json` exists).
    BlenderFolder(PathBuf),
    /// A single `transforms_*.json` of a Blender folder.
    BlenderFile(PathBuf),
    /// An instant-ngp / nerfstudio transforms file.
    Ngp(PathBuf),
    /// A COLMAP capture folder and its model's files.
    Colmap { dir: PathBuf, model: ModelFiles },
    /// An LLFF capture folder (its `poses_bounds.npy` exists).
    Llff(PathBuf),
}

/// Resolves `path`: a folder with `transforms.json` is instant-ngp (that file wins over
/// Blender split files beside it, as the tools that write both mean it to); a folder with
/// `transforms_train.json` is Blender; then a folder with a COLMAP model is COLMAP (a
/// transforms file beside a model was made from it, and says what the user chose); then a
/// folder with `poses_bounds.npy` is LLFF (LLFF's scripts leave the COLMAP model they ran
/// beside it, which is read first: the same cameras with their lens). A file named
/// `poses_bounds.npy` is its folder's LLFF capture; a file `transforms_*.json` with
/// `camera_angle_x` and no `fl_x` is Blender; any other file is instant-ngp.
///
/// Errors: a path that does not exist, a folder with none of these.
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
        if let Some(model) = colmap::locate(path) {
            return Ok(Source::Colmap {
                dir: path.to_path_buf(),
                model,
            });
        }
        if path.join(POSES_FILE).is_file() {
            return Ok(Source::Llff(path.to_path_buf()));
        }
        return Err(DataError::NoTransforms {
            path: path.to_path_buf(),
        });
    }
    if path.file_name().is_some_and(|n| n == POSES_FILE) {
        return Ok(Source::Llff(path.parent().unwrap_or(Path::new(".")).to_path_buf()));
    }
    if looks_like_blender(path) {
        Ok(Source::BlenderFile(path.to_path_buf()))
    } else {
        Ok(Source::Ngp(path.to_path_buf()))
    }
}
