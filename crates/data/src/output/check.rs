//! Outputs checked before any work starts: a command names what it reads ([`Inputs`]) and
//! what it will write ([`Output`]), and [`check_outputs`] refuses, in one line naming the
//! path, an output that would overwrite an input, a folder where a file is expected, or a
//! folder that cannot be written, so that no fit or render runs for hours to fail at its end.
//!
//! Paths are compared resolved: absolute, every symbolic link and `..` of the part that
//! exists followed (an output need not exist yet), so that `data/../data/train/a.png` and a
//! link to the dataset are recognised as the dataset's.

use std::collections::{HashMap, HashSet};
use std::fmt;
use std::path::{Component, Path, PathBuf};

use super::atomic::{folder_of, probe};
use crate::error::DataError;
use crate::escape::shown;
use crate::files::dataset_files;

/// What a command reads, which its outputs may not touch.
#[derive(Debug, Clone, Default)]
pub struct Inputs {
    /// Resolved input file to the path as the command was given it.
    files: HashMap<PathBuf, PathBuf>,
    /// Resolved dataset folder and the path as given; nothing inside may be written.
    folders: Vec<(PathBuf, PathBuf)>,
}

impl Inputs {
    /// No inputs.
    pub fn new() -> Self {
        Inputs::default()
    }

    /// `self` and the file `path` (a model, a transforms file...).
    pub fn file(mut self, path: &Path) -> Self {
        self.files.insert(resolved(path), path.to_path_buf());
        self
    }

    /// `self` and the dataset at `path` (see [`dataset_files`](crate::dataset_files)): its
    /// folder (everything inside it), when `path` is a folder, its transforms files and every
    /// picture they name.
    ///
    /// Errors: those of [`dataset_files`](crate::dataset_files).
    pub fn dataset(mut self, path: &Path) -> Result<Self, DataError> {
        let files = dataset_files(path)?;
        if let Some(folder) = files.folder {
            self.folders.push((resolved(&folder), folder));
        }
        for file in files.transforms.into_iter().chain(files.pictures) {
            self.files.insert(resolved(&file), file);
        }
        Ok(self)
    }
}

/// A path a command will write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Output<'a> {
    /// A file, written whole (its folder must exist, or be a [`Output::Folder`] of the same
    /// check, which the command creates).
    File(&'a Path),
    /// A folder that files are written into, created if missing: it may not be an input or
    /// lie inside an input folder.
    Folder(&'a Path),
    /// A folder of its own (a report): as [`Output::Folder`], and no input may lie inside it
    /// either, so that nothing the command writes there can land on the input.
    SeparateFolder(&'a Path),
}

/// Why an output path was refused.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum OutputProblem {
    /// It is one of the command's inputs.
    IsInput {
        /// The input, as the command was given it (a dataset's picture: as its transforms file
        /// names it).
        input: PathBuf,
    },
    /// It lies inside (or is) an input dataset's folder.
    InsideInput {
        /// The folder.
        folder: PathBuf,
    },
    /// A folder of its own that holds an input.
    HoldsInput {
        /// The input.
        input: PathBuf,
    },
    /// A folder where a file is expected.
    IsFolder,
    /// A file where a folder is expected (the output itself or one of its parents).
    NotAFolder {
        /// The file.
        path: PathBuf,
    },
    /// The folder of a file output does not exist.
    FolderMissing {
        /// The folder.
        folder: PathBuf,
    },
    /// No file can be created in the folder.
    NotWritable {
        /// The folder.
        folder: PathBuf,
        /// The operating system's reason.
        message: String,
    },
}

impl fmt::Display for OutputProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            OutputProblem::IsInput { input } => write!(f, "it is the input {}", shown(input)),
            OutputProblem::InsideInput { folder } => {
                write!(f, "it lies inside the input dataset folder {}", shown(folder))
            }
            OutputProblem::HoldsInput { input } => write!(f, "it holds the input {}", shown(input)),
            OutputProblem::IsFolder => write!(f, "it is a folder, where a file is expected"),
            OutputProblem::NotAFolder { path } => write!(f, "{} is a file, where a folder is expected", shown(path)),
            OutputProblem::FolderMissing { folder } => write!(f, "its folder {} does not exist", shown(folder)),
            OutputProblem::NotWritable { folder, message } => {
                write!(f, "its folder {} cannot be written ({message})", shown(folder))
            }
        }
    }
}

