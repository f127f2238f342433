//! Which folder of a capture the pictures come from. Captures (COLMAP, LLFF) keep their
//! full-size photographs in `images/` and often smaller copies in `images_2/`, `images_4/`,
//! `images_8/` (made by COLMAP's and LLFF's scripts, by nerfstudio's `ns-process-data`, or
//! shipped with Mip-NeRF 360 and the LLFF scenes): reading `images_K` for a downscale of `K`
//! is quicker than decoding full-size photographs only to average them, and is what the
//! published results were computed on.

use std::collections::HashSet;
use std::fmt;
use std::path::{Path, PathBuf};

use crate::error::DataError;

/// The full-size folder of a capture.
const FULL_SIZE: &str = "images";

/// The image extensions a capture's folders are searched for (any case).
const EXTENSIONS: [&str; 3] = ["png", "jpg", "jpeg"];

/// How deep below a capture's image folder registered images are looked for when counting
/// the unregistered ones (COLMAP names may hold sub-folders; this bounds a symlink loop).
const MAX_DEPTH: usize = 8;

/// Where a dataset's pictures were read from, and why.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum ImageSource {
    /// Each frame's own image file, as its transforms file names it (Blender, instant-ngp).
    Listed,
    /// The capture's full-size folder, each picture downscaled on load by `downscale` (1: as
    /// it is) and the intrinsics divided by it.
    FullSize {
        /// The folder (`DIR/images`).
        folder: PathBuf,
        /// [`LoadOptions::downscale`](crate::LoadOptions::downscale).
        downscale: usize,
        /// Why no smaller copy was read.
        why: FullSizeReason,
    },
    /// A folder of pictures already downscaled by `factor` (`DIR/images_K` for a
    /// [`LoadOptions::downscale`](crate::LoadOptions::downscale) of `K`), read as they are;
    /// the full-size intrinsics are divided by `factor` instead.
    Prescaled {
        /// The folder.
        folder: PathBuf,
        /// `K`.
        factor: usize,
    },
}

/// Why a capture's pictures were read from its full-size folder.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum FullSizeReason {
    /// No downscale was asked.
    NotAsked,
    /// There is no `images_K` folder for the downscale asked.
    NoFolder {
        /// The folder looked for.
        folder: PathBuf,
    },
    /// `images_K` lacks some registered images (COLMAP).
    Incomplete {
        /// The folder.
        folder: PathBuf,
        /// How many it lacks.
        missing: usize,
        /// The first of them.
        first: PathBuf,
    },
    /// An image of `images_K` whose size is not the full-size one divided by `K` (rounded
    /// either way) (COLMAP).
    OtherSize {
        /// The image.
        file: PathBuf,
        /// Its width and height.
        size: (usize, usize),
        /// The full-size width and height its camera has.
        full: (usize, usize),
    },
    /// `images_K` holds another number of images than there are poses (LLFF).
    OtherCount {
        /// The folder.
        folder: PathBuf,
        /// How many images it holds.
        images: usize,
        /// How many poses there are.
        poses: usize,
    },
}

impl ImageSource {
    /// The folder the pictures were read from (`None` for [`ImageSource::Listed`]).
    pub fn folder(&self) -> Option<&Path> {
        match self {
            ImageSource::Listed => None,
            ImageSource::FullSize { folder, .. } | ImageSource::Prescaled { folder, .. } => Some(folder),
        }
    }

    /// The factor by which the pictures on disk are already downscaled: `K` for
    /// [`ImageSource::Prescaled`], else 1.
    pub fn prescaled(&self) -> usize {
        match self {
            ImageSource::Prescaled { factor, .. } => *factor,
            _ => 1,
        }
    }
}

impl fmt::Display for ImageSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ImageSource::Listed => write!(f, "the image files the transforms file names"),
            ImageSource::FullSize {
                folder,
                downscale: 1,
                why,
            } => write!(f, "{} at full size ({why})", crate::shown(folder)),
            ImageSource::FullSize { folder, downscale, why } => {
                write!(f, "{} downscaled by {downscale} on load ({why})", crate::shown(folder))
            }
            ImageSource::Prescaled { folder, factor } => {
                write!(f, "{} as stored (already downscaled by {factor})", crate::shown(folder))
            }
        }
    }
}

