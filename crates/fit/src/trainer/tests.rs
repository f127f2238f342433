//! The trainer driven step by step, and each policy alone.

use fogray_tape::optim::{Adam, AdamConfig};

use super::*;
use crate::dense::DenseGrid;
use crate::schedule::learning_rate;
use crate::settings::Sampling;
use crate::sparse::SparseGrid;
use crate::state::{Start, TrainingState};
use crate::testing::small_dataset;
use crate::train::fit;

fn settings(steps: usize) -> FitSettings {
    FitSettings {
        grid: 12,
        batch: 96,
        steps: Some(steps),
        evaluations: 3,
        ..FitSettings::default()
    }
}

fn values<F: Float, M: RadianceField<F>>(model: &M) -> Vec<Vec<f64>> {
    let params = model.params();
    params
        .ids()
        .map(|id| params.get(id).unwrap().iter().map(|v| v.as_f64()).collect())
        .collect()
}

#[test]
fn stepping_a_trainer_by_hand_is_the_budget_loop_bit_for_bit() {
    let data = small_dataset();
    let s = settings(40);
    let fitted = fit::<f32, SparseGrid<f32>>(&data, &s, &mut |_| {}).unwrap();
    let mut trainer = Trainer::<f32, SparseGrid<f32>>::new(&data, &s, None).unwrap();
    let mut losses = Vec::new();
    while !trainer.is_done() {
        losses.push(trainer.step().unwrap().loss);
    }
    assert_eq!(losses.len(), 40);
    assert_eq!(values(trainer.model()), values(&fitted.model));
    // Everything but the clock.
    let state = TrainingState {
        seconds: fitted.training.seconds,
        ..trainer.state().unwrap()
    };
    assert_eq!(state, fitted.training);
    let last = trainer.evaluate(true).unwrap();
    assert_eq!(last.entry.test_psnr, fitted.final_test_psnr);
    // Evaluating with depth renders the same colours as without.
    assert_eq!(trainer.evaluate(false).unwrap().views[0].color, last.views[0].color);
}

#[test]
fn a_trainer_rebuilt_from_its_state_continues_bit_for_bit() {
    let data = small_dataset();
    let s = settings(30);
    let mut whole = Trainer::<f32, DenseGrid<f32>>::new(&data, &s, None).unwrap();
    let mut first = Trainer::<f32, DenseGrid<f32>>::new(&data, &s, None).unwrap();
    for _ in 0..17 {
        whole.step().unwrap();
        first.step().unwrap();
    }
    let training = first.state().unwrap();
    let (model, _) = first.into_parts();
    let mut second = Trainer::new(&data, &s, Some(Start { model, training })).unwrap();
    while !whole.is_done() {
        whole.step().unwrap();
        second.step().unwrap();
    }
    assert!(second.is_done());
    assert_eq!(values(second.model()), values(whole.model()));
}

/// A context over `model` at `step` and `fraction`, with a fresh Adam and no occupancy grid.
fn context<'a, M>(
    model: &'a mut M,
    optimiser: &'a mut Adam<f64>,
    occupancy: &'a mut Option<OccupancyGrid>,
    step: usize,
    fraction: f64,
) -> StepContext<'a, f64, M> {
    StepContext {
        step,
        fraction,
        model,
        optimiser,
        occupancy,
    }
}

#[test]
fn the_growth_policy_doubles_the_lattice_at_its_fractions_and_resets_adam() {
    let s = FitSettings {
        grid: 16,
        ..settings(100)
    };
    let mut model = DenseGrid::<f64>::fresh(&s, 4).unwrap();
    let mut growth = Growth::new(&s, 0, 4, None).unwrap();
    let mut adam = Adam::new(AdamConfig::default()).unwrap();
    let mut none = None;
    // Adam has a moment for every parameter it updated: make one so its reset shows.
    let id = model.params().ids().next().unwrap();
    let mut grads = fogray_tape::optim::ParamGradients::new();
    let ones = model.params().get(id).unwrap().mapv(|_| 1.0);
    grads.insert(model.params(), id, ones).unwrap();
    adam.step(model.params_mut(), &grads).unwrap();
    assert_eq!(adam.updates(id), 1);
    growth
        .before_step(&mut context(&mut model, &mut adam, &mut none, 9, 0.099))
        .unwrap();
    assert_eq!((model.nodes(), growth.stage(), adam.updates(id)), (4, 0, 1));
    growth
        .before_step(&mut context(&mut model, &mut adam, &mut none, 10, 0.1))
        .unwrap();
    assert_eq!((model.nodes(), growth.stage(), adam.updates(id)), (8, 1, 0));
    growth
        .before_step(&mut context(&mut model, &mut adam, &mut none, 29, 0.29))
        .unwrap();
    assert_eq!(model.nodes(), 8);
    growth
        .before_step(&mut context(&mut model, &mut adam, &mut none, 30, 0.3))
        .unwrap();
    assert_eq!((model.nodes(), growth.stage()), (16, 2));
    // The last stage stays.
    growth
        .before_step(&mut context(&mut model, &mut adam, &mut none, 99, 0.99))
        .unwrap();
    assert_eq!(model.nodes(), 16);
    // A model that is not at the stage it claims is refused.
    assert!(Growth::new(&s, 1, 4, None).is_err());
}

