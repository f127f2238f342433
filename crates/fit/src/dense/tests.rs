//! The dense grid: its training loss's gradient against central differences, the fused ops
//! against their taped twins, resampling, and its densities against their closed form.

use crate::dense::DenseGrid;
use crate::model::{RadianceField, TrainingBackground};
use crate::settings::{Method, SceneBox};
use fogray_ops::rays::{Aabb, RayBatch};
use fogray_ops::sample::{PackedSamples, Spacing, Uniform};
use fogray_tape::gradcheck::{gradcheck, GradcheckOptions};
use fogray_tape::{Tape, TapeError, Var};
use ndarray::{arr2, Array2, Array4, ArrayD, Ix4};

/// The background of the losses below.
const BACKGROUND: [f64; 3] = [1.0, 0.95, 0.9];

/// The backgrounds the losses are checked over: [`BACKGROUND`] shared, and one per ray of
/// [`setup`] (as a fit with random backgrounds draws them).
fn backgrounds() -> [TrainingBackground<f64>; 2] {
    [
        TrainingBackground::Shared(BACKGROUND),
        TrainingBackground::PerRay(arr2(&[[0.1, 0.7, 0.35], [0.9, 0.05, 0.6], [0.45, 0.2, 1.0]])),
    ]
}

/// Weights of the total-variation prior the losses are checked with: none (the photometric
/// loss alone) and one that weighs about as much as it.
const SMOOTHNESS: [f64; 2] = [0.0, 0.05];

/// Three rays crossing a 3^3 grid, sampled every 0.4, and a target colour per ray.
pub(crate) fn setup() -> (RayBatch<f64>, PackedSamples<f64>, Array2<f64>) {
    let origins = arr2(&[[0.1, -3.0, 0.2], [-2.5, 0.3, -0.4], [0.5, 0.6, 3.0]]);
    let directions = arr2(&[[0.05, 1.0, -0.1], [1.0, -0.2, 0.1], [-0.1, -0.2, -1.0]]);
    let rays = RayBatch::new(origins, directions).unwrap();
    let clip = Aabb::new([-1.0; 3], [1.0; 3]).unwrap().clip(&rays);
    let samples = Uniform::new(Spacing::Step(0.4)).unwrap().sample(&rays, &clip).unwrap();
    let target = arr2(&[[0.9, 0.2, 0.1], [0.3, 0.3, 0.8], [0.5, 0.9, 0.4]]);
    (rays, samples, target)
}

/// A raw grid with every value different, densities around the shift.
pub(crate) fn raw_grid() -> ArrayD<f64> {
    Array4::from_shape_fn((3, 3, 3, 4), |(i, j, k, c)| {
        ((i * 36 + j * 12 + k * 4 + c) as f64 * 0.37).sin() * 1.5
    })
    .into_dyn()
}

/// A 3^3 grid of shift -1 holding `raw`, with the prior's weight `smoothness`.
fn model(raw: &ArrayD<f64>, smoothness: f64) -> DenseGrid<f64> {
    let mut model = DenseGrid::<f64>::new(SceneBox::UNIT, 3, -1.0, smoothness).unwrap();
    let id = model.grid_id();
    model.params_mut().get_mut(id).unwrap().assign(raw);
    model
}

