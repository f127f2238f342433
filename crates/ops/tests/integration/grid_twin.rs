//! The fused grid field against its taped twin (f64, 1e-12 element by element, outputs and
//! both gradients) and both against central finite differences.

use crate::grid_common;

use fogray_ops::grid::twin;
use fogray_ops::GridField;
use fogray_tape::{gradcheck, GradcheckOptions, Tape, Var};
use grid_common::{node_position, positions_in_cells, random_field};
use ndarray::{Array2, ArrayD};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};

/// Output, dL/dgrid and dL/dpositions for L = sum(output * upstream), fused or taped.
fn run(
    field: &GridField,
    grid: &ArrayD<f64>,
    pts: &Array2<f64>,
    upstream: &Array2<f64>,
    taped: bool,
) -> [ArrayD<f64>; 3] {
    let mut tape = Tape::<f64>::new();
    let g = tape.param(grid.clone());
    let p = tape.param(pts.clone());
    let out = if taped {
        twin::lookup(&mut tape, field, g, p).unwrap()
    } else {
        field.apply(&mut tape, g, p).unwrap()
    };
    let grads = tape.backward_with(out, upstream.clone().into_dyn()).unwrap();
    [
        tape.value(out).unwrap().to_owned(),
        grads.get_or_zeros(&tape, g).unwrap(),
        grads.get_or_zeros(&tape, p).unwrap(),
    ]
}

/// Positions in and around the box (a tenth of the box's size beyond each face), a third of
/// the coordinates snapped to a node plane, some to a face of the box.
fn positions(seed: u64, field: &GridField, n: usize) -> Array2<f64> {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let d = field.dims();
    Array2::from_shape_fn((n, d), |(_, a)| {
        let nodes = field.nodes()[a];
        match rng.gen_range(0..3) {
            0 => node_position(field, a, rng.gen_range(0..nodes) as f64),
            _ => node_position(field, a, rng.gen_range(-0.1..1.1) * (nodes - 1) as f64),
        }
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Channel counts up to 9: the kernels' fixed widths (1 to 4), groups of 4 (8) and
    /// channel by channel (5, 6, 7, 9).
    #[test]
    fn fused_matches_the_taped_twin(
        seed in 0u64..1_000_000,
        nodes in proptest::collection::vec(2usize..6, 2..=3),
        ch in 1usize..10,
        n in 1usize..200,
    ) {
        let (field, grid) = random_field(seed, &nodes, ch);
        let pts = positions(seed + 1, &field, n);
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed + 2);
        let upstream = Array2::from_shape_fn((n, ch), |_| rng.gen_range(-1.0..1.0));
        let fused = run(&field, &grid, &pts, &upstream, false);
        let taped = run(&field, &grid, &pts, &upstream, true);
        for (what, (f, t)) in ["output", "grid gradient", "position gradient"].iter().zip(fused.iter().zip(&taped)) {
            prop_assert_eq!(f.shape(), t.shape());
            for (k, (a, b)) in f.iter().zip(t.iter()).enumerate() {
                prop_assert!((a - b).abs() <= 1e-12 * b.abs().max(1.0), "{} [{}]: fused {} taped {}", what, k, a, b);
            }
        }
    }
}

fn assert_gradcheck(
    name: &str,
    inputs: &[ArrayD<f64>],
    f: impl Fn(&mut Tape<f64>, &[Var]) -> fogray_tape::Result<Var>,
) {
    let report = gradcheck(f, inputs, &GradcheckOptions::default()).unwrap();
    if let Err(r) = report.check(1e-7, 1e-6) {
        panic!("{name}: {r}");
    }
}

/// Positions away from cell faces (the position gradient jumps there), plus some outside.
#[test]
fn gradcheck_fused_and_twin() {
    for (seed, nodes, ch) in [(1, vec![4, 3, 3], 2), (2, vec![3, 5], 3), (3, vec![2, 2, 2], 1)] {
        let (field, grid) = random_field(seed, &nodes, ch);
        let mut pts = positions_in_cells(seed, &field, 12, 0.1..0.9);
        pts[[0, 0]] = field.bbox().max()[0] + 0.5;
        pts[[1, field.dims() - 1]] = field.bbox().min()[field.dims() - 1] - 0.5;
        let inputs = [grid.clone(), pts.into_dyn()];
        let fused = field.clone();
        assert_gradcheck("fused", &inputs, move |t, v| fused.apply(t, v[0], v[1]));
        assert_gradcheck("twin", &inputs, |t, v| twin::lookup(t, &field, v[0], v[1]));
    }
}
