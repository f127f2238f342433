//! One training step of `DenseGridTrainer` against the same step through the CPU ops: the
//! batch drawn and sampled as the kernels do (the same hash, in f64 on the host), then
//! `GridField`, `DensityColor` or `ShColor`, `Composite` over each ray's background (shared, or
//! random against targets with alpha) and their backwards, down to the grid's gradient; its
//! coarse-to-fine resampling against the CPU lookup; and the trainer's refusals. Skipped, with
//! a message, where there is no CUDA driver or device.

use fogray_cuda::{device_for_tests, CudaError, DenseGridTrainer, OccupancySettings, TrainerSettings, TrainingRays};
use fogray_ops::{
    ActivatedGrads, Background, Composite, CompositeArrays, CompositeUpstream, CompositeWanted, DensityColor,
    DistortionLoss, GridBox, GridField, GridWanted, ShColor,
};
use ndarray::{s, Array2, ArrayView1, ArrayView2, ArrayViewD};
use rand::Rng;

use crate::common::rng;

/// The kernels' splitmix64 and uniform double (`kernels/train.cu`).
fn mix(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9e3779b97f4a7c15);
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58476d1ce4e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d049bb133111eb);
    x ^ (x >> 31)
}

fn unit(h: u64) -> f64 {
    (h >> 11) as f64 * (1.0 / 9007199254740992.0)
}

const SETTINGS: TrainerSettings = TrainerSettings {
    scene_box: ([-1.0; 3], [1.0; 3]),
    nodes: 6,
    samples_per_ray: 24,
    batch: 64,
    shift: -1.0,
    sh_degree: 0,
    background: [0.2, 0.5, 0.9],
    random_background: false,
    distortion: 0.0,
    occupancy: None,
    seed: 11,
};

/// The training pixels of [`scene`], owned.
struct TestRays {
    o: Vec<f32>,
    d: Vec<f32>,
    colors: Vec<f32>,
    alpha: Vec<f32>,
}

impl TestRays {
    /// The trainer's view of them, with or without their opacities.
    fn rays(&self, with_alpha: bool) -> TrainingRays<'_> {
        TrainingRays {
            origins: &self.o,
            directions: &self.d,
            colors: &self.colors,
            alpha: with_alpha.then_some(&self.alpha[..]),
        }
    }
}

/// Rays from a sphere of radius 4 towards points near the centre (some miss the box), their
/// target colours, and opacities (a third opaque, a third clear, a third between).
fn scene(rays: usize) -> TestRays {
    let mut r = rng(17);
    let (mut o, mut d, mut t, mut alpha) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for _ in 0..rays {
        let mut u: [f64; 3] = std::array::from_fn(|_| r.gen_range(-1.0..1.0));
        let len = u.iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-3);
        u.iter_mut().for_each(|x| *x *= 4.0 / len);
        let aim: [f64; 3] = std::array::from_fn(|_| r.gen_range(-1.5..1.5));
        let mut dir: [f64; 3] = std::array::from_fn(|a| aim[a] - u[a]);
        let len = dir.iter().map(|x| x * x).sum::<f64>().sqrt();
        dir.iter_mut().for_each(|x| *x /= len);
        for a in 0..3 {
            o.push(u[a] as f32);
            d.push(dir[a] as f32);
            t.push(r.gen_range(0.0..1.0));
        }
        alpha.push([1.0, 0.0, r.gen_range(0.0..1.0)][alpha.len() % 3]);
    }
    TestRays { o, d, colors: t, alpha }
}

