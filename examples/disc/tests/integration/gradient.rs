//! The soft renderer's dE/dx (tape backward through the fused op) against central finite
//! differences of E and against the same pipeline run on the stable taped twin.

use fogray_disc::sampling::Sampling;
use fogray_disc::scene::Scene;
use fogray_disc::setup::Setup;
use fogray_disc::soft::{evaluate, Compositor};

#[test]
fn slope_matches_finite_differences_and_the_taped_twin() {
    for sampling in [Sampling::Uniform, Sampling::Band] {
        let setup = Setup::new(Scene {
            sampling,
            ..Scene::default()
        })
        .unwrap();
        for (x, tau) in [(-1.5, 0.15), (-2.8, 0.15), (0.37, 0.3), (1.1, 0.6), (-0.2, 0.05)] {
            // Band samples follow x; hold them fixed for the difference quotient, as the
            // tape does (they are constants on it).
            let samples = setup.samples_for(x, tau).into_owned();
            let e = |cx: f64, c: Compositor| evaluate(&setup.scene, &samples, &setup.photo, cx, tau, c).unwrap();
            let fused = e(x, Compositor::Fused);
            let taped = e(x, Compositor::Taped);
            assert!(
                (fused.loss - taped.loss).abs() <= 1e-14,
                "{sampling:?} x={x}: {} vs {}",
                fused.loss,
                taped.loss
            );
            assert!(
                (fused.slope - taped.slope).abs() <= 1e-12 * fused.slope.abs().max(1e-3),
                "{sampling:?} x={x} tau={tau}: fused {} vs taped {}",
                fused.slope,
                taped.slope
            );
            let h = 1e-5;
            let fd = (e(x + h, Compositor::Fused).loss - e(x - h, Compositor::Fused).loss) / (2.0 * h);
            assert!(
                (fused.slope - fd).abs() <= 1e-6 * fd.abs().max(1e-4),
                "{sampling:?} x={x} tau={tau}: backward {} vs central difference {fd}",
                fused.slope
            );
        }
    }
}
