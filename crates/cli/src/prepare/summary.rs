//! What a finished `fogray prepare` says on stdout: how many photographs COLMAP registered
//! and which it left out, which model was kept, and the command that fits the folder.

use std::ffi::OsString;
use std::fmt;
use std::path::{Path, PathBuf};

use fogray_data::{escape_controls, shown};

use super::error::PrepareError;
use super::images::Placed;
use super::model;

/// How many left-out photographs are named (the count says how many in all).
const LEFT_OUT_LISTED: usize = 50;
/// The widest picture the suggested fit decodes: wider photographs get a `--downscale` that
/// brings them under it (a CPU fit of minutes rather than hours).
const FIT_WIDTH: u64 = 640;

/// A prepared folder.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Prepared {
    /// `--out`.
    pub out: PathBuf,
    /// Photographs given to COLMAP.
    pub photographs: usize,
    /// Photographs the kept model registers.
    pub registered: usize,
    /// The photographs it does not register, by name, sorted.
    pub left_out: Vec<String>,
    /// How the photographs were placed in `DIR/images`.
    pub placed: Placed,
    /// How many models COLMAP made.
    pub models: usize,
    /// The folder name COLMAP gave the kept model (`0` unless it made several).
    pub kept: String,
    /// The shared camera's width in pixels.
    pub width: Option<u64>,
}

impl Prepared {
    /// Reads what `out/sparse/0` registers of `names`.
    ///
    /// Errors: [`PrepareError::File`] for a model file (`images.bin`, `cameras.bin`) that
    /// cannot be opened, [`PrepareError::BadModel`] for one that ends early or counts more
    /// than its size holds.
    pub fn read(
        out: &Path,
        names: &[OsString],
        placed: Placed,
        (kept, models): (String, usize),
    ) -> Result<Prepared, PrepareError> {
        let model = out.join("sparse").join("0");
        let registered = model::registered_names(&model.join("images.bin"))?;
        let width = model::first_camera_width(&model.join("cameras.bin"))?;
        let left_out: Vec<String> = names
            .iter()
            .map(|n| n.to_string_lossy().into_owned())
            .filter(|n| !registered.contains(n))
            .collect();
        Ok(Prepared {
            out: out.to_path_buf(),
            photographs: names.len(),
            registered: names.len() - left_out.len(),
            left_out,
            placed,
            models,
            kept,
            width,
        })
    }

    /// The `--downscale` of the suggested fit, if one is needed.
    pub fn downscale(&self) -> Option<u64> {
        let width = self.width?;
        (width > FIT_WIDTH).then(|| width.div_ceil(FIT_WIDTH))
    }
}

/// `text` as one shell word: as it is if it holds only characters no shell treats
/// specially, else in single quotes.
fn shell_word(text: &str) -> String {
    let plain = |c: char| c.is_ascii_alphanumeric() || "/._-+,:@%".contains(c);
    if !text.is_empty() && text.chars().all(plain) {
        text.to_string()
    } else {
        format!("'{}'", text.replace('\'', r"'\''"))
    }
}

impl fmt::Display for Prepared {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let out = shown(&self.out).to_string();
        let model = shown(&self.out.join("sparse").join("0")).to_string();
        write!(
            f,
            "registered {} of {} photographs into {model}",
            self.registered, self.photographs
        )?;
        if !self.left_out.is_empty() {
            let listed: Vec<_> = self
                .left_out
                .iter()
                .take(LEFT_OUT_LISTED)
                .map(|n| escape_controls(n))
                .collect();
            write!(f, "; left out: {}", listed.join(", "))?;
            if self.left_out.len() > LEFT_OUT_LISTED {
                write!(f, " and {} more", self.left_out.len() - LEFT_OUT_LISTED)?;
            }
        }
        writeln!(f)?;
        if self.models > 1 {
            write!(
                f,
                "COLMAP made {} separate models (groups of photographs it could not pose together); ",
                self.models
            )?;
            if self.kept == "0" {
                writeln!(f, "the largest is sparse/0, the one fogray fit reads")?;
            } else {
                let kept = escape_controls(&self.kept);
                writeln!(
                    f,
                    "the largest, which it numbered {kept}, is moved to sparse/0 (and its sparse/0 to sparse/{kept})"
                )?;
            }
        }
        if self.placed.copied > 0 {
            writeln!(
                f,
                "{} photographs copied into {} (hard links were refused)",
                self.placed.copied,
                shown(&self.out.join("images"))
            )?;
        }
        let downscale = self
            .downscale()
            .map(|k| format!(" --downscale {k}"))
            .unwrap_or_default();
        write!(f, "fit it: fogray fit --data {}{downscale}", shell_word(&out))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn prepared(left_out: &[&str], models: usize, width: u64) -> Prepared {
        Prepared {
            out: PathBuf::from("my capture"),
            photographs: 12,
            registered: 12 - left_out.len(),
            left_out: left_out.iter().map(|s| s.to_string()).collect(),
            placed: Placed { linked: 12, copied: 0 },
            models,
            kept: "1".into(),
            width: Some(width),
        }
    }

    #[test]
    fn the_summary_names_the_left_out_and_the_fit_command() {
        let text = prepared(&["view_03.png", "view_07.png"], 2, 320).to_string();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(
            lines[0],
            "registered 10 of 12 photographs into my capture/sparse/0; left out: view_03.png, view_07.png"
        );
        assert!(
            lines[1].contains("2 separate models") && lines[1].contains("to sparse/1)"),
            "{text}"
        );
        assert_eq!(lines[2], "fit it: fogray fit --data 'my capture'");
    }

    #[test]
    fn wide_photographs_get_a_downscale_under_640_pixels() {
        // 4032 / 640 = 6.3: 7 brings it to 576 pixels.
        assert_eq!(prepared(&[], 1, 4032).downscale(), Some(7));
        assert_eq!(prepared(&[], 1, 1280).downscale(), Some(2));
        assert_eq!(prepared(&[], 1, 640).downscale(), None);
        let text = prepared(&[], 1, 1920).to_string();
        assert_eq!(text.lines().count(), 2, "{text}");
        assert!(text.ends_with("--downscale 3"), "{text}");
    }

    #[test]
    fn shell_words_are_quoted_where_a_shell_would_split_them() {
        assert_eq!(shell_word("out/cap_1"), "out/cap_1");
        assert_eq!(shell_word("it's here"), r"'it'\''s here'");
        assert_eq!(shell_word(""), "''");
    }
}
