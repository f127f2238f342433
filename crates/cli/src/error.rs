//! Why a `fogray` command failed: the one line it prints on stderr (exit status 2) is the
//! error's message.

use std::path::{Path, PathBuf};

use fogray_data::shown;
use fogray_ops::OpsError;
use fogray_tape::TapeError;
use thiserror::Error;

/// Why a JSON input of `fogray composite` or `fogray gradcheck` was refused (the rules the
/// CLI adds to those of the op; the op's own errors name the ray and sample too).
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum InputError {
    /// Not JSON, or not of the input's format.
    #[error("invalid input JSON: {0}")]
    Json(#[source] serde_json::Error),
    /// A precision other than `f32` and `f64`.
    #[error("unknown precision {0:?} (expected \"f32\" or \"f64\")")]
    UnknownPrecision(String),
    /// `min_transmittance` outside `[0, 1]`.
    #[error("min_transmittance must be in [0, 1], got {0}")]
    MinTransmittance(f64),
    /// An empty `rays` list.
    #[error("rays: at least one ray is needed")]
    NoRays,
    /// Colours of zero channels.
    #[error("colours need at least one channel")]
    NoChannels,
    /// A per-sample list whose length is not the ray's number of samples.
    #[error("ray {ray}: {what} has {got} entries, sigma has {samples}")]
    SampleCount {
        /// The ray.
        ray: usize,
        /// Which list.
        what: &'static str,
        /// Its length.
        got: usize,
        /// The ray's number of samples (the length of its sigma).
        samples: usize,
    },
    /// A sample's colour whose channel count is not the input's.
    #[error("ray {ray}, sample {sample}: color has {got} channels, expected {channels}")]
    SampleChannels {
        /// The ray.
        ray: usize,
        /// The sample within the ray.
        sample: usize,
        /// Its channel count.
        got: usize,
        /// The input's channel count.
        channels: usize,
    },
    /// A per-ray colour (background, grad_color) whose channel count is not the input's.
    #[error("ray {ray}: {what} has {got} channels, expected {channels}")]
    RayChannels {
        /// The ray.
        ray: usize,
        /// Which value.
        what: &'static str,
        /// Its channel count.
        got: usize,
        /// The input's channel count.
        channels: usize,
    },
    /// A NaN or infinite number.
    #[error("{what} is not finite")]
    NotFinite {
        /// Where (`ray 2, sample 5: sigma`).
        what: String,
    },
    /// A number too large for an f32 input.
    #[error("{what} = {value} overflows f32")]
    OverflowsF32 {
        /// Where.
        what: String,
        /// The number.
        value: f64,
    },
    /// A `grad_depth` on a ray without sample depths.
    #[error("ray {0}: grad_depth needs t (the depth needs sample depths)")]
    GradDepthWithoutT(usize),
    /// A `min_transmittance` other than 0 asked of a taped method.
    #[error("min_transmittance is offered by the fused method only (the taped twins are exact)")]
    MinTransmittanceNotFused,
}

/// Why a `fogray` command failed.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum CliError {
    /// The JSON input was refused.
    #[error("{0}")]
    Input(#[from] InputError),
    /// An op refused its input (its message names the op, and the ray and sample).
    #[error("{0}")]
    Ops(#[from] OpsError),
    /// A tape operation failed.
    #[error("{0}")]
    Tape(#[from] TapeError),
    /// Arrays that do not fit the shapes built from them.
    #[error("{0}")]
    Shape(#[from] ndarray::ShapeError),
    /// The output could not be serialised.
    #[error("{0}")]
    Json(#[from] serde_json::Error),
    /// Standard input could not be read.
    #[error("cannot read standard input: {0}")]
    Stdin(#[source] std::io::Error),
    /// A file or directory could not be read, written or created.
    #[error("cannot {action} {path}: {source}")]
    File {
        /// `"read"`, `"write"` or `"create"`.
        action: &'static str,
        /// The path, as displayed.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// A dataset or camera file that could not be read (the message names the file).
    #[error("{0}")]
    Data(#[from] fogray_data::DataError),
    /// A fit that could not run.
    #[error("{0}")]
    Fit(#[from] fogray_fit::FitError),
    /// A model file that could not be written or read.
    #[error("{0}")]
    Checkpoint(#[from] fogray_fit::checkpoint::CheckpointError),
    /// An image that could not be written.
    #[error("{0}")]
    Image(#[from] fogray_fit::images::ImageError),
    /// A fit session that could not run (settings, model file, data).
    #[error("{0}")]
    Session(#[from] fogray_fit::session::SessionError),
    /// A flag's value outside its domain: the flag, the value as given when the line shows
    /// it, and the rule it breaks (as fogray-fit's `FitError::Setting`).
    #[error("{flag}{} {rule}", flag_value(.value))]
    Flag {
        /// The flag (`--opacity`).
        flag: &'static str,
        /// The value given, when the message shows it (`--projections 0` needs no repeat).
        value: Option<String>,
        /// The rule it breaks.
        rule: String,
    },
    /// A flag's value that the op it configures refuses (`--fov`, `--orbit`): the op's error
    /// holds the value and the rule.
    #[error("{flag}: {source}")]
    FlagOp {
        /// The flag.
        flag: &'static str,
        /// The op's refusal.
        source: OpsError,
    },
    /// Two flags given together that exclude each other.
    #[error("{first} and {second} both given: {why}")]
    FlagsExclude {
        /// The first flag.
        first: &'static str,
        /// The second.
        second: &'static str,
        /// Why only one of them can hold.
        why: &'static str,
    },
    /// A flag (or one of several) that the command needs and was not given.
    #[error("give {give}")]
    MissingFlag {
        /// The flags, with their values' names (`--data PATH, or --resume FILE`).
        give: &'static str,
    },
    /// A model file of a kind the command does not know (not a field's).
    #[error("{}: a {kind:?} model, which {command} does not know", shown(.path))]
    UnknownModelKind {
        /// The model file.
        path: PathBuf,
        /// The kind it names.
        kind: String,
        /// The command (`fogray render`).
        command: &'static str,
    },
    /// A model file without an entry a resumed fit needs (one not written by `fogray fit`).
    #[error("{} has no saved {key} (it was not written by fogray fit): give --{key}", shown(.path))]
    NoSavedEntry {
        /// The model file.
        path: PathBuf,
        /// The entry, also the flag that stands in for it.
        key: &'static str,
    },
    /// A model file's entry that cannot be read (its background, its dataset's downscale).
    #[error("{}: its saved {key} {text:?} cannot be read: {reason}", shown(.path))]
    SavedEntry {
        /// The model file.
        path: PathBuf,
        /// The entry.
        key: &'static str,
        /// Its text.
        text: String,
        /// The parser's reason.
        reason: String,
    },
    /// Two frames of a cameras file whose output files would have one name.
    #[error("{}: two frames' files are named {name:?} (their PNGs would overwrite each other)", shown(.path))]
    FrameNameClash {
        /// The cameras file (or dataset).
        path: PathBuf,
        /// The name the frames share.
        name: String,
    },
    /// Frames too large for a GIF.
    #[error("--gif: {width}x{height} frames, the format holds at most 65535 pixels each way")]
    GifTooLarge {
        /// The frames' width.
        width: usize,
        /// Their height.
        height: usize,
    },
    /// A frame of another size than the GIF's.
    #[error("{}: a frame of {got:?}, the GIF's are {}x{}x3", shown(.path), .size[1], .size[0])]
    GifFrame {
        /// The GIF.
        path: PathBuf,
        /// The frame's `(height, width, channels)`.
        got: (usize, usize, usize),
        /// The GIF's `[width, height]`.
        size: [u16; 2],
    },
    /// A GIF that could not be written.
    #[error("cannot write {}: {source}", shown(.path))]
    Gif {
        /// The GIF.
        path: PathBuf,
        /// The encoder's error.
        source: gif::EncodingError,
    },
    /// A page's port that cannot be listened on (`fogray view --port`, `fogray fit --view-port`).
    #[error("{flag} {port}: cannot listen on 127.0.0.1: {source}")]
    Listen {
        /// The flag that gave the port.
        flag: &'static str,
        /// The port.
        port: u16,
        /// Why.
        source: std::io::Error,
    },
    /// The thread that renders `fogray fit --view`'s frames, which could not be started.
    #[error("cannot start the page's render thread: {0}")]
    RenderThread(#[source] rayon::ThreadPoolBuildError),
    /// The address listened on, which the system would not tell.
    #[error("cannot read the address listened on: {0}")]
    ListenAddress(#[source] std::io::Error),
    /// A page's server that stopped on an error.
    #[error("serving {address}: {source}")]
    Serve {
        /// The address it served.
        address: std::net::SocketAddr,
        /// Why.
        source: std::io::Error,
    },
    /// report.md's text that could not be composed.
    #[error("report.md: {0}")]
    Report(#[source] std::fmt::Error),
    /// A size (of a render's frames, of the cameras' pictures) that needs more memory than
    /// the machine has, refused before anything was allocated.
    #[error(transparent)]
    TooLarge(#[from] fogray_ops::limits::TooLarge),
    /// Outputs that cannot fit in their disk's free space, refused before the work
    /// ([`crate::disk_room`]).
    #[error(
        "{} {} at least {need}; {} disk has {free} free",
        .outputs.join(" and "),
        if .outputs.len() > 1 { "need" } else { "needs" },
        if .outputs.len() > 1 { "their" } else { "its" }
    )]
    NoRoom {
        /// The outputs, each named with what it is (`m.safetensors (the model file)`).
        outputs: Vec<String>,
        /// The fewest bytes they take together.
        need: fogray_ops::limits::Bytes,
        /// The bytes free on their disk.
        free: fogray_ops::limits::Bytes,
    },
    /// A computation that should have produced a value did not (a gradient missing...).
    #[error("{0}")]
    Missing(&'static str),
    /// Something asked of a fit before it has it, or more than it gives while it trains (a
    /// frame of `fogray fit --view` before the first step, or larger than it renders then).
    #[error("{0}")]
    NotYet(String),
}

/// A flag's value as its message shows it: ` 0:` after the flag, or nothing where the rule reads
/// on from the flag (`--projections must be at least 1`).
fn flag_value(value: &Option<String>) -> String {
    value.as_ref().map(|v| format!(" {v}:")).unwrap_or_default()
}

impl CliError {
    /// A file operation's error, naming the path.
    pub fn file<'a>(action: &'static str, path: &'a Path) -> impl FnOnce(std::io::Error) -> CliError + 'a {
        move |source| CliError::File {
            action,
            path: fogray_data::shown(path).to_string(),
            source,
        }
    }
}

#[cfg(test)]
mod tests;
