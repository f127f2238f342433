//! The fit's settings: one struct that is the command line's flags (with the `cli` feature),
//! the checkpoint's metadata and what a resumed fit starts from. Adding a hyperparameter is one
//! field here, with its default in [`FitSettings::DEFAULT`].
//!
//! ```
//! use fogray_fit::settings::{Budget, FitSettings, Method};
//!
//! let settings = FitSettings { steps: Some(300), method: Method::Taped, ..FitSettings::default() };
//! assert_eq!(settings.budget(), Budget::Steps(300));
//! let text = serde_json::to_string(&settings)?;
//! assert_eq!(serde_json::from_str::<FitSettings>(&text)?, settings);
//! // A file written before a setting existed reads that setting's default.
//! let old: FitSettings = serde_json::from_str(r#"{"grid": 32}"#)?;
//! assert_eq!((old.grid, old.lr), (32, FitSettings::DEFAULT.lr));
//! # Ok::<(), serde_json::Error>(())
//! ```

use serde::{Deserialize, Serialize};

use crate::error::FitError;
use crate::space::{FieldSpace, Framing, SpaceChoice};

mod check;
mod kinds;
#[cfg(test)]
mod limits_tests;
mod scene_box;
#[cfg(test)]
mod tests;

pub use kinds::{Method, ModelKind, Precision, Sampling};
pub use scene_box::SceneBox;

/// When training stops.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Budget {
    /// After this many steps.
    Steps(usize),
    /// Once this many seconds of training (evaluations excluded) have passed.
    Seconds(f64),
}

/// Training seconds when neither `steps` nor `seconds` is set.
pub(crate) const DEFAULT_SECONDS: f64 = 60.0;

/// The longest training budget accepted, in seconds: one week (a longer one is a typo or a
/// budget meant never to end).
pub(crate) const MAX_SECONDS: f64 = 7.0 * 24.0 * 3600.0;

/// The most training steps accepted: a hundred million (more than a week of the fastest
/// steps; a larger count is a typo or a budget meant never to end).
pub const MAX_STEPS: usize = 100_000_000;

/// The most held-out evaluations accepted. Each renders every held-out view, off the training
/// clock, so a budget of seconds with more evaluations than it has time for
/// evaluates after every step and never ends in the time asked; the curves of a report need
/// far fewer points.
pub(crate) const MAX_EVALUATIONS: usize = 10_000;

