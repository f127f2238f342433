//! The world a capture's cameras are moved into: COLMAP's (and so LLFF's) world is whatever the
//! reconstruction happened to fix (often the first camera's frame, at the scale of its first
//! baseline), so its cameras are oriented, centred and scaled as nerfstudio's COLMAP reader
//! does by default (`orientation_method="up"`, `center_method="poses"`,
//! `auto_scale_poses=True`), and the transform applied is kept, so that a point of the file's
//! world can be mapped to the cameras' world and back.
//!
//! The transform, in order:
//! 1. the axes turned by `(x, y, z) -> (y, x, -z)` ([`COLMAP_TURN`], nerfstudio's "applied
//!    transform" for COLMAP worlds; a half turn, so a proper rotation);
//! 2. the minimal rotation taking the mean of the cameras' up vectors (each camera's image up,
//!    `-y` in OpenCV axes) to `+Z` (a half turn about an axis perpendicular to it when that
//!    mean points down `-Z`; no rotation when the ups cancel out);
//! 3. the mean camera centre moved to the origin;
//! 4. a uniform scale making the largest `|coordinate|` of a camera centre 1 (no scaling when
//!    every camera sits at the same point).
//!
//! ```
//! use fogray_data::WorldTransform;
//!
//! // A half turn about z, a shift along x, lengths doubled.
//! let world = WorldTransform {
//!     rotation: [[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]],
//!     translation: [1.0, 0.0, 0.0],
//!     scale: 2.0,
//! };
//! // 2 ((-1, -2, 3) + (1, 0, 0)) = (0, -4, 6).
//! assert_eq!(world.apply_point([1.0, 2.0, 3.0]), [0.0, -4.0, 6.0]);
//! assert_eq!(world.invert_point([0.0, -4.0, 6.0]), [1.0, 2.0, 3.0]);
//! assert_eq!(world.apply_direction([1.0, 0.0, 0.0]), [-1.0, 0.0, 0.0]);
//! ```

/// `(x, y, z) -> (y, x, -z)`: the turn nerfstudio applies to a COLMAP world before orienting
/// it (its determinant is +1).
pub const COLMAP_TURN: [[f64; 3]; 3] = [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]];

/// Below this length the mean up vector has no direction (the cameras' ups cancel out).
const NO_DIRECTION: f64 = 1e-9;

/// A similarity `p -> scale (rotation p + translation)` from the world of a dataset's file to
/// the world of its cameras (and of [`SceneData`](crate::SceneData)'s box and points).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorldTransform {
    /// A rotation matrix (row-major; orthonormal, determinant +1).
    pub rotation: [[f64; 3]; 3],
    /// Added after the rotation, before the scale.
    pub translation: [f64; 3],
    /// Positive; multiplies lengths.
    pub scale: f64,
}

impl WorldTransform {
    /// The identity: the world of Blender and instant-ngp files is used as it is.
    pub const IDENTITY: WorldTransform = WorldTransform {
        rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        translation: [0.0; 3],
        scale: 1.0,
    };

    /// The point `p` of the file's world in the cameras' world: `scale (rotation p + translation)`.
    pub fn apply_point(&self, p: [f64; 3]) -> [f64; 3] {
        let r = mul(&self.rotation, p);
        std::array::from_fn(|i| self.scale * (r[i] + self.translation[i]))
    }

    /// The direction `d` of the file's world in the cameras' world (`rotation d`; lengths are
    /// kept, so a unit direction stays one).
    pub fn apply_direction(&self, d: [f64; 3]) -> [f64; 3] {
        mul(&self.rotation, d)
    }

    /// The point `q` of the cameras' world back in the file's: `rotationᵀ (q / scale - translation)`.
    pub fn invert_point(&self, q: [f64; 3]) -> [f64; 3] {
        let shifted: [f64; 3] = std::array::from_fn(|i| q[i] / self.scale - self.translation[i]);
        mul(&transpose(&self.rotation), shifted)
    }

    /// The direction `d` of the cameras' world back in the file's (`rotationᵀ d`).
    pub fn invert_direction(&self, d: [f64; 3]) -> [f64; 3] {
        mul(&transpose(&self.rotation), d)
    }

