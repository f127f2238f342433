//! The sparse grid: with every node kept it is the dense grid; its training loss against
//! central differences and its taped twin with nodes absent; which nodes a growth keeps;
//! resampling; its checkpoint; and a fit that prunes and loses nothing to the dense grid.

use crate::checkpoint;
use crate::dense::DenseGrid;
use crate::model::{RadianceField, TrainingBackground};
use crate::settings::{Budget, FitSettings, Method, ModelKind, SceneBox};
use crate::shading::Shading;
use crate::sparse::{keep_near_occupied, SparseGrid};
use crate::state::TrainingState;
use crate::train::fit;
use fogray_ops::grid::NodeIndex;
use fogray_ops::rays::Aabb;
use fogray_ops::sample::{CellPoints, OccupancyConfig, OccupancyGrid};
use fogray_tape::gradcheck::{gradcheck, GradcheckOptions};
use fogray_tape::{Tape, TapeError, Var};
use ndarray::{arr2, Array1, Array2, Array4, ArrayD, Ix2};

use crate::dense::tests::{raw_grid, setup};
use crate::testing::{ball_dataset, temp};

const BACKGROUND: [f64; 3] = [1.0, 0.95, 0.9];

/// A background of its own for each of [`setup`]'s rays (as random backgrounds give).
fn per_ray_background() -> TrainingBackground<f64> {
    TrainingBackground::PerRay(arr2(&[[0.2, 0.7, 0.1], [0.9, 0.4, 0.5], [0.0, 1.0, 0.3]]))
}

/// The dense grid's test raw values (every value different, densities around the shift).
fn raw_lattice() -> Array4<f64> {
    raw_grid().into_dimensionality().unwrap()
}

/// The 3^3 lattice's nodes with an odd linear index absent, except the centre.
fn some_absent() -> Vec<bool> {
    (0..27).map(|l| l % 2 == 0 || l == 13).collect()
}

/// A sparse grid over the unit box keeping `keep` of the 3^3 lattice, holding `raw`'s rows,
/// with the prior's weight `smoothness`.
fn sparse_model_tv(keep: &[bool], raw: &Array2<f64>, smoothness: f64) -> SparseGrid<f64> {
    let shading = Shading::new(-1.0, 0).unwrap();
    let index = NodeIndex::from_mask([3; 3], keep).unwrap();
    let mut model = SparseGrid::new(SceneBox::UNIT, 3, index, shading, smoothness).unwrap();
    let id = model.params().ids().next().unwrap();
    model.params_mut().get_mut(id).unwrap().assign(raw);
    model
}

/// [`sparse_model_tv`] without a prior.
fn sparse_model(keep: &[bool], raw: &Array2<f64>) -> SparseGrid<f64> {
    sparse_model_tv(keep, raw, 0.0)
}

/// The rows of `raw_lattice` that `keep` keeps.
fn kept_rows(keep: &[bool]) -> Array2<f64> {
    let full = raw_lattice().into_shape_with_order((27, 4)).unwrap();
    let rows: Vec<usize> = (0..27).filter(|&l| keep[l]).collect();
    Array2::from_shape_fn((rows.len(), 4), |(r, c)| full[[rows[r], c]])
}

/// The loss and the gradient of the packed values.
fn loss_and_gradient<M: RadianceField<f64>>(model: &M, method: Method) -> (f64, ArrayD<f64>) {
    let (rays, samples, target) = setup();
    let mut tape = Tape::<f64>::new();
    let target = tape.constant(target);
    let loss = model
        .training_loss(
            &mut tape,
            &rays,
            samples,
            TrainingBackground::Shared(BACKGROUND),
            target,
            method,
        )
        .unwrap();
    let value = tape.value(loss.objective).unwrap()[[]];
    let id = model.params().ids().next().unwrap();
    let g = tape.backward(loss.objective).unwrap().param(id).unwrap().to_owned();
    (value, g)
}

