//! A dense grid fitted to lego (NeRF-synthetic, `$FOGRAY_DATA/nerf_synthetic/lego`) at
//! `--downscale 4` (200x200) on the device: held-out PSNR against training time, on the views
//! `fogray fit` holds out (every eighth in file order). Ignored by default (it needs a GPU and
//! the dataset; it skips, saying so, without either):
//!
//! ```text
//! FOGRAY_DATA=<folder holding nerf_synthetic> cargo test --release -p fogray-cuda \
//!     --test integration lego -- --ignored --nocapture
//! ```
//!
//! `FOGRAY_GPU_FITS` lists the fits to run, `nodes:samples:batch:seconds` separated by commas
//! (default `128:256:8192:10`).

use std::path::Path;
use std::time::Instant;

use fogray_cuda::{device_for_tests, CudaError, DenseGridTrainer, TrainerSettings};
use fogray_data::{load, Frame, LoadOptions};
use ndarray::Array3;

/// Origins, directions and colours `[R, 3]` of every pixel of `frames`, row-major per frame.
fn rays(frames: &[Frame]) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let (mut o, mut d, mut c) = (Vec::new(), Vec::new(), Vec::new());
    for f in frames {
        let k = f.camera.intrinsics();
        let centre = f.camera.centre();
        for row in 0..k.height {
            for col in 0..k.width {
                let dir = f.camera.direction(row, col);
                for a in 0..3 {
                    o.push(centre[a] as f32);
                    d.push(dir[a] as f32);
                    c.push(f.picture.color[[row, col, a]]);
                }
            }
        }
    }
    (o, d, c)
}

fn held_out_psnr(trainer: &mut DenseGridTrainer<'_>, test: &[Frame], o: &[f32], d: &[f32]) -> Result<f64, CudaError> {
    let colors = trainer.render(o, d)?;
    let mut renders = Vec::new();
    let mut exacts = Vec::new();
    let mut at = 0;
    for f in test {
        let k = f.camera.intrinsics();
        let len = 3 * k.height * k.width;
        renders.push(
            Array3::from_shape_vec(
                (k.height, k.width, 3),
                colors[at..at + len].iter().map(|&v| f64::from(v)).collect(),
            )
            .unwrap(),
        );
        exacts.push(f.picture.color.mapv(f64::from));
        at += len;
    }
    let r: Vec<_> = renders.iter().map(|a| a.view()).collect();
    let e: Vec<_> = exacts.iter().map(|a| a.view()).collect();
    Ok(fogray_fit::metrics::psnr(&r, &e).expect("same shapes"))
}

#[test]
#[ignore = "needs a GPU and the lego dataset; prints PSNR against time"]
fn lego_fit_on_the_device() -> Result<(), CudaError> {
    let Some(gpu) = device_for_tests()? else { return Ok(()) };
    let Ok(root) = std::env::var("FOGRAY_DATA") else {
        eprintln!("SKIPPED: FOGRAY_DATA is not set");
        return Ok(());
    };
    let lego = Path::new(&root).join("nerf_synthetic/lego");
    let options = LoadOptions {
        downscale: 4,
        ..LoadOptions::default()
    };
    let scene = load(&lego, &options).unwrap_or_else(|e| panic!("{e}"));
    let names: Vec<&str> = scene.test.iter().map(|f| f.name.as_str()).collect();
    println!("lego: {} training views, held out {names:?}", scene.train.len());
    let (o, d, c) = rays(&scene.train);
    let (to, td, _) = rays(&scene.test);
    let fits = std::env::var("FOGRAY_GPU_FITS").unwrap_or_else(|_| "128:256:8192:10".into());
    for fit in fits.split(',') {
        let v: Vec<f64> = fit
            .split(':')
            .map(|x| x.parse().expect("nodes:samples:batch:seconds"))
            .collect();
        let (nodes, samples, batch, seconds) = (v[0] as usize, v[1] as usize, v[2] as usize, v[3]);
        let settings = TrainerSettings {
            scene_box: scene.scene_box,
            nodes,
            samples_per_ray: samples,
            batch,
            shift: -4.0,
            background: [1.0; 3],
            seed: 0,
        };
        let mut trainer = DenseGridTrainer::new(&gpu, settings, &o, &d, &c)?;
        // fogray fit's schedule: --lr 0.4 until 60 % of the budget, then down geometrically to 0.04.
        let lr_at = |t: f64| {
            let f = (t / seconds - 0.6).max(0.0) / 0.4;
            0.4 * (0.04f64 / 0.4).powf(f.min(1.0))
        };
        let checkpoints = [0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 30.0, 60.0];
        let mut next = checkpoints
            .iter()
            .filter(|&&t| t <= seconds)
            .copied()
            .collect::<Vec<_>>();
        if next.last() != Some(&seconds) {
            next.push(seconds);
        }
        let mut trained = 0.0;
        let mut since = 0;
        for &stop in &next {
            let start = Instant::now();
            loop {
                let t = trained + start.elapsed().as_secs_f64();
                if t >= stop {
                    break;
                }
                for _ in 0..10 {
                    trainer.step(lr_at(t))?;
                }
                since += 10;
                // Wait for the queued steps, so that the clock measures them.
                trainer.wait()?;
            }
            trained += start.elapsed().as_secs_f64();
            let mse = trainer.take_mean_squared_error(since)?;
            since = 0;
            let psnr = held_out_psnr(&mut trainer, &scene.test, &to, &td)?;
            println!(
                "lego GPU fit {nodes}^3, {samples} samples a ray, {batch} rays a step: {trained:.2} s, {} steps, held-out PSNR {psnr:.2} dB (training MSE {mse:.5})",
                trainer.steps()
            );
        }
    }
    Ok(())
}
