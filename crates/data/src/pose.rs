//! Camera poses: a frame's `transform_matrix` (OpenGL camera-to-world) checked to be a rigid
//! transform, and its way back out.
//!
//! fogray-ops accepts any invertible 3x3 part (rays are normalised after it), but the formats
//! store rigid poses: a scaled or mirrored matrix in a transforms file is a bug upstream (a
//! wrong export, a transposed matrix), better reported than rendered.

use serde_json::Value;

use crate::error::{DataError, MatrixProblem};
use crate::json::Obj;
use crate::ranges::MAX_COORDINATE;

/// Largest `|RᵀR - I|` entry accepted: poses stored as f32 (as Blender exports them) are
/// orthonormal to about 1e-7, so 1e-3 only refuses matrices that are really not rotations.
const ORTHONORMAL_TOLERANCE: f64 = 1e-3;

/// The `key` of `obj` as a checked 4x4 pose. Errors: absent ([`DataError::MissingKey`]), or
/// [`DataError::BadMatrix`] saying what is wrong.
pub(crate) fn read_pose(obj: Obj<'_>, key: &str) -> Result<[[f64; 4]; 4], DataError> {
    let value = obj.get(key).ok_or_else(|| obj.missing(key))?;
    let bad = |problem| DataError::BadMatrix {
        path: obj.path.to_path_buf(),
        key: obj.name(key),
        problem,
    };
    let m = parse(value).ok_or_else(|| bad(MatrixProblem::NotFourByFour))?;
    check(&m).map_err(bad)?;
    Ok(m)
}

fn parse(value: &Value) -> Option<[[f64; 4]; 4]> {
    let rows = value.as_array().filter(|r| r.len() == 4)?;
    let mut m = [[0.0; 4]; 4];
    for (row, r) in m.iter_mut().zip(rows) {
        let cols = r.as_array().filter(|c| c.len() == 4)?;
        for (x, c) in row.iter_mut().zip(cols) {
            *x = c.as_f64()?;
        }
    }
    Some(m)
}

/// Checks that `m` is `[[R, t], [0 0 0 1]]` with finite entries and `R` a rotation.
pub(crate) fn check(m: &[[f64; 4]; 4]) -> Result<(), MatrixProblem> {
    if m.iter().flatten().any(|v| !v.is_finite()) {
        return Err(MatrixProblem::NotFinite);
    }
    if m[3] != [0.0, 0.0, 0.0, 1.0] {
        return Err(MatrixProblem::LastRow);
    }
    if let Some(t) = (0..3).map(|i| m[i][3]).find(|t| t.abs() > MAX_COORDINATE) {
        return Err(MatrixProblem::FarTranslation { value: t });
    }
    let mut deviation = 0.0f64;
    for i in 0..3 {
        for j in 0..3 {
            let dot: f64 = (0..3).map(|k| m[k][i] * m[k][j]).sum();
            let target = if i == j { 1.0 } else { 0.0 };
            deviation = deviation.max((dot - target).abs());
        }
    }
    if deviation > ORTHONORMAL_TOLERANCE {
        return Err(MatrixProblem::NotOrthonormal { deviation });
    }
    let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    if det <= 0.0 {
        return Err(MatrixProblem::Reflection { det });
    }
    Ok(())
}

/// The OpenGL camera-to-world matrix of an OpenCV one (and back: the map is its own inverse):
/// the camera's y and z axes negated.
pub(crate) fn flip_yz(m: [[f64; 4]; 4]) -> [[f64; 4]; 4] {
    let mut m = m;
    for row in m.iter_mut().take(3) {
        row[1] = -row[1];
        row[2] = -row[2];
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rot_z(a: f64) -> [[f64; 4]; 4] {
        let (s, c) = a.sin_cos();
        [
            [c, -s, 0.0, 1.0],
            [s, c, 0.0, 2.0],
            [0.0, 0.0, 1.0, 3.0],
            [0.0, 0.0, 0.0, 1.0],
        ]
    }

    #[test]
    fn a_rotation_passes_and_each_fault_is_named() {
        assert_eq!(check(&rot_z(0.3)), Ok(()));
        let mut scaled = rot_z(0.3);
        scaled[0][0] *= 1.01;
        assert!(matches!(check(&scaled), Err(MatrixProblem::NotOrthonormal { deviation }) if deviation > 0.01));
        let mut mirror = rot_z(0.3);
        mirror[2][2] = -1.0;
        assert!(matches!(check(&mirror), Err(MatrixProblem::Reflection { det }) if (det + 1.0).abs() < 1e-12));
        let mut last = rot_z(0.3);
        last[3][0] = 0.5;
        assert_eq!(check(&last), Err(MatrixProblem::LastRow));
        let mut far = rot_z(0.3);
        far[0][3] = -1e308;
        assert_eq!(check(&far), Err(MatrixProblem::FarTranslation { value: -1e308 }));
        far[0][3] = -1e6;
        assert_eq!(check(&far), Ok(()));
        let mut nan = rot_z(0.3);
        nan[1][3] = f64::NAN;
        assert_eq!(check(&nan), Err(MatrixProblem::NotFinite));
    }

    #[test]
    fn flip_yz_negates_the_second_and_third_columns_only() {
        let m = flip_yz(rot_z(0.3));
        let r = rot_z(0.3);
        for i in 0..3 {
            assert_eq!(m[i], [r[i][0], -r[i][1], -r[i][2], r[i][3]]);
        }
        assert_eq!(m[3], r[3]);
    }
}
