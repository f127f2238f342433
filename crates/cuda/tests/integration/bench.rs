//! Throughput of the GPU composite, forward and backward, on 1,048,576 rays of 64 f32 samples,
//! against the device-to-device copy bandwidth, with the CPU op's time beside it. Ignored by
//! default (it needs a GPU and some seconds):
//!
//! ```text
//! cargo test --release -p fogray-cuda --test integration bench -- --ignored --nocapture
//! ```
//!
//! `FOGRAY_BENCH_CPU=0` leaves out the CPU op (its time, and the check of the GPU's results
//! against it on the same batch). `FOGRAY_BENCH_TUNINGS=1` also times every staging layout
//! the kernels are built for ([`KernelTuning`]), each checked to give the first one's bits;
//! `FOGRAY_BENCH_STAGING=batched|pipelined|async` times only those of that staging.
//! `FOGRAY_BENCH_F32_EXP=1` builds every kernel timed with `Exponentials::SplitSingle`.

use std::time::Instant;

use crate::common::{scales, worst, Case, Typed};
use fogray_cuda::cudarc::driver::sys::CUevent_flags;
use fogray_cuda::{
    device_for_tests, CudaComposite, CudaError, DeviceRays, DeviceUpstream, Exponentials, HostGradients, HostOutputs,
    KernelTuning, Staging,
};
use rand::Rng;

const RAYS: usize = 1 << 20;
const LEN: usize = 64;
const REPS: usize = 10;

/// The exponentials `FOGRAY_BENCH_F32_EXP` asks for.
fn exponentials() -> Exponentials {
    if std::env::var("FOGRAY_BENCH_F32_EXP").is_ok_and(|v| v == "1") {
        Exponentials::SplitSingle
    } else {
        Exponentials::Double
    }
}

/// Milliseconds per call of `f`, timed with events on the stream (after one warm-up call).
fn time_ms(gpu: &CudaComposite, mut f: impl FnMut() -> Result<(), CudaError>) -> Result<f64, CudaError> {
    f()?;
    let ctx = gpu.context();
    let (start, end) = (
        ctx.new_event(Some(CUevent_flags::CU_EVENT_DEFAULT))?,
        ctx.new_event(Some(CUevent_flags::CU_EVENT_DEFAULT))?,
    );
    start.record(gpu.stream())?;
    for _ in 0..REPS {
        f()?;
    }
    end.record(gpu.stream())?;
    end.synchronize()?;
    Ok(f64::from(start.elapsed_ms(&end)?) / REPS as f64)
}

