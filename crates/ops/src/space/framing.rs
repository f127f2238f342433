//! Framing a capture: the [`InnerRegion`] of a contraction from its cameras alone, before any
//! fit (a phone or drone capture has no scene box).
//!
//! The centre is the point nearest, in least squares, to every camera's optical axis: the
//! `p` minimising `sum_k |(I - d_k d_k^T)(p - c_k)|^2`, from the 3x3 normal equations
//! `(sum_k P_k) p = sum_k P_k c_k` with `P_k = I - d_k d_k^T`. Where the axes are close to
//! parallel (a forward-facing capture, a drone flying a line) that point is undetermined
//! along them, and where they diverge it lies behind the cameras: then the centre is the
//! mean of the cameras' centres.

use super::contraction::InnerRegion;
use crate::error::{At, Op, OpsError};

/// The inner region's radius per median distance from the cameras to the centre.
///
/// One: at least half the cameras (all of them, on a ring or a sphere around the subject)
/// lie inside the inner box, as nerfstudio frames a capture (poses scaled into the unit box that its
/// contraction leaves alone). What the cameras look at, nearer than they are, gets the
/// inner region's fine, undistorted cells; the surroundings seen past it are contracted. The
/// median, not the largest distance, so that a few cameras that wandered off do not stretch
/// the inner region over the whole scene.
pub const RADIUS_PER_MEDIAN_CAMERA_DISTANCE: f64 = 1.0;

/// The least reciprocal condition number (smallest over largest eigenvalue) of the normal
/// matrix `sum_k (I - d_k d_k^T)` for which the axes' meeting point is used.
///
/// For axes spread over an angle `a` (radians) the ratio is about `a^2 / 2`: this value
/// falls back to the mean of the centres when every axis lies within about 2.6 degrees of
/// the others, where the meeting point moves along the axes by more than the cameras' own
/// spread for an error of a degree in the poses.
pub const MIN_AXES_RECIPROCAL_CONDITION: f64 = 1e-3;

fn frame_error(problem: impl Into<String>) -> OpsError {
    OpsError::Frame {
        op: Op::Contraction,
        what: "camera framing",
        problem: problem.into(),
    }
}

/// The cameras checked: as many centres as axes, at least two, every value finite, every
/// axis non-zero; the axes returned unit.
fn checked(centres: &[[f64; 3]], forward_axes: &[[f64; 3]]) -> Result<Vec<[f64; 3]>, OpsError> {
    if centres.len() != forward_axes.len() {
        return Err(OpsError::shape(
            Op::Contraction,
            "forward axes",
            format!("one per camera centre ({})", centres.len()),
            format!("{}", forward_axes.len()),
        ));
    }
    if centres.len() < 2 {
        return Err(frame_error(format!(
            "{} camera(s): at least 2 are needed to place the inner region",
            centres.len()
        )));
    }
    for (what, rows) in [("camera centre", centres), ("forward axis", forward_axes)] {
        for (row, v) in rows.iter().enumerate() {
            if let Some(column) = (0..3).find(|&a| !v[a].is_finite()) {
                return Err(OpsError::domain(
                    Op::Contraction,
                    At::Entry { row, column },
                    what,
                    v[column],
                    "must be finite",
                ));
            }
        }
    }
    forward_axes
        .iter()
        .enumerate()
        .map(|(k, d)| {
            let n = d.iter().map(|v| v * v).sum::<f64>().sqrt();
            if n > 0.0 && n.is_finite() {
                Ok(d.map(|v| v / n))
            } else {
                Err(frame_error(format!("camera {k}'s forward axis has length {n}")))
            }
        })
        .collect()
}

/// The eigenvalues of the symmetric 3x3 `a`, smallest first (the trigonometric closed form;
/// absolute error about `1e-16` times the largest).
fn symmetric_eigenvalues(a: [[f64; 3]; 3]) -> [f64; 3] {
    let off = a[0][1].powi(2) + a[0][2].powi(2) + a[1][2].powi(2);
    let q = (a[0][0] + a[1][1] + a[2][2]) / 3.0;
    let p2 = (a[0][0] - q).powi(2) + (a[1][1] - q).powi(2) + (a[2][2] - q).powi(2) + 2.0 * off;
    let p = (p2 / 6.0).sqrt();
    if p == 0.0 {
        return [q; 3];
    }
    let b: [[f64; 3]; 3] =
        std::array::from_fn(|i| std::array::from_fn(|j| (a[i][j] - if i == j { q } else { 0.0 }) / p));
    let half_det = 0.5 * determinant(b);
    let phi = half_det.clamp(-1.0, 1.0).acos() / 3.0;
    let largest = q + 2.0 * p * phi.cos();
    let smallest = q + 2.0 * p * (phi + 2.0 * std::f64::consts::FRAC_PI_3).cos();
    [smallest, 3.0 * q - largest - smallest, largest]
}

