//! The camera a frame request names, read from its query string: every number checked before
//! a camera is built, so that a bad request is a one-line refusal and never a panic or a
//! large allocation.
//!
//! Two forms: `eye=x,y,z&target=x,y,z&up=x,y,z&fov=DEG&w=W&h=H` (a camera at `eye` looking at
//! `target`, rolled so that `up` appears up; `fov` the vertical field of view in degrees), or
//! `c2w=r00,r01,r02,tx,r10,...,tz&fov=DEG&w=W&h=H` (a camera-to-world matrix's first three
//! rows, row-major, OpenCV axes: x right, y down, z forward; its rotation must be orthonormal);
//! and `view=N`, the model's dataset's camera N as it is. Square pixels, the principal point
//! at the image centre.

use std::collections::BTreeMap;

use fogray_ops::{Intrinsics, OpsError, PinholeCamera};
use thiserror::Error;

/// The longest side a frame may have, in pixels.
pub const MAX_SIDE: usize = 2048;

/// How far a `c2w` rotation's columns may be from orthonormal (each entry of `R^T R - I`).
/// Loose enough for a matrix printed with eight digits, tight enough that a scaled or sheared
/// matrix is refused rather than silently normalised.
pub const ORTHONORMAL_TOLERANCE: f64 = 1e-6;

