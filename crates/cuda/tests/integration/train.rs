//! One training step of `DenseGridTrainer` against the same step through the CPU ops: the
//! batch drawn and sampled as the kernels do (the same hash, in f64 on the host), then
//! `GridField`, `DensityColor`, `Composite` and their backwards, down to the grid's gradient;
//! and the trainer's refusals. Skipped, with a message, where there is no CUDA driver or device.

use fogray_cuda::{device_for_tests, CudaError, DenseGridTrainer, TrainerSettings};
use fogray_ops::{
    ActivatedGrads, Background, Composite, CompositeArrays, CompositeUpstream, CompositeWanted, DensityColor, GridBox,
    GridField, GridWanted,
};
use ndarray::{ArrayView1, ArrayView2, ArrayViewD};
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
    background: [0.2, 0.5, 0.9],
    seed: 11,
};

/// Rays from a sphere of radius 4 towards points near the centre (some miss the box).
fn scene(rays: usize) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let mut r = rng(17);
    let (mut o, mut d, mut t) = (Vec::new(), Vec::new(), Vec::new());
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
    }
    (o, d, t)
}

/// The batch of step 0 as the kernel draws it: the picked rays, positions `[n, 3]` and step
/// lengths `[n]`.
fn batch_of_step_zero(o: &[f32], d: &[f32]) -> (Vec<usize>, Vec<f32>, Vec<f32>) {
    let s = SETTINGS;
    let rays = (o.len() / 3) as u64;
    let (mut picked, mut positions, mut delta) = (Vec::new(), Vec::new(), Vec::new());
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
        }
    }
    (picked, positions, delta)
}

#[test]
fn one_step_has_the_gradient_of_the_cpu_ops() {
    let Some(gpu) = device_for_tests().unwrap() else { return };
    let s = SETTINGS;
    let (o, d, targets) = scene(300);
    let mut trainer = DenseGridTrainer::new(&gpu, s, &o, &d, &targets).unwrap();
    let mut r = rng(19);
    let shape = [s.nodes, s.nodes, s.nodes, 4];
    let values: Vec<f32> = (0..shape.iter().product::<usize>())
        .map(|_| r.gen_range(-2.0..2.0))
        .collect();
    trainer.set_grid_values(&values).unwrap();
    trainer.step(0.1).unwrap();
    let gpu_grad = trainer.last_gradient().unwrap();
    let gpu_mse = trainer.take_mean_squared_error(1).unwrap();

    // The same step through the CPU ops.
    let (picked, positions, delta) = batch_of_step_zero(&o, &d);
    let n = positions.len() / 3;
    let field = GridField::new(GridBox::new(&s.scene_box.0, &s.scene_box.1).unwrap(), &shape).unwrap();
    let grid = ArrayViewD::from_shape(&shape[..], &values).unwrap();
    let pos = ArrayViewD::from_shape(&[n, 3][..], &positions).unwrap();
    let raw = field.evaluate(&grid, &pos).unwrap();
    let raw2 = raw.view().into_dimensionality::<ndarray::Ix2>().unwrap();
    let act = DensityColor::new(s.shift).unwrap();
    let activated = act.evaluate(raw2).unwrap();
    let offsets: Vec<usize> = (0..=s.batch).map(|b| b * s.samples_per_ray).collect();
    let op = Composite::new(&offsets).unwrap().background(Background::Shared);
    let (sigma, color) = (activated.sigma.view().into_dyn(), activated.color.view().into_dyn());
    let bg = ArrayViewD::from_shape(&[3][..], &s.background[..]).unwrap();
    let delta_v = ArrayViewD::from_shape(&[n][..], &delta).unwrap();
    let inputs = CompositeArrays::new(sigma, delta_v, color).with_background(bg);
    let (outs, res) = op.evaluate(&inputs).unwrap();
    let mut d_color = Vec::new();
    let mut sse = 0.0;
    for (b, &pick) in picked.iter().enumerate() {
        for c in 0..3 {
            let diff = f64::from(outs.color[[b, c]]) - f64::from(targets[3 * pick + c]);
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
    let (g_sigma, g_color) = (g.sigma.unwrap(), g.color.unwrap());
    let g_sigma1: ArrayView1<'_, f32> = g_sigma.view().into_dimensionality().unwrap();
    let g_color2: ArrayView2<'_, f32> = g_color.view().into_dimensionality().unwrap();
    let d_raw = act
        .vjp(
            raw2,
            &ActivatedGrads {
                sigma: Some(g_sigma1),
                color: Some(g_color2),
            },
        )
        .unwrap();
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

    let scale = cpu_grad.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    let worst = gpu_grad
        .iter()
        .zip(cpu_grad.iter())
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    let cpu_mse = sse / (3.0 * s.batch as f64);
    println!(
        "one step, {} rays of {} samples on a {}^3 grid: grid gradient max |GPU - CPU| {worst:.2e} of max |gradient| {scale:.2e}; MSE GPU {gpu_mse:.6e}, CPU {cpu_mse:.6e}",
        s.batch, s.samples_per_ray, s.nodes
    );
    assert!(scale > 0.0, "the batch must touch the grid");
    // The host's positions round the same f64 sums as the kernel's, which may fuse a multiply
    // and an add: the chain agrees to f32 rounding, far inside this bound.
    assert!(worst <= 1e-3 * scale, "{worst} against {scale}");
    assert!((gpu_mse - cpu_mse).abs() <= 1e-5 * cpu_mse, "{gpu_mse} {cpu_mse}");
}

#[test]
fn the_trainer_refuses_bad_input() {
    let Some(gpu) = device_for_tests().unwrap() else { return };
    let (o, d, t) = scene(10);
    let s = SETTINGS;
    assert!(matches!(
        DenseGridTrainer::new(&gpu, s, &o[1..], &d, &t),
        Err(CudaError::Shape { .. })
    ));
    assert!(matches!(
        DenseGridTrainer::new(&gpu, s, &o, &d[3..], &t),
        Err(CudaError::Shape { .. })
    ));
    assert!(matches!(
        DenseGridTrainer::new(&gpu, s, &[], &[], &[]),
        Err(CudaError::Shape { .. })
    ));
    let no_batch = TrainerSettings { batch: 0, ..s };
    assert!(matches!(
        DenseGridTrainer::new(&gpu, no_batch, &o, &d, &t),
        Err(CudaError::InvalidSettings(_))
    ));
    let one_node = TrainerSettings { nodes: 1, ..s };
    assert!(matches!(
        DenseGridTrainer::new(&gpu, one_node, &o, &d, &t),
        Err(CudaError::InvalidGrid(_))
    ));
    let mut trainer = DenseGridTrainer::new(&gpu, s, &o, &d, &t).unwrap();
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