/// The batch of step 0 as the kernel draws it: the picked rays, positions `[n, 3]`, step
/// lengths `[n]` and midpoints along the ray `[n]`.
fn batch_of_step_zero(s: &TrainerSettings, o: &[f32], d: &[f32]) -> (Vec<usize>, Vec<f32>, Vec<f32>, Vec<f32>) {
    let rays = (o.len() / 3) as u64;
    let (mut picked, mut positions, mut delta, mut ts) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for b in 0..s.batch as u64 {
        let h = mix(s.seed ^ mix(b));
        let r = (h % rays) as usize;
        picked.push(r);
        let offset = unit(mix(h));
        let (mut t0, mut t1) = (0.0f64, 1e300f64);
        for a in 0..3 {
            let (oa, da) = (f64::from(o[3 * r + a]), f64::from(d[3 * r + a]));
            let inv = 1.0 / da;
            let (mut lo, mut hi) = ((s.scene_box.0[a] - oa) * inv, (s.scene_box.1[a] - oa) * inv);
            if lo > hi {
                std::mem::swap(&mut lo, &mut hi);
            }
            if !lo.is_nan() {
                t0 = t0.max(lo);
            }
            if !hi.is_nan() {
                t1 = t1.min(hi);
            }
        }
        let step = if t1 > t0 {
            (t1 - t0) / s.samples_per_ray as f64
        } else {
            0.0
        };
        for k in 0..s.samples_per_ray {
            let t = t0 + (k as f64 + offset) * step;
            for a in 0..3 {
                positions.push((f64::from(o[3 * r + a]) + t * f64::from(d[3 * r + a])) as f32);
            }
            delta.push(step as f32);
            ts.push(t as f32);
        }
    }
    (picked, positions, delta, ts)
}

/// The hash of batch ray `b` at step 0 (`batch_hash` of `kernels/train.cu`).
fn hash_of_step_zero(s: &TrainerSettings, b: usize) -> u64 {
    mix(s.seed ^ mix(b as u64))
}

/// Skips the samples in empty cells as the sampling kernel does: no length, a position past
/// the box.
fn skip_empty(s: &TrainerSettings, occupied: &[u8], positions: &mut [f32], delta: &mut [f32]) {
    let Some(o) = s.occupancy else { return };
    let (lo, hi) = s.scene_box;
    let scale: [f64; 3] = std::array::from_fn(|a| o.cells as f64 / (hi[a] - lo[a]));
    for (p, dt) in positions.chunks_exact_mut(3).zip(delta.iter_mut()) {
        let mut cell = 0;
        for a in 0..3 {
            let u = ((f64::from(p[a]) - lo[a]) * scale[a]).floor();
            cell = cell * o.cells + (u.max(0.0) as usize).min(o.cells - 1);
        }
        if occupied[cell] == 0 {
            p.fill(f32::INFINITY);
            *dt = 0.0;
        }
    }
}

/// The distortion loss (times the settings' weight) of the samples of nonzero length, through
/// the CPU op (which takes no zero lengths; a sample of length 0 has weight 0, and adds and
/// gets nothing), and its gradient with respect to every sample's density.
fn cpu_distortion(s: &TrainerSettings, sigma: &[f32], delta: &[f32], ts: &[f32]) -> (f64, Vec<f32>) {
    let kept: Vec<usize> = (0..delta.len()).filter(|&k| delta[k] > 0.0).collect();
    let mut offsets = vec![0];
    for b in 0..s.batch {
        let end = kept.iter().filter(|&&k| k < (b + 1) * s.samples_per_ray).count();
        offsets.push(end);
    }
    let pick = |v: &[f32]| ndarray::Array1::from_iter(kept.iter().map(|&k| v[k]));
    let (sg, dl, tt) = (pick(sigma), pick(delta), pick(ts));
    let op = DistortionLoss::new(&offsets).unwrap();
    let value = f64::from(op.evaluate(sg.view(), dl.view(), tt.view()).unwrap()) * s.distortion;
    let g = op.vjp(sg.view(), dl.view(), tt.view(), s.distortion as f32).unwrap();
    let mut full = vec![0.0f32; delta.len()];
    for (&k, &v) in kept.iter().zip(g.iter()) {
        full[k] = v;
    }
    (value, full)
}

