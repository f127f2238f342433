//! The ranges within which a transforms file's numbers can mean something, checked where they
//! enter so that a typo or a hostile file is refused naming the file and the key, instead of
//! surfacing later as an infinite ray or step deep inside a fit (docs/datasets.md states them).
//!
//! Each bound is generous: it refuses only values no real capture has (a field of view of a
//! few hundredths of a degree, a principal point an image away from the image, a lens
//! coefficient whose polynomial no longer describes a lens, a camera a million scene units
//! away), never a calibration a tool could have produced.

use fogray_ops::Intrinsics;

/// A focal length (pixels) is at most this many times the image's larger side (a field of
/// view of about 0.06 degrees) and at least its reciprocal times it (about 179.9 degrees).
pub const FOCAL_PER_SIDE: f64 = 1000.0;

/// The principal point lies within this many image widths (heights) of the image: `cx` in
/// `[-w, 2w]`, `cy` in `[-h, 2h]`.
pub const PRINCIPAL_POINT_MARGIN: f64 = 1.0;

/// The radial distortion coefficients `k1 .. k4` are at most this in magnitude.
pub const MAX_RADIAL: f64 = 100.0;

/// The tangential distortion coefficients `p1`, `p2` are at most this in magnitude.
pub const MAX_TANGENTIAL: f64 = 1.0;

/// A camera's translation and the scene box's corners are at most this far from the origin on
/// each axis, in the file's world units: beyond it an `f32` ray cannot tell apart points a
/// tenth of a unit apart.
pub const MAX_COORDINATE: f64 = 1e6;

/// `aabb_scale` is at most this (instant-ngp's own stops at 128).
pub const MAX_AABB_SCALE: f64 = 1024.0;

/// The first value of `k` (as `(key, value)`) outside the range above, with the rule it
/// breaks: `fx`, `fy` against [`FOCAL_PER_SIDE`], `cx`, `cy` against
/// [`PRINCIPAL_POINT_MARGIN`].
pub(crate) fn intrinsics_outside(k: &Intrinsics) -> Option<(&'static str, f64, &'static str)> {
    let side = k.width.max(k.height) as f64;
    let (w, h) = (k.width as f64, k.height as f64);
    let focal_ok = |f: f64| f.is_finite() && f <= FOCAL_PER_SIDE * side && f >= side / FOCAL_PER_SIDE;
    let within = |c: f64, extent: f64| {
        c.is_finite() && c >= -PRINCIPAL_POINT_MARGIN * extent && c <= (1.0 + PRINCIPAL_POINT_MARGIN) * extent
    };
    const FOCAL: &str = "a focal length must lie between 1/1000 and 1000 times the image's larger side";
    if !focal_ok(k.fx) {
        return Some(("fl_x", k.fx, FOCAL));
    }
    if !focal_ok(k.fy) {
        return Some(("fl_y", k.fy, FOCAL));
    }
    if !within(k.cx, w) {
        return Some((
            "cx",
            k.cx,
            "the principal point must lie within one image width of the image",
        ));
    }
    if !within(k.cy, h) {
        return Some((
            "cy",
            k.cy,
            "the principal point must lie within one image height of the image",
        ));
    }
    None
}

/// The rule a distortion coefficient `key` of `value` breaks, if any ([`MAX_RADIAL`],
/// [`MAX_TANGENTIAL`]).
pub(crate) fn distortion_outside(key: &str, value: f64) -> Option<&'static str> {
    let (bound, rule) = if key.starts_with('p') {
        (
            MAX_TANGENTIAL,
            "a tangential coefficient must be at most 1 in magnitude",
        )
    } else {
        (MAX_RADIAL, "a radial coefficient must be at most 100 in magnitude")
    };
    (value.abs() > bound).then_some(rule)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn k(fx: f64, fy: f64, cx: f64, cy: f64) -> Intrinsics {
        Intrinsics {
            fx,
            fy,
            cx,
            cy,
            width: 800,
            height: 600,
        }
    }

    #[test]
    fn intrinsics_inside_the_bands_pass_and_the_first_outside_is_named() {
        // 800 is the larger side: focal lengths in [0.8, 800000], cx in [-800, 1600], cy in
        // [-600, 1200].
        assert_eq!(intrinsics_outside(&k(0.8, 800_000.0, -800.0, 1200.0)), None);
        assert_eq!(
            intrinsics_outside(&k(800_001.0, 1.0, 0.0, 0.0)).map(|v| v.0),
            Some("fl_x")
        );
        assert_eq!(intrinsics_outside(&k(1.0, 0.79, 0.0, 0.0)).map(|v| v.0), Some("fl_y"));
        assert_eq!(intrinsics_outside(&k(1.0, 1.0, 1600.5, 0.0)).map(|v| v.0), Some("cx"));
        assert_eq!(intrinsics_outside(&k(1.0, 1.0, 0.0, -600.5)).map(|v| v.0), Some("cy"));
        assert_eq!(intrinsics_outside(&k(1e308, 1.0, 0.0, 0.0)).map(|v| v.1), Some(1e308));
    }

    #[test]
    fn distortion_bounds_are_per_kind() {
        assert_eq!(distortion_outside("k1", -100.0), None);
        assert!(distortion_outside("k4", 100.5).is_some());
        assert_eq!(distortion_outside("p2", 1.0), None);
        assert!(distortion_outside("p1", -1.5).is_some());
    }
}
