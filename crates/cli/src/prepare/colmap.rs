//! The `colmap` program: found on `PATH`, asked its version, and its command lines written
//! with the option names its version understands. COLMAP renamed its option groups across
//! releases (3.x `--SiftExtraction.use_gpu` / `--SiftMatching.use_gpu`, 4.x
//! `--FeatureExtraction.use_gpu` / `--FeatureMatching.use_gpu`), so the names are read from
//! each command's `-h` rather than assumed, as nerfstudio and instant-ngp's scripts, which
//! assume one, cannot.

use std::ffi::OsString;
use std::io::ErrorKind;
use std::path::Path;
use std::process::{Command, Stdio};

use super::error::PrepareError;
use super::Matching;

/// The program run: `colmap`, looked up on `PATH`.
pub const PROGRAM: &str = "colmap";

/// The installed COLMAP and the option names of its steps.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Colmap {
    /// `COLMAP 3.8` as its help's first line says it, if it does.
    pub version: Option<String>,
    /// The GPU switch of feature extraction (`--SiftExtraction.use_gpu`...), if offered.
    extraction_gpu: Option<&'static str>,
    /// The GPU switch of matching, if offered.
    matching_gpu: Option<&'static str>,
    /// Whether the commands take `--log_to_stderr` (3.x default to glog's files in /tmp,
    /// which would keep the mapper's messages out of colmap.log).
    log_to_stderr: bool,
}

/// A COLMAP step, in the order they run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// SIFT features of every photograph, into the database.
    Extraction,
    /// Matches between pairs of photographs, into the database.
    Matching(Matching),
    /// Incremental structure from motion: the sparse models.
    Mapping,
}

impl Step {
    /// Its name in messages.
    pub fn name(self) -> &'static str {
        match self {
            Step::Extraction => "feature extraction",
            Step::Matching(Matching::Exhaustive) => "exhaustive matching",
            Step::Matching(Matching::Sequential) => "sequential matching",
            Step::Mapping => "mapping",
        }
    }

    /// The COLMAP command that runs it.
    pub fn command(self) -> &'static str {
        match self {
            Step::Extraction => "feature_extractor",
            Step::Matching(Matching::Exhaustive) => "exhaustive_matcher",
            Step::Matching(Matching::Sequential) => "sequential_matcher",
            Step::Mapping => "mapper",
        }
    }
}

/// Where a run reads and writes.
#[derive(Debug, Clone, Copy)]
pub struct Paths<'a> {
    /// The database (`DIR/database.db`).
    pub database: &'a Path,
    /// The photographs (`DIR/images`).
    pub images: &'a Path,
    /// The folder the mapper writes its models into (a temporary one in `DIR`).
    pub models: &'a Path,
}

/// Runs `colmap ARGS` and returns what it printed on stdout and stderr together.
fn help_text(args: &[&str]) -> Result<String, PrepareError> {
    let output = Command::new(PROGRAM)
        .args(args)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| match e.kind() {
            ErrorKind::NotFound => PrepareError::NoColmap,
            _ => PrepareError::CannotRun(e),
        })?;
    let mut text = String::from_utf8_lossy(&output.stdout).into_owned();
    text.push_str(&String::from_utf8_lossy(&output.stderr));
    Ok(text)
}

