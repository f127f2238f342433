//! `fogray view --model FILE [--port N]`: a model saved by `fogray fit` in the browser, served
//! on 127.0.0.1 only. The page orbits, pans and zooms a camera and asks the server for each
//! frame; the server renders it as `fogray render` does ([`render_picture`], the same options)
//! and sends it as PNG.
//!
//! The pieces: [`camera`] reads a frame request's camera, [`server`] answers the routes from a
//! [`server::Scene`] (what renders a camera), [`http`] is the bounded HTTP/1.1 around them;
//! [`live`] is the same page during `fogray fit --view`.
//! Ctrl-C stops accepting, lets the frames under way finish, and exits with status 130.

pub mod camera;
pub mod http;
pub mod live;
pub mod server;

use std::io::Write;
use std::marker::PhantomData;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use fogray_data::{load_cameras, shown};
use fogray_fit::checkpoint::{self, ModelInfo};
use fogray_fit::dataset::camera_rays;
use fogray_fit::images::to_u8;
use fogray_fit::interrupt::StopFlag;
use fogray_fit::model::RadianceField;
use fogray_fit::render::{render_picture, RenderOptions};
use fogray_fit::settings::Method;
use fogray_fit::space::SpaceChoice;
use fogray_ops::limits::{self, Bytes};
use fogray_ops::sample::OccupancyGrid;
use fogray_ops::PinholeCamera;
use fogray_tape::Float;
use serde_json::json;

use crate::error::CliError;
use crate::framing::FALLBACK_FOV_DEGREES;
use crate::render_memory::render_need;
use crate::saved::{SavedModel, WithModel};
use server::{RgbFrame, Scene, Site};

/// The flags of `fogray view`.
#[derive(Debug, Clone, clap::Args)]
pub struct ViewArgs {
    /// A model written by `fogray fit --save-model`.
    #[arg(long, value_name = "FILE")]
    pub model: PathBuf,
    /// The port on 127.0.0.1 to serve on; 0 lets the system choose a free one (the address is
    /// printed either way).
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub port: u16,
}

/// The side of the first frame where the dataset gives no size.
const FALLBACK_SIDE: usize = 400;

/// The longest side of the first frame: a dataset's full-size pictures would make every
/// frame slow.
const FIRST_FRAME_SIDE: usize = 800;

/// Runs `fogray view` until Ctrl-C. The address goes to stdout as soon as the model is
/// loaded and the server listens (`fogray view: http://127.0.0.1:PORT/`).
///
/// Errors: a model file that is not a fogray model, a port that cannot be bound, Ctrl-C that
/// cannot be caught.
pub fn run(args: &ViewArgs) -> Result<(), CliError> {
    let saved = SavedModel::open(&args.model, "fogray view")?;
    let stop = StopFlag::on_ctrl_c()?;
    saved.with(Serve {
        args,
        info: &saved.info,
        stop,
    })
}

/// The server's work, once the model's type is known.
struct Serve<'a> {
    args: &'a ViewArgs,
    info: &'a ModelInfo,
    stop: StopFlag,
}

impl WithModel for Serve<'_> {
    type Output = ();

    fn run<F: Float, M: RadianceField<F>>(self, path: &Path) -> Result<(), CliError> {
        let saved = checkpoint::load::<F, M>(path)?;
        let occupancy = saved.occupancy_grid()?;
        let background = match self.info.extra.get("background") {
            Some(text) => serde_json::from_str::<[f64; 3]>(text).map_err(|e| CliError::SavedEntry {
                path: path.to_path_buf(),
                key: "background",
                text: text.clone(),
                reason: e.to_string(),
            })?,
            None => [1.0; 3],
        };
        let scene = ModelScene::<F, M> {
            model: saved.start.model,
            occupancy,
            options: RenderOptions {
                background,
                method: Method::Fused,
                depth: false,
            },
            info: self.info,
            float: PhantomData,
        };
        let views = dataset_cameras(path, self.info);
        let photos = dataset_photos(self.info, &views);
        let info = describe(path, self.info, background, &views, !photos.is_empty());
        let listener = http::bind(self.args.port).map_err(|source| CliError::Listen {
            flag: "--port",
            port: self.args.port,
            source,
        })?;
        let address = listener.local_addr().map_err(CliError::ListenAddress)?;
        let site = Site {
            scene: &scene,
            info: info.to_string(),
            views: views.into_iter().map(|(_, c)| c).collect(),
            photos,
            rendering: Mutex::new(()),
        };
        // Printed and flushed once the server is ready, so that a script may wait for it.
        let mut out = std::io::stdout().lock();
        let _ = writeln!(out, "fogray view: http://{address}/").and_then(|()| out.flush());
        drop(out);
        http::serve(&listener, &site, &self.stop).map_err(|source| CliError::Serve { address, source })
    }
}