#[test]
#[ignore = "needs a GPU; prints throughput"]
fn throughput_of_a_million_rays_of_64_samples() -> Result<(), CudaError> {
    let Some(gpu) = device_for_tests()? else { return Ok(()) };
    let tuning = KernelTuning {
        exponentials: exponentials(),
        ..KernelTuning::default()
    };
    let gpu = if tuning == KernelTuning::default() {
        gpu
    } else {
        drop(gpu);
        CudaComposite::with_tuning(0, tuning)?
    };
    println!(
        "device: {} (compute capability {:?}), {tuning:?}",
        gpu.device_name(),
        gpu.compute_capability()
    );
    for k in gpu.kernel_info()? {
        println!(
            "kernel {}: {} registers, {} bytes of local memory per thread, {} bytes of shared memory and {} threads a block, {} blocks a multiprocessor",
            k.name, k.registers, k.local_bytes, k.shared_bytes, k.threads_per_block, k.blocks_per_multiprocessor
        );
    }
    let n = RAYS * LEN;
    let mut rng = crate::common::rng(2024);
    let case = Case {
        name: "bench",
        offsets: (0..=RAYS).map(|r| r * LEN).collect(),
        sigma: (0..n).map(|_| rng.gen_range(0.0..5.0)).collect(),
        delta: (0..n).map(|_| rng.gen_range(0.005..0.03)).collect(),
        color: (0..3 * n).map(|_| rng.gen_range(0.0..1.0)).collect(),
        background: [1.0, 1.0, 1.0],
        d_color: (0..3 * RAYS).map(|_| rng.gen_range(-1.0..1.0)).collect(),
        d_opacity: None,
    };
    let t = Typed::<f32>::of(&case);
    let x = gpu.upload(&t.host(&case))?;
    let up = gpu.upload_upstream(&x, &t.d_color, None)?;
    let mut fwd = gpu.forward_buffers(&x)?;
    let mut grads = gpu.gradient_buffers(&x)?;
    gpu.launch_forward(&x, &mut fwd)?;
    gpu.check_forward(&fwd)?;

    let t_fwd = time_ms(&gpu, || gpu.launch_forward(&x, &mut fwd))?;
    // The backward reads the forward's residual, computed above.
    let t_bwd = time_ms(&gpu, || gpu.launch_backward(&x, &fwd, &up, &mut grads))?;
    let t_both = time_ms(&gpu, || {
        gpu.launch_forward(&x, &mut fwd)?;
        gpu.launch_backward(&x, &fwd, &up, &mut grads)
    })?;

    // Bytes each pass must move at least: the forward reads sigma, delta and colour (20 B per
    // sample) and the offsets, writes colour and opacity and its residual (8 B per 8 samples);
    // the backward reads the same inputs, the residual and dL/dC, and writes three gradients
    // (20 B per sample).
    let (n64, r64) = (n as f64, RAYS as f64);
    let fwd_bytes = n64 * 20.0 + r64 * 8.0 + r64 * 16.0 + n64;
    let bwd_bytes = n64 * 20.0 + r64 * 8.0 + n64 + r64 * 12.0 + n64 * 20.0;
    let report = |what: &str, ms: f64, bytes: f64| {
        println!(
            "{what}: {ms:.3} ms, {:.0} M samples/s, {:.0} GB/s effective ({:.2} GB moved)",
            n64 / ms / 1e3,
            bytes / ms / 1e6,
            bytes / 1e9
        );
    };
    report("GPU forward", t_fwd, fwd_bytes);
    report("GPU backward", t_bwd, bwd_bytes);
    report("GPU forward+backward", t_both, fwd_bytes + bwd_bytes);

    // The reference: a device-to-device copy of 1 GiB, counting bytes read and written.
    let stream = gpu.stream();
    let words = 1usize << 28;
    let src = stream.alloc_zeros::<f32>(words)?;
    let mut dst = stream.alloc_zeros::<f32>(words)?;
    let t_copy = time_ms(&gpu, || Ok(stream.memcpy_dtod(&src, &mut dst)?))?;
    println!(
        "device-to-device copy of 1 GiB: {t_copy:.3} ms, {:.0} GB/s (read + write)",
        2.0 * (words * 4) as f64 / t_copy / 1e6
    );
    drop((src, dst));

    if std::env::var("FOGRAY_BENCH_CPU").is_ok_and(|v| v == "0") {
        return Ok(());
    }
    // The CPU op on the same batch: its time, and the GPU's results against it.
    let start = Instant::now();
    let (c_out, c_grad) = crate::common::cpu(&case, &t);
    let cpu_ms = start.elapsed().as_secs_f64() * 1e3;
    println!(
        "CPU op (fogray_ops::Composite evaluate + vjp, {} threads, allocating): {cpu_ms:.0} ms, {:.0} M samples/s",
        rayon_threads(),
        n64 / cpu_ms / 1e3
    );
    let g_out = gpu.download_outputs(&x, &fwd)?;
    let g_grad = HostGradients {
        sigma: stream.clone_dtoh(&grads.sigma)?,
        delta: stream.clone_dtoh(&grads.delta)?,
        color: stream.clone_dtoh(&grads.color)?,
        background: stream.clone_dtoh(&grads.background)?,
    };
    let s = scales(&case, &t);
    let floor = 1e-30;
    let errors = [
        ("colour", worst(&g_out.color, &c_out.color, &s.color, floor)),
        ("opacity", worst(&g_out.opacity, &c_out.opacity, &s.opacity, floor)),
        ("dsigma", worst(&g_grad.sigma, &c_grad.sigma, &s.sigma, floor)),
        ("ddelta", worst(&g_grad.delta, &c_grad.delta, &s.delta, floor)),
        ("dcolor", worst(&g_grad.color, &c_grad.color, &s.g_color, floor)),
        (
            "dbackground",
            worst(&g_grad.background, &c_grad.background, &s.background, floor),
        ),
    ];
    for (what, (e, i)) in errors {
        println!("bench batch, GPU vs CPU, {what}: max scaled error {e:.2e} at {i}");
        assert!(e <= 1e-6, "{what}: {e}");
    }
    let _: &HostOutputs<f32> = &g_out;
    Ok(())
}

