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
//! With `FOGRAY_GPU_RENDERS=<dir>`, each fit writes its first held-out view beside the
//! photograph there at its end (`gpu-<nodes>-<seconds>s-<view>.png`). Each fit prints the
//! device memory in use (total minus free) at most, sampled after each allocation it makes.
//!
//! `FOGRAY_GPU_EXPONENTIALS=split-single` builds the composite with
//! `Exponentials::SplitSingle` (default: `Exponentials::Double`).
//!
//! `FOGRAY_GPU_FITS` lists the fits to run, separated by commas, each
//! `nodes:samples:batch:seconds[:sh_degree[:grow[:random_background[:occupancy[:distortion]]]]]`
//! (default `128:256:8192:10:1:1:1:1:0.01`): with `grow` 1 the grid starts at a quarter of `nodes` and
//! doubles at 10 % and 30 % of the budget, as `fogray fit`'s does; `random_background` 1
//! trains each ray over a random colour (lego has alpha); `occupancy` 1 skips the samples in
//! empty cells of an occupancy grid as `fogray fit`'s (a cell per voxel of the final grid, up
//! to 128 per axis, occupied while a step of half the final voxel through it stops 1 % of the
//! light, refreshed every 16 steps); `distortion` is the distortion loss's weight (0: none). The learning rate is `fogray fit`'s: 0.4 until 60 %
//! of the budget, then down geometrically to 0.04.

use std::path::Path;
use std::time::Instant;

use fogray_cuda::{
    device_for_tests, CudaComposite, CudaError, DenseGridTrainer, Exponentials, KernelTuning, OccupancySettings,
    StepPhases, TrainerSettings, TrainingRays,
};
use fogray_data::{load, Frame, LoadOptions};
use ndarray::Array3;

/// Origins, directions and colours `[R, 3]` and opacities `[R]` of every pixel of `frames`,
/// row-major per frame (opacity 1 where a picture has no alpha).
fn rays(frames: &[Frame]) -> (Vec<f32>, Vec<f32>, Vec<f32>, Vec<f32>) {
    let (mut o, mut d, mut c, mut alpha) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
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
                alpha.push(f.picture.alpha.as_ref().map_or(1.0, |a| a[[row, col]]));
            }
        }
    }
    (o, d, c, alpha)
}

/// The held-out PSNR over all pixels of `test`, and the renders.
fn held_out_psnr(
    trainer: &mut DenseGridTrainer<'_>,
    test: &[Frame],
    o: &[f32],
    d: &[f32],
) -> Result<(f64, Vec<Array3<f64>>), CudaError> {
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
    Ok((fogray_fit::metrics::psnr(&r, &e).expect("same shapes"), renders))
}

/// Hands back to the device what the stream-ordered allocator keeps after frees (its pool),
/// so that the next fit's memory counts its own buffers alone.
fn release_pooled_memory(gpu: &CudaComposite) -> Result<(), CudaError> {
    use fogray_cuda::cudarc::driver::sys;
    gpu.stream().synchronize()?;
    let ctx = gpu.context();
    ctx.bind_to_thread()?;
    let mut pool = std::ptr::null_mut();
    // SAFETY: the context's own device, bound to this thread; its current pool is the one
    // the stream's allocations come from, and trimming frees only memory no buffer holds.
    unsafe {
        sys::cuDeviceGetMemPool(&mut pool, ctx.cu_device()).result()?;
        sys::cuMemPoolTrimTo(pool, 0).result()?;
    }
    Ok(())
}

