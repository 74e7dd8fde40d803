//! EMSSL's sampling acceleration (Table III) and fast adaptation (Table IV): the strategies
//! give the same samples, the latency is real, the link parameters of a changed arm are
//! learned, and adaptation recovers most of the error the change caused.

mod common;

use std::time::Instant;

use burn::tensor::{Tensor, TensorData};
use selfmodel::core::device::{DeviceChoice, select};
use selfmodel::core::preset::Preset;
use selfmodel::ik::data::{IkData, IkDataConfig, distances};
use selfmodel::ik::mlp::InverseModelConfig;
use selfmodel::ik::paper::calibration::{CalibrationConfig, calibrate};
use selfmodel::ik::paper::sampling_pass::{ForwardModel, Latency, Workers, sampling_pass};
use selfmodel::sim::arm_change::ArmChange;
use selfmodel::sim::tensor_kinematics::TensorChain;
use selfmodel_lab::studies::emssl::adaptation::{AdaptationConfig, adapt_robot};

fn ur5() -> selfmodel::sim::robot::Robot {
    selfmodel::sim::dh_robot::ur5([-1.6, 1.6])
}

#[test]
fn every_sampling_strategy_gives_the_same_samples() {
    let device = select(DeviceChoice::Cpu).unwrap();
    let robot = ur5();
    let data = IkData::generate(&robot.chain, &IkDataConfig::quick(90.0)).unwrap();
    let model = InverseModelConfig::quick(6).init(&device, 4).unwrap();
    let desired = &data.positions[..300];
    let forward = ForwardModel {
        chain: &robot.chain,
        latency: Latency::None,
    };
    let pass = |batch: usize, threads: usize| {
        sampling_pass(
            &model,
            &data,
            desired,
            batch,
            &forward,
            &Workers::new(threads).unwrap(),
            &device,
        )
        .unwrap()
    };
    let reference = pass(1, 1);
    // The forward half is the arm's kinematics of the answers.
    let direct = robot.chain.end_effector_batch(&reference.joints);
    assert!(
        distances(&direct, &reference.reached)
            .iter()
            .all(|&d| d == 0.0)
    );
    for (batch, threads) in [(64, 1), (1, 3), (128, 2), (300, 4)] {
        let other = pass(batch, threads);
        let worst = reference
            .joints
            .iter()
            .flatten()
            .zip(other.joints.iter().flatten())
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        // Batched matrix products may sum in another order: f32 rounding only.
        assert!(
            worst < 1e-5,
            "batch {batch}, threads {threads}: {worst} rad"
        );
        assert!(
            distances(
                &other.reached,
                &robot.chain.end_effector_batch(&other.joints)
            )
            .iter()
            .all(|&d| d == 0.0)
        );
    }
    assert!(Workers::new(0).is_err());
}

#[test]
fn a_forward_model_latency_costs_time_and_waiting_workers_overlap() {
    let robot = ur5();
    let joints = vec![vec![0.1; 6]; 24];
    let forward = ForwardModel {
        chain: &robot.chain,
        // Long enough that waking threads on a busy machine is small beside it.
        latency: Latency::Sleep { us: 5_000 },
    };
    let time = |threads: usize| {
        let workers = Workers::new(threads).unwrap();
        let t = Instant::now();
        let reached = forward.reach_all(&joints, &workers);
        assert_eq!(reached.len(), joints.len());
        t.elapsed().as_secs_f64()
    };
    let one = time(1);
    let six = time(6);
    assert!(one >= 24.0 * 5e-3, "one worker: {one} s");
    // Sleeping workers need no core: six overlap even on a two-core machine.
    assert!(six < one / 2.0, "six workers {six} s against one {one} s");
    let spin = ForwardModel {
        chain: &robot.chain,
        latency: Latency::Spin { us: 1_000 },
    };
    let t = Instant::now();
    spin.reach_all(&joints, &Workers::new(1).unwrap());
    assert!(t.elapsed().as_secs_f64() >= 24.0 * 1e-3);
}

#[test]
fn the_inverse_models_flop_count_is_its_matrix_products() {
    // 2 x (3*1024 + 1024*512 + 512*256 + 256*128 + 128*6) for the paper's network.
    assert_eq!(InverseModelConfig::paper(6).flop_per_row(), 1_383_936.0);
}

