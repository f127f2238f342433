//! A fit saved to a file and read back: the model, Adam's state and what is needed to continue
//! the fit, as [safetensors](https://huggingface.co/docs/safetensors) (which numpy, PyTorch and
//! others open).
//!
//! Tensors, little-endian `F32` or `F64` as the fit was trained:
//! - each of the model's parameters under its name (the dense grid's `grid`, `[N, N, N, 4]`);
//! - `adam.<name>.first_moment`, `adam.<name>.second_moment`: Adam's moments of parameter
//!   `<name>` (absent before the growth stage's first step);
//! - with occupancy sampling, `occupancy.estimate` (`F32`, `[R, R, R]`, the occupancy grid's
//!   density estimates) and `occupancy.occupied` (`BOOL`, the same shape).
//!
//! Metadata (strings): `format` (`fogray model`), `version` (`2`), `model` (the model's
//! [`RadianceField::KIND`]), `precision`, `nodes` (the saved stage's), `step`, `seconds`
//! (training seconds so far), `stage` (growth stage), `batch_stream` (words of the ChaCha12
//! batch generator used), `adam.<name>.updates`, `settings` (the [`FitSettings`] as JSON), and
//! the application's own entries as `extra.<key>` (the grid example's cameras and scene).
//! Numbers are written so that they read back bit for bit.
//!
//! ```
//! use std::collections::BTreeMap;
//! use fogray_fit::checkpoint::{load, save};
//! use fogray_fit::dense::DenseGrid;
//! use fogray_fit::model::RadianceField;
//! use fogray_fit::settings::FitSettings;
//! use fogray_fit::state::TrainingState;
//!
//! let settings = FitSettings { grid: 4, ..FitSettings::default() };
//! let model = DenseGrid::<f32>::fresh(&settings, 4)?;
//! let training = TrainingState::default();
//! let extra = BTreeMap::from([("views".to_string(), "8".to_string())]);
//! let file = std::env::temp_dir().join(format!("checkpoint-doc-{}.safetensors", std::process::id()));
//! save(&file, &model, &training, &settings, &extra)?;
//! let back = load::<f32, DenseGrid<f32>>(&file)?;
//! assert_eq!(back.start.training, training);
//! assert_eq!((back.settings, back.extra), (settings, extra));
//! # std::fs::remove_file(&file)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::str::FromStr;

use fogray_ops::sample::{CellPoints, OccupancyGrid, OccupancyState};
use fogray_tape::optim::{Adam, AdamConfig, AdamState};
use fogray_tape::Float;
use ndarray::{Array3, ArrayD, ArrayViewD, IxDyn};
use safetensors::tensor::{Dtype, TensorView};
use safetensors::SafeTensors;
use thiserror::Error;

use crate::model::RadianceField;
use crate::sampling::occupancy_grid;
use crate::settings::{FitSettings, Precision, Sampling};
use crate::state::{Start, TrainingState};

/// The `format` of the metadata.
pub(crate) const FORMAT: &str = "fogray model";
/// The `version` of the metadata this module writes and reads.
pub(crate) const VERSION: &str = "2";

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
    #[error("{path} is not a valid fogray model: {message}")]
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

/// A model file read back: the fit to continue, its settings and the application's entries.
#[derive(Debug)]
pub struct Checkpoint<F: Float, M> {
    /// The model and the fit's state.
    pub start: Start<F, M>,
    /// The fit's settings.
    pub settings: FitSettings,
    /// The application's own metadata (`extra.<key>` in the file, without the prefix).
    pub extra: BTreeMap<String, String>,
}

impl<F: Float, M: RadianceField<F>> Checkpoint<F, M> {
    /// The occupancy grid to render the saved model with: the saved one for a fit with
    /// occupancy sampling (rebuilt from the model's densities, one update at the cells'
    /// centres, if the file has none), `None` for uniform sampling.
    ///
    /// Errors: the ops' (not expected for a model [`load`] accepted).
    pub fn occupancy_grid(&self) -> Result<Option<OccupancyGrid>, crate::FitError> {
        if self.settings.sampling == Sampling::Uniform {
            return Ok(None);
        }
        let model = &self.start.model;
        let mut grid = occupancy_grid(model.bounds(), self.settings.grid)?;
        match &self.start.training.occupancy {
            Some(state) => grid.restore(state)?,
            None => grid.update(|p| model.densities(p), CellPoints::Centre)?,
        }
        Ok(Some(grid))
    }
}

