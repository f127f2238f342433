//! The sparse grid field against the textbook oracle on the dense lattice with its absent
//! nodes set to 0, against its taped twin and finite differences, on any thread count, and
//! its errors.

use crate::grid_common::{oracle, oracle_grid_gradient, positions_in_cells, random_field};

use fogray_ops::grid::{sparse, NodeIndex, SparseGridField};
use fogray_ops::{At, GridBox, GridField, GridWanted, Op, OpsError};
use fogray_tape::{gradcheck, Float, GradcheckOptions, Tape, TapeError, Var};
use ndarray::{Array2, ArrayD, IxDyn};
use rand::{Rng, SeedableRng};

const BOTH: GridWanted = GridWanted {
    grid: true,
    positions: true,
};

/// A random field's lattice with about `kept` of its nodes stored: the sparse field, its
/// packed values, and the dense values with the absent nodes at 0.
fn sparse_case(
    seed: u64,
    nodes: [usize; 3],
    ch: usize,
    kept: f64,
) -> (SparseGridField, GridField, Array2<f64>, ArrayD<f64>) {
    let (dense, values) = random_field(seed, &nodes, ch);
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed + 1000);
    let keep: Vec<bool> = (0..nodes.iter().product()).map(|_| rng.gen_bool(kept)).collect();
    let index = NodeIndex::from_mask(nodes, &keep).unwrap();
    let field = SparseGridField::new(*dense.bbox(), index, ch).unwrap();
    let flat = values.as_slice().unwrap();
    let rows = field.index().kept_nodes();
    let data = Array2::from_shape_fn((rows.len(), ch), |(r, c)| flat[rows[r] * ch + c]);
    let mut zeroed = values.clone();
    for (l, k) in keep.iter().enumerate() {
        if !k {
            zeroed.as_slice_mut().unwrap()[l * ch..(l + 1) * ch].fill(0.0);
        }
    }
    (field, dense, data, zeroed)
}

/// Positions in the cells, some on faces, a few outside the box.
fn positions(seed: u64, dense: &GridField, n: usize) -> Array2<f64> {
    let mut p = positions_in_cells(seed, dense, n, 0.0..1.0);
    p[[0, 0]] = dense.bbox().max()[0] + 0.5;
    p[[1, 2]] = f64::NEG_INFINITY;
    p
}

#[test]
fn lookups_and_gradients_match_the_oracle_on_the_zeroed_lattice() {
    for (seed, nodes, ch, kept) in [(1, [5, 4, 6], 3, 0.5), (2, [9, 7, 3], 13, 0.3), (3, [4, 4, 4], 1, 0.9)] {
        let (field, dense, data, zeroed) = sparse_case(seed, nodes, ch, kept);
        let p = positions(seed + 7, &dense, 400);
        let out = field.evaluate(&data.view().into_dyn(), &p.view().into_dyn()).unwrap();
        let want = oracle(&dense, &zeroed, &p);
        let err = (&out - &want.into_dyn())
            .mapv(f64::abs)
            .fold(0.0, |m: f64, &v| m.max(v));
        assert!(err < 1e-14, "{nodes:?}: values off by {err}");
        let up = Array2::from_shape_fn((p.nrows(), ch), |(s, c)| ((s * 7 + c) % 11) as f64 / 5.0 - 1.0);
        let g = field
            .vjp(
                &data.view().into_dyn(),
                &p.view().into_dyn(),
                &up.view().into_dyn(),
                BOTH,
            )
            .unwrap();
        let want = oracle_grid_gradient(&dense, &p, &up);
        let want = want.as_slice().unwrap();
        let got = g.grid.unwrap();
        for (r, &node) in field.index().kept_nodes().iter().enumerate() {
            for c in 0..ch {
                let (a, b) = (got[[r, c]], want[node * ch + c]);
                assert!((a - b).abs() < 1e-12, "{nodes:?} row {r} channel {c}: {a} vs {b}");
            }
        }
        // The position gradient is the dense field's on the zeroed lattice, bit for bit.
        let dense_g = dense
            .vjp(&zeroed.view(), &p.view().into_dyn(), &up.view().into_dyn(), BOTH)
            .unwrap();
        assert_eq!(g.positions.unwrap(), dense_g.positions.unwrap());
    }
}

#[test]
fn with_every_node_kept_the_values_are_the_dense_fields_bit_for_bit() {
    let (dense, values) = random_field(11, &[6, 5, 7], 4);
    let field = SparseGridField::new(*dense.bbox(), NodeIndex::full([6, 5, 7]).unwrap(), 4).unwrap();
    let data = values.clone().into_shape_with_order(IxDyn(&[6 * 5 * 7, 4])).unwrap();
    let p = positions(12, &dense, 1000).mapv(|v| v as f32);
    let (data, values) = (data.mapv(|v| v as f32), values.mapv(|v| v as f32));
    let sparse = field.evaluate(&data.view(), &p.view().into_dyn()).unwrap();
    let dense_out = dense.evaluate(&values.view(), &p.view().into_dyn()).unwrap();
    let bits = |a: &ArrayD<f32>| a.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&sparse), bits(&dense_out));
}