/// Checks every output against the inputs and the file system, before any work: each
/// [`Output::File`] is not an input, not inside an input folder, not an existing folder, and
/// its folder exists (or is an [`Output::Folder`] of `outputs`) and takes a new file; each
/// folder is not an input and not inside an input folder, is a folder if it exists, and its
/// nearest existing parent takes a new file. Writability is probed by creating and removing a
/// temporary (once per folder). Nothing else is written.
///
/// Errors: [`DataError::Output`] naming the first output refused and why.
pub fn check_outputs(inputs: &Inputs, outputs: &[Output<'_>]) -> Result<(), DataError> {
    let folders: Vec<PathBuf> = outputs
        .iter()
        .filter_map(|o| match o {
            Output::Folder(p) | Output::SeparateFolder(p) => Some(resolved(p)),
            Output::File(_) => None,
        })
        .collect();
    let mut probed = HashSet::new();
    for output in outputs {
        let (Output::File(path) | Output::Folder(path) | Output::SeparateFolder(path)) = *output;
        check_one(inputs, *output, &folders, &mut probed).map_err(|problem| DataError::Output {
            path: path.to_path_buf(),
            problem,
        })?;
    }
    Ok(())
}

fn check_one(
    inputs: &Inputs,
    output: Output<'_>,
    folders: &[PathBuf],
    probed: &mut HashSet<PathBuf>,
) -> Result<(), OutputProblem> {
    let (Output::File(path) | Output::Folder(path) | Output::SeparateFolder(path)) = output;
    let at = resolved(path);
    if let Some(input) = inputs.files.get(&at) {
        return Err(OutputProblem::IsInput { input: input.clone() });
    }
    if let Some((_, folder)) = inputs.folders.iter().find(|(f, _)| at.starts_with(f)) {
        return Err(OutputProblem::InsideInput { folder: folder.clone() });
    }
    if let Output::SeparateFolder(_) = output {
        let files = inputs.files.iter();
        let folders = inputs.folders.iter().map(|(r, given)| (r, given));
        if let Some((_, input)) = files.chain(folders).find(|(r, _)| r.starts_with(&at)) {
            return Err(OutputProblem::HoldsInput { input: input.clone() });
        }
    }
    let is_folder = std::fs::metadata(&at).map(|m| m.is_dir()).ok();
    match output {
        Output::File(_) => {
            let names_folder = path.to_string_lossy().ends_with(std::path::is_separator);
            if is_folder == Some(true) || names_folder {
                return Err(OutputProblem::IsFolder);
            }
            let folder = folder_of(&at);
            match std::fs::metadata(folder).map(|m| m.is_dir()) {
                Ok(true) => writable(folder, probed),
                Ok(false) => Err(OutputProblem::NotAFolder {
                    path: folder.to_path_buf(),
                }),
                // A folder the same command creates, itself checked.
                Err(_) if folders.iter().any(|f| folder.starts_with(f)) => Ok(()),
                Err(_) => Err(OutputProblem::FolderMissing {
                    folder: folder.to_path_buf(),
                }),
            }
        }
        Output::Folder(_) | Output::SeparateFolder(_) => {
            if is_folder == Some(false) {
                return Err(OutputProblem::NotAFolder {
                    path: path.to_path_buf(),
                });
            }
            let existing = at.ancestors().find(|a| a.exists()).unwrap_or(Path::new("/"));
            if !existing.is_dir() {
                return Err(OutputProblem::NotAFolder {
                    path: existing.to_path_buf(),
                });
            }
            writable(existing, probed)
        }
    }
}

/// Whether a file can be created in `folder` (probed once per folder).
fn writable(folder: &Path, probed: &mut HashSet<PathBuf>) -> Result<(), OutputProblem> {
    if probed.contains(folder) {
        return Ok(());
    }
    probe(folder).map_err(|e| OutputProblem::NotWritable {
        folder: folder.to_path_buf(),
        message: crate::error::one_line(e),
    })?;
    probed.insert(folder.to_path_buf());
    Ok(())
}

/// Checks the outputs of a fit before it trains (see [`check_outputs`]): `save_model`, the
/// model file, is not an input, not a folder, and its folder takes a new file (or is
/// `out_dir`, which the fit creates); `out_dir`, the report's folder, is not an input, and the
/// dataset and the report's folder do not overlap, neither inside the other; and each of
/// `report_folders` (the report's own subfolders, by name under `out_dir`), resolved through
/// any link already there, is a folder or absent and lies in no input (a link `out/test` to
/// the dataset's `test` would otherwise have the report's pictures written over its
/// photographs).
///
/// `inputs` are what the fit reads: `Inputs::new().dataset(data)?`, and the model it resumes
/// from if the fit flow does not mean to save over it.
///
/// Errors: [`DataError::Output`] naming the path and why.
pub fn plan_fit_outputs(
    inputs: &Inputs,
    save_model: Option<&Path>,
    out_dir: Option<&Path>,
    report_folders: &[&str],
) -> Result<(), DataError> {
    let subfolders: Vec<PathBuf> = out_dir
        .map(|out| report_folders.iter().map(|name| out.join(name)).collect())
        .unwrap_or_default();
    let mut outputs = Vec::with_capacity(2 + subfolders.len());
    outputs.extend(out_dir.map(Output::SeparateFolder));
    outputs.extend(subfolders.iter().map(|p| Output::SeparateFolder(p)));
    outputs.extend(save_model.map(Output::File));
    check_outputs(inputs, &outputs)
}

/// `path` made absolute, with every symbolic link, `.` and `..` of its existing part resolved
/// as the system resolves them; the part that does not exist is appended as written (its `..`
/// removing a name before it).
pub fn resolved(path: &Path) -> PathBuf {
    let absolute = match std::env::current_dir() {
        Ok(dir) if path.is_relative() => dir.join(path),
        _ => path.to_path_buf(),
    };
    let mut out = PathBuf::new();
    // How many trailing components of `out` do not exist.
    let mut missing = 0usize;
    for component in absolute.components() {
        match component {
            Component::Prefix(_) | Component::RootDir => out.push(component.as_os_str()),
            Component::CurDir => {}
            Component::ParentDir => {
                // `out` is resolved up to its missing tail, so its parent is the real one.
                out.pop();
                missing = missing.saturating_sub(1);
            }
            Component::Normal(name) => {
                out.push(name);
                if missing > 0 {
                    missing += 1;
                } else {
                    match out.canonicalize() {
                        Ok(real) => out = real,
                        Err(_) => missing = 1,
                    }
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests;