/// Checks that a model can be written to `path` before a fit spends its budget: its
/// directory exists (the working directory for a bare file name).
///
/// Errors: [`CheckpointError::Write`] naming the missing directory.
pub fn check_destination(path: &Path) -> Result<(), CheckpointError> {
    let parent = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    if parent.is_dir() {
        Ok(())
    } else {
        Err(CheckpointError::Write {
            path: path.to_path_buf(),
            message: format!("no directory {}", parent.display()),
        })
    }
}

/// The metadata of a model file, read without its tensors' values.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelInfo {
    /// The fit's settings.
    pub settings: FitSettings,
    /// The model's kind ([`RadianceField::KIND`]).
    pub kind: String,
    /// Nodes per axis of the saved model (a growing fit's current stage).
    pub nodes: usize,
    /// Steps done.
    pub step: usize,
    /// Training seconds so far.
    pub seconds: f64,
    /// The application's own metadata.
    pub extra: BTreeMap<String, String>,
}

impl ModelInfo {
    /// Checks that the file's model is one a fit with `precision` and `grid` nodes per axis
    /// can continue. Errors: [`CheckpointError::Mismatch`] naming the first setting that
    /// differs.
    pub(crate) fn check_matches(&self, path: &Path, precision: Precision, grid: usize) -> Result<(), CheckpointError> {
        let mismatch = |setting, file: String, asked: String| CheckpointError::Mismatch {
            path: path.to_path_buf(),
            setting,
            file,
            asked,
        };
        if self.settings.precision != precision {
            return Err(mismatch(
                "--precision",
                self.settings.precision.name().into(),
                precision.name().into(),
            ));
        }
        if self.settings.grid != grid {
            return Err(mismatch("--grid", self.settings.grid.to_string(), grid.to_string()));
        }
        Ok(())
    }
}

