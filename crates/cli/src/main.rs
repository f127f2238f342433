//! `fogray`: the command line of the fogray workspace (contracts in `docs/cli.md`).

use std::io::Read;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::parser::ValueSource;
use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};

use fogray_cli::error::CliError;
use fogray_cli::evaluate::CompositeMethod;
use fogray_cli::{composite, export, fit, flag_error, gradcheck, input, render};
use fogray_fit::interrupt::exit_on_ctrl_c;

#[derive(Parser)]
#[command(
    name = "fogray",
    version,
    about = "Differentiable volume rendering: the fused composite and its taped twins"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Fit a scene from a dataset on disk (Blender / NeRF-synthetic, instant-ngp or
    /// nerfstudio, COLMAP, LLFF): train on its training views, measure the held-out views (the
    /// test split, else every 8th view) at intervals off the clock, and print the log.
    // The defaults are the library's recommended settings (FitSettings::RECOMMENDED, which
    // says why each differs from FitSettings::DEFAULT).
    // Negative numbers are values (`--lr -1` is a bad rate, refused by name, not a flag).
    #[command(
        allow_negative_numbers = true,
        long_about = FIT_HELP,
        mut_arg("sh_degree", |a| a.default_value(fit::recommended("sh_degree"))),
        mut_arg("model", |a| a.default_value(fit::recommended("model"))),
        mut_arg("grid", |a| a.default_value(fit::recommended("grid")).help(fit::GRID_HELP)),
        mut_arg("tv", |a| a.default_value(fit::recommended("tv"))),
        mut_arg("lr", |a| a.default_value(fit::recommended("lr"))),
        mut_arg("lr_final", |a| a.default_value(fit::recommended("lr_final"))),
        mut_arg("distortion", |a| a.default_value(fit::recommended("distortion"))),
        mut_arg("space", |a| a.default_value(fit::recommended("space")))
    )]
    Fit(Box<fit::FitArgs>),
    /// Render a model saved by `fogray fit --save-model` from every camera of a transforms
    /// file, or from N cameras orbiting its scene box: `DIR/<name>.png`, 8-bit RGB, over the
    /// model's background; with --depth its depth maps, with --gif (an orbit) an animated GIF.
    #[command(allow_negative_numbers = true)]
    Render(render::RenderArgs),
    /// Export a model saved by `fogray fit --save-model` for other tools: --mesh OUT.ply, the
    /// surface where its density crosses a level (marching cubes), binary PLY with vertex
    /// colours, which MeshLab, Blender and trimesh open.
    #[command(allow_negative_numbers = true)]
    Export(export::ExportArgs),
    /// Pose a folder of photographs (or a video's frames) with COLMAP, run as a child process,
    /// into the folder `fogray fit --data DIR` reads: DIR/images (the photographs, linked or
    /// copied) and DIR/sparse/0, beside DIR/colmap.log. Needs `colmap` on PATH.
    Prepare(fogray_cli::prepare::PrepareArgs),
    /// Look at a model saved by `fogray fit --save-model` in the browser: a page served on
    /// 127.0.0.1 (the address is printed) where dragging orbits the camera, shift- or
    /// right-dragging pans and the wheel zooms; frames rendered as `fogray render` renders
    /// them. Ctrl-C stops it (exit status 130).
    #[command(allow_negative_numbers = true)]
    View(fogray_cli::view::ViewArgs),
    /// Composite packed rays given as JSON; print colour, opacity, depth, weights, transmittance
    /// and, with grad_color, the gradients, as JSON.
    #[command(long_about = COMPOSITE_HELP)]
    Composite {
        /// Which implementation computes it.
        #[arg(long, value_enum, default_value = "fused")]
        method: CompositeMethod,
        /// JSON input file, or - for standard input.
        #[arg(long, default_value = "-")]
        input: PathBuf,
        /// Print only these fields of each ray (comma-separated, in output order whatever the
        /// order given); default: every field.
        #[arg(long, value_enum, value_delimiter = ',', conflicts_with = "per_ray")]
        fields: Vec<composite::Field>,
        /// Print only the per-ray fields: color, opacity, depth, grad_background (no array
        /// as long as the ray). The same as --fields color,opacity,depth,grad_background.
        #[arg(long)]
        per_ray: bool,
    },
    /// Check the fused op's gradient (in the input's precision) against the stable taped twin
    /// and finite differences (f64); exit status 1 if any entry is outside the tolerance.
    #[command(long_about = GRADCHECK_HELP)]
    Gradcheck {
        /// JSON input file (the format of `fogray composite`), or - for standard input.
        #[arg(long, default_value = "-")]
        input: PathBuf,
        /// Absolute tolerance [default: 1e-6 for f64 input, 1e-4 for f32].
        #[arg(long)]
        atol: Option<f64>,
        /// Relative tolerance [default: 1e-5 for f64 input, 1e-3 for f32].
        #[arg(long)]
        rtol: Option<f64>,
        /// Check random directional derivatives instead of every element: time linear in the
        /// number of samples (full mode costs each ray's squared length).
        #[arg(long)]
        fast: bool,
        /// Number of random directions with --fast.
        #[arg(long, default_value_t = 8)]
        projections: usize,
        /// Seed of the random directions.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// How many of the worst comparisons to print.
        #[arg(long, default_value_t = 5)]
        worst: usize,
        /// Print the report as JSON.
        #[arg(long)]
        json: bool,
    },
}