/// The training objective of [`setup`]'s rays with the raw grid `grid` (a value on `tape`), as
/// a function of `grid` that gradcheck can difference, for the model `build` makes holding
/// `grid`'s value: the model lends its own copy of the grid to the tape, so the tape's
/// gradient of the objective with respect to that copy, `g`, is carried to `grid` by adding
/// `sum((grid - detach(grid)) * g)`, which is exactly 0 (the value is the objective's) and
/// whose gradient with respect to `grid` is exactly `g`.
fn carried_objective(
    tape: &mut Tape<f64>,
    grid: Var,
    method: Method,
    background: TrainingBackground<f64>,
    build: impl Fn(&ArrayD<f64>) -> DenseGrid<f64>,
) -> Result<Var, TapeError> {
    let model = build(&tape.value(grid)?.to_owned());
    let (rays, samples, target) = setup();
    let target = tape.constant(target);
    let loss = model
        .training_loss(tape, &rays, samples, background, target, method)?
        .objective;
    let g = tape.backward(loss)?.param(model.grid_id()).unwrap().to_owned();
    let g = tape.constant(g);
    let frozen = tape.detach(grid)?;
    let zero = tape.sub(grid, frozen)?;
    let carried = tape.mul(zero, g)?;
    let carried = tape.sum(carried)?;
    tape.add(loss, carried)
}

/// [`carried_objective`] of the view-independent grid with the prior's weight `smoothness`.
fn objective(
    tape: &mut Tape<f64>,
    grid: Var,
    method: Method,
    background: TrainingBackground<f64>,
    smoothness: f64,
) -> Result<Var, TapeError> {
    carried_objective(tape, grid, method, background, |raw| model(raw, smoothness))
}

#[test]
fn the_training_loss_passes_gradcheck_fused_and_taped() {
    let (_, samples, _) = setup();
    assert!(
        samples.len() > 12,
        "the rays must cross the grid: {} samples",
        samples.len()
    );
    for (smoothness, background) in SMOOTHNESS.into_iter().zip(backgrounds()) {
        for method in [Method::Fused, Method::Taped] {
            let report = gradcheck(
                |t, v| objective(t, v[0], method, background.clone(), smoothness),
                &[raw_grid()],
                &GradcheckOptions::default(),
            )
            .unwrap();
            assert!(
                report.passes(),
                "{method:?}, smoothness {smoothness}, {background:?}: {report}"
            );
            // Every element was compared, against a gradient that is not all zero.
            assert_eq!(report.checked, 3 * 3 * 3 * 4);
            assert!(report.entries.iter().any(|e| e.analytic.abs() > 1e-3));
        }
    }
}

#[test]
fn fused_and_taped_give_the_same_loss_and_gradient() {
    let cases = SMOOTHNESS.into_iter().flat_map(|s| backgrounds().map(|b| (s, b)));
    let mut photometric_by_background = Vec::new();
    for (smoothness, background) in cases {
        let mut results = Vec::new();
        for method in [Method::Fused, Method::Taped] {
            let model = model(&raw_grid(), smoothness);
            let (rays, samples, target) = setup();
            let mut tape = Tape::<f64>::new();
            let target = tape.constant(target);
            let loss = model
                .training_loss(&mut tape, &rays, samples, background.clone(), target, method)
                .unwrap();
            let value = |v: Var| tape.value(v).unwrap()[[]];
            let (photometric, objective) = (value(loss.photometric), value(loss.objective));
            // The prior joins the objective only when it weighs something.
            if smoothness == 0.0 {
                assert_eq!(loss.objective, loss.photometric);
            } else {
                assert!(objective > photometric + 1e-3, "{objective} {photometric}");
            }
            let grads = tape.backward(loss.objective).unwrap();
            let g = grads.param(model.grid_id()).unwrap().to_owned();
            results.push((photometric, objective, g));
        }
        let ((p0, o0, g0), (p1, o1, g1)) = (&results[0], &results[1]);
        assert!((p0 - p1).abs() < 1e-14, "{p0} {p1}");
        assert!((o0 - o1).abs() < 1e-14, "{o0} {o1}");
        assert!(g0.iter().any(|v| v.abs() > 1e-3), "a gradient that can fail");
        for (a, b) in g0.iter().zip(g1.iter()) {
            assert!(
                (a - b).abs() < 1e-13,
                "smoothness {smoothness}, {background:?}: {a} {b}"
            );
        }
        photometric_by_background.push(*p0);
    }
    // The per-ray background reaches the loss: it is not the shared one's.
    let p = photometric_by_background;
    assert!((p[0] - p[1]).abs() > 1e-3 && (p[2] - p[3]).abs() > 1e-3, "{p:?}");
}