#[test]
fn a_model_pruned_by_occupancy_grows_no_sooner_than_its_refreshes() {
    let s = FitSettings {
        grid: 16,
        ..settings(20)
    };
    let mut model = DenseGrid::<f64>::fresh(&s, 4).unwrap();
    // First refresh at step 16: stage 1 waits until step 16, stage 2 until step 32.
    let mut growth = Growth::new(&s, 0, 4, Some(16)).unwrap();
    let mut adam = Adam::new(AdamConfig::default()).unwrap();
    let mut none = None;
    growth
        .before_step(&mut context(&mut model, &mut adam, &mut none, 15, 0.75))
        .unwrap();
    assert_eq!(growth.stage(), 0);
    growth
        .before_step(&mut context(&mut model, &mut adam, &mut none, 16, 0.8))
        .unwrap();
    assert_eq!(growth.stage(), 1);
    growth
        .before_step(&mut context(&mut model, &mut adam, &mut none, 31, 0.95))
        .unwrap();
    assert_eq!(growth.stage(), 1);
}

#[test]
fn the_rate_policy_sets_the_schedules_rate() {
    let s = FitSettings {
        lr: 0.3,
        lr_final: 0.003,
        ..settings(10)
    };
    let mut model = DenseGrid::<f64>::fresh(&s, 4).unwrap();
    let mut adam = Adam::new(AdamConfig::default()).unwrap();
    let mut none = None;
    let mut rate = LearningRate::new(&s);
    for fraction in [0.0, 0.5, 0.6, 0.8, 1.0] {
        rate.before_step(&mut context(&mut model, &mut adam, &mut none, 0, fraction))
            .unwrap();
        // Constant to 60 %, then geometric: 0.3 * 0.01^((f - 0.6) / 0.4).
        let expected = if fraction <= 0.6 {
            0.3
        } else {
            0.3 * 0.01f64.powf((fraction - 0.6) / 0.4)
        };
        assert!((adam.config().lr - expected).abs() < 1e-15, "{fraction}");
        assert_eq!(adam.config().lr, learning_rate(&s, fraction));
    }
}

#[test]
fn the_refresh_policy_keeps_every_cell_while_no_density_reaches_the_threshold() {
    let s = FitSettings {
        sampling: Sampling::Occupancy,
        // A thin fog everywhere: no cell stops 1 % of the light at the first refresh.
        shift: -30.0,
        ..settings(100)
    };
    let mut model = DenseGrid::<f64>::fresh(&s, 12).unwrap();
    let mut adam = Adam::new(AdamConfig::default()).unwrap();
    let mut grid = Some(crate::sampling::occupancy_grid(model.bounds(), 12).unwrap());
    let mut refresh = OccupancyRefresh;
    let due = grid.as_ref().unwrap().config().refresh().first_due();
    // Not due: nothing happens (a fresh grid is all occupied).
    refresh
        .after_step(&mut context(&mut model, &mut adam, &mut grid, due - 1, 0.1))
        .unwrap();
    assert_eq!(grid.as_ref().unwrap().occupied_fraction(), 1.0);
    refresh
        .after_step(&mut context(&mut model, &mut adam, &mut grid, due, 0.1))
        .unwrap();
    assert_eq!(grid.as_ref().unwrap().occupied_fraction(), 1.0);
    // A dense fog everywhere marks every cell at its refresh too; an empty one would have
    // emptied the grid, which the policy refills.
    let thick = FitSettings { shift: 10.0, ..s };
    let mut model = DenseGrid::<f64>::fresh(&thick, 12).unwrap();
    refresh
        .after_step(&mut context(&mut model, &mut adam, &mut grid, 2 * due, 0.2))
        .unwrap();
    assert_eq!(grid.as_ref().unwrap().occupied_fraction(), 1.0);
}
