//! Where a model's field lives: a box of the world (a synthetic object, or `--box`), or all of
//! space contracted into the cube `[-2, 2]^3` around an inner region framed from the cameras
//! (a capture whose background reaches to infinity). The space decides how a ray is sampled
//! (clipped to the box, or cut into pieces of equal contracted length) and how the occupancy
//! grid judges a cell (in the contracted shell one step stands for a long stretch of world).
//!
//! The choice is made from the data unless a flag makes it ([`SpaceChoice::Auto`]): pictures
//! with alpha (an object over nothing) keep the box, and so do pictures without alpha whose
//! borders are all one colour (an object over a plain backdrop); other pictures without alpha
//! (a capture, whose background is real) are contracted ([`SpaceDecision`] says which and
//! why).

use fogray_ops::rays::{Aabb, RayBatch};
use fogray_ops::sample::{OccupancyGrid, PackedSamples, DEFAULT_FAR_GAP, MAX_CONTRACTED_PATH};
use fogray_ops::space::{framing_from_cameras, Contraction, InnerRegion, CONTRACTED_HALF_WIDTH};
use fogray_tape::Float;
use fogray_tape::Offsets;
use ndarray::{Array1, Array2};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::backdrop::plain_backdrop;
use crate::dataset::Dataset;
use crate::error::FitError;
use crate::sampling::sample_rays;
use crate::settings::FitSettings;

/// Which space a fit's field lives in (`--space`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum SpaceChoice {
    /// Decided from the data: the box for pictures with alpha, contracted for pictures
    /// without.
    Auto,
    /// The scene box (`--box`, or the dataset's).
    Box,
    /// All of space, contracted around an inner region framed from the training cameras.
    Contracted,
}

impl SpaceChoice {
    /// `auto`, `box` or `contracted`.
    pub(crate) fn name(self) -> &'static str {
        match self {
            SpaceChoice::Auto => "auto",
            SpaceChoice::Box => "box",
            SpaceChoice::Contracted => "contracted",
        }
    }
}

/// The inner region of a contracted field as settings and checkpoints keep it: a cube of
/// half-side `radius` around `centre` (world units), kept as it is; everything beyond is
/// contracted into the shell.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Framing {
    /// The centre (world units).
    pub centre: [f64; 3],
    /// The half-side of the inner cube (world units).
    pub radius: f64,
}

impl Framing {
    /// The framing of `data`'s training cameras ([`framing_from_cameras`]: the point nearest
    /// their optical axes, and their median distance to it).
    ///
    /// Errors: cameras that frame nothing (one camera, all at one point).
    pub(crate) fn of_cameras(data: &Dataset) -> Result<Framing, FitError> {
        let centres: Vec<[f64; 3]> = data.train.iter().map(|v| v.camera.centre()).collect();
        let axes: Vec<[f64; 3]> = data
            .train
            .iter()
            .map(|v| {
                let m = v.camera.camera_to_world();
                [m[0][2], m[1][2], m[2][2]]
            })
            .collect();
        let region = framing_from_cameras(&centres, &axes)?;
        Ok(Framing {
            centre: region.centre,
            radius: region.radius,
        })
    }

    /// The contraction around this inner region.
    ///
    /// Errors: a radius that is not finite and positive, a centre that is not finite.
    pub(crate) fn contraction(&self) -> Result<Contraction, FitError> {
        Ok(Contraction::new(InnerRegion::new(self.centre, self.radius)?)?)
    }
}

/// A fit's space as the model samples in it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FieldSpace {
    /// The field covers this box of the world; rays are clipped to it.
    Box(Aabb),
    /// The field covers the contracted cube `[-2, 2]^3`; rays are sampled from their origin
    /// out to the cube's faces at equal contracted steps.
    Contracted(Contraction),
}

impl FieldSpace {
    /// The contraction, for a contracted space.
    pub(crate) fn contraction(&self) -> Option<Contraction> {
        match self {
            FieldSpace::Box(_) => None,
            FieldSpace::Contracted(c) => Some(*c),
        }
    }

