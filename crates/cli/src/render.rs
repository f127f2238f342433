//! `fogray render`: a saved model rendered from every camera of a transforms file (either
//! format), one 8-bit RGB PNG per frame.

use std::path::{Path, PathBuf};

use fogray_data::{load_cameras, NamedCamera};
use fogray_fit::checkpoint;
use fogray_fit::dataset::camera_rays;
use fogray_fit::images::write_png;
use fogray_fit::model::RadianceField;
use fogray_fit::render::{render_picture, RenderOptions};
use fogray_fit::settings::Method;
use fogray_tape::Float;
use ndarray::Array3;

use crate::error::CliError;
use crate::saved::{SavedModel, WithModel};

/// The flags of `fogray render`.
#[derive(Debug, Clone, clap::Args)]
pub struct RenderArgs {
    /// A model written by `fogray fit --save-model`.
    #[arg(long, value_name = "FILE")]
    pub model: PathBuf,
    /// A transforms file or dataset folder (Blender or instant-ngp/nerfstudio) whose every
    /// frame is rendered (a Blender folder: train, val and test frames).
    #[arg(long, value_name = "TRANSFORMS")]
    pub cameras: PathBuf,
    /// Divide the cameras' image size, focal lengths and principal point by K.
    #[arg(long, default_value_t = 1, value_name = "K")]
    pub downscale: usize,
    /// The directory of the PNGs, `DIR/<name>.png` with `<name>` the frame's file name
    /// without folder and extension.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
}

/// Runs `fogray render`: the paths written, one per line.
///
/// Errors: a model file that is not a fogray dense- or sparse-grid model, a bad transforms file (naming
/// it), two frames of one name, a file that cannot be written.
pub fn run(args: &RenderArgs) -> Result<String, CliError> {
    let saved = SavedModel::open(&args.model, "fogray render")?;
    let cameras = load_cameras(&args.cameras, args.downscale)?;
    let mut names = std::collections::BTreeSet::new();
    if let Some(twice) = cameras.iter().find(|c| !names.insert(c.name.as_str())) {
        return Err(CliError::Option(format!(
            "{}: two frames are named {:?} (their PNGs would overwrite each other)",
            args.cameras.display(),
            twice.name
        )));
    }
    let background = match saved.info.extra.get("background") {
        Some(text) => serde_json::from_str::<[f64; 3]>(text)
            .map_err(|e| CliError::Option(format!("{}: its background {text:?}: {e}", args.model.display())))?,
        None => [1.0; 3],
    };
    std::fs::create_dir_all(&args.out).map_err(CliError::file("create", &args.out))?;
    saved.with(RenderAll {
        args,
        cameras: &cameras,
        background,
    })
}

/// Every camera's render of the model.
struct RenderAll<'a> {
    args: &'a RenderArgs,
    cameras: &'a [NamedCamera],
    background: [f64; 3],
}

impl WithModel for RenderAll<'_> {
    type Output = String;

    fn run<F: Float, M: RadianceField<F>>(self, path: &Path) -> Result<String, CliError> {
        let RenderAll {
            args,
            cameras,
            background,
        } = self;
        let saved = checkpoint::load::<F, M>(path)?;
        let occupancy = saved.occupancy_grid()?;
        let options = RenderOptions {
            background,
            method: Method::Fused,
            depth: false,
        };
        let bar = indicatif::ProgressBar::new(cameras.len() as u64);
        if let Ok(style) = indicatif::ProgressStyle::with_template("render [{bar:40}] {pos}/{len} ({elapsed})") {
            bar.set_style(style.progress_chars("=> "));
        }
        let mut written = Vec::new();
        for c in cameras {
            let k = c.camera.intrinsics();
            let (origins, directions) = camera_rays(&c.camera);
            let picture = render_picture(
                &saved.start.model,
                occupancy.as_ref(),
                &origins,
                &directions,
                [k.height, k.width],
                &options,
            )?;
            let path = args.out.join(format!("{}.png", c.name));
            write_whole(&path, &picture.color)?;
            written.push(path.display().to_string());
            bar.inc(1);
        }
        bar.finish_and_clear();
        Ok(written.join("\n"))
    }
}

/// Writes the PNG beside its final name and renames it, so that an interrupted render leaves
/// whole files only.
fn write_whole(path: &Path, image: &Array3<f64>) -> Result<(), CliError> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let partial = path.with_file_name(format!(".{name}.partial.png"));
    write_png(&partial, image.view())?;
    std::fs::rename(&partial, path).map_err(CliError::file("write", path))
}
