//! `fogray prepare IMAGES --out DIR`: a folder of photographs (or a phone video's frames)
//! posed by COLMAP, run as a child process, into the folder `fogray fit --data DIR` reads:
//! `DIR/images/` (the photographs, hard-linked or copied, names kept) and
//! `DIR/sparse/0/{cameras,images,points3D}.bin`, beside `DIR/colmap.log` (everything COLMAP
//! printed) and `DIR/database.db` (its features and matches).
//!
//! The steps are those of nerfstudio's `ns-process-data images` and instant-ngp's
//! `colmap2nerf.py`: feature extraction (one shared camera, OpenCV's lens model, on the
//! CPU), matching (exhaustive, or sequential for video frames), mapping. The mapper writes
//! into a temporary folder in `DIR`, renamed to `DIR/sparse` only once whole, its largest
//! model first: Ctrl-C, or a failure, leaves no half-written model behind.

mod checks;
mod colmap;
mod error;
mod images;
mod model;
mod progress;
mod step;
mod summary;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::ValueEnum;
use fogray_data::{escape_controls, shown};
use fogray_fit::interrupt::{StopFlag, INTERRUPTED_STATUS};

pub use error::PrepareError;
pub use summary::Prepared;

use colmap::{Colmap, Paths, Step};
use step::{Log, Place};

/// From how many photographs matching is sequential unless `--matching` says otherwise:
/// exhaustive matching compares every pair (time growing with the square of the count),
/// sequential matching each photograph with its neighbours in name order, which is how a
/// video's frames overlap.
pub const SEQUENTIAL_FROM: usize = 200;

/// The folder the mapper writes into, renamed to `sparse` when whole.
const PARTIAL: &str = ".sparse-partial";

/// Which pairs of photographs COLMAP matches.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Matching {
    /// Every pair: photographs taken in no particular order.
    Exhaustive,
    /// Each photograph with its neighbours in name order (and loop closure where COLMAP has a
    /// vocabulary tree): the frames of a video.
    Sequential,
}

impl Matching {
    /// The default for `count` photographs, and why, in words.
    pub fn for_count(count: usize) -> (Matching, String) {
        if count < SEQUENTIAL_FROM {
            let why = format!("under {SEQUENTIAL_FROM} photographs; --matching sequential suits video frames");
            (Matching::Exhaustive, why)
        } else {
            let why = format!(
                "{SEQUENTIAL_FROM} photographs or more, matched with their neighbours in name order as a video's \
                 frames overlap; --matching exhaustive for photographs taken in no order"
            );
            (Matching::Sequential, why)
        }
    }
}

/// The flags of `fogray prepare`.
#[derive(clap::Args, Debug, Clone)]
pub struct PrepareArgs {
    /// The folder of photographs (.jpg, .jpeg, .png, any case; its top level only): never
    /// moved or written.
    pub images: PathBuf,
    /// The folder to make (missing or empty, outside IMAGES): DIR/images, DIR/sparse/0,
    /// DIR/colmap.log, DIR/database.db.
    #[arg(long)]
    pub out: PathBuf,
    /// Which pairs COLMAP matches [default: exhaustive under 200 photographs, else
    /// sequential].
    #[arg(long, value_enum)]
    pub matching: Option<Matching>,
}

/// Runs `fogray prepare` and prints its outcome: the summary on stdout (exit status 0), one
/// line on stderr otherwise (exit status 2; 130 after Ctrl-C).
pub fn main(args: &PrepareArgs) -> ExitCode {
    match run(args) {
        Ok(prepared) => {
            println!("{prepared}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            let message = e.to_string().replace('\n', " ");
            let (what, status) = match e {
                PrepareError::Interrupted { .. } => ("", INTERRUPTED_STATUS),
                _ => ("error: ", 2),
            };
            eprintln!("fogray prepare: {what}{}", escape_controls(&message));
            ExitCode::from(status as u8)
        }
    }
}

/// Prepares `args.images` into `args.out` (see the [module docs](self)).
///
/// Errors: the refusals made before anything is written ([`PrepareError::NotAFolder`],
/// [`PrepareError::NoPhotographs`], [`PrepareError::OutInsideImages`],
/// [`PrepareError::OutNotEmpty`], [`PrepareError::NoColmap`]); then
/// [`PrepareError::StepFailed`], [`PrepareError::NoModel`], [`PrepareError::Interrupted`]
/// or [`PrepareError::File`], after which `DIR` holds no `sparse` folder.
pub fn run(args: &PrepareArgs) -> Result<Prepared, PrepareError> {
    let names = checks::photographs(&args.images)?;
    checks::output(&args.images, &args.out)?;
    let (matching, why) = match args.matching {
        Some(m) => (m, "--matching".to_string()),
        None => Matching::for_count(names.len()),
    };
    let colmap = Colmap::find(matching)?;
    let stop = StopFlag::on_ctrl_c()?;
    let out = args.out.as_path();
    eprintln!(
        "fogray prepare: {}, {} photographs, {} ({why})",
        colmap.version.as_deref().unwrap_or("COLMAP (version unknown)"),
        names.len(),
        Step::Matching(matching).name(),
    );
    std::fs::create_dir_all(out).map_err(PrepareError::file("create", out))?;
    let images = out.join("images");
    let placed = images::place(&args.images, &names, &images, &stop)?;
    if stop.is_raised() {
        return Err(PrepareError::Interrupted {
            step: "placing the photographs".to_string(),
            out: shown(out).to_string(),
        });
    }
    let mut log = Log::create(&out.join("colmap.log"))?;
    let partial = out.join(PARTIAL);
    std::fs::create_dir(&partial).map_err(PrepareError::file("create", &partial))?;
    let posed = pose(&colmap, matching, out, &images, &partial, &mut log, &stop);
    if posed.is_err() {
        // Removed so that no half-written model is left; an error removing it is not the one
        // to report.
        let _ = std::fs::remove_dir_all(&partial);
    }
    let renumbered = posed?;
    let sparse = out.join("sparse");
    std::fs::rename(&partial, &sparse).map_err(PrepareError::file("rename", &partial))?;
    Prepared::read(out, &names, placed, renumbered)
}

/// Runs the three steps and puts the largest model first, in `partial`; returns the folder
/// name COLMAP gave the largest model and how many models it made.
fn pose(
    colmap: &Colmap,
    matching: Matching,
    out: &Path,
    images: &Path,
    partial: &Path,
    log: &mut Log,
    stop: &StopFlag,
) -> Result<(String, usize), PrepareError> {
    let database = out.join("database.db");
    let paths = Paths {
        database: &database,
        images,
        models: partial,
    };
    let steps = [Step::Extraction, Step::Matching(matching), Step::Mapping];
    for (i, step) in steps.into_iter().enumerate() {
        let place = Place {
            number: i + 1,
            of: steps.len(),
        };
        step::run(step, &colmap.arguments(step, paths), place, log, stop, out)?;
    }
    let models = model::models(partial)?;
    let best = model::largest(&models).ok_or_else(|| PrepareError::NoModel { log: log.shown() })?;
    let first = partial.join("0");
    let chosen = &models[best].0;
    if *chosen != first {
        let swap = partial.join(".swap");
        let rename = |from: &Path, to: &Path| std::fs::rename(from, to).map_err(PrepareError::file("rename", from));
        if first.exists() {
            rename(&first, &swap)?;
        }
        rename(chosen, &first)?;
        if swap.exists() {
            rename(&swap, chosen)?;
        }
    }
    let number = chosen
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    Ok((number, models.len()))
}