/// Forward, backward and both, in milliseconds, on `gpu`'s kernels; and the results' bits.
fn time_layout(
    gpu: &CudaComposite,
    x: &DeviceRays<f32>,
    up: &DeviceUpstream<f32>,
) -> Result<([f64; 3], Vec<Vec<f32>>), CudaError> {
    let mut fwd = gpu.forward_buffers(x)?;
    let mut grads = gpu.gradient_buffers(x)?;
    let t_fwd = time_ms(gpu, || gpu.launch_forward(x, &mut fwd))?;
    let t_bwd = time_ms(gpu, || gpu.launch_backward(x, &fwd, up, &mut grads))?;
    let t_both = time_ms(gpu, || {
        gpu.launch_forward(x, &mut fwd)?;
        gpu.launch_backward(x, &fwd, up, &mut grads)
    })?;
    let s = gpu.stream();
    let bits = vec![
        s.clone_dtoh(&fwd.color)?,
        s.clone_dtoh(&fwd.opacity)?,
        s.clone_dtoh(&grads.sigma)?,
        s.clone_dtoh(&grads.delta)?,
        s.clone_dtoh(&grads.color)?,
        s.clone_dtoh(&grads.background)?,
    ];
    Ok(([t_fwd, t_bwd, t_both], bits))
}

#[test]
#[ignore = "needs a GPU; prints throughput"]
fn throughput_of_each_staging_layout() -> Result<(), CudaError> {
    if !std::env::var("FOGRAY_BENCH_TUNINGS").is_ok_and(|v| v == "1") {
        return Ok(());
    }
    let Some(gpu) = device_for_tests()? else { return Ok(()) };
    println!("staging layouts on {}", gpu.device_name());
    drop(gpu);
    let n = RAYS * LEN;
    let mut rng = crate::common::rng(7);
    let offsets: Vec<usize> = (0..=RAYS).map(|r| r * LEN).collect();
    let sigma: Vec<f32> = (0..n).map(|_| rng.gen_range(0.0..5.0)).collect();
    let delta: Vec<f32> = (0..n).map(|_| rng.gen_range(0.005..0.03)).collect();
    let color: Vec<f32> = (0..3 * n).map(|_| rng.gen_range(0.0..1.0)).collect();
    let d_color: Vec<f32> = (0..3 * RAYS).map(|_| rng.gen_range(-1.0..1.0)).collect();
    let host = fogray_cuda::HostRays {
        offsets: &offsets,
        sigma: &sigma,
        delta: &delta,
        color: &color,
        background: &[1.0, 1.0, 1.0],
    };
    let mut reference: Option<Vec<Vec<f32>>> = None;
    let only = std::env::var("FOGRAY_BENCH_STAGING").ok();
    for layout in KernelTuning::every() {
        let tuning = KernelTuning {
            exponentials: exponentials(),
            ..layout
        };
        let staging = match tuning.staging {
            Staging::Batched { loads_in_flight } => format!("batched, {loads_in_flight} loads"),
            Staging::Pipelined => "pipelined".to_string(),
            Staging::Async => "async".to_string(),
        };
        if only.as_ref().is_some_and(|o| !staging.starts_with(o.as_str())) {
            continue;
        }
        let g = CudaComposite::with_tuning(0, tuning)?;
        let x = g.upload(&host)?;
        let up = g.upload_upstream(&x, &d_color, None)?;
        let ([f, b, both], bits) = time_layout(&g, &x, &up)?;
        let regs: Vec<String> = g
            .kernel_info()?
            .into_iter()
            .filter(|k| k.name.ends_with("f32") && !k.name.starts_with("reduce"))
            .map(|k| {
                format!(
                    "{} {} regs {} B local {} B shared {} blocks/SM",
                    k.name, k.registers, k.local_bytes, k.shared_bytes, k.blocks_per_multiprocessor
                )
            })
            .collect();
        println!(
            "layout span {} B, {staging}, {} threads: forward {f:.3} ms, backward {b:.3} ms, both {both:.3} ms ({:.0} M samples/s); {}",
            tuning.span_bytes,
            tuning.threads_per_block,
            n as f64 / both / 1e3,
            regs.join(", ")
        );
        match &reference {
            None => reference = Some(bits),
            Some(want) => assert!(bits == *want, "layout {tuning:?} gives other bits"),
        }
    }
    Ok(())
}