/// What step 0 gives through the CPU ops: the grid's gradient, the MSE, and the weighted
/// distortion loss.
struct CpuStep {
    grad: Vec<f32>,
    mse: f64,
    distortion: f64,
}

/// Step 0 through the CPU ops (with the occupancy grid's cells, if the settings have one).
fn cpu_step(s: &TrainerSettings, data: &TrainingRays<'_>, values: &[f32], occupied: &[u8]) -> CpuStep {
    let (o, d) = (data.origins, data.directions);
    let (picked, mut positions, mut delta, ts) = batch_of_step_zero(s, o, d);
    skip_empty(s, occupied, &mut positions, &mut delta);
    let n = positions.len() / 3;
    let channels = if s.sh_degree == 0 {
        4
    } else {
        1 + 3 * (s.sh_degree + 1).pow(2)
    };
    let shape = [s.nodes, s.nodes, s.nodes, channels];
    let field = GridField::new(GridBox::new(&s.scene_box.0, &s.scene_box.1).unwrap(), &shape).unwrap();
    let grid = ArrayViewD::from_shape(&shape[..], values).unwrap();
    let pos = ArrayViewD::from_shape(&[n, 3][..], &positions).unwrap();
    let raw = field.evaluate(&grid, &pos).unwrap();
    let raw2 = raw.view().into_dimensionality::<ndarray::Ix2>().unwrap();
    let act = DensityColor::new(s.shift).unwrap();
    // Each sample's direction, its ray's.
    let dirs = Array2::from_shape_fn((n, 3), |(k, a)| d[3 * picked[k / s.samples_per_ray] + a]);
    let sh = (s.sh_degree > 0).then(|| ShColor::new(s.sh_degree).unwrap());
    let (sigma, color) = match &sh {
        None => {
            let a = act.evaluate(raw2).unwrap();
            (a.sigma, a.color)
        }
        Some(sh) => (
            act.density(raw2).unwrap(),
            sh.evaluate(raw2.slice(s![.., 1..]), dirs.view()).unwrap(),
        ),
    };
    // Each ray's background, and its target composited over it.
    let random = s.random_background && data.alpha.is_some();
    let mut backgrounds = Vec::new();
    let mut targets = Vec::new();
    for (b, &r) in picked.iter().enumerate() {
        let h = hash_of_step_zero(s, b);
        for c in 0..3 {
            let bg = if random {
                unit(mix(h + 1 + c as u64))
            } else {
                f64::from(s.background[c])
            };
            let unseen = data.alpha.map_or(0.0, |a| 1.0 - f64::from(a[r]));
            backgrounds.push(bg as f32);
            targets.push(f64::from(data.colors[3 * r + c]) + (bg - f64::from(s.background[c])) * unseen);
        }
    }
    let offsets: Vec<usize> = (0..=s.batch).map(|b| b * s.samples_per_ray).collect();
    let op = Composite::new(&offsets).unwrap().background(Background::PerRay);
    let bg = ArrayViewD::from_shape(&[s.batch, 3][..], &backgrounds).unwrap();
    let delta_v = ArrayViewD::from_shape(&[n][..], &delta).unwrap();
    let inputs = CompositeArrays::new(sigma.view().into_dyn(), delta_v, color.view().into_dyn()).with_background(bg);
    let (outs, res) = op.evaluate(&inputs).unwrap();
    let mut d_color = Vec::new();
    let mut sse = 0.0;
    for b in 0..s.batch {
        for c in 0..3 {
            let diff = f64::from(outs.color[[b, c]]) - targets[3 * b + c];
            d_color.push((2.0 / (3.0 * s.batch as f64) * diff) as f32);
            sse += diff * diff;
        }
    }
    let upstream = CompositeUpstream {
        color: Some(ArrayViewD::from_shape(&[s.batch, 3][..], &d_color).unwrap()),
        ..CompositeUpstream::default()
    };
    let wanted = CompositeWanted {
        sigma: true,
        color: true,
        ..CompositeWanted::default()
    };
    let g = op.vjp(&inputs, &res, &upstream, wanted).unwrap();
    let (mut g_sigma, g_color) = (g.sigma.unwrap(), g.color.unwrap());
    let mut distortion = 0.0;
    if s.distortion > 0.0 {
        let (value, g_dist) = cpu_distortion(s, sigma.as_slice().unwrap(), &delta, &ts);
        distortion = value;
        for (a, b) in g_sigma.iter_mut().zip(g_dist) {
            *a += b;
        }
    }
    let g_sigma1: ArrayView1<'_, f32> = g_sigma.view().into_dimensionality().unwrap();
    let g_color2: ArrayView2<'_, f32> = g_color.view().into_dimensionality().unwrap();
    let d_raw = match &sh {
        None => act
            .vjp(
                raw2,
                &ActivatedGrads {
                    sigma: Some(g_sigma1),
                    color: Some(g_color2),
                },
            )
            .unwrap(),
        Some(sh) => {
            // The density's column from the activation (its colour columns get no upstream),
            // the coefficients' from the spherical harmonics.
            let mut d_raw = act
                .vjp(
                    raw2,
                    &ActivatedGrads {
                        sigma: Some(g_sigma1),
                        color: None,
                    },
                )
                .unwrap();
            let d_coeffs = sh.vjp(raw2.slice(s![.., 1..]), dirs.view(), g_color2).unwrap();
            d_raw.slice_mut(s![.., 1..]).assign(&d_coeffs);
            d_raw
        }
    };
    let cpu_grad = field
        .vjp(
            &grid,
            &pos,
            &d_raw.view().into_dyn(),
            GridWanted {
                grid: true,
                positions: false,
            },
        )
        .unwrap()
        .grid
        .unwrap();
    CpuStep {
        grad: cpu_grad.iter().copied().collect(),
        mse: sse / (3.0 * s.batch as f64),
        distortion,
    }
}

