//! A contracted grid's cells judged by the world length of a step there: a far shell that
//! stops light is kept where the inner step's criterion prunes it.

use fogray_tape::Tape;
use ndarray::{arr2, Array1, Array2, ArrayView2};

use super::{CellPoints, ContractedOccupancy, ContractedSampler, Jitter, OccupancyConfig, OccupancyGrid};
use crate::rays::{Aabb, RayBatch};
use crate::space::{Contraction, InnerRegion};
use crate::{Background, Composite, CompositeInputs};

const R: f64 = 2.0;
const STEP: f64 = 1.0 / 64.0;
const OPACITY: f64 = 0.01;

fn sampler() -> ContractedSampler {
    ContractedSampler::new(Contraction::new(InnerRegion::new([0.0; 3], R).unwrap()).unwrap(), STEP).unwrap()
}

/// A shell of density `sigma1` (per world unit) between `|x|_inf = 2 r` and `4 r`, i.e.
/// between the contracted norms 1.5 and 1.75: the 16-cell grid's layers 14 and 1 of cells.
fn shell(sigma1: f64) -> impl Fn(ArrayView2<'_, f64>) -> Result<Array1<f64>, std::convert::Infallible> + Sync {
    move |p: ArrayView2<'_, f64>| {
        let space = Contraction::new(InnerRegion::new([0.0; 3], R).unwrap()).unwrap();
        Ok(Array1::from_iter(p.rows().into_iter().map(|y| {
            let x = space.inverse([y[0], y[1], y[2]]).unwrap();
            let m = x.iter().fold(0f64, |a, v| a.max(v.abs())) / R;
            if (2.0..4.0).contains(&m) {
                sigma1
            } else {
                0.0
            }
        })))
    }
}

fn opacity(samples: &super::PackedSamples<f64>, sigma: Array1<f64>) -> f64 {
    let mut tape = Tape::<f64>::new();
    let n = samples.len();
    let inputs = CompositeInputs {
        sigma: tape.constant(sigma),
        delta: tape.constant(samples.delta.clone()),
        color: tape.constant(Array2::ones((n, 1))),
        background: None,
        t: None,
    };
    let op = Composite::new(&samples.offsets).unwrap().background(Background::None);
    let out = op.apply(&mut tape, &inputs).unwrap();
    tape.value(out.opacity).unwrap()[0]
}

#[test]
fn a_far_shell_that_stops_light_is_kept() {
    let s = sampler();
    // Half the density at which one inner step (world length s r) is 1 % opaque: the
    // criterion with the inner step prunes it everywhere. Across the shell a radial ray
    // travels 2 r of world: optical depth 0.5 (-ln 0.99) 2 / s, about 0.64.
    let inner_threshold = -(-OPACITY).ln_1p() / (STEP * R);
    let sigma1 = 0.5 * inner_threshold;
    let tau = sigma1 * 2.0 * R;
    assert!(tau > 0.6);

    let mut naive = OccupancyGrid::new(
        Contraction::cube(),
        16,
        OccupancyConfig::opacity(STEP * R, OPACITY).unwrap(),
    )
    .unwrap();
    naive.update(shell(sigma1), CellPoints::Centre).unwrap();
    assert_eq!(naive.occupied_fraction(), 0.0);

    let mut grid = OccupancyGrid::new(
        Contraction::cube(),
        16,
        OccupancyConfig::opacity(STEP, OPACITY).unwrap(),
    )
    .unwrap();
    let scale = ContractedOccupancy::new(&s, &grid).unwrap();
    grid.update(scale.optical_density(shell(sigma1)), CellPoints::Centre)
        .unwrap();
    // The shell's cells: centre norm 1.625 (layer 14 or 1 on some axis, the others within).
    assert!(grid.is_occupied([14, 8, 8]) && grid.is_occupied([1, 5, 12]) && grid.is_occupied([14, 14, 14]));
    // Nothing else: the inner region and the outermost layer hold no density.
    assert!(!grid.is_occupied([8, 8, 8]) && !grid.is_occupied([15, 8, 8]) && !grid.is_occupied([13, 8, 8]));

    // Rendered along +x from the centre: the shell's faces are at the edges 96 and 112 (the
    // contracted x = k s), so its pieces are exactly the shell and the opacity its closed
    // form; the naive grid leaves the ray nothing.
    let rays = RayBatch::new(arr2(&[[0.0, 0.0, 0.0]]), arr2(&[[1.0, 0.0, 0.0]])).unwrap();
    let sampled = |g: &OccupancyGrid| {
        let samples = s.sample(&rays, &[0.0], Jitter::None, Some(g)).unwrap();
        let sigma = shell(sigma1)(samples.positions.view()).unwrap();
        opacity(&samples, sigma)
    };
    assert_eq!(sampled(&naive), 0.0);
    let kept = sampled(&grid);
    // Edges solved to 1e-12 in contracted units, 1e-12 r m^2 (m <= 4) in the world.
    assert!((kept - (1.0 - (-tau).exp())).abs() < 1e-10, "{kept}");
    // Each of those pieces is well above the threshold: at least 4 times the inner step.
    let samples = s.sample(&rays, &[0.0], Jitter::None, Some(&grid)).unwrap();
    assert!(samples.delta.iter().all(|&d| sigma1 * d > -(-OPACITY).ln_1p()));
}

#[test]
fn cell_stretch_is_r_inside_and_bounded_by_the_contraction_outside() {
    let s = sampler();
    let grid = OccupancyGrid::new(
        Contraction::cube(),
        16,
        OccupancyConfig::opacity(STEP, OPACITY).unwrap(),
    )
    .unwrap();
    let scale = ContractedOccupancy::new(&s, &grid).unwrap();
    // Cells 4..=11 on every axis lie in [-1, 1]^3.
    assert_eq!(scale.cell_stretch([4, 11, 7]), R);
    // Layer 14 reaches norm 1.75 (m = 4): at least the radial stretch r m^2.
    let outer = scale.cell_stretch([14, 8, 8]);
    assert!(outer >= R * 16.0 && outer <= 3f64.sqrt() * R * 16.0, "{outer}");
    assert_eq!(outer, s.contraction().max_stretch(1.75));
    // The outermost layer is capped at the far gap: m = 1 / gap.
    let last = scale.cell_stretch([15, 0, 3]);
    assert_eq!(last, s.contraction().max_stretch(2.0 - s.far_gap()));
    assert!(last.is_finite());
    assert_eq!(scale.stretch_at([1.6, 0.1, -0.2]), outer);
    assert_eq!(scale.stretch_at([5.0, 0.0, 0.0]), last);
    // A grid over another box has no contracted cells.
    let boxed = OccupancyGrid::new(
        Aabb::new([-1.0; 3], [1.0; 3]).unwrap(),
        4,
        OccupancyConfig::density(0.0).unwrap(),
    )
    .unwrap();
    assert!(ContractedOccupancy::new(&s, &boxed).is_err());
}

#[test]
fn a_density_of_the_wrong_length_is_reported_by_the_grid() {
    let s = sampler();
    let mut grid =
        OccupancyGrid::new(Contraction::cube(), 4, OccupancyConfig::opacity(STEP, OPACITY).unwrap()).unwrap();
    let scale = ContractedOccupancy::new(&s, &grid).unwrap();
    let short = |_: ArrayView2<'_, f64>| Ok::<_, std::convert::Infallible>(Array1::zeros(1));
    let before = grid.clone();
    assert!(grid.update(scale.optical_density(short), CellPoints::Centre).is_err());
    assert_eq!(grid, before);
}