fn rayon_threads() -> usize {
    std::thread::available_parallelism().map_or(1, usize::from)
}

/// The grid field's lookup and backward on a 128^3 grid of 4 f32 channels at 8,388,608
/// positions uniform in its box, with the CPU op's time beside it.
#[test]
#[ignore = "needs a GPU; prints throughput"]
fn throughput_of_the_grid_field() -> Result<(), CudaError> {
    use fogray_cuda::{CudaGrid, GridSpec};
    let Some(gpu) = device_for_tests()? else { return Ok(()) };
    let spec = GridSpec {
        min: [-1.0; 3],
        max: [1.0; 3],
        nodes: [128; 3],
        channels: 4,
    };
    let n = 1usize << 23;
    let mut rng = crate::common::rng(3);
    let values: Vec<f32> = (0..spec.values()).map(|_| rng.gen_range(-1.0..1.0)).collect();
    let positions: Vec<f32> = (0..3 * n).map(|_| rng.gen_range(-1.0..1.0)).collect();
    let upstream: Vec<f32> = (0..4 * n).map(|_| rng.gen_range(-1.0..1.0)).collect();
    let grid = CudaGrid::new(&gpu, spec)?;
    let s = gpu.stream();
    let (g, p, u) = (
        s.clone_htod(&values)?,
        s.clone_htod(&positions)?,
        s.clone_htod(&upstream)?,
    );
    let mut out = s.alloc_zeros::<f32>(4 * n)?;
    let mut invalid = s.alloc_zeros::<u32>(1)?;
    let mut acc = s.alloc_zeros::<f64>(spec.values())?;
    let mut gg = s.alloc_zeros::<f32>(spec.values())?;
    let mut gp = s.alloc_zeros::<f32>(3 * n)?;
    let t_fwd = time_ms(&gpu, || grid.launch_lookup(&g, &p, n, &mut out, &mut invalid))?;
    let t_bwd = time_ms(&gpu, || {
        grid.launch_backward(&g, &p, &u, n, &mut acc, &mut gg, Some(&mut gp))
    })?;
    println!(
        "GPU grid lookup, 128^3 x 4 f32, {n} positions: forward {t_fwd:.3} ms ({:.0} M lookups/s), backward (grid and positions) {t_bwd:.3} ms ({:.0} M/s)",
        n as f64 / t_fwd / 1e3,
        n as f64 / t_bwd / 1e3
    );
    if std::env::var("FOGRAY_BENCH_CPU").is_ok_and(|v| v == "0") {
        return Ok(());
    }
    let field = fogray_ops::GridField::new(
        fogray_ops::GridBox::new(&spec.min, &spec.max).unwrap(),
        &[128, 128, 128, 4],
    )
    .unwrap();
    let gv = ndarray::ArrayViewD::from_shape(&[128, 128, 128, 4][..], &values).unwrap();
    let pv = ndarray::ArrayViewD::from_shape(&[n, 3][..], &positions).unwrap();
    let uv = ndarray::ArrayViewD::from_shape(&[n, 4][..], &upstream).unwrap();
    let start = Instant::now();
    let cpu_out = field.evaluate(&gv, &pv).unwrap();
    let cpu_fwd = start.elapsed().as_secs_f64() * 1e3;
    let start = Instant::now();
    let wanted = fogray_ops::GridWanted {
        grid: true,
        positions: true,
    };
    let _ = field.vjp(&gv, &pv, &uv, wanted).unwrap();
    let cpu_bwd = start.elapsed().as_secs_f64() * 1e3;
    println!(
        "CPU op ({} threads): forward {cpu_fwd:.0} ms, backward {cpu_bwd:.0} ms",
        rayon_threads()
    );
    let got = s.clone_dtoh(&out)?;
    assert!(
        got.iter().zip(cpu_out.iter()).all(|(a, b)| a.to_bits() == b.to_bits()),
        "forward bits"
    );
    Ok(())
}
