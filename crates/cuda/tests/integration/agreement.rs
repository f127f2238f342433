//! The GPU composite against the CPU op (`fogray_ops::Composite`), element by element, on
//! random rays and the CPU suite's hard cases, in f32 (to 1e-6) and f64 (to 1e-12) of the size
//! of the terms each value is made of. Skipped, with a message, where there is no CUDA driver
//! or device (`FOGRAY_CUDA_REQUIRED=1` makes that a failure).

use crate::common::{compare, random_case, rng, Case, Typed};
use fogray_cuda::{device_for_tests, CudaComposite, CudaError, DeviceFloat, Exponentials, HostRays, KernelTuning};

/// Scaled-error bounds, and the scale below which a value is judged absolutely (an f32 output
/// below 1e-30 is near its subnormals, where relative precision ends).
const F32_TOL: f64 = 1e-6;
const F32_FLOOR: f64 = 1e-30;
const F64_TOL: f64 = 1e-12;
const F64_FLOOR: f64 = 1e-290;

/// The default kernels, and those that take f32 data's exponentials in single precision
/// (`Exponentials::SplitSingle`), which every f32 check runs too.
struct Gpus {
    exact: CudaComposite,
    split_single: CudaComposite,
}

impl std::ops::Deref for Gpus {
    type Target = CudaComposite;
    fn deref(&self) -> &CudaComposite {
        &self.exact
    }
}

fn gpu() -> Option<Gpus> {
    let exact = device_for_tests().unwrap_or_else(|e| panic!("CUDA device present but unusable: {e}"))?;
    let tuning = KernelTuning {
        exponentials: Exponentials::SplitSingle,
        ..KernelTuning::default()
    };
    let split_single = CudaComposite::with_tuning(0, tuning).unwrap_or_else(|e| panic!("{tuning:?}: {e}"));
    Some(Gpus { exact, split_single })
}

fn check_both(gpu: &Gpus, c: &Case) {
    check_f32(gpu, c);
    check_f64(gpu, c);
}

fn check_f32(gpu: &Gpus, c: &Case) {
    let e = compare::<f32>(&gpu.exact, c, F32_FLOOR);
    assert!(e.iter().all(|&e| e <= F32_TOL), "f32 {}: {e:?}", c.name);
    let e = compare::<f32>(&gpu.split_single, c, F32_FLOOR);
    let worst = e.iter().fold(0.0f64, |m, &v| m.max(v));
    println!(
        "f32 {}, single-precision exponentials: worst scaled error {worst:.2e}",
        c.name
    );
    assert!(e.iter().all(|&e| e <= F32_TOL), "f32 {} (SplitSingle): {e:?}", c.name);
}

fn check_f64(gpu: &CudaComposite, c: &Case) {
    let e = compare::<f64>(gpu, c, F64_FLOOR);
    assert!(e.iter().all(|&e| e <= F64_TOL), "f64 {}: {e:?}", c.name);
}

fn rays_of(lens: &[usize], sample: impl Fn(usize, usize) -> (f64, f64)) -> Vec<Vec<(f64, f64)>> {
    lens.iter()
        .enumerate()
        .map(|(r, &len)| (0..len).map(|k| sample(r, k)).collect())
        .collect()
}

#[test]
fn random_rays_agree_with_the_cpu_op() {
    let Some(gpu) = gpu() else { return };
    let mut rng = rng(44);
    for (rays, max_len) in [(1, 5), (37, 20), (300, 300), (2000, 70)] {
        let c = random_case(&mut rng, rays, max_len);
        check_both(&gpu, &c);
    }
    // Without an opacity upstream.
    let mut c = random_case(&mut rng, 200, 100);
    c.d_opacity = None;
    check_both(&gpu, &c);
}

#[test]
fn every_length_around_the_residual_chunks_agrees() {
    let Some(gpu) = gpu() else { return };
    let lens: Vec<usize> = (0..=34).collect();
    let c = Case::new(
        "lengths 0..=34",
        &rays_of(&lens, |r, k| {
            (0.3 + ((r * 7 + k * 3) % 11) as f64, 0.05 + (k % 3) as f64 * 0.1)
        }),
        &mut rng(1),
    );
    check_both(&gpu, &c);
}

#[test]
fn tiny_optical_depths_agree() {
    let Some(gpu) = gpu() else { return };
    // tau = 1e-12 (f64: where 1 - exp(-tau) loses five digits) and 1e-10 (f32 data).
    let c = Case::new("tau 1e-12", &rays_of(&[1, 7, 50], |_, _| (1e-6, 1e-6)), &mut rng(2));
    check_f64(&gpu, &c);
    let c = Case::new("tau 1e-10", &rays_of(&[1, 7, 50], |_, _| (1e-5, 1e-5)), &mut rng(3));
    check_f32(&gpu, &c);
}