const FIT_HELP: &str = r#"Fit a scene from a dataset on disk.

--data is a Blender / NeRF-synthetic folder (transforms_train.json, and transforms_test.json or
transforms_val.json if present), an instant-ngp or nerfstudio folder (transforms.json), a COLMAP
folder (sparse/0, sparse or colmap/sparse/0, binary or text, beside images/), an LLFF folder
(poses_bounds.npy beside images/), or a transforms file; the format is recognised by its files.
Held out: the test split, else the val split, else every 8th frame (i % 8 == 0; COLMAP and LLFF
in image-name order). Images (PNG 8 or 16 bits, JPEG; grey, RGB or RGBA) are composited over
--background.

--space auto (the default) looks at the pictures: views with alpha, or whose borders are one plain
colour, show an object and are fitted in the scene box (--box, else the dataset's: [-1.5, 1.5]^3
for Blender, instant-ngp's aabb_scale); other captures are fitted in a contracted space framed
from the cameras (an inner ball where they look, everything beyond it mapped into a shell). The
report and --json say which was chosen and why.

The defaults are the recommended configuration: `fogray fit --data DIR --downscale 4` is a
whole fit. Ctrl-C stops after the current step and saves the model (to --save-model, else
fogray-model.safetensors in --out or here), exit status 130; `fogray fit --resume FILE`
continues it.

--json prints {"final_test_psnr", "final_test_psnr_view_mean", "train_views_psnr", "seconds",
"steps", "log": [{"step", "seconds", "train_loss", "test_psnr", "samples"}], "views", "size",
"load_seconds"}: final_test_psnr is the PSNR of the mean squared error over the held-out views,
final_test_psnr_view_mean the mean of their own PSNRs (the figure papers and nerfstudio report;
never lower for views of one size); train_views_psnr is the PSNR on as many training views as held-out ones, and its gap to
final_test_psnr how much the fit learnt its own views rather than the scene; a progress bar on
stderr otherwise. A bad dataset: exit status 2, one line on stderr naming the file."#;

const COMPOSITE_HELP: &str = r#"Composite packed rays (the emission-absorption model: w_k = T_k (1 - exp(-sigma_k delta_k)),
C = sum w_k c_k + T_end c_bg).

