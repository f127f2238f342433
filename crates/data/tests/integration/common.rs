//! Helpers: transforms files and images written by hand into temporary folders.

use std::path::{Path, PathBuf};

use fogray_data::DataError;
use image::{ImageBuffer, Pixel};
use serde_json::{json, Value};

/// A fresh temporary folder.
pub fn tempdir() -> tempfile::TempDir {
    tempfile::tempdir().expect("a temporary folder")
}

/// Writes `value` as JSON to `path`.
pub fn write_json(path: &Path, value: &Value) {
    std::fs::write(path, serde_json::to_string_pretty(value).unwrap()).unwrap();
}

/// An OpenGL camera-to-world matrix with identity rotation at `eye`.
pub fn at(eye: [f64; 3]) -> Value {
    json!([
        [1.0, 0.0, 0.0, eye[0]],
        [0.0, 1.0, 0.0, eye[1]],
        [0.0, 0.0, 1.0, eye[2]],
        [0.0, 0.0, 0.0, 1.0]
    ])
}

/// Saves an image buffer as PNG (or by `path`'s extension), creating the folder.
pub fn save<P>(path: &Path, image: &ImageBuffer<P, Vec<P::Subpixel>>)
where
    P: Pixel + image::PixelWithColorType,
    [P::Subpixel]: image::EncodableLayout,
{
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    image.save(path).unwrap();
}

/// A `w x h` RGB PNG at `path`, every pixel `rgb`.
pub fn solid_png(path: &Path, w: u32, h: u32, rgb: [u8; 3]) {
    save(path, &image::RgbImage::from_pixel(w, h, image::Rgb(rgb)));
}

/// A Blender folder in `dir`: `transforms_train.json` with `camera_angle_x = angle` and one
/// frame per (file_path, eye); a `w x h` grey PNG for each.
pub fn blender_folder(dir: &Path, angle: f64, frames: &[(&str, [f64; 3])], w: u32, h: u32) -> PathBuf {
    let list: Vec<Value> = frames
        .iter()
        .map(|(file, eye)| json!({ "file_path": file, "transform_matrix": at(*eye) }))
        .collect();
    for (file, _) in frames {
        solid_png(&dir.join(format!("{file}.png")), w, h, [128, 128, 128]);
    }
    let path = dir.join("transforms_train.json");
    write_json(&path, &json!({ "camera_angle_x": angle, "frames": list }));
    path
}

/// An instant-ngp `transforms.json` in `dir` with the given top-level keys and frames
/// (`frames` as JSON values); returns its path.
pub fn ngp_file(dir: &Path, top: Value, frames: Vec<Value>) -> PathBuf {
    let mut doc = top;
    doc.as_object_mut()
        .unwrap()
        .insert("frames".into(), Value::Array(frames));
    let path = dir.join("transforms.json");
    write_json(&path, &doc);
    path
}

/// Asserts that `err`'s message is one line and names `path`.
pub fn names(err: &DataError, path: &Path) {
    let msg = err.to_string();
    assert!(!msg.contains('\n'), "not one line: {msg}");
    assert!(
        msg.contains(&path.display().to_string()),
        "{msg} does not name {}",
        path.display()
    );
}
