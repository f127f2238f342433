//! COLMAP's binary layout (`cameras.bin`, `images.bin`, `points3D.bin`), little-endian:
//!
//! ```text
//! cameras.bin   u64 count; per camera: i32 id, i32 model id, u64 width, u64 height,
//!               f64 params[number of the model's parameters]
//! images.bin    u64 count; per image: i32 id, f64 qw qx qy qz, f64 tx ty tz, i32 camera id,
//!               the name's bytes and a NUL, u64 count of 2-D points, then per point
//!               f64 x, f64 y, i64 point id
//! points3D.bin  u64 count; per point: u64 id, f64 x y z, u8 r g b, f64 error,
//!               u64 track length, then per track element i32 image id, i32 point index
//! ```
//!
//! Every count is checked against the bytes left before anything is sized by it: a count that
//! the rest of the file cannot hold (a corrupt or hostile header) is a
//! [`DataError::Truncated`], never an allocation the machine cannot make.

use std::collections::HashMap;
use std::path::Path;

use super::model::{insert_camera, Camera, Image, Model, Point};
use crate::error::DataError;

/// The fewest bytes a camera record takes (no parameters).
const CAMERA_BYTES: usize = 4 + 4 + 8 + 8;
/// The fewest bytes an image record takes (an empty name, no 2-D points).
const IMAGE_BYTES: usize = 4 + 4 * 8 + 3 * 8 + 4 + 1 + 8;
/// The bytes of one 2-D point of an image.
const POINT2D_BYTES: usize = 8 + 8 + 8;
/// The fewest bytes a 3-D point record takes (an empty track).
const POINT_BYTES: usize = 8 + 3 * 8 + 3 + 8 + 8;
/// The bytes of one track element of a 3-D point.
const TRACK_BYTES: usize = 4 + 4;

/// A position in a file's bytes whose reads fail with [`DataError::Truncated`] naming the file.
pub(crate) struct Cursor<'a> {
    path: &'a Path,
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Cursor<'a> {
    pub fn new(path: &'a Path, bytes: &'a [u8]) -> Self {
        Cursor { path, bytes, pos: 0 }
    }

    fn left(&self) -> usize {
        self.bytes.len() - self.pos
    }

    fn truncated(&self, what: String, needed: u64) -> DataError {
        DataError::Truncated {
            path: self.path.to_path_buf(),
            offset: self.pos as u64,
            what,
            needed,
            available: self.left() as u64,
        }
    }

    /// The next `n` bytes.
    pub fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], DataError> {
        if n > self.left() {
            return Err(self.truncated(what.to_string(), n as u64));
        }
        let out = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(out)
    }

    fn array<const N: usize>(&mut self, what: &str) -> Result<[u8; N], DataError> {
        let mut out = [0u8; N];
        out.copy_from_slice(self.take(N, what)?);
        Ok(out)
    }

    pub fn u64(&mut self, what: &str) -> Result<u64, DataError> {
        self.array(what).map(u64::from_le_bytes)
    }

    pub fn i32(&mut self, what: &str) -> Result<i32, DataError> {
        self.array(what).map(i32::from_le_bytes)
    }

    pub fn f64(&mut self, what: &str) -> Result<f64, DataError> {
        self.array(what).map(f64::from_le_bytes)
    }

    pub fn f64s<const N: usize>(&mut self, what: &str) -> Result<[f64; N], DataError> {
        let mut out = [0.0; N];
        for v in &mut out {
            *v = self.f64(what)?;
        }
        Ok(out)
    }

    /// A count of records of at least `record` bytes each, checked to fit in the bytes left.
    pub fn count(&mut self, record: usize, what: &str) -> Result<usize, DataError> {
        let count = self.u64(what)?;
        let needed = count.saturating_mul(record as u64);
        if needed > self.left() as u64 {
            self.pos -= 8;
            let needed = needed.saturating_add(8);
            return Err(self.truncated(format!("{count} {what} of at least {record} bytes each"), needed));
        }
        Ok(count as usize)
    }

    /// Skips `count` records of `record` bytes each.
    fn skip(&mut self, count: usize, record: usize, what: &str) -> Result<(), DataError> {
        // count * record fits: count was checked by `count` to fit in the bytes left.
        self.take(count * record, what).map(|_| ())
    }

    /// Bytes up to a NUL, which is consumed.
    fn c_string(&mut self, what: &str) -> Result<&'a [u8], DataError> {
        let rest = &self.bytes[self.pos..];
        match rest.iter().position(|&b| b == 0) {
            Some(n) => {
                self.pos += n + 1;
                Ok(&rest[..n])
            }
            None => Err(self.truncated(format!("{what} (no terminating NUL)"), self.left() as u64 + 1)),
        }
    }

    /// Errors: bytes after the last record.
    fn end(&self) -> Result<(), DataError> {
        if self.left() > 0 {
            return Err(DataError::Malformed {
                path: self.path.to_path_buf(),
                at: format!("byte {}", self.pos),
                message: format!("{} byte(s) after the last record", self.left()),
            });
        }
        Ok(())
    }
}