#[test]
#[ignore = "needs a GPU and the lego dataset; prints PSNR against time"]
fn lego_fit_on_the_device() -> Result<(), CudaError> {
    let Some(gpu) = device_for_tests()? else { return Ok(()) };
    let gpu = match std::env::var("FOGRAY_GPU_EXPONENTIALS").as_deref() {
        Ok("split-single") => CudaComposite::with_tuning(
            0,
            KernelTuning {
                exponentials: Exponentials::SplitSingle,
                ..KernelTuning::default()
            },
        )?,
        Ok("double") | Err(_) => gpu,
        Ok(other) => panic!("FOGRAY_GPU_EXPONENTIALS={other}: split-single or double"),
    };
    println!("exponentials: {:?}", gpu.tuning().exponentials);
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
    let (o, d, c, alpha) = rays(&scene.train);
    let (to, td, _, _) = rays(&scene.test);
    let data = TrainingRays {
        origins: &o,
        directions: &d,
        colors: &c,
        alpha: Some(&alpha),
    };
    // The device memory in use (total - free): the context and kernels before any trainer,
    // then sampled after each allocation of a fit (its start, each growth, each evaluation).
    let used = || -> Result<f64, CudaError> {
        let (free, total) = gpu.context().mem_get_info()?;
        Ok((total - free) as f64 / (1 << 20) as f64)
    };
    let before = used()?;
    let fits = std::env::var("FOGRAY_GPU_FITS").unwrap_or_else(|_| "128:256:8192:10:1:1:1:1:0.01".into());
    for fit in fits.split(',') {
        let v: Vec<f64> = fit
            .split(':')
            .map(|x| x.parse().expect("see FOGRAY_GPU_FITS in the module docs"))
            .collect();
        let (nodes, samples, batch, seconds) = (v[0] as usize, v[1] as usize, v[2] as usize, v[3]);
        let flag = |i: usize| v.get(i).copied().unwrap_or(0.0);
        let (sh_degree, grow, random_background) = (flag(4) as usize, flag(5) == 1.0, flag(6) == 1.0);
        let distortion = flag(8);
        let (lo, hi) = scene.scene_box;
        // Half the final grid's node spacing along the box's shortest side.
        let half_voxel = (0..3)
            .map(|a| (hi[a] - lo[a]) / (nodes - 1) as f64 / 2.0)
            .fold(f64::INFINITY, f64::min);
        let occupancy = (flag(7) == 1.0).then(|| OccupancySettings {
            cells: (nodes - 1).min(128),
            density: -(0.99f64.ln()) / half_voxel,
            every: 16,
            decay: 0.95,
        });
        // fogray fit's growth: a quarter, a half, then all of the nodes per axis.
        let stages = if grow {
            vec![(0.0, nodes.div_ceil(4)), (0.1, nodes.div_ceil(2)), (0.3, nodes)]
        } else {
            vec![(0.0, nodes)]
        };
        let settings = TrainerSettings {
            scene_box: scene.scene_box,
            nodes: stages[0].1,
            samples_per_ray: samples,
            batch,
            shift: -4.0,
            sh_degree,
            background: [1.0; 3],
            random_background,
            distortion,
            occupancy,
            seed: 0,
        };
        release_pooled_memory(&gpu)?;
        let mut trainer = DenseGridTrainer::new(&gpu, settings, data)?;
        let mut peak = used()?;
        let mut stage = 1;
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
                if stage < stages.len() && t >= stages[stage].0 * seconds {
                    trainer.resample(stages[stage].1)?;
                    peak = peak.max(used()?);
                    stage += 1;
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
            let (psnr, renders) = held_out_psnr(&mut trainer, &scene.test, &to, &td)?;
            peak = peak.max(used()?);
            // The first held-out view beside its photograph, at the end of the fit.
            if let (Ok(dir), true) = (std::env::var("FOGRAY_GPU_RENDERS"), stop == seconds) {
                let frame = &scene.test[0];
                let path = Path::new(&dir).join(format!("gpu-{nodes}-{seconds}s-{}.png", frame.name));
                let exact = frame.picture.color.mapv(f64::from);
                let render = &renders[0];
                let error = (render - &exact).mapv(|v| (4.0 * v.abs()).min(1.0));
                // Photograph, render, |error| x 4, side by side (no titles: the machine may
                // have no fonts).
                let row = ndarray::concatenate(ndarray::Axis(1), &[exact.view(), render.view(), error.view()])
                    .expect("same heights");
                fogray_fit::images::write_png(&path, row.view()).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            }
            let occupied = trainer.occupancy()?.map_or(String::new(), |cells| {
                let kept = cells.iter().filter(|&&c| c != 0).count();
                format!(", {:.1} % of cells occupied", 100.0 * kept as f64 / cells.len() as f64)
            });
            println!(
                "lego GPU fit {nodes}^3 (grown: {grow}), SH degree {sh_degree}, random background {random_background}, occupancy {}, distortion {distortion}, {samples} samples a ray, {batch} rays a step: {trained:.2} s, {} steps, held-out PSNR {psnr:.2} dB (training MSE {mse:.5}){occupied}",
                occupancy.is_some(),
                trainer.steps()
            );
        }
        // Where a step's time goes at the end of the fit (steps waited on phase by phase,
        // after the last evaluation: they change nothing above).
        let mut sum = StepPhases::default();
        let timed = 32;
        for _ in 0..timed {
            sum += trainer.step_timed(lr_at(seconds))?;
        }
        let ms = |v: f64| format!("{:.3}", 1e3 * v / timed as f64);
        println!(
            "  step split over {timed} steps at {}^3, ms: occupancy {} sampling {} lookup {} shading {} composite {} loss {} composite backward {} distortion {} shading backward {} grid backward {} adam {} (total {})",
            trainer.nodes(), ms(sum.occupancy), ms(sum.sampling), ms(sum.lookup), ms(sum.shading), ms(sum.composite),
            ms(sum.loss), ms(sum.composite_backward), ms(sum.distortion), ms(sum.shading_backward),
            ms(sum.grid_backward), ms(sum.adam), ms(sum.total())
        );
        println!("  device memory in use: at most {peak:.0} MiB, of which {before:.0} MiB before the trainer");
    }
    Ok(())
}
