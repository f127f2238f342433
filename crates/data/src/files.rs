//! The files a dataset is made of: its folder, its transforms files and every picture they
//! name, found without decoding a picture, so that a command can keep its outputs off them
//! (see [`Inputs::dataset`](crate::Inputs::dataset)).

use std::path::{Path, PathBuf};

use crate::blender::{self, split_file, SPLITS};
use crate::colmap;
use crate::error::DataError;
use crate::llff;
use crate::ngp;
use crate::resolve::{resolve, Source};

/// What a dataset on disk is made of.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct DatasetFiles {
    /// The dataset's folder, when the path given was a folder (a transforms file given alone
    /// names its files, not the folder it lies in).
    pub folder: Option<PathBuf>,
    /// Its transforms files.
    pub transforms: Vec<PathBuf>,
    /// The picture of every frame, whether the file exists or not, in the files' order.
    pub pictures: Vec<PathBuf>,
}

/// The files of the dataset at `path`, as [`load`](crate::load) and
/// [`load_cameras`](crate::load_cameras) read it: a Blender folder's `train`, `val` and `test`
/// files, an instant-ngp folder's `transforms.json`, or a transforms file alone; a COLMAP
/// capture's model files and registered full-size images; an LLFF capture's
/// `poses_bounds.npy` and full-size images.
///
/// Errors: as [`load_cameras`](crate::load_cameras) for a path that does not exist, a folder
/// without a transforms file, a transforms file that does not parse.
pub fn dataset_files(path: &Path) -> Result<DatasetFiles, DataError> {
    let folder = path.is_dir().then(|| path.to_path_buf());
    let mut files = DatasetFiles {
        folder,
        ..DatasetFiles::default()
    };
    match resolve(path)? {
        Source::BlenderFolder(dir) => {
            for split in SPLITS {
                let file = split_file(&dir, split);
                if split == "train" || file.is_file() {
                    files
                        .pictures
                        .extend(blender::read(&file)?.frames.into_iter().map(|s| s.file));
                    files.transforms.push(file);
                }
            }
        }
        Source::BlenderFile(file) => {
            files.pictures = blender::read(&file)?.frames.into_iter().map(|s| s.file).collect();
            files.transforms.push(file);
        }
        Source::Ngp(file) => {
            files.pictures = ngp::read(&file)?.frames.into_iter().map(|s| s.file).collect();
            files.transforms.push(file);
        }
        Source::Colmap { dir, model } => {
            let capture = colmap::capture(&dir, &model, 1, false)?;
            files.pictures = capture.frames.into_iter().map(|f| f.spec.file).collect();
            files.transforms = [model.cameras, model.images, model.points]
                .into_iter()
                .filter(|f| f.is_file())
                .collect();
        }
        Source::Llff(dir) => {
            let capture = llff::capture(&dir, 1)?;
            files.pictures = capture.frames.into_iter().map(|f| f.spec.file).collect();
            files.transforms.push(capture.registry);
        }
    }
    Ok(files)
}
