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
use serde_json::{Map, Value};

use fogray_ops::limits::{self, Bytes, GridShape};

use crate::error::FitError;
use crate::space::{FieldSpace, Framing, SpaceChoice};

/// Which implementation of the grid lookup, the activation and the composite a step records.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum Method {
    /// The fused ops (one record each, hand-written backwards).
    Fused,
    /// Their taped twins (built from tape primitives).
    Taped,
}

/// Where samples go along each ray.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum Sampling {
    /// Every half voxel across the box.
    Uniform,
    /// Every half voxel, but only in the cells of an occupancy grid (one cell per voxel) that
    /// the current density marks as occupied, refreshed every few steps.
    Occupancy,
}

/// Which radiance field a fit trains.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum ModelKind {
    /// Every node of the grid stored ([`DenseGrid`](crate::dense::DenseGrid)): small scenes.
    Dense,
    /// Only the nodes near what the occupancy grid finds, pruned at each growth
    /// ([`SparseGrid`](crate::sparse::SparseGrid)): memory follows the scene.
    Sparse,
    /// 3-D Gaussians composited by projection onto the image, densified where the picture
    /// needs them ([`SplatModel`](crate::splats::SplatModel)).
    Splats,
}

impl ModelKind {
    /// `dense`, `sparse` or `splats`.
    pub fn name(self) -> &'static str {
        match self {
            ModelKind::Dense => "dense",
            ModelKind::Sparse => "sparse",
            ModelKind::Splats => "splats",
        }
    }
}

/// The floating-point type of a model and its render.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum Precision {
    /// 32-bit floats.
    F32,
    /// 64-bit floats.
    F64,
}

impl Precision {
    /// `f32` or `f64`.
    pub fn name(self) -> &'static str {
        match self {
            Precision::F32 => "f32",
            Precision::F64 => "f64",
        }
    }

    /// The precision of `F` (`f32` or `f64`, the two [`Float`](fogray_tape::Float) types).
    pub fn of<F: fogray_tape::Float>() -> Precision {
        if std::mem::size_of::<F>() == 4 {
            Precision::F32
        } else {
            Precision::F64
        }
    }
}

impl Method {
    /// `fused` or `taped`.
    pub fn name(self) -> &'static str {
        match self {
            Method::Fused => "fused",
            Method::Taped => "taped",
        }
    }
}

impl Sampling {
    /// `uniform` or `occupancy`.
    pub fn name(self) -> &'static str {
        match self {
            Sampling::Uniform => "uniform",
            Sampling::Occupancy => "occupancy",
        }
    }
}

/// The box a model covers: `min` to `max` on each axis (world units).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SceneBox {
    /// The lower corner.
    pub min: [f64; 3],
    /// The upper corner.
    pub max: [f64; 3],
}

impl SceneBox {
    /// `[-1, 1]^3`, the box of a model whose settings name none.
    pub const UNIT: SceneBox = SceneBox {
        min: [-1.0; 3],
        max: [1.0; 3],
    };

    /// The cube `[-half, half]^3`.
    pub fn cube(half: f64) -> SceneBox {
        SceneBox {
            min: [-half; 3],
            max: [half; 3],
        }
    }

    /// Half the spacing of a lattice of `nodes` per axis along the box's shortest side: the
    /// sample step that resolves a grid over the box (`1 / (nodes - 1)` for `[-1, 1]^3`).
    pub fn half_node_spacing(&self, nodes: usize) -> f64 {
        let side = (0..3).map(|a| self.max[a] - self.min[a]).fold(f64::INFINITY, f64::min);
        side / (2 * (nodes - 1)) as f64
    }

    /// Errors: [`FitError::Config`] for a bound that is not finite or an axis whose minimum is
    /// not below its maximum.
    pub fn check(&self) -> Result<(), FitError> {
        for a in 0..3 {
            let (lo, hi) = (self.min[a], self.max[a]);
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(FitError::Config(format!(
                    "--box: axis {a} runs from {lo} to {hi} (must be finite and increasing)"
                )));
            }
        }
        Ok(())
    }
}

impl std::fmt::Display for SceneBox {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let [a, b, c] = self.min;
        let [d, e, g] = self.max;
        write!(f, "{a},{b},{c},{d},{e},{g}")
    }
}

impl std::str::FromStr for SceneBox {
    type Err = String;

