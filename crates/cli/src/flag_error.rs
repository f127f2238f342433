//! Flag errors in one line: clap's message, without the usage block and the "For more
//! information" line that follow it, any "tip:" folded onto the same line, prefixed like the
//! command's own errors (`fogray render: error: ...`) and with control characters escaped, so
//! that a script reading stderr sees one line per failure, whatever refused it.

use clap::error::ErrorKind;
use fogray_data::escape_controls;

/// The one line to print for `error`, a parse error of `fogray` whose subcommand is
/// `subcommand` (when the command line named one).
pub fn one_line(error: &clap::Error, subcommand: Option<&str>) -> String {
    // clap writes paragraphs separated by blank lines: the error (whose later lines list the
    // missing arguments or the possible values), tips, the usage, a pointer to --help.
    let text = error.render().to_string();
    let mut paragraphs = Vec::new();
    let mut current: Vec<&str> = Vec::new();
    for line in text.lines().map(str::trim).chain([""]) {
        if line.is_empty() {
            if !current.is_empty() {
                paragraphs.push(current.join(" "));
                current.clear();
            }
        } else {
            current.push(line);
        }
    }
    let kept: Vec<&str> = paragraphs
        .iter()
        .map(|p| p.strip_prefix("error:").map_or(p.as_str(), str::trim))
        .filter(|p| !p.starts_with("Usage:") && !p.starts_with("For more information"))
        .collect();
    let message = kept.join("; ");
    let prefix = match subcommand {
        Some(name) => format!("fogray {name}"),
        None => "fogray".to_string(),
    };
    format!("{prefix}: error: {}", escape_controls(&message))
}

/// Whether clap's own output for `error` is the one to show: help and version (on stdout,
/// exit status 0), and the help printed when no subcommand is given.
pub fn is_help(error: &clap::Error) -> bool {
    matches!(
        error.kind(),
        ErrorKind::DisplayHelp | ErrorKind::DisplayVersion | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::{Arg, Command};

    fn command() -> Command {
        Command::new("fogray").subcommand(
            Command::new("render")
                .arg(Arg::new("size").long("size").value_parser(clap::value_parser!(u32)))
                .arg(Arg::new("orbit").long("orbit").conflicts_with("cameras"))
                .arg(Arg::new("cameras").long("cameras")),
        )
    }

    fn refusal(args: &[&str]) -> String {
        let error = command().try_get_matches_from(args).unwrap_err();
        assert!(!is_help(&error));
        one_line(&error, Some("render"))
    }

    #[test]
    fn usage_and_hints_are_dropped_or_folded() {
        let line = refusal(&["fogray", "render", "--size", "32x"]);
        assert!(
            line.starts_with("fogray render: error: invalid value '32x' for '--size"),
            "{line}"
        );
        let line = refusal(&["fogray", "render", "--orbit", "3", "--cameras", "c.json"]);
        assert!(line.contains("cannot be used with"), "{line}");
        // The missing argument is named on the error's second line: folded in.
        let required = Command::new("fogray").arg(Arg::new("mesh").long("mesh").required(true));
        let error = required.try_get_matches_from(["fogray"]).unwrap_err();
        let line = one_line(&error, None);
        assert!(
            line.starts_with("fogray: error: the following required arguments were not provided: --mesh"),
            "{line}"
        );
        // A misspelt flag: clap's tip names the right one; its usage and pointer to --help go.
        let line = refusal(&["fogray", "render", "--sise", "3"]);
        assert!(
            line.contains("unexpected argument '--sise'") && line.contains("; tip:"),
            "{line}"
        );
        assert!(
            !line.contains('\n') && !line.contains("Usage") && !line.contains("--help"),
            "{line}"
        );
    }

    #[test]
    fn a_value_with_control_characters_is_escaped() {
        let line = refusal(&["fogray", "render", "--size", "a\rb\u{7}c"]);
        // clap drops some controls from what it renders (escape sequences, BEL) and keeps
        // others; none reaches the terminal raw.
        assert!(line.contains("'a\\rb"), "{line}");
        let line = refusal(&["fogray", "render", "--size", "\u{1b}[2J\u{0}"]);
        assert!(!line.chars().any(char::is_control), "{line}");
    }
}
