//! `fogray export`: a saved model as a file other tools open; `--mesh OUT.ply`, the surface
//! where its density crosses a level (marching cubes, [`fogray_fit::mesh`]) as binary PLY with
//! vertex colours.
//!
//! The mesh may not be the model file (checked before any work), and is written whole: to a
//! fresh temporary beside it, renamed once complete.

use std::path::{Path, PathBuf};

use fogray_data::{check_outputs, shown, AtomicFile, Inputs, Output};
use fogray_fit::checkpoint;
use fogray_fit::mesh::{extract, Extraction, Level, MeshOptions};
use fogray_fit::model::RadianceField;
use fogray_tape::Float;

use crate::error::CliError;
use crate::saved::{SavedModel, WithModel};

/// The flags of `fogray export`.
#[derive(Debug, Clone, clap::Args)]
pub struct ExportArgs {
    /// A model written by `fogray fit --save-model`.
    #[arg(long, value_name = "FILE")]
    pub model: PathBuf,
    /// Write the model's surface as a binary PLY mesh (vertex colours: the model's
    /// view-independent colour).
    #[arg(long, value_name = "OUT.ply")]
    pub mesh: PathBuf,
    /// The surface's level as a density SIGMA (the model's units); not with --opacity.
    #[arg(long, value_name = "SIGMA", allow_negative_numbers = true)]
    pub level: Option<f64>,
    /// The surface's level as the opacity A in (0, 1) of one sample step of the model
    /// (density -ln(1 - A) / step) [default: 0.1, when --level is not given].
    #[arg(long, value_name = "A", allow_negative_numbers = true)]
    pub opacity: Option<f64>,
    /// Sample the density on an N^3 lattice over the model's box [default: the model's own
    /// nodes per axis].
    #[arg(long, value_name = "N")]
    pub resolution: Option<usize>,
}

impl ExportArgs {
    /// The extraction's options, checked before any file is read.
    ///
    /// Errors: both --level and --opacity, an opacity outside (0, 1), a resolution below 2.
    pub fn options(&self) -> Result<MeshOptions, CliError> {
        let level = match (self.level, self.opacity) {
            (Some(_), Some(_)) => {
                return Err(CliError::FlagsExclude {
                    first: "--level",
                    second: "--opacity",
                    why: "the surface's level is one or the other",
                })
            }
            (Some(sigma), None) => Level::Density(sigma),
            (None, Some(a)) if a > 0.0 && a < 1.0 => Level::Opacity(a),
            (None, Some(a)) => {
                return Err(CliError::Flag {
                    flag: "--opacity",
                    value: Some(a.to_string()),
                    rule: "must be in (0, 1)".into(),
                })
            }
            (None, None) => Level::default(),
        };
        if let Some(n) = self.resolution.filter(|&n| n < 2) {
            return Err(CliError::Flag {
                flag: "--resolution",
                value: Some(n.to_string()),
                rule: "the lattice needs at least 2 nodes per axis".into(),
            });
        }
        Ok(MeshOptions {
            level,
            resolution: self.resolution,
        })
    }
}

/// Runs `fogray export`: one line naming the file written, its vertices and triangles and
/// the density level.
///
/// Errors: bad options, a model file that is not a fogray model (or of a kind it does not
/// know), a level outside the density's range on the lattice, a file that cannot be written.
pub fn run(args: &ExportArgs) -> Result<String, CliError> {
    let options = args.options()?;
    let destination = &args.mesh;
    check_outputs(&Inputs::new().file(&args.model), &[Output::File(destination)])?;
    let saved = SavedModel::open(&args.model, "fogray export")?;
    // Created before the work, so that an unwritable destination is refused at once; removed
    // on any error (and on Ctrl-C).
    let file = AtomicFile::create(destination)?;
    let e = saved.with(ExportMesh {
        options,
        file,
        destination,
    })?;
    Ok(format!(
        "{}: {} vertices, {} triangles, density level {} on a {}^3 lattice",
        shown(destination),
        e.mesh.positions.len(),
        e.mesh.triangles.len(),
        e.level,
        e.resolution
    ))
}

/// The mesh of the model, written to `file` and renamed into place.
struct ExportMesh<'a> {
    options: MeshOptions,
    file: AtomicFile,
    destination: &'a Path,
}

impl WithModel for ExportMesh<'_> {
    type Output = Extraction;

    fn run<F: Float, M: RadianceField<F>>(self, path: &Path) -> Result<Extraction, CliError> {
        let saved = checkpoint::load::<F, M>(path)?;
        let extraction = extract(&saved.start.model, &self.options)?;
        let comment = format!(
            "fogray export of {}: density level {} on a {}^3 lattice",
            path.file_name().map(|n| n.to_string_lossy()).unwrap_or_default(),
            extraction.level,
            extraction.resolution
        )
        .replace(['\n', '\r'], " ");
        let mut file = self.file;
        extraction
            .mesh
            .write_ply(&comment, &mut file)
            .map_err(CliError::file("write", self.destination))?;
        file.commit()?;
        Ok(extraction)
    }
}