fn dtype(precision: Precision) -> Dtype {
    match precision {
        Precision::F32 => Dtype::F32,
        Precision::F64 => Dtype::F64,
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

fn adam_key(name: &str, what: &str) -> String {
    format!("adam.{name}.{what}")
}

fn metadata<F: Float, M: RadianceField<F>>(
    model: &M,
    training: &TrainingState<F>,
    settings: &FitSettings,
    extra: &BTreeMap<String, String>,
) -> Result<HashMap<String, String>, String> {
    let mut m: HashMap<String, String> = [
        ("format", FORMAT.to_string()),
        ("version", VERSION.to_string()),
        ("model", M::KIND.to_string()),
        ("precision", settings.precision.name().to_string()),
        ("nodes", model.nodes().to_string()),
        ("step", training.step.to_string()),
        // Rust prints a float in the fewest digits that read back to the same bits.
        ("seconds", training.seconds.to_string()),
        ("stage", training.stage.to_string()),
        ("batch_stream", training.batch_stream.to_string()),
        ("settings", serde_json::to_string(settings).map_err(|e| e.to_string())?),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect();
    for (name, state) in &training.adam {
        m.insert(adam_key(name, "updates"), state.updates.to_string());
    }
    for (k, v) in extra {
        m.insert(format!("extra.{k}"), v.clone());
    }
    Ok(m)
}

/// Writes `model` and `training` with the fit's `settings` and the application's `extra`
/// entries to `path` (see the [module docs](self) for the layout).
///
/// Errors: [`CheckpointError::Mismatch`] if `settings.precision` is not `F`'s,
/// [`CheckpointError::Write`].
pub fn save<F: Float, M: RadianceField<F>>(
    path: &Path,
    model: &M,
    training: &TrainingState<F>,
    settings: &FitSettings,
    extra: &BTreeMap<String, String>,
) -> Result<(), CheckpointError> {
    let write_error = |message: String| CheckpointError::Write {
        path: path.to_path_buf(),
        message,
    };
    if settings.precision != Precision::of::<F>() {
        return Err(CheckpointError::Mismatch {
            path: path.to_path_buf(),
            setting: "--precision",
            file: Precision::of::<F>().name().into(),
            asked: settings.precision.name().into(),
        });
    }
    let dtype = dtype(settings.precision);
    let mut tensors: Vec<(String, Dtype, Vec<usize>, Vec<u8>)> = Vec::new();
    let params = model.params();
    for id in params.ids() {
        let value = params.get(id).map_err(|e| write_error(e.to_string()))?;
        let name = params.name(id).map_err(|e| write_error(e.to_string()))?;
        tensors.push((name.to_string(), dtype, value.shape().to_vec(), to_bytes(value.view())));
    }
    for (name, adam) in &training.adam {
        for (what, moment) in [
            ("first_moment", &adam.first_moment),
            ("second_moment", &adam.second_moment),
        ] {
            tensors.push((
                adam_key(name, what),
                dtype,
                moment.shape().to_vec(),
                to_bytes(moment.view()),
            ));
        }
    }
    for (name, mask) in model.structure() {
        let n = model.nodes();
        tensors.push((
            name.into(),
            Dtype::BOOL,
            vec![n, n, n],
            mask.iter().map(|&k| u8::from(k)).collect(),
        ));
    }
    if let Some(occupancy) = &training.occupancy {
        let shape = occupancy.estimate.shape().to_vec();
        let estimate = occupancy.estimate.iter().flat_map(|e| e.to_le_bytes()).collect();
        let occupied = occupancy.occupied.iter().map(|&o| u8::from(o)).collect();
        tensors.push(("occupancy.estimate".into(), Dtype::F32, shape.clone(), estimate));
        tensors.push(("occupancy.occupied".into(), Dtype::BOOL, shape, occupied));
    }
    let views = tensors
        .iter()
        .map(|(name, dtype, shape, bytes)| Ok((name.as_str(), TensorView::new(*dtype, shape.clone(), bytes)?)))
        .collect::<Result<Vec<_>, safetensors::SafeTensorError>>()
        .map_err(|e| write_error(e.to_string()))?;
    let meta = metadata(model, training, settings, extra).map_err(write_error)?;
    safetensors::serialize_to_file(views, Some(meta), path).map_err(|e| write_error(e.to_string()))?;
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

    fn settings(&self) -> Result<FitSettings, CheckpointError> {
        let settings: FitSettings =
            serde_json::from_str(self.text("settings")?).map_err(|e| self.error(format!("settings: {e}")))?;
        settings.check().map_err(|e| self.error(format!("settings: {e}")))?;
        Ok(settings)
    }

    fn extra(&self) -> BTreeMap<String, String> {
        self.entries
            .iter()
            .filter_map(|(k, v)| Some((k.strip_prefix("extra.")?.to_string(), v.clone())))
            .collect()
    }

    fn info(&self) -> Result<ModelInfo, CheckpointError> {
        let settings = self.settings()?;
        // The entry is written beside the settings for readers that do not parse them; the two
        // must agree, or a reader trusting the entry would take the tensors for another type.
        let precision = self.text("precision")?;
        if precision != settings.precision.name() {
            return Err(self.error(format!(
                "metadata entry \"precision\" is {precision:?} but its settings say {:?}",
                settings.precision.name()
            )));
        }
        // What a reader allocates follows the nodes and the settings' grid: both are checked
        // against the settings' ranges and the machine's memory before anything is built.
        settings.check().map_err(|e| self.error(format!("its settings: {e}")))?;
        let nodes: usize = self.parse("nodes")?;
        if !(2..=settings.grid).contains(&nodes) {
            return Err(self.error(format!(
                "metadata entry \"nodes\" is {nodes}, outside 2 to the settings' grid of {}",
                settings.grid
            )));
        }
        Ok(ModelInfo {
            settings,
            kind: self.text("model")?.to_string(),
            nodes,
            step: self.parse("step")?,
            seconds: self.finite("seconds")?,
            extra: self.extra(),
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
    parse_meta(path, &bytes)?.info()
}

/// Reads the model file `path` as written by [`save`], checking the model's kind, every
/// tensor's type, shape and finiteness, Adam's state (as [`Adam::restore`] would) and the
/// occupancy grid's.
///
/// Errors: [`CheckpointError::Read`], [`CheckpointError::Format`],
/// [`CheckpointError::Mismatch`] if the file's precision is not `F`.
pub fn load<F: Float, M: RadianceField<F>>(path: &Path) -> Result<Checkpoint<F, M>, CheckpointError> {
    let bytes = read(path)?;
    let meta = parse_meta(path, &bytes)?;
    let info = meta.info()?;
    let settings = info.settings;
    if settings.precision != Precision::of::<F>() {
        return Err(CheckpointError::Mismatch {
            path: path.to_path_buf(),
            setting: "--precision",
            file: settings.precision.name().into(),
            asked: Precision::of::<F>().name().into(),
        });
    }
    if info.kind != M::KIND {
        return Err(meta.error(format!("model {:?}, not {:?}", info.kind, M::KIND)));
    }
    let tensors = SafeTensors::deserialize(&bytes).map_err(|e| meta.error(e.to_string()))?;
    let n = info.nodes;
    let mask = |name: &str| {
        let view = tensors.tensor(name).ok()?;
        (view.dtype() == Dtype::BOOL && view.shape() == [n, n, n])
            .then(|| view.data().iter().map(|&b| b != 0).collect())
    };
    let mut model = M::with_structure(&settings, n, &mask).map_err(|e| meta.error(e.to_string()))?;
    let tensor = |name: &str, shape: &[usize]| -> Result<ArrayD<F>, CheckpointError> {
        let view = tensors
            .tensor(name)
            .map_err(|e| meta.error(format!("tensor {name:?}: {e}")))?;
        if view.dtype() != dtype(settings.precision) || view.shape() != shape {
            return Err(meta.error(format!(
                "tensor {name:?} is {:?} {:?}, expected {:?} {shape:?}",
                view.dtype(),
                view.shape(),
                dtype(settings.precision)
            )));
        }
        let values = from_bytes::<F>(view.data());
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(meta.error(format!(
                "tensor {name:?} holds {} at flat index {i}",
                values[i].as_f64()
            )));
        }
        ArrayD::from_shape_vec(IxDyn(shape), values).map_err(|e| meta.error(e.to_string()))
    };
    let ids: Vec<_> = model.params().ids().collect();
    let mut adam = Vec::new();
    for id in ids {
        let (name, shape) = {
            let params = model.params();
            let name = params.name(id).map_err(|e| meta.error(e.to_string()))?.to_string();
            let shape = params.get(id).map_err(|e| meta.error(e.to_string()))?.shape().to_vec();
            (name, shape)
        };
        let value = tensor(&name, &shape)?;
        model
            .params_mut()
            .get_mut(id)
            .map_err(|e| meta.error(e.to_string()))?
            .assign(&value);
        if meta.entries.contains_key(&adam_key(&name, "updates")) {
            let state = AdamState {
                first_moment: tensor(&adam_key(&name, "first_moment"), &shape)?,
                second_moment: tensor(&adam_key(&name, "second_moment"), &shape)?,
                updates: meta.parse(&adam_key(&name, "updates"))?,
            };
            // Checked now, so that a bad file fails here rather than in the fit.
            Adam::new(AdamConfig::default())
                .and_then(|mut a| a.restore(model.params(), id, state.clone()))
                .map_err(|e| meta.error(e.to_string()))?;
            adam.push((name, state));
        }
    }
    let occupancy = occupancy_state(&meta, &tensors, &settings, &model)?;
    let training = TrainingState {
        occupancy,
        step: info.step,
        seconds: info.seconds,
        stage: meta.parse("stage")?,
        batch_stream: meta.parse("batch_stream")?,
        adam,
    };
    Ok(Checkpoint {
        start: Start { model, training },
        settings,
        extra: info.extra,
    })
}

/// The occupancy grid's tensors of an occupancy fit's file, checked as
/// [`OccupancyGrid::restore`](fogray_ops::sample::OccupancyGrid::restore) would: absent is
/// `None`, one without the other is an error.
fn occupancy_state<F: Float, M: RadianceField<F>>(
    meta: &Meta<'_>,
    tensors: &SafeTensors<'_>,
    settings: &FitSettings,
    model: &M,
) -> Result<Option<OccupancyState>, CheckpointError> {
    let names = ["occupancy.estimate", "occupancy.occupied"];
    let present = names.map(|n| tensors.tensor(n).is_ok());
    if settings.sampling == Sampling::Uniform || present == [false, false] {
        return Ok(None);
    }
    let mut grid = occupancy_grid(model.bounds(), settings.grid).map_err(|e| meta.error(e.to_string()))?;
    let shape = [grid.resolution(); 3];
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
    grid.restore(&state).map_err(|e| meta.error(e.to_string()))?;
    Ok(Some(state))
}

#[cfg(test)]
mod tests;
