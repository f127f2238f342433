//! The sparse total-variation prior: the dense prior with every node stored, a pair-by-pair
//! oracle with nodes absent, finite differences, and any thread count.

use fogray_ops::grid::{NodeIndex, SparseGridField};
use fogray_ops::prior::{SparseTotalVariation, TotalVariation};
use fogray_ops::{GridBox, Op, OpsError};
use fogray_tape::{gradcheck, GradcheckOptions, Tape, TapeError, Var};
use ndarray::{Array2, IxDyn};
use rand::{Rng, SeedableRng};

fn field(nodes: [usize; 3], keep: &[bool], ch: usize) -> SparseGridField {
    let bbox = GridBox::new(&[0.0; 3], &[1.0; 3]).unwrap();
    SparseGridField::new(bbox, NodeIndex::from_mask(nodes, keep).unwrap(), ch).unwrap()
}

fn random_case(seed: u64, nodes: [usize; 3], ch: usize, kept: f64) -> (Vec<bool>, Array2<f64>) {
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let keep: Vec<bool> = (0..nodes.iter().product()).map(|_| rng.gen_bool(kept)).collect();
    let rows = keep.iter().filter(|&&k| k).count();
    (keep, Array2::from_shape_fn((rows, ch), |_| rng.gen_range(-1.0..1.0)))
}

/// The prior pair by pair from the definition: every node and axis whose neighbour is
/// stored too.
fn oracle(nodes: [usize; 3], keep: &[bool], v: &Array2<f64>, weight: f64) -> f64 {
    let row = |l: usize| keep[..l].iter().filter(|&&k| k).count();
    let [n0, n1, n2] = nodes;
    let (mut sum, mut terms) = (0.0, 0);
    for i in 0..n0 {
        for j in 0..n1 {
            for k in 0..n2 {
                let l = (i * n1 + j) * n2 + k;
                for (inside, m) in [(i + 1 < n0, l + n1 * n2), (j + 1 < n1, l + n2), (k + 1 < n2, l + 1)] {
                    if keep[l] && inside && keep[m] {
                        for c in 0..v.ncols() {
                            sum += (v[[row(m), c]] - v[[row(l), c]]).powi(2);
                            terms += 1;
                        }
                    }
                }
            }
        }
    }
    weight * sum / terms as f64
}

#[test]
fn with_every_node_stored_it_is_the_dense_prior() {
    let nodes = [4, 5, 3];
    let (_, v) = random_case(1, nodes, 3, 1.0);
    let tv = TotalVariation::new(0.7).unwrap();
    let sparse = SparseTotalVariation::new(tv, &field(nodes, &[true; 60], 3));
    let lattice = v.clone().into_shape_with_order(IxDyn(&[4, 5, 3, 3])).unwrap();
    let (a, b) = (
        sparse.value(&v.view().into_dyn()).unwrap(),
        tv.value(&lattice.view()).unwrap(),
    );
    assert!((a - b).abs() < 1e-15 * b, "{a} {b}");
    let mut dense_g = lattice.clone();
    tv.gradient_into(&lattice.view(), 1.5, dense_g.view_mut()).unwrap();
    let g = sparse.gradient(&v.view().into_dyn(), 1.5).unwrap();
    for (x, y) in g.iter().zip(dense_g.iter()) {
        assert!((x - y).abs() < 1e-15, "{x} {y}");
    }
}

#[test]
fn with_nodes_absent_it_is_the_pair_by_pair_sum_and_passes_gradcheck() {
    let nodes = [4, 3, 5];
    let (keep, v) = random_case(2, nodes, 2, 0.6);
    let sparse = SparseTotalVariation::new(TotalVariation::new(0.3).unwrap(), &field(nodes, &keep, 2));
    let value = sparse.value(&v.view().into_dyn()).unwrap();
    let want = oracle(nodes, &keep, &v, 0.3);
    assert!((value - want).abs() < 1e-14, "{value} {want}");
    let f = |t: &mut Tape<f64>, x: &[Var]| -> Result<Var, TapeError> { sparse.apply(t, x[0]) };
    let report = gradcheck(f, &[v.clone().into_dyn()], &GradcheckOptions::default()).unwrap();
    assert!(report.passes(), "{report}");
    assert!(report.entries.iter().any(|e| e.analytic.abs() > 1e-3));
}

#[test]
fn results_are_bitwise_the_same_on_any_thread_count() {
    let nodes = [30, 20, 25];
    let (keep, v) = random_case(3, nodes, 4, 0.5);
    let v = v.mapv(|x| x as f32);
    let sparse = SparseTotalVariation::new(TotalVariation::new(1.0).unwrap(), &field(nodes, &keep, 4));
    let at = |threads| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let value = sparse.value(&v.view().into_dyn()).unwrap();
            let g = sparse.gradient(&v.view().into_dyn(), 1.0).unwrap();
            (value.to_bits(), g.iter().map(|x| x.to_bits()).collect::<Vec<_>>())
        })
    };
    let one = at(1);
    assert!(one == at(2) && one == at(5));
}

#[test]
fn values_of_another_shape_are_an_error() {
    let sparse = SparseTotalVariation::new(TotalVariation::new(1.0).unwrap(), &field([2; 3], &[true; 8], 2));
    let v = Array2::<f64>::zeros((7, 2));
    assert!(matches!(
        sparse.value(&v.view().into_dyn()),
        Err(OpsError::Shape {
            op: Op::SparseTotalVariation,
            what: "sparse grid values",
            ..
        })
    ));
}
