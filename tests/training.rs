//! The shared training loop: resume reproduces an uninterrupted run (its learning-rate
//! schedule included), a NaN loss stops cleanly keeping the last checkpoint, and gradient
//! clipping bounds the global norm.

mod common;

use std::cell::Cell;

use burn::nn::{Linear, LinearConfig};
use burn::optim::GradientsParams;
use burn::tensor::{Device, Distribution, Tensor};
use selfmodel::train::adam::clip_global_norm;
use selfmodel::train::losses::{bce, bce_with_logits, mse};
use selfmodel::train::{
    batcher::{Batch, TrainSet},
    checkpoint::CheckpointPlan,
    config::{TrainConfig, TrainLog},
    trainer::{StepLoss, Trainer, autodiff_device},
};

/// The training loop with an optional checkpoint plan.
fn train<M: burn::module::Module, S: Into<StepLoss>>(
    model: M,
    set: &TrainSet,
    cfg: &TrainConfig,
    plan: Option<&CheckpointPlan>,
    label: &str,
    loss: impl Fn(&M, &Batch) -> S,
) -> selfmodel::Result<(M, TrainLog)> {
    Trainer::new(cfg, label)
        .checkpoint(plan)
        .fit(model, set, loss)
}

fn cfg(steps: usize) -> TrainConfig {
    TrainConfig {
        steps,
        batch: 8,
        learning_rate: 1e-2,
        grad_clip_norm: Some(1.0),
        input_noise: 0.01,
        seed: 7,
        checkpoint_every: 5,
        log_every: 0,
        precision: Default::default(),
        schedule: Default::default(),
    }
}

/// 40 samples of y = sum(x) as a 1x1 "image".
fn data(dev: &Device) -> TrainSet {
    let x = Tensor::<2>::random([40, 4], Distribution::Uniform(-1.0, 1.0), dev);
    let y = x.clone().sum_dim(1).reshape([40, 1, 1, 1]);
    TrainSet {
        inputs: x,
        targets: vec![y],
    }
}

fn loss(m: &Linear, b: &selfmodel::train::batcher::Batch) -> Tensor<1> {
    let n = b.inputs.dims()[0];
    mse(
        m.forward(b.inputs.clone()).reshape([n, 1, 1, 1]),
        b.targets[0].clone(),
    )
}

fn weights(m: &Linear) -> Vec<f32> {
    m.weight.val().into_data().try_into_vec::<f32>().unwrap()
}

#[test]
fn resuming_reproduces_an_uninterrupted_run() {
    let dev = autodiff_device(&Device::flex(), 3);
    let set = data(&dev);
    dev.seed(11);
    let init = LinearConfig::new(4, 1).init(&dev);
    let dir = common::tempdir();
    let plan = |resume| CheckpointPlan {
        dir: dir.path().join("ckpt"),
        resume,
        fingerprint: serde_json::json!({"test": 1}),
    };
    let (full, log_full) = train(init.clone(), &set, &cfg(20), None, "full", loss).unwrap();
    // Train 10 steps with checkpoints, then resume to 20.
    let (_, first) = train(
        init.clone(),
        &set,
        &cfg(10),
        Some(&plan(false)),
        "first",
        loss,
    )
    .unwrap();
    assert_eq!(first.step, 10);
    let mut resumed_cfg = cfg(20);
    resumed_cfg.checkpoint_every = 5;
    // The fingerprint guards against resuming a different configuration.
    let fresh = LinearConfig::new(4, 1).init(&dev);
    let (resumed, log) =
        train(fresh, &set, &resumed_cfg, Some(&plan(true)), "resume", loss).unwrap();
    assert_eq!(log.resumed_from, Some(10));
    assert_eq!(log.step, 20);
    // The losses read back from state.json are the logged ones to the last bit.
    assert!(!first.curve.is_empty());
    assert_eq!(&log.curve[..first.curve.len()], &first.curve[..]);
    let (a, b) = (weights(&full), weights(&resumed));
    for (x, y) in a.iter().zip(&b) {
        assert!((x - y).abs() < 1e-6, "{a:?} vs {b:?}");
    }
    assert!(
        log_full.curve.last().unwrap().1 < log_full.curve[0].1,
        "loss fell"
    );
    let bad = CheckpointPlan {
        fingerprint: serde_json::json!({"test": 2}),
        ..plan(true)
    };
    let err = train(init, &set, &cfg(20), Some(&bad), "bad", loss)
        .unwrap_err()
        .to_string();
    assert!(err.contains("different configuration"), "{err}");
}

