//! A fit saved to a file and read back: the model, Adam's state and what is needed to continue
//! the fit, as [safetensors](https://huggingface.co/docs/safetensors) (which numpy, PyTorch and
//! others open).
//!
//! Tensors, little-endian `F32` or `F64` as the fit was trained:
//! - `grid`: the raw grid `[N, N, N, 4]` (raw density, raw RGB per node);
//! - `adam.first_moment`, `adam.second_moment`: Adam's moments, the grid's shape (absent before
//!   the growth stage's first step);
//! - with occupancy sampling, `occupancy.estimate` (`F32`, `[R, R, R]` with `R = grid - 1`, the
//!   occupancy grid's density estimates) and `occupancy.occupied` (`BOOL`, the same shape).
//!
//! Metadata (strings): `format` (`fogray-grid model`), `version` (`1`), `precision`, `nodes`
//! (the grid's, `N`), `step`, `seconds` (training seconds so far), `stage` (growth stage),
//! `batch_stream` (words of the ChaCha12 batch generator used), `adam.updates`, the fit's
//! settings (`grid`, `batch`, `budget` as `steps:N` or `seconds:S`, `method`, `sampling`,
//! `seed`, `lr`, `lr_final`, `shift`, `evaluations`, `grow`, `smoothness`), the cameras (`views`, `test_views`, `size`)
//! and the scene as JSON (`scene`). Numbers are written so that they read back bit for bit.
//!
//! ```
//! use fogray_grid::checkpoint::{load, save, Cameras, Precision, SavedFit};
//! use fogray_grid::fit::FitConfig;
//! use fogray_grid::model::GridModel;
//! use fogray_grid::state::TrainingState;
//! use fogray_grid::scene::Scene;
//!
//! let model = GridModel::<f32>::new(4, -4.0)?;
//! let training = TrainingState { step: 0, seconds: 0.0, stage: 0, batch_stream: 0, adam: None, occupancy: None };
//! let fit = SavedFit {
//!     precision: Precision::F32,
//!     config: FitConfig { grid: 4, ..FitConfig::default() },
//!     cameras: Cameras { views: 8, test_views: 2, size: 16 },
//!     scene: Scene::default(),
//! };
//! let file = std::env::temp_dir().join(format!("checkpoint-doc-{}.safetensors", std::process::id()));
//! save(&file, &model, &training, &fit)?;
//! let back = load::<f32>(&file)?;
//! assert_eq!(back.start.training, training);
//! assert_eq!(back.fit, fit);
//! # std::fs::remove_file(&file)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use fogray::ops::sample::OccupancyState;
use fogray::tape::optim::{Adam, AdamConfig, AdamState};
use fogray::tape::Float;
use ndarray::{Array3, ArrayD, ArrayViewD, IxDyn};
use safetensors::tensor::{Dtype, TensorView};
use safetensors::SafeTensors;
use thiserror::Error;

use crate::fit::{Budget, FitConfig, Sampling};
use crate::model::CHANNELS;
use crate::model::{GridModel, Method};
use crate::ring::Ring;
use crate::scene::Scene;
use crate::state::{Start, TrainingState};

/// The `format` of the metadata.
pub const FORMAT: &str = "fogray-grid model";
/// The `version` of the metadata this module writes and reads.
pub const VERSION: &str = "1";

/// Why a model file could not be written, read or used.
#[non_exhaustive]
#[derive(Debug, Clone, PartialEq, Error)]
pub enum CheckpointError {
    /// The file could not be read.
    #[error("cannot read {path}: {message}")]
    Read {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// The file could not be written.
    #[error("cannot write {path}: {message}")]
    Write {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// The file is not a model this module wrote (not safetensors, a tensor or a metadata
    /// entry missing or out of range, a non-finite value).
    #[error("{path} is not a valid fogray-grid model: {message}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The file's model disagrees with what the caller asked for (its precision, its grid).
    #[error("{path} holds a model with {setting} {file}, but {setting} {asked} was asked for")]
    Mismatch {
        /// The file.
        path: PathBuf,
        /// Which setting (`--precision`, `--grid`).
        setting: &'static str,
        /// The file's value.
        file: String,
        /// The value asked for.
        asked: String,
    },
}

/// The floating-point type of a model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Precision {
    /// `f32`.
    F32,
    /// `f64`.
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

    /// The precision of `F` (`f32` or `f64`, the two [`Float`] types).
    pub fn of<F: Float>() -> Precision {
        if std::mem::size_of::<F>() == 4 {
            Precision::F32
        } else {
            Precision::F64
        }
    }

    fn dtype(self) -> Dtype {
        match self {
            Precision::F32 => Dtype::F32,
            Precision::F64 => Dtype::F64,
        }
    }
}

/// What the file says about the fit beside its state: its settings, cameras and scene.
#[derive(Debug, Clone, PartialEq)]
pub struct SavedFit {
    /// The model's floating-point type.
    pub precision: Precision,
    /// The fit's settings (the budget is the one it ran with).
    pub config: FitConfig,
    /// The cameras it was fitted with.
    pub cameras: Cameras,
    /// The scene it was fitted to.
    pub scene: Scene,
}

/// The settings of a [`Ring`] of cameras.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Cameras {
    /// Training views.
    pub views: usize,
    /// Held-out test views asked for.
    pub test_views: usize,
    /// Image width and height in pixels.
    pub size: usize,
}

