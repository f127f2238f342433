//! The report end to end on a tiny problem budgeted by steps: the fits it runs are the fits
//! `fit` runs, its tables read their logs, and its files are there.

use crate::common::default_scene_data;
use fogray::fit::dataset::Dataset;
use fogray::fit::dense::DenseGrid;
use fogray::fit::settings::{Budget, FitSettings, Sampling};
use fogray::fit::train::{fit, LogEntry};
use fogray_grid::report::write::{write_report, MachineBandwidth, ReportSetup};
use fogray_grid::ring::Ring;
use fogray_grid::scene::Scene;
use fogray_lab::curves::{Anchor, AnchorPoint};
use fogray_lab::machine::Bandwidth;
use fogray_lab::sweep::pairs::fused_vs_taped_rows;
use fogray_lab::sweep::{run_configs, same_steps, SweepOptions, DEFAULT_CONFIGS};

fn tiny() -> (Scene, Dataset, FitSettings) {
    let scene = Scene::default();
    let data = default_scene_data(&Ring::new(6, 1, 10).unwrap());
    let config = FitSettings {
        grid: 10,
        batch: 128,
        lr: 0.3,
        evaluations: 5,
        ..FitSettings::default()
    }
    .with_budget(Budget::Steps(70));
    (scene, data, config)
}

