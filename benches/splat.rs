//! Timing of the splatting stages on a fixed scene (a plain timing binary, not criterion):
//! `cargo bench -p fogray-benches --bench splat [-- SPLATS SIZE]`. Prints the time of each stage
//! (best of a few runs) on the global pool and on one thread, and the depth sort on its own
//! at 1e5 and 1e6 keys.

use std::time::{Duration, Instant};

use fogray_ops::splat::{bin, project, rasterize, rasterize_vjp, SplatArrays, SplatRender};
use fogray_ops::{Intrinsics, PinholeCamera};
use ndarray::{Array1, Array2};
use rand::{Rng, SeedableRng};

fn best<T>(runs: usize, mut f: impl FnMut() -> T) -> (Duration, T) {
    let mut out = None;
    let mut best = Duration::MAX;
    for _ in 0..runs {
        let t = Instant::now();
        let v = f();
        best = best.min(t.elapsed());
        out = Some(v);
    }
    (best, out.unwrap())
}

fn main() {
    let args: Vec<usize> = std::env::args().skip(1).filter_map(|a| a.parse().ok()).collect();
    let n = args.first().copied().unwrap_or(100_000);
    let size = args.get(1).copied().unwrap_or(200);
    let k = Intrinsics::from_vertical_fov(size, size, 50f64.to_radians()).unwrap();
    let cam = PinholeCamera::look_at(k, [0.0, 0.0, -4.0], [0.0; 3], [0.0, -1.0, 0.0]).unwrap();
    let mut rng = rand::rngs::StdRng::seed_from_u64(1);
    let means = Array2::from_shape_fn((n, 3), |_| rng.gen_range(-1.5..1.5));
    let log_scales = Array2::from_shape_fn((n, 3), |_| rng.gen_range(0.005f64.ln()..0.04f64.ln()));
    let quats = Array2::from_shape_fn((n, 4), |_| rng.gen_range(-1.0..1.0));
    let logits = Array1::from_shape_fn(n, |_| rng.gen_range(-2.0..3.0));
    let colors = Array2::from_shape_fn((n, 3), |_| rng.gen_range(0.0..1.0));
    let opacity: Vec<f64> = logits.iter().map(|x: &f64| 1.0 / (1.0 + (-x).exp())).collect();
    let cols: Vec<[f64; 3]> = (0..n).map(|i| [0, 1, 2].map(|c| colors[[i, c]])).collect();
    let op = SplatRender::new(&cam, [1.0; 3]).unwrap();
    let up: Vec<[f64; 3]> = vec![[1.0, -0.5, 0.25]; size * size];
    let g_image = Array2::from_shape_fn((size * size, 3), |(_, c)| [1.0, -0.5, 0.25][c]);

    for threads in [0, 1] {
        let mut builder = rayon::ThreadPoolBuilder::new();
        if threads > 0 {
            builder = builder.num_threads(threads);
        }
        let pool = builder.build().unwrap();
        pool.install(|| {
            let label = format!("{} thread(s)", rayon::current_num_threads());
            let (t_proj, proj) = best(5, || {
                project(&cam, means.view(), log_scales.view(), quats.view()).unwrap()
            });
            let (t_bin, tiles) = best(5, || bin(&proj, size, size, 1 << 26).unwrap());
            let (t_raster, raster) = best(5, || rasterize(&proj, &tiles, &opacity, &cols, [1.0; 3]).unwrap());
            let (t_back, _) = best(5, || {
                rasterize_vjp(&proj, &tiles, &opacity, &cols, [1.0; 3], &raster, &up).unwrap()
            });
            let arrays = || SplatArrays {
                means: means.view(),
                log_scales: log_scales.view(),
                quats: quats.view(),
                opacity_logits: logits.view(),
                colors: colors.view(),
            };
            let (t_render, _) = best(5, || op.render(arrays()).unwrap());
            let (t_vjp, _) = best(5, || op.vjp(arrays(), g_image.view()).unwrap());
            let visible = proj.radius.iter().filter(|&&r| r > 0).count();
            println!(
                "{n} splats ({visible} visible), {size}x{size}, {} intersections, {label}:",
                tiles.intersections()
            );
            println!(
                "  project {t_proj:.2?}  bin {t_bin:.2?}  rasterize {t_raster:.2?}  rasterize backward {t_back:.2?}"
            );
            println!("  fused render (forward) {t_render:.2?}  fused vjp (forward + backward) {t_vjp:.2?}");
        });
    }

    for keys in [100_000usize, 1_000_000] {
        let data: Vec<(u64, u32)> = (0..keys)
            .map(|i| (rng.gen_range(1.0f64..10.0).to_bits(), i as u32))
            .collect();
        let (t_seq, _) = best(5, || {
            let mut d = data.clone();
            d.sort_unstable();
            d
        });
        let (t_par, _) = best(5, || {
            let mut d = data.clone();
            rayon::slice::ParallelSliceMut::par_sort_unstable(&mut d[..]);
            d
        });
        println!("sort of {keys} (depth, index) keys: sort_unstable {t_seq:.2?}, par_sort_unstable {t_par:.2?}");
    }
}