    /// `H` for the cube `[-H, H]^3`, or `x0,y0,z0,x1,y1,z1` for the lower and upper corners.
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let values = text
            .split(',')
            .map(|v| v.trim().parse::<f64>().map_err(|e| format!("{v:?}: {e}")))
            .collect::<Result<Vec<_>, _>>()?;
        let scene_box = match values[..] {
            [h] => SceneBox::cube(h),
            [a, b, c, d, e, g] => SceneBox {
                min: [a, b, c],
                max: [d, e, g],
            },
            _ => return Err(format!("{text:?}: give H (the cube [-H, H]^3) or x0,y0,z0,x1,y1,z1")),
        };
        scene_box.check().map_err(|e| e.to_string())?;
        Ok(scene_box)
    }
}

/// When training stops.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Budget {
    /// After this many steps.
    Steps(usize),
    /// Once this many seconds of training (evaluations excluded) have passed.
    Seconds(f64),
}

/// Training seconds when neither `steps` nor `seconds` is set.
pub const DEFAULT_SECONDS: f64 = 60.0;

/// The longest training budget accepted, in seconds: one week (a longer one is a typo or a
/// budget meant never to end).
pub const MAX_SECONDS: f64 = 7.0 * 24.0 * 3600.0;

/// The most training steps accepted: a hundred million (more than a week of the fastest
/// steps; a larger count is a typo or a budget meant never to end).
pub const MAX_STEPS: usize = 100_000_000;

