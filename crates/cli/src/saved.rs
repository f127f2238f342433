//! A model file that a command reads (`fogray render`, `fogray export`): its metadata, read
//! first, and the dispatch from its kind and precision to the model type that loads it
//! (fogray-fit's [`with_field_kind`]), so that each command writes its work once, generic over
//! the model.

use std::path::{Path, PathBuf};

use fogray_fit::checkpoint::{read_info, ModelInfo};
use fogray_fit::dispatch::{with_field_kind, FieldKind, FieldWork};
use fogray_fit::model::RadianceField;
use fogray_tape::Float;

use crate::error::CliError;

/// What a command does with a model, once its type is known.
pub trait WithModel {
    /// What the work gives.
    type Output;
    /// Does the work with the model file `path`, whose model is an `M` in `F` (load it with
    /// [`fogray_fit::checkpoint::load`]).
    ///
    /// Errors: the command's.
    fn run<F: Float, M: RadianceField<F>>(self, path: &Path) -> Result<Self::Output, CliError>;
}

/// A model file whose metadata has been read and whose kind is known.
#[derive(Debug, Clone)]
pub struct SavedModel {
    /// The file.
    pub path: PathBuf,
    /// Its metadata (settings, nodes, the application's entries).
    pub info: ModelInfo,
    /// Its kind (a field: a splat fit is saved as a 3DGS PLY file, not as a model file).
    pub kind: FieldKind,
}

impl SavedModel {
    /// Reads the metadata of `path` for `command` (named in the refusal of an unknown kind).
    ///
    /// Errors: a file that cannot be read or is not a fogray model, a model of a kind the
    /// command line does not know.
    pub fn open(path: &Path, command: &'static str) -> Result<Self, CliError> {
        let info = read_info(path)?;
        let kind = FieldKind::of_kind(&info.kind).ok_or_else(|| CliError::UnknownModelKind {
            path: path.to_path_buf(),
            kind: info.kind.clone(),
            command,
        })?;
        Ok(SavedModel {
            path: path.to_path_buf(),
            info,
            kind,
        })
    }

    /// Runs `work` with the model type of the file's kind and precision.
    ///
    /// Errors: `work`'s.
    pub fn with<W: WithModel>(&self, work: W) -> Result<W::Output, CliError> {
        let at = AtPath { work, path: &self.path };
        with_field_kind(self.info.settings.precision, self.kind, at)
    }
}

/// A command's work on the model file `path`, as fogray-fit's dispatch runs it.
struct AtPath<'a, W> {
    work: W,
    path: &'a Path,
}

impl<W: WithModel> FieldWork for AtPath<'_, W> {
    type Output = Result<W::Output, CliError>;

    fn run<F: Float, M: RadianceField<F>>(self) -> Self::Output {
        self.work.run::<F, M>(self.path)
    }
}