/// Everything a fit is configured by (see the [module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct FitSettings {
    /// Nodes per axis of the grid (of its last growth stage).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = FitSettings::DEFAULT.grid))]
    pub grid: usize,
    /// Training seconds (evaluations excluded); 60 unless --steps is given.
    #[cfg_attr(feature = "cli", arg(long, conflicts_with = "steps", allow_negative_numbers = true))]
    pub seconds: Option<f64>,
    /// Training steps instead of seconds.
    #[cfg_attr(feature = "cli", arg(long))]
    pub steps: Option<usize>,
    /// Training rays per step.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = FitSettings::DEFAULT.batch))]
    pub batch: usize,
    /// Seed of the batches.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = FitSettings::DEFAULT.seed))]
    pub seed: u64,
    /// Fused ops or their taped twins.
    #[cfg_attr(feature = "cli", arg(long, value_enum, default_value_t = FitSettings::DEFAULT.method))]
    pub method: Method,
    /// Floating-point type of the model and the render.
    #[cfg_attr(feature = "cli", arg(long, value_enum, default_value_t = FitSettings::DEFAULT.precision))]
    pub precision: Precision,
    /// Samples every half voxel across the box, or only in the cells an occupancy grid marks
    /// occupied (test views are then rendered with it too).
    #[cfg_attr(feature = "cli", arg(long, value_enum, default_value_t = FitSettings::DEFAULT.sampling))]
    pub sampling: Sampling,
    /// Adam's learning rate, until 60 % of the budget.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = FitSettings::DEFAULT.lr))]
    pub lr: f64,
    /// Adam's learning rate at the end: from 60 % of the budget on it falls geometrically
    /// from --lr to this (pass the --lr value for a constant rate).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = FitSettings::DEFAULT.lr_final))]
    pub lr_final: f64,
    /// Weight of the total-variation prior on the raw grid (the mean squared difference of
    /// neighbouring nodes) added to the loss; 0 for none.
    // Checkpoints written before the field took its flag's name call it `smoothness`.
    #[serde(alias = "smoothness")]
    #[cfg_attr(feature = "cli", arg(long, value_name = "WEIGHT", default_value_t = FitSettings::DEFAULT.tv))]
    pub tv: f64,
    /// Train the full grid from the start instead of growing it coarse to fine (a quarter of
    /// --grid nodes per axis, doubled at 10 % and 30 % of the budget).
    #[cfg_attr(feature = "cli", arg(long = "no-grow", action = clap::ArgAction::SetFalse))]
    pub grow: bool,
    /// The density's shift: raw 0 is density softplus(shift), the fresh grid's thin fog.
    #[cfg_attr(feature = "cli", arg(long, allow_negative_numbers = true, default_value_t = FitSettings::DEFAULT.shift))]
    pub shift: f64,
    /// Test evaluations, evenly spaced over the budget (plus one at the start and the end);
    /// at most one a step, and a count beyond what a report can use is refused.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = FitSettings::DEFAULT.evaluations))]
    pub evaluations: usize,
    /// Degree of the spherical harmonics of the colour, 0 to 3 (0: the same colour from every
    /// direction; 1 to 3: 3 (degree + 1)^2 coefficients a node).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = FitSettings::DEFAULT.sh_degree))]
    pub sh_degree: usize,
    /// For training views with an alpha channel: composite each training ray over its own
    /// random colour, uniform in [0, 1]^3 and drawn afresh every step, against the picture
    /// composited over the same colour, so that the model cannot paint the background into
    /// the scene (held-out views are still rendered over the dataset's background). No effect
    /// on views without alpha. A file written before this setting existed reads false.
    #[cfg_attr(
        feature = "cli",
        arg(long, value_name = "BOOL", num_args = 0..=1, default_missing_value = "true",
            action = clap::ArgAction::Set, default_value_t = FitSettings::DEFAULT.random_background)
    )]
    #[serde(default = "trained_without_random_background")]
    pub random_background: bool,
    /// The box the model covers: H for [-H, H]^3, or x0,y0,z0,x1,y1,z1; the data's own box
    /// when not given ([-1, 1]^3 for data that names none).
    #[cfg_attr(
        feature = "cli",
        arg(long = "box", value_name = "BOX", allow_negative_numbers = true)
    )]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scene_box: Option<SceneBox>,
    /// Weight of the distortion loss (mip-NeRF 360's: it pulls each ray's weights together,
    /// against floaters and haze) added to the training objective; 0 for none.
    #[cfg_attr(feature = "cli", arg(long, value_name = "WEIGHT", default_value_t = FitSettings::DEFAULT.distortion))]
    pub distortion: f64,
    /// The model: a dense grid, a sparse one pruned to the occupied space at each growth, or
    /// 3-D Gaussian splats.
    #[cfg_attr(feature = "cli", arg(long, value_enum, default_value_t = FitSettings::DEFAULT.model))]
    pub model: ModelKind,
    /// For captures without alpha (photographs whose background lies beyond the box): learn
    /// the background, a colour that depends on the view direction (spherical harmonics of
    /// --background-degree), in place of the dataset's fixed background colour; renders use
    /// it too. Views with alpha are trained over random colours instead (--random-background).
    #[cfg_attr(feature = "cli", arg(long))]
    pub learn_background: bool,
    /// The degree of the learned background's spherical harmonics, 0 to 3 (3 (degree + 1)^2
    /// values; 0 is one colour from every direction). Used with --learn-background.
    #[cfg_attr(feature = "cli", arg(long, value_name = "DEGREE", default_value_t = FitSettings::DEFAULT.background_degree))]
    #[serde(default = "background_of_degree_2")]
    pub background_degree: usize,
    /// Where the field lives: `auto` decides from the data (the box for pictures with alpha,
    /// all of space contracted around what the cameras look at for pictures without), `box`
    /// the scene box (--box, or the dataset's, e.g. instant-ngp's aabb_scale), `contracted`
    /// all of space. A file written before this setting existed reads `box`.
    #[cfg_attr(feature = "cli", arg(long, value_enum, default_value_t = FitSettings::DEFAULT.space))]
    #[serde(default = "fitted_in_a_box")]
    pub space: SpaceChoice,
    /// The inner region of a contracted space; framed from the training cameras when not
    /// given (a checkpoint keeps the one its fit used).
    #[cfg_attr(feature = "cli", arg(skip))]
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub framing: Option<Framing>,
}

impl FitSettings {
    /// The defaults: a 64^3 grid grown coarse to fine, 8192 rays a step for 60 s, fused ops,
    /// occupancy sampling, f32, a random background per training ray for views with alpha.
    pub const DEFAULT: FitSettings = FitSettings {
        grid: 64,
        seconds: None,
        steps: None,
        batch: 8192,
        seed: 0,
        method: Method::Fused,
        precision: Precision::F32,
        sampling: Sampling::Occupancy,
        lr: 0.2,
        lr_final: 0.02,
        tv: 1.5e-4,
        grow: true,
        shift: -4.0,
        evaluations: 20,
        sh_degree: 0,
        random_background: true,
        scene_box: None,
        model: ModelKind::Dense,
        distortion: 0.0,
        learn_background: false,
        background_degree: 3,
        space: SpaceChoice::Box,
        framing: None,
    };

