//! Why a dataset could not be read or written: every variant names the file at fault, and its
//! message is one line, so that a user with hundreds of frames knows which one to fix. Paths
//! are shown with their control characters escaped ([`escape_controls`](crate::escape_controls)):
//! a name read from a file cannot drive the terminal that shows the error.

use std::fmt;
use std::path::PathBuf;

use fogray_ops::OpsError;
use thiserror::Error;

use crate::escape::shown;

/// What is wrong with a `transform_matrix`.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum MatrixProblem {
    /// Not an array of 4 arrays of 4 numbers.
    NotFourByFour,
    /// An entry that is NaN or infinite.
    NotFinite,
    /// The last row is not `0 0 0 1` (a projective transform, not a camera pose).
    LastRow,
    /// The 3x3 part is not orthonormal: `max |RᵀR - I|` exceeds `1e-3` (a scaled or sheared
    /// pose, which the formats do not allow).
    NotOrthonormal {
        /// `max |RᵀR - I|` over the nine entries.
        deviation: f64,
    },
    /// The 3x3 part is orthonormal but its determinant is negative (a mirror).
    Reflection {
        /// The determinant.
        det: f64,
    },
    /// A translation entry beyond `1e6` in magnitude: no scene is that far from its cameras'
    /// origin, and rays from there cannot resolve one.
    FarTranslation {
        /// The entry.
        value: f64,
    },
}

impl fmt::Display for MatrixProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MatrixProblem::NotFourByFour => write!(f, "is not a 4x4 array of numbers"),
            MatrixProblem::NotFinite => write!(f, "has an entry that is not finite"),
            MatrixProblem::LastRow => write!(f, "has a last row other than 0 0 0 1"),
            MatrixProblem::NotOrthonormal { deviation } => write!(
                f,
                "has a 3x3 part that is not a rotation: not orthonormal (max |R^T R - I| = {deviation:.3e} > 1e-3)"
            ),
            MatrixProblem::FarTranslation { value } => {
                write!(f, "has a translation entry {value:e}, beyond 1e6 from the origin")
            }
            MatrixProblem::Reflection { det } => {
                write!(
                    f,
                    "has a 3x3 part that is not a rotation: determinant {det} is negative"
                )
            }
        }
    }
}

