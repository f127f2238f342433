//! The hand-written backward of the projection: from the gradients of the 2-D means, conics
//! and depths to those of the means, log-scales and quaternions, splat by splat, recomputing
//! the forward's intermediate values ([`frame1`]). Culled splats get zeros.
//!
//! With `K = C^-1` and `G_K` the gradient of the conic read as a symmetric matrix (its
//! off-diagonal entry `b` stands for both `K_01` and `K_10`, so each gets half of `dL/db`):
//!
//! ```text
//! G_C = -K G_K K                 (inverse)
//! G_V = J^T G_C J,  G_J = 2 G_C J V      (C = J V J^T + 0.3 I)
//! G_Sigma = W^T G_V W            (V = W Sigma W^T)
//! G_M = 2 G_Sigma M              (Sigma = M M^T, M = R S)
//! G_R = G_M S,  dL/dlog_s_j = s_j sum_i G_M[i][j] R[i][j]
//! ```
//!
//! and the quaternion's through [`rotation_backward`]. The camera-frame mean collects the
//! 2-D mean's, the Jacobian's (`J` depends on `x, y, z`, except along a clamped direction)
//! and the depth's gradients, and `dL/dp = W^T dL/dp_c`.

use rayon::prelude::*;

use super::camera::SplatCamera;
use super::check::SplatParams;
use super::linalg::{mul, t_apply, t_mul, M23, M3};
use super::project::{frame1, Frame1, CHUNK};
use super::quat::rotation_backward;

/// The gradients of one splat's parameters: mean, log-scale, quaternion.
pub(crate) type ParamGrads = ([f64; 3], [f64; 3], [f64; 4]);

/// The upstream gradients of one splat: 2-D mean, conic, depth.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Upstream1 {
    pub(crate) mean2d: [f64; 2],
    pub(crate) conic: [f64; 3],
    pub(crate) depth: f64,
}

/// `G_C = -K G K` for symmetric `K` and `G` (2x2, full).
#[inline]
fn inverse_backward(k: [f64; 3], g: [f64; 3]) -> [[f64; 2]; 2] {
    let kk = [[k[0], k[1]], [k[1], k[2]]];
    let gg = [[g[0], 0.5 * g[1]], [0.5 * g[1], g[2]]];
    let kg: [[f64; 2]; 2] = [0, 1].map(|i| [0, 1].map(|j| kk[i][0] * gg[0][j] + kk[i][1] * gg[1][j]));
    [0, 1].map(|i| [0, 1].map(|j| -(kg[i][0] * kk[0][j] + kg[i][1] * kk[1][j])))
}

/// One visible splat's backward (see the [module docs](self)).
#[inline]
fn backward1(cam: &SplatCamera, f: &Frame1, up: &Upstream1) -> ParamGrads {
    let gc = inverse_backward(f.conic, up.conic);
    let j = &f.jac;
    // G_V = J^T G_C J (3x3), G_J = 2 G_C J V (2x3).
    let gcj: M23 = [0, 1].map(|r| [0, 1, 2].map(|c| gc[r][0] * j[0][c] + gc[r][1] * j[1][c]));
    let gv: M3 = [0, 1, 2].map(|a| [0, 1, 2].map(|b| j[0][a] * gcj[0][b] + j[1][a] * gcj[1][b]));
    let gj: M23 = [0, 1]
        .map(|r| [0, 1, 2].map(|c| 2.0 * (gcj[r][0] * f.v[0][c] + gcj[r][1] * f.v[1][c] + gcj[r][2] * f.v[2][c])));
    // G_Sigma = W^T G_V W, G_M = 2 G_Sigma M.
    let gsigma = t_mul(&cam.w, &mul(&gv, &cam.w));
    let gm = mul(&gsigma, &f.m).map(|r| r.map(|v| 2.0 * v));
    let gr: M3 = [0, 1, 2].map(|i| [0, 1, 2].map(|k| gm[i][k] * f.scale[k]));
    let g_log_scale =
        [0, 1, 2].map(|k| f.scale[k] * (gm[0][k] * f.rot[0][k] + gm[1][k] * f.rot[1][k] + gm[2][k] * f.rot[2][k]));
    let g_quat = rotation_backward(f.unit_q, f.q_norm, &gr);

    // The camera-frame mean: 2-D mean, Jacobian, depth.
    let [x, y, z] = f.pc;
    let rz = 1.0 / z;
    let rz2 = rz * rz;
    let (fx, fy) = (cam.fx, cam.fy);
    let [gu, gvv] = up.mean2d;
    let mut gp = [
        gu * fx * rz,
        gvv * fy * rz,
        -(gu * fx * x + gvv * fy * y) * rz2 + up.depth,
    ];
    // J00 = fx / z, J11 = fy / z.
    gp[2] -= (gj[0][0] * fx + gj[1][1] * fy) * rz2;
    // J02 = -fx u / z with u = x / z inside the limits (a constant outside them).
    let u = -j[0][2] / (fx * rz);
    let v = -j[1][2] / (fy * rz);
    gp[2] += gj[0][2] * fx * u * rz2 + gj[1][2] * fy * v * rz2;
    if f.inside.0 {
        gp[0] -= gj[0][2] * fx * rz2;
        gp[2] += gj[0][2] * fx * x * rz2 * rz;
    }
    if f.inside.1 {
        gp[1] -= gj[1][2] * fy * rz2;
        gp[2] += gj[1][2] * fy * y * rz2 * rz;
    }
    (t_apply(&cam.w, gp), g_log_scale, g_quat)
}

