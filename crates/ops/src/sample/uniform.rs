//! Uniform sampling of each ray's segment: a fixed step, or a fixed number of equal pieces.

use fogray_tape::Float;

use super::packed::{check_lengths, pack, PackedSamples};
use super::stratified::RayJitter;
use crate::error::{Op, OpsError};
use crate::rays::{RayBatch, RayIntervals};

/// How finely a segment `[t_near, t_far]` is cut.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Spacing {
    /// Pieces `[t_near + i h, t_near + (i + 1) h]`, the last one clipped to `t_far` (so it is
    /// at most `h` long, at least a millionth of `h` unless the segment is shorter); samples
    /// at their midpoints. `h` finite and positive.
    Step(f64),
    /// `n >= 1` equal pieces; samples at their midpoints.
    Count(usize),
}

impl Spacing {
    pub(crate) fn check(self) -> Result<Self, OpsError> {
        match self {
            Spacing::Step(h) if !(h.is_finite() && h > 0.0) => Err(OpsError::Config {
                op: Op::Sample,
                what: "step",
                value: h,
                rule: "must be finite and positive",
            }),
            Spacing::Count(0) => Err(OpsError::Config {
                op: Op::Sample,
                what: "sample count",
                value: 0.0,
                rule: "must be at least 1",
            }),
            s => Ok(s),
        }
    }

    /// The step for a segment of length `len > 0`.
    pub(crate) fn step(self, len: f64) -> f64 {
        match self {
            Spacing::Step(h) => h,
            Spacing::Count(n) => len / n as f64,
        }
    }
}

/// Uniform sampling: every hit ray's `[t_near, t_far]` cut by a [`Spacing`], one sample per
/// piece at its midpoint with `delta` its length, so the pieces tile the segment exactly.
/// Misses and zero-length segments get no sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Uniform {
    spacing: Spacing,
}

impl Uniform {
    /// Errors: a step that is not finite and positive, a count of 0.
    pub fn new(spacing: Spacing) -> Result<Self, OpsError> {
        Ok(Uniform {
            spacing: spacing.check()?,
        })
    }

    /// Samples every ray of `rays` within its interval (parallel over rays).
    /// Errors: `intervals` not one per ray.
    pub fn sample<F: Float>(&self, rays: &RayBatch<F>, intervals: &RayIntervals) -> Result<PackedSamples<F>, OpsError> {
        sample_segments(rays, intervals, self.spacing, |_| RayJitter::none())
    }
}

/// The shared body of the uniform and stratified samplers.
pub(crate) fn sample_segments<F: Float>(
    rays: &RayBatch<F>,
    intervals: &RayIntervals,
    spacing: Spacing,
    jitter_of: impl Fn(usize) -> RayJitter + Sync,
) -> Result<PackedSamples<F>, OpsError> {
    check_lengths(rays, intervals)?;
    Ok(pack(rays, |r, pieces| {
        if let Some((near, far)) = intervals.segment(r) {
            if far > near {
                let step = spacing.step(far - near);
                jitter_of(r).cut(near, far, near, step, pieces);
            }
        }
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rays::Aabb;
    use ndarray::arr2;

    fn rays() -> RayBatch<f64> {
        // Ray 0 along +x from x = -3 (segment [2, 4]); ray 1 misses; ray 2 from the centre
        // along +z (segment [0, 1]).
        RayBatch::new(
            arr2(&[[-3.0, 0.0, 0.0], [0.0, 5.0, 0.0], [0.0, 0.0, 0.0]]),
            arr2(&[[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
        )
        .unwrap()
    }

    #[test]
    fn fixed_step_by_hand() {
        let r = rays();
        let iv = Aabb::new([-1.0; 3], [1.0; 3]).unwrap().clip(&r);
        let s = Uniform::new(Spacing::Step(0.75)).unwrap().sample(&r, &iv).unwrap();
        // Ray 0: [2, 4] -> [2, 2.75], [2.75, 3.5], [3.5, 4]; ray 1: none; ray 2: [0, 0.75], [0.75, 1].
        assert_eq!(s.offsets, vec![0, 3, 3, 5]);
        assert_eq!(s.t.to_vec(), vec![2.375, 3.125, 3.75, 0.375, 0.875]);
        assert_eq!(s.delta.to_vec(), vec![0.75, 0.75, 0.5, 0.75, 0.25]);
        assert_eq!(s.ray, vec![0, 0, 0, 2, 2]);
        // x = -3 + t on ray 0; z = t on ray 2.
        assert_eq!(s.positions.row(0).to_vec(), vec![-0.625, 0.0, 0.0]);
        assert_eq!(s.positions.row(4).to_vec(), vec![0.0, 0.0, 0.875]);
        // The pieces tile each segment: deltas sum to its length.
        assert_eq!(s.delta.slice(ndarray::s![0..3]).sum(), 2.0);
        assert_eq!(s.samples_per_ray(), 5.0 / 3.0);
    }

    #[test]
    fn fixed_count_by_hand() {
        let r = rays();
        let iv = Aabb::new([-1.0; 3], [1.0; 3]).unwrap().clip(&r);
        let s = Uniform::new(Spacing::Count(4)).unwrap().sample(&r, &iv).unwrap();
        assert_eq!(s.offsets, vec![0, 4, 4, 8]);
        assert_eq!(s.t.to_vec(), vec![2.25, 2.75, 3.25, 3.75, 0.125, 0.375, 0.625, 0.875]);
        assert_eq!(s.delta.to_vec(), vec![0.5, 0.5, 0.5, 0.5, 0.25, 0.25, 0.25, 0.25]);
    }

    #[test]
    fn feeds_the_composite_directly() {
        // A constant density 0.5 and colour 1 over ray 0's [2, 4] (length 2): opacity
        // 1 - exp(-0.5 * 2) = 1 - 1/e whatever the step; ray 1 (a miss) is empty: opacity 0.
        let r = rays();
        let iv = Aabb::new([-1.0; 3], [1.0; 3]).unwrap().clip(&r);
        let s = Uniform::new(Spacing::Step(0.3)).unwrap().sample(&r, &iv).unwrap();
        let op = crate::Composite::new(&s.offsets)
            .unwrap()
            .background(crate::Background::None);
        let sigma = ndarray::Array1::from_elem(s.len(), 0.5).into_dyn();
        let color = ndarray::Array2::from_elem((s.len(), 1), 1.0).into_dyn();
        let delta = s.delta.clone().into_dyn();
        let inputs = crate::CompositeArrays::new(sigma.view(), delta.view(), color.view());
        let (outs, _) = op.evaluate(&inputs).unwrap();
        assert!((outs.opacity[0] - (1.0 - (-1.0f64).exp())).abs() < 1e-14);
        assert_eq!(outs.opacity[1], 0.0);
        // 1 - exp(-0.5 * 1) for ray 2's [0, 1].
        assert!((outs.opacity[2] - (1.0 - (-0.5f64).exp())).abs() < 1e-14);
    }

    #[test]
    fn bad_configs_are_errors() {
        assert!(Uniform::new(Spacing::Step(0.0)).is_err());
        assert!(Uniform::new(Spacing::Step(f64::NAN)).is_err());
        assert!(Uniform::new(Spacing::Count(0)).is_err());
        let r = rays();
        let iv = RayIntervals::new(vec![0.0], vec![1.0]).unwrap();
        let e = Uniform::new(Spacing::Count(2)).unwrap().sample(&r, &iv).unwrap_err();
        assert!(matches!(
            e,
            OpsError::Shape {
                op: Op::Sample,
                what: "intervals",
                ..
            }
        ));
    }
}
