//! The report's table logic on hand-made logs, against numbers computed by hand.

use super::markdown::{checkpoints, config_rows};
use fogray::fit::settings::Budget;
use fogray::fit::train::LogEntry;
use fogray_lab::sweep::{ConfigRun, FinalPictures};

fn entry(step: usize, seconds: f64, test_psnr: f64, samples: usize) -> LogEntry {
    LogEntry {
        step,
        seconds,
        train_loss: 0.0,
        test_psnr,
        test_ssim: f64::NAN,
        samples,
    }
}

fn run(name: &str, method: &'static str, sampling: &'static str, log: Vec<LogEntry>) -> ConfigRun {
    let last = *log.last().unwrap();
    ConfigRun {
        name: name.into(),
        method,
        sampling,
        precision: "f32",
        final_test_psnr: last.test_psnr,
        seconds: last.seconds,
        steps: last.step,
        samples_per_ray_mean: 0.0,
        occupied_fraction: 1.0,
        log,
        pictures: FinalPictures::default(),
    }
}

#[test]
fn table_rows_read_each_run_at_the_checkpoints() {
    let fused = vec![
        entry(0, 0.0, 10.0, 0),
        entry(100, 1.0, 20.0, 0),
        entry(200, 2.0, 26.0, 0),
    ];
    let taped = vec![entry(0, 0.0, 10.0, 0), entry(30, 3.0, 22.0, 0)];
    let runs = [
        run("fused-uniform", "fused", "uniform", fused.clone()),
        run("taped-uniform", "taped", "uniform", taped),
        run("fused-occupancy", "fused", "occupancy", fused),
    ];
    // Checkpoints of a 3-step budget: the shortest run trained 2 s.
    let points = checkpoints(Budget::Steps(3), &runs);
    assert_eq!(points, vec![0.5, 1.0, 2.0]);
    assert_eq!(checkpoints(Budget::Seconds(60.0), &runs), vec![15.0, 30.0, 60.0]);
    let rows = config_rows(&runs, &points).unwrap();
    assert_eq!(rows[0].psnr_at, vec![Some(15.0), Some(20.0), Some(26.0)]);
    assert_eq!(rows[0].steps_per_second, 100.0);
    // The taped run: 10 dB at 0 s to 22 dB at 3 s, 4 dB per second.
    assert_eq!(rows[1].psnr_at, vec![Some(12.0), Some(14.0), Some(18.0)]);
}
