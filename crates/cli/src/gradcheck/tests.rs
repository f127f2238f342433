//! `fogray gradcheck --fast` on the long ray that made a correct op fail: 1,000,000 samples,
//! sigma uniform in [0, 5] to six decimals with some samples at and next to 0, delta 2e-6,
//! colours in [0, 1], a white background, grad_color (1, 1.5, 2).

use super::*;

const SAMPLES: usize = 1_000_000;

/// The ray, from a fixed linear congruential stream (the same on every machine).
fn long_ray() -> Packed {
    let mut state: u64 = 0x2545_f491_4f6c_dd1d;
    let mut uniform = move || {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let six_decimals = |v: f64| (v * 1e6).round() / 1e6;
    let mut sigma: Vec<f64> = (0..SAMPLES).map(|_| six_decimals(5.0 * uniform())).collect();
    // At 0, within a step of it, and just beyond.
    for (k, v) in [(10, 0.0), (20, 1e-9), (30, 1e-6), (40, 0.0)] {
        sigma[k] = v;
    }
    let color: Vec<f64> = (0..3 * SAMPLES).map(|_| six_decimals(uniform())).collect();
    Packed {
        precision: Precision::F64,
        min_transmittance: 0.0,
        offsets: vec![0, SAMPLES],
        sigma,
        delta: vec![2e-6; SAMPLES],
        color,
        ch: 3,
        background: vec![1.0; 3],
        t: None,
        has_t: vec![false],
        grad_color: Some(vec![1.0, 1.5, 2.0]),
        has_grad: vec![true],
        grad_depth: None,
        has_grad_depth: vec![false],
    }
}

fn fast(atol: Option<f64>, rtol: Option<f64>) -> Settings {
    Settings {
        atol,
        rtol,
        fast: true,
        projections: 8,
        seed: 0,
        json: true,
        worst: 5,
    }
}

/// The finite differences' row of the report's table: (checked, failing).
fn finite_differences(outcome: &Outcome) -> (u64, u64) {
    let report: serde_json::Value = serde_json::from_str(&outcome.text).unwrap();
    let row = report["inputs"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["against"] == "finite_differences")
        .unwrap()
        .clone();
    (row["checked"].as_u64().unwrap(), row["failing"].as_u64().unwrap())
}

#[test]
fn a_correct_op_passes_on_a_long_ray_with_samples_at_zero_and_fails_at_zero_tolerance() {
    let outcome = run(long_ray(), &fast(None, None)).unwrap();
    assert!(outcome.passed, "{}", outcome.text);
    // Eight directions, each central and one-sided.
    assert_eq!(finite_differences(&outcome), (16, 0));
    let report: serde_json::Value = serde_json::from_str(&outcome.text).unwrap();
    let text = report.to_string();
    // Each direction gives a central check and a one-sided one through the samples at 0.
    assert!(text.contains("\"one_sided\":true"), "{text}");
    assert!(text.contains("\"one_sided\":false"), "{text}");
    let exact = run(long_ray(), &fast(Some(0.0), Some(0.0))).unwrap();
    assert!(!exact.passed);
    assert!(finite_differences(&exact).1 > 0, "{}", exact.text);
}

#[test]
fn a_backward_wrong_by_one_part_in_a_thousand_at_one_sample_fails_on_the_long_ray() {
    let tamper = |g: &mut InputGrads<f64>| g.delta[123_456] *= 1.0 + 1e-3;
    let outcome = check_with(long_ray(), &fast(None, None), &tamper).unwrap();
    assert!(!outcome.passed, "{}", outcome.text);
    let report: serde_json::Value = serde_json::from_str(&outcome.text).unwrap();
    let worst = &report["worst"][0];
    assert_eq!(worst["sample"], 123_456, "{worst}");
}