#[test]
fn with_every_node_kept_it_is_the_dense_grid() {
    let mut dense = DenseGrid::<f64>::new(SceneBox::UNIT, 3, -1.0, 0.0).unwrap();
    let id = dense.grid_id();
    dense
        .params_mut()
        .get_mut(id)
        .unwrap()
        .assign(&raw_lattice().into_dyn());
    let keep = vec![true; 27];
    let sparse = sparse_model(&keep, &kept_rows(&keep));
    let (l_dense, g_dense) = loss_and_gradient(&dense, Method::Fused);
    let (l_sparse, g_sparse) = loss_and_gradient(&sparse, Method::Fused);
    assert_eq!(l_dense, l_sparse);
    let g_dense = g_dense.into_shape_with_order((27, 4)).unwrap().into_dyn();
    assert!(g_dense.iter().any(|v| v.abs() > 1e-3));
    for (a, b) in g_dense.iter().zip(&g_sparse) {
        assert!((a - b).abs() < 1e-15, "{a} {b}");
    }
}

#[test]
fn with_nodes_absent_a_prior_and_the_distortion_loss_the_loss_passes_gradcheck_and_fused_is_taped() {
    let keep = some_absent();
    let objective = |tape: &mut Tape<f64>, data: Var, method: Method| -> Result<Var, TapeError> {
        // The model's own copy of the values carries its gradient to `data` (exactly 0 added).
        let value = tape.value(data)?.to_owned().into_dimensionality::<Ix2>().unwrap();
        let model = sparse_model_tv(&keep, &value, 0.05).with_distortion(0.05).unwrap();
        let (rays, samples, target) = setup();
        let target = tape.constant(target);
        let loss = model
            .training_loss(tape, &rays, samples, per_ray_background(), target, method)?
            .objective;
        let id = model.params().ids().next().unwrap();
        let g = tape.backward(loss)?.param(id).unwrap().to_owned();
        let g = tape.constant(g);
        let frozen = tape.detach(data)?;
        let zero = tape.sub(data, frozen)?;
        let carried = tape.mul(zero, g)?;
        let carried = tape.sum(carried)?;
        tape.add(loss, carried)
    };
    let rows = kept_rows(&keep);
    assert_eq!(rows.nrows(), 15);
    for method in [Method::Fused, Method::Taped] {
        let report = gradcheck(
            |t, v| objective(t, v[0], method),
            &[rows.clone().into_dyn()],
            &GradcheckOptions::default(),
        )
        .unwrap();
        assert!(report.passes(), "{method:?}: {report}");
        assert!(report.entries.iter().any(|e| e.analytic.abs() > 1e-3));
    }
    let model = sparse_model_tv(&keep, &rows, 0.05).with_distortion(0.05).unwrap();
    let (l0, g0) = loss_and_gradient(&model, Method::Fused);
    let (l1, g1) = loss_and_gradient(&model, Method::Taped);
    assert!((l0 - l1).abs() < 1e-14, "{l0} {l1}");
    for (a, b) in g0.iter().zip(&g1) {
        assert!((a - b).abs() < 1e-13, "{a} {b}");
    }
}

/// An occupancy grid of 4^3 cells over the unit box with only cell `[1, 1, 1]` occupied.
fn one_occupied_cell() -> OccupancyGrid {
    let bounds = Aabb::new([-1.0; 3], [1.0; 3]).unwrap();
    let mut grid = OccupancyGrid::new(bounds, 4, OccupancyConfig::density(1.0).unwrap()).unwrap();
    // Cell [1, 1, 1] spans [-0.5, 0]^3.
    let density = |p: ndarray::ArrayView2<'_, f64>| -> Result<Array1<f64>, String> {
        Ok(p.rows()
            .into_iter()
            .map(|q| {
                if q.iter().all(|&x| (-0.5..0.0).contains(&x)) {
                    10.0
                } else {
                    0.0
                }
            })
            .collect())
    };
    grid.update(density, CellPoints::Centre).unwrap();
    assert_eq!(grid.occupied_fraction(), 1.0 / 64.0);
    grid
}

