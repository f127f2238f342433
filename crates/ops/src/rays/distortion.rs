//! Lens distortion: the OpenCV radial-tangential model, as instant-ngp and nerfstudio store it
//! (`k1 k2 k3 k4 p1 p2`).
//!
//! A lens sends the undistorted normalised point `(x, y)` (camera-frame `x / z`, `y / z`) to
//!
//! ```text
//! r² = x² + y²,   s = 1 + k1 r² + k2 r⁴ + k3 r⁶ + k4 r⁸
//! x' = x s + 2 p1 x y + p2 (r² + 2 x²)
//! y' = y s + p1 (r² + 2 y²) + 2 p2 x y
//! ```
//!
//! and the pixel is `(fx x' + cx, fy y' + cy)`. A pixel's ray needs the inverse, which has no
//! closed form: [`LensDistortion::undistort`] solves `distort(p) = p'` by Newton's method on the
//! 2x2 system, started at `p'` (the distortion of a real lens is a small perturbation of the
//! identity, so the start is close and the iteration converges quadratically).

use crate::error::{At, Op, OpsError};

/// Newton steps at most; well-behaved lenses converge in under ten.
const MAX_STEPS: usize = 40;
/// A step shorter than this (in normalised image units, about 1e-12 of a pixel at any
/// practical focal length) ends the iteration.
const STEP_TOLERANCE: f64 = 1e-15;

/// The radial (`k1` to `k4`) and tangential (`p1`, `p2`) coefficients of the OpenCV model;
/// all zero (the default) is a perfect pinhole. The lens sends the undistorted normalised point
/// `(x, y)` (camera-frame `x / z`, `y / z`) to
///
/// ```text
/// r² = x² + y²,   s = 1 + k1 r² + k2 r⁴ + k3 r⁶ + k4 r⁸
/// x' = x s + 2 p1 x y + p2 (r² + 2 x²)
/// y' = y s + p1 (r² + 2 y²) + 2 p2 x y
/// ```
///
/// and the pixel is `(fx x' + cx, fy y' + cy)`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LensDistortion {
    /// Radial coefficient of r².
    pub k1: f64,
    /// Radial coefficient of r⁴.
    pub k2: f64,
    /// Radial coefficient of r⁶.
    pub k3: f64,
    /// Radial coefficient of r⁸.
    pub k4: f64,
    /// First tangential coefficient.
    pub p1: f64,
    /// Second tangential coefficient.
    pub p2: f64,
}

impl LensDistortion {
    /// No distortion.
    pub const NONE: LensDistortion = LensDistortion {
        k1: 0.0,
        k2: 0.0,
        k3: 0.0,
        k4: 0.0,
        p1: 0.0,
        p2: 0.0,
    };

    /// Whether every coefficient is zero (rays are then built without any iteration, so a
    /// pinhole camera's rays are exactly those of the formula).
    pub fn is_none(&self) -> bool {
        *self == LensDistortion::NONE
    }

    /// Errors: a coefficient that is not finite.
    pub fn check(&self) -> Result<(), OpsError> {
        let named = [
            ("k1", self.k1),
            ("k2", self.k2),
            ("k3", self.k3),
            ("k4", self.k4),
            ("p1", self.p1),
            ("p2", self.p2),
        ];
        match named.iter().find(|(_, v)| !v.is_finite()) {
            Some(&(what, value)) => Err(OpsError::Domain {
                op: Op::Rays,
                at: At::Value,
                what: format!("distortion {what}"),
                value,
                rule: "must be finite",
            }),
            None => Ok(()),
        }
    }

    /// Where the lens sends the undistorted normalised point `p`.
    pub fn distort(&self, p: [f64; 2]) -> [f64; 2] {
        self.distort_with_jacobian(p).0
    }

    /// The distorted point and the Jacobian `d(x', y') / d(x, y)` (row-major).
    fn distort_with_jacobian(&self, [x, y]: [f64; 2]) -> ([f64; 2], [[f64; 2]; 2]) {
        let LensDistortion { k1, k2, k3, k4, p1, p2 } = *self;
        let r2 = x * x + y * y;
        let s = 1.0 + r2 * (k1 + r2 * (k2 + r2 * (k3 + r2 * k4)));
        // ds/d(r²); d(r²)/dx = 2x, d(r²)/dy = 2y.
        let ds = k1 + r2 * (2.0 * k2 + r2 * (3.0 * k3 + r2 * 4.0 * k4));
        let xd = x * s + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
        let yd = y * s + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
        let jacobian = [
            [
                s + 2.0 * x * x * ds + 2.0 * p1 * y + 6.0 * p2 * x,
                2.0 * x * y * ds + 2.0 * p1 * x + 2.0 * p2 * y,
            ],
            [
                2.0 * x * y * ds + 2.0 * p1 * x + 2.0 * p2 * y,
                s + 2.0 * y * y * ds + 6.0 * p1 * y + 2.0 * p2 * x,
            ],
        ];
        ([xd, yd], jacobian)
    }