impl fmt::Display for FullSizeReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FullSizeReason::NotAsked => write!(f, "no downscale asked"),
            FullSizeReason::NoFolder { folder } => write!(f, "{} does not exist", folder.display()),
            FullSizeReason::Incomplete { folder, missing, first } => write!(
                f,
                "{} lacks {missing} registered image(s), {} the first",
                folder.display(),
                first.display()
            ),
            FullSizeReason::OtherSize { file, size, full } => write!(
                f,
                "{} is {}x{}, not the full-size {}x{} downscaled",
                file.display(),
                size.0,
                size.1,
                full.0,
                full.1
            ),
            FullSizeReason::OtherCount { folder, images, poses } => {
                write!(f, "{} holds {images} images for {poses} poses", folder.display())
            }
        }
    }
}

/// The folder to read for `downscale`: `dir/images_K` when it exists and `usable` finds
/// nothing wrong with it (`None`), else `dir/images` with the reason.
pub(crate) fn choose(
    dir: &Path,
    downscale: usize,
    usable: impl FnOnce(&Path) -> Result<Option<FullSizeReason>, DataError>,
) -> Result<ImageSource, DataError> {
    let full = |why| ImageSource::FullSize {
        folder: dir.join(FULL_SIZE),
        downscale,
        why,
    };
    if downscale == 1 {
        return Ok(full(FullSizeReason::NotAsked));
    }
    let folder = dir.join(format!("{FULL_SIZE}_{downscale}"));
    if !folder.is_dir() {
        return Ok(full(FullSizeReason::NoFolder { folder }));
    }
    Ok(match usable(&folder)? {
        None => ImageSource::Prescaled {
            folder,
            factor: downscale,
        },
        Some(why) => full(why),
    })
}

/// Whether `path` has an image extension (`png`, `jpg`, `jpeg`, any case).
pub(crate) fn is_image(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| EXTENSIONS.iter().any(|x| e.eq_ignore_ascii_case(x)))
}

/// The image files directly in `folder`, sorted by file name. Errors: an unreadable folder.
pub(crate) fn list_images(folder: &Path) -> Result<Vec<PathBuf>, DataError> {
    let entries = std::fs::read_dir(folder).map_err(|e| DataError::io(folder, e))?;
    let mut files = Vec::new();
    for entry in entries {
        let path = entry.map_err(|e| DataError::io(folder, e))?.path();
        if is_image(&path) && path.is_file() {
            files.push(path);
        }
    }
    files.sort_by(|a, b| a.file_name().cmp(&b.file_name()));
    Ok(files)
}

/// How many image files in `folder` (and its sub-folders, to a depth of 8) are not in
/// `registered`. Errors: an unreadable folder.
pub(crate) fn count_unregistered(folder: &Path, registered: &HashSet<PathBuf>) -> Result<usize, DataError> {
    fn walk(folder: &Path, registered: &HashSet<PathBuf>, depth: usize) -> Result<usize, DataError> {
        let mut count = 0;
        for entry in std::fs::read_dir(folder).map_err(|e| DataError::io(folder, e))? {
            let entry = entry.map_err(|e| DataError::io(folder, e))?;
            let path = entry.path();
            let is_dir = entry.file_type().map_err(|e| DataError::io(&path, e))?.is_dir();
            if is_dir && depth < MAX_DEPTH {
                count += walk(&path, registered, depth + 1)?;
            } else if is_image(&path) && path.is_file() && !registered.contains(&path) {
                count += 1;
            }
        }
        Ok(count)
    }
    walk(folder, registered, 0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn image_extensions_in_any_case() {
        assert!(is_image(Path::new("a/IMG_1.JPG")));
        assert!(is_image(Path::new("b.png")) && is_image(Path::new("c.Jpeg")));
        assert!(!is_image(Path::new("d.txt")) && !is_image(Path::new("png")));
    }

    #[test]
    fn no_downscale_reads_full_size_without_looking() {
        let source = choose(Path::new("/nowhere"), 1, |_| panic!("not asked")).unwrap();
        assert_eq!(
            source,
            ImageSource::FullSize {
                folder: PathBuf::from("/nowhere/images"),
                downscale: 1,
                why: FullSizeReason::NotAsked
            }
        );
    }
}