impl Cameras {
    /// The ring. Errors: as [`Ring::new`].
    pub fn ring(&self) -> Result<Ring, crate::ring::RingError> {
        Ring::new(self.views, self.test_views, self.size)
    }
}

/// A model file read back: the fit to continue, and its settings.
#[derive(Debug)]
pub struct Checkpoint<F: Float> {
    /// The model and the fit's state.
    pub start: Start<F>,
    /// The fit's settings, cameras and scene.
    pub fit: SavedFit,
}

/// The metadata of a model file, read without its tensors' values.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelInfo {
    /// The fit's settings, cameras and scene.
    pub fit: SavedFit,
    /// Nodes per axis of the saved grid (a growing fit's current stage).
    pub nodes: usize,
    /// Steps done.
    pub step: usize,
    /// Training seconds so far.
    pub seconds: f64,
}

impl ModelInfo {
    /// Checks that the file's model is one a fit with `precision` and `grid` nodes per axis
    /// can continue. Errors: [`CheckpointError::Mismatch`] naming the first setting that
    /// differs.
    pub fn check_matches(&self, path: &Path, precision: Precision, grid: usize) -> Result<(), CheckpointError> {
        let mismatch = |setting, file: String, asked: String| CheckpointError::Mismatch {
            path: path.to_path_buf(),
            setting,
            file,
            asked,
        };
        if self.fit.precision != precision {
            return Err(mismatch(
                "--precision",
                self.fit.precision.name().into(),
                precision.name().into(),
            ));
        }
        if self.fit.config.grid != grid {
            return Err(mismatch("--grid", self.fit.config.grid.to_string(), grid.to_string()));
        }
        Ok(())
    }
}

fn method_name(m: Method) -> &'static str {
    match m {
        Method::Fused => "fused",
        Method::Taped => "taped",
    }
}

fn sampling_name(s: Sampling) -> &'static str {
    match s {
        Sampling::Uniform => "uniform",
        Sampling::Occupancy => "occupancy",
    }
}

fn to_bytes<F: Float>(values: ArrayViewD<'_, F>) -> Vec<u8> {
    // `as_f64` widens exactly, so narrowing an `f32`'s back is exact too.
    match Precision::of::<F>() {
        Precision::F32 => values.iter().flat_map(|v| (v.as_f64() as f32).to_le_bytes()).collect(),
        Precision::F64 => values.iter().flat_map(|v| v.as_f64().to_le_bytes()).collect(),
    }
}

fn from_bytes<F: Float>(bytes: &[u8]) -> Vec<F> {
    match Precision::of::<F>() {
        Precision::F32 => bytes
            .chunks_exact(4)
            .map(|c| F::lit(f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64))
            .collect(),
        Precision::F64 => bytes
            .chunks_exact(8)
            .map(|c| F::lit(f64::from_le_bytes(c.try_into().unwrap_or([0; 8]))))
            .collect(),
    }
}

fn metadata<F: Float>(model: &GridModel<F>, training: &TrainingState<F>, fit: &SavedFit) -> HashMap<String, String> {
    let c = &fit.config;
    let mut m: Vec<(&str, String)> = vec![
        ("format", FORMAT.into()),
        ("version", VERSION.into()),
        ("precision", fit.precision.name().into()),
        ("nodes", model.nodes().to_string()),
        ("step", training.step.to_string()),
        // Rust prints a float in the fewest digits that read back to the same bits.
        ("seconds", training.seconds.to_string()),
        ("stage", training.stage.to_string()),
        ("batch_stream", training.batch_stream.to_string()),
        ("grid", c.grid.to_string()),
        ("batch", c.batch.to_string()),
        (
            "budget",
            match c.budget {
                Budget::Steps(n) => format!("steps:{n}"),
                Budget::Seconds(s) => format!("seconds:{s}"),
            },
        ),
        ("method", method_name(c.method).into()),
        ("sampling", sampling_name(c.sampling).into()),
        ("seed", c.seed.to_string()),
        ("lr", c.lr.to_string()),
        ("lr_final", c.lr_final.to_string()),
        ("shift", c.shift.to_string()),
        ("evaluations", c.evaluations.to_string()),
        ("grow", c.grow.to_string()),
        ("smoothness", c.smoothness.to_string()),
        ("views", fit.cameras.views.to_string()),
        ("test_views", fit.cameras.test_views.to_string()),
        ("size", fit.cameras.size.to_string()),
        ("scene", fit.scene.to_json_pretty()),
    ];
    if let Some(adam) = &training.adam {
        m.push(("adam.updates", adam.updates.to_string()));
    }
    m.into_iter().map(|(k, v)| (k.to_string(), v)).collect()
}

