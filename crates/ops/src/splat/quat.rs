//! Rotations from quaternions `(w, x, y, z)`, taken unnormalised and normalised here, and the
//! backward of both steps. Normalising inside the op lets an optimiser move the four numbers
//! freely; the gradient it gets is tangent to the sphere (no component along `q`), so a step
//! changes the rotation, not the length.

use super::linalg::M3;

/// The rotation of the unit quaternion `q` (`w, x, y, z`).
#[inline]
pub(crate) fn rotation(q: [f64; 4]) -> M3 {
    let [w, x, y, z] = q;
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// `q / |q|` and `|q|`; the caller has checked that `|q|` is positive and finite.
#[inline]
pub(crate) fn normalise(q: [f64; 4]) -> ([f64; 4], f64) {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    (q.map(|v| v / n), n)
}

/// The gradient for the raw quaternion, given `g`, the gradient for the rotation of its
/// normalised `u = q / |q|`, and `n = |q|`: first `dL/du` from [`rotation`] entry by entry,
/// then the normalisation's `(dL/du - u (u . dL/du)) / n`.
#[inline]
pub(crate) fn rotation_backward(u: [f64; 4], n: f64, g: &M3) -> [f64; 4] {
    let [w, x, y, z] = u;
    let gw = 2.0 * (-z * g[0][1] + y * g[0][2] + z * g[1][0] - x * g[1][2] - y * g[2][0] + x * g[2][1]);
    let gx = 2.0
        * (y * g[0][1] + z * g[0][2] + y * g[1][0] - 2.0 * x * g[1][1] - w * g[1][2] + z * g[2][0] + w * g[2][1]
            - 2.0 * x * g[2][2]);
    let gy = 2.0
        * (-2.0 * y * g[0][0] + x * g[0][1] + w * g[0][2] + x * g[1][0] + z * g[1][2] - w * g[2][0] + z * g[2][1]
            - 2.0 * y * g[2][2]);
    let gz = 2.0
        * (-2.0 * z * g[0][0] - w * g[0][1] + x * g[0][2] + w * g[1][0] - 2.0 * z * g[1][1]
            + y * g[1][2]
            + x * g[2][0]
            + y * g[2][1]);
    let gu = [gw, gx, gy, gz];
    let radial = u[0] * gw + u[1] * gx + u[2] * gy + u[3] * gz;
    [0, 1, 2, 3].map(|i| (gu[i] - u[i] * radial) / n)
}