#[test]
fn huge_optical_depths_agree() {
    let Some(gpu) = gpu() else { return };
    // 1e3, 1e6, 1e30 (a product of two finite f32s), and a sample of 1 behind a 1e30 (what
    // a subtraction from the total depth would lose).
    let rays = vec![
        vec![(1e3, 1.0); 3],
        vec![(1e6, 1.0), (1.0, 0.5), (2.0, 0.25)],
        vec![(1.0, 0.5), (1e15, 1e15), (1.0, 1.0), (3.0, 0.1)],
        vec![(1.0, 1.0), (1.0, 1.0), (1e15, 1e15)],
        (0..40)
            .map(|k| if k == 20 { (1e15, 1e15) } else { (0.1, 0.2) })
            .collect(),
        // 1e40: past f32's range, so the depth behind it rounds to an infinite f32 (what the
        // single-precision exponentials must not turn into NaN).
        vec![(1.0, 0.5), (1e20, 1e20), (1.0, 1.0), (2.0, 0.5)],
    ];
    check_both(&gpu, &Case::new("huge tau", &rays, &mut rng(4)));
    // f64: an optical depth that overflows to infinity from finite inputs.
    let rays = vec![vec![(0.5, 0.5), (1e200, 1e200), (1.0, 1.0)], vec![(1e200, 1e200)]];
    check_f64(&gpu, &Case::new("infinite tau", &rays, &mut rng(5)));
}

#[test]
fn zero_lengths_zero_densities_and_empty_rays_agree() {
    let Some(gpu) = gpu() else { return };
    let zero_delta = rays_of(&[1, 5, 9], |_, _| (3.0, 0.0));
    check_both(&gpu, &Case::new("delta = 0", &zero_delta, &mut rng(6)));
    let zero_sigma = rays_of(&[1, 5, 17], |_, _| (0.0, 0.3));
    let c = Case::new("sigma = 0", &zero_sigma, &mut rng(7));
    check_both(&gpu, &c);
    // Zero density: the colour is the background exactly.
    let t = Typed::<f32>::of(&c);
    let out = gpu.evaluate(&t.host(&c)).expect("forward");
    for r in 0..c.rays() {
        assert_eq!(&out.color[3 * r..3 * r + 3], &t.background[..], "ray {r}");
        assert_eq!(out.opacity[r], 0.0);
    }
    let empty = rays_of(&[0, 3, 0, 0, 8, 0], |_, k| (1.0 + k as f64, 0.1));
    check_both(&gpu, &Case::new("empty rays", &empty, &mut rng(8)));
    check_both(
        &gpu,
        &Case::new("only empty rays", &rays_of(&[0, 0, 0], |_, _| (1.0, 1.0)), &mut rng(9)),
    );
    check_both(&gpu, &Case::new("no ray", &[], &mut rng(10)));
}

#[test]
fn transmittance_underflow_and_long_rays_agree() {
    let Some(gpu) = gpu() else { return };
    // Depth 200 (T underflows f32, not f64) and 1000 (underflows f64 too).
    let rays = rays_of(&[400, 2000], |_, _| (5.0, 0.1));
    check_both(&gpu, &Case::new("transmittance underflow", &rays, &mut rng(11)));
    // A 1e5-sample ray of constant density, total depth 20.
    let rays = rays_of(&[100_000], |_, _| (2.0, 1e-4));
    check_both(&gpu, &Case::new("1e5 samples", &rays, &mut rng(12)));
}

#[test]
fn invalid_values_are_errors() {
    let Some(gpu) = gpu() else { return };
    let offsets = [0, 2, 3];
    let good = [0.5f32, 1.0, 2.0];
    let color = [0.5f32; 9];
    let bg = [0.0f32; 3];
    let run = |sigma: &[f32], delta: &[f32], color: &[f32], bg: &[f32]| {
        gpu.evaluate(&HostRays {
            offsets: &offsets,
            sigma,
            delta,
            color,
            background: bg,
        })
    };
    assert!(run(&good, &good, &color, &bg).is_ok());
    let invalid = |r: Result<_, CudaError>| matches!(r, Err(CudaError::InvalidSample));
    assert!(invalid(run(&[0.5, f32::NAN, 1.0], &good, &color, &bg)));
    assert!(invalid(run(&good, &[0.5, 1.0, -1.0], &color, &bg)));
    assert!(invalid(run(&[f32::INFINITY, 1.0, 1.0], &good, &color, &bg)));
    let mut bad_color = color;
    bad_color[7] = f32::NAN;
    assert!(invalid(run(&good, &good, &bad_color, &bg)));
    assert!(matches!(
        run(&good, &good, &color, &[0.0, f32::INFINITY, 0.0]),
        Err(CudaError::InvalidBackground { channel: 1, .. })
    ));
    assert!(matches!(
        run(&good, &good[..2], &color, &bg),
        Err(CudaError::Shape { .. })
    ));
    assert!(matches!(
        gpu.evaluate(&HostRays {
            offsets: &[0, 3, 2],
            sigma: &good,
            delta: &good,
            color: &color,
            background: &bg,
        }),
        Err(CudaError::Offsets(_))
    ));
}

