//! The refusals made before any work: a folder of photographs to read, and an output folder
//! that is new (or empty) and outside it. Nothing is created or written here.

use std::ffi::OsString;
use std::path::{Path, PathBuf};

use fogray_data::shown;

use super::error::PrepareError;

/// Whether `name` is a photograph COLMAP reads and fogray decodes: `.jpg`, `.jpeg` or `.png`,
/// in any case.
pub fn is_photograph(name: &Path) -> bool {
    name.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| ["jpg", "jpeg", "png"].iter().any(|x| e.eq_ignore_ascii_case(x)))
}

/// The names of the photographs at the top level of `folder` (files, or links to files),
/// sorted. Sub-folders are not read: COLMAP would name their photographs `sub/name`, which
/// the flat `DIR/images/` folder of the output cannot hold.
///
/// Errors: [`PrepareError::NotAFolder`], [`PrepareError::NoPhotographs`], or
/// [`PrepareError::File`] if the folder cannot be listed.
pub fn photographs(folder: &Path) -> Result<Vec<OsString>, PrepareError> {
    if !folder.is_dir() {
        return Err(PrepareError::NotAFolder {
            path: shown(folder).to_string(),
        });
    }
    let mut names = Vec::new();
    for entry in std::fs::read_dir(folder).map_err(PrepareError::file("list", folder))? {
        let entry = entry.map_err(PrepareError::file("list", folder))?;
        let name = entry.file_name();
        if is_photograph(Path::new(&name)) && entry.path().is_file() {
            names.push(name);
        }
    }
    if names.is_empty() {
        return Err(PrepareError::NoPhotographs {
            path: shown(folder).to_string(),
        });
    }
    names.sort();
    Ok(names)
}

/// `path` made absolute with its links resolved, for a path that may not exist yet: its
/// nearest existing ancestor canonicalised, the rest appended.
fn resolved(path: &Path) -> Result<PathBuf, PrepareError> {
    let absolute = std::path::absolute(path).map_err(PrepareError::file("resolve", path))?;
    let mut existing = absolute.as_path();
    let mut rest = Vec::new();
    loop {
        if let Ok(canonical) = existing.canonicalize() {
            return Ok(rest.iter().rev().fold(canonical, |p, c| p.join(c)));
        }
        match (existing.parent(), existing.file_name()) {
            (Some(parent), Some(name)) => {
                rest.push(name.to_os_string());
                existing = parent;
            }
            // `..` components of a missing path: compared as written.
            _ => return Ok(absolute),
        }
    }
}

/// Checks that `out` can receive the prepared capture: not `images` nor inside it, and
/// missing or an empty folder.
///
/// Errors: [`PrepareError::OutInsideImages`], [`PrepareError::OutNotEmpty`].
pub fn output(images: &Path, out: &Path) -> Result<(), PrepareError> {
    if resolved(out)?.starts_with(resolved(images)?) {
        return Err(PrepareError::OutInsideImages {
            out: shown(out).to_string(),
            images: shown(images).to_string(),
        });
    }
    let empty_folder = out.is_dir()
        && std::fs::read_dir(out)
            .map_err(PrepareError::file("list", out))?
            .next()
            .is_none();
    if out.symlink_metadata().is_ok() && !empty_folder {
        return Err(PrepareError::OutNotEmpty {
            path: shown(out).to_string(),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn photographs_are_jpg_jpeg_png_in_any_case_sorted_top_level_only() {
        let dir = tempfile::tempdir().unwrap();
        for name in ["b.JPG", "a.png", "c.jpeg", "notes.txt", "d.Png", "e.tif"] {
            std::fs::write(dir.path().join(name), b"x").unwrap();
        }
        std::fs::create_dir(dir.path().join("sub.jpg")).unwrap();
        std::fs::write(dir.path().join("sub.jpg").join("f.jpg"), b"x").unwrap();
        let names = photographs(dir.path()).unwrap();
        assert_eq!(names, ["a.png", "b.JPG", "c.jpeg", "d.Png"]);
    }

    #[test]
    fn a_missing_or_empty_folder_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("missing");
        assert!(matches!(photographs(&missing), Err(PrepareError::NotAFolder { .. })));
        std::fs::write(dir.path().join("notes.txt"), b"x").unwrap();
        assert!(matches!(
            photographs(dir.path()),
            Err(PrepareError::NoPhotographs { .. })
        ));
    }

    #[test]
    fn out_must_be_new_or_empty_and_outside_the_photographs() {
        let dir = tempfile::tempdir().unwrap();
        let images = dir.path().join("photos");
        std::fs::create_dir(&images).unwrap();
        let inside = |out: &Path| matches!(output(&images, out), Err(PrepareError::OutInsideImages { .. }));
        assert!(inside(&images));
        assert!(inside(&images.join("out")));
        assert!(inside(&images.join("new").join("deeper")));
        assert!(inside(&images.join("..").join("photos").join("x")));
        // A sibling whose name starts with the folder's is outside it.
        assert!(output(&images, &dir.path().join("photos-prepared")).is_ok());
        let empty = dir.path().join("empty");
        std::fs::create_dir(&empty).unwrap();
        assert!(output(&images, &empty).is_ok());
        std::fs::write(empty.join("x"), b"x").unwrap();
        assert!(matches!(output(&images, &empty), Err(PrepareError::OutNotEmpty { .. })));
        let file = dir.path().join("file");
        std::fs::write(&file, b"x").unwrap();
        assert!(matches!(output(&images, &file), Err(PrepareError::OutNotEmpty { .. })));
    }
}