#[test]
fn resampling_keeps_a_linear_field_exactly() {
    // Trilinear interpolation reproduces a linear field, so the 5^3 grid grown from a 3^3 one
    // holding f(x, y, z) = 1 + x - 2y + 3z (channel c scaled by c + 1) holds it at its nodes.
    let f = |x: f64, y: f64, z: f64, c: usize| (1.0 + x - 2.0 * y + 3.0 * z) * (c + 1) as f64;
    let at = |i: usize, n: usize| -1.0 + 2.0 * i as f64 / (n - 1) as f64;
    let linear = Array4::from_shape_fn((3, 3, 3, 4), |(i, j, k, c)| f(at(i, 3), at(j, 3), at(k, 3), c));
    let model = model(&linear.into_dyn(), 0.0);
    let grown = model.resampled(5, None).unwrap();
    assert_eq!(grown.nodes(), 5);
    let values = grown.params().get(grown.grid_id()).unwrap();
    for ((i, j, k, c), v) in values.into_dimensionality::<Ix4>().unwrap().indexed_iter() {
        let want = f(at(i, 5), at(j, 5), at(k, 5), c);
        assert!((v - want).abs() < 1e-12, "({i}, {j}, {k}, {c}): {v} vs {want}");
    }
}

#[test]
fn densities_are_the_softplus_of_the_shifted_raw_density() {
    // Raw densities from -30 to 30 at the nodes of a 3^3 grid; the model reads them at the
    // nodes, so its densities are ln(1 + exp(raw - 2)), computed here through the C library.
    let mut model = DenseGrid::<f64>::new(SceneBox::UNIT, 3, -2.0, 0.0).unwrap();
    let id = model.grid_id();
    let raw = |i: usize, j: usize, k: usize| (i * 9 + j * 3 + k) as f64 * (60.0 / 26.0) - 30.0;
    model
        .params_mut()
        .get_mut(id)
        .unwrap()
        .assign(&Array4::from_shape_fn((3, 3, 3, 4), |(i, j, k, c)| {
            if c == 0 {
                raw(i, j, k)
            } else {
                7.0
            }
        }));
    let positions = Array2::from_shape_fn((27, 3), |(p, axis)| [p / 9, p / 3 % 3, p % 3][axis] as f64 - 1.0);
    let sigma = model.densities(positions.view()).unwrap();
    for (p, s) in sigma.iter().enumerate() {
        let x = raw(p / 9, p / 3 % 3, p % 3) - 2.0;
        let want = if x > 0.0 {
            x + (-x).exp().ln_1p()
        } else {
            x.exp().ln_1p()
        };
        assert!((s - want).abs() <= 5e-16 * want, "node {p}: {s:e} vs {want:e}");
    }
    // Outside the box the raw value is 0: softplus(-2).
    let outside = model.densities(arr2(&[[2.0, 0.0, 0.0]]).view()).unwrap();
    assert!((outside[0] - (-2f64).exp().ln_1p()).abs() < 1e-16);
    assert!(DenseGrid::<f32>::new(SceneBox::UNIT, 3, f64::NAN, 0.0).is_err());
}

/// A 3^3 grid of spherical-harmonics degree `degree` holding values that differ everywhere.
fn view_dependent_model(raw: &ArrayD<f64>, degree: usize) -> DenseGrid<f64> {
    let mut model = DenseGrid::<f64>::view_dependent(SceneBox::UNIT, 3, -1.0, 1e-3, degree).unwrap();
    let id = model.grid_id();
    model.params_mut().get_mut(id).unwrap().assign(raw);
    model
}