/// Step 0 on the device against [`cpu_step`], from random grid values.
fn check_one_step(s: TrainerSettings, with_alpha: bool) {
    let Some(gpu) = device_for_tests().unwrap() else { return };
    let pixels = scene(300);
    let data = pixels.rays(with_alpha);
    let mut trainer = DenseGridTrainer::new(&gpu, s, data).unwrap();
    let mut r = rng(19);
    let values: Vec<f32> = (0..s.nodes.pow(3) * trainer.channels())
        .map(|_| r.gen_range(-2.0..2.0))
        .collect();
    trainer.set_grid_values(&values).unwrap();
    trainer.refresh_occupancy().unwrap();
    let occupied = trainer.occupancy().unwrap().unwrap_or_default();
    trainer.record_gradients(true);
    trainer.step(0.1).unwrap();
    let gpu_grad = trainer.last_gradient().unwrap();
    let gpu_mse = trainer.take_mean_squared_error(1).unwrap();
    let gpu_distortion = trainer.take_distortion_loss(1).unwrap();
    let cpu = cpu_step(&s, &data, &values, &occupied);
    let (cpu_grad, cpu_mse) = (cpu.grad, cpu.mse);

    let scale = cpu_grad.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    let worst = gpu_grad
        .iter()
        .zip(cpu_grad.iter())
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    println!(
        "one step, {} rays of {} samples on a {}^3 grid, SH degree {}, random background {}, {} of {} cells occupied: grid gradient max |GPU - CPU| {worst:.2e} of max |gradient| {scale:.2e}; MSE GPU {gpu_mse:.6e}, CPU {cpu_mse:.6e}",
        s.batch, s.samples_per_ray, s.nodes, s.sh_degree, s.random_background && with_alpha,
        occupied.iter().filter(|&&c| c != 0).count(), occupied.len()
    );
    assert_eq!(gpu_grad.len(), cpu_grad.len());
    assert!(scale > 0.0, "the batch must touch the grid");
    // The host's positions round the same f64 sums as the kernel's, which may fuse a multiply
    // and an add, and the device composites over black and adds (1 - opacity) times the
    // background: the chain agrees to f32 rounding, far inside this bound.
    assert!(worst <= 1e-3 * scale, "{worst} against {scale}");
    assert!((gpu_mse - cpu_mse).abs() <= 1e-5 * cpu_mse, "{gpu_mse} {cpu_mse}");
    if s.distortion > 0.0 {
        println!(
            "  weighted distortion loss GPU {gpu_distortion:.6e}, CPU {:.6e}",
            cpu.distortion
        );
        assert!(cpu.distortion > 0.0);
        // The loss's share of the gradient is far above the bound the check allows.
        let without = cpu_step(&TrainerSettings { distortion: 0.0, ..s }, &data, &values, &occupied);
        let share = without
            .grad
            .iter()
            .zip(&cpu_grad)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        println!("  the distortion loss moves the gradient by up to {share:.2e}");
        assert!(share > 1e-2 * scale, "{share} against {scale}");
        assert!((gpu_distortion - cpu.distortion).abs() <= 1e-5 * cpu.distortion);
    } else {
        assert_eq!(gpu_distortion, 0.0);
    }
}

