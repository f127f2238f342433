//! The real spherical-harmonics basis to degree 3, in the order, normalisation and signs of
//! Plenoxels (svox2) and 3D Gaussian splatting (see the [module docs](super) for the table).
//! The basis of a lower degree is a prefix of this one: degree `l` uses the first
//! `(l + 1)^2` values.

/// The highest degree written out.
pub const MAX_DEGREE: usize = 3;

/// `Y_0 = C0 = 1 / (2 sqrt(pi))`.
pub const C0: f64 = 0.282_094_791_773_878_14;

/// Degree 1: `Y_1 = -C1 y`, `Y_2 = C1 z`, `Y_3 = -C1 x`, with `C1 = sqrt(3 / (4 pi))`.
pub const C1: f64 = 0.488_602_511_902_919_9;

/// Degree 2, the factors of `xy`, `yz`, `2z^2 - x^2 - y^2`, `xz` and `x^2 - y^2` (`Y_4..Y_8`).
pub const C2: [f64; 5] = [
    1.092_548_430_592_079_2,
    -1.092_548_430_592_079_2,
    0.315_391_565_252_520_05,
    -1.092_548_430_592_079_2,
    0.546_274_215_296_039_6,
];

/// Degree 3, the factors of `y (3x^2 - y^2)`, `xyz`, `y (4z^2 - x^2 - y^2)`,
/// `z (2z^2 - 3x^2 - 3y^2)`, `x (4z^2 - x^2 - y^2)`, `z (x^2 - y^2)` and `x (x^2 - 3y^2)`
/// (`Y_9..Y_15`).
pub const C3: [f64; 7] = [
    -0.590_043_589_926_643_5,
    2.890_611_442_640_554,
    -0.457_045_799_464_465_8,
    0.373_176_332_590_115_4,
    -0.457_045_799_464_465_8,
    1.445_305_721_320_277,
    -0.590_043_589_926_643_5,
];

/// The number of basis functions of `degree`, `(degree + 1)^2`: 1, 4, 9, 16 for 0..=3.
pub const fn basis_count(degree: usize) -> usize {
    (degree + 1) * (degree + 1)
}

/// The 16 basis values of degree 0 to 3 at `direction` `(x, y, z)`, taken as given (it is not
/// normalised here: the ops check that their directions are unit vectors).
pub fn basis(direction: [f64; 3]) -> [f64; 16] {
    let [x, y, z] = direction;
    let (xx, yy, zz) = (x * x, y * y, z * z);
    [
        C0,
        -C1 * y,
        C1 * z,
        -C1 * x,
        C2[0] * (x * y),
        C2[1] * (y * z),
        C2[2] * (2.0 * zz - xx - yy),
        C2[3] * (x * z),
        C2[4] * (xx - yy),
        C3[0] * y * (3.0 * xx - yy),
        C3[1] * (x * y) * z,
        C3[2] * y * (4.0 * zz - xx - yy),
        C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy),
        C3[4] * x * (4.0 * zz - xx - yy),
        C3[5] * z * (xx - yy),
        C3[6] * x * (xx - 3.0 * yy),
    ]
}
