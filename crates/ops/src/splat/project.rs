//! Projection of 3-D Gaussians into a pinhole camera: the 2-D mean, the depth, the conic (the
//! inverse of the 2-D covariance) and the screen radius of each splat, by the EWA
//! approximation of 3D Gaussian splatting.
//!
//! For a splat with mean `p`, scales `s = exp(log_scale)` and rotation `R(q / |q|)`:
//!
//! ```text
//! p_c = W p + t = (x, y, z)                       camera frame
//! mean2d = (fx x / z + cx, fy y / z + cy)
//! Sigma = R S S R^T,  S = diag(s)                 world covariance
//! J = [[fx / z, 0, -fx u / z], [0, fy / z, -fy v / z]],  (u, v) = (x / z, y / z) clamped
//! C = J W Sigma W^T J^T + 0.3 I                   screen covariance, low-pass dilated
//! conic = C^-1,  radius = ceil(3 sqrt(lambda_max(C)))
//! ```
//!
//! The dilation keeps a splat at least about a pixel wide, so that a splat smaller than a
//! pixel is not sampled between pixel centres and lost (it also makes `C` invertible for any
//! scale). Splats with `z` below [`NEAR`] or a non-positive (or non-finite) determinant are
//! culled: radius 0, nothing drawn, no gradient.

use fogray_tape::Float;
use rayon::prelude::*;

use super::camera::SplatCamera;
use super::check::SplatParams;
use super::linalg::{mul_t, sandwich_23, Sym2, M23, M3};
use super::quat::{normalise, rotation};

/// Splats nearer the camera plane than this (in the camera frame's units) are culled.
pub const NEAR: f64 = 0.01;

/// What is added to the diagonal of every screen covariance, in pixels squared.
pub const DILATION: f64 = 0.3;

/// Splats per parallel task.
pub(crate) const CHUNK: usize = 1024;

/// The splats of one camera after projection, in f64, one entry per splat (culled ones
/// included, with radius 0, so that indices are the splats' own).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Projection {
    /// The 2-D mean in image coordinates (column, row; pixel centres at `+0.5`).
    pub mean2d: Vec<[f64; 2]>,
    /// The camera-frame `z` (depth along the optical axis); set for culled splats too.
    pub depth: Vec<f64>,
    /// The inverse screen covariance `[a, b, c]` of `[[a, b], [b, c]]`; zeros when culled.
    pub conic: Vec<[f64; 3]>,
    /// Three standard deviations of the screen covariance's major axis, in whole pixels; 0
    /// for a culled splat.
    pub radius: Vec<u32>,
}

impl Projection {
    /// The number of splats (culled ones included).
    pub fn len(&self) -> usize {
        self.depth.len()
    }

    /// The common length of the four arrays, or the error naming the first that differs.
    pub fn check_lengths(&self) -> Result<usize, crate::OpsError> {
        let n = self.depth.len();
        for (what, len) in [
            ("projection 2-D means", self.mean2d.len()),
            ("projection conics", self.conic.len()),
            ("projection radii", self.radius.len()),
        ] {
            if len != n {
                return Err(crate::OpsError::shape(
                    crate::Op::Splat,
                    what,
                    n.to_string(),
                    len.to_string(),
                ));
            }
        }
        Ok(n)
    }

    /// Whether there are no splats.
    pub fn is_empty(&self) -> bool {
        self.depth.is_empty()
    }
}

/// The intermediate values of one splat's projection, which the backward recomputes rather
/// than keeps (they cost more memory than time).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Frame1 {
    pub(crate) pc: [f64; 3],
    pub(crate) unit_q: [f64; 4],
    pub(crate) q_norm: f64,
    pub(crate) rot: M3,
    pub(crate) scale: [f64; 3],
    /// `M = R S`.
    pub(crate) m: M3,
    /// `V = W Sigma W^T`.
    pub(crate) v: M3,
    pub(crate) jac: M23,
    /// Whether `x / z` and `y / z` lie inside the frustum limits (else the Jacobian's
    /// direction is clamped and has no derivative in that coordinate).
    pub(crate) inside: (bool, bool),
    /// The dilated screen covariance.
    pub(crate) cov2d: Sym2,
    pub(crate) conic: Sym2,
}

