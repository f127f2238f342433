//! Sampling unbounded scenes in contracted space: each ray cut into pieces of equal
//! contracted length, so that the world spacing grows with distance as the contracted
//! grid's resolution falls, from the near distance to where the ray reaches the contracted
//! cube's faces.
//!
//! A piece's edges lie at contracted (Euclidean) distance `step` from each other: edge
//! `k + 1` is the first point of the ray past edge `k` whose contracted image is `step` away
//! from edge `k`'s, found by Newton's method on the world depth with a bisection safeguard
//! (geometric where the bracket spans decades, as it does far out, where a contracted step
//! is a world step of `r m^2`). The world step `step / |J d|` of a first-order march would
//! shrink geometrically towards the faces (the speed `|J d|` falls like `1 / t^2` there) and
//! never arrive; solving for the chord makes the spacing exact in every region, across the
//! inner region's faces and the diagonal planes where the map has a kink.

use fogray_tape::{Float, Offsets};
use ndarray::{Array1, Array2};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rayon::prelude::*;

use super::occupancy::OccupancyGrid;
use super::packed::{PackedSamples, Piece, RAYS_PER_TASK};
use super::stratified::Jitter;
use crate::error::{At, Op, OpsError};
use crate::rays::RayBatch;
use crate::space::{Contraction, CONTRACTED_HALF_WIDTH};

/// The default gap left between the last sample and the contracted cube's faces: a ray is
/// sampled until `||contract(x)||_inf = 2 - gap`, i.e. out to `1 / gap` inner radii from the
/// centre (the far plane nerfacto uses for a unit scene). What lies beyond is the
/// composite's background.
pub const DEFAULT_FAR_GAP: f64 = 1e-3;

/// An upper bound on the contracted length of the image of a ray (a half-line): at most the
/// inner cube's diagonal inside it, and, outside, the path from the inner cube to the faces
/// (`contracted_paths_are_short` in the tests measures random rays against it). The default
/// cap on samples per ray is this over the step.
pub const MAX_CONTRACTED_PATH: f64 = 12.0;

/// The largest number of samples per ray a sampler may be set to allow.
pub const MAX_SAMPLES_PER_RAY: usize = 1 << 20;

/// The smallest contracted step: `MAX_CONTRACTED_PATH / MIN_STEP` stays below
/// [`MAX_SAMPLES_PER_RAY`].
pub const MIN_STEP: f64 = 1e-4;

/// Absolute tolerance (contracted units) on each piece's contracted chord: far above the
/// rounding of a contracted point in f64, far below any step.
const CHORD_TOLERANCE: f64 = 1e-12;

/// Newton / bisection iterations per edge, at most (a geometric bisection halves the
/// decades of a bracket, so even a bracket from 1e-300 to 1e300 closes well within this).
const MAX_ITERATIONS: usize = 200;

/// Samples rays of unbounded scenes in the contracted space of a [`Contraction`]: pieces of
/// contracted length `step` from each ray's near distance to the far gap, optionally kept
/// only where an [`OccupancyGrid`] over the contracted cube is occupied.
///
/// Each sample's `positions` row is the CONTRACTED point of its piece's world midpoint
/// (what a grid over `[-2, 2]^3` looks up), its `t` the world depth of that midpoint, and
/// its `delta` the WORLD length of the piece: a field's density stays per world unit and
/// the composite's optical depth `sum sigma_k delta_k` stays the world integral.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContractedSampler {
    contraction: Contraction,
    step: f64,
    far_gap: f64,
    max_samples: usize,
}

fn sample_config(what: &'static str, value: f64, rule: &'static str) -> OpsError {
    OpsError::config(Op::Sample, what, value, rule)
}

fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// A ray's generator for `Jitter::PerRay` (the splitmix constant spreads neighbouring rays'
/// seeds, as the other samplers do).
fn ray_rng(seed: u64, r: usize) -> StdRng {
    StdRng::seed_from_u64(seed ^ (r as u64).wrapping_add(1).wrapping_mul(0x9E37_79B9_7F4A_7C15))
}

