//! `fogray-lego --replot` redraws the committed lego report from its runs' files alone: the
//! same report.json (stamp and runs, as the measuring run wrote it) and the same table rows.

use std::path::{Path, PathBuf};
use std::process::Command;

fn report_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../reports/lego")
}

fn table_rows(md: &str) -> Vec<&str> {
    md.lines().filter(|l| l.starts_with("| ")).collect()
}

#[test]
fn replot_gives_back_the_measured_report() {
    let from = report_dir();
    let out = std::env::temp_dir().join(format!("fogray-lego-replot-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    std::fs::create_dir_all(&out).unwrap();
    std::fs::copy(from.join("report.json"), out.join("report.json")).unwrap();
    for run in std::fs::read_dir(from.join("runs")).unwrap() {
        let run = run.unwrap().path();
        let dir = out.join("runs").join(run.file_name().unwrap());
        // The held-out views are left behind: the report then names none.
        std::fs::create_dir_all(dir.join("test")).unwrap();
        std::fs::copy(run.join("fit.json"), dir.join("fit.json")).unwrap();
    }
    let status = Command::new(env!("CARGO_BIN_EXE_fogray-lego"))
        .args(["--replot", "--out"])
        .arg(&out)
        .arg("--anchor")
        .arg(from.join("anchor-pytorch.json"))
        .status()
        .unwrap();
    assert!(status.success());
    let json = |dir: &Path| std::fs::read_to_string(dir.join("report.json")).unwrap();
    assert_eq!(json(&out), json(&from), "report.json");
    let md = |dir: &Path| std::fs::read_to_string(dir.join("report.md")).unwrap();
    let (got, want) = (md(&out), md(&from));
    assert!(!table_rows(&want).is_empty());
    assert_eq!(table_rows(&got), table_rows(&want));
    assert!(out.join("psnr-vs-seconds.png").is_file());
    // A replot without the runs' files is an error naming the file.
    std::fs::remove_file(out.join("runs/sparse-128/fit.json")).unwrap();
    let output = Command::new(env!("CARGO_BIN_EXE_fogray-lego"))
        .args(["--replot", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(!output.status.success());
    assert!(String::from_utf8_lossy(&output.stderr).contains("sparse-128/fit.json"));
    std::fs::remove_dir_all(&out).unwrap();
}