#[test]
fn a_growth_keeps_the_nodes_within_the_dilation_of_an_occupied_cell() {
    let grid = one_occupied_cell();
    // Nodes every 0.25 over [-1, 1]; cells 0..=2 per axis (dilation 1 around cell 1) span
    // [-1, 0.5), which holds 6 of the 9 node positions per axis (0.5 itself is in cell 3).
    let keep = keep_near_occupied(&SceneBox::UNIT, 9, &grid, 1);
    assert_eq!(keep.iter().filter(|&&k| k).count(), 6 * 6 * 6);
    assert!(keep[0] && !keep[8]); // node [0, 0, 0] at (-1, -1, -1); [0, 0, 8] at (-1, -1, 1)
                                  // Dilation 0: the cell [-0.5, 0) holds nodes -0.5 and -0.25 per axis.
    let keep = keep_near_occupied(&SceneBox::UNIT, 9, &grid, 0);
    assert_eq!(keep.iter().filter(|&&k| k).count(), 8);
}

#[test]
fn a_pruned_growth_keeps_a_linear_field_exactly_at_its_nodes() {
    // f = 1 + x - 2y + 3z in every channel (scaled by c + 1): trilinear interpolation holds it.
    let f = |p: [f64; 3], c: usize| (1.0 + p[0] - 2.0 * p[1] + 3.0 * p[2]) * (c + 1) as f64;
    let node = |i: usize| -1.0 + i as f64;
    let raw = Array2::from_shape_fn((27, 4), |(l, c)| f([node(l / 9), node(l / 3 % 3), node(l % 3)], c));
    let model = sparse_model(&[true; 27], &raw);
    let grid = one_occupied_cell();
    let grown = model
        .resampled_onto(9, &keep_near_occupied(&SceneBox::UNIT, 9, &grid, 1))
        .unwrap();
    assert_eq!(grown.kept(), 6 * 6 * 6);
    let data = grown
        .params()
        .get(grown.params().ids().next().unwrap())
        .unwrap()
        .to_owned();
    for (r, l) in grown.index().kept_nodes().into_iter().enumerate() {
        let p = [l / 81, l / 9 % 9, l % 9].map(|i| -1.0 + i as f64 * 0.25);
        for c in 0..4 {
            assert!((data[[r, c]] - f(p, c)).abs() < 1e-12, "node {l} channel {c}");
        }
    }
}

#[test]
fn a_checkpoint_keeps_the_kept_nodes_and_their_values() {
    let keep = some_absent();
    let model = sparse_model(&keep, &kept_rows(&keep));
    let settings = FitSettings {
        grid: 3,
        shift: -1.0,
        model: ModelKind::Sparse,
        precision: crate::settings::Precision::F64,
        ..FitSettings::default()
    };
    let path = temp("sparse.safetensors");
    checkpoint::save(&path, &model, &TrainingState::default(), &settings, &Default::default()).unwrap();
    let loaded = checkpoint::load::<f64, SparseGrid<f64>>(&path).unwrap().start.model;
    assert_eq!(loaded.index(), model.index());
    let values = |m: &SparseGrid<f64>| m.params().get(m.params().ids().next().unwrap()).unwrap().to_owned();
    assert_eq!(values(&loaded), values(&model));
    // A dense grid's file is not a sparse grid.
    let dense = DenseGrid::<f64>::new(SceneBox::UNIT, 3, -1.0, 0.0).unwrap();
    checkpoint::save(&path, &dense, &TrainingState::default(), &settings, &Default::default()).unwrap();
    assert!(checkpoint::load::<f64, SparseGrid<f64>>(&path).is_err());
}

