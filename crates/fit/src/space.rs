//! Where a model's field lives: a box of the world (a synthetic object, or `--box`), or all of
//! space contracted into the cube `[-2, 2]^3` around an inner region framed from the cameras
//! (a capture whose background reaches to infinity). The space decides how a ray is sampled
//! (clipped to the box, or cut into pieces of equal contracted length) and how the occupancy
//! grid judges a cell (in the contracted shell one step stands for a long stretch of world).
//!
//! The choice is made from the data unless a flag makes it ([`resolve`]): pictures with alpha
//! (an object over nothing) keep the box; pictures without alpha (a capture, whose background
//! is real) are contracted.

use fogray_ops::rays::{Aabb, RayBatch};
use fogray_ops::sample::{OccupancyGrid, PackedSamples, DEFAULT_FAR_GAP, MAX_CONTRACTED_PATH};
use fogray_ops::space::{framing_from_cameras, Contraction, InnerRegion, CONTRACTED_HALF_WIDTH};
use fogray_tape::Float;
use fogray_tape::Offsets;
use ndarray::{Array1, Array2};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

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
    pub fn name(self) -> &'static str {
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
    pub fn of_cameras(data: &Dataset) -> Result<Framing, FitError> {
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
    pub fn contraction(&self) -> Result<Contraction, FitError> {
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
    pub fn contraction(&self) -> Option<Contraction> {
        match self {
            FieldSpace::Box(_) => None,
            FieldSpace::Contracted(c) => Some(*c),
        }
    }

    /// The box the field's grid covers: the world box, or the contracted cube.
    pub fn bounds(&self) -> Aabb {
        match self {
            FieldSpace::Box(bounds) => *bounds,
            FieldSpace::Contracted(_) => Contraction::cube(),
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
    pub fn sample<F: Float>(
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

/// The pieces of one ray from its origin to the far gap: each about `step` long in contracted
/// space, found by a secant march (the next world step is `step` over the contracted speed of
/// the last piece, which starts at `r` inside the inner region), each piece's length the exact
/// chord between the contracted images of its ends. The chord, not `step`, is the piece's
/// length, so the optical depth of a piece is right however far its length strays from `step`
/// where the speed changes fast (across the inner faces, far out); the secant keeps the march
/// to about one piece per `step`, and out in the shell, where the speed falls like `1 / t^2`,
/// each step halves what is left to the faces, so the far gap is reached in a few pieces.
fn march_ray(contraction: &Contraction, origin: [f64; 3], direction: [f64; 3], step: f64) -> Vec<ContractedPiece> {
    let at = |t: f64| contraction.contract([0, 1, 2].map(|a| origin[a] + t * direction[a]));
    let limit = CONTRACTED_HALF_WIDTH - DEFAULT_FAR_GAP;
    let mut pieces = Vec::new();
    let (mut t, mut y) = (0.0, at(0.0));
    let mut world_step = step * contraction.region().radius;
    let mut walked = 0.0;
    for _ in 0..max_pieces(step) {
        if y.iter().any(|v| v.abs() >= limit) {
            break;
        }
        let t_next = t + world_step;
        let next = at(t_next);
        let chord = (0..3).map(|a| (next[a] - y[a]).powi(2)).sum::<f64>().sqrt();
        if !(chord.is_finite() && chord > 0.0 && t_next.is_finite()) {
            break;
        }
        pieces.push((at(t + world_step / 2.0), walked + chord / 2.0, chord));
        walked += chord;
        (t, y) = (t_next, next);
        // A speed that falls along the ray makes the chord short of `step`: the next world
        // step is scaled by what this one gave, at most doubling or halving at once.
        world_step *= (step / chord).clamp(0.5, 2.0);
    }
    pieces
}

/// [`FieldSpace::sample`] in the contracted space: each ray marched by [`march_ray`] (in
/// parallel over rays), the pieces whose contracted midpoint lies in an unoccupied cell of
/// `occupancy` dropped.
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
    let per_ray: Vec<Vec<ContractedPiece>> = (0..rays.len())
        .into_par_iter()
        .map(|r| {
            let (o, d) = (origins.row(r), directions.row(r));
            let origin = [o[0].as_f64(), o[1].as_f64(), o[2].as_f64()];
            let direction = [d[0].as_f64(), d[1].as_f64(), d[2].as_f64()];
            let mut pieces = march_ray(contraction, origin, direction, step);
            if let Some(grid) = occupancy {
                pieces.retain(|(y, _, _)| grid.is_occupied_at(*y));
            }
            pieces
        })
        .collect();
    let n: usize = per_ray.iter().map(Vec::len).sum();
    let mut positions = Array2::zeros((n, 3));
    let (mut t, mut delta, mut ray) = (Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n));
    for (r, pieces) in per_ray.iter().enumerate() {
        for (y, depth, length) in pieces {
            for a in 0..3 {
                positions[[ray.len(), a]] = F::lit(y[a]);
            }
            t.push(F::lit(*depth));
            delta.push(F::lit(*length));
            ray.push(r);
        }
    }
    Ok(PackedSamples {
        positions,
        t: Array1::from(t),
        delta: Array1::from(delta),
        offsets: Offsets::from_lengths(per_ray.iter().map(Vec::len)),
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
/// training pictures have alpha (an object over nothing: the box is its world) and the
/// contracted space when they have none (a capture: what lies beyond any box is real and must
/// be modelled); a contracted space without a framing is framed from the training cameras.
///
/// Errors: cameras that frame nothing.
pub fn resolve(settings: &FitSettings, data: &Dataset) -> Result<(FitSettings, SpaceDecision), FitError> {
    let alpha = data.training_alpha();
    let (space, why) = match settings.space {
        SpaceChoice::Auto if alpha => (
            SpaceChoice::Box,
            "the training pictures have alpha: an object over nothing, fitted in its box".to_string(),
        ),
        SpaceChoice::Auto => (
            SpaceChoice::Contracted,
            "the training pictures have no alpha: their background is real, so all of space is modelled, contracted around the region the cameras look at".to_string(),
        ),
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
        let pieces = march_ray(&c, [0.0; 3], [1.0, 0.0, 0.0], step);
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
        let pieces = march_ray(&c, [0.0; 3], [0.0, 0.0, -1.0], 0.02);
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
}
