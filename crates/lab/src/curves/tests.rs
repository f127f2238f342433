//! The curves on hand-made logs, against numbers computed by hand.

use approx::assert_relative_eq;
use fogray_fit::train::LogEntry;

use super::{against_anchor, fused_vs_taped, occupancy_vs_uniform, psnr_at, reach, Anchor, CurveError};

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

/// Rises to 24 dB at 4 s, dips to 23 at 6 s, ends at 26 at 8 s.
fn wavy() -> Vec<LogEntry> {
    vec![
        entry(0, 0.0, 10.0, 0),
        entry(10, 2.0, 20.0, 1000),
        entry(20, 4.0, 24.0, 2000),
        entry(30, 6.0, 23.0, 3000),
        entry(40, 8.0, 26.0, 4000),
    ]
}

#[test]
fn psnr_at_a_time_is_linear_between_evaluations() {
    let log = wavy();
    // 3 s: halfway from (2 s, 20 dB) to (4 s, 24 dB).
    assert_eq!(psnr_at(&log, 3.0).unwrap(), Some(22.0));
    // 5 s: halfway from 24 down to 23.
    assert_eq!(psnr_at(&log, 5.0).unwrap(), Some(23.5));
    // 7.5 s: three quarters of the way from 23 to 26.
    assert_eq!(psnr_at(&log, 7.5).unwrap(), Some(25.25));
    assert_eq!(psnr_at(&log, 0.0).unwrap(), Some(10.0));
    assert_eq!(psnr_at(&log, 8.0).unwrap(), Some(26.0));
    assert_eq!(psnr_at(&log, 8.5).unwrap(), None, "past the last evaluation");
    assert_eq!(psnr_at(&log, -1.0).unwrap(), None, "before the first");
}

#[test]
fn reach_is_the_first_crossing_interpolated_in_time_steps_and_samples() {
    let log = wavy();
    // 23.5 dB: first crossed between (2 s, 20 dB) and (4 s, 24 dB), 3.5/4 of the way, not in
    // the later climb from 23 to 26.
    let r = reach(&log, 23.5).unwrap().unwrap();
    assert_eq!(r.seconds, 3.75);
    assert_eq!(r.steps, 18.75);
    assert_eq!(r.samples, 1875.0);
    assert_eq!(r.samples_per_ray(10), Some(10.0)); // 1875 / (18.75 x 10)

    // 25 dB: only in the last climb, 2/3 of the way from (6 s, 23) to (8 s, 26).
    assert_relative_eq!(
        reach(&log, 25.0).unwrap().unwrap().seconds,
        6.0 + 4.0 / 3.0,
        epsilon = 1e-12
    );
    // An evaluation exactly at the target: its own time.
    assert_eq!(reach(&log, 24.0).unwrap().unwrap().seconds, 4.0);
    // Reached at the start: time 0, and no samples per ray yet.
    let start = reach(&log, 5.0).unwrap().unwrap();
    assert_eq!((start.seconds, start.samples_per_ray(10)), (0.0, None));
    assert_eq!(reach(&log, 26.5).unwrap(), None);
}

#[test]
fn logs_that_are_not_curves_are_rejected() {
    let is_log_error = |r: Result<Option<f64>, CurveError>| matches!(r, Err(CurveError::Log(_)));
    assert!(is_log_error(psnr_at(&[], 1.0)));
    let mut back = wavy();
    back[2].seconds = 1.0;
    assert!(is_log_error(psnr_at(&back, 1.0)));
    let mut nan = wavy();
    nan[3].test_psnr = f64::NAN;
    assert!(is_log_error(psnr_at(&nan, 1.0)));
    let mut inf_time = wavy();
    inf_time[4].seconds = f64::INFINITY;
    assert!(matches!(reach(&inf_time, 20.0), Err(CurveError::Log(_))));
}

#[test]
fn fused_against_taped_at_the_taped_final_psnr() {
    let fused = vec![
        entry(0, 0.0, 10.0, 0),
        entry(100, 1.0, 20.0, 0),
        entry(200, 2.0, 26.0, 0),
    ];
    let taped = vec![
        entry(0, 0.0, 10.0, 0),
        entry(10, 1.0, 14.0, 0),
        entry(20, 2.0, 18.0, 0),
        entry(30, 3.0, 22.0, 0),
    ];
    let c = fused_vs_taped(&fused, &taped).unwrap();
    assert_eq!(c.target_psnr, 22.0);
    assert_eq!(c.taped.seconds, 3.0);
    // 22 dB is 2/6 of the way from (1 s, 20 dB) to (2 s, 26 dB): 4/3 s, so 3 / (4/3) = 2.25.
    let f = c.fused;
    assert_relative_eq!(f.seconds, 4.0 / 3.0, epsilon = 1e-12);
    assert_relative_eq!(f.steps, 100.0 + 100.0 / 3.0, epsilon = 1e-12);
    assert_relative_eq!(c.speedup.unwrap(), 2.25, epsilon = 1e-12);
    // A fused run that ends lower sets the target: 21 dB, which the taped run crosses 3/4 of
    // the way from (2 s, 18 dB) to (3 s, 22 dB).
    let slow = vec![entry(0, 0.0, 10.0, 0), entry(5, 4.0, 21.0, 0)];
    let c = fused_vs_taped(&slow, &taped).unwrap();
    assert_eq!((c.target_psnr, c.fused.seconds, c.taped.seconds), (21.0, 4.0, 2.75));
    assert_eq!(c.speedup, Some(2.75 / 4.0));
}