Input (JSON):
  { "precision": "f64",            "f32" or "f64" (default f64)
    "min_transmittance": 0.0,      optional early termination (fused only; 0 = exact)
    "rays": [ { "sigma": [..],     density per sample (1/m), finite, >= 0
                "delta": [..],     sample length (m), finite, >= 0
                "color": [[r,g,b], ..]   any number of channels, the same everywhere
                "background": [r,g,b],   optional, default all zeros
                "t": [..],         optional sample depths: enables "depth"
                "grad_color": [gr,gg,gb] optional dL/dC: enables the grad_* outputs
                "grad_depth": g    optional dL/ddepth (needs t): adds g * depth to the
                                   loss and enables grad_t
              } ] }

Output (JSON, one object per ray):
  { "rays": [ { "color": [..], "opacity": x, "depth": x or null,
                "weights": [..], "transmittance": [..],      T before each sample
                "grad_sigma": [..], "grad_delta": [..],
                "grad_color": [[..], ..], "grad_background": [..],
                "grad_t": [..] } ] }                       (rays with grad_depth)

--fields color,opacity,... prints only those fields; --per-ray only color, opacity, depth
and grad_background (a ray of ten million samples then prints a few numbers).

depth is the unnormalised expected depth sum w_k t_k. Bad input: exit status 2, one line on
stderr naming the ray and sample, nothing on stdout.

Example:
  echo '{"rays":[{"sigma":[0,0.5,2,8],"delta":[0.5,0.5,0.5,0.5],"color":[[0.9],[0.2],[0.9],[0.4]],"background":[1],"grad_color":[1]}]}' | fogray composite"#;

const GRADCHECK_HELP: &str = r#"Check the fused composite's gradient on a JSON input (the format of fogray composite).

The loss is L = sum(grad_color . color) + sum(grad_depth depth), with the input's grad_color
and grad_depth; where a ray gives none, ones are used and the output says so (a note line).
The gradients of sigma, delta, color, background and t (rays with t) are computed by the fused
op in the input's precision ("precision": "f32" computes in f32, at the input rounded to f32)
and compared with
  - the stable taped twin in f64, every element;
  - finite differences of the fused op in f64, every element, ray by ray (central, step 1e-6
    relative; one-sided where sigma or delta is within a step of 0, their lower bound), or
    with --fast along random unit directions through every input (step 1e-5; central through
    the elements the step keeps at or above 0, and a second, one-sided and inward direction
    through the samples at or next to 0), in time linear in the number of samples.
Each comparison passes if |fused - reference| <= atol + rtol |reference|. Defaults: atol 1e-6,
rtol 1e-5 for f64 input; atol 1e-4, rtol 1e-3 for f32 input.

