//! `fogray-lego --replot` redraws the committed lego report from its report.json alone (the
//! runs' folders are not committed): the same report.json (stamp and runs, as the measuring
//! run wrote it) and the same report.md but for the line that says it was redrawn.

use std::path::{Path, PathBuf};
use std::process::Command;

fn report_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../reports/lego")
}

/// The report's lines without the paragraph saying it was redrawn (the line and the blank
/// line after it), so that a redrawn report compares equal to a measured one and to another
/// redrawn one.
fn without_redrawn_line(md: &str) -> Vec<&str> {
    let mut lines = Vec::new();
    let mut after_redrawn = false;
    for line in md.lines() {
        let skip = line.starts_with("Tables and plot redrawn") || (after_redrawn && line.is_empty());
        after_redrawn = line.starts_with("Tables and plot redrawn");
        if !skip {
            lines.push(line);
        }
    }
    lines
}

fn replot(out: &Path, anchor: &Path) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_fogray-lego"))
        .args(["--replot", "--out"])
        .arg(out)
        .arg("--anchor")
        .arg(anchor)
        .output()
        .unwrap()
}

#[test]
fn replot_gives_back_the_measured_report() {
    let from = report_dir();
    let anchor = from.join("anchor-pytorch.json");
    let out = std::env::temp_dir().join(format!("fogray-lego-replot-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    std::fs::create_dir_all(&out).unwrap();
    std::fs::copy(from.join("report.json"), out.join("report.json")).unwrap();
    std::fs::copy(from.join("held-out-r_0.png"), out.join("held-out-r_0.png")).unwrap();
    let output = replot(&out, &anchor);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let read = |dir: &Path, file: &str| std::fs::read_to_string(dir.join(file)).unwrap();
    assert_eq!(read(&out, "report.json"), read(&from, "report.json"));
    let (got, want) = (read(&out, "report.md"), read(&from, "report.md"));
    assert!(
        want.lines().filter(|l| l.starts_with("| ")).count() > 10,
        "the report has its tables"
    );
    assert_eq!(without_redrawn_line(&got), without_redrawn_line(&want));
    assert!(got.lines().any(|l| l.starts_with("Tables and plot redrawn")));
    assert!(out.join("psnr-vs-seconds.png").is_file());

    // A report.json whose run no longer matches its configuration is refused, naming both.
    let json = read(&out, "report.json").replacen(
        "--model dense --grid 64 --sh-degree 0",
        "--model dense --grid 32 --sh-degree 0",
        1,
    );
    std::fs::write(out.join("report.json"), json).unwrap();
    let output = replot(&out, &anchor);
    assert!(!output.status.success());
    let err = String::from_utf8_lossy(&output.stderr);
    assert!(err.contains("dense-64-sh0") && err.contains("--grid 32"), "{err}");
    // And a missing one is named.
    std::fs::remove_file(out.join("report.json")).unwrap();
    let output = replot(&out, &anchor);
    assert!(!output.status.success());
    assert!(String::from_utf8_lossy(&output.stderr).contains("report.json"));
    std::fs::remove_dir_all(&out).unwrap();
}