/// One splat's projection: `None` when it is culled, with its depth either way.
#[inline]
pub(crate) fn frame1(cam: &SplatCamera, mean: [f64; 3], log_scale: [f64; 3], quat: [f64; 4]) -> (f64, Option<Frame1>) {
    let pc = cam.camera_point(mean);
    let [x, y, z] = pc;
    // NaN never passes (the inputs are checked finite, but the camera may map far away).
    if z.is_nan() || z < NEAR {
        return (z, None);
    }
    let (unit_q, q_norm) = normalise(quat);
    let rot = rotation(unit_q);
    let scale = log_scale.map(f64::exp);
    let m: M3 = [0, 1, 2].map(|i| [0, 1, 2].map(|j| rot[i][j] * scale[j]));
    let sigma = mul_t(&m, &m);
    let v = mul_t(&super::linalg::mul(&cam.w, &sigma), &cam.w);
    let rz = 1.0 / z;
    let (ux, uy) = (x * rz, y * rz);
    let cu = ux.clamp(-cam.lim_x.1, cam.lim_x.0);
    let cv = uy.clamp(-cam.lim_y.1, cam.lim_y.0);
    let jac = [
        [cam.fx * rz, 0.0, -cam.fx * cu * rz],
        [0.0, cam.fy * rz, -cam.fy * cv * rz],
    ];
    let c = sandwich_23(&jac, &v);
    let cov2d = [c[0] + DILATION, c[1], c[2] + DILATION];
    let det = cov2d[0] * cov2d[2] - cov2d[1] * cov2d[1];
    if !(det > 0.0 && det.is_finite()) {
        return (z, None);
    }
    let conic = [cov2d[2] / det, -cov2d[1] / det, cov2d[0] / det];
    let f = Frame1 {
        pc,
        unit_q,
        q_norm,
        rot,
        scale,
        m,
        v,
        jac,
        inside: (cu == ux, cv == uy),
        cov2d,
        conic,
    };
    (z, Some(f))
}

/// Three standard deviations of the major axis of `cov2d`, rounded up. The eigenvalue is
/// floored as gsplat floors it (`sqrt(max(0.1, b^2 - det))`), which keeps a round splat's
/// radius from resting on a square root of rounding noise.
#[inline]
pub(crate) fn radius(cov2d: Sym2) -> u32 {
    let det = cov2d[0] * cov2d[2] - cov2d[1] * cov2d[1];
    let b = 0.5 * (cov2d[0] + cov2d[2]);
    let major = b + (b * b - det).max(0.1).sqrt();
    // `as` saturates: an enormous splat covers the whole image, which the binning clips.
    (3.0 * major.sqrt()).ceil() as u32
}

/// The projection of every splat of `params` into `cam`, in parallel over fixed chunks
/// (each splat on its own, so the result does not depend on the thread count).
pub(crate) fn project_params(cam: &SplatCamera, params: &SplatParams) -> Projection {
    let n = params.len();
    let mut out = Projection {
        mean2d: vec![[0.0; 2]; n],
        depth: vec![0.0; n],
        conic: vec![[0.0; 3]; n],
        radius: vec![0; n],
    };
    out.mean2d
        .par_chunks_mut(CHUNK)
        .zip(out.depth.par_chunks_mut(CHUNK))
        .zip(out.conic.par_chunks_mut(CHUNK))
        .zip(out.radius.par_chunks_mut(CHUNK))
        .enumerate()
        .for_each(|(chunk, (((mean2d, depth), conic), rad))| {
            for k in 0..depth.len() {
                let i = chunk * CHUNK + k;
                let (z, f) = frame1(cam, params.means[i], params.log_scales[i], params.quats[i]);
                depth[k] = z;
                if let Some(f) = f {
                    let [x, y, _] = f.pc;
                    mean2d[k] = [cam.fx * x / z + cam.cx, cam.fy * y / z + cam.cy];
                    conic[k] = f.conic;
                    rad[k] = radius(f.cov2d);
                }
            }
        });
    out
}

/// The inputs of [`project`](super::project) gathered into f64, for callers with `F` arrays.
pub(crate) fn widen<F: Float, const K: usize>(rows: &[F]) -> Vec<[f64; K]> {
    rows.chunks_exact(K)
        .map(|r| std::array::from_fn(|j| r[j].as_f64()))
        .collect()
}

/// Projects `n` splats, means `[n, 3]`, log-scales `[n, 3]` (natural log of the standard
/// deviations along the splat's axes) and quaternions `[n, 4]` (`w, x, y, z`, any non-zero
/// length: normalised here), into `camera` (see the [module docs](self)). Computed in f64
/// whatever `F` is.
///
/// Errors: a camera with a lens distortion or a non-positive focal length
/// ([`OpsError::Mismatch`](crate::OpsError::Mismatch), [`OpsError::Config`](crate::OpsError::Config)),
/// shapes that do not fit ([`OpsError::Shape`](crate::OpsError::Shape)), a NaN or infinite
/// value or a zero quaternion ([`OpsError::Domain`](crate::OpsError::Domain)).
pub fn project<F: Float>(
    camera: &crate::PinholeCamera,
    means: ndarray::ArrayView2<'_, F>,
    log_scales: ndarray::ArrayView2<'_, F>,
    quats: ndarray::ArrayView2<'_, F>,
) -> Result<Projection, crate::OpsError> {
    let cam = SplatCamera::new(camera)?;
    let params = super::check::params(&means, &log_scales, &quats)?;
    Ok(project_params(&cam, &params))
}