    /// Samples `rays` every `step` (world units in a box, contracted units in the contracted
    /// space), only where `occupancy` is occupied if given.
    ///
    /// In the contracted space each sample's position is contracted (what the grid looks
    /// up), and its length and depth are measured in contracted units too: pieces of about
    /// `step` along the contracted path, each of the length of its contracted chord and at the
    /// contracted distance of its midpoint from the ray's origin ([`march_ray`]), so that the field's density is per
    /// unit of contracted length, as DVGO v2 and Plenoxels model unbounded scenes. Measured in
    /// world units instead, a step in the far shell stands for thousands of world units, the
    /// fresh grid's thin fog there is opaque, every shell cell stays occupied, and the
    /// distortion loss (a sum of weights times distances) is dominated by the far shell; in
    /// contracted units the shell is as thin as the inner region until the views make it
    /// otherwise, and the background at infinity is a layer of cells next to the cube's faces.
    /// Depths of a contracted field are therefore distances along the contracted path.
    ///
    /// Errors: a step that is not finite and positive, the samplers' errors.
    pub(crate) fn sample<F: Float>(
        &self,
        occupancy: Option<&OccupancyGrid>,
        rays: &RayBatch<F>,
        step: f64,
    ) -> Result<PackedSamples<F>, FitError> {
        match self {
            FieldSpace::Box(bounds) => sample_rays(bounds, occupancy, rays, step),
            FieldSpace::Contracted(contraction) => march_contracted(contraction, occupancy, rays, step),
        }
    }
}

/// The most pieces a ray is cut into in the contracted space: a ray's contracted path is at
/// most [`MAX_CONTRACTED_PATH`] long, and a piece about `step` long.
fn max_pieces(step: f64) -> usize {
    (MAX_CONTRACTED_PATH / step).ceil() as usize + 1
}

/// One sample of a contracted march: its contracted midpoint, its distance along the
/// contracted path to the midpoint, and its contracted length.
type ContractedPiece = ([f64; 3], f64, f64);

/// The pieces of one ray from its origin to the far gap, handed to `emit` in order: each about
/// `step` long in contracted space, found by a secant march (the next world step is `step`
/// over the contracted speed of the last piece, which starts at `r` inside the inner region),
/// each piece's length the exact chord between the contracted images of its ends. The chord,
/// not `step`, is the piece's length, so the optical depth of a piece is right however far its
/// length strays from `step` where the speed changes fast (across the inner faces, far out);
/// the secant keeps the march to about one piece per `step`, and out in the shell, where the
/// speed falls like `1 / t^2`, each step halves what is left to the faces, so the far gap is
/// reached in a few pieces.
fn march_ray(
    contraction: &Contraction,
    origin: [f64; 3],
    direction: [f64; 3],
    step: f64,
    mut emit: impl FnMut(ContractedPiece),
) {
    let region = contraction.region();
    let Some(ray) = ScaledRay::new(region.centre, region.radius, origin, direction) else {
        return;
    };
    let limit = CONTRACTED_HALF_WIDTH - DEFAULT_FAR_GAP;
    let (mut s, mut y) = (0.0, ray.contracted_at(0.0));
    // In radii: a step of `step` is `step` radii of world inside the inner region.
    let mut scaled_step = step;
    let mut walked = 0.0;
    for _ in 0..max_pieces(step) {
        if y.iter().any(|v| v.abs() >= limit) {
            break;
        }
        let s_next = s + scaled_step;
        let next = ray.contracted_at(s_next);
        let chord = (0..3).map(|a| (next[a] - y[a]).powi(2)).sum::<f64>().sqrt();
        if !(chord.is_finite() && chord > 0.0 && s_next.is_finite()) {
            break;
        }
        emit((ray.contracted_at(s + scaled_step / 2.0), walked + chord / 2.0, chord));
        walked += chord;
        (s, y) = (s_next, next);
        // A speed that falls along the ray makes the chord short of `step`: the next world
        // step is scaled by what this one gave, at most doubling or halving at once.
        scaled_step *= (step / chord).clamp(0.5, 2.0);
    }
}

/// A ray in units of the inner region's radius, measured from its centre: the point at `s`
/// radii along the ray is `start + s u`, and its contraction is that point inside the unit
/// cube and `(2 - 1/m) p / m` (`m = ||p||_inf`) outside, the map [`Contraction::contract`]
/// computes for any world point, here without its guards for points beyond the float range:
/// a marched ray stops at the far gap, `1 / gap` radii out, long before.
struct ScaledRay {
    start: [f64; 3],
    u: [f64; 3],
}

