//! Writing a dataset: cameras and images out as a Blender folder or an instant-ngp
//! `transforms.json`, so that a scene rendered by fogray (or anything else) can be read back by
//! [`load`](crate::load) and by the tools that read these formats.
//!
//! Images are `[height][width][3]` (RGB) or `[height][width][4]` (RGBA, straight alpha) arrays
//! in `[0, 1]`, clamped and rounded to 8 bits. Poses are written as OpenGL camera-to-world
//! matrices (the camera's y and z axes negated from fogray's OpenCV ones). Every file is
//! written whole or not at all ([`write_atomic`](crate::write_atomic)).

use std::path::{Path, PathBuf};

use fogray_ops::{Intrinsics, PinholeCamera};
use ndarray::Array3;
use serde_json::{json, Map, Value};

use crate::error::DataError;
use crate::output::write_atomic;
use crate::png::{write_png8, PngChannels};
use crate::pose::flip_yz;

/// One view to write: its name (the image file's stem), camera and image.
pub type FrameToWrite<'a> = (&'a str, &'a PinholeCamera, &'a Array3<f64>);

/// How close `fx` and `fy`, and the principal point and the image centre, must be for
/// [`write_blender`], which stores one field of view and no principal point (relative to the
/// focal length / the image size).
const BLENDER_TOLERANCE: f64 = 1e-9;

