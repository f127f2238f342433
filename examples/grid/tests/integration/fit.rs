//! A tiny fit of the built-in scene that must learn, with either sampling. (The model's
//! gradient against central differences, the fused ops against their taped twins, resampling,
//! the densities, the learning rate's schedule and the step profile are fogray-fit's own tests:
//! crates/fit/tests/integration.)

use crate::common::default_scene_data;
use fogray::fit::dense::DenseGrid;
use fogray::fit::settings::{Budget, FitSettings, Sampling};
use fogray::fit::train::fit;
use fogray_grid::ring::Ring;

#[test]
fn a_tiny_fit_raises_the_test_psnr_by_5_db() {
    let ring = Ring::new(12, 2, 12).unwrap();
    let data = default_scene_data(&ring);
    for sampling in [Sampling::Uniform, Sampling::Occupancy] {
        let settings = FitSettings {
            grid: 12,
            batch: 512,
            sampling,
            lr: 0.3,
            ..FitSettings::default()
        }
        .with_budget(Budget::Steps(80));
        let result = fit::<f32, DenseGrid<f32>>(&data, &settings, &mut |_| {}).unwrap();
        let first = result.log[0].test_psnr;
        assert!(
            result.final_test_psnr > first + 5.0,
            "{sampling:?}: {first} -> {}",
            result.final_test_psnr
        );
        assert_eq!(result.renders.len(), ring.test_views().len());
    }
}