/// A piece and the contracted point of its world midpoint.
type ContractedPiece = (Piece, [f64; 3]);

impl ContractedSampler {
    /// Pieces of contracted length `step` (in `[MIN_STEP, 4]`; `4 / resolution` gives one
    /// sample per cell of a grid of that resolution over the cube), out to
    /// [`DEFAULT_FAR_GAP`], at most `ceil(MAX_CONTRACTED_PATH / step)` per ray.
    /// Errors: `step` outside that range or not finite.
    pub fn new(contraction: Contraction, step: f64) -> Result<Self, OpsError> {
        if !(step.is_finite() && (MIN_STEP..=2.0 * CONTRACTED_HALF_WIDTH).contains(&step)) {
            return Err(sample_config("contracted step", step, "must be in [1e-4, 4]"));
        }
        Ok(ContractedSampler {
            contraction,
            step,
            far_gap: DEFAULT_FAR_GAP,
            max_samples: (MAX_CONTRACTED_PATH / step).ceil() as usize,
        })
    }

    /// Sets the far gap: rays are sampled until their contracted point is within `gap` of
    /// the cube's faces (`1 / gap` inner radii out). Errors: `gap` outside `(0, 1)`.
    pub fn with_far_gap(mut self, gap: f64) -> Result<Self, OpsError> {
        if !(gap > 0.0 && gap < 1.0) {
            return Err(sample_config("far gap", gap, "must be in (0, 1)"));
        }
        self.far_gap = gap;
        Ok(self)
    }

    /// Sets the most samples one ray may get (the rest of a ray past them is not sampled).
    /// Errors: 0 or above [`MAX_SAMPLES_PER_RAY`].
    pub fn with_max_samples(mut self, max_samples: usize) -> Result<Self, OpsError> {
        if !(1..=MAX_SAMPLES_PER_RAY).contains(&max_samples) {
            return Err(sample_config(
                "samples per ray",
                max_samples as f64,
                "must be in 1..=2^20",
            ));
        }
        self.max_samples = max_samples;
        Ok(self)
    }

    /// The contraction.
    pub fn contraction(&self) -> &Contraction {
        &self.contraction
    }

    /// The contracted length of a piece.
    pub fn step(&self) -> f64 {
        self.step
    }

    /// The far gap.
    pub fn far_gap(&self) -> f64 {
        self.far_gap
    }

    /// The most samples per ray.
    pub fn max_samples(&self) -> usize {
        self.max_samples
    }

    /// The world depth at which the ray `origin + t direction` (unit direction) leaves the
    /// box `|x - c|_inf <= r / gap` for good, where its contracted point reaches
    /// `||y||_inf = 2 - gap`: the far end of its sampling (negative when the ray starts
    /// outside and leads away).
    pub fn far_end(&self, origin: [f64; 3], direction: [f64; 3]) -> f64 {
        let region = self.contraction.region();
        let half = region.radius / self.far_gap;
        (0..3)
            .filter(|&a| direction[a] != 0.0)
            .map(|a| (region.centre[a] + half.copysign(direction[a]) - origin[a]) / direction[a])
            .fold(f64::INFINITY, f64::min)
    }

    fn contract_at(&self, o: [f64; 3], d: [f64; 3], t: f64) -> [f64; 3] {
        self.contraction.contract(std::array::from_fn(|a| o[a] + t * d[a]))
    }

    /// The contracted velocity `J(x(t)) d`.
    fn velocity(&self, o: [f64; 3], d: [f64; 3], t: f64) -> [f64; 3] {
        let j = self.contraction.jacobian(std::array::from_fn(|a| o[a] + t * d[a]));
        std::array::from_fn(|i| j[i][0] * d[0] + j[i][1] * d[1] + j[i][2] * d[2])
    }

