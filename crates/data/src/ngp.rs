//! The instant-ngp / nerfstudio format: one `transforms.json` whose intrinsics are global or
//! per frame (a frame's values override the global ones): `fl_x fl_y cx cy w h`, with
//! `camera_angle_x` / `camera_angle_y` (radians) as the fallback for the focal lengths and the
//! image centre for a missing principal point; OpenCV distortion `k1 k2 k3 k4 p1 p2` (absent
//! = 0); `frames[].file_path` with its extension, relative to the file's folder;
//! `frames[].transform_matrix` OpenGL camera-to-world.
//!
//! # The scene box
//!
//! instant-ngp maps a world point `p` of the file into its unit cube as
//! `q = cycle(p * scale + offset)`, where `cycle` sends `(x, y, z)` to `(y, z, x)`, `scale`
//! defaults to 0.33 and `offset` to `(0.5, 0.5, 0.5)` (a number is used for all three axes),
//! and it marches the cube `[0.5 - aabb_scale / 2, 0.5 + aabb_scale / 2]^3` in `q` (with
//! `aabb_scale` defaulting to 1). A cube is unchanged by the cycle, so in the file's own world
//! coordinates the box is, axis by axis (`offset` in the file's axis order),
//!
//! ```text
//! min_i = (0.5 - aabb_scale / 2 - offset_i) / scale
//! max_i = (0.5 + aabb_scale / 2 - offset_i) / scale
//! ```
//!
//! which for the defaults is `[-1.5152 aabb_scale, 1.5152 aabb_scale]^3` (`0.5 / 0.33`). A
//! file with `aabb: [[x0, y0, z0], [x1, y1, z1]]` sets, as instant-ngp does,
//! `scale = 1 / max_i |x1_i - x0_i|` and `offset_i = 0.5 - scale (x0_i + x1_i) / 2` before the
//! formula above.

use std::path::{Path, PathBuf};

use fogray_ops::LensDistortion;

use crate::error::DataError;
use crate::json::{self, Obj};
use crate::ranges::{MAX_AABB_SCALE, MAX_COORDINATE};
use crate::spec::{image_path, FrameSpec, Lens};

/// instant-ngp's default `scale` (its `NERF_SCALE`).
pub const NGP_DEFAULT_SCALE: f64 = 0.33;
/// instant-ngp's default `offset`, per axis.
pub const NGP_DEFAULT_OFFSET: [f64; 3] = [0.5; 3];

/// Image extensions tried, in order, for a `file_path` without one whose file does not exist.
const TRIED_EXTENSIONS: [&str; 3] = ["png", "jpg", "jpeg"];

/// A parsed instant-ngp / nerfstudio transforms file.
pub(crate) struct NgpFile {
    pub frames: Vec<FrameSpec>,
    pub scene_box: ([f64; 3], [f64; 3]),
}

/// The camera values of a frame or the top level, before merging.
#[derive(Default, Clone, Copy)]
struct Camera {
    lens: Lens,
    w: Option<usize>,
    h: Option<usize>,
    k: [Option<f64>; 6],
}

const DISTORTION_KEYS: [&str; 6] = ["k1", "k2", "k3", "k4", "p1", "p2"];

impl Camera {
    fn read(obj: Obj<'_>) -> Result<Camera, DataError> {
        if let Some(model) = obj.string("camera_model")? {
            if model != "OPENCV" && model != "PINHOLE" {
                return Err(DataError::Unsupported {
                    path: obj.path.to_path_buf(),
                    what: format!("{} \"{model}\" (only OPENCV and PINHOLE are)", obj.name("camera_model")),
                });
            }
        }
        if obj.get("is_fisheye").and_then(|v| v.as_bool()) == Some(true) {
            return Err(DataError::Unsupported {
                path: obj.path.to_path_buf(),
                what: format!("{} (a fisheye lens)", obj.name("is_fisheye")),
            });
        }
        let mut k = [None; 6];
        for (slot, key) in k.iter_mut().zip(DISTORTION_KEYS) {
            *slot = obj.finite(key)?;
            if let Some((v, rule)) = slot.and_then(|v| Some((v, crate::ranges::distortion_outside(key, v)?))) {
                return Err(obj.bad_value(key, v, rule));
            }
        }
        Ok(Camera {
            lens: Lens::read(obj)?,
            w: obj.size("w")?,
            h: obj.size("h")?,
            k,
        })
    }

    fn overridden_by(self, frame: Camera) -> Camera {
        let mut k = self.k;
        for (slot, v) in k.iter_mut().zip(frame.k) {
            *slot = v.or(*slot);
        }
        Camera {
            lens: self.lens.overridden_by(frame.lens),
            w: frame.w.or(self.w),
            h: frame.h.or(self.h),
            k,
        }
    }

    fn distortion(&self) -> LensDistortion {
        let [k1, k2, k3, k4, p1, p2] = self.k.map(|v| v.unwrap_or(0.0));
        LensDistortion { k1, k2, k3, k4, p1, p2 }
    }
}

