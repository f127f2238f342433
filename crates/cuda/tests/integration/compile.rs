//! The kernels compile with NVRTC (no GPU needed; skipped where libnvrtc does not load).

use fogray_cuda::{compile, compile_grid, compile_train, compile_tuned, CudaError, KernelTuning};

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
            loads_in_flight: 3,
            ..good
        },
        KernelTuning {
            threads_per_block: 256,
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