impl ScaledRay {
    /// `None` where the origin, in radii from the centre, is not finite.
    fn new(centre: [f64; 3], radius: f64, origin: [f64; 3], direction: [f64; 3]) -> Option<ScaledRay> {
        let start = [0, 1, 2].map(|a| (origin[a] - centre[a]) / radius);
        (start.iter().chain(&direction).all(|v| v.is_finite())).then_some(ScaledRay { start, u: direction })
    }

    /// The contracted point `s` radii along the ray.
    #[inline]
    fn contracted_at(&self, s: f64) -> [f64; 3] {
        let p = [0, 1, 2].map(|a| self.start[a] + s * self.u[a]);
        let m = p[0].abs().max(p[1].abs()).max(p[2].abs());
        if m <= 1.0 {
            return p;
        }
        let scale = (2.0 - 1.0 / m) / m;
        p.map(|v| v * scale)
    }
}

/// Rays a worker marches into one buffer: enough that the buffers' bookkeeping is small
/// beside the march, few enough that both cores share a batch evenly.
const RAYS_PER_CHUNK: usize = 128;

/// The kept pieces of a run of rays, packed as [`PackedSamples`] packs them.
struct MarchedChunk<F> {
    positions: Vec<F>,
    t: Vec<F>,
    delta: Vec<F>,
    lengths: Vec<usize>,
}

/// [`FieldSpace::sample`] in the contracted space: each ray marched by [`march_ray`], the
/// pieces whose contracted midpoint lies in an unoccupied cell of `occupancy` dropped as they
/// are made. Runs of rays are marched in parallel into packed buffers of their own, joined in
/// ray order, so the samples are the same at any thread count.
fn march_contracted<F: Float>(
    contraction: &Contraction,
    occupancy: Option<&OccupancyGrid>,
    rays: &RayBatch<F>,
    step: f64,
) -> Result<PackedSamples<F>, FitError> {
    if !(step.is_finite() && step > 0.0) {
        return Err(FitError::Config(format!(
            "contracted sample step {step}: must be finite and positive"
        )));
    }
    let (origins, directions) = (rays.origins(), rays.directions());
    let chunks: Vec<MarchedChunk<F>> = (0..rays.len().div_ceil(RAYS_PER_CHUNK))
        .into_par_iter()
        .map(|c| {
            let rays_here = c * RAYS_PER_CHUNK..((c + 1) * RAYS_PER_CHUNK).min(rays.len());
            let mut chunk = MarchedChunk {
                positions: Vec::new(),
                t: Vec::new(),
                delta: Vec::new(),
                lengths: Vec::with_capacity(rays_here.len()),
            };
            for r in rays_here {
                let (o, d) = (origins.row(r), directions.row(r));
                let origin = [o[0].as_f64(), o[1].as_f64(), o[2].as_f64()];
                let direction = [d[0].as_f64(), d[1].as_f64(), d[2].as_f64()];
                let before = chunk.t.len();
                march_ray(contraction, origin, direction, step, |(y, depth, length)| {
                    if occupancy.is_none_or(|grid| grid.is_occupied_at(y)) {
                        chunk.positions.extend(y.map(F::lit));
                        chunk.t.push(F::lit(depth));
                        chunk.delta.push(F::lit(length));
                    }
                });
                chunk.lengths.push(chunk.t.len() - before);
            }
            chunk
        })
        .collect();
    let n: usize = chunks.iter().map(|c| c.t.len()).sum();
    let (mut positions, mut t, mut delta) = (Vec::with_capacity(3 * n), Vec::with_capacity(n), Vec::with_capacity(n));
    let mut ray = Vec::with_capacity(n);
    let mut lengths = Vec::with_capacity(rays.len());
    for chunk in chunks {
        positions.extend(chunk.positions);
        t.extend(chunk.t);
        delta.extend(chunk.delta);
        for length in chunk.lengths {
            ray.extend(std::iter::repeat_n(lengths.len(), length));
            lengths.push(length);
        }
    }
    Ok(PackedSamples {
        positions: Array2::from_shape_vec((n, 3), positions)
            .map_err(|e| FitError::Config(format!("packing contracted samples: {e}")))?,
        t: Array1::from(t),
        delta: Array1::from(delta),
        offsets: Offsets::from_lengths(lengths),
        ray,
    })
}

/// What a fit decided about its space, and why, for the report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SpaceDecision {
    /// `box` or `contracted`.
    pub space: &'static str,
    /// The inner region, for a contracted space.
    pub framing: Option<Framing>,
    /// Why, in one sentence.
    pub why: String,
}

