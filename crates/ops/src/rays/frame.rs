//! A camera's placement: the linear part `R` and the centre `c` of its camera-to-world map
//! `x_world = R x_cam + c`, checked on construction.

use super::batch::{norm, normalise};
use crate::error::{Op, OpsError};

/// `x_world = rotation x_cam + centre` (`rotation` row-major, invertible).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Frame {
    pub(crate) rotation: [[f64; 3]; 3],
    pub(crate) centre: [f64; 3],
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn transform(problem: String) -> OpsError {
    OpsError::Frame {
        op: Op::Rays,
        what: "camera-to-world transform",
        problem,
    }
}

fn degenerate(problem: String) -> OpsError {
    OpsError::Frame {
        op: Op::Rays,
        what: "look_at",
        problem,
    }
}

/// Checks a 4x4 camera-to-world matrix: finite, affine (last row `0 0 0 1` within 1e-9) and
/// with an invertible linear part. Invertibility is judged scale-free: `|det R|` against the
/// product of the column lengths (1 for a rotation, 0 for a singular matrix).
pub(crate) fn checked_transform(m: [[f64; 4]; 4]) -> Result<Frame, OpsError> {
    if let Some((i, j)) = (0..16).map(|k| (k / 4, k % 4)).find(|&(i, j)| !m[i][j].is_finite()) {
        return Err(transform(format!("entry [{i}][{j}] is {} (must be finite)", m[i][j])));
    }
    if (0..4).any(|j| (m[3][j] - if j == 3 { 1.0 } else { 0.0 }).abs() > 1e-9) {
        return Err(transform(format!("last row is {:?} (must be [0, 0, 0, 1])", m[3])));
    }
    let rotation = [
        [m[0][0], m[0][1], m[0][2]],
        [m[1][0], m[1][1], m[1][2]],
        [m[2][0], m[2][1], m[2][2]],
    ];
    let col = |j: usize| [rotation[0][j], rotation[1][j], rotation[2][j]];
    let det = dot(col(0), cross(col(1), col(2)));
    let scale = norm(col(0)) * norm(col(1)) * norm(col(2));
    let invertible = det.abs() > 1e-9 * scale && scale > 0.0;
    if !invertible {
        return Err(transform(format!(
            "the 3x3 part is singular (determinant {det:e}, column lengths' product {scale:e})"
        )));
    }
    Ok(Frame {
        rotation,
        centre: [m[0][3], m[1][3], m[2][3]],
    })
}

impl Frame {
    /// OpenCV axes looking from `eye` at `target` with `up` up (see `PinholeCamera::look_at`).
    pub(crate) fn look_at(eye: [f64; 3], target: [f64; 3], up: [f64; 3]) -> Result<Frame, OpsError> {
        if let Some(v) = eye.iter().chain(&target).chain(&up).find(|v| !v.is_finite()) {
            return Err(degenerate(format!("{v} in eye, target or up (must be finite)")));
        }
        let forward = normalise([target[0] - eye[0], target[1] - eye[1], target[2] - eye[2]])
            .ok_or_else(|| degenerate("eye and target coincide".into()))?;
        let up_unit = normalise(up).ok_or_else(|| degenerate("up is zero".into()))?;
        let side = cross(forward, up_unit);
        if norm(side) < 1e-9 {
            return Err(degenerate(format!(
                "up {up:?} is parallel to the viewing direction {forward:?}"
            )));
        }
        let right = normalise(side).expect("non-zero by the check above");
        let down = cross(forward, right);
        Ok(Frame {
            rotation: [
                [right[0], down[0], forward[0]],
                [right[1], down[1], forward[1]],
                [right[2], down[2], forward[2]],
            ],
            centre: eye,
        })
    }

    /// `R v`.
    pub(crate) fn rotate(&self, v: [f64; 3]) -> [f64; 3] {
        self.rotation.map(|row| dot(row, v))
    }

    /// `R⁻¹ (p - c)`: the world point `p` in camera coordinates, by Cramer's rule (`R` may
    /// scale or shear); `None` if `R` has no usable inverse (not after `checked_transform`).
    pub(crate) fn to_camera(&self, p: [f64; 3]) -> Option<[f64; 3]> {
        let r = &self.rotation;
        let v = [p[0] - self.centre[0], p[1] - self.centre[1], p[2] - self.centre[2]];
        let col = |j: usize| [r[0][j], r[1][j], r[2][j]];
        let det = dot(col(0), cross(col(1), col(2)));
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        // x_j = det(R with column j replaced by v) / det(R).
        Some([
            dot(v, cross(col(1), col(2))) / det,
            dot(col(0), cross(v, col(2))) / det,
            dot(col(0), cross(col(1), v)) / det,
        ])
    }

    /// The 4x4 camera-to-world matrix.
    pub(crate) fn matrix(&self) -> [[f64; 4]; 4] {
        let r = &self.rotation;
        let c = self.centre;
        [
            [r[0][0], r[0][1], r[0][2], c[0]],
            [r[1][0], r[1][1], r[1][2], c[1]],
            [r[2][0], r[2][1], r[2][2], c[2]],
            [0.0, 0.0, 0.0, 1.0],
        ]
    }
}
