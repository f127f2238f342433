//! A batch of rays: origins and unit directions, `[R, 3]` each.

use fogray_tape::Float;
use ndarray::{Array2, ArrayView2, Axis};

use crate::error::{At, Op, OpsError};

/// `R` rays as origins `[R, 3]` and unit directions `[R, 3]` (world units; a point at
/// distance `t` along ray `r` is `origins[r] + t * directions[r]`).
///
/// The directions are unit length (normalised in f64 on construction, then rounded to `F`),
/// so every `t` a sampler returns is a distance.
#[derive(Debug, Clone, PartialEq)]
pub struct RayBatch<F: Float> {
    origins: Array2<F>,
    directions: Array2<F>,
}

impl<F: Float> RayBatch<F> {
    /// Rays from `origins` `[R, 3]` and `directions` `[R, 3]` (any non-zero length; they are
    /// normalised).
    ///
    /// Errors: shapes other than `[R, 3]` or different `R`, a non-finite value, a zero (or
    /// overflowing) direction.
    pub fn new(origins: Array2<F>, directions: Array2<F>) -> Result<Self, OpsError> {
        for (what, a) in [("origins", &origins), ("directions", &directions)] {
            if a.ncols() != 3 {
                return Err(OpsError::shape_of(Op::Rays, what, "[R, 3]", a.shape()));
            }
            if let Some((k, v)) = a.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                return Err(OpsError::Domain {
                    op: Op::Rays,
                    at: At::Entry {
                        row: k / 3,
                        column: k % 3,
                    },
                    what: what.into(),
                    value: v.as_f64(),
                    rule: "must be finite",
                });
            }
        }
        if origins.nrows() != directions.nrows() {
            return Err(OpsError::Shape {
                op: Op::Rays,
                what: "directions",
                expected: format!("[{}, 3] like the origins", origins.nrows()),
                got: format!("{:?}", directions.shape()),
            });
        }
        let mut unit = Vec::with_capacity(directions.len());
        for (r, d) in directions.axis_iter(Axis(0)).enumerate() {
            let d = [d[0].as_f64(), d[1].as_f64(), d[2].as_f64()];
            let n = normalise(d).ok_or_else(|| OpsError::Domain {
                op: Op::Rays,
                at: At::Ray(r),
                what: "direction's length".into(),
                value: norm(d),
                rule: "must be positive and finite",
            })?;
            unit.extend(n.map(F::lit));
        }
        let directions = Array2::from_shape_vec((origins.nrows(), 3), unit).map_err(|e| OpsError::Shape {
            op: Op::Rays,
            what: "directions",
            expected: "[R, 3]".into(),
            got: e.to_string(),
        })?;
        Ok(RayBatch { origins, directions })
    }

    /// Builds from row-major data already checked (finite origins, unit directions).
    pub(crate) fn from_checked(origins: Vec<F>, directions: Vec<F>) -> Self {
        let rays = origins.len() / 3;
        RayBatch {
            origins: Array2::from_shape_vec((rays, 3), origins).expect("three values per origin"),
            directions: Array2::from_shape_vec((rays, 3), directions).expect("three values per direction"),
        }
    }

    /// The rays of several batches, in order (batch 0's rays first).
    pub fn concat(batches: &[RayBatch<F>]) -> Self {
        let origins = batches.iter().flat_map(|b| b.origins.iter().copied()).collect();
        let directions = batches.iter().flat_map(|b| b.directions.iter().copied()).collect();
        Self::from_checked(origins, directions)
    }

    /// Number of rays.
    pub fn len(&self) -> usize {
        self.origins.nrows()
    }

    /// Whether the batch has no ray.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Origins `[R, 3]`.
    pub fn origins(&self) -> ArrayView2<'_, F> {
        self.origins.view()
    }

    /// Unit directions `[R, 3]`.
    pub fn directions(&self) -> ArrayView2<'_, F> {
        self.directions.view()
    }

    /// Ray `r`'s origin and direction in f64. Panics if `r >= len()` (a caller's bug).
    pub(crate) fn ray(&self, r: usize) -> ([f64; 3], [f64; 3]) {
        let (o, d) = (self.origins.row(r), self.directions.row(r));
        (
            [o[0].as_f64(), o[1].as_f64(), o[2].as_f64()],
            [d[0].as_f64(), d[1].as_f64(), d[2].as_f64()],
        )
    }
}

/// Euclidean length, without overflow for large finite components or lost digits for tiny
/// ones: the square root of the sum of squares where that sum lies far from both ends of the
/// exponent range (every batch's directions, on every training step), else nested `hypot`,
/// which scales but costs several times as much.
pub(crate) fn norm(v: [f64; 3]) -> f64 {
    // About 2^-900 and 2^900: a component square below the first (perhaps subnormal) is below the
    // sum's last digit, and no square overflowed.
    const SAFE: std::ops::Range<f64> = 1.2e-271..8.5e270;
    let s = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
    if SAFE.contains(&s) {
        s.sqrt()
    } else {
        v[0].hypot(v[1]).hypot(v[2])
    }
}

