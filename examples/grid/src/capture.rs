//! A phone-like capture of a scene: what a hand-held walk around an object gives to
//! colmap2nerf or `ns-process-data`, made exactly, so that `fogray fit` can be measured on
//! such data with known answers.
//!
//! What makes it a capture rather than the ring's photographs:
//! - **a background beyond the box**: the scene stands in a room, a sphere of radius
//!   [`CaptureSettings::room_radius`] around the origin whose wall is painted with a smooth
//!   pattern ([`wall_color`]); the wall is at a finite distance, so it moves against the scene
//!   as the camera moves (parallax), which an environment at infinity explains only in part;
//! - **no alpha**: every picture is RGB, the wall behind whatever the scene lets through;
//! - **a real lens**: an off-centre principal point and OpenCV distortion
//!   ([`CaptureSettings::distortion`]); each pixel's ray is the one the lens sends there
//!   (`PinholeCamera::direction` undistorts it), so the photograph is exact for that lens;
//! - **a hand-held path**: the views go once around the scene at heights and distances that
//!   wander, aimed near the centre, not on a lattice.
//!
//! Along each ray the scene is composited exactly ([`render_ray`] over a black background)
//! and the wall's colour where the ray meets it is added times the transmittance.

use fogray::ops::{Intrinsics, LensDistortion, OpsError, PinholeCamera};
use ndarray::Array3;

use crate::exact::{render_ray, Ray};
use crate::photographs::picture;
use crate::scene::Scene;

/// The capture's cameras, lens and room (the command line of `fogray-grid capture`).
#[derive(Debug, Clone, Copy, PartialEq, clap::Args)]
pub struct CaptureSettings {
    /// Views along the walk (every eighth is held out by `fogray fit`).
    #[arg(long, default_value_t = CaptureSettings::DEFAULT.views)]
    pub views: usize,
    /// Picture width in pixels.
    #[arg(long, default_value_t = CaptureSettings::DEFAULT.width)]
    pub width: usize,
    /// Picture height in pixels.
    #[arg(long, default_value_t = CaptureSettings::DEFAULT.height)]
    pub height: usize,
    /// The lens's OpenCV distortion.
    #[arg(skip = CaptureSettings::DEFAULT.distortion)]
    pub distortion: LensDistortion,
    /// The room's radius, beyond the scene's box and the cameras (more than 3.6).
    #[arg(long, default_value_t = CaptureSettings::DEFAULT.room_radius)]
    pub room_radius: f64,
}

impl CaptureSettings {
    /// 120 views of 480 x 360 pixels through a barrel-distorted lens, in a room of radius 8
    /// (the cameras walk at about 3 from the centre).
    pub const DEFAULT: CaptureSettings = CaptureSettings {
        views: 120,
        width: 480,
        height: 360,
        distortion: LensDistortion {
            k1: -0.12,
            k2: 0.03,
            p1: 0.0008,
            p2: -0.0005,
            ..LensDistortion::NONE
        },
        room_radius: 8.0,
    };
}

impl Default for CaptureSettings {
    fn default() -> Self {
        CaptureSettings::DEFAULT
    }
}

/// Why a capture cannot be made.
#[derive(Debug, thiserror::Error)]
pub enum CaptureError {
    /// Fewer than 2 views, an empty picture, or a room that does not hold the cameras.
    #[error("invalid capture settings: {0}")]
    Settings(String),
    /// A camera the ops refuse (for example, a distortion that does not invert over the picture).
    #[error("camera {view}: {source}")]
    Camera {
        /// The view's index.
        view: usize,
        /// The refusal.
        source: OpsError,
    },
}

/// The farthest the walk takes a camera from the origin (see [`cameras`]).
const MAX_CAMERA_DISTANCE: f64 = 3.6;

