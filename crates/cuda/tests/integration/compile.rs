//! The kernels compile with NVRTC (no GPU needed; skipped where libnvrtc does not load).

use fogray_cuda::{
    compile, compile_grid, compile_train, compile_tuned, CudaError, Exponentials, KernelTuning, Staging,
};

#[test]
fn the_kernels_compile_for_hopper_ampere_and_turing() {
    for capability in [(7, 5), (8, 0), (9, 0)] {
        match compile(capability) {
            Ok(ptx) => {
                let src = ptx.to_src();
                for name in [
                    "composite_forward_f32",
                    "composite_backward_f64",
                    "composite_reduce_background_f32",
                ] {
                    assert!(src.contains(name), "{name} missing from the PTX for {capability:?}");
                }
            }
            Err(CudaError::NoNvrtc) => {
                eprintln!("SKIPPED: libnvrtc could not be loaded (put the CUDA toolkit's lib64 on LD_LIBRARY_PATH)");
                return;
            }
            Err(e) => panic!("{e}"),
        }
    }
}

#[test]
fn every_staging_layout_compiles_and_others_are_refused() {
    let good = KernelTuning::default();
    for bad in [
        KernelTuning { span_bytes: 16, ..good },
        KernelTuning {
            staging: Staging::Batched { loads_in_flight: 3 },
            ..good
        },
        KernelTuning {
            threads_per_block: 256,
            ..good
        },
        // Two stages of 128 warps' spans overflow a block's static shared memory.
        KernelTuning {
            staging: Staging::Pipelined,
            threads_per_block: 128,
            ..good
        },
    ] {
        assert!(matches!(compile_tuned((9, 0), bad), Err(CudaError::Tuning(t)) if t == bad));
    }
    for tuning in KernelTuning::every() {
        match compile_tuned((9, 0), tuning) {
            Ok(ptx) => assert!(ptx.to_src().contains("composite_backward_f32")),
            Err(CudaError::NoNvrtc) => {
                eprintln!("SKIPPED: libnvrtc could not be loaded");
                return;
            }
            Err(e) => panic!("{tuning:?}: {e}"),
        }
    }
}

#[test]
fn the_grid_and_training_kernels_compile() {
    for capability in [(7, 5), (8, 0), (9, 0)] {
        match compile_grid(capability).and_then(|g| Ok((g, compile_train(capability)?))) {
            Ok((grid, train)) => {
                let src = grid.to_src() + &train.to_src();
                for name in [
                    "grid_forward_f32",
                    "grid_scatter_f64",
                    "density_color_backward_f32",
                    "sh_density_color_forward_f32",
                    "sh_density_color_backward_f64",
                    "sample_batch",
                    "sample_range",
                    "photometric_loss",
                    "lattice",
                    "occupancy_points",
                    "occupancy_update",
                    "distortion",
                    "count_kept",
                    "scan_offsets",
                    "compact",
                    "adam",
                ] {
                    assert!(src.contains(name), "{name} missing from the PTX for {capability:?}");
                }
            }
            Err(CudaError::NoNvrtc) => {
                eprintln!("SKIPPED: libnvrtc could not be loaded");
                return;
            }
            Err(e) => panic!("{e}"),
        }
    }
}

#[test]
fn the_pipelined_and_async_stagings_copy_asynchronously_from_ampere_on() {
    for staging in [Staging::Pipelined, Staging::Async] {
        let tuning = KernelTuning {
            staging,
            threads_per_block: 64,
            ..KernelTuning::default()
        };
        for (capability, want_async) in [((7, 5), false), ((8, 0), true), ((9, 0), true)] {
            match compile_tuned(capability, tuning) {
                Ok(ptx) => {
                    let src = ptx.to_src();
                    let what = format!("{staging:?} {capability:?}");
                    assert_eq!(src.contains("cp.async.ca.shared.global"), want_async, "{what}");
                    assert_eq!(src.contains("cp.async.wait_group"), want_async, "{what}");
                }
                Err(CudaError::NoNvrtc) => {
                    eprintln!("SKIPPED: libnvrtc could not be loaded");
                    return;
                }
                Err(e) => panic!("{capability:?}: {e}"),
            }
        }
    }
    // The batched staging never does.
    let batched = KernelTuning {
        staging: Staging::Batched { loads_in_flight: 8 },
        ..KernelTuning::default()
    };
    if let Ok(ptx) = compile_tuned((9, 0), batched) {
        assert!(!ptx.to_src().contains("cp.async"));
    }
}

#[test]
fn single_precision_exponentials_use_the_single_precision_functions() {
    let split = KernelTuning {
        exponentials: Exponentials::SplitSingle,
        ..KernelTuning::default()
    };
    match (compile((9, 0)), compile_tuned((9, 0), split)) {
        (Ok(double), Ok(single)) => {
            // expf reduces to the hardware's base-2 exponential; the double exp and expm1 are
            // polynomials in f64 and never use it.
            assert!(!double.to_src().contains("ex2.approx"));
            assert!(single.to_src().contains("ex2.approx"));
        }
        (Err(CudaError::NoNvrtc), _) | (_, Err(CudaError::NoNvrtc)) => {
            eprintln!("SKIPPED: libnvrtc could not be loaded");
        }
        (Err(e), _) | (_, Err(e)) => panic!("{e}"),
    }
}