#[test]
fn one_step_with_the_distortion_loss_has_the_gradient_of_the_cpu_ops() {
    // A weight large enough that the loss's share of the gradient is not lost in the bound.
    let with = TrainerSettings {
        distortion: 0.5,
        ..SETTINGS
    };
    check_one_step(with, false);
    check_one_step(
        TrainerSettings {
            sh_degree: 1,
            random_background: true,
            occupancy: Some(OCCUPANCY),
            ..with
        },
        true,
    );
}

#[test]
fn one_step_has_the_gradient_of_the_cpu_ops() {
    check_one_step(SETTINGS, false);
}

#[test]
fn one_step_with_spherical_harmonics_has_the_gradient_of_the_cpu_ops() {
    for degree in 1..=3 {
        check_one_step(
            TrainerSettings {
                sh_degree: degree,
                ..SETTINGS
            },
            false,
        );
    }
}

#[test]
fn one_step_over_random_backgrounds_has_the_gradient_of_the_cpu_ops() {
    let random = TrainerSettings {
        random_background: true,
        ..SETTINGS
    };
    // Alpha given: each ray over its own colour; without alpha the setting does nothing.
    check_one_step(random, true);
    check_one_step(random, false);
    check_one_step(TrainerSettings { sh_degree: 1, ..random }, true);
    // Alpha given but not random: the targets stay over the shared background.
    check_one_step(SETTINGS, true);
}

const OCCUPANCY: OccupancySettings = OccupancySettings {
    cells: 5,
    density: 0.4,
    every: 16,
    decay: 0.95,
};

