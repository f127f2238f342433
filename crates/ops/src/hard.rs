//! The hard renderer: a ray shows the colour of the first sample whose density exceeds a
//! threshold, or the background if none does ("first hit", the limit the soft composite
//! reaches as densities grow). It has no useful derivative, so it is not a tape op.
//!
//! For a scene whose surface is a ball (a disc in 2-D), [`ray_meets_ball`] is the exact hit
//! test, with no samples to miss a grazing ray.

use fogray_tape::{Float, Offsets};

use crate::error::{At, Op, OpsError};

/// For each ray of the packing, the index (within the ray) of the first sample with
/// `sigma > threshold`, or `None`.
///
/// Errors if the offsets are not a valid packing of `sigma`, or a density is NaN.
pub fn first_hit<F: Float>(sigma: &[F], offsets: &[usize], threshold: F) -> Result<Vec<Option<usize>>, OpsError> {
    let offsets = Offsets::new(offsets).map_err(|source| OpsError::Offsets {
        op: Op::FirstHit,
        source,
    })?;
    if offsets.rows() != sigma.len() {
        return Err(OpsError::Shape {
            op: Op::FirstHit,
            what: "sigma",
            expected: format!("{} samples (the offsets' end)", offsets.rows()),
            got: format!("{}", sigma.len()),
        });
    }
    if let Some(i) = sigma.iter().position(|s| s.is_nan()) {
        let (ray, sample) = offsets.locate(i).unwrap_or((0, i));
        return Err(OpsError::domain(
            Op::FirstHit,
            At::Sample { ray, sample },
            "sigma",
            f64::NAN,
            "density must not be NaN",
        ));
    }
    Ok(offsets
        .ranges()
        .map(|rows| sigma[rows].iter().position(|&s| s > threshold))
        .collect())
}