/// Writes `model` and `training` with the fit's settings `fit` to `path` (see the
/// [module docs](self) for the layout). The file is written beside `path` and renamed onto
/// it, so an existing file is replaced whole or not at all.
///
/// Errors: [`CheckpointError::Mismatch`] if `fit.precision` is not `F`'s,
/// [`CheckpointError::Write`].
pub fn save<F: Float>(
    path: &Path,
    model: &GridModel<F>,
    training: &TrainingState<F>,
    fit: &SavedFit,
) -> Result<(), CheckpointError> {
    let write_error = |message: String| CheckpointError::Write {
        path: path.to_path_buf(),
        message,
    };
    if fit.precision != Precision::of::<F>() {
        return Err(CheckpointError::Mismatch {
            path: path.to_path_buf(),
            setting: "--precision",
            file: Precision::of::<F>().name().into(),
            asked: fit.precision.name().into(),
        });
    }
    let grid = model
        .params()
        .get(model.grid_id())
        .map_err(|e| write_error(e.to_string()))?;
    let mut tensors: Vec<(&str, Vec<usize>, Vec<u8>)> = vec![("grid", grid.shape().to_vec(), to_bytes(grid.view()))];
    if let Some(adam) = &training.adam {
        tensors.push((
            "adam.first_moment",
            adam.first_moment.shape().to_vec(),
            to_bytes(adam.first_moment.view()),
        ));
        tensors.push((
            "adam.second_moment",
            adam.second_moment.shape().to_vec(),
            to_bytes(adam.second_moment.view()),
        ));
    }
    let dtype = fit.precision.dtype();
    let mut tensors: Vec<_> = tensors.into_iter().map(|(n, s, b)| (n, dtype, s, b)).collect();
    if let Some(occupancy) = &training.occupancy {
        let shape = occupancy.estimate.shape().to_vec();
        let estimate = occupancy.estimate.iter().flat_map(|e| e.to_le_bytes()).collect();
        let occupied = occupancy.occupied.iter().map(|&o| u8::from(o)).collect();
        tensors.push(("occupancy.estimate", Dtype::F32, shape.clone(), estimate));
        tensors.push(("occupancy.occupied", Dtype::BOOL, shape, occupied));
    }
    let views = tensors
        .iter()
        .map(|(name, dtype, shape, bytes)| Ok((*name, TensorView::new(*dtype, shape.clone(), bytes)?)))
        .collect::<Result<Vec<_>, safetensors::SafeTensorError>>()
        .map_err(|e| write_error(e.to_string()))?;
    safetensors::serialize_to_file(views, Some(metadata(model, training, fit)), path)
        .map_err(|e| write_error(e.to_string()))?;
    // The file is made private (as a temporary file) and renamed; a model is no secret.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o644))
            .map_err(|e| write_error(e.to_string()))?;
    }
    Ok(())
}

/// The metadata of a parsed file, with typed look-ups that name the file on error.
struct Meta<'a> {
    path: &'a Path,
    entries: HashMap<String, String>,
}