#[test]
fn a_refresh_marks_the_cells_whose_density_exceeds_the_threshold() {
    let Some(gpu) = device_for_tests().unwrap() else { return };
    let pixels = scene(20);
    let s = TrainerSettings {
        scene_box: ([-1.0, -0.5, 0.0], [1.0, 2.0, 0.75]),
        occupancy: Some(OCCUPANCY),
        ..SETTINGS
    };
    let data = pixels.rays(false);
    let mut trainer = DenseGridTrainer::new(&gpu, s, data).unwrap();
    let cells = OCCUPANCY.cells;
    assert_eq!(
        trainer.occupancy().unwrap(),
        Some(vec![1; cells.pow(3)]),
        "occupied until the first refresh"
    );
    let mut r = rng(37);
    let values: Vec<f32> = (0..s.nodes.pow(3) * 4).map(|_| r.gen_range(-2.0..2.0)).collect();
    trainer.set_grid_values(&values).unwrap();
    trainer.refresh_occupancy().unwrap();
    let got = trainer.occupancy().unwrap().unwrap();

    // The same refresh on the host: the density at each cell's centre and at its random point
    // (the kernel's hash, refresh 0), through the CPU ops; the estimate starts at 0.
    let (lo, hi) = s.scene_box;
    let mut points = Vec::new();
    for i in 0..cells.pow(3) {
        let idx = [i / (cells * cells), (i / cells) % cells, i % cells];
        let h = mix(s.seed ^ mix(0x5bd1e995u64.wrapping_add(i as u64)));
        let mut random = [0.0f32; 3];
        for a in 0..3 {
            let side = 1.0 / (cells as f64 / (hi[a] - lo[a]));
            points.push((lo[a] + (idx[a] as f64 + 0.5) * side) as f32);
            random[a] = (lo[a] + (idx[a] as f64 + unit(mix(h.wrapping_add(a as u64)))) * side) as f32;
        }
        points.extend(random);
    }
    let shape = [s.nodes, s.nodes, s.nodes, 4];
    let field = GridField::new(GridBox::new(&lo, &hi).unwrap(), &shape).unwrap();
    let grid = ArrayViewD::from_shape(&shape[..], &values).unwrap();
    let pos = ArrayViewD::from_shape(&[2 * cells.pow(3), 3][..], &points).unwrap();
    let raw = field.evaluate(&grid, &pos).unwrap();
    let density = DensityColor::new(s.shift)
        .unwrap()
        .density(raw.view().into_dimensionality().unwrap())
        .unwrap();
    let mut occupied = 0;
    for (i, &g) in got.iter().enumerate() {
        let fresh = f64::from(density[2 * i].max(density[2 * i + 1]));
        let want = fresh > OCCUPANCY.density;
        occupied += usize::from(want);
        // The CPU op's f32 softplus may differ from the kernel's in the last place: only a
        // density that close to the threshold may fall the other way.
        assert!(
            (g != 0) == want || (fresh - OCCUPANCY.density).abs() < 1e-6,
            "cell {i}: {g} for density {fresh}"
        );
    }
    println!("occupancy refresh: {occupied} of {} cells occupied", cells.pow(3));
    assert!(occupied > 0 && occupied < cells.pow(3), "the test must see both");
}

#[test]
fn a_step_after_a_refresh_that_empties_the_occupancy_grid_samples_every_cell() {
    let Some(gpu) = device_for_tests().unwrap() else { return };
    let pixels = scene(100);
    let s = TrainerSettings {
        occupancy: Some(OCCUPANCY),
        ..SETTINGS
    };
    let mut trainer = DenseGridTrainer::new(&gpu, s, pixels.rays(false)).unwrap();
    // Raw density -20 (softplus(-21) = 7.6e-10) everywhere: far below the threshold 0.4.
    let values: Vec<f32> = (0..s.nodes.pow(3) * 4)
        .map(|i| if i % 4 == 0 { -20.0 } else { 0.5 })
        .collect();
    trainer.set_grid_values(&values).unwrap();
    trainer.refresh_occupancy().unwrap();
    let cells = OCCUPANCY.cells.pow(3);
    assert_eq!(
        trainer.occupancy().unwrap(),
        Some(vec![0; cells]),
        "the refresh empties it"
    );
    trainer.record_gradients(true);
    trainer.step(0.1).unwrap();
    // With no cell occupied no sample would be kept and nothing could raise a density
    // again: the step occupies every cell and trains on the batch.
    assert_eq!(trainer.occupancy().unwrap(), Some(vec![1; cells]));
    let g = trainer.last_gradient().unwrap();
    let touched = g.iter().filter(|&&v| v != 0.0).count();
    println!(
        "a step after an emptying refresh: {touched} of {} grid values have a gradient",
        g.len()
    );
    assert!(touched > 0);
    assert!(trainer.take_mean_squared_error(1).unwrap() > 0.0);
}

#[test]
fn one_step_skipping_empty_cells_has_the_gradient_of_the_cpu_ops() {
    for sh_degree in [0, 1] {
        check_one_step(
            TrainerSettings {
                occupancy: Some(OCCUPANCY),
                sh_degree,
                ..SETTINGS
            },
            false,
        );
    }
}