/// The comparison's scales bound the CPU op's values (each is the sum of the sizes of the
/// terms that value is made of): the harness itself, checked on any machine.
#[test]
fn the_scales_bound_the_cpu_values() {
    let mut rng = rng(45);
    let mut cases = vec![random_case(&mut rng, 100, 120)];
    cases.push(Case::new(
        "huge tau",
        &[vec![(1.0, 0.5), (1e15, 1e15), (1.0, 1.0)], vec![(5.0, 0.1); 400]],
        &mut rng,
    ));
    for c in &cases {
        let t = Typed::<f64>::of(c);
        let (out, g) = crate::common::cpu(c, &t);
        let s = crate::common::scales(c, &t);
        let pairs = [
            (&out.color, &s.color),
            (&out.opacity, &s.opacity),
            (&g.sigma, &s.sigma),
            (&g.delta, &s.delta),
            (&g.color, &s.g_color),
            (&g.background, &s.background),
        ];
        for (k, (values, scale)) in pairs.iter().enumerate() {
            for (i, (v, s)) in values.iter().zip(scale.iter()).enumerate() {
                assert!(
                    v.abs() <= s * (1.0 + 1e-9) + 1e-300,
                    "{} array {k} [{i}]: {v} > {s}",
                    c.name
                );
            }
        }
    }
}

/// Every staging layout the kernels are built for sums in the same order: the same bits as
/// the default layout, in f32 and f64, on random rays (lengths across the span sizes) and a
/// ray longer than any span; and with `Exponentials::SplitSingle`, the same f32 bits as the
/// default layout built with it.
#[test]
fn every_staging_layout_gives_the_same_bits() {
    let Some(default) = gpu() else { return };
    let mut r = rng(31);
    let mut cases = vec![random_case(&mut r, 500, 70)];
    let long = rays_of(&[1, 3001, 17], |_, k| {
        (0.05 + (k % 13) as f64 * 0.4, 0.01 + (k % 5) as f64 * 0.002)
    });
    cases.push(Case::new("a long ray between short ones", &long, &mut r));
    let build = |layouts: &[KernelTuning]| -> Vec<CudaComposite> {
        layouts
            .iter()
            .map(|&t| CudaComposite::with_tuning(0, t).unwrap_or_else(|e| panic!("{t:?}: {e}")))
            .collect()
    };
    let layouts = KernelTuning::every();
    let others = build(&layouts);
    for c in &cases {
        same_bits::<f32>(&default, &others, &layouts, c);
        same_bits::<f64>(&default, &others, &layouts, c);
    }
    let split = |t: KernelTuning| KernelTuning {
        exponentials: Exponentials::SplitSingle,
        ..t
    };
    let default = CudaComposite::with_tuning(0, split(KernelTuning::default())).expect("SplitSingle");
    let layouts: Vec<KernelTuning> = layouts.into_iter().map(split).collect();
    let others = build(&layouts);
    for c in &cases {
        same_bits::<f32>(&default, &others, &layouts, c);
    }
}

fn same_bits<F: fogray_tape::Float + DeviceFloat>(
    default: &CudaComposite,
    others: &[CudaComposite],
    layouts: &[KernelTuning],
    c: &Case,
) {
    let t = Typed::<F>::of(c);
    let run = |g: &CudaComposite| {
        let (o, d) = g
            .evaluate_vjp(&t.host(c), &t.d_color, t.d_opacity.as_deref())
            .unwrap_or_else(|e| panic!("{}: {e}", c.name));
        [o.color, o.opacity, d.sigma, d.delta, d.color, d.background]
    };
    let want = run(default);
    for (g, layout) in others.iter().zip(layouts) {
        let got = run(g);
        for (k, (a, b)) in got.iter().zip(&want).enumerate() {
            let first = a
                .iter()
                .zip(b)
                .position(|(x, y)| DeviceFloat::to_f64(*x).to_bits() != DeviceFloat::to_f64(*y).to_bits());
            assert!(
                first.is_none(),
                "{} {layout:?}: output {k} differs at {first:?}",
                c.name
            );
        }
    }
    println!(
        "{} {}: {} layouts, the same bits",
        std::any::type_name::<F>(),
        c.name,
        layouts.len()
    );
}