#[test]
fn a_cosine_schedule_falls_to_a_hundredth_and_resumes_where_it_stopped() {
    use selfmodel::train::config::LrSchedule;
    use selfmodel::train::trainer::Watch;
    let cosine = LrSchedule::Cosine;
    assert_eq!(cosine.rate(0.1, 0, 20), 0.1);
    assert!((cosine.rate(0.1, 10, 20) - 0.1 * 0.505).abs() < 1e-12);
    assert!((cosine.rate(0.1, 20, 20) - 0.001).abs() < 1e-12);
    let dev = autodiff_device(&Device::flex(), 3);
    let set = data(&dev);
    dev.seed(11);
    let init = LinearConfig::new(4, 1).init(&dev);
    let cfg = TrainConfig {
        schedule: cosine,
        ..cfg(20)
    };
    let (full, _) = train(init.clone(), &set, &cfg, None, "full", loss).unwrap();
    let (constant, _) = train(init.clone(), &set, &self::cfg(20), None, "constant", loss).unwrap();
    let dir = common::tempdir();
    let plan = |resume| CheckpointPlan {
        dir: dir.path().join("ckpt"),
        resume,
        fingerprint: serde_json::json!({"test": 1}),
    };
    // Killed at step 12: the checkpoint of step 10 stays.
    let mut kill = Watch(|_: &Linear, step: usize| {
        if step == 12 {
            Err(selfmodel::Error::Config("killed".into()))
        } else {
            Ok(())
        }
    });
    let killed = Trainer::new(&cfg, "killed")
        .checkpoint(Some(&plan(false)))
        .hooks(&mut kill)
        .fit(init.clone(), &set, loss);
    assert!(killed.is_err());
    let (resumed, log) = train(init, &set, &cfg, Some(&plan(true)), "resumed", loss).unwrap();
    assert_eq!(log.resumed_from, Some(10));
    let (a, b, c) = (weights(&full), weights(&resumed), weights(&constant));
    for (x, y) in a.iter().zip(&b) {
        assert!((x - y).abs() < 1e-6, "{a:?} vs {b:?}");
    }
    // The schedule changed the run: its weights are not the constant rate's.
    assert!(
        a.iter().zip(&c).any(|(x, y)| (x - y).abs() > 1e-4),
        "{a:?} vs {c:?}"
    );
}

#[test]
fn a_nan_loss_stops_and_keeps_the_last_checkpoint() {
    let dev = autodiff_device(&Device::flex(), 3);
    let set = data(&dev);
    let model = LinearConfig::new(4, 1).init(&dev);
    let dir = common::tempdir();
    let plan = CheckpointPlan {
        dir: dir.path().join("ckpt"),
        resume: false,
        fingerprint: serde_json::json!({}),
    };
    let calls = Cell::new(0);
    let err = train(model, &set, &cfg(20), Some(&plan), "nan", |m, b| {
        calls.set(calls.get() + 1);
        let l = loss(m, b);
        if calls.get() == 8 {
            l.mul_scalar(f32::NAN)
        } else {
            l
        }
    })
    .unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, selfmodel::Error::Training(_)), "{msg}");
    assert!(
        msg.contains("step 8") && msg.contains("last good checkpoint"),
        "{msg}"
    );
    let state = std::fs::read_to_string(dir.path().join("ckpt/state.json")).unwrap();
    assert!(
        state.contains("\"step\": 5") || state.contains("\"step\":5"),
        "{state}"
    );
}

#[test]
fn clipping_bounds_the_global_gradient_norm() {
    let dev = autodiff_device(&Device::flex(), 1);
    let m = LinearConfig::new(16, 16).init(&dev);
    let x = Tensor::<2>::random([8, 16], Distribution::Normal(0.0, 100.0), &dev);
    let l = m.forward(x).square().mean();
    let mut grads = GradientsParams::from_grads(l.backward(), &m);
    let norm = |n: Option<Tensor<1>>| n.expect("gradients").into_scalar::<f32>();
    let before = norm(clip_global_norm(&m, &mut grads, 0.5));
    assert!(
        before > 0.5,
        "the test needs a large gradient, got {before}"
    );
    let after = norm(clip_global_norm(&m, &mut grads, 1e9));
    assert!((after - 0.5).abs() < 1e-3, "norm after clipping {after}");
}

#[test]
fn bce_from_logits_matches_bce_of_probabilities() {
    let dev = Device::flex();
    let z = Tensor::<2>::random([4, 50], Distribution::Normal(0.0, 3.0), &dev);
    let y = Tensor::<2>::random([4, 50], Distribution::Bernoulli(0.3), &dev);
    let a = bce_with_logits(z.clone(), y.clone()).into_scalar::<f32>();
    let b = bce(burn::tensor::activation::sigmoid(z), y).into_scalar::<f32>();
    assert!((a - b).abs() < 1e-4, "{a} vs {b}");
    // Saturated logits stay finite.
    let z = Tensor::<2>::from_floats([[-200.0, 200.0]], &dev);
    let y = Tensor::<2>::from_floats([[1.0, 0.0]], &dev);
    assert!(bce_with_logits(z, y).into_scalar::<f32>().is_finite());
}