Output: a table per input and reference (checked, failing, worst difference and where: ray,
sample, channel, or direction), the worst comparisons, and PASS or FAIL (--json: the same
as JSON). Exit status: 0 if every comparison passes, 1 if any fails, 2 on bad input (one line
on stderr, e.g. the composite's own message for a negative density).

Example:
  echo '{"rays":[{"sigma":[0,0.5,2,8],"delta":[0.5,0.5,0.5,0.5],"color":[[0.9],[0.2],[0.9],[0.4]],"background":[1],"grad_color":[1]}]}' | fogray gradcheck"#;

fn read_input(path: &PathBuf) -> Result<String, CliError> {
    let mut text = String::new();
    if path.as_os_str() == "-" {
        std::io::stdin().read_to_string(&mut text).map_err(CliError::Stdin)?;
    } else {
        text = std::fs::read_to_string(path).map_err(CliError::file("read", path))?;
    }
    Ok(text)
}

/// A flag error in one line on stderr, exit status 2 (help and version: clap's own output).
fn refuse_flags(error: clap::Error) -> ExitCode {
    if flag_error::is_help(&error) {
        error.exit()
    }
    let names: Vec<String> = Cli::command()
        .get_subcommands()
        .map(|c| c.get_name().to_string())
        .collect();
    let subcommand = std::env::args().skip(1).find(|a| names.contains(a));
    eprintln!("{}", flag_error::one_line(&error, subcommand.as_deref()));
    ExitCode::from(2)
}

fn main() -> ExitCode {
    let matches = match Cli::command().try_get_matches() {
        Ok(matches) => matches,
        Err(e) => return refuse_flags(e),
    };
    let cli = match Cli::from_arg_matches(&matches) {
        Ok(cli) => cli,
        Err(e) => return refuse_flags(e),
    };
    let (name, result) = match &cli.command {
        Command::Fit(args) => match fit::run(args, &|id| {
            matches.subcommand_matches("fit").and_then(|m| m.value_source(id)) == Some(ValueSource::CommandLine)
        }) {
            Ok(fit::FitOutcome::Done(text)) => ("fit", Ok(text)),
            // Printed when the fit ended; the page then served until Ctrl-C.
            Ok(fit::FitOutcome::Served) => return ExitCode::SUCCESS,
            Ok(fit::FitOutcome::Interrupted(path)) => {
                eprintln!(
                    "fogray fit: interrupted: the fit is saved to {0} (continue it with fogray fit --resume {0})",
                    fogray_data::shown(&path)
                );
                // 128 + SIGINT, as a shell reports a command stopped by Ctrl-C.
                return ExitCode::from(130);
            }
            Err(e) => ("fit", Err(e)),
        },
        // Nothing to save on Ctrl-C: exit 130 at once, leaving whole files only.
        Command::Render(args) => (
            "render",
            exit_on_ctrl_c()
                .map_err(CliError::from)
                .and_then(|()| render::run(args)),
        ),
        // Prints its own outcome: Ctrl-C stops COLMAP and exits 130, leaving no model half-written.
        Command::Prepare(args) => return fogray_cli::prepare::main(args),
        Command::View(args) => match fogray_cli::view::run(args) {
            Ok(()) => {
                eprintln!("fogray view: stopped");
                // 128 + SIGINT: the server only stops on Ctrl-C.
                return ExitCode::from(130);
            }
            Err(e) => ("view", Err(e)),
        },
        Command::Export(args) => (
            "export",
            exit_on_ctrl_c()
                .map_err(CliError::from)
                .and_then(|()| export::run(args)),
        ),
        Command::Composite {
            method,
            input,
            fields,
            per_ray,
        } => {
            use composite::Field;
            let fields: &[Field] = match (fields.is_empty(), per_ray) {
                (_, true) => &Field::PER_RAY,
                (true, false) => &Field::ALL,
                (false, false) => fields,
            };
            (
                "composite",
                read_input(input)
                    .and_then(|t| Ok(input::parse(&t)?))
                    .and_then(|p| composite::run(&p, *method, fields)),
            )
        }
        Command::Gradcheck {
            input,
            atol,
            rtol,
            fast,
            projections,
            seed,
            worst,
            json,
        } => {
            let settings = gradcheck::Settings {
                atol: *atol,
                rtol: *rtol,
                fast: *fast,
                projections: *projections,
                seed: *seed,
                json: *json,
                worst: *worst,
            };
            let outcome = read_input(input)
                .and_then(|t| Ok(input::parse(&t)?))
                .and_then(|p| gradcheck::run(p, &settings));
            match outcome {
                // Exit status 1: the check ran and found a disagreement.
                Ok(o) => {
                    println!("{}", o.text);
                    return if o.passed { ExitCode::SUCCESS } else { ExitCode::from(1) };
                }
                Err(e) => ("gradcheck", Err(e)),
            }
        }
    };
    match result {
        Ok(out) => {
            println!("{out}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            // One line: the reason, with any newline of a nested message folded and the control
            // characters of a name read from a file escaped.
            let message = e.to_string().replace('\n', " ");
            eprintln!("fogray {name}: error: {}", fogray_data::escape_controls(&message));
            ExitCode::from(2)
        }
    }
}