fn determinant(a: [[f64; 3]; 3]) -> f64 {
    a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
}

/// `a^-1 b` by the adjugate (the caller has checked that `a` is well conditioned).
fn solve(a: [[f64; 3]; 3], b: [f64; 3]) -> [f64; 3] {
    let det = determinant(a);
    std::array::from_fn(|col| {
        let mut m = a;
        for row in 0..3 {
            m[row][col] = b[row];
        }
        determinant(m) / det
    })
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The median of `values` (the mean of the middle two for an even count); `values` is
/// not empty.
fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n % 2 == 1 {
        values[n / 2]
    } else {
        0.5 * (values[n / 2 - 1] + values[n / 2])
    }
}

/// The point nearest, in least squares, to the cameras' optical axes (camera `k` at
/// `centres[k]` looking along `forward_axes[k]`, any non-zero length), or `None` where it
/// is not to be trusted: the normal matrix's reciprocal condition number below
/// [`MIN_AXES_RECIPROCAL_CONDITION`] (near-parallel axes), or the point behind the median
/// camera (diverging axes: a capture looking outward).
///
/// Errors: different counts, fewer than 2 cameras, a value not finite (named by camera and
/// coordinate), a zero forward axis.
pub fn axes_meeting_point(centres: &[[f64; 3]], forward_axes: &[[f64; 3]]) -> Result<Option<[f64; 3]>, OpsError> {
    let axes = checked(centres, forward_axes)?;
    let mut normal = [[0.0; 3]; 3];
    let mut rhs = [0.0; 3];
    for (c, d) in centres.iter().zip(&axes) {
        for i in 0..3 {
            for j in 0..3 {
                let projector = f64::from(u8::from(i == j)) - d[i] * d[j];
                normal[i][j] += projector;
                rhs[i] += projector * c[j];
            }
        }
    }
    let [smallest, _, largest] = symmetric_eigenvalues(normal);
    if smallest.is_nan() || smallest < MIN_AXES_RECIPROCAL_CONDITION * largest {
        return Ok(None);
    }
    let p = solve(normal, rhs);
    let depth = median(
        centres
            .iter()
            .zip(&axes)
            .map(|(c, d)| dot(std::array::from_fn(|a| p[a] - c[a]), *d))
            .collect(),
    );
    Ok((depth > 0.0 && p.iter().all(|v| v.is_finite())).then_some(p))
}

/// The inner region of a capture from its cameras: centred on [`axes_meeting_point`], or on
/// the mean of the cameras' centres where that gives `None`; its radius
/// [`RADIUS_PER_MEDIAN_CAMERA_DISTANCE`] times the median distance from the cameras to the
/// centre. A camera's forward axis is the third column of its camera-to-world rotation
/// (OpenCV axes, as [`PinholeCamera`](crate::rays::PinholeCamera) keeps them).
///
/// Errors: as [`axes_meeting_point`], and cameras all at the centre (no spread to size the
/// region by: a panorama turning on one spot).
pub fn framing_from_cameras(centres: &[[f64; 3]], forward_axes: &[[f64; 3]]) -> Result<InnerRegion, OpsError> {
    let centre = match axes_meeting_point(centres, forward_axes)? {
        Some(p) => p,
        None => {
            let n = centres.len() as f64;
            std::array::from_fn(|a| centres.iter().map(|c| c[a]).sum::<f64>() / n)
        }
    };
    let spread = median(
        centres
            .iter()
            .map(|c| (0..3).map(|a| (c[a] - centre[a]).powi(2)).sum::<f64>().sqrt())
            .collect(),
    );
    let radius = RADIUS_PER_MEDIAN_CAMERA_DISTANCE * spread;
    if !(radius > 0.0 && radius.is_finite()) {
        return Err(frame_error(format!(
            "the cameras' median distance to the centre is {spread}: no spread to size the inner region by"
        )));
    }
    InnerRegion::new(centre, radius)
}
