//! A sweep over configurations on a small synthetic scene: its checks before anything trains,
//! and fused against taped over the same steps with a budget of seconds.

use crate::common::ball_dataset;
use fogray_fit::dataset::Dataset;
use fogray_fit::settings::{Budget, FitSettings};
use fogray_lab::sweep::{run_configs, same_steps, SweepError, SweepOptions, DEFAULT_CONFIGS};

fn tiny() -> (Dataset, FitSettings) {
    let config = FitSettings {
        grid: 10,
        batch: 128,
        lr: 0.3,
        evaluations: 5,
        ..FitSettings::default()
    }
    .with_budget(Budget::Steps(70));
    (ball_dataset(6, 1, 10), config)
}

#[test]
fn bad_options_fail_before_any_fit() {
    let (data, config) = tiny();
    let mut ran = false;
    for (configs, slice_pixels) in [
        (vec![], 8),
        (vec![DEFAULT_CONFIGS[0], DEFAULT_CONFIGS[0]], 8),
        (DEFAULT_CONFIGS.to_vec(), 0),
    ] {
        let options = SweepOptions {
            fit: config,
            configs,
            slice_pixels,
        };
        let result = run_configs(&data, &options, &mut |_, _| ran = true);
        assert!(matches!(result, Err(SweepError::Config(_))));
    }
    assert!(!ran);
    // A fit's own check (a zero batch) comes back as the fit's error.
    let options = SweepOptions {
        fit: FitSettings { batch: 0, ..config },
        configs: vec![DEFAULT_CONFIGS[0]],
        slice_pixels: 8,
    };
    assert!(matches!(
        run_configs(&data, &options, &mut |_, _| {}),
        Err(SweepError::Fit(_))
    ));
}

#[test]
fn with_a_budget_of_seconds_each_pair_trains_again_for_the_taped_runs_steps() {
    let (data, config) = tiny();
    let options = SweepOptions {
        fit: config.with_budget(Budget::Seconds(0.3)),
        configs: vec![DEFAULT_CONFIGS[2], DEFAULT_CONFIGS[3]],
        slice_pixels: 12,
    };
    let runs = run_configs(&data, &options, &mut |_, _| {}).unwrap();
    let taped_steps = runs[1].steps;
    assert!(taped_steps > 0);
    let mut heard: Vec<String> = Vec::new();
    let pairs = same_steps(&data, &options, &runs, &mut |label, _| {
        if heard.last().map(String::as_str) != Some(label) {
            heard.push(label.to_string());
        }
    })
    .unwrap();
    assert_eq!(
        heard,
        [
            format!("fused-occupancy, {taped_steps} steps"),
            format!("taped-occupancy, {taped_steps} steps"),
            format!("fused-occupancy, {taped_steps} steps, again")
        ]
    );
    assert_eq!(pairs.len(), 1);
    let (name, pair) = &pairs[0];
    assert_eq!(name, "occupancy");
    assert!(pair.extra_runs);
    assert_eq!(
        (pair.steps, pair.fused.steps, pair.taped.steps),
        (taped_steps, taped_steps, taped_steps)
    );
    // The same steps of the same arithmetic: the same PSNR but for rounding.
    assert!(
        (pair.fused.final_test_psnr - pair.taped.final_test_psnr).abs() < 0.01,
        "{pair:?}"
    );
    // The fused run again: the same steps to the same bits, only its time differs; the
    // speed-up is over the mean of the two.
    let again = pair.fused_again.expect("a fused run after the taped one");
    assert_eq!(
        (again.steps, again.final_test_psnr),
        (taped_steps, pair.fused.final_test_psnr)
    );
    let mean = 0.5 * (pair.fused.seconds + again.seconds);
    assert_eq!(pair.fused_seconds(), mean);
    assert_eq!(pair.speedup, Some(pair.taped.seconds / mean));

    // Runs that are not the configurations' are refused before anything trains.
    let mut ran = false;
    let result = same_steps(&data, &options, &runs[..1], &mut |_, _| ran = true);
    assert!(matches!(result, Err(SweepError::Config(_))) && !ran);
}