    /// The first depth in `(t0, t_far)` whose contracted point lies `target` from `y0`
    /// (the caller has checked that the far end lies farther), and that point.
    fn next_edge(&self, o: [f64; 3], d: [f64; 3], t0: f64, y0: [f64; 3], target: f64, t_far: f64) -> (f64, [f64; 3]) {
        let (mut lo, mut hi) = (t0, t_far);
        // Between the bracket's ends: geometric in the offset from t0 where the bracket
        // spans more than a decade of it (far out), arithmetic otherwise.
        let split = |lo: f64, hi: f64| {
            let (a, b) = (lo - t0, hi - t0);
            if a > 0.0 && b > 16.0 * a {
                t0 + (a * b).sqrt()
            } else {
                0.5 * (lo + hi)
            }
        };
        let v0 = self.velocity(o, d, t0);
        let speed = distance(v0, [0.0; 3]);
        let mut t = t0 + target / speed;
        if !(t > lo && t < hi) {
            t = split(lo, hi);
        }
        for _ in 0..MAX_ITERATIONS {
            let y = self.contract_at(o, d, t);
            let chord: [f64; 3] = std::array::from_fn(|a| y[a] - y0[a]);
            let length = distance(y, y0);
            let g = length - target;
            if g.abs() <= CHORD_TOLERANCE {
                return (t, y);
            }
            if g < 0.0 {
                lo = t;
            } else {
                hi = t;
            }
            if hi - lo <= 4.0 * f64::EPSILON * hi.abs() {
                break;
            }
            let v = self.velocity(o, d, t);
            let slope = (chord[0] * v[0] + chord[1] * v[1] + chord[2] * v[2]) / length;
            let newton = t - g / slope;
            t = if slope > 0.0 && newton > lo && newton < hi {
                newton
            } else {
                split(lo, hi)
            };
        }
        (hi, self.contract_at(o, d, hi))
    }

    /// Ray `(o, d)`'s pieces from `t_near`, the first of contracted length `first * step`,
    /// appended to `out` with their midpoints' contracted points.
    fn ray_pieces(&self, o: [f64; 3], d: [f64; 3], t_near: f64, first: f64, out: &mut Vec<ContractedPiece>) {
        let t_far = self.far_end(o, d);
        if t_far <= t_near {
            return;
        }
        let y_far = self.contract_at(o, d, t_far);
        let (mut t, mut y) = (t_near, self.contract_at(o, d, t_near));
        let mut target = first * self.step;
        let push = |lo: f64, hi: f64, out: &mut Vec<ContractedPiece>| {
            out.push(((lo, hi), self.contract_at(o, d, 0.5 * (lo + hi))));
        };
        for _ in 0..self.max_samples {
            if distance(y_far, y) <= target {
                push(t, t_far, out);
                return;
            }
            let (next, y_next) = self.next_edge(o, d, t, y, target, t_far);
            if next <= t {
                // A step below the depth's resolution: the rest is one piece.
                push(t, t_far, out);
                return;
            }
            push(t, next, out);
            (t, y) = (next, y_next);
            target = self.step;
        }
    }