/// Every self-model with a checkpoint, reloaded from it after a finished run (`--resume` on a
/// done run), renders bit for bit what the trained model rendered: BatchNorm's running
/// statistics included (burn writes them one training step behind unless synchronised).
#[test]
fn every_self_model_reloaded_from_its_checkpoint_renders_bit_identically() {
    use selfmodel::core::device::DeviceChoice;
    use selfmodel::self_models::ffksm::{FfksmVariant, ffksm_run};
    use selfmodel::self_models::neurokin::{neurokin_run, neurokin64_run};
    use selfmodel::self_models::resneurokin_d::resneurokin_d_run;
    use selfmodel::self_models::{
        harness::{Fitted, fit_run},
        model::SelfModel,
        run_config::SelfModelRun,
    };

    fn images<R: selfmodel::Render>(f: &Fitted<R>) -> Vec<Vec<f32>> {
        let q = f.test_set.inputs.clone().slice([0..4]);
        let host = |t: Tensor<4>| t.into_data().try_into_vec::<f32>().unwrap();
        f.trained
            .renderers
            .iter()
            .flat_map(|(_, r)| {
                let (s, d) = r.render(q.clone());
                std::iter::once(host(s)).chain(d.map(host))
            })
            .collect()
    }
    fn reloads_exactly<M: SelfModel>(mut cfg: SelfModelRun<M>, steps: usize) {
        cfg.train.steps = steps;
        cfg.train.checkpoint_every = steps;
        let dir = common::tempdir();
        let fit = |resume| {
            fit_run(&cfg, &dir.path().join("ckpt"), DeviceChoice::Cpu, resume)
                .unwrap_or_else(|e| panic!("{}: {e}", cfg.name))
        };
        let trained = fit(false);
        let reloaded = fit(true);
        assert_eq!(
            reloaded.trained.log.resumed_from,
            Some(steps),
            "{}",
            cfg.name
        );
        let (a, b) = (images(&trained), images(&reloaded));
        assert!(!a.is_empty());
        for (x, y) in a.iter().zip(&b) {
            let differing = x.iter().zip(y).filter(|(p, q)| p.to_bits() != q.to_bits());
            assert_eq!(
                differing.count(),
                0,
                "{}: the reloaded model renders other pixels",
                cfg.name
            );
        }
    }
    reloads_exactly(neurokin_run("quick").unwrap(), 12);
    reloads_exactly(neurokin64_run("quick").unwrap(), 6);
    reloads_exactly(resneurokin_d_run("quick").unwrap(), 6);
    reloads_exactly(
        ffksm_run("quick", FfksmVariant::Reimplementation).unwrap(),
        6,
    );
}

/// Our Adam (one parallel pass per parameter on the CPU) against burn's: the same parameters to
/// the bit over several steps on a layer large enough for several parallel chunks, and the
/// state of either, saved and loaded into the other, goes on identically (so checkpoints
/// written before the switch resume).
#[test]
fn our_adam_is_burns_to_the_bit_and_shares_its_checkpoints() {
    let dev = autodiff_device(&Device::flex(), 3);
    dev.seed(5);
    let layer = LinearConfig::new(300, 400).init(&dev);
    let x = Tensor::<2>::random([16, 300], Distribution::Default, &dev);
    let step = |m: Linear, optim: &mut burn::optim::ModuleOptimizer, lr: f64| {
        let loss = m.forward(x.clone()).square().mean();
        let grads = GradientsParams::from_grads(loss.backward(), &m);
        optim.step(lr, m, grads)
    };
    let params = |m: &Linear| {
        let mut w = weights(m);
        w.extend(m.bias.as_ref().unwrap().val().into_data().iter::<f32>());
        w
    };
    let burns_optim = || burn::optim::AdamConfig::new().init();
    let (mut ours, mut theirs) = (layer.clone(), layer);
    let (mut our_optim, mut their_optim) = (selfmodel::train::adam::adam(), burns_optim());
    for k in 0..4 {
        let lr = 1e-2 / (k + 1) as f64;
        ours = step(ours, &mut our_optim, lr);
        theirs = step(theirs, &mut their_optim, lr);
        let (a, b) = (params(&ours), params(&theirs));
        assert!(a != params(&LinearConfig::new(300, 400).init(&dev)));
        assert!(
            a.iter().zip(&b).all(|(p, q)| p.to_bits() == q.to_bits()),
            "step {k}: our Adam differs from burn's"
        );
    }
    // Swap the states: ours goes on from burn's record, burn's from ours.
    let mut ours_from_theirs = selfmodel::train::adam::adam().load_record(their_optim.to_record());
    let mut theirs_from_ours = burns_optim().load_record(our_optim.to_record());
    let a = step(ours.clone(), &mut ours_from_theirs, 1e-3);
    let b = step(theirs, &mut theirs_from_ours, 1e-3);
    let c = step(ours, &mut our_optim, 1e-3);
    assert_eq!(params(&a), params(&b));
    assert_eq!(params(&a), params(&c));
}
