//! What one NeuroKin training step asks of a GPU, counted on wgpu (lavapipe in CI): kernel
//! launches, host reads and uploads per step (`eval::device_counts`). A host read inside a
//! step makes the step wait for the device, so the losses are read only at log intervals:
//! this test fails when a read appears in any other step. Behind the `wgpu` feature:
//! `cargo test --release --features wgpu --test gpu_counts -- --nocapture` prints the counts.
#![cfg(feature = "wgpu")]

use burn::tensor::{Distribution, Tensor};
use selfmodel::core::device::{DeviceChoice, select, with_seed};
use selfmodel::core::preset::Preset;
use selfmodel::eval::device_counts::{self, DeviceCounts};
use selfmodel::self_models::neurokin::{NeuroKin, NeuroKinConfig};
use selfmodel::train::trainer::{TrainConfig, TrainHooks, TrainSet, Trainer, autodiff_device};

/// The counts of each step: what happened between the end of the previous step and its own.
struct PerStep {
    last: DeviceCounts,
    steps: Vec<DeviceCounts>,
}

impl TrainHooks<NeuroKin> for PerStep {
    fn after_step(&mut self, model: NeuroKin, _step: usize) -> selfmodel::Result<(NeuroKin, bool)> {
        let now = device_counts::snapshot();
        self.steps.push(now.since(&self.last));
        self.last = now;
        Ok((model, false))
    }
}

#[test]
fn a_neurokin_training_step_reads_nothing_back() {
    assert!(
        device_counts::install(),
        "another tracing subscriber was installed first"
    );
    let device = select(DeviceChoice::Wgpu).expect("a wgpu adapter (lavapipe in CI)");
    let tdev = autodiff_device(&device, 7);
    let mut cfg = NeuroKinConfig::preset("quick").unwrap();
    cfg.dof = 4;
    let (n, log_every, steps) = (32, 4, 12);
    let set = with_seed(&tdev, 3, || TrainSet {
        inputs: Tensor::<2>::random([n, cfg.dof], Distribution::Normal(0.0, 30.0), &tdev),
        targets: vec![Tensor::<4>::random(
            [n, 1, cfg.image[0], cfg.image[1]],
            Distribution::Bernoulli(0.2),
            &tdev,
        )],
    });
    let set = cfg.training_set(&set);
    // The paper preset's step: input noise, clipping; batches of 8, an epoch every 4 steps.
    let train = TrainConfig {
        steps,
        batch: 8,
        learning_rate: 1e-3,
        grad_clip_norm: Some(1.0),
        input_noise: 0.01,
        seed: 7,
        checkpoint_every: 0,
        log_every,
    };
    let model = cfg.init(&tdev, 7).unwrap();
    let mut hooks = PerStep {
        last: device_counts::snapshot(),
        steps: Vec::new(),
    };
    let (_, log) = Trainer::new(&train, "gpu counts")
        .quiet()
        .hooks(&mut hooks)
        .fit(model, &set, cfg.training_loss())
        .unwrap();
    assert_eq!(log.curve.len(), steps / log_every, "{:?}", log.curve);
    for (i, c) in hooks.steps.iter().enumerate() {
        let step = i + 1;
        eprintln!(
            "step {step:>2}: {:>4} kernel launches, {} host reads, {} uploads",
            c.launches, c.reads, c.uploads
        );
    }
    // The first step compiles and tunes its kernels; from the second on, a step is what
    // every later step will be.
    for (i, c) in hooks.steps.iter().enumerate().skip(1) {
        let step = i + 1;
        let expected = u64::from(step % log_every == 0);
        assert_eq!(
            c.reads, expected,
            "step {step}: {} host reads where {expected} was expected (the losses are read every {log_every} steps, nothing else)",
            c.reads
        );
        assert!(c.launches > 0, "step {step}: no kernel launch counted");
    }
    let typical = &hooks.steps[1];
    let mut kernels: Vec<_> = typical.kernels.iter().collect();
    kernels.sort_by(|a, b| b.1.cmp(a.1));
    eprintln!("step 2's kernels, most launched first:");
    for (name, count) in kernels.iter().take(12) {
        eprintln!("  {count:>4} x {name}");
    }
}
