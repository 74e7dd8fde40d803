//! Lower precision (`--precision`, autocast): f32 master weights, the network run in bf16, f16
//! or flex32 on a cast copy of them each step, the losses in f32. On the CPU a lower dtype runs
//! on burn's ops (our kernels take f32 only, `cpu_extension::on_flex`).

use burn::module::{Module, ModuleVisitor, Param};
use burn::tensor::{DType, Distribution, Tensor};
use selfmodel::core::device::{DeviceChoice, select};
use selfmodel::self_models::neurokin::neurokin_run;
use selfmodel::train::batcher::TrainSet;
use selfmodel::train::config::TrainConfig;
use selfmodel::train::precision::Precision;
use selfmodel::train::trainer::{Trainer, autodiff_device};

/// The dtypes of a module's float parameters and buffers.
fn dtypes<M: Module>(m: &M) -> Vec<DType> {
    struct Dtypes(Vec<DType>);
    impl ModuleVisitor for Dtypes {
        fn visit_float<const D: usize>(&mut self, p: &Param<Tensor<D>>) {
            self.0.push(p.val().dtype());
        }
    }
    let mut v = Dtypes(Vec::new());
    m.visit(&mut v);
    v.0
}

#[test]
fn neurokin_trains_in_every_precision_with_f32_master_weights() {
    let device = select(DeviceChoice::Cpu).unwrap();
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
    let set = cfg.training_set(&set);
    let mut finals = Vec::new();
    // flex32 is a GPU dtype: the CPU refuses it in one line.
    let refused = Precision::Flex32.check(&device).unwrap_err().to_string();
    assert!(
        refused.contains("flex32") && refused.contains("bf16") && !refused.contains('\n'),
        "{refused}"
    );
    for precision in [Precision::F32, Precision::Bf16, Precision::F16] {
        precision.check(&device).unwrap();
        let train = TrainConfig {
            steps: 20,
            batch: 16,
            learning_rate: 1e-3,
            grad_clip_norm: Some(1.0),
            input_noise: 0.01,
            seed: 0,
            checkpoint_every: 0,
            log_every: 5,
            precision,
            schedule: Default::default(),
        };
        let model = cfg.init(&tdev, 0).unwrap();
        // The cast copy computes in the lower dtype; BatchNorm and the buffers stay f32.
        if let Some(low) = precision.autocast(&model) {
            let out = low.forward(set.inputs.clone().cast(precision.dtype()));
            assert_eq!(out.dtype(), DType::from(precision.dtype()), "{precision}");
            let kinds = dtypes(&low);
            assert!(
                kinds.contains(&DType::from(precision.dtype())),
                "{precision}: {kinds:?}"
            );
            assert!(
                kinds.contains(&DType::F32),
                "{precision}: BatchNorm stays f32"
            );
        }
        let label = precision.to_string();
        let (model, log) = Trainer::new(&train, &label)
            .quiet()
            .fit(model, &set, cfg.training_loss())
            .unwrap();
        assert!(
            dtypes(&model).iter().all(|d| *d == DType::F32),
            "{precision}: the master weights stay f32"
        );
        let (first, last) = (log.curve[0].1, log.curve.last().unwrap().1);
        println!("{precision} loss: {:?}", log.curve);
        assert!(
            last.is_finite() && last < 0.8 * first,
            "{precision} training learns: loss {first} -> {last}"
        );
        finals.push((precision, last));
    }
    // Each lower precision ends near f32 (the same seed, batches and steps).
    let f32_last = finals[0].1;
    for (precision, last) in &finals[1..] {
        assert!(
            (last - f32_last).abs() < 0.05 * f32_last,
            "{precision}: loss {last} against f32's {f32_last}"
        );
    }
    // And differs from it: the network did compute in the lower dtype.
    assert!(
        finals[1..].iter().all(|(_, l)| *l != f32_last),
        "{finals:?}"
    );
}
