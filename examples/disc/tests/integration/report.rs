//! The speed-against-error report: every configuration is measured, and its error column
//! means what it says (speed is reported, never asserted).

use fogray_disc::report::{self, Timing, COUNTS, THRESHOLDS};
use fogray_disc::sampling::Sampling;
use fogray_disc::scene::Scene;
use fogray_disc::setup::Setup;
use fogray_lab::stamp::Stamp;

#[test]
fn report_measures_every_configuration_with_meaningful_errors() {
    let setup = Setup::new(Scene::default()).unwrap();
    let rows = report::run(&setup, 0.15, Timing::ONCE, &|| {}).unwrap();
    // 2 samplings x 5 counts x 2 precisions x (4 fused thresholds + 2 taped twins)
    assert_eq!(rows.len(), 2 * COUNTS.len() * 2 * (THRESHOLDS.len() + 2));
    assert!(rows.iter().all(|r| r.max_error.is_finite() && r.us_per_frame > 0.0));
    let find = |method: &str, precision: &str, sampling: Sampling, samples: usize, threshold: f64| {
        rows.iter()
            .find(|r| {
                r.method == method
                    && r.precision == precision
                    && r.sampling == sampling
                    && r.samples == samples
                    && r.min_transmittance == threshold
            })
            .unwrap()
            .max_error
    };
    for sampling in [Sampling::Uniform, Sampling::Band] {
        for samples in COUNTS {
            // In f64 the error is the quadrature's: the fused op and the stable twin agree.
            let fused = find("fused", "f64", sampling, samples, 0.0);
            let taped = find("taped", "f64", sampling, samples, 0.0);
            assert!(
                (fused - taped).abs() <= 1e-12,
                "{sampling:?} {samples}: {fused} vs {taped}"
            );
            // f32 adds at most rounding on top of it.
            assert!((find("fused", "f32", sampling, samples, 0.0) - fused).abs() <= 1e-6);
            // Early termination at 1e-2 costs at most about 1e-2 of colour contrast more.
            assert!(find("fused", "f64", sampling, samples, 1e-2) <= fused + 1e-2);
        }
    }
    // Band sampling beats uniform sampling at equal (small) sample counts.
    assert!(find("fused", "f64", Sampling::Band, 16, 0.0) < find("fused", "f64", Sampling::Uniform, 16, 0.0));
    let md = report::markdown(&rows, 0.15, Timing::ONCE, &Stamp::now("test"));
    assert_eq!(md.lines().filter(|l| l.starts_with("| fused |")).count(), 80);
    // The front: no row on it is beaten in both time and error by any row, and every row off
    // it is (checked here by brute force, independently of how the report marks it).
    for r in &rows {
        let beaten = rows.iter().any(|o| {
            o.us_per_frame <= r.us_per_frame
                && o.max_error <= r.max_error
                && (o.us_per_frame < r.us_per_frame || o.max_error < r.max_error)
        });
        assert_eq!(r.pareto, !beaten);
    }
    // Each recommendation is the fastest row of all within its budget.
    for (budget, pick) in report::recommendations(&rows) {
        let fastest = rows
            .iter()
            .filter(|r| r.max_error <= budget)
            .map(|r| r.us_per_frame)
            .fold(f64::INFINITY, f64::min);
        match pick {
            Some(r) => assert_eq!(r.us_per_frame, fastest, "budget {budget}"),
            None => assert!(fastest.is_infinite(), "budget {budget}"),
        }
    }
}