    /// Samples `rays` from `t_near[r]` (world depth, finite, at least 0) to the far gap in
    /// pieces of contracted length `step` (see the [type docs](ContractedSampler) for what
    /// the outputs hold). With `occupancy` (a grid over [`Contraction::cube`]) only the
    /// pieces whose midpoint's contracted point lies in an occupied cell are kept, as
    /// [`OccupancyGrid::march_midpoints`] does in a box.
    ///
    /// `jitter`: [`Jitter::None`], or [`Jitter::PerRay`] (the first piece's contracted
    /// length `u step`, `u` uniform in `(0, 1]` per ray, seeded from the seed and the ray's
    /// index, which shifts every edge). A ray whose origin lies past the far gap and leads
    /// away has no sample; a ray that reaches the sampler's [`max_samples`](Self::max_samples)
    /// is not sampled past them. Parallel over rays; the same output whatever the thread
    /// count.
    ///
    /// Errors (nothing sampled): `t_near` not one per ray, a `t_near` negative or not
    /// finite (named by ray), [`Jitter::PerSample`] (its edges move between neighbouring
    /// midpoints in world depth, which far out is not where the contracted spacing puts
    /// them), a grid not over the contracted cube.
    pub fn sample<F: Float>(
        &self,
        rays: &RayBatch<F>,
        t_near: &[f64],
        jitter: Jitter,
        occupancy: Option<&OccupancyGrid>,
    ) -> Result<PackedSamples<F>, OpsError> {
        if t_near.len() != rays.len() {
            return Err(OpsError::shape(
                Op::Sample,
                "t_near",
                format!("one per ray ({})", rays.len()),
                format!("{}", t_near.len()),
            ));
        }
        if let Some((r, &t)) = t_near.iter().enumerate().find(|(_, t)| !(t.is_finite() && **t >= 0.0)) {
            return Err(OpsError::domain(
                Op::Sample,
                At::Ray(r),
                "t_near",
                t,
                "must be finite and non-negative",
            ));
        }
        let seed = match jitter {
            Jitter::None => None,
            Jitter::PerRay { seed } => Some(seed),
            Jitter::PerSample { .. } => {
                return Err(OpsError::Mismatch {
                    op: Op::Sample,
                    what: "jitter",
                    problem: "per-sample jitter is not defined in contracted space: use Jitter::PerRay",
                })
            }
        };
        if let Some(grid) = occupancy {
            check_cube(grid)?;
        }
        let n_rays = rays.len();
        let chunks: Vec<(Vec<usize>, Vec<ContractedPiece>)> = (0..n_rays.div_ceil(RAYS_PER_TASK))
            .into_par_iter()
            .map(|c| {
                let mut counts = Vec::with_capacity(RAYS_PER_TASK);
                let mut kept = Vec::new();
                let mut candidates = Vec::new();
                let task = c * RAYS_PER_TASK..((c + 1) * RAYS_PER_TASK).min(n_rays);
                for (r, &near) in task.clone().zip(&t_near[task]) {
                    let (o, d) = rays.ray(r);
                    let first = seed.map_or(1.0, |s| 1.0 - ray_rng(s, r).gen::<f64>());
                    candidates.clear();
                    self.ray_pieces(o, d, near, first, &mut candidates);
                    let before = kept.len();
                    match occupancy {
                        Some(grid) => kept.extend(candidates.iter().filter(|(_, y)| grid.is_occupied_at(*y))),
                        None => kept.extend_from_slice(&candidates),
                    }
                    counts.push(kept.len() - before);
                }
                (counts, kept)
            })
            .collect();
        let offsets = Offsets::from_lengths(chunks.iter().flat_map(|(counts, _)| counts.iter().copied()));
        let ray: Vec<usize> = offsets
            .ranges()
            .enumerate()
            .flat_map(|(r, range)| std::iter::repeat_n(r, range.len()))
            .collect();
        let pieces = chunks.iter().flat_map(|(_, kept)| kept.iter());
        let n = offsets.rows();
        let mut positions = Vec::with_capacity(3 * n);
        let mut t = Vec::with_capacity(n);
        let mut delta = Vec::with_capacity(n);
        for &((lo, hi), y) in pieces {
            positions.extend(y.map(F::lit));
            t.push(F::lit(0.5 * (lo + hi)));
            delta.push(F::lit(hi - lo));
        }
        Ok(PackedSamples {
            positions: Array2::from_shape_vec((n, 3), positions).expect("three coordinates per sample"),
            t: Array1::from(t),
            delta: Array1::from(delta),
            offsets,
            ray,
        })
    }
}

/// An occupancy grid for contracted samples must cover the contracted cube exactly.
pub(crate) fn check_cube(grid: &OccupancyGrid) -> Result<(), OpsError> {
    let cube = Contraction::cube();
    if grid.bounds() == cube {
        Ok(())
    } else {
        Err(OpsError::Mismatch {
            op: Op::Sample,
            what: "occupancy grid",
            problem: "its box must be the contracted cube [-2, 2]^3 (Contraction::cube)",
        })
    }
}