impl Meta<'_> {
    fn error(&self, message: String) -> CheckpointError {
        CheckpointError::Format {
            path: self.path.to_path_buf(),
            message,
        }
    }

    fn text(&self, key: &str) -> Result<&str, CheckpointError> {
        self.entries
            .get(key)
            .map(String::as_str)
            .ok_or_else(|| self.error(format!("no metadata entry {key:?}")))
    }

    fn parse<T: FromStr>(&self, key: &str) -> Result<T, CheckpointError> {
        let text = self.text(key)?;
        text.parse()
            .map_err(|_| self.error(format!("metadata entry {key:?} is {text:?}")))
    }

    fn finite(&self, key: &str) -> Result<f64, CheckpointError> {
        let x: f64 = self.parse(key)?;
        if x.is_finite() {
            Ok(x)
        } else {
            Err(self.error(format!("metadata entry {key:?} is {x}")))
        }
    }

    fn saved_fit(&self) -> Result<SavedFit, CheckpointError> {
        let precision = match self.text("precision")? {
            "f32" => Precision::F32,
            "f64" => Precision::F64,
            other => return Err(self.error(format!("precision {other:?}"))),
        };
        let budget_text = self.text("budget")?;
        let budget = match budget_text.split_once(':') {
            Some(("steps", n)) => n.parse().ok().map(Budget::Steps),
            Some(("seconds", s)) => s.parse().ok().filter(|s: &f64| s.is_finite()).map(Budget::Seconds),
            _ => None,
        }
        .ok_or_else(|| self.error(format!("budget {budget_text:?}")))?;
        let method = match self.text("method")? {
            "fused" => Method::Fused,
            "taped" => Method::Taped,
            other => return Err(self.error(format!("method {other:?}"))),
        };
        let sampling = match self.text("sampling")? {
            "uniform" => Sampling::Uniform,
            "occupancy" => Sampling::Occupancy,
            other => return Err(self.error(format!("sampling {other:?}"))),
        };
        let config = FitConfig {
            grid: self.parse("grid")?,
            batch: self.parse("batch")?,
            budget,
            method,
            sampling,
            seed: self.parse("seed")?,
            lr: self.finite("lr")?,
            // Files written before the rate annealed ran at a constant rate.
            lr_final: match self.entries.get("lr_final") {
                Some(_) => self.finite("lr_final")?,
                None => self.finite("lr")?,
            },
            shift: self.finite("shift")?,
            evaluations: self.parse("evaluations")?,
            grow: self.parse("grow")?,
            smoothness: self.finite("smoothness")?,
        };
        let cameras = Cameras {
            views: self.parse("views")?,
            test_views: self.parse("test_views")?,
            size: self.parse("size")?,
        };
        cameras.ring().map_err(|e| self.error(e.to_string()))?;
        let scene = Scene::from_json(self.text("scene")?).map_err(|e| self.error(format!("scene: {e}")))?;
        Ok(SavedFit {
            precision,
            config,
            cameras,
            scene,
        })
    }
}

fn read(path: &Path) -> Result<Vec<u8>, CheckpointError> {
    std::fs::read(path).map_err(|e| CheckpointError::Read {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

fn parse_meta<'a>(path: &'a Path, bytes: &[u8]) -> Result<Meta<'a>, CheckpointError> {
    let (_, header) = SafeTensors::read_metadata(bytes).map_err(|e| CheckpointError::Format {
        path: path.to_path_buf(),
        message: format!("not a safetensors file ({e})"),
    })?;
    let meta = Meta {
        path,
        entries: header.metadata().clone().unwrap_or_default(),
    };
    if meta.text("format")? != FORMAT {
        return Err(meta.error(format!("format {:?}, not {FORMAT:?}", meta.text("format")?)));
    }
    if meta.text("version")? != VERSION {
        return Err(meta.error(format!("version {:?}, not {VERSION:?}", meta.text("version")?)));
    }
    Ok(meta)
}

/// Reads the metadata of the model file `path`: the fit's settings and where it stands.
///
/// Errors: [`CheckpointError::Read`], [`CheckpointError::Format`].
pub fn read_info(path: &Path) -> Result<ModelInfo, CheckpointError> {
    let bytes = read(path)?;
    let meta = parse_meta(path, &bytes)?;
    Ok(ModelInfo {
        fit: meta.saved_fit()?,
        nodes: meta.parse("nodes")?,
        step: meta.parse("step")?,
        seconds: meta.finite("seconds")?,
    })
}

/// Reads the model file `path` as written by [`save`], checking every tensor's type, shape
/// and finiteness and Adam's state (as [`Adam::restore`] would).
///
/// Errors: [`CheckpointError::Read`], [`CheckpointError::Format`],
/// [`CheckpointError::Mismatch`] if the file's precision is not `F`.
pub fn load<F: Float>(path: &Path) -> Result<Checkpoint<F>, CheckpointError> {
    let bytes = read(path)?;
    let meta = parse_meta(path, &bytes)?;
    let fit = meta.saved_fit()?;
    if fit.precision != Precision::of::<F>() {
        return Err(CheckpointError::Mismatch {
            path: path.to_path_buf(),
            setting: "--precision",
            file: fit.precision.name().into(),
            asked: Precision::of::<F>().name().into(),
        });
    }
    let tensors = SafeTensors::deserialize(&bytes).map_err(|e| meta.error(e.to_string()))?;
    let nodes: usize = meta.parse("nodes")?;
    if nodes < 2 {
        return Err(meta.error(format!("nodes {nodes}")));
    }
    let shape = [nodes, nodes, nodes, CHANNELS];
    let tensor = |name: &str| -> Result<ArrayD<F>, CheckpointError> {
        let view = tensors
            .tensor(name)
            .map_err(|e| meta.error(format!("tensor {name:?}: {e}")))?;
        if view.dtype() != fit.precision.dtype() || view.shape() != shape {
            return Err(meta.error(format!(
                "tensor {name:?} is {:?} {:?}, expected {:?} {shape:?}",
                view.dtype(),
                view.shape(),
                fit.precision.dtype()
            )));
        }
        let values = from_bytes::<F>(view.data());
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(meta.error(format!(
                "tensor {name:?} holds {} at flat index {i}",
                values[i].as_f64()
            )));
        }
        ArrayD::from_shape_vec(IxDyn(&shape), values).map_err(|e| meta.error(e.to_string()))
    };
    let raw = tensor("grid")?;
    let mut model = GridModel::<F>::new(nodes, fit.config.shift).map_err(|e| meta.error(e.to_string()))?;
    let id = model.grid_id();
    model
        .params_mut()
        .get_mut(id)
        .map_err(|e| meta.error(e.to_string()))?
        .assign(&raw);
    let adam = match meta.entries.get("adam.updates") {
        None => None,
        Some(_) => {
            let state = AdamState {
                first_moment: tensor("adam.first_moment")?,
                second_moment: tensor("adam.second_moment")?,
                updates: meta.parse("adam.updates")?,
            };
            // Checked now, so that a bad file fails here rather than in the fit.
            Adam::new(AdamConfig::default())
                .and_then(|mut a| a.restore(model.params(), id, state.clone()))
                .map_err(|e| meta.error(e.to_string()))?;
            Some(state)
        }
    };
    let occupancy = occupancy_state(&meta, &tensors, fit.config.sampling)?;
    let training = TrainingState {
        occupancy,
        step: meta.parse("step")?,
        seconds: meta.finite("seconds")?,
        stage: meta.parse("stage")?,
        batch_stream: meta.parse("batch_stream")?,
        adam,
    };
    Ok(Checkpoint {
        start: Start { model, training },
        fit,
    })
}