#[test]
fn tensor_kinematics_with_origin_tensors_matches_the_chain() {
    let device = select(DeviceChoice::Cpu).unwrap();
    for chain in [ur5().chain, selfmodel::sim::arm4::chain()] {
        let tensor_chain = TensorChain::new(&chain);
        let (r, t, tip) = tensor_chain.origin_rows();
        let n = tensor_chain.joint_count();
        let qs: Vec<Vec<f64>> = (0..7)
            .map(|i| {
                (0..chain.dof())
                    .map(|k| ((i * 3 + k * 5) % 11) as f64 * 0.3 - 1.5)
                    .collect()
            })
            .collect();
        let q = Tensor::<2>::from_data(
            TensorData::new(
                qs.iter().flatten().map(|&v| v as f32).collect(),
                [qs.len(), chain.dof()],
            ),
            &device,
        );
        let ours = tensor_chain
            .end_effector_with(
                q,
                Tensor::from_data(TensorData::new(r, [n, 3, 3]), &device),
                Tensor::from_data(TensorData::new(t, [n, 3]), &device),
                Tensor::from_data(TensorData::new(tip.to_vec(), [1, 3]), &device),
            )
            .into_data()
            .try_into_vec::<f32>()
            .unwrap();
        for (i, q) in qs.iter().enumerate() {
            let p = chain.end_effector(q);
            for k in 0..3 {
                assert!((ours[3 * i + k] as f64 - p[k]).abs() < 1e-5, "pose {i}");
            }
        }
    }
}

#[test]
fn the_link_parameters_of_a_changed_arm_are_learned_from_a_small_sample() {
    let device = select(DeviceChoice::Cpu).unwrap();
    let robot = ur5();
    let data = IkData::generate(&robot.chain, &IkDataConfig::quick(90.0)).unwrap();
    for change in [
        ArmChange::Lengthen { cm: 3.0 },
        ArmChange::Bend { joint: 2, deg: 3.0 },
    ] {
        let changed = change.apply(&robot.chain).unwrap();
        let sample = &data.joints[..40];
        let cfg = CalibrationConfig {
            samples: 40,
            stages: vec![(300, 3e-3), (200, 3e-4)],
            seed: 0,
        };
        let (learned, fit) = calibrate(
            &robot.chain,
            sample,
            &changed.end_effector_batch(sample),
            &cfg,
            &device,
        )
        .unwrap();
        // Judged on joints it never saw.
        let unseen = &data.joints[1000..1500];
        let mm = |chain: &selfmodel::sim::kinematics::KinematicChain| {
            1e3 * distances(
                &chain.end_effector_batch(unseen),
                &changed.end_effector_batch(unseen),
            )
            .iter()
            .sum::<f64>()
                / unseen.len() as f64
        };
        let (nominal, after) = (mm(&robot.chain), mm(&learned));
        eprintln!(
            "{}: nominal {nominal:.2} mm, learned {after:.3} mm (fit {:.2} -> {:.3} mm)",
            change.label(),
            fit.fit_before_mm,
            fit.fit_after_mm
        );
        assert!(nominal > 20.0, "{nominal}");
        assert!(after < 1.0, "{after}");
    }
}

#[test]
fn adaptation_recovers_most_of_the_error_a_longer_arm_causes() {
    let cfg = AdaptationConfig {
        changes: vec![ArmChange::Lengthen { cm: 3.0 }],
        ..AdaptationConfig::quick()
    };
    let tmp = common::tempdir();
    let dir = tmp.path().to_path_buf();
    let (rows, curve) = adapt_robot(&cfg, &ur5(), &dir, DeviceChoice::Cpu).unwrap();
    assert_eq!(rows.len(), 2);
    for r in &rows {
        eprintln!(
            "{}: unchanged {:.2}, before {:.2}, after {:.2} cm, {} iterations, {} arm samples",
            r.approach, r.unchanged_cm, r.before_cm, r.after_cm, r.iterations_run, r.arm_samples
        );
        assert!(r.before_cm > 1.5 * r.unchanged_cm, "the change must hurt");
        assert!(r.after_cm < 0.7 * r.before_cm, "adaptation must recover");
    }
    // Approach 1 touches the changed arm only for its sample; approach 2 at every call.
    assert_eq!(rows[0].arm_samples, cfg.calibration.samples);
    assert_eq!(
        rows[1].arm_samples,
        2 * (cfg.base.train - cfg.base.validation) * rows[1].iterations_run
    );
    assert!(curve.iter().any(|c| c.iteration == 0));
}
