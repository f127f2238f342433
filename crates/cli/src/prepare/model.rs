//! What the mapper made: which of its models is the largest, and the names of the
//! photographs each registered, read from `images.bin` and nothing else (the full reader is
//! fogray-data's).
//!
//! `images.bin` (little-endian): `u64` the number of images; each image `u32` id, four `f64`
//! (rotation quaternion), three `f64` (translation), `u32` camera id, its name as bytes ended
//! by a NUL, `u64` the number of its 2D points, then that many `(f64 x, f64 y, i64 point id)`.

use std::fs::File;
use std::io::{BufRead, BufReader, Read, Seek};
use std::path::{Path, PathBuf};

use fogray_data::shown;

use super::error::PrepareError;

/// The bytes of an image's record before its name (id, pose, camera id).
const BEFORE_NAME: i64 = 4 + 8 * 4 + 8 * 3 + 4;
/// The bytes of one 2D point.
const POINT_BYTES: u64 = 8 + 8 + 8;
/// The longest name read (a longer one is refused rather than read into memory).
const MAX_NAME: usize = 4096;

fn bad(path: &Path, reason: String) -> PrepareError {
    PrepareError::BadModel {
        path: shown(path).to_string(),
        reason,
    }
}

fn read_u64(file: &mut impl Read, path: &Path, what: &str) -> Result<u64, PrepareError> {
    let mut bytes = [0u8; 8];
    file.read_exact(&mut bytes)
        .map_err(|e| bad(path, format!("cannot read {what}: {e}")))?;
    Ok(u64::from_le_bytes(bytes))
}

/// The names of the images `path` (an `images.bin`) registers, in the file's order.
///
/// Errors: [`PrepareError::File`] if it cannot be opened, [`PrepareError::BadModel`] if it
/// ends early, holds a name without its NUL within 4096 bytes, or counts more records or
/// points than its size holds.
pub fn registered_names(path: &Path) -> Result<Vec<String>, PrepareError> {
    let file = File::open(path).map_err(PrepareError::file("read", path))?;
    let size = file.metadata().map_err(PrepareError::file("read", path))?.len();
    let mut file = BufReader::new(file);
    let count = read_u64(&mut file, path, "the number of images")?;
    // The smallest record: a one-byte name (its NUL) and no points.
    let smallest = BEFORE_NAME as u64 + 1 + 8;
    if count.checked_mul(smallest).is_none_or(|bytes| bytes > size) {
        return Err(bad(path, format!("{count} images do not fit in {size} bytes")));
    }
    let mut names = Vec::new();
    for image in 0..count {
        file.seek_relative(BEFORE_NAME)
            .map_err(|e| bad(path, format!("image {image}: {e}")))?;
        let mut name = Vec::new();
        (&mut file)
            .take(MAX_NAME as u64 + 1)
            .read_until(0, &mut name)
            .map_err(|e| bad(path, format!("image {image}: cannot read its name: {e}")))?;
        if name.pop() != Some(0) {
            return Err(bad(
                path,
                format!("image {image}: its name has no end within {MAX_NAME} bytes"),
            ));
        }
        let points = read_u64(&mut file, path, &format!("image {image}'s number of points"))?;
        let position = file.stream_position().map_err(PrepareError::file("read", path))?;
        let bytes = points
            .checked_mul(POINT_BYTES)
            .filter(|&b| b <= size.saturating_sub(position))
            .ok_or_else(|| bad(path, format!("image {image}: {points} points do not fit in the file")))?;
        // At most the file's size, which a seek offset holds.
        file.seek_relative(bytes as i64)
            .map_err(|e| bad(path, format!("image {image}: {e}")))?;
        names.push(String::from_utf8_lossy(&name).into_owned());
    }
    Ok(names)
}

/// The width in pixels of the first camera of `path` (a `cameras.bin`: `u64` the number of
/// cameras, then each `u32` id, `i32` model id, `u64` width, `u64` height, its parameters);
/// `None` if it holds no camera.
///
/// Errors: [`PrepareError::File`] if it cannot be opened, [`PrepareError::BadModel`] if it
/// ends before the first camera's width.
pub fn first_camera_width(path: &Path) -> Result<Option<u64>, PrepareError> {
    let mut file = BufReader::new(File::open(path).map_err(PrepareError::file("read", path))?);
    if read_u64(&mut file, path, "the number of cameras")? == 0 {
        return Ok(None);
    }
    // The camera's id and model id.
    let _ = read_u64(&mut file, path, "camera 0's id and model")?;
    Ok(Some(read_u64(&mut file, path, "camera 0's width")?))
}

/// The models the mapper wrote into `models` (its numbered folders holding an `images.bin`),
/// with the number of photographs each registered, in folder-number order.
///
/// Errors: [`PrepareError::File`] if the folder cannot be listed; those of
/// [`registered_names`].
pub fn models(models: &Path) -> Result<Vec<(PathBuf, usize)>, PrepareError> {
    let mut found: Vec<(usize, PathBuf, usize)> = Vec::new();
    let entries = match std::fs::read_dir(models) {
        Ok(entries) => entries,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(PrepareError::file("list", models)(e)),
    };
    for entry in entries {
        let entry = entry.map_err(PrepareError::file("list", models))?;
        let Some(number) = entry.file_name().to_str().and_then(|n| n.parse::<usize>().ok()) else {
            continue;
        };
        let images = entry.path().join("images.bin");
        if images.is_file() {
            found.push((number, entry.path(), registered_names(&images)?.len()));
        }
    }
    found.sort_by_key(|(number, _, _)| *number);
    Ok(found.into_iter().map(|(_, path, count)| (path, count)).collect())
}