#[test]
fn the_fused_op_matches_its_twin_and_both_pass_gradcheck() {
    let (field, dense, data, _) = sparse_case(21, [4, 5, 3], 2, 0.6);
    let p = positions_in_cells(22, &dense, 6, 0.1..0.9);
    let w = Array2::from_shape_fn((6, 2), |(s, c)| (s + 2 * c) as f64 / 7.0 - 0.4);
    let loss = |fused: bool| {
        let (field, w) = (field.clone(), w.clone());
        move |t: &mut Tape<f64>, v: &[Var]| -> Result<Var, TapeError> {
            let out = if fused {
                field.apply(t, v[0], v[1])?
            } else {
                sparse::twin::lookup(t, &field, v[0], v[1])?
            };
            let w = t.constant(w.clone());
            let weighted = t.mul(out, w)?;
            t.sum(weighted)
        }
    };
    let inputs = [data.clone().into_dyn(), p.clone().into_dyn()];
    let mut grads = Vec::new();
    for fused in [true, false] {
        let report = gradcheck(loss(fused), &inputs, &GradcheckOptions::default()).unwrap();
        assert!(report.passes(), "fused {fused}: {report}");
        let mut t = Tape::new();
        let vars: Vec<Var> = inputs.iter().map(|x| t.param(x.clone())).collect();
        let l = loss(fused)(&mut t, &vars).unwrap();
        let g = t.backward(l).unwrap();
        grads.push((
            t.value(l).unwrap()[[]],
            g.get(vars[0]).unwrap().to_owned(),
            g.get(vars[1]).unwrap().to_owned(),
        ));
    }
    let ((l0, d0, p0), (l1, d1, p1)) = (&grads[0], &grads[1]);
    assert!((l0 - l1).abs() < 1e-13);
    assert!((d0 - d1).iter().all(|v| v.abs() < 1e-13));
    assert!((p0 - p1).iter().all(|v| v.abs() < 1e-12));
}

fn on_threads<F: Float>(
    threads: usize,
    field: &SparseGridField,
    data: &Array2<F>,
    p: &Array2<F>,
    up: &Array2<F>,
) -> Vec<u64> {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
    pool.install(|| {
        let out = field.evaluate(&data.view().into_dyn(), &p.view().into_dyn()).unwrap();
        let g = field
            .vjp(
                &data.view().into_dyn(),
                &p.view().into_dyn(),
                &up.view().into_dyn(),
                BOTH,
            )
            .unwrap();
        out.iter()
            .chain(g.grid.unwrap().iter())
            .chain(g.positions.unwrap().iter())
            .map(|v| v.as_f64().to_bits())
            .collect()
    })
}

/// Many positions per cell, so that the order of the sums shows in the last bits.
#[test]
fn results_are_bitwise_the_same_on_any_thread_count() {
    let (field, dense, data, _) = sparse_case(31, [12, 9, 10], 5, 0.7);
    let p = positions_in_cells(32, &dense, 50_000, 0.0..1.0);
    let up = Array2::from_shape_fn((p.nrows(), 5), |(s, c)| ((s * 13 + c * 5) % 17) as f64 / 3.0 - 2.5);
    let (data32, p32, up32) = (data.mapv(|v| v as f32), p.mapv(|v| v as f32), up.mapv(|v| v as f32));
    let one = on_threads(1, &field, &data32, &p32, &up32);
    for threads in [2, 3, 8] {
        assert!(
            one == on_threads(threads, &field, &data32, &p32, &up32),
            "f32, {threads} threads"
        );
    }
    assert!(on_threads(1, &field, &data, &p, &up) == on_threads(5, &field, &data, &p, &up));
}

#[test]
fn bad_input_is_an_error_naming_it() {
    let (field, dense, data, _) = sparse_case(41, [3, 3, 3], 2, 0.5);
    let mut p = positions_in_cells(42, &dense, 4, 0.1..0.9);
    let short = data.slice(ndarray::s![1.., ..]).to_owned();
    assert!(matches!(
        field.evaluate(&short.view().into_dyn(), &p.view().into_dyn()),
        Err(OpsError::Shape {
            op: Op::SparseGridField,
            what: "sparse grid values",
            ..
        })
    ));
    p[[2, 1]] = f64::NAN;
    assert!(matches!(
        field.evaluate(&data.view().into_dyn(), &p.view().into_dyn()),
        Err(OpsError::Domain {
            op: Op::SparseGridField,
            at: At::Entry { row: 2, column: 1 },
            ..
        })
    ));
    let up = Array2::<f64>::zeros((3, 2));
    p[[2, 1]] = 0.0;
    assert!(matches!(
        field.vjp(
            &data.view().into_dyn(),
            &p.view().into_dyn(),
            &up.view().into_dyn(),
            BOTH
        ),
        Err(OpsError::Shape {
            op: Op::SparseGridField,
            what: "upstream gradient",
            ..
        })
    ));
    let flat = GridBox::new(&[0.0; 2], &[1.0; 2]).unwrap();
    assert!(SparseGridField::new(flat, NodeIndex::full([2, 2, 2]).unwrap(), 1).is_err());
    assert!(SparseGridField::new(*dense.bbox(), NodeIndex::full([2, 2, 2]).unwrap(), 0).is_err());
}