/// Why a dataset could not be read or written. Nothing is returned alongside it.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum DataError {
    /// A file or folder that could not be read or written.
    #[error("{path}: {message}", path = shown(.path))]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's reason, on one line.
        message: String,
    },
    /// A transforms file that is not valid JSON (truncated, a stray comma...).
    #[error("{path}: invalid JSON at line {line}, column {column}: {message}", path = shown(.path))]
    Json {
        /// The transforms file.
        path: PathBuf,
        /// 1-based line of the error.
        line: usize,
        /// 1-based column of the error.
        column: usize,
        /// The parser's reason.
        message: String,
    },
    /// A key that the format requires is absent.
    #[error("{path}: missing key `{key}`", path = shown(.path))]
    MissingKey {
        /// The transforms file.
        path: PathBuf,
        /// The key, with where it was looked for (`frames[3].transform_matrix`).
        key: String,
    },
    /// A key whose value has the wrong type (a string where a number belongs...).
    #[error("{path}: `{key}` must be {expected}", path = shown(.path))]
    WrongType {
        /// The transforms file.
        path: PathBuf,
        /// The key, with where it was found.
        key: String,
        /// What it must be.
        expected: &'static str,
    },
    /// A camera pose that is not a rigid camera-to-world transform.
    #[error("{path}: `{key}` {problem}", path = shown(.path))]
    BadMatrix {
        /// The transforms file.
        path: PathBuf,
        /// The key (`frames[3].transform_matrix`).
        key: String,
        /// What is wrong with it.
        problem: MatrixProblem,
    },
    /// A number outside its domain: a focal length or field of view that is not positive and
    /// finite, an image size that is not a positive integer, a principal point that is not
    /// finite...
    #[error("{path}: `{key}` is {value} ({rule})", path = shown(.path), value = number(*.value))]
    BadValue {
        /// The transforms file.
        path: PathBuf,
        /// The key, with where it was found.
        key: String,
        /// The offending value.
        value: f64,
        /// The rule it breaks.
        rule: &'static str,
    },
    /// A transforms file whose `frames` list is empty.
    #[error("{path}: no frames", path = shown(.path))]
    NoFrames {
        /// The transforms file.
        path: PathBuf,
    },
    /// A folder with no dataset in it: no transforms file, COLMAP model or LLFF poses file.
    #[error("{path}: no dataset (expected transforms.json, transforms_train.json, a COLMAP model in sparse/0, sparse or colmap/sparse/0, or poses_bounds.npy)", path = shown(.path))]
    NoTransforms {
        /// The folder.
        path: PathBuf,
    },
    /// Image files named by frames that do not exist (and the load did not ask to skip them).
    #[error("{path}: {count} image file(s) missing: {}{}", list(.first), if *.count > .first.len() { ", ..." } else { "" }, path = shown(.path))]
    MissingImages {
        /// The transforms file.
        path: PathBuf,
        /// How many are missing.
        count: usize,
        /// The first few of them.
        first: Vec<PathBuf>,
    },
    /// An image file that exists but does not decode.
    #[error("{path}: cannot decode image: {message}", path = shown(.path))]
    Decode {
        /// The image file.
        path: PathBuf,
        /// The decoder's reason, on one line.
        message: String,
    },
    /// An image whose size differs from the first image of its Blender split (the format has
    /// one `camera_angle_x` per split, so one size).
    #[error("{path}: image is {}x{} but {first} in the same split is {}x{}", .size.0, .size.1, .first_size.0, .first_size.1, path = shown(.path), first = shown(.first))]
    MixedSizes {
        /// The image file.
        path: PathBuf,
        /// Its width and height.
        size: (usize, usize),
        /// The split's first image.
        first: PathBuf,
        /// Its width and height.
        first_size: (usize, usize),
    },
    /// An image whose size disagrees with the `w` / `h` of its transforms file.
    #[error("{path}: image is {}x{} but {transforms} says w = {}, h = {}", .size.0, .size.1, .expected.0, .expected.1, path = shown(.path), transforms = shown(.transforms))]
    SizeMismatch {
        /// The image file.
        path: PathBuf,
        /// Its width and height.
        size: (usize, usize),
        /// The transforms file.
        transforms: PathBuf,
        /// Its `w` and `h`.
        expected: (usize, usize),
    },
    /// No image size could be found for cameras read without their images: no image file
    /// exists and the transforms file has no `w` / `h`.
    #[error("{path}: no image size: no image file of its frames exists and it has no `w` and `h`", path = shown(.path))]
    NoImageSize {
        /// The transforms file.
        path: PathBuf,
    },
    /// A `downscale` of 0, or one larger than an image.
    #[error("{path}: downscale {downscale} {problem}", path = shown(.path))]
    BadDownscale {
        /// The dataset (or the image too small for it).
        path: PathBuf,
        /// The requested factor.
        downscale: usize,
        /// Why it cannot be used.
        problem: &'static str,
    },
    /// A feature of the file that this crate does not read (a fisheye `camera_model`...).
    #[error("{path}: {what} is not supported", path = shown(.path))]
    Unsupported {
        /// The transforms file.
        path: PathBuf,
        /// What it asks for.
        what: String,
    },
    /// A camera that fogray-ops refused (an intrinsic or distortion value outside its domain).
    #[error("{path}: {key}: {source}", path = shown(.path))]
    Camera {
        /// The transforms file.
        path: PathBuf,
        /// The frame (`frames[3]`).
        key: String,
        /// The camera's reason (boxed: it is several times the size of the other variants,
        /// and every result of the crate would carry its size).
        source: Box<OpsError>,
    },
    /// An output path refused before any work (see [`check_outputs`](crate::check_outputs)):
    /// it would overwrite one of the command's inputs, it is a folder where a file is
    /// expected, its folder cannot be written...
    #[error("{path}: refused as an output: {problem}", path = shown(.path))]
    Output {
        /// The output, as the command was given it.
        path: PathBuf,
        /// Why it was refused.
        problem: crate::output::OutputProblem,
    },
    /// A binary file (a COLMAP `.bin`, an `.npy`) that ends before what it announces: cut
    /// short, or a count in it that the rest of the file cannot hold (refused before anything
    /// is allocated for it).
    #[error("{path}: truncated or corrupt at byte {offset}: {what} needs {needed} bytes, {available} left", path = shown(.path))]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Where the record that does not fit starts.
        offset: u64,
        /// What was being read.
        what: String,
        /// The bytes it needs.
        needed: u64,
        /// The bytes left from `offset`.
        available: u64,
    },
    /// A COLMAP camera whose model fogray does not read (a fisheye, FULL_OPENCV...).
    #[error("{path}: camera {camera} has model {model}, which is not supported (SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL and OPENCV are)", path = shown(.path))]
    CameraModel {
        /// The cameras file.
        path: PathBuf,
        /// The camera's id.
        camera: i64,
        /// The model's name (or its unknown id).
        model: String,
    },
    /// A COLMAP image whose camera id is not among the model's cameras.
    #[error("{path}: image `{image}` has camera id {camera}, which {cameras} does not hold", path = shown(.path), image = crate::escape_controls(.image), cameras = shown(.cameras))]
    UnknownCamera {
        /// The images file.
        path: PathBuf,
        /// The image's name.
        image: String,
        /// The camera id it names.
        camera: i64,
        /// The cameras file.
        cameras: PathBuf,
    },
    /// A record of a COLMAP file that does not read: a missing field, a word where a number
    /// belongs, an id given twice, bytes after the last record.
    #[error("{path}: {at}: {message}", path = shown(.path))]
    Malformed {
        /// The file.
        path: PathBuf,
        /// Where (`line 12`, `byte 340`, `image 7`).
        at: String,
        /// What is wrong.
        message: String,
    },
    /// An `.npy` file that is not the array the format needs (its dtype, order, shape or
    /// header).
    #[error("{path}: {what} is {found}, expected {expected}", path = shown(.path))]
    BadArray {
        /// The file.
        path: PathBuf,
        /// What is wrong (`the dtype`, `the shape`...).
        what: &'static str,
        /// What the file has.
        found: String,
        /// What it must have.
        expected: &'static str,
    },
    /// A folder the dataset needs that does not exist.
    #[error("{path}: folder not found ({what})", path = shown(.path))]
    MissingFolder {
        /// The folder.
        path: PathBuf,
        /// What it should hold.
        what: &'static str,
    },
    /// An LLFF capture whose images folder holds another number of images than there are
    /// poses.
    #[error("{path}: {poses} poses but {folder} holds {images} images", path = shown(.path), folder = shown(.folder))]
    ImageCount {
        /// The poses file.
        path: PathBuf,
        /// How many poses.
        poses: usize,
        /// The images folder.
        folder: PathBuf,
        /// How many images it holds.
        images: usize,
    },
    /// An image whose shape is not its camera's scaled (an LLFF image rotated or cropped).
    #[error("{path}: image is {}x{}, not the shape of the {}x{} that {poses} gives its camera", .size.0, .size.1, .expected.0, .expected.1, path = shown(.path), poses = shown(.poses))]
    AspectMismatch {
        /// The image file.
        path: PathBuf,
        /// Its width and height.
        size: (usize, usize),
        /// The poses file.
        poses: PathBuf,
        /// The width and height the poses file gives.
        expected: (f64, f64),
    },
    /// Pictures (one frame's, or all of them together) that need more memory than the machine
    /// has, refused before any is decoded.
    #[error("{path}: {source}", path = shown(.path))]
    TooLarge {
        /// The transforms file.
        path: PathBuf,
        /// What would need how much, and what is available.
        source: fogray_ops::limits::TooLarge,
    },
    /// A dataset with too few frames that have a picture to fit: one to train on and one held
    /// out.
    #[error("{path}: {frames} frame(s) with a picture{}; a fit needs at least two (one to train on, one held out)", skipped_note(*.skipped), path = shown(.path))]
    TooFewFrames {
        /// The transforms file (or the dataset's folder).
        path: PathBuf,
        /// Frames that have a picture.
        frames: usize,
        /// Frames dropped because their picture is missing.
        skipped: usize,
    },
    /// Something given to a writer that cannot be written (an image whose shape differs from
    /// its camera's, a non-finite value, no frames...).
    #[error("{path}: {message}", path = shown(.path))]
    BadInput {
        /// The file that was to be written.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

/// A number as a message writes it: in full up to 1e15, in scientific notation beyond (Rust
/// writes 1e308 in all its 309 digits).
fn number(value: f64) -> String {
    // Huge and tiny values in exponent form (1e-300 is not 300 zeros).
    if value.is_finite() && value != 0.0 && !(1e-6..1e15).contains(&value.abs()) {
        format!("{value:e}")
    } else {
        value.to_string()
    }
}

fn skipped_note(skipped: usize) -> String {
    match skipped {
        0 => String::new(),
        n => format!(" ({n} skipped: their picture is missing)"),
    }
}

fn list(paths: &[PathBuf]) -> String {
    paths
        .iter()
        .map(|p| shown(p).to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// Messages from the OS, the JSON parser and the image decoders, on one line.
pub(crate) fn one_line(message: impl fmt::Display) -> String {
    message.to_string().split_whitespace().collect::<Vec<_>>().join(" ")
}

impl DataError {
    pub(crate) fn io(path: impl Into<PathBuf>, err: impl fmt::Display) -> Self {
        DataError::Io {
            path: path.into(),
            message: one_line(err),
        }
    }
}