#[test]
fn a_sparse_fit_prunes_the_empty_space_and_fits_as_well_as_the_dense_grid() {
    let data = ball_dataset(10, 2, 16);
    let settings = FitSettings {
        grid: 32,
        batch: 512,
        evaluations: 1,
        ..FitSettings::default()
    }
    .with_budget(Budget::Steps(300));
    let dense = fit::<f32, DenseGrid<f32>>(&data, &settings, &mut |_| {}).unwrap();
    let sparse = fit::<f32, SparseGrid<f32>>(
        &data,
        &FitSettings {
            model: ModelKind::Sparse,
            ..settings
        },
        &mut |_| {},
    )
    .unwrap();
    // The ball of radius 0.5 fills 7 % of the box: most of the lattice is pruned.
    let kept = sparse.model.kept() as f64 / 32f64.powi(3);
    assert!(kept < 0.4, "kept {kept}");
    assert!(dense.final_test_psnr > 20.0, "{}", dense.final_test_psnr);
    assert!(
        sparse.final_test_psnr > dense.final_test_psnr - 0.5,
        "sparse {} dense {}",
        sparse.final_test_psnr,
        dense.final_test_psnr
    );
}

#[test]
fn a_short_fit_grows_only_after_the_occupancy_grid_has_seen_each_stage() {
    // 200 steps: the budget's growth points (steps 20 and 60) come before the occupancy grid's
    // first refresh (step 64), where a growth would keep every node; the growths wait for it
    // (steps 64 and 128) and prune.
    let data = ball_dataset(10, 2, 16);
    let settings = FitSettings {
        grid: 32,
        batch: 256,
        evaluations: 1,
        model: ModelKind::Sparse,
        ..FitSettings::default()
    }
    .with_budget(Budget::Steps(200));
    let sparse = fit::<f32, SparseGrid<f32>>(&data, &settings, &mut |_| {}).unwrap();
    assert_eq!(sparse.model.nodes(), 32);
    let kept = sparse.model.kept() as f64 / 32f64.powi(3);
    assert!(kept < 0.4, "kept {kept}");
}

#[test]
fn a_refresh_that_skips_the_known_cells_is_the_refresh_of_every_cell() {
    // A 9^3 lattice keeping a block of nodes off centre, every kept value different.
    let n = 9;
    let keep: Vec<bool> = (0..n * n * n)
        .map(|l| {
            let i = [l / (n * n), l / n % n, l % n];
            (2..=4).contains(&i[0]) && (3..=6).contains(&i[1]) && (1..=4).contains(&i[2])
        })
        .collect();
    let index = NodeIndex::from_mask([n; 3], &keep).unwrap();
    let kept = index.kept();
    let shading = Shading::new(-4.0, 1).unwrap();
    let mut model = SparseGrid::<f32>::new(SceneBox::UNIT, n, index, shading, 0.0).unwrap();
    let id = model.params().ids().next().unwrap();
    let raw = Array2::from_shape_fn((kept, shading.channels()), |(r, c)| ((r * 7 + c * 3) % 11) as f32 - 2.0);
    model.params_mut().get_mut(id).unwrap().assign(&raw);
    let bounds = Aabb::new([-1.0; 3], [1.0; 3]).unwrap();
    // Occupancy cells finer, coarser and out of step with the lattice's.
    for r in [4, 7, 8, 13] {
        let config = OccupancyConfig::density(0.5).unwrap();
        let mut every = OccupancyGrid::new(bounds, r, config).unwrap();
        let mut skipping = every.clone();
        let known = model.known_cells(&skipping).unwrap().unwrap();
        let marked = known.cells.iter().filter(|&&k| k).count();
        assert!(marked > 0 && marked < r * r * r, "r {r}: {marked} cells known");
        // raw 0 through softplus(x - 4), in f32: ln(1 + e^-4) to f32's rounding.
        let fog = (-4.0f64).exp().ln_1p();
        assert!((known.density - fog).abs() < 1e-9, "{} vs {fog}", known.density);
        skipping.set_known_cells(Some(known)).unwrap();
        for seed in [1, 2] {
            let points = CellPoints::CentreAndRandom { seed };
            every.update(|p| model.densities(p), points).unwrap();
            skipping.update(|p| model.densities(p), points).unwrap();
            assert_eq!(every.state(), skipping.state(), "r {r}, seed {seed}");
        }
    }
}