#[test]
fn a_step_moves_the_entries_with_a_gradient_by_adam_and_no_others() {
    let Some(gpu) = device_for_tests().unwrap() else { return };
    let pixels = scene(300);
    let s = TrainerSettings {
        occupancy: Some(OCCUPANCY),
        ..SETTINGS
    };
    let data = pixels.rays(false);
    let mut trainer = DenseGridTrainer::new(&gpu, s, data).unwrap();
    assert!(matches!(trainer.last_gradient(), Err(CudaError::InvalidSettings(_))));
    let mut r = rng(41);
    let values: Vec<f32> = (0..s.nodes.pow(3) * 4).map(|_| r.gen_range(-2.0..2.0)).collect();
    trainer.set_grid_values(&values).unwrap();
    trainer.refresh_occupancy().unwrap();
    trainer.record_gradients(true);
    let lr = 0.3;
    trainer.step(lr).unwrap();
    let g = trainer.last_gradient().unwrap();
    let after = trainer.grid_values().unwrap();
    // Adam's first step from zero moments: m = (1 - beta1) g, v = (1 - beta2) g^2, both
    // bias-corrected back to g and g^2: the entry moves by lr g / (|g| + eps).
    let (mut moved, mut kept) = (0, 0);
    for ((&x, &x1), &gi) in values.iter().zip(&after).zip(&g) {
        if gi == 0.0 {
            assert_eq!(x1.to_bits(), x.to_bits(), "an entry without a gradient keeps its value");
            kept += 1;
        } else {
            let (gd, c1, c2) = (f64::from(gi), 1.0 - 0.9, 1.0 - 0.999f64);
            let (m, v) = (c1 * gd, c2 * gd * gd);
            let want = f64::from(x) - lr * (m / c1) / ((v / c2).sqrt() + 1e-8);
            assert!(
                (f64::from(x1) - want).abs() <= 1e-6 * want.abs().max(1.0),
                "{x1} against {want}"
            );
            moved += 1;
        }
    }
    println!("one Adam step: {moved} entries moved, {kept} without a gradient kept");
    assert!(moved > 0 && kept > 0, "the test must see both");
}

#[test]
fn resampling_takes_the_cpu_lookup_at_the_new_nodes() {
    let Some(gpu) = device_for_tests().unwrap() else { return };
    let pixels = scene(50);
    let s = TrainerSettings {
        scene_box: ([-1.0, -0.5, 0.0], [1.0, 2.0, 0.75]),
        sh_degree: 1,
        ..SETTINGS
    };
    let data = pixels.rays(false);
    let mut trainer = DenseGridTrainer::new(&gpu, s, data).unwrap();
    let k = trainer.channels();
    let mut r = rng(23);
    let values: Vec<f32> = (0..s.nodes.pow(3) * k).map(|_| r.gen_range(-2.0..2.0)).collect();
    trainer.set_grid_values(&values).unwrap();
    let shape = [s.nodes, s.nodes, s.nodes, k];
    let field = GridField::new(GridBox::new(&s.scene_box.0, &s.scene_box.1).unwrap(), &shape).unwrap();
    let grid = ArrayViewD::from_shape(&shape[..], &values).unwrap();
    for nodes in [11, 4] {
        let before = trainer.grid_values().unwrap();
        trainer.resample(nodes).unwrap();
        assert_eq!(trainer.nodes(), nodes);
        let after = trainer.grid_values().unwrap();
        assert_eq!(after.len(), nodes.pow(3) * k);
        // The new lattice's nodes, the last on the max face exactly.
        let mut at = Vec::new();
        for i in 0..nodes.pow(3) {
            let idx = [i / (nodes * nodes), (i / nodes) % nodes, i % nodes];
            for (a, &j) in idx.iter().enumerate() {
                let (lo, hi) = (s.scene_box.0[a], s.scene_box.1[a]);
                let p = if j + 1 == nodes {
                    hi
                } else {
                    lo + j as f64 * ((hi - lo) / (nodes - 1) as f64)
                };
                at.push(p as f32);
            }
        }
        if nodes == 11 {
            // From the original grid: the CPU lookup's bits.
            let pos = ArrayViewD::from_shape(&[nodes.pow(3), 3][..], &at).unwrap();
            let expected = field.evaluate(&grid, &pos).unwrap();
            assert_eq!(after, expected.iter().copied().collect::<Vec<f32>>());
        } else {
            // Down from 11 to 4 nodes: the corners of the box keep their values.
            let corner = |v: &[f32], n: usize, i: usize| v[(i * (n - 1) * (n * n + n + 1)) * k..][..k].to_vec();
            assert_eq!(corner(&after, 4, 0), corner(&before, 11, 0));
            assert_eq!(corner(&after, 4, 1), corner(&before, 11, 1));
        }
    }
    // Steps go on at the new size.
    trainer.record_gradients(true);
    trainer.step(0.1).unwrap();
    assert_eq!(trainer.last_gradient().unwrap().len(), 4usize.pow(3) * k);
    assert!(matches!(trainer.resample(1), Err(CudaError::InvalidGrid(_))));
    assert_eq!(trainer.nodes(), 4);
}