/// Reads the instant-ngp / nerfstudio transforms file `path`.
pub(crate) fn read(path: &Path) -> Result<NgpFile, DataError> {
    let root = json::read(path)?;
    let folder = path.parent().unwrap_or(Path::new("."));
    let top = Obj {
        path,
        map: &root,
        prefix: "",
    };
    let global = Camera::read(top)?;
    let scene_box = scene_box(top)?;
    let frames = json::frames(path, &root)?
        .into_iter()
        .enumerate()
        .map(|(i, map)| {
            let prefix = format!("frames[{i}].");
            let frame = Obj {
                path,
                map,
                prefix: &prefix,
            };
            let camera = global.overridden_by(Camera::read(frame)?);
            if !camera.lens.has_focal() {
                return Err(frame.missing("fl_x (or fl_y, camera_angle_x, camera_angle_y)"));
            }
            let file_path = frame.string("file_path")?.ok_or_else(|| frame.missing("file_path"))?;
            let pose = crate::pose::read_pose(frame, "transform_matrix")?;
            let (file, name) = image_path(folder, file_path, false);
            Ok(FrameSpec {
                transforms: path.to_path_buf(),
                key: format!("frames[{i}]"),
                name,
                file: with_found_extension(file),
                pose,
                lens: camera.lens,
                distortion: camera.distortion(),
                size: camera.w.zip(camera.h),
            })
        })
        .collect::<Result<Vec<_>, DataError>>()?;
    Ok(NgpFile { frames, scene_box })
}

/// A `file_path` without an extension names the first of `.png`, `.jpg`, `.jpeg` that exists
/// (as instant-ngp resolves it); otherwise it is taken as is.
fn with_found_extension(file: PathBuf) -> PathBuf {
    if file.extension().is_some() || file.exists() {
        return file;
    }
    TRIED_EXTENSIONS
        .iter()
        .map(|ext| file.with_extension(ext))
        .find(|f| f.exists())
        .unwrap_or(file)
}

/// The scene box of the [module docs](self), from `aabb_scale`, `scale`, `offset` and `aabb`.
fn scene_box(top: Obj<'_>) -> Result<([f64; 3], [f64; 3]), DataError> {
    let aabb_scale = top.positive("aabb_scale")?.unwrap_or(1.0);
    if aabb_scale > MAX_AABB_SCALE {
        return Err(top.bad_value("aabb_scale", aabb_scale, "must be at most 1024"));
    }
    let mut scale = top.positive("scale")?.unwrap_or(NGP_DEFAULT_SCALE);
    let mut offset = match top.get("offset") {
        None => NGP_DEFAULT_OFFSET,
        Some(v) => match (v.as_f64(), v.as_array()) {
            (Some(o), _) => [o; 3],
            (None, Some(a)) if a.len() == 3 && a.iter().all(|x| x.is_f64() || x.is_i64() || x.is_u64()) => {
                [0, 1, 2].map(|i| a[i].as_f64().unwrap_or(f64::NAN))
            }
            _ => return Err(top.wrong_type("offset", "a number or an array of 3 numbers")),
        },
    };
    if let Some(v) = top.get("aabb") {
        let corners = v
            .as_array()
            .filter(|a| a.len() == 2)
            .and_then(|a| {
                let corner = |c: &serde_json::Value| -> Option<[f64; 3]> {
                    let c = c.as_array().filter(|c| c.len() == 3)?;
                    Some([c[0].as_f64()?, c[1].as_f64()?, c[2].as_f64()?])
                };
                Some((corner(&a[0])?, corner(&a[1])?))
            })
            .ok_or_else(|| top.wrong_type("aabb", "two corners of 3 numbers each"))?;
        let (lo, hi) = corners;
        let length = (0..3).map(|i| (hi[i] - lo[i]).abs()).fold(0.0f64, f64::max);
        if !(length.is_finite() && length > 0.0) {
            return Err(top.bad_value("aabb", length, "its largest side must be positive and finite"));
        }
        scale = 1.0 / length;
        offset = [0, 1, 2].map(|i| 0.5 - scale * (lo[i] + hi[i]) / 2.0);
    }
    if let Some(i) = (0..3).find(|&i| !offset[i].is_finite()) {
        return Err(top.bad_value("offset", offset[i], "must be finite"));
    }
    let (min, max) = ngp_scene_box(aabb_scale, scale, offset);
    // A tiny `scale` or a huge `offset` sends the box out of any scene's reach.
    if min.iter().chain(&max).any(|v| v.is_nan() || v.abs() > MAX_COORDINATE) {
        // Named after the entry the file gives that moves the box furthest: its corners are
        // not in the file.
        let rule = "the scene box it gives (with aabb_scale, scale, offset, aabb) must lie within 1e6 of the origin";
        let farthest = |v: [f64; 3]| v.into_iter().fold(0.0f64, |m, x| if x.abs() > m.abs() { x } else { m });
        return Err(if top.get("aabb").is_some() {
            top.bad_value("aabb", farthest(min).abs().max(farthest(max).abs()), rule)
        } else if top.get("offset").is_some() {
            top.bad_value("offset", farthest(offset), rule)
        } else if top.get("scale").is_some() {
            top.bad_value("scale", scale, rule)
        } else {
            top.bad_value("aabb_scale", aabb_scale, rule)
        });
    }
    Ok((min, max))
}

/// The box in world coordinates that instant-ngp marches for `aabb_scale`, `scale` and
/// `offset`: axis by axis `[(0.5 - aabb_scale / 2 - offset_i) / scale, (0.5 + aabb_scale / 2 - offset_i) / scale]`
/// (instant-ngp's cube mapped back to world coordinates; see the crate docs).
pub fn ngp_scene_box(aabb_scale: f64, scale: f64, offset: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let half = aabb_scale / 2.0;
    (
        offset.map(|o| (0.5 - half - o) / scale),
        offset.map(|o| (0.5 + half - o) / scale),
    )
}
