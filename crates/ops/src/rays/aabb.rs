//! Axis-aligned boxes and where rays cross them: `[t_near, t_far]` per ray by the slab method.

use fogray_tape::Float;
use rayon::prelude::*;

use super::batch::RayBatch;
use crate::error::{At, Op, OpsError};

/// An axis-aligned box `[min, max]` (finite, `min < max` on every axis).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    min: [f64; 3],
    max: [f64; 3],
}

/// Where each ray of a batch crosses a box (or any caller-chosen segment): ray `r` is inside
/// for `t` in `[t_near[r], t_far[r]]` when `hit[r]`. A miss has `hit[r] = false` and
/// `t_near[r] = t_far[r] = 0`.
#[derive(Debug, Clone, PartialEq)]
pub struct RayIntervals {
    t_near: Vec<f64>,
    t_far: Vec<f64>,
    hit: Vec<bool>,
}

impl Aabb {
    /// The box `[min, max]`. Errors: a non-finite bound or `min >= max` on some axis.
    pub fn new(min: [f64; 3], max: [f64; 3]) -> Result<Self, OpsError> {
        for axis in 0..3 {
            let (lo, hi) = (min[axis], max[axis]);
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(OpsError::Box {
                    op: Op::Rays,
                    axis,
                    min: lo,
                    max: hi,
                });
            }
        }
        Ok(Aabb { min, max })
    }

    /// The lower corner.
    pub fn min(&self) -> [f64; 3] {
        self.min
    }

    /// The upper corner.
    pub fn max(&self) -> [f64; 3] {
        self.max
    }

    /// Whether `p` lies in the closed box.
    pub fn contains(&self, p: [f64; 3]) -> bool {
        (0..3).all(|a| self.min[a] <= p[a] && p[a] <= self.max[a])
    }

    /// The `t >= 0` part of one ray inside the box, or `None` for a miss (computed in f64;
    /// a ray grazing an edge gets a zero-length interval).
    pub fn clip_ray(&self, origin: [f64; 3], direction: [f64; 3]) -> Option<(f64, f64)> {
        // Rays are half-lines: starting inside gives t_near = 0.
        let (mut near, mut far) = (0.0f64, f64::INFINITY);
        for a in 0..3 {
            let (o, d) = (origin[a], direction[a]);
            if d == 0.0 {
                // Parallel to the slab: inside it for every t, or never.
                if o < self.min[a] || o > self.max[a] {
                    return None;
                }
                continue;
            }
            // Divisions, not products with 1/d: (min - o) = 0 with a tiny d stays 0, not NaN.
            let (t0, t1) = ((self.min[a] - o) / d, (self.max[a] - o) / d);
            near = near.max(t0.min(t1));
            far = far.min(t0.max(t1));
        }
        (near <= far).then_some((near, far))
    }

    /// `[t_near, t_far]` of every ray of `rays` inside the box (see [`Aabb::clip_ray`]).
    /// Parallel over rays (a training step clips thousands of them before it can march any).
    pub fn clip<F: Float>(&self, rays: &RayBatch<F>) -> RayIntervals {
        /// Rays per parallel task: a clip is a few nanoseconds.
        const MIN_RAYS_PER_TASK: usize = 1024;
        let mut segments = Vec::with_capacity(rays.len());
        (0..rays.len())
            .into_par_iter()
            .with_min_len(MIN_RAYS_PER_TASK)
            .map(|r| {
                let (o, d) = rays.ray(r);
                self.clip_ray(o, d)
            })
            .collect_into_vec(&mut segments);
        RayIntervals {
            t_near: segments.iter().map(|s| s.map_or(0.0, |s| s.0)).collect(),
            t_far: segments.iter().map(|s| s.map_or(0.0, |s| s.1)).collect(),
            hit: segments.iter().map(Option::is_some).collect(),
        }
    }
}

impl RayIntervals {
    /// Caller-chosen segments (near and far planes, say), every ray a hit.
    /// Errors: different lengths, a non-finite bound, `t_near < 0` or `t_near > t_far`.
    pub fn new(t_near: Vec<f64>, t_far: Vec<f64>) -> Result<Self, OpsError> {
        if t_near.len() != t_far.len() {
            return Err(OpsError::Shape {
                op: Op::Rays,
                what: "t_far",
                expected: format!("{} values like t_near", t_near.len()),
                got: format!("{}", t_far.len()),
            });
        }
        for (r, (&n, &f)) in t_near.iter().zip(&t_far).enumerate() {
            let bad = |what: &str, value: f64, rule| OpsError::Domain {
                op: Op::Rays,
                at: At::Ray(r),
                what: what.into(),
                value,
                rule,
            };
            if !(n.is_finite() && n >= 0.0) {
                return Err(bad("t_near", n, "must be finite and non-negative"));
            }
            if !(f.is_finite() && f >= n) {
                return Err(bad("t_far", f, "must be finite and at least t_near"));
            }
        }
        let hit = vec![true; t_near.len()];
        Ok(RayIntervals { t_near, t_far, hit })
    }

    /// Number of rays.
    pub fn len(&self) -> usize {
        self.hit.len()
    }

    /// Whether there is no ray.
    pub fn is_empty(&self) -> bool {
        self.hit.is_empty()
    }

    /// Entry distances (0 for a miss).
    pub fn t_near(&self) -> &[f64] {
        &self.t_near
    }

    /// Exit distances (0 for a miss).
    pub fn t_far(&self) -> &[f64] {
        &self.t_far
    }