/// The first of `names` that `help` lists as an option (`--NAME`), without the dashes.
fn offered(help: &str, names: &[&'static str]) -> Option<&'static str> {
    names
        .iter()
        .find(|name| {
            help.split_whitespace()
                .any(|word| word.strip_prefix("--") == Some(**name))
        })
        .copied()
}

/// `COLMAP 3.8` from a help text's line `COLMAP 3.8 -- Structure-from-Motion...`.
fn version(help: &str) -> Option<String> {
    let line = help.lines().find(|l| l.starts_with("COLMAP "))?;
    let number = line.split_whitespace().nth(1)?;
    Some(format!("COLMAP {number}"))
}

impl Colmap {
    /// Finds `colmap` on `PATH` and reads the option names of the steps a run with `matching`
    /// takes (three short `-h` runs).
    ///
    /// Errors: [`PrepareError::NoColmap`] if there is no `colmap` on `PATH`,
    /// [`PrepareError::CannotRun`] if it cannot be started.
    pub fn find(matching: Matching) -> Result<Colmap, PrepareError> {
        let main = help_text(&["-h"])?;
        let extraction = help_text(&[Step::Extraction.command(), "-h"])?;
        let matcher = help_text(&[Step::Matching(matching).command(), "-h"])?;
        Ok(Colmap::from_help(&main, &extraction, &matcher))
    }

    /// What the help texts of `colmap -h`, `colmap feature_extractor -h` and the matcher's
    /// `-h` say.
    pub fn from_help(main: &str, extraction: &str, matcher: &str) -> Colmap {
        Colmap {
            version: version(main).or_else(|| version(extraction)),
            extraction_gpu: offered(extraction, &["FeatureExtraction.use_gpu", "SiftExtraction.use_gpu"]),
            matching_gpu: offered(matcher, &["FeatureMatching.use_gpu", "SiftMatching.use_gpu"]),
            log_to_stderr: offered(extraction, &["log_to_stderr"]).is_some(),
        }
    }

    /// The arguments of `step` (after `colmap`): one camera shared by every photograph,
    /// OpenCV's lens model (which fogray reads), on the CPU (the GPU switch where offered: a
    /// COLMAP built without CUDA refuses `use_gpu 1` only at run time, and one built with it
    /// needs a display for SiftGPU's OpenGL path).
    pub fn arguments(&self, step: Step, paths: Paths<'_>) -> Vec<OsString> {
        let mut args: Vec<OsString> = vec![step.command().into(), "--database_path".into(), paths.database.into()];
        let mut push = |name: &str, value: &str| {
            args.push(format!("--{name}").into());
            args.push(value.into());
        };
        if self.log_to_stderr {
            push("log_to_stderr", "1");
        }
        match step {
            Step::Extraction => {
                push("ImageReader.single_camera", "1");
                push("ImageReader.camera_model", "OPENCV");
                if let Some(gpu) = self.extraction_gpu {
                    push(gpu, "0");
                }
            }
            Step::Matching(_) => {
                if let Some(gpu) = self.matching_gpu {
                    push(gpu, "0");
                }
            }
            Step::Mapping => {}
        }
        if matches!(step, Step::Extraction | Step::Mapping) {
            args.push("--image_path".into());
            args.push(paths.images.into());
        }
        if step == Step::Mapping {
            args.push("--output_path".into());
            args.push(paths.models.into());
        }
        args
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Excerpts of COLMAP 3.8's help texts (Debian's build).
    const MAIN_3_8: &str = "COLMAP 3.8 -- Structure-from-Motion and Multi-View Stereo\n  \
                            (Commit Unknown on Unknown without CUDA)\n\nUsage:\n  colmap [command] [options]\n";
    const EXTRACTOR_3_8: &str = "COLMAP 3.8 (Commit Unknown on Unknown without CUDA)\n\n  -h [ --help ] \n  \
                                 --log_to_stderr arg (=0)\n  --database_path arg\n  \
                                 --ImageReader.camera_model arg (=SIMPLE_RADIAL)\n  \
                                 --SiftExtraction.num_threads arg (=-1)\n  --SiftExtraction.use_gpu arg (=1)\n";
    const MATCHER_3_8: &str = "  --SiftMatching.num_threads arg (=-1)\n  --SiftMatching.use_gpu arg (=1)\n  \
                               --SiftMatching.gpu_index arg (=-1)\n";
    /// The 4.x names.
    const EXTRACTOR_4: &str = "  --log_to_stderr arg (=1)\n  --FeatureExtraction.use_gpu arg (=1)\n  \
                               --SiftExtraction.max_num_features arg (=8192)\n";
    const MATCHER_4: &str = "  --FeatureMatching.use_gpu arg (=1)\n  --SiftMatching.max_ratio arg (=0.8)\n";

    fn strings(args: &[OsString]) -> Vec<&str> {
        args.iter().map(|a| a.to_str().unwrap()).collect()
    }

    fn paths() -> Paths<'static> {
        Paths {
            database: Path::new("out/database.db"),
            images: Path::new("out/images"),
            models: Path::new("out/.sparse-partial"),
        }
    }

    #[test]
    fn the_3_8_names_are_read_from_its_help() {
        let colmap = Colmap::from_help(MAIN_3_8, EXTRACTOR_3_8, MATCHER_3_8);
        assert_eq!(colmap.version.as_deref(), Some("COLMAP 3.8"));
        let args = colmap.arguments(Step::Extraction, paths());
        assert_eq!(
            strings(&args),
            [
                "feature_extractor",
                "--database_path",
                "out/database.db",
                "--log_to_stderr",
                "1",
                "--ImageReader.single_camera",
                "1",
                "--ImageReader.camera_model",
                "OPENCV",
                "--SiftExtraction.use_gpu",
                "0",
                "--image_path",
                "out/images"
            ]
        );
        let args = colmap.arguments(Step::Matching(Matching::Sequential), paths());
        assert_eq!(
            strings(&args),
            [
                "sequential_matcher",
                "--database_path",
                "out/database.db",
                "--log_to_stderr",
                "1",
                "--SiftMatching.use_gpu",
                "0"
            ]
        );
        let args = colmap.arguments(Step::Mapping, paths());
        assert_eq!(
            strings(&args),
            [
                "mapper",
                "--database_path",
                "out/database.db",
                "--log_to_stderr",
                "1",
                "--image_path",
                "out/images",
                "--output_path",
                "out/.sparse-partial"
            ]
        );
    }

    #[test]
    fn the_4_x_names_are_preferred_where_offered() {
        let colmap = Colmap::from_help("COLMAP 4.0.1 -- Structure-from-Motion", EXTRACTOR_4, MATCHER_4);
        assert_eq!(colmap.version.as_deref(), Some("COLMAP 4.0.1"));
        let args = strings(&colmap.arguments(Step::Extraction, paths()))
            .into_iter()
            .map(String::from)
            .collect::<Vec<_>>();
        assert!(args.contains(&"--FeatureExtraction.use_gpu".to_string()), "{args:?}");
        assert!(!args.iter().any(|a| a.starts_with("--Sift")), "{args:?}");
        let args = colmap.arguments(Step::Matching(Matching::Exhaustive), paths());
        assert_eq!(strings(&args)[0], "exhaustive_matcher");
        assert!(strings(&args).contains(&"--FeatureMatching.use_gpu"));
    }

    #[test]
    fn options_a_version_lacks_are_left_out() {
        // A prefix of a name is not the name.
        let colmap = Colmap::from_help("", "--SiftExtraction.use_gpu_x arg", "");
        assert_eq!(colmap.version, None);
        let args = colmap.arguments(Step::Extraction, paths());
        assert!(!strings(&args)
            .iter()
            .any(|a| a.contains("use_gpu") || a.contains("log_to")));
        let args = colmap.arguments(Step::Matching(Matching::Exhaustive), paths());
        assert_eq!(
            strings(&args),
            ["exhaustive_matcher", "--database_path", "out/database.db"]
        );
    }
}