    /// The undistorted normalised point that the lens sends to `distorted`, by Newton's method
    /// (Newton's method on the 2x2 system, started at `distorted`); `None` if the iteration does not settle (a point beyond
    /// where the model folds back on itself, which no real pixel of a calibrated lens is) or
    /// meets a singular Jacobian.
    pub fn undistort(&self, distorted: [f64; 2]) -> Option<[f64; 2]> {
        if self.is_none() {
            return Some(distorted);
        }
        let mut p = distorted;
        for _ in 0..MAX_STEPS {
            let ([xd, yd], [[a, b], [c, d]]) = self.distort_with_jacobian(p);
            let (fx, fy) = (xd - distorted[0], yd - distorted[1]);
            let det = a * d - b * c;
            if !det.is_finite() || det.abs() < 1e-12 {
                return None;
            }
            let step = [(d * fx - b * fy) / det, (a * fy - c * fx) / det];
            p = [p[0] - step[0], p[1] - step[1]];
            if step[0].abs().max(step[1].abs()) <= STEP_TOLERANCE * (1.0 + p[0].abs().max(p[1].abs())) {
                return Some(p);
            }
        }
        // Converged to rounding but oscillating in the last bit: accept a residual at rounding.
        let r = self.distort(p);
        let residual = (r[0] - distorted[0]).abs().max((r[1] - distorted[1]).abs());
        (residual <= 1e-12).then_some(p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LENS: LensDistortion = LensDistortion {
        k1: -0.12,
        k2: 0.03,
        k3: -0.004,
        k4: 0.0005,
        p1: 0.0013,
        p2: -0.0021,
    };

    #[test]
    fn the_forward_model_matches_the_formula_written_out() {
        // x = 0.3, y = -0.2: r² = 0.13.
        let (x, y) = (0.3f64, -0.2f64);
        let r2: f64 = 0.13;
        let s = 1.0 - 0.12 * r2 + 0.03 * r2.powi(2) - 0.004 * r2.powi(3) + 0.0005 * r2.powi(4);
        let want = [
            x * s + 2.0 * 0.0013 * x * y - 0.0021 * (r2 + 2.0 * x * x),
            y * s + 0.0013 * (r2 + 2.0 * y * y) + 2.0 * -0.0021 * x * y,
        ];
        let got = LENS.distort([x, y]);
        assert!(
            (got[0] - want[0]).abs() < 1e-15 && (got[1] - want[1]).abs() < 1e-15,
            "{got:?} {want:?}"
        );
    }

    #[test]
    fn the_jacobian_matches_central_differences() {
        let h = 1e-6;
        for p in [[0.3, -0.2], [-0.7, 0.5], [0.05, 0.9]] {
            let (_, j) = LENS.distort_with_jacobian(p);
            for (col, axis) in [(0, [h, 0.0]), (1, [0.0, h])] {
                let plus = LENS.distort([p[0] + axis[0], p[1] + axis[1]]);
                let minus = LENS.distort([p[0] - axis[0], p[1] - axis[1]]);
                for row in 0..2 {
                    let fd = (plus[row] - minus[row]) / (2.0 * h);
                    assert!(
                        (j[row][col] - fd).abs() < 1e-8,
                        "{p:?} d{row}/d{col}: {} vs {fd}",
                        j[row][col]
                    );
                }
            }
        }
    }

    /// Undistorting what the lens distorted gives the point back, over the whole field of a
    /// wide lens (normalised radius up to 1, about 90 degrees across), where the first-order
    /// inverse `p - (distort(p) - p)` (a common shortcut) is off by more than a pixel.
    #[test]
    fn undistort_inverts_distort_where_the_first_order_inverse_does_not() {
        let mut worst_shortcut = 0.0f64;
        for i in -10..=10 {
            for j in -10..=10 {
                let p = [i as f64 * 0.07, j as f64 * 0.07];
                let d = LENS.distort(p);
                let back = LENS.undistort(d).expect("a well-behaved lens converges");
                assert!(
                    (back[0] - p[0]).abs() < 1e-13 && (back[1] - p[1]).abs() < 1e-13,
                    "{p:?} -> {back:?}"
                );
                let shortcut = [2.0 * d[0] - LENS.distort(d)[0], 2.0 * d[1] - LENS.distort(d)[1]];
                worst_shortcut = worst_shortcut.max((shortcut[0] - p[0]).abs().max((shortcut[1] - p[1]).abs()));
            }
        }
        // At a focal length of 500 pixels, 2e-3 normalised units is a pixel.
        assert!(worst_shortcut > 2e-3, "{worst_shortcut}");
    }

    #[test]
    fn no_distortion_is_the_identity_bit_for_bit() {
        let p = [0.123456789, -0.987654321];
        assert_eq!(LensDistortion::NONE.undistort(p), Some(p));
        assert_eq!(LensDistortion::NONE.distort(p), p);
    }

    #[test]
    fn a_non_finite_coefficient_is_refused() {
        let bad = LensDistortion { p2: f64::NAN, ..LENS };
        let e = bad.check().unwrap_err();
        assert!(e.to_string().contains("distortion p2"), "{e}");
    }
}