    /// A camera-to-world matrix `[[R, c], [0 0 0 1]]` (either axis convention) of the file's
    /// world as one of the cameras' world: `[[rotation R, apply_point(c)], [0 0 0 1]]`.
    pub fn apply_pose(&self, camera_to_world: [[f64; 4]; 4]) -> [[f64; 4]; 4] {
        let m = camera_to_world;
        let centre = self.apply_point([m[0][3], m[1][3], m[2][3]]);
        let mut out = [[0.0, 0.0, 0.0, 0.0], [0.0; 4], [0.0; 4], [0.0, 0.0, 0.0, 1.0]];
        for (i, row) in out.iter_mut().take(3).enumerate() {
            for (j, v) in row.iter_mut().take(3).enumerate() {
                *v = (0..3).map(|k| self.rotation[i][k] * m[k][j]).sum();
            }
            row[3] = centre[i];
        }
        out
    }
}

/// The transform of the [module docs](self) for cameras whose OpenCV camera-to-world matrices
/// (x right, y down, z forward) are `poses`, after the axes turn `turn` (a rotation). `poses`
/// must not be empty.
pub(crate) fn normalising(poses: &[[[f64; 4]; 4]], turn: [[f64; 3]; 3]) -> WorldTransform {
    let n = poses.len().max(1) as f64;
    let mean = |column: usize, sign: f64| -> [f64; 3] {
        std::array::from_fn(|i| poses.iter().map(|m| sign * m[i][column]).sum::<f64>() / n)
    };
    let centre = mean(3, 1.0);
    let up = mul(&turn, mean(1, -1.0));
    let rotation = matmul(&rotation_onto_z(up), &turn);
    let moved = mul(&rotation, centre);
    let translation = moved.map(|v| -v);
    let largest = poses
        .iter()
        .flat_map(|m| {
            let c = mul(&rotation, [m[0][3], m[1][3], m[2][3]]);
            (0..3).map(move |i| (c[i] + translation[i]).abs())
        })
        .fold(0.0f64, f64::max);
    let scale = if largest > 0.0 && largest.is_finite() {
        1.0 / largest
    } else {
        1.0
    };
    WorldTransform {
        rotation,
        translation,
        scale,
    }
}

/// The minimal rotation taking the direction of `a` to `+Z` (Rodrigues' formula about
/// `a × z`); a half turn about an axis perpendicular to `a` when `a` points down `-Z`; the
/// identity for a vector too short to have a direction.
pub(crate) fn rotation_onto_z(a: [f64; 3]) -> [[f64; 3]; 3] {
    let identity = WorldTransform::IDENTITY.rotation;
    let length = norm(a);
    if !(length > NO_DIRECTION && length.is_finite()) {
        return identity;
    }
    let a = a.map(|v| v / length);
    // a × z = (a_y, -a_x, 0); its length is the sine of the angle, a_z its cosine.
    let (axis, sin, cos) = {
        let s = (a[0] * a[0] + a[1] * a[1]).sqrt();
        if s > NO_DIRECTION {
            ([a[1] / s, -a[0] / s, 0.0], s, a[2])
        } else if a[2] > 0.0 {
            return identity;
        } else {
            ([1.0, 0.0, 0.0], 0.0, -1.0)
        }
    };
    let [x, y, z] = axis;
    let k = [[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]];
    let k2 = matmul(&k, &k);
    std::array::from_fn(|i| std::array::from_fn(|j| identity[i][j] + sin * k[i][j] + (1.0 - cos) * k2[i][j]))
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

pub(crate) fn mul(m: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2])
}

pub(crate) fn transpose(m: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|j| m[j][i]))
}