/// The backward of [`project_params`](super::project::project_params) for every splat, in
/// parallel over fixed chunks (each splat on its own: the result does not depend on the
/// thread count). `upstream[i]` is splat `i`'s; culled splats get zeros.
pub(crate) fn project_backward(cam: &SplatCamera, params: &SplatParams, upstream: &[Upstream1]) -> Vec<ParamGrads> {
    let mut out = vec![([0.0; 3], [0.0; 3], [0.0; 4]); params.len()];
    out.par_chunks_mut(CHUNK).enumerate().for_each(|(chunk, out)| {
        for (k, o) in out.iter_mut().enumerate() {
            let i = chunk * CHUNK + k;
            if let (_, Some(f)) = frame1(cam, params.means[i], params.log_scales[i], params.quats[i]) {
                *o = backward1(cam, &f, &upstream[i]);
            }
        }
    });
    out
}

/// The gradients of a loss for the parameters of [`project`](super::project), in f64.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ProjectionGradients {
    /// `dL/dmeans`, `[n][3]`.
    pub means: Vec<[f64; 3]>,
    /// `dL/dlog_scales`, `[n][3]`.
    pub log_scales: Vec<[f64; 3]>,
    /// `dL/dquats`, `[n][4]` (tangent to the sphere through the quaternion).
    pub quats: Vec<[f64; 4]>,
}

/// The gradients of a loss for the parameters of [`project`](super::project), given its
/// gradients for each splat's 2-D mean, conic and depth (one entry per splat each); culled
/// splats get zeros (see the [module docs](self)).
///
/// Errors: those of [`project`](super::project), and upstream gradients whose lengths are not
/// the number of splats ([`OpsError::Shape`](crate::OpsError::Shape)).
pub fn project_vjp<F: fogray_tape::Float>(
    camera: &crate::PinholeCamera,
    means: ndarray::ArrayView2<'_, F>,
    log_scales: ndarray::ArrayView2<'_, F>,
    quats: ndarray::ArrayView2<'_, F>,
    g_mean2d: &[[f64; 2]],
    g_conic: &[[f64; 3]],
    g_depth: &[f64],
) -> Result<ProjectionGradients, crate::OpsError> {
    let cam = SplatCamera::new(camera)?;
    let params = super::check::params(&means, &log_scales, &quats)?;
    let n = params.len();
    for (what, len) in [
        ("2-D mean gradient", g_mean2d.len()),
        ("conic gradient", g_conic.len()),
        ("depth gradient", g_depth.len()),
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
    let upstream: Vec<Upstream1> = (0..n)
        .map(|i| Upstream1 {
            mean2d: g_mean2d[i],
            conic: g_conic[i],
            depth: g_depth[i],
        })
        .collect();
    Ok(split(project_backward(&cam, &params, &upstream)))
}

/// The per-splat triples as three arrays.
pub(crate) fn split(grads: Vec<ParamGrads>) -> ProjectionGradients {
    let mut out = ProjectionGradients::default();
    for (m, s, q) in grads {
        out.means.push(m);
        out.log_scales.push(s);
        out.quats.push(q);
    }
    out
}
