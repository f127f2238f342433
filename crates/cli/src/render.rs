//! `fogray render`: a saved model rendered from every camera of a transforms file (either
//! format) or from an orbit around its scene box, one 8-bit RGB PNG per frame, and on request
//! each frame's depth map and (an orbit) an animated GIF.
//!
//! Every output is checked before the first frame renders ([`check_outputs`]): none may be the
//! model, the dataset's transforms files or pictures, or lie inside a dataset folder given to
//! `--cameras`; each file is written whole (a fresh temporary renamed into place).

use std::path::{Path, PathBuf};

use fogray_data::{check_outputs, load_split_cameras, shown, Inputs, Output as Destination, Split};
use fogray_fit::checkpoint::{self, ModelInfo};
use fogray_fit::dataset::camera_rays;
use fogray_fit::depth::write_depth_png;
use fogray_fit::images::write_png;
use fogray_fit::model::RadianceField;
use fogray_fit::render::{render_picture, RenderOptions};
use fogray_fit::settings::Method;
use fogray_ops::PinholeCamera;
use fogray_tape::Float;

use crate::animation::GifWriter;
use crate::error::CliError;
use crate::framing::{self, ImageSize};
use crate::render_memory;
use crate::saved::{SavedModel, WithModel};

/// `--split`: which frames of a dataset to render.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum SplitArg {
    /// Every frame.
    All,
    /// The frames a fit trains on.
    Train,
    /// The frames a fit holds out.
    Test,
}

impl From<SplitArg> for Split {
    fn from(split: SplitArg) -> Split {
        match split {
            SplitArg::All => Split::All,
            SplitArg::Train => Split::Train,
            SplitArg::Test => Split::Test,
        }
    }
}

/// The flags of `fogray render`.
#[derive(Debug, Clone, clap::Args)]
pub struct RenderArgs {
    /// A model written by `fogray fit --save-model`.
    #[arg(long, value_name = "FILE")]
    pub model: PathBuf,
    /// A dataset `fogray fit --data` reads (a folder of any of its formats, or a transforms
    /// file) whose frames are rendered (by default every one; a Blender folder: train, val and
    /// test frames).
    #[arg(
        long,
        value_name = "TRANSFORMS",
        required_unless_present = "orbit",
        conflicts_with = "orbit"
    )]
    pub cameras: Option<PathBuf>,
    /// Which frames of --cameras: every one, the ones `fogray fit --data` trains on, or the
    /// ones it holds out (a Blender folder's test split, else its val split, else every 8th
    /// frame; every 8th frame, `i % 8 == 0`, of any other format). Each PNG is named after its
    /// frame's image file without the extension.
    #[arg(long, value_enum, default_value_t = SplitArg::All, requires = "cameras")]
    pub split: SplitArg,
    /// Divide the cameras' image size, focal lengths and principal point by K.
    #[arg(long, default_value_t = 1, value_name = "K", conflicts_with = "orbit")]
    pub downscale: usize,
    // Clap waives an orbit flag's `requires = "orbit"` beside --cameras (which conflicts with
    // --orbit): each also conflicts with --cameras.
    /// Render N frames on a circle around the centre of the model's scene box instead (world
    /// +z up, as in Blender scenes), frame k at azimuth 360 k / N degrees from +x towards +y,
    /// each looking at the centre: DIR/frame-000.png ...
    #[arg(long, value_name = "N")]
    pub orbit: Option<usize>,
    /// The orbit's angle above the horizontal plane through the centre, in degrees, in
    /// (-90, 90) [default: 30].
    #[arg(
        long,
        value_name = "DEG",
        allow_negative_numbers = true,
        requires = "orbit",
        conflicts_with = "cameras"
    )]
    pub elevation: Option<f64>,
    /// The orbit's distance from the centre [default: the mean distance of the cameras of the
    /// model's dataset from the centre, else the distance at which the scene box's bounding
    /// sphere fits in the view].
    #[arg(
        long,
        value_name = "R",
        allow_negative_numbers = true,
        requires = "orbit",
        conflicts_with = "cameras"
    )]
    pub radius: Option<f64>,
    /// The orbit's image size [default: that of the model's dataset's first camera, else
    /// 200x200].
    #[arg(
        long,
        value_name = "WxH",
        requires = "orbit",
        conflicts_with_all = ["cameras", "width", "height"]
    )]
    pub size: Option<ImageSize>,
    /// The orbit's image width alone [default: --size's].
    #[arg(long, value_name = "W", requires = "orbit", conflicts_with = "cameras")]
    pub width: Option<usize>,
    /// The orbit's image height alone [default: --size's].
    #[arg(long, value_name = "H", requires = "orbit", conflicts_with = "cameras")]
    pub height: Option<usize>,
    /// The orbit's vertical field of view in degrees [default: that of the model's dataset's
    /// first camera, else 40].
    #[arg(
        long,
        value_name = "DEG",
        allow_negative_numbers = true,
        requires = "orbit",
        conflicts_with = "cameras"
    )]
    pub fov: Option<f64>,
    /// The directory of the PNGs, `DIR/<name>.png` with `<name>` the frame's file name
    /// without folder and extension (`frame-000` ... for an orbit).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Also write the orbit's frames as an animated GIF (looping forever, 20 frames a
    /// second, a 256-colour palette per frame).
    #[arg(long, value_name = "OUT.gif", requires = "orbit", conflicts_with = "cameras")]
    pub gif: Option<PathBuf>,
    /// Also write each frame's depth map, `DIR/<name>-depth.png`: the expected depth along
    /// the ray given that it stops, in the viridis colour map with a labelled colour bar, grey
    /// where the opacity is below 0.1.
    #[arg(long)]
    pub depth: bool,
}