#[test]
fn the_trainer_refuses_bad_input() {
    let Some(gpu) = device_for_tests().unwrap() else { return };
    let pixels = scene(10);
    let (o, d, alpha) = (&pixels.o, &pixels.d, &pixels.alpha);
    let s = SETTINGS;
    let data = pixels.rays(false);
    let bad_data = [
        TrainingRays {
            origins: &o[1..],
            ..data
        },
        TrainingRays {
            directions: &d[3..],
            ..data
        },
        TrainingRays {
            origins: &[],
            directions: &[],
            colors: &[],
            alpha: None,
        },
        TrainingRays {
            alpha: Some(&alpha[1..]),
            ..data
        },
    ];
    for bad in bad_data {
        assert!(matches!(
            DenseGridTrainer::new(&gpu, s, bad),
            Err(CudaError::Shape { .. })
        ));
    }
    let bad_settings = [
        TrainerSettings { batch: 0, ..s },
        TrainerSettings {
            samples_per_ray: 0,
            ..s
        },
        TrainerSettings { sh_degree: 4, ..s },
        TrainerSettings { distortion: -1.0, ..s },
        TrainerSettings {
            occupancy: Some(OccupancySettings { cells: 0, ..OCCUPANCY }),
            ..s
        },
        TrainerSettings {
            occupancy: Some(OccupancySettings {
                decay: 1.5,
                ..OCCUPANCY
            }),
            ..s
        },
    ];
    for bad in bad_settings {
        assert!(matches!(
            DenseGridTrainer::new(&gpu, bad, data),
            Err(CudaError::InvalidSettings(_))
        ));
    }
    let one_node = TrainerSettings { nodes: 1, ..s };
    assert!(matches!(
        DenseGridTrainer::new(&gpu, one_node, data),
        Err(CudaError::InvalidGrid(_))
    ));
    let nan_background = TrainerSettings {
        background: [0.0, f32::NAN, 0.0],
        ..s
    };
    assert!(matches!(
        DenseGridTrainer::new(&gpu, nan_background, data),
        Err(CudaError::InvalidBackground { channel: 1, .. })
    ));
    let mut trainer = DenseGridTrainer::new(&gpu, s, data).unwrap();
    let before = trainer.grid_values().unwrap();
    assert!(matches!(
        trainer.set_grid_values(&[0.0; 5]),
        Err(CudaError::Shape { .. })
    ));
    assert_eq!(trainer.grid_values().unwrap(), before);
    assert!(matches!(
        trainer.render(&[0.0; 3], &[0.0; 6]),
        Err(CudaError::Shape { .. })
    ));
}
