//! `--device wgpu` against the CPU (`flex`): a few training steps of tiny NeuroKin, K-3DGS and
//! FFKSM models from the same seed on both, their losses step by step and their rendered
//! images compared within a tolerance (`selfmodel::self_models::device_equivalence`). Part of `tests/gpu.rs`;
//! under the SPIR-V compiler, the same with `--features vulkan` (a build of its own:
//! `CARGO_TARGET_DIR=target/vulkan`),
//! on a GPU's driver: lavapipe ends the process compiling cubecl's SPIR-V for shared memory
//! (docs/performance.md), so there only the compiler test below runs.

use selfmodel::core::device::DeviceChoice;
use selfmodel::self_models::device_equivalence::compare;
use selfmodel::self_models::ffksm::{FfksmVariant, ffksm_run};
use selfmodel::self_models::k3dgs::{K3dgsVariant, TrainSplatting, k3dgs_run};
use selfmodel::self_models::neurokin::neurokin_run;
use selfmodel::self_models::{model::SelfModel, run_config::SelfModelRun};

/// Train `cfg` for `steps` steps on the CPU and on wgpu, and compare.
fn same_on_both<M: SelfModel>(cfg: SelfModelRun<M>, steps: usize, loss_tol: f64, image_tol: f64) {
    let dir = crate::common::tempdir();
    let name = cfg.name.clone();
    let e = compare(cfg, steps, DeviceChoice::Wgpu, dir.path())
        .unwrap_or_else(|e| panic!("{name}: {e}"));
    for (s, a, b) in &e.losses {
        eprintln!("{name} step {s}: cpu {a:.6} wgpu {b:.6}");
    }
    eprintln!(
        "{name}: largest loss difference {:.1e} (relative), largest pixel difference {:.2e} ({})",
        e.max_loss_rel, e.max_image_abs, e.worst_image
    );
    assert!(
        e.max_loss_rel <= loss_tol,
        "{name}: losses differ by up to {:.2e} (relative)",
        e.max_loss_rel
    );
    assert!(
        e.max_image_abs <= image_tol,
        "{name}: {} differs by up to {}",
        e.worst_image,
        e.max_image_abs
    );
}

/// The build's shader compiler is the one its features name: SPIR-V with `vulkan` (on a
/// Vulkan device: lavapipe here), WGSL without, so this file tests the compiler it says.
#[test]
fn kernels_are_compiled_by_the_features_compiler() {
    let device = selfmodel::core::device::select(DeviceChoice::Wgpu).unwrap();
    let compiler = selfmodel::kernels::cube::compiler(&device).expect("a CubeCL device");
    eprintln!("GPU kernels compiled by {compiler}");
    let expected = if cfg!(feature = "vulkan") {
        "wgpu<spirv>"
    } else {
        "wgpu<wgsl>"
    };
    assert_eq!(compiler, expected);
}

#[test]
fn neurokin_trains_the_same_on_wgpu() {
    same_on_both(neurokin_run("quick").unwrap(), 6, 1e-3, 1e-3);
}

/// Autocast in f16 (`--precision f16`) trains the same on wgpu as on the CPU, where the device
/// computes in f16; where it cannot, the precision is refused in one line.
#[test]
fn f16_autocast_trains_the_same_on_wgpu() {
    let device = selfmodel::core::device::select(DeviceChoice::Wgpu).unwrap();
    let f16 = selfmodel::train::precision::Precision::F16;
    if let Err(e) = f16.check(&device) {
        let line = e.to_string();
        eprintln!("this device has no f16: {line}");
        assert!(line.contains("f16") && !line.contains('\n'), "{line}");
        return;
    }
    let mut cfg = neurokin_run("quick").unwrap();
    cfg.train.precision = f16;
    same_on_both(cfg, 6, 1e-2, 1e-2);
}

/// Autocast in flex32 (`--precision flex32`: f32 storage, relaxed arithmetic) trains on wgpu
/// as f32 does there. burn's cast from flex32 to f32 hands the tensor back still marked flex32,
/// and our batch norm refused it ("an f32 [N, C, ...] tensor": the H200's failure of
/// 2026-11-28, which followed the f16 run). The CPU has no flex32, so both runs are on wgpu.
#[test]
fn neurokin_trains_in_flex32_on_wgpu() {
    use selfmodel::train::precision::Precision;
    let dir = crate::common::tempdir();
    let train = |precision: Precision| {
        let mut cfg = neurokin_run("quick").unwrap();
        cfg.train.precision = precision;
        cfg.train.steps = 6;
        let out = dir.path().join(precision.to_string());
        selfmodel::self_models::harness::run(&cfg, &out, DeviceChoice::Wgpu, false)
            .unwrap_or_else(|e| panic!("{precision}: {e}"))
    };
    let (f32, flex32) = (train(Precision::F32), train(Precision::Flex32));
    let losses = |o: &selfmodel::self_models::harness::RunOutcome| {
        o.log.curve.iter().map(|p| p.1).collect::<Vec<_>>()
    };
    eprintln!(
        "f32: {:.3} dB, losses {:?}; flex32: {:.3} dB, losses {:?}",
        f32.result.psnr_db_test,
        losses(&f32),
        flex32.result.psnr_db_test,
        losses(&flex32)
    );
    assert!(flex32.result.psnr_db_test.is_finite());
    assert!(
        (flex32.result.psnr_db_test - f32.result.psnr_db_test).abs() < 0.1,
        "flex32 {} dB against f32 {} dB",
        flex32.result.psnr_db_test,
        f32.result.psnr_db_test
    );
}

/// K-3DGS trains dense on a GPU (no read of the projected Gaussians at every step): the
/// CPU trains dense here too, so both run the same arithmetic.
#[test]
fn k3dgs_trains_the_same_on_wgpu() {
    let mut run = k3dgs_run("quick", K3dgsVariant::IsotropicAlpha).unwrap();
    run.model.train_splatting = TrainSplatting::Dense;
    same_on_both(run, 6, 1e-3, 1e-3);
}

/// Left out of CI's lavapipe run: FFKSM's field tunes some forty matrix products there (three
/// minutes of kernel compilation, as long as the rest of this file). `gpu_check`'s
/// `equivalence` part runs the same comparison (reports/gpu/lavapipe/equivalence.csv, and on
/// each GPU); `-- --ignored` runs it here.
#[test]
#[ignore = "minutes of kernel tuning on lavapipe: run with -- --ignored, or gpu_check --parts equivalence"]
fn ffksm_trains_the_same_on_wgpu() {
    same_on_both(
        ffksm_run("quick", FfksmVariant::Reimplementation).unwrap(),
        6,
        1e-3,
        1e-3,
    );
}