/// Whether the ray `origin + t dir`, `t >= 0`, meets the closed ball of `radius` about
/// `centre`, in any dimension `N` (a disc in 2-D, a sphere in 3-D).
///
/// `dir` need not be of unit length. The ray meets the ball when its line passes within
/// `radius` of `centre` and the ball is in front of `origin`: the point of the line nearest
/// the centre is ahead (`w . dir > 0`, `w = centre - origin`), or `origin` is itself in the
/// ball. Tangent rays are hits.
///
/// The squared distance of the line from the centre, times `|dir|^2`, is computed as
/// `sum over i < j of (dir_i w_j - dir_j w_i)^2` (the cross product's square in 2-D and 3-D),
/// which has no cancellation, not as `|w|^2 |dir|^2 - (w . dir)^2`, whose two large terms
/// cancel for a ray grazing a distant ball. It is compared with `radius^2 |dir|^2` with a
/// relative allowance of `1e-12`, far above the rounding of the terms (about `1e-16` each)
/// and far below a geometric gap a scene cares about: every ray that is tangent in exact
/// arithmetic is a hit, however its terms round, so ties are treated alike; a ray that
/// passes outside the ball by less than about `5e-13 radius` is a hit too. The rounding grows
/// with `|w| / radius`; the allowance covers it while the ball is within about a thousand
/// radii of `origin`.
///
/// A zero `dir` meets the ball iff `origin` is in it; a NaN anywhere gives `false`.
pub fn ray_meets_ball<const N: usize>(origin: [f64; N], dir: [f64; N], centre: [f64; N], radius: f64) -> bool {
    let w: [f64; N] = std::array::from_fn(|i| centre[i] - origin[i]);
    let dot = |a: &[f64; N], b: &[f64; N]| a.iter().zip(b).fold(0.0, |acc, (x, y)| acc + x * y);
    let mut wedge2 = 0.0;
    for i in 0..N {
        for j in i + 1..N {
            let c = dir[i] * w[j] - dir[j] * w[i];
            wedge2 += c * c;
        }
    }
    let r2 = radius * radius;
    let r2d2 = r2 * dot(&dir, &dir);
    let on_line = wedge2 - r2d2 <= 1e-12 * r2d2;
    on_line && (dot(&w, &dir) > 0.0 || dot(&w, &w) <= r2)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ray_meets_ball_by_closed_form_geometry() {
        // Down the z axis from (0, 5): a unit disc at the origin is hit, one at x = 1 is
        // tangent (a hit), one a nanometre further is missed.
        let (o, d) = ([0.0, 5.0], [0.0, -1.0]);
        assert!(ray_meets_ball(o, d, [0.0, 0.0], 1.0));
        assert!(ray_meets_ball(o, d, [1.0, 0.0], 1.0), "tangent counts as a hit");
        assert!(ray_meets_ball(o, d, [-1.0, 0.0], 1.0), "tangent counts as a hit");
        assert!(!ray_meets_ball(o, d, [1.0 + 1e-9, 0.0], 1.0));
        // Behind the origin: not seen; the origin inside the ball: seen whatever the direction.
        assert!(!ray_meets_ball([0.0, -5.0], d, [0.0, 0.0], 1.0));
        assert!(ray_meets_ball([0.0, 0.5], [0.0, 1.0], [0.0, 0.0], 1.0));
        assert!(
            ray_meets_ball([0.0, 0.0], [0.0, 0.0], [0.5, 0.0], 1.0),
            "zero direction, origin inside"
        );
        assert!(
            !ray_meets_ball([0.0, 0.0], [0.0, 0.0], [2.0, 0.0], 1.0),
            "zero direction, origin outside"
        );
        assert!(!ray_meets_ball(o, d, [f64::NAN, 0.0], 1.0));

        // An oblique line through the origin along (3, 4) passes |3 * 5 - 4 * 10| / 5 = 5 from
        // (10, 5): tangent at radius 5 whatever the length of the direction.
        for dir in [[3.0, 4.0], [0.6, 0.8], [30.0, 40.0]] {
            assert!(ray_meets_ball([0.0, 0.0], dir, [10.0, 5.0], 5.0), "{dir:?}");
            assert!(
                !ray_meets_ball([0.0, 0.0], dir, [10.0, 5.0], 5.0 * (1.0 - 1e-9)),
                "{dir:?}"
            );
            assert!(
                ray_meets_ball([0.0, 0.0], dir, [10.0, 5.0], 5.0 * (1.0 + 1e-9)),
                "{dir:?}"
            );
            assert!(!ray_meets_ball([0.0, 0.0], dir, [-10.0, -5.0], 6.0), "behind: {dir:?}");
        }

        // 3-D: (2, -2, 1) is perpendicular to (1, 2, 2) and of length 3, so the line along
        // (1, 2, 2) passes 3 from 2 (1, 2, 2) + (2, -2, 1) = (4, 2, 5).
        let (o, d, c) = ([0.0; 3], [1.0, 2.0, 2.0], [4.0, 2.0, 5.0]);
        assert!(ray_meets_ball(o, d, c, 3.0));
        assert!(!ray_meets_ball(o, d, c, 3.0 * (1.0 - 1e-9)));
        assert!(!ray_meets_ball(o, d, [-4.0, -2.0, -5.0], 3.5), "behind");
    }

    #[test]
    fn tangency_survives_rounding_at_a_distance() {
        // A unit disc whose centre is `s` along the unit direction (0.6, 0.8) and 1 to its
        // side, (0.8, -0.6): the line is tangent in decimal arithmetic, and within 5e-14 of
        // tangent once the inputs are rounded to binary (measured in exact rational
        // arithmetic for these `s`), while the products the test forms are of size `s`. Every
        // one is a hit, and a gap of 1e-9 is still seen.
        let d = [0.6, 0.8];
        for s in [1.0, 10.0, 100.0, 1000.0] {
            let c = [0.6 * s + 0.8, 0.8 * s - 0.6];
            assert!(ray_meets_ball([0.0, 0.0], d, c, 1.0), "s = {s}");
            assert!(!ray_meets_ball([0.0, 0.0], d, c, 1.0 - 1e-9), "s = {s}");
        }
    }

    #[test]
    fn first_sample_above_threshold_per_ray() {
        let sigma = [0.0, 2.0, 9.0, 0.5, 0.0, 7.0];
        let hits = first_hit(&sigma, &[0, 3, 3, 5, 6], 1.0).unwrap();
        assert_eq!(hits, vec![Some(1), None, None, Some(0)]);
        assert!(first_hit(&sigma, &[0, 3], 1.0).is_err());
        assert!(first_hit(&[f64::NAN], &[0, 1], 1.0).is_err());
    }
}
