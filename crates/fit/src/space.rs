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
use fogray_ops::sample::{ContractedSampler, Jitter, OccupancyGrid, PackedSamples};
use fogray_ops::space::{framing_from_cameras, Contraction, InnerRegion};
use fogray_tape::Float;
use fogray_tape::Offsets;
use ndarray::{Array1, Array2};
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
    /// up), and its length and depth are measured in contracted units too: the `k`-th piece of
    /// a ray has length `step` and depth `(k + 1/2) step`, so that the field's density is per
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
            FieldSpace::Contracted(contraction) => {
                let sampler = ContractedSampler::new(*contraction, step)?;
                let near = vec![0.0; rays.len()];
                let all = sampler.sample(rays, &near, Jitter::None, None)?;
                Ok(in_contracted_units(all, occupancy, step))
            }
        }
    }

}

/// `all` (every piece of each ray, in order, of contracted length `step`) with lengths and
/// depths in contracted units ([`FieldSpace::sample`]), keeping only the samples whose
/// contracted position lies in an occupied cell of `occupancy` if given.
fn in_contracted_units<F: Float>(all: PackedSamples<F>, occupancy: Option<&OccupancyGrid>, step: f64) -> PackedSamples<F> {
    let mut lengths = Vec::with_capacity(all.rays());
    let mut kept = Vec::with_capacity(all.len());
    for r in 0..all.rays() {
        let range = all.range(r).unwrap_or(0..0);
        let start = range.start;
        let before = kept.len();
        for k in range {
            let p = all.positions.row(k);
            let occupied = occupancy.is_none_or(|g| g.is_occupied_at([p[0].as_f64(), p[1].as_f64(), p[2].as_f64()]));
            if occupied {
                kept.push((k, k - start));
            }
        }
        lengths.push(kept.len() - before);
    }
    let positions = Array2::from_shape_fn((kept.len(), 3), |(i, a)| all.positions[[kept[i].0, a]]);
    let t = Array1::from_iter(kept.iter().map(|&(_, j)| F::lit((j as f64 + 0.5) * step)));
    let delta = Array1::from_elem(kept.len(), F::lit(step));
    let ray = kept.iter().map(|&(k, _)| all.ray[k]).collect();
    PackedSamples {
        positions,
        t,
        delta,
        offsets: Offsets::from_lengths(lengths),
        ray,
    }
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
