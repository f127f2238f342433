//! The configurations' names, the pairing of runs and the pick of the best run, on hand-made
//! logs (the sweep's fits are the integration tests').

use approx::assert_relative_eq;
use fogray_fit::settings::{Method, Precision, Sampling};
use fogray_fit::train::LogEntry;

use super::pairs::{fused_vs_taped_rows, occupancy_vs_uniform_rows};
use super::{best, ConfigRun, FinalPictures, RunConfig, SweepError, DEFAULT_CONFIGS};

#[test]
fn configuration_names_read_back() {
    for c in DEFAULT_CONFIGS {
        assert_eq!(c.to_string().parse::<RunConfig>().unwrap(), c);
    }
    let f64_config: RunConfig = "taped-occupancy-f64".parse().unwrap();
    assert_eq!(
        f64_config,
        RunConfig {
            method: Method::Taped,
            sampling: Sampling::Occupancy,
            precision: Precision::F64
        }
    );
    assert_eq!(f64_config.to_string(), "taped-occupancy-f64");
    assert_eq!("fused-uniform-f32".parse::<RunConfig>().unwrap(), DEFAULT_CONFIGS[0]);
    for bad in [
        "fused",
        "fast-uniform",
        "fused-dense",
        "fused-uniform-f16",
        "fused-uniform-f32-x",
        "",
    ] {
        assert!(matches!(bad.parse::<RunConfig>(), Err(SweepError::Config(_))), "{bad}");
    }
}

fn run(name: &str, final_test_psnr: f64) -> ConfigRun {
    ConfigRun {
        name: name.into(),
        method: "fused",
        sampling: "uniform",
        precision: "f32",
        log: vec![LogEntry {
            step: 0,
            seconds: 0.0,
            train_loss: f64::NAN,
            test_psnr: final_test_psnr,
            test_ssim: f64::NAN,
            samples: 0,
        }],
        final_test_psnr,
        seconds: 0.0,
        steps: 0,
        samples_per_ray_mean: 0.0,
        occupied_fraction: 1.0,
        pictures: FinalPictures::default(),
    }
}

#[test]
fn the_best_run_is_the_first_of_the_highest_final_psnr() {
    let runs = [run("a", 20.0), run("b", 26.0), run("c", 26.0), run("d", 25.0)];
    assert_eq!(best(&runs).unwrap().name, "b");
    assert!(best(&[]).is_none());
}

fn entry(step: usize, seconds: f64, test_psnr: f64) -> LogEntry {
    LogEntry {
        step,
        seconds,
        train_loss: 0.0,
        test_psnr,
        test_ssim: f64::NAN,
        samples: 0,
    }
}

fn run_of(name: &str, method: &'static str, sampling: &'static str, log: Vec<LogEntry>) -> ConfigRun {
    let last = *log.last().unwrap();
    ConfigRun {
        method,
        sampling,
        final_test_psnr: last.test_psnr,
        seconds: last.seconds,
        steps: last.step,
        log,
        ..run(name, 0.0)
    }
}

#[test]
fn pairs_are_the_runs_that_share_all_but_one_setting() {
    let fused = vec![entry(0, 0.0, 10.0), entry(100, 1.0, 20.0), entry(200, 2.0, 26.0)];
    let taped = vec![entry(0, 0.0, 10.0), entry(30, 3.0, 22.0)];
    let runs = [
        run_of("fused-uniform", "fused", "uniform", fused.clone()),
        run_of("taped-uniform", "taped", "uniform", taped),
        run_of("fused-occupancy", "fused", "occupancy", fused),
    ];
    let fvt = fused_vs_taped_rows(&runs).unwrap();
    assert_eq!(fvt.len(), 1, "no taped-occupancy to pair with fused-occupancy");
    assert_eq!(fvt[0].0, "uniform");
    // The taped run ends at 22 dB at 3 s; the fused run passes 22 dB 2/6 of the way from
    // (1 s, 20 dB) to (2 s, 26 dB), at 4/3 s: 3 / (4/3) = 2.25.
    assert_relative_eq!(fvt[0].1.speedup.unwrap(), 2.25, epsilon = 1e-12);
    let ovu = occupancy_vs_uniform_rows(&runs, 10).unwrap();
    assert_eq!(ovu.len(), 1);
    assert_eq!(ovu[0].0, "fused");
    // Both fused runs have the same log: they meet at their common final PSNR, 26 dB at 2 s.
    assert_eq!((ovu[0].1.target_psnr, ovu[0].1.speedup), (26.0, Some(1.0)));
}