    /// Whether each ray crosses the box.
    pub fn hit(&self) -> &[bool] {
        &self.hit
    }

    /// Ray `r`'s segment, `None` for a miss or `r` out of range.
    pub fn segment(&self, r: usize) -> Option<(f64, f64)> {
        self.hit
            .get(r)
            .and_then(|&h| h.then(|| (self.t_near[r], self.t_far[r])))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::arr2;

    fn cube() -> Aabb {
        Aabb::new([-1.0; 3], [1.0; 3]).unwrap()
    }

    #[test]
    fn slab_intervals_by_hand() {
        let b = cube();
        // Along +x from x = -3: enters at x = -1 (t = 2), leaves at x = 1 (t = 4).
        assert_eq!(b.clip_ray([-3.0, 0.0, 0.0], [1.0, 0.0, 0.0]), Some((2.0, 4.0)));
        // Starting inside at x = 0.5 going -x: t_near = 0, leaves at x = -1 (t = 1.5).
        assert_eq!(b.clip_ray([0.5, 0.2, -0.3], [-1.0, 0.0, 0.0]), Some((0.0, 1.5)));
        // The box behind the ray: a miss.
        assert_eq!(b.clip_ray([-3.0, 0.0, 0.0], [-1.0, 0.0, 0.0]), None);
        // Parallel to x outside the y slab: a miss.
        assert_eq!(b.clip_ray([-3.0, 1.5, 0.0], [1.0, 0.0, 0.0]), None);
        // Diagonal through the corner region: from (-2, -2, 0) along (1, 1, 0)/sqrt2 enters at
        // (-1, -1, 0), t = sqrt2, leaves at (1, 1, 0), t = 3 sqrt2.
        let s = std::f64::consts::FRAC_1_SQRT_2;
        let (n, f) = b.clip_ray([-2.0, -2.0, 0.0], [s, s, 0.0]).unwrap();
        assert!((n - 2f64.sqrt()).abs() < 1e-15 && (f - 3.0 * 2f64.sqrt()).abs() < 1e-15);
        // Grazing the edge x = y = 1 from (0, 2, 0) along (1, -1, 0)/sqrt2: touches (1, 1, 0) only.
        let (n, f) = b.clip_ray([0.0, 2.0, 0.0], [s, -s, 0.0]).unwrap();
        assert!((n - 2f64.sqrt()).abs() < 1e-15 && (f - n).abs() < 1e-15);
        // A ray on the face plane x = 1 moving in y still counts (closed box): [0, 2] from y = -1.
        assert_eq!(b.clip_ray([1.0, -1.0, 0.0], [0.0, 1.0, 0.0]), Some((0.0, 2.0)));
    }

    #[test]
    fn clip_marks_misses_and_keeps_order() {
        let rays = RayBatch::new(
            arr2(&[[-3.0f32, 0.0, 0.0], [0.0, 5.0, 0.0], [0.0, 0.0, 0.0]]),
            arr2(&[[1.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
        )
        .unwrap();
        let iv = cube().clip(&rays);
        assert_eq!(iv.t_near(), &[2.0, 0.0, 0.0]);
        assert_eq!(iv.t_far(), &[4.0, 0.0, 1.0]);
        assert_eq!(iv.hit(), &[true, false, true]);
        assert_eq!(iv.segment(1), None);
        assert_eq!(iv.segment(2), Some((0.0, 1.0)));
    }

    #[test]
    fn random_rays_agree_with_a_dense_point_test() {
        // Oracle: march 4000 points along each ray and test box membership directly.
        use rand::{Rng, SeedableRng};
        let b = Aabb::new([-1.0, -0.5, 0.0], [1.0, 0.5, 2.0]).unwrap();
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        for _ in 0..300 {
            let o: [f64; 3] = std::array::from_fn(|_| rng.gen_range(-3.0..3.0));
            let d = crate::rays::batch::normalise(std::array::from_fn(|_| rng.gen_range(-1.0..1.0))).unwrap();
            let seg = b.clip_ray(o, d);
            let h = 10.0 / 4000.0;
            for i in 0..4000 {
                let t = (i as f64 + 0.5) * h;
                let inside = b.contains(std::array::from_fn(|a| o[a] + t * d[a]));
                let in_seg = seg.is_some_and(|(n, f)| n - 1e-12 <= t && t <= f + 1e-12);
                assert_eq!(inside, in_seg, "o {o:?} d {d:?} t {t} seg {seg:?}");
            }
        }
    }

    #[test]
    fn bad_boxes_and_intervals_are_errors() {
        assert_eq!(
            Aabb::new([0.0; 3], [1.0, -1.0, 1.0]),
            Err(OpsError::Box {
                op: Op::Rays,
                axis: 1,
                min: 0.0,
                max: -1.0
            })
        );
        assert!(Aabb::new([0.0; 3], [1.0, 1.0, f64::INFINITY]).is_err());
        assert!(Aabb::new([f64::NAN, 0.0, 0.0], [1.0; 3]).is_err());
        assert!(Aabb::new([0.0; 3], [0.0, 1.0, 1.0]).is_err());
        assert!(RayIntervals::new(vec![0.0], vec![]).is_err());
        assert!(RayIntervals::new(vec![1.0], vec![0.5]).is_err());
        assert!(RayIntervals::new(vec![-1.0], vec![0.5]).is_err());
        assert!(RayIntervals::new(vec![0.0], vec![f64::NAN]).is_err());
        assert!(RayIntervals::new(vec![0.0, 1.0], vec![0.5, 1.0]).is_ok());
    }
}