/// Why a frame request was refused: its message is the response's one line.
#[derive(Debug, Error, PartialEq)]
#[non_exhaustive]
pub enum RequestError {
    /// A query string that is not `key=value&...` of UTF-8 text.
    #[error("the query is not key=value pairs of UTF-8 text")]
    Query,
    /// A key given twice.
    #[error("{0} is given twice")]
    Duplicate(String),
    /// A key the route does not take.
    #[error("unknown parameter {0:?} (expected eye, target, up, fov, w, h; or c2w, fov, w, h; or view)")]
    Unknown(String),
    /// A key the camera needs is missing.
    #[error("{0} is missing")]
    Missing(&'static str),
    /// Parameters of two forms together.
    #[error("{0}")]
    Mixed(&'static str),
    /// A value that is not a number.
    #[error("{key}: {value:?} is not a number")]
    NotNumber {
        /// The parameter.
        key: &'static str,
        /// Its text.
        value: String,
    },
    /// A list of the wrong length.
    #[error("{key}: {got} numbers, expected {expected}")]
    Count {
        /// The parameter.
        key: &'static str,
        /// How many it needs.
        expected: usize,
        /// How many it had.
        got: usize,
    },
    /// NaN or infinity.
    #[error("{key}: not finite")]
    NotFinite {
        /// The parameter.
        key: &'static str,
    },
    /// A field of view outside (0, 180) degrees.
    #[error("fov {0}: must be in (0, 180) degrees")]
    Fov(f64),
    /// A size of 0 or above [`MAX_SIDE`].
    #[error("{key} {value}: must be in 1..={MAX_SIDE}")]
    Size {
        /// `w` or `h`.
        key: &'static str,
        /// The value given.
        value: String,
    },
    /// A `c2w` whose rotation is not orthonormal (or not a rotation: a reflection).
    #[error("c2w: its rotation is not orthonormal with determinant 1 (entry of R^T R - I up to {0:.3e})")]
    NotOrthonormal(f64),
    /// A dataset view that does not exist.
    #[error("view {index}: the model's dataset has {count} cameras")]
    NoView {
        /// The index asked for.
        index: String,
        /// How many there are.
        count: usize,
    },
    /// A dataset view larger than a frame may be.
    #[error("view {index}: {width}x{height} is larger than {MAX_SIDE} pixels a side")]
    ViewTooLarge {
        /// The view.
        index: usize,
        /// Its width.
        width: usize,
        /// Its height.
        height: usize,
    },
    /// A camera the camera module refuses (eye at the target, up along the view).
    #[error("camera: {0}")]
    Camera(#[from] OpsError),
}

/// The query string's pairs, percent-decoded (`+` is a space, as forms send it).
///
/// Errors: [`RequestError::Query`] for a pair without `=`, a bad escape or text that is not
/// UTF-8; [`RequestError::Duplicate`] for a key given twice.
pub fn parse_query(query: &str) -> Result<BTreeMap<String, String>, RequestError> {
    let mut pairs = BTreeMap::new();
    for pair in query.split('&').filter(|p| !p.is_empty()) {
        let (key, value) = pair.split_once('=').ok_or(RequestError::Query)?;
        let (key, value) = (decode(key)?, decode(value)?);
        if pairs.contains_key(&key) {
            return Err(RequestError::Duplicate(key));
        }
        pairs.insert(key, value);
    }
    Ok(pairs)
}

/// Percent-decoding of one query component.
fn decode(text: &str) -> Result<String, RequestError> {
    let bytes = text.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        match bytes[i] {
            b'%' => {
                let hex = bytes.get(i + 1..i + 3).ok_or(RequestError::Query)?;
                let hex = std::str::from_utf8(hex).map_err(|_| RequestError::Query)?;
                out.push(u8::from_str_radix(hex, 16).map_err(|_| RequestError::Query)?);
                i += 3;
            }
            b'+' => {
                out.push(b' ');
                i += 1;
            }
            b => {
                out.push(b);
                i += 1;
            }
        }
    }
    String::from_utf8(out).map_err(|_| RequestError::Query)
}

/// What a frame request asks for.
#[derive(Debug, Clone, PartialEq)]
pub enum FrameRequest {
    /// A camera of the request's own.
    Camera(PinholeCamera),
    /// The dataset's camera of this index (checked against the dataset by the server).
    View(String),
}

/// The camera of a frame request's parameters `pairs` (see the [module docs](self)).
///
/// Errors: an unknown, missing or malformed parameter, a size outside 1..=[`MAX_SIDE`], a field
/// of view outside (0, 180) degrees, a non-orthonormal `c2w`, a camera the camera module
/// refuses.
pub fn frame_request(pairs: &BTreeMap<String, String>) -> Result<FrameRequest, RequestError> {
    const KEYS: [&str; 8] = ["eye", "target", "up", "c2w", "fov", "w", "h", "view"];
    if let Some(unknown) = pairs.keys().find(|k| !KEYS.contains(&k.as_str())) {
        return Err(RequestError::Unknown(unknown.clone()));
    }
    if let Some(index) = pairs.get("view") {
        if pairs.len() > 1 {
            return Err(RequestError::Mixed("view takes no other parameter"));
        }
        return Ok(FrameRequest::View(index.clone()));
    }
    let get = |key: &'static str| pairs.get(key).map(String::as_str).ok_or(RequestError::Missing(key));
    let width = size("w", get("w")?)?;
    let height = size("h", get("h")?)?;
    let [fov] = numbers::<1>("fov", get("fov")?)?;
    if !(fov > 0.0 && fov < 180.0) {
        return Err(RequestError::Fov(fov));
    }
    let k = Intrinsics::from_vertical_fov(width, height, fov.to_radians())?;
    let look_at = ["eye", "target", "up"].iter().any(|k| pairs.contains_key(*k));
    match (pairs.get("c2w"), look_at) {
        (Some(_), true) => Err(RequestError::Mixed("c2w or eye, target and up: not both")),
        (Some(m), false) => {
            let m = numbers::<12>("c2w", m)?;
            let rows = [
                [m[0], m[1], m[2], m[3]],
                [m[4], m[5], m[6], m[7]],
                [m[8], m[9], m[10], m[11]],
                [0.0, 0.0, 0.0, 1.0],
            ];
            check_rotation(&rows)?;
            Ok(FrameRequest::Camera(PinholeCamera::new(k, rows)?))
        }
        (None, _) => {
            let eye = numbers::<3>("eye", get("eye")?)?;
            let target = numbers::<3>("target", get("target")?)?;
            let up = numbers::<3>("up", get("up")?)?;
            Ok(FrameRequest::Camera(PinholeCamera::look_at(k, eye, target, up)?))
        }
    }
}

/// `N` finite numbers separated by commas.
fn numbers<const N: usize>(key: &'static str, text: &str) -> Result<[f64; N], RequestError> {
    let mut out = [0.0; N];
    let mut got = 0;
    for part in text.split(',') {
        // Counted past N without storing: a long list costs no memory.
        if got < N {
            out[got] = part.trim().parse::<f64>().map_err(|_| RequestError::NotNumber {
                key,
                value: part.to_string(),
            })?;
            if !out[got].is_finite() {
                return Err(RequestError::NotFinite { key });
            }
        }
        got += 1;
    }
    if got != N {
        return Err(RequestError::Count { key, expected: N, got });
    }
    Ok(out)
}

/// A side of 1..=[`MAX_SIDE`] pixels.
fn size(key: &'static str, text: &str) -> Result<usize, RequestError> {
    match text.trim().parse::<usize>() {
        Ok(n) if (1..=MAX_SIDE).contains(&n) => Ok(n),
        _ => Err(RequestError::Size {
            key,
            value: text.chars().take(32).collect(),
        }),
    }
}

/// Refuses a rotation whose columns are not orthonormal, or that reflects.
fn check_rotation(m: &[[f64; 4]; 4]) -> Result<(), RequestError> {
    let mut worst: f64 = 0.0;
    for i in 0..3 {
        for j in 0..3 {
            let dot: f64 = (0..3).map(|r| m[r][i] * m[r][j]).sum();
            worst = worst.max((dot - if i == j { 1.0 } else { 0.0 }).abs());
        }
    }
    let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    if worst > ORTHONORMAL_TOLERANCE || det < 0.0 {
        return Err(RequestError::NotOrthonormal(worst));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn request(query: &str) -> Result<FrameRequest, RequestError> {
        frame_request(&parse_query(query)?)
    }

    #[test]
    fn a_look_at_camera_is_built_from_its_numbers() {
        let Ok(FrameRequest::Camera(c)) = request("eye=0,-4,0&target=0,0,0&up=0,0,1&fov=40&w=30&h=20") else {
            panic!("refused");
        };
        assert_eq!(c.centre(), [0.0, -4.0, 0.0]);
        assert_eq!((c.intrinsics().width, c.intrinsics().height), (30, 20));
        // The same camera as a matrix, commas percent-encoded as URLSearchParams sends them.
        let m = c.camera_to_world();
        let c2w: Vec<String> = m[..3].iter().flatten().map(|v| v.to_string()).collect();
        let query = format!("c2w={}&fov=40&w=30&h=20", c2w.join("%2C"));
        assert_eq!(request(&query), Ok(FrameRequest::Camera(c)));
    }

    #[test]
    fn bad_numbers_are_refused_by_name() {
        let base = "target=0,0,0&up=0,0,1&fov=40&w=30&h=20";
        let cases = [
            (format!("eye=NaN,0,0&{base}"), RequestError::NotFinite { key: "eye" }),
            (
                format!("eye=1,2&{base}"),
                RequestError::Count {
                    key: "eye",
                    expected: 3,
                    got: 2,
                },
            ),
            (
                format!("eye=1,x,3&{base}"),
                RequestError::NotNumber {
                    key: "eye",
                    value: "x".into(),
                },
            ),
            (
                "eye=0,-4,0&target=0,0,0&up=0,0,1&fov=40&w=3000&h=20".into(),
                RequestError::Size {
                    key: "w",
                    value: "3000".into(),
                },
            ),
            (
                "eye=0,-4,0&target=0,0,0&up=0,0,1&fov=180&w=3&h=2".into(),
                RequestError::Fov(180.0),
            ),
            (
                format!("eye=1,1,1&eye=1,1,1&{base}"),
                RequestError::Duplicate("eye".into()),
            ),
            (format!("what=1&{base}"), RequestError::Unknown("what".into())),
            (base.into(), RequestError::Missing("eye")),
            (
                "c2w=2,0,0,0,0,1,0,0,0,0,1,0&fov=40&w=3&h=2".into(),
                RequestError::NotOrthonormal(3.0),
            ),
        ];
        for (query, want) in cases {
            assert_eq!(request(&query), Err(want), "{query}");
        }
        // Up along the view: the camera module's refusal.
        assert!(matches!(
            request("eye=0,0,4&target=0,0,0&up=0,0,1&fov=40&w=3&h=2"),
            Err(RequestError::Camera(_))
        ));
        // A reflection is orthonormal but no camera.
        assert!(matches!(
            request("c2w=-1,0,0,0,0,1,0,0,0,0,1,0&fov=40&w=3&h=2"),
            Err(RequestError::NotOrthonormal(_))
        ));
        assert_eq!(parse_query("eye=%zz"), Err(RequestError::Query));
        assert_eq!(parse_query("eye=%ff"), Err(RequestError::Query));
    }
}