fn read(path: &Path) -> Result<Vec<u8>, DataError> {
    std::fs::read(path).map_err(|e| DataError::io(path, e))
}

/// Reads `cameras.bin`.
pub(crate) fn cameras(path: &Path) -> Result<HashMap<i64, Camera>, DataError> {
    let bytes = read(path)?;
    let mut c = Cursor::new(path, &bytes);
    let count = c.count(CAMERA_BYTES, "cameras")?;
    let mut cameras = HashMap::with_capacity(count);
    for _ in 0..count {
        let at = format!("byte {}", c.pos);
        let id = i64::from(c.i32("a camera id")?);
        let model = Model::by_id(path, id, c.i32("a camera model id")?)?;
        let width = c.u64("a camera width")?;
        let height = c.u64("a camera height")?;
        let mut params = [0.0; 8];
        for p in params.iter_mut().take(model.params()) {
            *p = c.f64("a camera parameter")?;
        }
        let camera = Camera::new(path, id, model, width, height, &params[..model.params()])?;
        insert_camera(&mut cameras, path, at, id, camera)?;
    }
    c.end()?;
    Ok(cameras)
}

/// Reads `images.bin` (the 2-D points are skipped).
pub(crate) fn images(path: &Path) -> Result<Vec<Image>, DataError> {
    let bytes = read(path)?;
    let mut c = Cursor::new(path, &bytes);
    let count = c.count(IMAGE_BYTES, "images")?;
    let mut images = Vec::with_capacity(count);
    for _ in 0..count {
        let id = i64::from(c.i32("an image id")?);
        let q = c.f64s::<4>("an image quaternion")?;
        let t = c.f64s::<3>("an image translation")?;
        let camera = i64::from(c.i32("an image camera id")?);
        let at = format!("byte {}", c.pos);
        let name = std::str::from_utf8(c.c_string("an image name")?)
            .map_err(|_| DataError::Malformed {
                path: path.to_path_buf(),
                at,
                message: format!("the name of image {id} is not UTF-8"),
            })?
            .to_string();
        let points = c.count(POINT2D_BYTES, "2-D points")?;
        c.skip(points, POINT2D_BYTES, "2-D points")?;
        images.push(Image::new(path, id, q, t, camera, name)?);
    }
    c.end()?;
    Ok(images)
}

/// Reads `points3D.bin` (the tracks and errors are skipped).
pub(crate) fn points(path: &Path) -> Result<Vec<Point>, DataError> {
    let bytes = read(path)?;
    let mut c = Cursor::new(path, &bytes);
    let count = c.count(POINT_BYTES, "points")?;
    let mut points = Vec::with_capacity(count);
    for _ in 0..count {
        let id = c.u64("a point id")?;
        let position = c.f64s::<3>("a point position")?;
        let color = c.array::<3>("a point colour")?;
        c.f64("a point error")?;
        let track = c.count(TRACK_BYTES, "track elements")?;
        c.skip(track, TRACK_BYTES, "track elements")?;
        points.push(Point::new(path, id, position, color)?);
    }
    c.end()?;
    Ok(points)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_count_the_bytes_cannot_hold_is_refused_with_its_offset() {
        let mut bytes = u64::MAX.to_le_bytes().to_vec();
        bytes.extend([0u8; 30]);
        let mut c = Cursor::new(Path::new("x.bin"), &bytes);
        let e = c.count(IMAGE_BYTES, "images").unwrap_err();
        match &e {
            DataError::Truncated {
                offset,
                needed,
                available,
                ..
            } => assert_eq!((*offset, *needed, *available), (0, u64::MAX, 38)),
            other => panic!("{other}"),
        }
        // 30 bytes hold one 24-byte camera but not two.
        let mut bytes = 2u64.to_le_bytes().to_vec();
        bytes.extend([0u8; 30]);
        assert!(Cursor::new(Path::new("x.bin"), &bytes)
            .count(CAMERA_BYTES, "cameras")
            .is_err());
        let mut bytes = 1u64.to_le_bytes().to_vec();
        bytes.extend([0u8; 30]);
        assert_eq!(
            Cursor::new(Path::new("x.bin"), &bytes)
                .count(CAMERA_BYTES, "cameras")
                .unwrap(),
            1
        );
    }

    #[test]
    fn reads_are_little_endian_and_names_end_at_nul() {
        let mut bytes = (-3i32).to_le_bytes().to_vec();
        bytes.extend(1.5f64.to_le_bytes());
        bytes.extend(b"ab/c.png\0rest");
        let mut c = Cursor::new(Path::new("x.bin"), &bytes);
        assert_eq!(c.i32("i").unwrap(), -3);
        assert_eq!(c.f64("f").unwrap(), 1.5);
        assert_eq!(c.c_string("name").unwrap(), b"ab/c.png");
        assert_eq!(c.take(4, "rest").unwrap(), b"rest");
        assert!(c.take(1, "more").is_err());
    }
}