/// The index in `models` of the one that registered the most photographs (the first of
/// equals), if any.
pub fn largest(models: &[(PathBuf, usize)]) -> Option<usize> {
    // max_by_key keeps the last of equals: reverse, so that the first wins.
    (0..models.len()).rev().max_by_key(|&i| models[i].1)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// `images.bin` registering `names`, image `i` with `i` points, written field by field as
    /// the module docs lay it out.
    pub(crate) fn images_bin(names: &[&str]) -> Vec<u8> {
        let mut bytes = (names.len() as u64).to_le_bytes().to_vec();
        for (i, name) in names.iter().enumerate() {
            bytes.extend((i as u32 + 1).to_le_bytes());
            for q in [1.0f64, 0.0, 0.0, 0.0, 0.5, -0.5, 2.0] {
                bytes.extend(q.to_le_bytes());
            }
            bytes.extend(1u32.to_le_bytes());
            bytes.extend(name.as_bytes());
            bytes.push(0);
            bytes.extend((i as u64).to_le_bytes());
            for p in 0..i {
                bytes.extend((p as f64).to_le_bytes());
                bytes.extend(3.5f64.to_le_bytes());
                bytes.extend((-1i64).to_le_bytes());
            }
        }
        bytes
    }

    #[test]
    fn names_are_read_past_each_images_points() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("images.bin");
        std::fs::write(&path, images_bin(&["a.jpg", "b c.png", "d.JPG"])).unwrap();
        assert_eq!(registered_names(&path).unwrap(), ["a.jpg", "b c.png", "d.JPG"]);
    }

    #[test]
    fn truncated_or_oversized_counts_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("images.bin");
        let whole = images_bin(&["a.jpg", "b.jpg", "c.jpg"]);
        // Cut inside the last image's points.
        std::fs::write(&path, &whole[..whole.len() - 5]).unwrap();
        let e = registered_names(&path).unwrap_err().to_string();
        assert!(e.contains("image 2") && e.contains("images.bin"), "{e}");
        let mut huge = whole.clone();
        huge[..8].copy_from_slice(&u64::MAX.to_le_bytes());
        std::fs::write(&path, &huge).unwrap();
        let e = registered_names(&path).unwrap_err().to_string();
        assert!(e.contains("do not fit"), "{e}");
        // A name without its NUL.
        let mut open = 1u64.to_le_bytes().to_vec();
        open.extend(vec![0u8; BEFORE_NAME as usize]);
        open.extend(vec![b'x'; MAX_NAME + 10]);
        std::fs::write(&path, &open).unwrap();
        let e = registered_names(&path).unwrap_err().to_string();
        assert!(e.contains("no end"), "{e}");
    }

    #[test]
    fn the_first_cameras_width_is_read() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cameras.bin");
        // One OPENCV camera (model id 4) of 320 x 240 and its eight parameters.
        let mut bytes = 1u64.to_le_bytes().to_vec();
        bytes.extend(1u32.to_le_bytes());
        bytes.extend(4i32.to_le_bytes());
        bytes.extend(320u64.to_le_bytes());
        bytes.extend(240u64.to_le_bytes());
        for p in [300.0f64, 300.0, 160.0, 120.0, 0.0, 0.0, 0.0, 0.0] {
            bytes.extend(p.to_le_bytes());
        }
        std::fs::write(&path, &bytes).unwrap();
        assert_eq!(first_camera_width(&path).unwrap(), Some(320));
        std::fs::write(&path, 0u64.to_le_bytes()).unwrap();
        assert_eq!(first_camera_width(&path).unwrap(), None);
        std::fs::write(&path, &bytes[..20]).unwrap();
        assert!(first_camera_width(&path).unwrap_err().to_string().contains("width"));
    }

    #[test]
    fn the_largest_model_is_the_one_with_most_images_first_of_equals() {
        let dir = tempfile::tempdir().unwrap();
        for (folder, names) in [("0", &["a"][..]), ("1", &["a", "b", "c"]), ("2", &["d", "e", "f"])] {
            std::fs::create_dir(dir.path().join(folder)).unwrap();
            std::fs::write(dir.path().join(folder).join("images.bin"), images_bin(names)).unwrap();
        }
        std::fs::create_dir(dir.path().join("notes")).unwrap();
        let found = models(dir.path()).unwrap();
        let counts: Vec<usize> = found.iter().map(|(_, c)| *c).collect();
        assert_eq!(counts, [1, 3, 3]);
        assert_eq!(largest(&found), Some(1));
        assert_eq!(largest(&[]), None);
        assert!(models(&dir.path().join("missing")).unwrap().is_empty());
    }
}