/// Writes `frames` as a Blender dataset in `dir` (created if needed): `transforms_train.json`
/// with `camera_angle_x = 2 atan(W / (2 fx))`, and `train/NAME.png` per frame.
///
/// The format has one field of view and one image size for all frames, square pixels, a
/// centred principal point and no distortion. Errors ([`DataError::BadInput`]): no frames, a
/// camera that breaks one of those rules or differs from the first, a name that is empty or
/// holds a path separator, an image whose shape is not its camera's `H x W x 3` (or 4) or that
/// holds a non-finite value; [`DataError::Io`] for a file that cannot be written.
/// Returns the transforms file's path.
pub fn write_blender(dir: &Path, frames: &[FrameToWrite<'_>]) -> Result<PathBuf, DataError> {
    let transforms = dir.join("transforms_train.json");
    let bad = |message: String| DataError::BadInput {
        path: transforms.clone(),
        message,
    };
    let first = frames
        .first()
        .ok_or_else(|| bad("no frames to write".into()))?
        .1
        .intrinsics();
    for (name, camera, _) in frames {
        let k = camera.intrinsics();
        if (k.width, k.height) != (first.width, first.height) || !close(k.fx, first.fx) {
            return Err(bad(format!("camera of `{name}` differs from the first frame's (the format has one field of view and one image size)")));
        }
        if !close(k.fx, k.fy) || !close(k.cx, k.width as f64 / 2.0) || !close(k.cy, k.height as f64 / 2.0) {
            return Err(bad(format!("camera of `{name}` has fx != fy or an off-centre principal point, which the Blender format cannot store (use write_instant_ngp)")));
        }
        if !camera.distortion().is_none() {
            return Err(bad(format!(
                "camera of `{name}` has lens distortion, which the Blender format cannot store (use write_instant_ngp)"
            )));
        }
    }
    let written = write_images(dir, "train", frames, &transforms)?;
    let list: Vec<Value> = frames
        .iter()
        .map(|(name, camera, _)| {
            json!({
                "file_path": format!("./train/{name}"),
                "transform_matrix": flip_yz(camera.camera_to_world()),
            })
        })
        .collect();
    debug_assert_eq!(written.len(), list.len());
    let angle = 2.0 * (first.width as f64 / (2.0 * first.fx)).atan();
    let doc = json!({ "camera_angle_x": angle, "frames": list });
    write_json(&transforms, &doc)?;
    Ok(transforms)
}

/// Writes `frames` as an instant-ngp / nerfstudio dataset in `dir` (created if needed):
/// `transforms.json` and `images/NAME.png` per frame (`file_path` with its extension).
///
/// The intrinsics and OpenCV distortion (`fl_x fl_y cx cy w h k1 k2 p1 p2 k3 k4`,
/// `camera_model` `OPENCV`) are written once at the top level when every camera shares them,
/// else per frame. Errors as [`write_blender`], without its camera rules.
/// Returns the transforms file's path.
pub fn write_instant_ngp(dir: &Path, frames: &[FrameToWrite<'_>]) -> Result<PathBuf, DataError> {
    let transforms = dir.join("transforms.json");
    let first = frames.first().ok_or_else(|| DataError::BadInput {
        path: transforms.clone(),
        message: "no frames to write".into(),
    })?;
    write_images(dir, "images", frames, &transforms)?;
    let shared = frames
        .iter()
        .all(|(_, c, _)| c.intrinsics() == first.1.intrinsics() && c.distortion() == first.1.distortion());
    let mut doc = Map::new();
    doc.insert("camera_model".into(), json!("OPENCV"));
    if shared {
        lens_keys(first.1, &mut doc);
    }
    let list: Vec<Value> = frames
        .iter()
        .map(|(name, camera, _)| {
            let mut frame = Map::new();
            frame.insert("file_path".into(), json!(format!("images/{name}.png")));
            frame.insert("transform_matrix".into(), json!(flip_yz(camera.camera_to_world())));
            if !shared {
                lens_keys(camera, &mut frame);
            }
            Value::Object(frame)
        })
        .collect();
    doc.insert("frames".into(), Value::Array(list));
    write_json(&transforms, &Value::Object(doc))?;
    Ok(transforms)
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= BLENDER_TOLERANCE * a.abs().max(b.abs()).max(1.0)
}

fn lens_keys(camera: &PinholeCamera, out: &mut Map<String, Value>) {
    let Intrinsics {
        fx,
        fy,
        cx,
        cy,
        width,
        height,
    } = *camera.intrinsics();
    let d = camera.distortion();
    let entries = [
        ("fl_x", json!(fx)),
        ("fl_y", json!(fy)),
        ("cx", json!(cx)),
        ("cy", json!(cy)),
        ("w", json!(width)),
        ("h", json!(height)),
        ("k1", json!(d.k1)),
        ("k2", json!(d.k2)),
        ("p1", json!(d.p1)),
        ("p2", json!(d.p2)),
        ("k3", json!(d.k3)),
        ("k4", json!(d.k4)),
    ];
    for (key, value) in entries {
        out.insert(key.into(), value);
    }
}

/// Checks every frame, then writes `dir/sub/NAME.png` for each; returns the paths.
fn write_images(
    dir: &Path,
    sub: &str,
    frames: &[FrameToWrite<'_>],
    transforms: &Path,
) -> Result<Vec<PathBuf>, DataError> {
    let bad = |message: String| DataError::BadInput {
        path: transforms.to_path_buf(),
        message,
    };
    for (name, camera, image) in frames {
        if name.is_empty() || name.contains(['/', '\\']) || *name == "." || *name == ".." {
            return Err(bad(format!("frame name `{name}` is not a plain file name")));
        }
        let k = camera.intrinsics();
        let (h, w, c) = image.dim();
        if (h, w) != (k.height, k.width) || !(c == 3 || c == 4) {
            return Err(bad(format!(
                "image of `{name}` is {h}x{w}x{c} but its camera needs {}x{}x3 (or x4)",
                k.height, k.width
            )));
        }
        if image.iter().any(|v| !v.is_finite()) {
            return Err(bad(format!("image of `{name}` has a value that is not finite")));
        }
    }
    let folder = dir.join(sub);
    std::fs::create_dir_all(&folder).map_err(|e| DataError::io(&folder, e))?;
    frames
        .iter()
        .map(|(name, _, image)| {
            let path = folder.join(format!("{name}.png"));
            write_png(&path, image)?;
            Ok(path)
        })
        .collect()
}

fn write_png(path: &Path, image: &Array3<f64>) -> Result<(), DataError> {
    let (h, w, c) = image.dim();
    let bytes: Vec<u8> = image
        .iter()
        .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect();
    let channels = if c == 4 { PngChannels::Rgba } else { PngChannels::Rgb };
    let too_large = |_| DataError::BadInput {
        path: path.to_path_buf(),
        message: format!("a {w}x{h} picture is larger than PNG holds"),
    };
    let (w, h) = (
        u32::try_from(w).map_err(too_large)?,
        u32::try_from(h).map_err(too_large)?,
    );
    write_png8(path, &bytes, w, h, channels)
}

fn write_json(path: &Path, doc: &Value) -> Result<(), DataError> {
    let text = serde_json::to_string_pretty(doc).map_err(|e| DataError::io(path, e))?;
    write_atomic(path, |out| out.write_all((text + "\n").as_bytes()))
}