fn matmul(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: [f64; 3], b: [f64; 3], tol: f64) {
        assert!((0..3).all(|i| (a[i] - b[i]).abs() < tol), "{a:?} != {b:?}");
    }

    fn is_rotation(r: &[[f64; 3]; 3]) {
        let rtr = matmul(&transpose(r), r);
        let identity = WorldTransform::IDENTITY.rotation;
        assert!(
            rtr.iter()
                .flatten()
                .zip(identity.iter().flatten())
                .all(|(a, b)| (a - b).abs() < 1e-12),
            "{r:?}"
        );
        let det = r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1]) - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
            + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0]);
        assert!((det - 1.0).abs() < 1e-12);
    }

    #[test]
    fn each_direction_is_rotated_onto_z() {
        for a in [
            [1.0, 2.0, 3.0],
            [0.3, -0.2, -5.0],
            [0.0, 0.0, -2.0],
            [0.0, 0.0, 4.0],
            [-1.0, 0.0, 0.0],
        ] {
            let r = rotation_onto_z(a);
            is_rotation(&r);
            let len = norm(a);
            close(mul(&r, a), [0.0, 0.0, len], 1e-12);
        }
        // x onto z: a quarter turn about -y, which sends z to -x and keeps y.
        let r = rotation_onto_z([1.0, 0.0, 0.0]);
        close(mul(&r, [0.0, 0.0, 1.0]), [-1.0, 0.0, 0.0], 1e-15);
        close(mul(&r, [0.0, 1.0, 0.0]), [0.0, 1.0, 0.0], 1e-15);
        assert_eq!(rotation_onto_z([0.0; 3]), WorldTransform::IDENTITY.rotation);
    }

    #[test]
    fn the_turn_is_a_rotation() {
        is_rotation(&COLMAP_TURN);
        close(mul(&COLMAP_TURN, [1.0, 2.0, 3.0]), [2.0, 1.0, -3.0], 1e-15);
    }

    /// The OpenCV pose at `c` with the given x (right), y (down) and z (forward) columns.
    fn pose(c: [f64; 3], right: [f64; 3], down: [f64; 3], forward: [f64; 3]) -> [[f64; 4]; 4] {
        [
            [right[0], down[0], forward[0], c[0]],
            [right[1], down[1], forward[1], c[1]],
            [right[2], down[2], forward[2], c[2]],
            [0.0, 0.0, 0.0, 1.0],
        ]
    }

    #[test]
    fn cameras_are_centred_levelled_and_scaled() {
        // Two cameras whose image up is world +X (down -X) in the file, looking along -Y and +Y.
        // The turn sends +X to +Y, which then goes to +Z; the centres (1, 2, 3) and (3, 2, -1)
        // average to (2, 2, 1), and their offsets (-1, 0, 2) and (1, 0, -2) become, turned
        // ((x, y, z) -> (y, x, -z)) then +Y -> +Z (a quarter turn about +X: (x, y, z) -> (x, -z, y)),
        // (0, 2, -1) and (0, -2, 1): largest coordinate 2, so scale 1/2.
        let poses = [
            pose([1.0, 2.0, 3.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]),
            pose([3.0, 2.0, -1.0], [0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
        ];
        let w = normalising(&poses, COLMAP_TURN);
        is_rotation(&w.rotation);
        assert!((w.scale - 0.5).abs() < 1e-15);
        close(w.apply_point([1.0, 2.0, 3.0]), [0.0, 1.0, -0.5], 1e-15);
        close(w.apply_point([3.0, 2.0, -1.0]), [0.0, -1.0, 0.5], 1e-15);
        close(w.apply_direction([1.0, 0.0, 0.0]), [0.0, 0.0, 1.0], 1e-15);
        close(w.invert_point(w.apply_point([0.3, -7.0, 2.0])), [0.3, -7.0, 2.0], 1e-14);
        close(
            w.invert_direction(w.apply_direction([0.3, -7.0, 2.0])),
            [0.3, -7.0, 2.0],
            1e-14,
        );
        let moved = w.apply_pose(poses[0]);
        // The first camera's up (+X in the file) is +Z now; its centre as above.
        close([-moved[0][1], -moved[1][1], -moved[2][1]], [0.0, 0.0, 1.0], 1e-15);
        close([moved[0][3], moved[1][3], moved[2][3]], [0.0, 1.0, -0.5], 1e-15);
        assert_eq!(moved[3], [0.0, 0.0, 0.0, 1.0]);
    }

    #[test]
    fn one_camera_is_not_scaled() {
        let p = pose([1.0, 2.0, 3.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
        let w = normalising(&[p], COLMAP_TURN);
        assert_eq!(w.scale, 1.0);
        close(w.apply_point([1.0, 2.0, 3.0]), [0.0; 3], 1e-15);
    }
}