fn view_dependent_raw(degree: usize) -> ArrayD<f64> {
    let channels = 1 + 3 * (degree + 1) * (degree + 1);
    Array4::from_shape_fn((3, 3, 3, channels), |(i, j, k, c)| {
        (((i * 9 + j * 3 + k) * channels + c) as f64 * 0.37).sin() * 1.5
    })
    .into_dyn()
}

/// Spherical-harmonics colour through the whole model: its gradient against central
/// differences for degrees 1 and 2, fused and taped, and the fused and taped losses equal.
#[test]
fn a_view_dependent_grid_passes_gradcheck_fused_and_taped() {
    for degree in [1, 2] {
        let mut losses = Vec::new();
        for method in [Method::Fused, Method::Taped] {
            let report = gradcheck(
                |t, v| {
                    carried_objective(t, v[0], method, backgrounds()[degree % 2].clone(), |raw| {
                        view_dependent_model(raw, degree)
                    })
                },
                &[view_dependent_raw(degree)],
                &GradcheckOptions::default(),
            )
            .unwrap();
            assert!(report.passes(), "degree {degree} {method:?}: {report}");
            assert_eq!(report.checked, 27 * (1 + 3 * (degree + 1) * (degree + 1)));
            // Coefficients beyond degree 0 get gradients: the colour depends on direction.
            assert!(report.entries.iter().any(|e| e.analytic.abs() > 1e-4));
            let model = view_dependent_model(&view_dependent_raw(degree), degree);
            let (rays, samples, target) = setup();
            let mut tape = Tape::<f64>::new();
            let target = tape.constant(target);
            let loss = model
                .training_loss(
                    &mut tape,
                    &rays,
                    samples,
                    backgrounds()[degree % 2].clone(),
                    target,
                    method,
                )
                .unwrap();
            losses.push(tape.value(loss.objective).unwrap()[[]]);
        }
        assert!((losses[0] - losses[1]).abs() < 1e-12, "degree {degree}: {losses:?}");
    }
}

/// A view-dependent grid's colour changes with the direction a point is seen from; the
/// view-independent one's does not.
#[test]
fn a_view_dependent_colour_depends_on_the_direction() {
    let render = |model: &DenseGrid<f64>, direction: [f64; 3]| {
        let rays = RayBatch::new(
            arr2(&[[-3.0 * direction[0], -3.0 * direction[1], -3.0 * direction[2]]]),
            arr2(&[direction]),
        )
        .unwrap();
        let clip = model.bounds().clip(&rays);
        let samples = Uniform::new(Spacing::Step(0.1)).unwrap().sample(&rays, &clip).unwrap();
        let mut tape = Tape::<f64>::new();
        let out = model
            .render(&mut tape, &rays, samples, BACKGROUND, Method::Fused, Default::default())
            .unwrap();
        tape.value(out.color).unwrap().to_owned()
    };
    let model = view_dependent_model(&view_dependent_raw(1), 1);
    let (a, b) = (render(&model, [1.0, 0.0, 0.0]), render(&model, [-1.0, 0.0, 0.0]));
    assert!((a[[0, 0]] - b[[0, 0]]).abs() > 1e-3, "{a} {b}");
    let plain = model_with_colour_only();
    let (a, b) = (render(&plain, [1.0, 0.0, 0.0]), render(&plain, [-1.0, 0.0, 0.0]));
    assert!((a[[0, 0]] - b[[0, 0]]).abs() < 1e-12, "{a} {b}");
}

/// A view-independent grid whose density and colour are the same everywhere.
fn model_with_colour_only() -> DenseGrid<f64> {
    let mut model = DenseGrid::<f64>::new(SceneBox::UNIT, 3, -1.0, 0.0).unwrap();
    let id = model.grid_id();
    let raw = Array4::from_shape_fn((3, 3, 3, 4), |(_, _, _, c)| [1.0, 0.3, -0.2, 0.5][c]).into_dyn();
    model.params_mut().get_mut(id).unwrap().assign(&raw);
    model
}