/// A view to render and the stem of its files.
struct View {
    name: String,
    camera: PinholeCamera,
}

/// Runs `fogray render`: the paths written, one per line.
///
/// Errors: a flag outside its domain (one line naming it), a model file that is not a fogray
/// grid model, a bad transforms file (naming it), two frames of one name, a file that cannot
/// be written.
pub fn run(args: &RenderArgs) -> Result<String, CliError> {
    framing::check_flags(args)?;
    let saved = SavedModel::open(&args.model, "fogray render")?;
    let info = &saved.info;
    let views = views(args, info)?;
    render_memory::check_cameras(info, args.cameras.as_deref(), views.iter().map(|v| &v.camera))?;
    // Only a transforms file's names can clash (frame `a-depth` beside frame `a`'s depth map
    // too); an orbit's are numbered.
    if let Some(cameras) = &args.cameras {
        let mut names = std::collections::BTreeSet::new();
        for v in &views {
            let clash = !names.insert(v.name.clone()) || (args.depth && !names.insert(format!("{}-depth", v.name)));
            if clash {
                return Err(CliError::FrameNameClash {
                    path: cameras.clone(),
                    name: v.name.clone(),
                });
            }
        }
    }
    check_render_outputs(args, &views)?;
    let background = match info.extra.get("background") {
        Some(text) => serde_json::from_str::<[f64; 3]>(text).map_err(|e| CliError::SavedEntry {
            path: args.model.clone(),
            key: "background",
            text: text.clone(),
            reason: e.to_string(),
        })?,
        None => [1.0; 3],
    };
    // Started before the first frame, so that a GIF that cannot be created costs no render.
    let gif = match (&args.gif, views.first()) {
        (Some(path), Some(v)) => {
            let k = v.camera.intrinsics();
            Some(GifWriter::create(path, k.width, k.height)?)
        }
        _ => None,
    };
    // Removed again (while empty) if the render fails: a failed render leaves no empty folder.
    let mut created = crate::created_dirs::CreatedDirs::new();
    created.create(&args.out)?;
    let result = saved.with(Output {
        args,
        background,
        gif,
        views: &views,
    })?;
    created.keep();
    Ok(result)
}

/// Refuses, before any work, outputs that would land on the model or the dataset of
/// `--cameras` (a folder: anything inside it), a folder where a frame's file or the GIF goes,
/// and folders that cannot be written.
fn check_render_outputs(args: &RenderArgs, views: &[View]) -> Result<(), CliError> {
    let mut inputs = Inputs::new().file(&args.model);
    if let Some(cameras) = &args.cameras {
        inputs = inputs.dataset(cameras)?;
    }
    let mut files = Vec::with_capacity(views.len() * 2);
    for v in views {
        files.push(frame_file(args, &v.name, ""));
        if args.depth {
            files.push(frame_file(args, &v.name, "-depth"));
        }
    }
    let mut outputs = vec![Destination::Folder(&args.out)];
    outputs.extend(files.iter().map(|f| Destination::File(f)));
    outputs.extend(args.gif.as_deref().map(Destination::File));
    Ok(check_outputs(&inputs, &outputs)?)
}

