//! COLMAP's text layout (`cameras.txt`, `images.txt`, `points3D.txt`): the binary layout's
//! fields, whitespace-separated, one record a line, lines starting with `#` ignored:
//!
//! ```text
//! cameras.txt   CAMERA_ID MODEL WIDTH HEIGHT PARAMS...
//! images.txt    IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME
//!               X Y POINT3D_ID ...        (the next line, always present, possibly empty)
//! points3D.txt  POINT3D_ID X Y Z R G B ERROR (IMAGE_ID POINT2D_IDX)...
//! ```
//!
//! `MODEL` is the model's name (`PINHOLE`...). An image's name is the rest of its line (COLMAP
//! writes names without spaces; one with spaces is kept whole).

use std::collections::HashMap;
use std::path::Path;
use std::str::FromStr;

use super::model::{insert_camera, Camera, Image, Model, Point};
use crate::error::DataError;
use crate::escape::escape_controls;

/// The fields of one line, read in order; errors name the file and the line.
struct Fields<'a> {
    path: &'a Path,
    line: usize,
    rest: &'a str,
}

impl<'a> Fields<'a> {
    fn malformed(&self, message: String) -> DataError {
        DataError::Malformed {
            path: self.path.to_path_buf(),
            at: format!("line {}", self.line),
            message,
        }
    }

    fn word(&mut self, what: &str) -> Result<&'a str, DataError> {
        let rest = self.rest.trim_start();
        if rest.is_empty() {
            return Err(self.malformed(format!("missing {what}")));
        }
        let end = rest.find(char::is_whitespace).unwrap_or(rest.len());
        self.rest = &rest[end..];
        Ok(&rest[..end])
    }

    fn next<T: FromStr>(&mut self, what: &str) -> Result<T, DataError> {
        let word = self.word(what)?;
        word.parse().map_err(|_| {
            self.malformed(format!(
                "{what} `{}` is not a number of its type",
                escape_controls(word)
            ))
        })
    }

    /// The rest of the line, trimmed.
    fn remainder(&mut self, what: &str) -> Result<&'a str, DataError> {
        let rest = self.rest.trim();
        if rest.is_empty() {
            return Err(self.malformed(format!("missing {what}")));
        }
        self.rest = "";
        Ok(rest)
    }

    fn done(&self, what: &str) -> Result<(), DataError> {
        if !self.rest.trim().is_empty() {
            return Err(self.malformed(format!(
                "unexpected `{}` after {what}",
                escape_controls(self.rest.trim())
            )));
        }
        Ok(())
    }
}

fn read(path: &Path) -> Result<String, DataError> {
    std::fs::read_to_string(path).map_err(|e| DataError::io(path, e))
}

/// The next line that is neither blank nor a comment, as fields (lines counted from 1).
fn record<'a>(path: &'a Path, lines: &mut impl Iterator<Item = (usize, &'a str)>) -> Option<Fields<'a>> {
    lines
        .find(|(_, l)| {
            let l = l.trim();
            !l.is_empty() && !l.starts_with('#')
        })
        .map(|(i, rest)| Fields {
            path,
            line: i + 1,
            rest,
        })
}

/// Reads `cameras.txt`.
pub(crate) fn cameras(path: &Path) -> Result<HashMap<i64, Camera>, DataError> {
    let text = read(path)?;
    let mut lines = text.lines().enumerate();
    let mut cameras = HashMap::new();
    while let Some(mut f) = record(path, &mut lines) {
        let id: i64 = f.next("CAMERA_ID")?;
        let model = Model::by_name(path, id, f.word("MODEL")?)?;
        let width: u64 = f.next("WIDTH")?;
        let height: u64 = f.next("HEIGHT")?;
        let mut params = [0.0; 8];
        for p in params.iter_mut().take(model.params()) {
            *p = f.next("a parameter")?;
        }
        f.done("the model's parameters")?;
        let camera = Camera::new(path, id, model, width, height, &params[..model.params()])?;
        insert_camera(&mut cameras, path, format!("line {}", f.line), id, camera)?;
    }
    Ok(cameras)
}

/// Reads `images.txt` (the 2-D points lines are skipped).
pub(crate) fn images(path: &Path) -> Result<Vec<Image>, DataError> {
    let text = read(path)?;
    let mut lines = text.lines().enumerate();
    let mut images = Vec::new();
    while let Some(mut f) = record(path, &mut lines) {
        let id: i64 = f.next("IMAGE_ID")?;
        let mut q = [0.0; 4];
        for (v, what) in q.iter_mut().zip(["QW", "QX", "QY", "QZ"]) {
            *v = f.next(what)?;
        }
        let mut t = [0.0; 3];
        for (v, what) in t.iter_mut().zip(["TX", "TY", "TZ"]) {
            *v = f.next(what)?;
        }
        let camera: i64 = f.next("CAMERA_ID")?;
        let name = f.remainder("NAME")?.to_string();
        images.push(Image::new(path, id, q, t, camera, name)?);
        // The image's 2-D points line.
        lines.next();
    }
    Ok(images)
}

/// Reads `points3D.txt` (the tracks and errors are skipped).
pub(crate) fn points(path: &Path) -> Result<Vec<Point>, DataError> {
    let text = read(path)?;
    let mut lines = text.lines().enumerate();
    let mut points = Vec::new();
    while let Some(mut f) = record(path, &mut lines) {
        let id: u64 = f.next("POINT3D_ID")?;
        let mut position = [0.0; 3];
        for (v, what) in position.iter_mut().zip(["X", "Y", "Z"]) {
            *v = f.next(what)?;
        }
        let mut color = [0u8; 3];
        for (v, what) in color.iter_mut().zip(["R", "G", "B"]) {
            *v = f.next(what)?;
        }
        let _error: f64 = f.next("ERROR")?;
        points.push(Point::new(path, id, position, color)?);
    }
    Ok(points)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fields(line: &str) -> Fields<'_> {
        Fields {
            path: Path::new("images.txt"),
            line: 3,
            rest: line,
        }
    }

    #[test]
    fn fields_read_in_order_and_the_name_is_the_rest() {
        let mut f = fields("  7 0.5\tPINHOLE  my image.png ");
        assert_eq!(f.next::<i64>("id").unwrap(), 7);
        assert_eq!(f.next::<f64>("q").unwrap(), 0.5);
        assert_eq!(f.word("model").unwrap(), "PINHOLE");
        assert_eq!(f.remainder("name").unwrap(), "my image.png");
        let e = f.word("more").unwrap_err().to_string();
        assert_eq!(e, "images.txt: line 3: missing more");
    }

    #[test]
    fn a_word_that_is_not_a_number_is_named() {
        let e = fields("x1").next::<u64>("WIDTH").unwrap_err().to_string();
        assert!(e.contains("line 3") && e.contains("WIDTH `x1`"), "{e}");
        let e = fields("1 2").done("the parameters").map(|_| ()).is_ok();
        assert!(!e);
    }
}