/// The most held-out evaluations accepted. Each renders every held-out view, off the training
/// clock, so a budget of seconds with more evaluations than it has time for
/// evaluates after every step and never ends in the time asked; the curves of a report need
/// far fewer points.
pub const MAX_EVALUATIONS: usize = 10_000;

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
    #[cfg_attr(feature = "cli", arg(long = "tv", value_name = "WEIGHT", default_value_t = FitSettings::DEFAULT.smoothness))]
    pub smoothness: f64,
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
        smoothness: 1.5e-4,
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
    /// - `smoothness` (`--tv`): none: tens of views constrain a scene enough, and the prior
    ///   costs a step as much as the lookup's backward without buying held-out PSNR;
    /// - `lr`, `lr_final`: twice the library's: tens of photographs seen through a sparse grid
    ///   with view-dependent colour gain held-out PSNR step for step at this rate, and no more
    ///   above it (the library's rate suits the grid example's hundreds of rays a pixel);
    /// - `distortion`: a little of mip-NeRF 360's loss pulls each ray's weights onto its
    ///   surface, which clears the haze a photograph cannot tell from a sheet; ten times more
    ///   costs PSNR;
    /// - `space`: decided from the data ([`crate::space::resolve`]).
    pub const RECOMMENDED: FitSettings = FitSettings {
        grid: 128,
        model: ModelKind::Sparse,
        sh_degree: 1,
        smoothness: 0.0,
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
    pub fn field_space(&self) -> Result<FieldSpace, FitError> {
        match (self.space, self.framing) {
            (SpaceChoice::Contracted, Some(framing)) => Ok(FieldSpace::Contracted(framing.contraction()?)),
            (SpaceChoice::Contracted, None) => Err(FitError::Config(
                "--space contracted needs an inner region (framed from the cameras by fogray fit)".into(),
            )),
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

    /// Checks every setting's range, the budget against [`MAX_SECONDS`] and [`MAX_STEPS`], the
    /// evaluations against [`MAX_EVALUATIONS`], and the grid and batch against the machine's
    /// memory ([`FitSettings::check_memory`]).
    ///
    /// Errors: [`FitError::Config`] naming the flag, [`FitError::TooLarge`] naming the flag and
    /// the bytes it would need.
    pub fn check(&self) -> Result<(), FitError> {
        let bad = |what: &str| Err(FitError::Config(what.into()));
        if self.grid < 2 {
            return bad("--grid must be at least 2");
        }
        if self.batch == 0 {
            return bad("--batch must be at least 1");
        }
        if !(self.lr.is_finite() && self.lr > 0.0) {
            return bad("--lr must be finite and positive");
        }
        if !(self.lr_final.is_finite() && self.lr_final > 0.0) {
            return bad("--lr-final must be finite and positive");
        }
        if !(self.smoothness.is_finite() && self.smoothness >= 0.0) {
            return bad("--tv must be finite and non-negative");
        }
        if !self.shift.is_finite() {
            return bad("--shift must be finite");
        }
        if !(self.distortion.is_finite() && self.distortion >= 0.0) {
            return bad("--distortion must be finite and non-negative");
        }
        if self.sh_degree > 3 {
            return bad("--sh-degree must be 0, 1, 2 or 3");
        }
        if self.background_degree > 3 {
            return bad("--background-degree must be 0, 1, 2 or 3");
        }
        if let Some(b) = self.scene_box {
            b.check()?;
        }
        if self.evaluations > MAX_EVALUATIONS {
            return Err(FitError::Config(format!(
                "--evaluations {}: at most {MAX_EVALUATIONS} (each renders every held-out view)",
                self.evaluations
            )));
        }
        match self.budget() {
            Budget::Steps(0) => return bad("--steps must be at least 1"),
            Budget::Steps(n) if n > MAX_STEPS => {
                return Err(FitError::Config(format!(
                    "--steps {n}: at most {MAX_STEPS} (a budget that can end)"
                )))
            }
            Budget::Seconds(s) if !(s.is_finite() && s > 0.0) => return bad("--seconds must be finite and positive"),
            Budget::Seconds(s) if s > MAX_SECONDS => {
                // Rust writes a large float in all its digits: 1e308 as 309 of them.
                let s = if s < 1e9 { s.to_string() } else { format!("{s:e}") };
                return Err(FitError::Config(format!(
                    "--seconds {s}: at most {MAX_SECONDS} (one week; a budget that can end)"
                )));
            }
            _ => {}
        }
        self.check_memory(limits::available())
    }

    /// Checks that the grid (at its last stage, with the stage before it while it grows) and
    /// a step's batch fit in `available` bytes, as [`limits`] counts them: a sparse grid as if
    /// it kept every node, as it may.
    ///
    /// Errors: [`FitError::TooLarge`] naming the flag and the bytes it would need.
    pub fn check_memory(&self, available: Bytes) -> Result<(), FitError> {
        let shape = |nodes| GridShape {
            nodes,
            channels: limits::grid_channels(self.sh_degree),
            float_bytes: match self.precision {
                Precision::F32 => 4,
                Precision::F64 => 8,
            },
        };
        let model_bytes = |nodes| match self.model {
            ModelKind::Dense => shape(nodes).dense_bytes(),
            ModelKind::Sparse => shape(nodes).sparse_bytes(),
            // No grid: splats are counted where they are made (`splats::check_count`).
            ModelKind::Splats => Bytes(0),
        };
        let stages = crate::schedule::growth_stages(self);
        // A growth builds the finer grid while the coarser one still exists.
        let grid = stages
            .iter()
            .rev()
            .take(2)
            .fold(Bytes(0), |sum, &(_, nodes)| sum.plus(model_bytes(nodes)));
        let kind = format!(
            "the {} grid ({}, {} channels a node)",
            self.model.name(),
            self.precision.name(),
            shape(self.grid).channels
        );
        Bytes::check(grid, available, &format!("--grid {}", self.grid), &kind)?;
        let batch = shape(self.grid).training_ray_bytes().times(self.batch as u64);
        let rays = format!("a step's rays at --grid {}", self.grid);
        Bytes::check(batch, available, &format!("--batch {}", self.batch), &rays)?;
        let what = format!("--grid {} with --batch {}", self.grid, self.batch);
        Bytes::check(grid.plus(batch), available, &what, "the grid and a step's rays")?;
        Ok(())
    }

    /// A resumed fit's settings: `saved`'s, except the fields `given` names (by field name, as
    /// clap's argument ids are), which are `self`'s. `steps` and `seconds` are one setting, the
    /// budget: giving either replaces both.
    ///
    /// Errors: [`FitError::Config`] if the settings cannot be merged (not expected for two
    /// values of this type).
    pub fn given_over(&self, saved: &FitSettings, given: &dyn Fn(&str) -> bool) -> Result<FitSettings, FitError> {
        let as_map = |s: &FitSettings| match serde_json::to_value(s) {
            Ok(Value::Object(map)) => Ok(map),
            other => Err(FitError::Config(format!("settings as JSON: {other:?}"))),
        };
        let (flags, mut merged): (Map<String, Value>, Map<String, Value>) = (as_map(self)?, as_map(saved)?);
        let budget_given = given("steps") || given("seconds");
        for (key, value) in flags {
            let budget = key == "steps" || key == "seconds";
            if (budget && budget_given) || (!budget && given(&key)) {
                merged.insert(key, value);
            }
        }
        serde_json::from_value(Value::Object(merged)).map_err(|e| FitError::Config(e.to_string()))
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_long_budget_of_seconds_grows_to_the_finer_lattice() {
        let long = FitSettings::LONG_FIT_SECONDS;
        assert_eq!(FitSettings::recommended_grid(Budget::Seconds(60.0)), 128);
        assert_eq!(FitSettings::recommended_grid(Budget::Seconds(long - 1e-9)), 128);
        assert_eq!(FitSettings::recommended_grid(Budget::Seconds(long)), 192);
        assert_eq!(FitSettings::recommended_grid(Budget::Seconds(300.0)), 192);
        // Steps say nothing of time.
        assert_eq!(FitSettings::recommended_grid(Budget::Steps(1_000_000)), 128);
        assert!(FitSettings::RECOMMENDED.check().is_ok());
    }

    #[test]
    fn given_flags_win_over_the_saved_settings_and_the_rest_is_saved() {
        let saved = FitSettings {
            grid: 32,
            lr: 0.5,
            steps: Some(100),
            ..FitSettings::DEFAULT
        };
        let flags = FitSettings {
            lr: 0.1,
            seconds: Some(5.0),
            grid: 64,
            ..FitSettings::DEFAULT
        };
        let merged = flags.given_over(&saved, &|id| id == "lr" || id == "seconds").unwrap();
        assert_eq!(merged.lr, 0.1);
        assert_eq!(merged.grid, 32);
        // The budget is one setting: --seconds clears the saved --steps.
        assert_eq!(merged.budget(), Budget::Seconds(5.0));
        let untouched = flags.given_over(&saved, &|_| false).unwrap();
        assert_eq!(untouched, saved);
    }

    #[test]
    fn settings_written_before_the_background_degree_read_degree_2() {
        const { assert!(FitSettings::DEFAULT.background_degree == 3) };
        let old: FitSettings = serde_json::from_str(r#"{"grid": 32, "learn_background": true}"#).unwrap();
        assert_eq!(old.background_degree, 2);
        let text = serde_json::to_string(&FitSettings::DEFAULT).unwrap();
        assert_eq!(serde_json::from_str::<FitSettings>(&text).unwrap().background_degree, 3);
        let four = FitSettings {
            background_degree: 4,
            ..FitSettings::DEFAULT
        };
        assert!(four.check().unwrap_err().to_string().contains("--background-degree"));
    }

    #[test]
    fn settings_written_before_random_backgrounds_read_them_off() {
        const { assert!(FitSettings::DEFAULT.random_background) };
        let old: FitSettings = serde_json::from_str(r#"{"grid": 32}"#).unwrap();
        assert!(!old.random_background);
        assert_eq!(
            FitSettings {
                random_background: true,
                // The other field that settings this old read otherwise (see above).
                background_degree: FitSettings::DEFAULT.background_degree,
                ..old
            },
            FitSettings {
                grid: 32,
                ..FitSettings::DEFAULT
            }
        );
        let text = serde_json::to_string(&FitSettings::DEFAULT).unwrap();
        assert!(serde_json::from_str::<FitSettings>(&text).unwrap().random_background);
    }

    #[test]
    fn every_setting_is_checked() {
        let ok = FitSettings::DEFAULT;
        assert!(ok.check().is_ok());
        for (bad, flag) in [
            (FitSettings { grid: 1, ..ok }, "--grid"),
            (FitSettings { batch: 0, ..ok }, "--batch"),
            (FitSettings { lr: f64::NAN, ..ok }, "--lr"),
            (FitSettings { lr_final: 0.0, ..ok }, "--lr-final"),
            (FitSettings { smoothness: -1.0, ..ok }, "--tv"),
            (
                FitSettings {
                    shift: f64::INFINITY,
                    ..ok
                },
                "--shift",
            ),
            (FitSettings { steps: Some(0), ..ok }, "--steps"),
            (
                FitSettings {
                    evaluations: MAX_EVALUATIONS + 1,
                    ..ok
                },
                "--evaluations",
            ),
            (
                FitSettings {
                    seconds: Some(-1.0),
                    ..ok
                },
                "--seconds",
            ),
        ] {
            let e = bad.check().unwrap_err().to_string();
            assert!(e.starts_with(flag), "{e}");
        }
    }
}
