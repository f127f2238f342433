//! The camera as the projection reads it: the world-to-camera map `p_c = W p + t` (the inverse
//! of the camera's camera-to-world transform, which may scale or shear), the focal lengths and
//! principal point, the image size, and the limits of the view frustum that the covariance's
//! Jacobian is evaluated inside.

use crate::error::{Op, OpsError};
use crate::rays::PinholeCamera;

/// How far past the image's edge, as a fraction of the half field of view, the Jacobian of
/// the perspective map is still evaluated at the splat's own direction. Beyond it the
/// direction is clamped (as 3D Gaussian splatting and gsplat do): the first-order (EWA)
/// approximation of a splat far outside the view stretches without bound, and such a splat
/// can only touch the image with its tail.
pub(crate) const FRUSTUM_MARGIN: f64 = 0.3;

/// A pinhole camera, ready for projecting splats.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SplatCamera {
    /// World-to-camera linear part `W` (row-major), the inverse of the camera-to-world `R`.
    pub(crate) w: [[f64; 3]; 3],
    /// World-to-camera translation `t = -W c`.
    pub(crate) t: [f64; 3],
    pub(crate) fx: f64,
    pub(crate) fy: f64,
    pub(crate) cx: f64,
    pub(crate) cy: f64,
    pub(crate) width: usize,
    pub(crate) height: usize,
    /// `x / z` is clamped to `[-lim_x_neg, lim_x_pos]` inside the Jacobian.
    pub(crate) lim_x: (f64, f64),
    /// `y / z` is clamped to `[-lim_y_neg, lim_y_pos]` inside the Jacobian.
    pub(crate) lim_y: (f64, f64),
}

fn det3(m: &[[f64; 3]; 3]) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}

/// The inverse of `m` by its adjugate; `None` if singular.
fn inverse3(m: &[[f64; 3]; 3]) -> Option<[[f64; 3]; 3]> {
    let det = det3(m);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let c = |r0: usize, c0: usize, r1: usize, c1: usize| m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0];
    let adj = [
        [c(1, 1, 2, 2), -c(0, 1, 2, 2), c(0, 1, 1, 2)],
        [-c(1, 0, 2, 2), c(0, 0, 2, 2), -c(0, 0, 1, 2)],
        [c(1, 0, 2, 1), -c(0, 0, 2, 1), c(0, 0, 1, 1)],
    ];
    Some(adj.map(|row| row.map(|v| v / det)))
}

impl SplatCamera {
    /// The projection's view of `camera`. Splatting projects with the pinhole alone, so a
    /// camera with a lens distortion is refused rather than rendered as if it had none.
    pub(crate) fn new(camera: &PinholeCamera) -> Result<Self, OpsError> {
        if !camera.distortion().is_none() {
            return Err(OpsError::Mismatch {
                op: Op::Splat,
                what: "camera",
                problem: "has a lens distortion; splats are projected through a pinhole only",
            });
        }
        let k = camera.intrinsics();
        for (what, v) in [("fx", k.fx), ("fy", k.fy)] {
            if v <= 0.0 {
                // The frustum limits and the image's orientation assume positive focal lengths.
                return Err(OpsError::config(Op::Splat, what, v, "must be positive for splatting"));
            }
        }
        let m = camera.camera_to_world();
        let r = [
            [m[0][0], m[0][1], m[0][2]],
            [m[1][0], m[1][1], m[1][2]],
            [m[2][0], m[2][1], m[2][2]],
        ];
        let w = inverse3(&r).ok_or(OpsError::Frame {
            op: Op::Splat,
            what: "camera-to-world transform",
            problem: "its 3x3 part is singular".into(),
        })?;
        let c = [m[0][3], m[1][3], m[2][3]];
        let t = [0, 1, 2].map(|i| -(w[i][0] * c[0] + w[i][1] * c[1] + w[i][2] * c[2]));
        let (width, height) = (k.width as f64, k.height as f64);
        // gsplat's limits: the image's extent on each side of the principal point plus the
        // margin of the half field of view (1.3 tan(fov / 2) each way for a centred camera).
        let (tan_x, tan_y) = (0.5 * width / k.fx, 0.5 * height / k.fy);
        let lim_x = (
            (width - k.cx) / k.fx + FRUSTUM_MARGIN * tan_x,
            k.cx / k.fx + FRUSTUM_MARGIN * tan_x,
        );
        let lim_y = (
            (height - k.cy) / k.fy + FRUSTUM_MARGIN * tan_y,
            k.cy / k.fy + FRUSTUM_MARGIN * tan_y,
        );
        Ok(SplatCamera {
            w,
            t,
            fx: k.fx,
            fy: k.fy,
            cx: k.cx,
            cy: k.cy,
            width: k.width,
            height: k.height,
            lim_x,
            lim_y,
        })
    }

    /// `W p + t`.
    #[inline]
    pub(crate) fn camera_point(&self, p: [f64; 3]) -> [f64; 3] {
        let w = &self.w;
        [0, 1, 2].map(|i| w[i][0] * p[0] + w[i][1] * p[1] + w[i][2] * p[2] + self.t[i])
    }
}