/// The occupancy grid's tensors of an occupancy fit's file, checked as
/// [`OccupancyGrid::restore`](fogray::ops::sample::OccupancyGrid::restore) would: absent (a
/// file written before grids were saved) is `None`, one without the other is an error.
fn occupancy_state(
    meta: &Meta<'_>,
    tensors: &SafeTensors<'_>,
    sampling: Sampling,
) -> Result<Option<OccupancyState>, CheckpointError> {
    let names = ["occupancy.estimate", "occupancy.occupied"];
    let present = names.map(|n| tensors.tensor(n).is_ok());
    if sampling == Sampling::Uniform || present == [false, false] {
        return Ok(None);
    }
    let cells = meta.parse::<usize>("grid")?.saturating_sub(1);
    let shape = [cells; 3];
    let read = |name: &str, dtype: Dtype| -> Result<Vec<u8>, CheckpointError> {
        let view = tensors
            .tensor(name)
            .map_err(|e| meta.error(format!("tensor {name:?}: {e}")))?;
        if view.dtype() != dtype || view.shape() != shape {
            return Err(meta.error(format!(
                "tensor {name:?} is {:?} {:?}, expected {dtype:?} {shape:?}",
                view.dtype(),
                view.shape()
            )));
        }
        Ok(view.data().to_vec())
    };
    let estimate: Vec<f32> = read(names[0], Dtype::F32)?
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    let occupied = read(names[1], Dtype::BOOL)?
        .into_iter()
        .map(|b| match b {
            0 => Ok(false),
            1 => Ok(true),
            other => Err(meta.error(format!("tensor \"occupancy.occupied\" holds the byte {other}"))),
        })
        .collect::<Result<Vec<bool>, _>>()?;
    let to_array = |e: ndarray::ShapeError| meta.error(e.to_string());
    let state = OccupancyState {
        estimate: Array3::from_shape_vec(shape, estimate).map_err(to_array)?,
        occupied: Array3::from_shape_vec(shape, occupied).map_err(to_array)?,
    };
    // Checked now, so that a bad file fails here rather than in the fit.
    crate::fit::occupancy_grid(cells + 1)
        .map_err(|e| meta.error(e.to_string()))?
        .restore(&state)
        .map_err(|e| meta.error(e.to_string()))?;
    Ok(Some(state))
}