/// A model loaded from a file, rendered as `fogray render` renders it.
struct ModelScene<'a, F, M> {
    model: M,
    occupancy: Option<OccupancyGrid>,
    options: RenderOptions,
    info: &'a ModelInfo,
    float: PhantomData<fn() -> F>,
}

impl<F: Float, M: RadianceField<F>> Scene for ModelScene<'_, F, M> {
    fn render(&self, camera: &PinholeCamera) -> Result<RgbFrame, CliError> {
        let k = camera.intrinsics();
        let (width, height) = (k.width, k.height);
        let what = format!("a {width}x{height} frame");
        Bytes::check(
            render_need(self.info, 1, [width, height]),
            limits::available(),
            &what,
            "rendering",
        )?;
        let (origins, directions) = camera_rays(camera);
        let picture = render_picture(
            &self.model,
            self.occupancy.as_ref(),
            &origins,
            &directions,
            [height, width],
            &self.options,
        )?;
        Ok(RgbFrame {
            width,
            height,
            pixels: picture.color.iter().map(|&v| to_u8(v)).collect(),
        })
    }
}

/// The cameras of the model's dataset, with their names; none where the checkpoint names no
/// dataset or it cannot be read (then a note on stderr: the page has no views to offer).
fn dataset_cameras(model: &Path, info: &ModelInfo) -> Vec<(String, PinholeCamera)> {
    let Some(data) = info.extra.get("data") else {
        return Vec::new();
    };
    let downscale = info.extra.get("downscale").and_then(|d| d.parse().ok()).unwrap_or(1);
    match load_cameras(Path::new(data), downscale) {
        Ok(cameras) => cameras.into_iter().map(|c| (c.name, c.camera)).collect(),
        Err(e) => {
            eprintln!(
                "fogray view: note: {}'s dataset cannot be read ({}); the page offers no dataset views",
                shown(model),
                fogray_data::escape_controls(&e.to_string())
            );
            Vec::new()
        }
    }
}

/// The photograph of each of `views`, in their order, as the dataset the checkpoint names lists
/// them; none unless every one is found there under its view's name (a dataset whose files
/// are listed in another order than its cameras offers no photographs rather than wrong ones).
fn dataset_photos(info: &ModelInfo, views: &[(String, PinholeCamera)]) -> Vec<PathBuf> {
    let Some(data) = info.extra.get("data") else {
        return Vec::new();
    };
    let Ok(files) = fogray_data::dataset_files(Path::new(data)) else {
        return Vec::new();
    };
    let named = files.pictures.len() == views.len()
        && files
            .pictures
            .iter()
            .zip(views)
            .all(|(file, (name, _))| file.file_stem().is_some_and(|s| s == name.as_str()));
    if named {
        files.pictures
    } else {
        Vec::new()
    }
}

/// A camera as the page and `/frame` take it: eye, target, up, vertical field of view in
/// degrees, size.
fn camera_json(eye: [f64; 3], target: [f64; 3], up: [f64; 3], fov: f64, [w, h]: [usize; 2]) -> serde_json::Value {
    json!({ "eye": eye, "target": target, "up": up, "fov": fov, "w": w, "h": h })
}

/// The vertical field of view of `camera`, degrees.
fn fov_degrees(camera: &PinholeCamera) -> f64 {
    let k = camera.intrinsics();
    (2.0 * (k.height as f64 / (2.0 * k.fy.abs())).atan()).to_degrees()
}

