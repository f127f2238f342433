//! Names shown on a terminal with their control characters escaped.
//!
//! A file name, or a `file_path` in a transforms file, may hold any byte but `/` and NUL:
//! an ESC followed by `[2J` clears the screen of whoever reads the error, a carriage return
//! overwrites the start of the line. Every path and name that fogray prints or puts in an
//! error goes through [`escape_controls`] (or [`shown`] for a path), which writes each control
//! character (U+0000 to U+001F, U+007F to U+009F) as Rust writes it in a string literal:
//! `\n`, `\r`, `\t`, `\0`, else `\u{1b}`. Every other character, non-ASCII ones included, is
//! kept.
//!
//! ```
//! use fogray_data::{escape_controls, shown};
//! use std::path::Path;
//!
//! assert_eq!(escape_controls("red\u{1b}[31m\n"), "red\\u{1b}[31m\\n");
//! assert_eq!(escape_controls("café.png"), "café.png");
//! assert_eq!(shown(Path::new("a\u{7f}/b")).to_string(), "a\\u{7f}/b");
//! ```

use std::borrow::Cow;
use std::fmt;
use std::path::Path;

/// `text` with its control characters escaped (see the [module docs](self)); borrowed when it
/// has none.
pub fn escape_controls(text: &str) -> Cow<'_, str> {
    if !text.chars().any(char::is_control) {
        return Cow::Borrowed(text);
    }
    let mut out = String::with_capacity(text.len() + 8);
    for c in text.chars() {
        match c {
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            '\0' => out.push_str("\\0"),
            c if c.is_control() => out.push_str(&format!("\\u{{{:x}}}", u32::from(c))),
            c => out.push(c),
        }
    }
    Cow::Owned(out)
}

/// A path to print: [`Path::display`] (bytes that are not UTF-8 shown as U+FFFD) with its
/// control characters escaped.
pub fn shown(path: &Path) -> Shown<'_> {
    Shown(path)
}

/// What [`shown`] returns: a path that displays escaped.
#[derive(Debug, Clone, Copy)]
pub struct Shown<'a>(&'a Path);

impl fmt::Display for Shown<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let text = self.0.display().to_string();
        f.write_str(&escape_controls(&text))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_control_character_is_escaped_and_nothing_else() {
        // The C0 controls, DEL and the C1 controls; a space, a tilde and U+00A0 are not.
        for code in (0u32..0x20).chain(0x7f..0xa0) {
            let c = char::from_u32(code).unwrap();
            let escaped = escape_controls(&c.to_string()).into_owned();
            assert!(escaped.starts_with('\\'), "U+{code:04X} gave {escaped:?}");
            assert!(!escaped.chars().any(char::is_control), "U+{code:04X} gave {escaped:?}");
        }
        for text in [" ", "~", "\u{a0}", "ü", "日本", "a\\b"] {
            assert!(matches!(escape_controls(text), Cow::Borrowed(t) if t == text));
        }
    }

    #[test]
    fn escapes_read_as_rust_string_literals() {
        assert_eq!(escape_controls("\u{1b}[2J"), "\\u{1b}[2J");
        assert_eq!(escape_controls("a\0b\tc\rd"), "a\\0b\\tc\\rd");
        assert_eq!(escape_controls("\u{9b}"), "\\u{9b}");
        assert_eq!(shown(Path::new("x/\u{1b}y.png")).to_string(), "x/\\u{1b}y.png");
    }
}