/// `settings` with their space decided for `data`: `--space auto` becomes the box when the
/// training pictures have alpha (an object over nothing: the box is its world) or borders of
/// one colour (an object over a plain backdrop), and the contracted space otherwise (a
/// capture: what lies beyond any box is real and must be modelled); a contracted space without a framing is framed from the training cameras.
///
/// Errors: cameras that frame nothing.
pub fn resolve(settings: &FitSettings, data: &Dataset) -> Result<(FitSettings, SpaceDecision), FitError> {
    let alpha = data.training_alpha();
    let (space, why) = match settings.space {
        SpaceChoice::Auto if alpha => (
            SpaceChoice::Box,
            "the training pictures have alpha: an object over nothing, fitted in its box".to_string(),
        ),
        SpaceChoice::Auto => match plain_backdrop(&data.train) {
            Some(c) => (
                SpaceChoice::Box,
                format!(
                    "the training pictures have no alpha, but every border is one colour ({:.2}, {:.2}, {:.2}): an object over a plain backdrop, fitted in its box",
                    c[0], c[1], c[2]
                ),
            ),
            None => (
            SpaceChoice::Contracted,
            "the training pictures have no alpha: their background is real, so all of space is modelled, contracted around the region the cameras look at".to_string(),
        ),
        },
        given => (given, format!("--space {}", given.name())),
    };
    let framing = match (space, settings.framing) {
        (SpaceChoice::Contracted, Some(f)) => Some(f),
        (SpaceChoice::Contracted, None) => Some(Framing::of_cameras(data)?),
        _ => settings.framing,
    };
    let resolved = FitSettings {
        space,
        framing,
        ..*settings
    };
    let decision = SpaceDecision {
        space: space.name(),
        framing: (space == SpaceChoice::Contracted).then_some(framing).flatten(),
        why,
    };
    Ok((resolved, decision))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn contraction() -> Contraction {
        Framing {
            centre: [0.0; 3],
            radius: 2.0,
        }
        .contraction()
        .unwrap()
    }

    #[test]
    fn a_ray_from_the_centre_walks_the_contracted_path_to_the_far_gap() {
        let c = contraction();
        let step = 0.01;
        let mut pieces = Vec::new();
        march_ray(&c, [0.0; 3], [1.0, 0.0, 0.0], step, |p| pieces.push(p));
        // Along +x from the centre the contracted path is the segment from 0 to 2: the
        // lengths add up to where the march stopped, within a piece of the far gap.
        let walked: f64 = pieces.iter().map(|p| p.2).sum();
        assert!((walked - 2.0).abs() < DEFAULT_FAR_GAP + 2.0 * step, "{walked}");
        // Inside the inner region (world |x| < 2) the map is x / r: pieces of exactly `step`.
        for p in pieces.iter().take(50) {
            assert!((p.2 - step).abs() < 1e-12, "{}", p.2);
        }
        // Depths are the distance walked to each midpoint, and positions lie on the axis.
        let mut before = 0.0;
        for p in &pieces {
            assert!((p.1 - (before + p.2 / 2.0)).abs() < 1e-12);
            assert!(p.0[1].abs() < 1e-15 && p.0[2].abs() < 1e-15);
            // On the axis the contracted point lies within its piece of the path: at its
            // middle inside the inner region, where the map is linear; between its ends in the
            // shell (the image of the world midpoint).
            if p.0[0] < 1.0 {
                assert!((p.0[0] - p.1).abs() < 1e-9, "{:?}", p);
            } else {
                assert!(p.0[0] > before - 1e-12 && p.0[0] < before + p.2 + 1e-12, "{:?}", p);
            }
            before += p.2;
        }
        // Far out the march reaches the gap in few pieces, not thousands.
        assert!(pieces.len() < (2.0 / step) as usize + 60, "{}", pieces.len());
    }

    #[test]
    fn a_constant_density_per_contracted_unit_gives_the_closed_form_transmittance() {
        // Optical depth is the density times the contracted length: along any ray from the
        // centre to the far gap, sigma times the path length 2 - gap (in L-inf terms the path
        // along an axis), whatever the world spacing of the pieces.
        let c = contraction();
        let mut pieces = Vec::new();
        march_ray(&c, [0.0; 3], [0.0, 0.0, -1.0], 0.02, |p| pieces.push(p));
        let sigma = 0.7;
        let tau: f64 = pieces.iter().map(|p| sigma * p.2).sum();
        let last = pieces.last().unwrap();
        let reached = last.1 + last.2 / 2.0;
        assert!((tau - sigma * reached).abs() < 1e-9);
        assert!(reached > 2.0 - DEFAULT_FAR_GAP - 0.05 && reached <= 2.0, "{reached}");
    }

    #[test]
    fn unoccupied_cells_drop_their_samples() {
        use fogray_ops::sample::OccupancyConfig;
        let c = contraction();
        let rays = RayBatch::new(
            ndarray::arr2(&[[0.0f64, 0.0, 0.0], [0.5, 0.5, 0.0]]),
            ndarray::arr2(&[[1.0f64, 0.0, 0.0], [0.0, 1.0, 0.0]]),
        )
        .unwrap();
        let all = march_contracted(&c, None, &rays, 0.05).unwrap();
        let mut grid =
            OccupancyGrid::new(Contraction::cube(), 8, OccupancyConfig::opacity(0.05, 0.01).unwrap()).unwrap();
        // Occupied only where contracted x > 1 (the +x half of the shell).
        grid.update(
            |p: ndarray::ArrayView2<'_, f64>| {
                Ok::<_, FitError>(Array1::from_iter(p.rows().into_iter().map(|q| {
                    if q[0] > 1.0 {
                        100.0
                    } else {
                        0.0
                    }
                })))
            },
            fogray_ops::sample::CellPoints::Centre,
        )
        .unwrap();
        let kept = march_contracted(&c, Some(&grid), &rays, 0.05).unwrap();
        let expected = (0..all.len())
            .filter(|&k| grid.is_occupied_at([0, 1, 2].map(|a| all.positions[[k, a]])))
            .count();
        assert_eq!(kept.len(), expected);
        assert!(!kept.is_empty() && kept.len() < all.len());
        assert!(kept.positions.column(0).iter().all(|&x| x > 1.0 - 1e-12));
    }

    #[test]
    fn auto_contracts_a_capture_and_keeps_the_box_for_an_object_over_a_plain_backdrop() {
        let capture = crate::testing::small_dataset();
        let auto = FitSettings {
            space: SpaceChoice::Auto,
            ..FitSettings::DEFAULT
        };
        let (settings, decision) = resolve(&auto, &capture).unwrap();
        assert_eq!(
            (settings.space, decision.space),
            (SpaceChoice::Contracted, "contracted")
        );
        assert!(decision.framing.is_some());
        // The same cameras, each picture a dark object over white: the box, framed by nothing.
        let mut studio = capture.clone();
        for v in studio.train.iter_mut() {
            v.image.indexed_iter_mut().for_each(|((y, x, _), p)| {
                *p = if (2..6).contains(&y) && (2..6).contains(&x) {
                    0.1
                } else {
                    1.0
                };
            });
        }
        let (settings, decision) = resolve(&auto, &studio).unwrap();
        assert_eq!((settings.space, decision.space), (SpaceChoice::Box, "box"));
        assert!(decision.why.contains("plain backdrop") && decision.framing.is_none());
        // A flag overrides the data.
        let asked = FitSettings {
            space: SpaceChoice::Contracted,
            ..FitSettings::DEFAULT
        };
        assert_eq!(resolve(&asked, &studio).unwrap().0.space, SpaceChoice::Contracted);
    }

    #[test]
    fn the_scaled_ray_contracts_as_the_contraction_does() {
        let c = Framing {
            centre: [0.3, -1.0, 2.0],
            radius: 1.7,
        }
        .contraction()
        .unwrap();
        let (origin, direction) = ([2.0, 0.5, -3.0], [0.48, -0.6, 0.64]);
        let ray = ScaledRay::new([0.3, -1.0, 2.0], 1.7, origin, direction).unwrap();
        for s in [0.0, 0.1, 0.5, 1.0, 3.0, 10.0, 1e3, 1e6] {
            let exact = c.contract([0, 1, 2].map(|a| origin[a] + s * 1.7 * direction[a]));
            let fast = ray.contracted_at(s);
            for a in 0..3 {
                assert!((exact[a] - fast[a]).abs() < 1e-12, "{s}: {exact:?} {fast:?}");
            }
        }
    }
}