#[test]
fn occupancy_against_uniform_samples_per_ray_at_the_lower_final_psnr() {
    let batch = 100;
    // Uniform: 128 samples per ray throughout.
    let uniform = vec![
        entry(0, 0.0, 10.0, 0),
        entry(10, 1.0, 20.0, 10 * batch * 128),
        entry(20, 2.0, 24.0, 20 * batch * 128),
    ];
    // Occupancy: 40, then 20, then 15 samples per ray per step: 40, 30, 25 on average.
    let occupancy = vec![
        entry(0, 0.0, 10.0, 0),
        entry(10, 1.0, 18.0, 10 * batch * 40),
        entry(20, 2.0, 22.0, 20 * batch * 30),
        entry(30, 3.0, 23.0, 30 * batch * 25),
    ];
    let c = occupancy_vs_uniform(&occupancy, &uniform, batch).unwrap();
    assert_eq!(c.target_psnr, 23.0);
    // Occupancy reaches 23 dB at its last evaluation: 75000 samples over 30 x 100 rays.
    assert_eq!(c.occupancy.seconds, 3.0);
    assert_eq!(c.occupancy_samples_per_ray, Some(25.0));
    // Uniform: 3/4 of the way from step 10 to step 20: step 17.5, 224000 samples, 1.75 s.
    assert_eq!(c.uniform.seconds, 1.75);
    assert_eq!(c.uniform.samples, 224_000.0);
    assert_eq!(c.uniform_samples_per_ray, Some(128.0));
    assert_relative_eq!(c.samples_per_ray_ratio.unwrap(), 25.0 / 128.0, epsilon = 1e-15);
    assert_relative_eq!(c.speedup.unwrap(), 1.75 / 3.0, epsilon = 1e-15);
    assert!(matches!(
        occupancy_vs_uniform(&occupancy, &uniform, 0),
        Err(CurveError::Log(_))
    ));
}

#[test]
fn anchors_that_are_not_curves_are_refused() {
    for bad in [
        "not json",
        r#"{"log": [{"seconds": 0, "test_psnr": 1}]}"#,
        r#"{"name": " ", "log": [{"seconds": 0, "test_psnr": 1}]}"#,
        r#"{"name": "a", "log": []}"#,
        r#"{"name": "a", "log": [{"seconds": -1, "test_psnr": 1}]}"#,
        r#"{"name": "a", "log": [{"seconds": 2, "test_psnr": 1}, {"seconds": 1, "test_psnr": 2}]}"#,
        r#"{"name": "a", "log": [{"seconds": 1, "test_psnr": null}]}"#,
        r#"{"name": "a", "log": [{"seconds": 1, "test_psnr": 3, "step": 5}, {"seconds": 2, "test_psnr": 4, "step": 4}]}"#,
    ] {
        assert!(matches!(Anchor::from_json(bad), Err(CurveError::Anchor(_))), "{bad}");
    }
    // A fit's JSON with a name is an anchor: other fields are ignored.
    let fit_json = r#"{"name": "f", "log": [{"step": 0, "seconds": 0.0, "train_loss": null, "test_psnr": 9.5, "samples": 0}], "final_test_psnr": 9.5}"#;
    let anchor = Anchor::from_json(fit_json).unwrap();
    assert_eq!((anchor.final_psnr(), anchor.log[0].step), (9.5, Some(0)));
}

#[test]
fn against_an_anchor_at_the_anchors_final_psnr() {
    // The anchor passes its final 19 dB on the way up (at 90 s) and ends there at 200 s.
    let anchor = [
        entry(0, 0.0, 10.0, 0),
        entry(0, 100.0, 20.0, 0),
        entry(0, 200.0, 19.0, 0),
    ];
    // This run reaches 19 dB at 1 + (19 - 14) / (22 - 14) = 1.625 s.
    let fast = [
        entry(0, 0.0, 10.0, 0),
        entry(5, 1.0, 14.0, 50),
        entry(10, 2.0, 22.0, 100),
    ];
    let c = against_anchor(&fast, &anchor).unwrap();
    assert_eq!(c.target_psnr, 19.0);
    assert_relative_eq!(c.anchor.seconds, 90.0, max_relative = 1e-12);
    assert_relative_eq!(c.run.unwrap().seconds, 1.625, max_relative = 1e-12);
    assert_relative_eq!(c.speedup.unwrap(), 90.0 / 1.625, max_relative = 1e-12);
    // A run that never gets there has no time and no speed-up.
    let slow = [entry(0, 0.0, 10.0, 0), entry(5, 1.0, 15.0, 50)];
    let c = against_anchor(&slow, &anchor).unwrap();
    assert_eq!((c.run, c.speedup), (None, None));
    assert!(matches!(against_anchor(&[], &anchor), Err(CurveError::Log(_))));
}
