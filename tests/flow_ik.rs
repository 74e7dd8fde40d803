//! The conditional normalizing flow (IKFlow-style) that returns many IK solutions.

use burn::tensor::{Tensor, TensorData};
use selfmodel::core::device::{DeviceChoice, select};
use selfmodel::ik::data::{DistanceErrors, IkData, IkDataConfig, reach_errors};
use selfmodel::ik::flow::{Draws, FlowConfig, FlowIk, best_of, diversity, sample, train_flow};
use selfmodel::ik::learning::FitConfig;

fn small() -> FlowConfig {
    FlowConfig {
        couplings: 6,
        hidden: vec![64, 64],
        fit: FitConfig {
            epochs: 15,
            batch: 128,
            learning_rate: 2e-3,
            ..FitConfig::paper()
        },
        best_of: 8,
        ..FlowConfig::standard()
    }
}

#[test]
fn the_flow_inverts_its_forward_pass_and_its_log_determinant_is_the_volume_change() {
    let device = select(DeviceChoice::Cpu).unwrap();
    let cfg = small();
    let flow = FlowIk::new(&cfg, 6, &device, 3).unwrap();
    // Give the zero-initialised last layers some weight: a few steps of training would, but a
    // perturbation of every parameter is quicker and covers every coupling.
    let flow = perturbed(flow, &device);
    let n = 64;
    let x: Vec<f32> = (0..n * 6)
        .map(|i| ((i * 37 % 101) as f32 / 50.0) - 1.0)
        .collect();
    let c: Vec<f32> = (0..n * 4).map(|i| (i * 13 % 17) as f32 / 17.0).collect();
    let x = Tensor::<2>::from_data(TensorData::new(x, [n, 6]), &device);
    let c = Tensor::<2>::from_data(TensorData::new(c, [n, 4]), &device);
    let (z, logdet) = flow.forward(x.clone(), c.clone());
    let back = flow.inverse(z.clone(), c.clone());
    let err = (back - x.clone()).abs().max().into_scalar::<f32>();
    assert!(err < 1e-4, "forward then inverse is off by {err}");
    // The map is not the identity, so the test means something.
    let moved = (z - x.clone()).abs().max().into_scalar::<f32>();
    assert!(
        moved > 1e-2,
        "the perturbed flow barely moves its input ({moved})"
    );
    // log|det| against finite differences of the whole map for one row.
    let row = |t: &Tensor<2>| t.clone().slice([0..1, 0..6]);
    let (x0, c0) = (row(&x), c.clone().slice([0..1, 0..4]));
    let h = 1e-2f32;
    let mut jac = nalgebra::DMatrix::<f64>::zeros(6, 6);
    for k in 0..6 {
        let mut e = vec![0.0f32; 6];
        e[k] = h;
        let d = Tensor::<2>::from_data(TensorData::new(e, [1, 6]), &device);
        let (zp, _) = flow.forward(x0.clone() + d.clone(), c0.clone());
        let (zm, _) = flow.forward(x0.clone() - d, c0.clone());
        let col = ((zp - zm) / (2.0 * h))
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        for (r, v) in col.iter().enumerate() {
            jac[(r, k)] = *v as f64;
        }
    }
    let numeric = jac.determinant().abs().ln();
    let analytic = logdet.into_data().try_to_vec::<f32>().unwrap()[0] as f64;
    assert!(
        (numeric - analytic).abs() < 2e-2,
        "log|det| {analytic} against finite differences {numeric}"
    );
}

/// Every parameter plus a small seeded offset.
fn perturbed(flow: FlowIk, device: &burn::tensor::Device) -> FlowIk {
    use burn::module::{Module, ModuleMapper, Param};
    struct Jitter<'a>(&'a burn::tensor::Device, u64);
    impl ModuleMapper for Jitter<'_> {
        fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
            self.1 += 1;
            let seed = self.1;
            let device = self.0.clone();
            param.map(move |t| {
                let dims = t.dims();
                let n: usize = dims.iter().product();
                let v: Vec<f32> = (0..n)
                    .map(|i| {
                        (((i as u64 * 2654435761 + seed * 97) % 1000) as f32 / 1000.0 - 0.5) * 0.2
                    })
                    .collect();
                t + Tensor::<D>::from_data(TensorData::new(v, dims), &device)
            })
        }
    }
    flow.map(&mut Jitter(device, 0))
}

#[test]
fn a_tiny_flow_fit_lowers_its_likelihood_loss_and_samples_many_seeded_solutions() {
    let r = 90f64.to_radians();
    let robot = selfmodel::sim::dh_robot::ur5([-r, r]);
    let data = IkData::generate(
        &robot.chain,
        &IkDataConfig {
            samples: 4_000,
            train: 3_000,
            range_deg: 90.0,
            seed: 2,
            validation: 0,
        },
    )
    .unwrap();
    let device = select(DeviceChoice::Cpu).unwrap();
    let cfg = small();
    let trained = train_flow(&robot.chain, &data, &cfg, &device).unwrap();
    let targets = &data.positions[data.test()];
    // The likelihood loss of the test pairs fell from the untrained (identity) flow's.
    let nll = |flow: &FlowIk| {
        let x: Vec<f32> = data
            .joint_rows(&data.joints[data.test()])
            .into_iter()
            .map(|u| 2.0 * u - 1.0)
            .collect();
        let mut c = Vec::new();
        for p in data.position_rows(targets).chunks(3) {
            c.extend([p[0], p[1], p[2], 0.0]);
        }
        let n = targets.len();
        flow.nll(
            Tensor::from_data(TensorData::new(x, [n, 6]), &device),
            Tensor::from_data(TensorData::new(c, [n, 4]), &device),
        )
        .into_scalar::<f32>()
    };
    let before = nll(&FlowIk::new(&cfg, 6, &device, cfg.fit.seed).unwrap());
    let after = nll(&trained.model);
    assert!(after < before - 1.0, "NLL {before} -> {after}");
    // Seeded sampling repeats; another seed gives other answers.
    let draw = |seed| {
        let draws = Draws {
            k: 4,
            batch: 512,
            seed,
        };
        sample(&trained.model, &data, targets, draws, &device)
    };
    let (a, b, other) = (draw(9), draw(9), draw(10));
    assert_eq!(a, b);
    assert_ne!(a, other);
    // The answers differ from each other, and the best of 4 beats one sample, which beats an
    // input-blind answer (the training joints in order).
    assert!(diversity(&a) > 0.1, "diversity {}", diversity(&a));
    let cm = |q: &[Vec<f64>]| {
        DistanceErrors::from_metres(&reach_errors(&robot.chain, targets, q)).mean_cm
    };
    let one = cm(&a[0]);
    let best = cm(&best_of(&robot.chain, targets, &a));
    let blind = cm(&data.joints[..targets.len()]);
    eprintln!("flow: one sample {one:.2} cm, best of 4 {best:.2} cm, input-blind {blind:.2} cm");
    assert!(best < one && one < 0.6 * blind);
}