/// The hand-held walk: view `i` of `n` at azimuth `2 pi i / n` (plus a wobble), at a height
/// of 10 to 40 degrees and a distance of 2.7 to 3.3 that vary smoothly along the walk, aimed
/// at a point that wanders within 0.15 of the centre across and 0.2 below it, world `z` up
/// (the built-in scene's floor is level in `z`). The lens is `settings.distortion` with the
/// focal length `0.85 width` and the principal point 1.1 % and 0.7 % of the picture off its
/// centre.
pub fn cameras(settings: &CaptureSettings) -> Result<Vec<PinholeCamera>, CaptureError> {
    let s = settings;
    if s.views < 2 || s.width == 0 || s.height == 0 {
        return Err(CaptureError::Settings(format!(
            "{} views of {} x {} pixels (at least 2 views of one pixel)",
            s.views, s.width, s.height
        )));
    }
    if !(s.room_radius.is_finite() && s.room_radius > MAX_CAMERA_DISTANCE) {
        return Err(CaptureError::Settings(format!(
            "room radius {} does not hold the cameras (they go {MAX_CAMERA_DISTANCE} from the centre)",
            s.room_radius
        )));
    }
    let f = 0.85 * s.width as f64;
    let intrinsics = Intrinsics {
        width: s.width,
        height: s.height,
        fx: f,
        fy: f,
        cx: 0.5 * s.width as f64 + 0.011 * s.width as f64,
        cy: 0.5 * s.height as f64 - 0.007 * s.height as f64,
    };
    let tau = std::f64::consts::TAU;
    (0..s.views)
        .map(|i| {
            let u = i as f64 / s.views as f64;
            let azimuth = tau * u + 0.04 * (7.0 * tau * u).sin();
            let elevation = (25.0 + 15.0 * (2.0 * tau * u).sin()).to_radians();
            let distance = 3.0 + 0.3 * (3.0 * tau * u + 1.0).sin();
            let eye = [
                distance * elevation.cos() * azimuth.cos(),
                distance * elevation.cos() * azimuth.sin(),
                distance * elevation.sin(),
            ];
            let target = [
                0.15 * (5.0 * tau * u).sin(),
                0.15 * (4.0 * tau * u + 2.0).cos(),
                -0.1 + 0.1 * (3.0 * tau * u).cos(),
            ];
            PinholeCamera::look_at(intrinsics, eye, target, [0.0, 0.0, 1.0])
                .and_then(|c| c.with_distortion(s.distortion))
                .map_err(|source| CaptureError::Camera { view: i, source })
        })
        .collect()
}

/// The room's wall colour at the unit direction `u` from the centre, within `[0.1, 0.9]`:
/// broad bands (which an environment of low degree can follow) and finer detail (which it
/// cannot), brighter overhead than underfoot.
pub fn wall_color(u: [f64; 3]) -> [f64; 3] {
    let [x, y, z] = u;
    let light = 0.5 + 0.12 * z;
    let bands = |phase: f64| 0.12 * (3.0 * x + 2.0 * y + phase).sin() * (2.5 * z - phase).cos();
    let stripes = 0.04 * (9.0 * (y - 0.5 * x)).sin();
    let detail = 0.07 * (11.0 * x + 3.0).sin() * (13.0 * y).sin() * (9.0 * z + 1.0).sin();
    [
        light + bands(0.0) + stripes + detail,
        light + bands(1.3) - 0.04 - detail,
        light + bands(2.6) - stripes + 0.03 + detail,
    ]
}

/// Where a ray from inside the room (`|origin| < radius`) meets its wall: the direction from
/// the centre to that point.
fn wall_direction(ray: &Ray, radius: f64) -> [f64; 3] {
    let (o, d) = (ray.origin, ray.direction);
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let (a, b, c) = (dot(d, d), dot(o, d), dot(o, o) - radius * radius);
    // |o + t d| = radius: a t^2 + 2 b t + c = 0, with c < 0 inside the room, so the far root
    // (-b + root) / a is positive. For b >= 0 that difference cancels; the same root is
    // then c / (a t_near) = -c / (b + root), a sum.
    let root = (b * b - a * c).sqrt();
    let t = if b >= 0.0 { -c / (b + root) } else { (root - b) / a };
    let p = [o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]];
    p.map(|v| v / radius)
}

/// The exact picture from `camera` of `scene` standing in the room: the scene composited
/// along each ray, the wall behind it, each pixel the mean over its area
/// ([`picture`](crate::photographs::picture)). `scene`'s own background is not used.
pub fn capture_photograph(scene: &Scene, camera: &PinholeCamera, room_radius: f64) -> Array3<f64> {
    let in_room = Scene {
        background: [0.0; 3],
        primitives: scene.primitives.clone(),
    };
    picture(camera, |ray| {
        let seen = render_ray(&in_room, ray);
        let wall = wall_color(wall_direction(ray, room_radius));
        std::array::from_fn(|c| seen.color[c] + seen.transmittance * wall[c])
    })
}

/// The capture's name for view `i` (its picture's file stem).
pub fn frame_name(i: usize) -> String {
    format!("frame_{i:04}")
}

#[cfg(test)]
mod tests;