#[test]
fn the_report_runs_each_configuration_as_fit_does_and_writes_its_files() {
    let (scene, data, config) = tiny();
    let options = SweepOptions {
        fit: config,
        configs: DEFAULT_CONFIGS.to_vec(),
        slice_pixels: 12,
    };
    let mut heard = Vec::new();
    let runs = run_configs(&data, &options, &mut |i, p| heard.push((i, p.step))).unwrap();
    assert_eq!(runs.len(), 4);
    assert_eq!(
        heard.len(),
        4 * 70,
        "one progress report per step of each configuration"
    );
    // Each run is the fit of its configuration: the same steps and test PSNRs.
    for (run, c) in runs.iter().zip(DEFAULT_CONFIGS) {
        let alone = fit::<f32, DenseGrid<f32>>(
            &data,
            &FitSettings {
                method: c.method,
                sampling: c.sampling,
                ..config
            },
            &mut |_| {},
        )
        .unwrap();
        assert_eq!(run.name, c.to_string());
        let steps = |log: &[LogEntry]| log.iter().map(|e| (e.step, e.test_psnr, e.samples)).collect::<Vec<_>>();
        assert_eq!(steps(&run.log), steps(&alone.log), "{}", run.name);
        assert_eq!(run.steps, 70);
        assert_eq!(run.pictures.renders.len(), 1);
        assert_eq!(run.pictures.occupancy.is_some(), c.sampling == Sampling::Occupancy);
        // Uniform sampling counts every sample of every step: the mean per ray times the rays.
        let last = run.log.last().unwrap();
        let total = run.samples_per_ray_mean * (70 * 128) as f64;
        assert!((last.samples as f64 - total).abs() < 1e-6 * total, "{}", run.name);
    }
    // Fused and taped do the same arithmetic, so at the taped run's final PSNR the fused log
    // crosses at the same step (to rounding), whatever the clocks say.
    for (name, c) in fused_vs_taped_rows(&runs).unwrap() {
        assert!(
            (c.fused.steps - c.taped.steps).abs() < 1.0,
            "{name}: {} vs {}",
            c.fused.steps,
            c.taped.steps
        );
        let final_of = |method: &str| {
            let run = runs.iter().find(|r| r.method == method && r.sampling == name).unwrap();
            run.final_test_psnr
        };
        assert_eq!(c.target_psnr, final_of("taped").min(final_of("fused")));
    }

    // With a budget of steps the runs are already pairs over the same steps: nothing runs again.
    let mut reran = false;
    let pairs = same_steps(&data, &options, &runs, &mut |_, _| reran = true).unwrap();
    assert!(!reran);
    assert_eq!(pairs.len(), 2);
    for (name, pair) in &pairs {
        let of = |method: &str| runs.iter().find(|r| r.method == method && r.sampling == name).unwrap();
        let (f, t) = (of("fused"), of("taped"));
        assert!(
            !pair.extra_runs && pair.fused_again.is_none() && pair.steps == 70,
            "{name}"
        );
        assert_eq!(
            (pair.fused.seconds, pair.fused.final_test_psnr),
            (f.seconds, f.final_test_psnr)
        );
        assert_eq!(
            (pair.taped.seconds, pair.taped.final_test_psnr),
            (t.seconds, t.final_test_psnr)
        );
        assert_eq!(pair.speedup, Some(t.seconds / f.seconds));
    }

    let dir = std::env::temp_dir().join(format!("fogray-grid-report-{}", std::process::id()));
    let stamp = fogray_lab::stamp::Stamp::now("fogray-grid report --steps 70");
    // Set by hand: what is tested here is how the report writes them.
    let bandwidth = MachineBandwidth {
        before: Bandwidth {
            threads: 2,
            bytes_per_sec: 44.04e9,
        },
        after: Bandwidth {
            threads: 2,
            bytes_per_sec: 46.16e9,
        },
    };
    let setup = ReportSetup {
        stamp: &stamp,
        reproduce: "cargo run --release -p fogray-grid -- report --steps 70",
        budget: config.budget(),
        batch: config.batch,
        problem: "A tiny problem.",
        evaluations: config.evaluations,
        anchor: None,
        same_steps: &pairs,
        bandwidth: Some(bandwidth),
    };
    let md = write_report(&dir, &runs, &data, &scene, &setup).unwrap();
    let text = std::fs::read_to_string(&md).unwrap();
    assert!(
        text.contains("## Fused against taped: time to the same PSNR\n"),
        "{text}"
    );
    assert!(
        text.contains("| occupancy | 70 |") && text.contains("which made the same steps"),
        "{text}"
    );
    assert!(text.contains("`cargo run --release -p fogray-grid -- report --steps 70`"));
    assert!(text.contains("(5 per run, evenly spaced"), "{text}");
    assert!(
        text.contains(
            "(a STREAM triad, 2 threads) was 44.0 GB/s just before the first run and 46.2 GB/s just after the last"
        ),
        "{text}"
    );
    for row in ["| fused-uniform |", "| taped-occupancy |", "| uniform |", "| fused |"] {
        assert!(text.contains(row), "{row} missing from\n{text}");
    }
    for file in [
        "psnr-vs-seconds.svg",
        "psnr-vs-seconds.png",
        "psnr-vs-steps.png",
        "report.json",
        "density-slices.png",
        "occupancy-slices.png",
        "test-view-003.png",
    ] {
        assert!(dir.join(file).exists(), "{file}");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap()).unwrap();
    let configs = json["configurations"].as_array().unwrap();
    assert_eq!(configs.len(), 4);
    assert_eq!(configs[1]["name"], "taped-uniform");
    assert_eq!(configs[1]["log"].as_array().unwrap().len(), runs[1].log.len());
    assert_eq!(configs[1]["final_test_psnr"].as_f64().unwrap(), runs[1].final_test_psnr);
    assert_eq!(json["fused_vs_taped"].as_array().unwrap().len(), 2);
    let json_pairs = json["fused_vs_taped_same_steps"].as_array().unwrap();
    assert_eq!(json_pairs.len(), 2);
    assert_eq!(json_pairs[1]["name"], "occupancy");
    assert_eq!(
        json_pairs[1]["taped"]["seconds"].as_f64().unwrap(),
        pairs[1].1.taped.seconds
    );
    assert!(json.get("anchor").is_none() && !text.contains("outside pipeline"));
    assert!(!dir.join("psnr-vs-seconds-log.png").exists());

    // An anchor that is the taped-uniform run slowed down ten times over: that run reaches the
    // anchor's final PSNR at a tenth of the anchor's time, and the report says so.
    let slowed: Vec<AnchorPoint> = runs[1]
        .log
        .iter()
        .map(|e| AnchorPoint {
            seconds: 10.0 * e.seconds,
            test_psnr: e.test_psnr,
            step: Some(e.step),
        })
        .collect();
    let anchor = Anchor {
        name: "slow twin".into(),
        note: Some("Measured nowhere.".into()),
        log: slowed,
    };
    let with_anchor = ReportSetup {
        anchor: Some(&anchor),
        ..setup
    };
    let md = write_report(&dir, &runs, &data, &scene, &with_anchor).unwrap();
    let text = std::fs::read_to_string(&md).unwrap();
    assert!(text.contains("## Against an outside pipeline: slow twin") && text.contains("Measured nowhere."));
    assert!(dir.join("psnr-vs-seconds-log.png").exists() && dir.join("psnr-vs-seconds-log.svg").exists());
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap()).unwrap();
    assert_eq!(
        json["machine_bandwidth"]["before"]["bytes_per_sec"].as_f64(),
        Some(44.04e9)
    );
    assert_eq!(json["machine_bandwidth"]["after"]["threads"].as_u64(), Some(2));
    let against = json["anchor"]["against"].as_array().unwrap();
    assert_eq!(json["anchor"]["name"], "slow twin");
    assert_eq!(against.len(), 4);
    assert_eq!(against[1]["name"], "taped-uniform");
    assert_eq!(against[1]["target_psnr"].as_f64().unwrap(), runs[1].final_test_psnr);
    let speedup = against[1]["speedup"].as_f64().unwrap();
    assert!((speedup - 10.0).abs() < 1e-9, "{speedup}");
    // The markdown's table holds the same comparisons.
    let row = text
        .lines()
        .find(|l| l.starts_with("| taped-uniform |") && l.ends_with(" x |") && l.split('|').count() == 5)
        .unwrap_or_else(|| panic!("no anchor row for taped-uniform in:\n{text}"));
    assert!(row.ends_with("| 10.0 x |"), "{row}");

    // Written again into the same folder without the anchor, the report leaves no plot of it.
    write_report(&dir, &runs, &data, &scene, &setup).unwrap();
    assert!(!dir.join("psnr-vs-seconds-log.png").exists() && !dir.join("psnr-vs-seconds-log.svg").exists());
    let _ = std::fs::remove_dir_all(&dir);
}