/// The world's up as `camera` sees it (minus its image's y axis).
fn up_of(camera: &PinholeCamera) -> [f64; 3] {
    let m = camera.camera_to_world();
    [-m[0][1], -m[1][1], -m[2][1]]
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn norm(a: [f64; 3]) -> f64 {
    a.iter().map(|v| v * v).sum::<f64>().sqrt()
}

/// `/info`: what the model is, where it is, a first camera that looks at it, and the dataset's
/// views (each as a look-at camera through its own centre and axis, aimed at the model's
/// centre's depth).
fn describe(
    model: &Path,
    info: &ModelInfo,
    background: [f64; 3],
    views: &[(String, PinholeCamera)],
    photos: bool,
) -> serde_json::Value {
    let settings = &info.settings;
    let contracted = settings.space == SpaceChoice::Contracted;
    let (centre, extent, bounds, framing) = match (contracted, settings.framing) {
        (true, Some(f)) => (
            f.centre,
            f.radius,
            serde_json::Value::Null,
            json!({ "centre": f.centre, "radius": f.radius }),
        ),
        _ => {
            let b = settings.model_box();
            let centre = std::array::from_fn(|i| (b.min[i] + b.max[i]) / 2.0);
            let half_diagonal = norm(sub(b.max, centre));
            (
                centre,
                half_diagonal,
                json!({ "min": b.min, "max": b.max }),
                serde_json::Value::Null,
            )
        }
    };
    let first = first_camera(contracted, centre, extent, views);
    let views_json: Vec<serde_json::Value> = views
        .iter()
        .enumerate()
        .map(|(index, (name, c))| {
            let m = c.camera_to_world();
            let eye = c.centre();
            let forward = [m[0][2], m[1][2], m[2][2]];
            let depth = norm(sub(centre, eye)).max(1e-6);
            let target = std::array::from_fn(|i| eye[i] + depth * forward[i]);
            let k = c.intrinsics();
            let mut v = camera_json(eye, target, up_of(c), fov_degrees(c), [k.width, k.height]);
            v["index"] = json!(index);
            v["name"] = json!(name);
            v["photo"] = json!(photos);
            v
        })
        .collect();
    json!({
        "model": model.file_name().map(|n| n.to_string_lossy().into_owned()),
        "kind": info.kind,
        "precision": settings.precision,
        "space": if contracted { "contracted" } else { "box" },
        "bounds": bounds,
        "framing": framing,
        "background": background,
        "dataset": info.extra.get("data"),
        "camera": first,
        "limits": { "max_side": camera::MAX_SIDE },
        "views": views_json,
    })
}

/// `up`, or the world axis it is within [`SNAP_DEGREES`] of: cameras that stand around an
/// object tilt their up towards it, and their mean is then a little off the axis the scene
/// was built along, which orbiting about would show as a wobble.
fn snapped(up: [f64; 3]) -> [f64; 3] {
    let cos = SNAP_DEGREES.to_radians().cos();
    for axis in 0..3 {
        for sign in [1.0, -1.0] {
            if sign * up[axis] >= cos {
                let mut e = [0.0; 3];
                e[axis] = sign;
                return e;
            }
        }
    }
    up
}

/// How near a world axis the dataset cameras' mean up must be to be taken as that axis.
const SNAP_DEGREES: f64 = 10.0;

/// The first camera: from the direction of the dataset's first camera at the cameras' mean
/// distance, with their mean up (snapped to a world axis within 10 degrees) and the first
/// one's field of view; without a dataset, 30
/// degrees above the +x axis (+z up, as Blender scenes are), at the distance where a box's
/// bounding sphere fits the view, or on the framing's sphere (where a capture's cameras stand).
fn first_camera(
    contracted: bool,
    centre: [f64; 3],
    extent: f64,
    views: &[(String, PinholeCamera)],
) -> serde_json::Value {
    if let Some((_, first)) = views.first() {
        let mean_distance = views.iter().map(|(_, c)| norm(sub(c.centre(), centre))).sum::<f64>() / views.len() as f64;
        let mut up = [0.0; 3];
        for (_, c) in views {
            let u = up_of(c);
            up = std::array::from_fn(|i| up[i] + u[i]);
        }
        let direction = sub(first.centre(), centre);
        let (d, u) = (norm(direction), norm(up));
        if d > 1e-9 && u > 1e-9 && mean_distance.is_finite() {
            let eye = std::array::from_fn(|i| centre[i] + direction[i] / d * mean_distance);
            let up = snapped(up.map(|v| v / u));
            let k = first.intrinsics();
            let scale = (FIRST_FRAME_SIDE as f64 / k.width.max(k.height) as f64).min(1.0);
            let size = [k.width, k.height].map(|s| ((s as f64 * scale).round() as usize).max(1));
            return camera_json(eye, centre, up, fov_degrees(first), size);
        }
    }
    let fov = FALLBACK_FOV_DEGREES;
    let distance = if contracted {
        extent
    } else {
        extent / (fov.to_radians() / 2.0).sin()
    };
    let elevation = 30f64.to_radians();
    let eye = [
        centre[0] + distance * elevation.cos(),
        centre[1],
        centre[2] + distance * elevation.sin(),
    ];
    camera_json(eye, centre, [0.0, 0.0, 1.0], fov, [FALLBACK_SIDE; 2])
}
