//! Lower precision on the CPU: a device whose default float dtype is bf16 trains NeuroKin on
//! burn's ops (our kernels take f32 only, `cpu_extension::on_flex`). Its own process: a
//! device's dtype is set once for the whole process.

use burn::tensor::{DType, Distribution, FloatDType, Tensor};
use selfmodel::core::device::{DeviceChoice, select};
use selfmodel::self_models::neurokin::neurokin_run;
use selfmodel::train::batcher::TrainSet;
use selfmodel::train::config::TrainConfig;
use selfmodel::train::trainer::{Trainer, autodiff_device};

#[test]
fn neurokin_trains_in_bf16_on_the_cpu() {
    let mut device = select(DeviceChoice::Cpu).unwrap();
    device.configure(FloatDType::BF16).unwrap();
    let tdev = autodiff_device(&device, 0);
    let cfg = neurokin_run("quick").unwrap().model;
    let n = 64;
    let [h, w] = cfg.image;
    let set = TrainSet {
        inputs: Tensor::<2>::random([n, cfg.dof], Distribution::Normal(0.0, 30.0), &tdev),
        targets: vec![Tensor::<4>::random(
            [n, 1, h, w],
            Distribution::Bernoulli(0.1),
            &tdev,
        )],
    };
    assert_eq!(
        set.inputs.dtype(),
        DType::BF16,
        "the device's default dtype"
    );
    let set = cfg.training_set(&set);
    let train = TrainConfig {
        steps: 20,
        batch: 16,
        learning_rate: 1e-3,
        grad_clip_norm: Some(1.0),
        input_noise: 0.01,
        seed: 0,
        checkpoint_every: 0,
        log_every: 5,
    };
    let model = cfg.init(&tdev, 0).unwrap();
    let (model, log) = Trainer::new(&train, "bf16")
        .quiet()
        .fit(model, &set, cfg.training_loss())
        .unwrap();
    let out = model.forward(set.inputs.clone());
    assert_eq!(out.dtype(), DType::BF16, "the network ran in bf16");
    let (first, last) = (log.curve[0].1, log.curve.last().unwrap().1);
    println!("bf16 loss: {:?}", log.curve);
    assert!(
        last.is_finite() && last < 0.8 * first,
        "bf16 training learns: loss {first} -> {last}"
    );
}
