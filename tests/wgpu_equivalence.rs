//! `--device wgpu` against the CPU (`flex`): a few training steps of tiny NeuroKin, K-3DGS and
//! FFKSM models from the same seed on both, their losses step by step and their rendered
//! images compared within a tolerance. Behind the `wgpu` feature; CI runs it on lavapipe
//! (Mesa's software Vulkan): `cargo test --release --features wgpu --test wgpu_equivalence`.
#![cfg(feature = "wgpu")]

use burn::tensor::Tensor;
use selfmodel::core::device::DeviceChoice;
use selfmodel::self_models::ffksm::{FfksmVariant, ffksm_run};
use selfmodel::self_models::harness::{Fitted, SelfModel, SelfModelRun, fit_run};
use selfmodel::self_models::k3dgs::{K3dgsVariant, TrainSplatting, k3dgs_run};
use selfmodel::self_models::neurokin::neurokin_run;

/// Test poses rendered by both devices.
const POSES: usize = 4;

fn host(t: Tensor<4>) -> Vec<f32> {
    t.into_data().try_into_vec::<f32>().unwrap()
}

/// Every renderer's images (silhouettes, then depth where it has one) of the first test poses.
fn images(f: &Fitted) -> Vec<(String, Vec<f32>)> {
    let q = f.test_set.inputs.clone().slice([0..POSES]);
    f.trained
        .renderers
        .iter()
        .flat_map(|(label, r)| {
            let (s, d) = r.render(q.clone());
            let mut v = vec![(format!("{label} silhouette"), host(s))];
            if let Some(d) = d {
                v.push((format!("{label} depth"), host(d)));
            }
            v
        })
        .collect()
}

/// Train `cfg` for `steps` steps on the CPU and on wgpu, and compare.
fn same_on_both<M: SelfModel>(
    mut cfg: SelfModelRun<M>,
    steps: usize,
    loss_tol: f64,
    image_tol: f32,
) {
    cfg.train.steps = steps;
    cfg.train.checkpoint_every = 0;
    let dir = std::env::temp_dir().join(format!(
        "selfmodel_wgpu_{}_{}",
        std::process::id(),
        cfg.name.replace(|c: char| !c.is_alphanumeric(), "_")
    ));
    let fit = |d| {
        fit_run(&cfg, &dir.join(format!("{d}")), d, false)
            .unwrap_or_else(|e| panic!("{} on {d}: {e}", cfg.name))
    };
    let (cpu, gpu) = (fit(DeviceChoice::Cpu), fit(DeviceChoice::Wgpu));
    let (a, b) = (&cpu.trained.log.curve, &gpu.trained.log.curve);
    assert_eq!(
        a.len(),
        b.len(),
        "{}: loss curves of different length",
        cfg.name
    );
    assert!(!a.is_empty(), "{}: no losses logged", cfg.name);
    for ((s, la), (_, lb)) in a.iter().zip(b) {
        let rel = (la - lb).abs() / la.abs().max(1e-6);
        eprintln!(
            "{} step {s}: cpu {la:.6} wgpu {lb:.6} (rel {rel:.1e})",
            cfg.name
        );
        assert!(
            rel <= loss_tol,
            "{} step {s}: loss {la} on the CPU, {lb} on wgpu",
            cfg.name
        );
    }
    for ((name, x), (_, y)) in images(&cpu).iter().zip(images(&gpu)) {
        assert_eq!(x.len(), y.len());
        let max = x
            .iter()
            .zip(&y)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f32::max);
        let mean = x.iter().zip(&y).map(|(p, q)| (p - q).abs()).sum::<f32>() / x.len() as f32;
        eprintln!(
            "{} {name}: max |cpu - wgpu| {max:.2e}, mean {mean:.2e}",
            cfg.name
        );
        assert!(
            max <= image_tol,
            "{} {name}: images differ by up to {max} (mean {mean})",
            cfg.name
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn neurokin_trains_the_same_on_wgpu() {
    same_on_both(neurokin_run("quick").unwrap(), 6, 1e-3, 1e-3);
}

/// K-3DGS trains dense on a GPU (no read of the projected Gaussians at every step): the
/// CPU trains dense here too, so both run the same arithmetic.
#[test]
fn k3dgs_trains_the_same_on_wgpu() {
    let mut run = k3dgs_run("quick", K3dgsVariant::IsotropicAlpha).unwrap();
    run.model.train_splatting = TrainSplatting::Dense;
    same_on_both(run, 6, 1e-3, 1e-3);
}

#[test]
fn ffksm_trains_the_same_on_wgpu() {
    same_on_both(
        ffksm_run("quick", FfksmVariant::Reimplementation).unwrap(),
        6,
        1e-3,
        1e-3,
    );
}