/// `DIR/<name><suffix>.png`.
fn frame_file(args: &RenderArgs, name: &str, suffix: &str) -> PathBuf {
    args.out.join(format!("{name}{suffix}.png"))
}

/// The views the flags ask for: every frame of `--cameras`, or the orbit's.
fn views(args: &RenderArgs, info: &ModelInfo) -> Result<Vec<View>, CliError> {
    if let Some(cameras) = &args.cameras {
        return Ok(load_split_cameras(cameras, args.downscale, args.split.into())?
            .into_iter()
            .map(|c| View {
                name: c.name,
                camera: c.camera,
            })
            .collect());
    }
    let scene_box = info.settings.model_box();
    let centre: [f64; 3] = std::array::from_fn(|i| (scene_box.min[i] + scene_box.max[i]) / 2.0);
    let half_diagonal = (0..3)
        .map(|i| ((scene_box.max[i] - scene_box.min[i]) / 2.0).powi(2))
        .sum::<f64>()
        .sqrt();
    let dataset = framing::dataset_views(&args.model, info, centre);
    let (orbit, k) = framing::orbit_of(args, dataset.as_ref(), centre, half_diagonal)?;
    render_memory::check_orbit(info, orbit.frames, &k)?;
    let digits = (orbit.frames - 1).max(1).ilog10() as usize + 1;
    let cameras = orbit.cameras(k).map_err(|source| CliError::FlagOp {
        flag: "--orbit",
        source,
    })?;
    Ok(cameras
        .into_iter()
        .enumerate()
        .map(|(i, camera)| View {
            name: format!("frame-{i:0width$}", width = digits.max(3)),
            camera,
        })
        .collect())
}

/// The views to render and where their frames go.
struct Output<'a> {
    args: &'a RenderArgs,
    background: [f64; 3],
    gif: Option<GifWriter>,
    views: &'a [View],
}

impl WithModel for Output<'_> {
    type Output = String;

    fn run<F: Float, M: RadianceField<F>>(self, path: &Path) -> Result<String, CliError> {
        render_all::<F, M>(self, path)
    }
}

fn render_all<F: Float, M: RadianceField<F>>(mut output: Output<'_>, model: &Path) -> Result<String, CliError> {
    let (args, views) = (output.args, output.views);
    let saved = checkpoint::load::<F, M>(model)?;
    let occupancy = saved.occupancy_grid()?;
    let options = RenderOptions {
        background: output.background,
        method: Method::Fused,
        depth: args.depth,
    };
    let bar = indicatif::ProgressBar::new(views.len() as u64);
    if let Ok(style) = indicatif::ProgressStyle::with_template("render [{bar:40}] {pos}/{len} ({elapsed})") {
        bar.set_style(style.progress_chars("=> "));
    }
    let mut written = Vec::new();
    for v in views {
        let k = v.camera.intrinsics();
        let (origins, directions) = camera_rays(&v.camera);
        let picture = render_picture(
            &saved.start.model,
            occupancy.as_ref(),
            &origins,
            &directions,
            [k.height, k.width],
            &options,
        )?;
        // Each written whole: an interrupted render leaves whole files only.
        let path = frame_file(args, &v.name, "");
        write_png(&path, picture.color.view())?;
        written.push(shown(&path).to_string());
        if let Some(depth) = &picture.depth {
            let path = frame_file(args, &v.name, "-depth");
            // Magnified so that the bar's labels have room beside a small image.
            let scale = (DEPTH_MAP_SIDE / k.width.max(k.height)).max(1) as u32;
            write_depth_png(&path, depth.view(), &v.name, scale)?;
            written.push(shown(&path).to_string());
        }
        if let Some(gif) = output.gif.as_mut() {
            gif.push(picture.color.view())?;
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    if let Some(gif) = output.gif.take() {
        written.push(shown(&gif.finish()?).to_string());
    }
    Ok(written.join("\n"))
}

/// Depth maps of smaller images are magnified to about this many pixels on their longer side.
const DEPTH_MAP_SIDE: usize = 256;