/// `v / |v|`, or `None` when the length is zero or not finite.
pub(crate) fn normalise(v: [f64; 3]) -> Option<[f64; 3]> {
    let n = norm(v);
    (n > 0.0 && n.is_finite()).then(|| v.map(|x| x / n))
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::arr2;

    #[test]
    fn directions_are_normalised_and_concat_keeps_order() {
        let a = RayBatch::new(arr2(&[[1.0, 2.0, 3.0]]), arr2(&[[0.0, 3.0, 4.0]])).unwrap();
        // |(0, 3, 4)| = 5.
        assert_eq!(a.directions(), arr2(&[[0.0, 0.6, 0.8]]));
        let b = RayBatch::new(arr2(&[[-1.0, 0.0, 0.0]]), arr2(&[[0.0, 0.0, -2.0]])).unwrap();
        let ab = RayBatch::concat(&[a, b]);
        assert_eq!(ab.origins(), arr2(&[[1.0, 2.0, 3.0], [-1.0, 0.0, 0.0]]));
        assert_eq!(ab.directions(), arr2(&[[0.0, 0.6, 0.8], [0.0, 0.0, -1.0]]));
    }

    #[test]
    fn tiny_directions_normalise_without_underflow() {
        // |(3e-170, 4e-170, 0)|: the squares underflow to zero, so the naive sum gives 0.
        let d: [f64; 3] = [3e-170, 4e-170, 0.0];
        assert_eq!(d[0] * d[0] + d[1] * d[1], 0.0);
        let r = RayBatch::new(arr2(&[[0.0; 3]]), arr2(&[d])).unwrap();
        let got = r.directions().row(0).to_vec();
        assert!(
            got.iter().zip([0.6f64, 0.8, 0.0]).all(|(g, w)| (g - w).abs() < 1e-15),
            "{got:?}"
        );
        // Where the sum of squares is safe it agrees with nested hypot to an ulp or two.
        for v in [
            [1.0, 2.0, 3.0],
            [1e-120, -3e-121, 2e-120],
            [0.3, -1e5, 7.0],
            [4e130, 1e130, -2e129],
        ] {
            let (fast, scaled) = (norm(v), v[0].hypot(v[1]).hypot(v[2]));
            assert!(
                (fast - scaled).abs() <= 2.0 * f64::EPSILON * scaled,
                "{v:?}: {fast} vs {scaled}"
            );
        }
    }

    #[test]
    fn huge_directions_normalise_without_overflow() {
        // |(3e200, 4e200, 0)| overflows as a sum of squares but not as a hypot.
        let d: [f64; 3] = [3e200, 4e200, 0.0];
        assert!((d[0] * d[0] + d[1] * d[1]).sqrt().is_infinite());
        let r = RayBatch::new(arr2(&[[0.0; 3]]), arr2(&[d])).unwrap();
        let got = r.directions().row(0).to_vec();
        assert!(
            got.iter().zip([0.6f64, 0.8, 0.0]).all(|(g, w)| (g - w).abs() < 1e-15),
            "{got:?}"
        );
    }

    #[test]
    fn bad_batches_are_errors() {
        let ok = arr2(&[[0.0f32, 0.0, 1.0]]);
        let wide = ndarray::Array2::<f32>::zeros((1, 4));
        assert!(matches!(
            RayBatch::new(wide.clone(), ok.clone()),
            Err(OpsError::Shape {
                op: Op::Rays,
                what: "origins",
                ..
            })
        ));
        assert!(matches!(
            RayBatch::new(ok.clone(), wide),
            Err(OpsError::Shape { op: Op::Rays, .. })
        ));
        let nan = arr2(&[[0.0f32, f32::NAN, 1.0]]);
        let e = RayBatch::new(nan, ok.clone()).unwrap_err();
        assert_eq!(e.to_string(), "rays: row 0, column 1: origins is NaN (must be finite)");
        let zero = arr2(&[[0.0f32, 0.0, 0.0]]);
        assert!(matches!(
            RayBatch::new(ok.clone(), zero),
            Err(OpsError::Domain {
                op: Op::Rays,
                at: At::Ray(0),
                value: 0.0,
                ..
            })
        ));
        let two = arr2(&[[0.0f32, 0.0, 1.0], [0.0, 0.0, 1.0]]);
        assert!(matches!(
            RayBatch::new(ok, two),
            Err(OpsError::Shape {
                op: Op::Rays,
                what: "directions",
                ..
            })
        ));
    }
}