    /// What `fogray fit` trains unless a flag says otherwise: [`FitSettings::DEFAULT`] with
    /// the choices a dataset of real photographs is fitted best with, each measured on lego at
    /// equal steps or seconds (reports/lego/report.md):
    /// - `model`: the sparse grid: a real scene fills a small part of its box, and the sparse
    ///   grid keeps only that part;
    /// - `grid`: 128 nodes per axis (32, 64, then 128), the finest a minute's fit on two cores
    ///   still trains well; [`FitSettings::recommended_grid`] for long budgets;
    /// - `sh_degree`: 1: real objects shine, and degree 1 buys more on held-out views than
    ///   its cost per step takes;
    /// - `tv`: none: tens of views constrain a scene enough, and the prior
    ///   costs a step as much as the lookup's backward without buying held-out PSNR;
    /// - `lr`, `lr_final`: twice the library's: tens of photographs seen through a sparse grid
    ///   with view-dependent colour gain held-out PSNR step for step at this rate, and no more
    ///   above it (the library's rate suits the grid example's hundreds of rays a pixel);
    /// - `distortion`: a little of mip-NeRF 360's loss pulls each ray's weights onto its
    ///   surface, which clears the haze a photograph cannot tell from a sheet; ten times more
    ///   costs PSNR;
    /// - `space`: decided from the data ([`SpaceChoice::Auto`]).
    pub const RECOMMENDED: FitSettings = FitSettings {
        grid: 128,
        model: ModelKind::Sparse,
        sh_degree: 1,
        tv: 0.0,
        lr: 0.4,
        lr_final: 0.04,
        distortion: 0.01,
        space: SpaceChoice::Auto,
        ..FitSettings::DEFAULT
    };

    /// The lattice of a long recommended fit (48, 96, then 192): its finer nodes cost a step
    /// twice as much, which a long budget pays back in held-out PSNR and a short one does not.
    pub const RECOMMENDED_GRID_LONG: usize = 192;

    /// The training seconds from which [`FitSettings::RECOMMENDED_GRID_LONG`] is the
    /// recommended lattice.
    pub const LONG_FIT_SECONDS: f64 = 150.0;

    /// The recommended lattice for a fit of `budget`: [`FitSettings::RECOMMENDED_GRID_LONG`]
    /// for a budget of [`FitSettings::LONG_FIT_SECONDS`] or more, else the grid of
    /// [`FitSettings::RECOMMENDED`] (a budget of steps says nothing of time).
    pub fn recommended_grid(budget: Budget) -> usize {
        match budget {
            Budget::Seconds(s) if s >= FitSettings::LONG_FIT_SECONDS => FitSettings::RECOMMENDED_GRID_LONG,
            _ => FitSettings::RECOMMENDED.grid,
        }
    }

    /// The box the model's grid covers: the contracted cube `[-2, 2]^3` in a contracted
    /// space, else `scene_box`, else [`SceneBox::UNIT`].
    pub fn model_box(&self) -> SceneBox {
        match self.space {
            SpaceChoice::Contracted => SceneBox::cube(fogray_ops::space::CONTRACTED_HALF_WIDTH),
            _ => self.scene_box.unwrap_or(SceneBox::UNIT),
        }
    }

    /// The space the model samples in: the contracted one around `framing` for a contracted
    /// space, else the model's box (`auto`, not yet decided from data, is the box).
    ///
    /// Errors: a contracted space without a framing, or a framing that is not finite and
    /// positive.
    pub(crate) fn field_space(&self) -> Result<FieldSpace, FitError> {
        match (self.space, self.framing) {
            (SpaceChoice::Contracted, Some(framing)) => Ok(FieldSpace::Contracted(framing.contraction()?)),
            (SpaceChoice::Contracted, None) => Err(FitError::Setting {
                flag: "--space",
                value: None,
                rule: "contracted needs an inner region (framed from the cameras by fogray fit)".into(),
            }),
            _ => {
                let b = self.model_box();
                Ok(FieldSpace::Box(fogray_ops::rays::Aabb::new(b.min, b.max)?))
            }
        }
    }

    /// `steps` if set, else `seconds` (60 if neither).
    pub fn budget(&self) -> Budget {
        match (self.steps, self.seconds) {
            (Some(n), _) => Budget::Steps(n),
            (None, s) => Budget::Seconds(s.unwrap_or(DEFAULT_SECONDS)),
        }
    }

    /// Sets the budget (`steps` or `seconds`, the other cleared).
    pub fn with_budget(mut self, budget: Budget) -> Self {
        (self.steps, self.seconds) = match budget {
            Budget::Steps(n) => (Some(n), None),
            Budget::Seconds(s) => (None, Some(s)),
        };
        self
    }
}

/// `random_background` of settings written before it existed: their fits trained over the
/// dataset's background.
fn trained_without_random_background() -> bool {
    false
}

/// `space` of settings written before it existed: their fits were in a box.
fn fitted_in_a_box() -> SpaceChoice {
    SpaceChoice::Box
}

/// `background_degree` of settings written before it existed: their learned backgrounds were
/// of degree 2 (and their checkpoints hold that many coefficients).
fn background_of_degree_2() -> usize {
    2
}

impl Default for FitSettings {
    fn default() -> Self {
        FitSettings::DEFAULT
    }
}
