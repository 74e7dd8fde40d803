//! Training to convergence (the validation split, early stopping, best weights) and the
//! wrapped joint output of the learned inverse-kinematics methods.

mod common;

use nalgebra::Point3;
use selfmodel::core::device::{DeviceChoice, select};
use selfmodel::ik::data::{IkData, IkDataConfig, JointOutput};
use selfmodel::ik::learning::{FitConfig, predict, validation_cm};
use selfmodel::ik::mlp::InverseModelConfig;
use selfmodel::ik::paper::direct_regression::drl;
use selfmodel::train::convergence::{Convergence, Plateau};

#[test]
fn the_validation_split_is_carved_from_the_training_samples_and_leaves_the_test_set_alone() {
    let robot = selfmodel::sim::dh_robot::ur5([-1.0, 1.0]);
    let cfg = IkDataConfig {
        samples: 1_000,
        train: 700,
        range_deg: 90.0,
        seed: 4,
        validation: 100,
    };
    let with = IkData::generate(&robot.chain, &cfg).unwrap();
    let without = IkData::generate(
        &robot.chain,
        &IkDataConfig {
            validation: 0,
            ..cfg.clone()
        },
    )
    .unwrap();
    assert_eq!(
        (with.train(), with.validation(), with.test()),
        (0..600, 600..700, 700..1000)
    );
    assert_eq!(without.validation(), 700..700);
    // The same samples, the same test targets and normalisation either way.
    assert_eq!(with.positions, without.positions);
    assert_eq!(with.position_bounds, without.position_bounds);
    assert!(
        IkData::generate(
            &robot.chain,
            &IkDataConfig {
                validation: 700,
                ..cfg
            }
        )
        .is_err()
    );
}

/// A plateau rule fed `scores`: per score (new best, stop, rate scale), and the best.
fn follow(
    patience: usize,
    min_improvement: f64,
    min_epochs: usize,
    scores: &[f64],
) -> (Vec<bool>, Vec<bool>, Vec<f64>, f64) {
    let mut rule = Plateau::new(&Convergence {
        max_epochs: 100,
        patience,
        lr_patience: 2,
        lr_factor: 0.5,
        min_improvement,
        min_epochs,
    });
    let (mut best, mut stop, mut scale) = (Vec::new(), Vec::new(), Vec::new());
    for &s in scores {
        let (b, st) = rule.observe(s);
        best.push(b);
        stop.push(st);
        scale.push(rule.scale);
    }
    (best, stop, scale, rule.best())
}

#[test]
fn the_plateau_rule_halves_the_rate_then_stops() {
    // Improves twice, then a gain below 1% (not a new best), then nothing: the rate halves
    // after 2 epochs without a new best and again 2 later; the run stops at the 5th.
    let (best, stop, scale, kept) = follow(5, 0.01, 0, &[10.0, 9.0, 8.95, 9.5, 9.2, 9.1, 9.3]);
    assert_eq!(best, [true, true, false, false, false, false, false]);
    assert_eq!(stop, [false, false, false, false, false, false, true]);
    assert_eq!(scale, [1.0, 1.0, 1.0, 0.5, 0.5, 0.25, 0.25]);
    assert_eq!(kept, 9.0);
}

#[test]
fn a_warm_up_holds_the_plateau_rule_off_then_it_counts_from_there() {
    // A best at the first score, then swings above it: during the 4 warm-up scores nothing
    // is cut or stopped; after them the counts start from zero (cut after 2, stop after 3).
    let scores = [10.0, 30.0, 12.0, 40.0, 11.0, 20.0, 15.0];
    let (_, stop, scale, kept) = follow(3, 0.0, 4, &scores);
    assert_eq!(stop, [false, false, false, false, false, false, true]);
    assert_eq!(scale, [1.0, 1.0, 1.0, 1.0, 1.0, 0.5, 0.5]);
    assert_eq!(kept, 10.0);
    // Without the warm-up the same scores stop the run at the 4th.
    let (_, stop, _, _) = follow(3, 0.0, 0, &scores);
    assert_eq!(stop[..4], [false, false, false, true]);
}

#[test]
fn a_tiny_run_to_convergence_stops_on_a_plateau_and_keeps_its_best_weights() {
    let r = 90f64.to_radians();
    let robot = selfmodel::sim::dh_robot::ur5([-r, r]);
    let data = IkData::generate(
        &robot.chain,
        &IkDataConfig {
            samples: 2_400,
            train: 2_000,
            range_deg: 90.0,
            seed: 5,
            validation: 400,
        },
    )
    .unwrap();
    let device = select(DeviceChoice::Cpu).unwrap();
    // A high learning rate on a small set: the validation error rises and wanders after its
    // best, so the rule has a plateau to find.
    let fit = FitConfig {
        batch: 64,
        learning_rate: 3e-3,
        converge: Some(Convergence {
            max_epochs: 200,
            patience: 4,
            lr_patience: 2,
            lr_factor: 0.5,
            min_improvement: 1e-3,
            min_epochs: 0,
        }),
        ..FitConfig::paper()
    };
    let model_cfg = InverseModelConfig::inverse(vec![64, 64], 6, JointOutput::Sigmoid);
    let (model, log) = drl(&robot.chain, &data, &model_cfg, &fit, &device).unwrap();
    let log = log.expect("trained to convergence");
    assert!(log.stopped_on_plateau, "{}", log.summary());
    assert!(
        log.epochs < 200 && log.best_epoch + 4 == log.epochs,
        "{}",
        log.summary()
    );
    assert_eq!(log.curve.len(), log.epochs);
    // The kept model is the best epoch's, not the last one's.
    let best = log
        .curve
        .iter()
        .map(|p| p.validation)
        .fold(f64::INFINITY, f64::min);
    let last = log.curve.last().unwrap().validation;
    assert!(best < last, "the last epoch was the best: nothing to keep");
    let kept = validation_cm(&model, &robot.chain, &data, 512, &device);
    assert!(
        (kept - best).abs() < 1e-6 * best.max(1.0),
        "kept {kept}, best {best}"
    );
    // The learning rate was reduced on the way.
    assert!(log.curve.last().unwrap().learning_rate < fit.learning_rate);
}

/// Wrapped difference of two angles (rad).
fn angle_gap(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(std::f64::consts::TAU);
    d.min(std::f64::consts::TAU - d)
}

#[test]
fn the_wrapped_code_round_trips_and_puts_plus_and_minus_179_degrees_side_by_side() {
    let robot = selfmodel::sim::dh_robot::ur5([-4.0, 4.0]);
    let data = IkData::generate(
        &robot.chain,
        &IkDataConfig {
            samples: 10,
            train: 5,
            range_deg: 180.0,
            seed: 0,
            validation: 0,
        },
    )
    .unwrap();
    let q = [
        179f64.to_radians(),
        -179f64.to_radians(),
        0.5,
        -2.0,
        3.0,
        -3.1,
    ];
    let back = data.decode_joints(
        &data.encode_joints(&q, JointOutput::Wrapped),
        JointOutput::Wrapped,
    );
    assert!(
        back.iter().zip(&q).all(|(a, b)| angle_gap(*a, *b) < 1e-6),
        "{back:?}"
    );
    let code = |deg: f64, out| data.encode_joints(&[f64::to_radians(deg)], out);
    let gap = |a: Vec<f32>, b: Vec<f32>| {
        a.iter()
            .zip(&b)
            .map(|(x, y)| (x - y).powi(2))
            .sum::<f32>()
            .sqrt()
    };
    assert!(
        gap(
            code(179.0, JointOutput::Wrapped),
            code(-179.0, JointOutput::Wrapped)
        ) < 0.04
    );
    assert!(
        gap(
            code(179.0, JointOutput::Sigmoid),
            code(-179.0, JointOutput::Sigmoid)
        ) > 0.98
    );
}

#[test]
fn a_wrapped_model_answers_targets_at_plus_and_minus_179_degrees_with_nearby_joints() {
    // Only the base joint moves, over the whole circle: each target has one answer, and the
    // targets at +179 and -179 degrees are 2 degrees of base rotation apart.
    let robot = selfmodel::sim::dh_robot::ur5([-4.0, 4.0]);
    let rest = [-0.6, 1.1, -0.4, 0.7, 0.2];
    let arm = |q1: f64| {
        let mut q = vec![q1];
        q.extend(rest);
        q
    };
    let n = 3_000;
    let joints: Vec<Vec<f64>> = (0..n)
        .map(|i| {
            arm(-std::f64::consts::PI + std::f64::consts::TAU * ((i * 7919) % n) as f64 / n as f64)
        })
        .collect();
    let template = IkData::generate(
        &robot.chain,
        &IkDataConfig {
            samples: n,
            train: n - 500,
            range_deg: 180.0,
            seed: 0,
            validation: 0,
        },
    )
    .unwrap();
    let data = IkData {
        positions: robot.chain.end_effector_batch(&joints),
        joints,
        ..template
    };
    let data = IkData {
        position_bounds: {
            let mut lo = [f64::INFINITY; 3];
            let mut hi = [f64::NEG_INFINITY; 3];
            for p in &data.positions {
                for k in 0..3 {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                }
            }
            [lo, hi]
        },
        ..data
    };
    let device = select(DeviceChoice::Cpu).unwrap();
    let fit = FitConfig {
        epochs: 30,
        batch: 64,
        learning_rate: 2e-3,
        ..FitConfig::paper()
    };
    let seam: Vec<Point3<f64>> = robot
        .chain
        .end_effector_batch(&[arm(179f64.to_radians()), arm(-179f64.to_radians())]);
    let answer = |output| {
        let (model, _) = drl(
            &robot.chain,
            &data,
            &InverseModelConfig::inverse(vec![64, 64], 6, output),
            &fit,
            &device,
        )
        .unwrap();
        let q = predict(&model, &data, &seam, 8, &device);
        (q[0][0], q[1][0])
    };
    let (plus, minus) = answer(JointOutput::Wrapped);
    eprintln!(
        "wrapped: {:.1} and {:.1} deg",
        plus.to_degrees(),
        minus.to_degrees()
    );
    assert!(angle_gap(plus, minus) < 8f64.to_radians(), "{plus} {minus}");
    assert!(
        angle_gap(plus, 179f64.to_radians()) < 6f64.to_radians(),
        "{plus}"
    );
    assert!(
        angle_gap(minus, -179f64.to_radians()) < 6f64.to_radians(),
        "{minus}"
    );
    // The sigmoid cannot put them side by side: its answers at the seam are far from one end.
    let (plus_s, minus_s) = answer(JointOutput::Sigmoid);
    eprintln!(
        "sigmoid: {:.1} and {:.1} deg",
        plus_s.to_degrees(),
        minus_s.to_degrees()
    );
    let wrapped_err = angle_gap(plus, 179f64.to_radians()) + angle_gap(minus, -179f64.to_radians());
    let sigmoid_err =
        angle_gap(plus_s, 179f64.to_radians()) + angle_gap(minus_s, -179f64.to_radians());
    assert!(
        sigmoid_err > 2.0 * wrapped_err,
        "sigmoid {sigmoid_err} against wrapped {wrapped_err}"
    );
}

#[test]
fn an_emssl_run_stopped_early_and_continued_from_its_checkpoint_gives_the_uninterrupted_run() {
    use selfmodel::ik::paper::emssl::{EmsslConfig, LrPlateau, emssl};
    let (robot, data) = tiny_ur5(6);
    let device = select(DeviceChoice::Cpu).unwrap();
    let model = InverseModelConfig::inverse(vec![64, 32], 6, JointOutput::Sigmoid);
    // A high learning rate makes the selection error wander, so the plateau rule acts.
    let fit = FitConfig {
        epochs: 2,
        batch: 64,
        learning_rate: 4e-2,
        ..FitConfig::paper()
    };
    let cfg = EmsslConfig {
        max_iterations: 8,
        patience: 100,
        learning_rate_decay: 1.0,
        lr_plateau: Some(LrPlateau {
            patience: 1,
            factor: 0.5,
        }),
        warm_start_epochs: 2,
        ..EmsslConfig::paper()
    };
    let (whole, whole_curve) =
        emssl(&robot.chain, &data, &model, &fit, &cfg, &device, None).unwrap();
    let tmp = common::tempdir();
    let dir = tmp.path().to_path_buf();
    let cut = EmsslConfig {
        max_iterations: 3,
        ..cfg.clone()
    };
    let (_, first) = emssl(&robot.chain, &data, &model, &fit, &cut, &device, Some(&dir)).unwrap();
    assert_eq!(first.len(), 3);
    let (resumed, curve) =
        emssl(&robot.chain, &data, &model, &fit, &cfg, &device, Some(&dir)).unwrap();
    let key = |c: &[selfmodel::ik::paper::emssl::EmsslIteration]| {
        c.iter()
            .map(|i| {
                (
                    i.iteration,
                    i.learning_rate,
                    i.test.mean_cm,
                    i.selection_cm(),
                )
            })
            .collect::<Vec<_>>()
    };
    assert_eq!(key(&curve), key(&whole_curve));
    let answers = |m| predict(m, &data, &data.positions[data.test()], 256, &device);
    assert_eq!(answers(&resumed), answers(&whole));
    // The plateau rule halved the rate on the way, so its state was carried too.
    assert!(curve.iter().any(|c| c.learning_rate < fit.learning_rate));
}

#[test]
fn emssl_polishing_keeps_a_round_only_when_it_lowers_the_validation_reach_error() {
    use selfmodel::ik::learning::validation_cm;
    use selfmodel::ik::paper::emssl::{EmsslConfig, emssl};
    let (robot, data) = tiny_ur5(7);
    let device = select(DeviceChoice::Cpu).unwrap();
    let model = InverseModelConfig::inverse(vec![64, 32], 6, JointOutput::Sigmoid);
    let fit = FitConfig {
        epochs: 2,
        batch: 64,
        ..FitConfig::paper()
    };
    let cfg = EmsslConfig {
        max_iterations: 4,
        patience: 100,
        polish_rounds: 2,
        ..EmsslConfig::paper()
    };
    let tmp = common::tempdir();
    let dir = tmp.path().to_path_buf();
    let (polished, curve) =
        emssl(&robot.chain, &data, &model, &fit, &cfg, &device, Some(&dir)).unwrap();
    let rounds: Vec<_> = curve.iter().filter(|c| c.iteration > 4).collect();
    assert!(!rounds.is_empty() && rounds.len() <= 2);
    assert!(rounds.iter().all(|c| c.exploration == 0.0));
    // The model returned is the one of the lowest selection error over iterations and rounds.
    let lowest = curve
        .iter()
        .map(|c| c.selection_cm())
        .fold(f64::INFINITY, f64::min);
    let got = validation_cm(&polished, &robot.chain, &data, 256, &device);
    assert!(
        (got - lowest).abs() < 1e-6 * lowest.max(1.0),
        "returned model {got} cm, lowest on the curve {lowest} cm"
    );
    // A finished checkpoint is polished again without rerunning the iterations.
    let (_, again) = emssl(&robot.chain, &data, &model, &fit, &cfg, &device, Some(&dir)).unwrap();
    assert_eq!(again.len(), curve.len());
}

/// The UR5 in +-90 degrees and 2,000 samples of it (1,500 to train, 300 of them to validate).
fn tiny_ur5(seed: u64) -> (selfmodel::sim::robot::Robot, IkData) {
    let r = 90f64.to_radians();
    let robot = selfmodel::sim::dh_robot::ur5([-r, r]);
    let data = IkData::generate(
        &robot.chain,
        &IkDataConfig {
            samples: 2_000,
            train: 1_500,
            range_deg: 90.0,
            seed,
            validation: 300,
        },
    )
    .unwrap();
    (robot, data)
}

/// A run to convergence killed mid-way (here: a loss that turns NaN in its 12th epoch, after the rate was halved, which
/// stops the run with the last epoch's checkpoint kept) and started again continues from its
/// checkpoint to the uninterrupted run's curve, best epoch and weights.
#[test]
fn a_run_to_convergence_killed_and_continued_from_its_checkpoint_gives_the_uninterrupted_run() {
    use selfmodel::ik::learning::{fit_converged, joint_set, mse};
    use selfmodel::train::{batcher::Batch, convergence::FitCheckpoint, trainer::autodiff_device};
    let (robot, data) = tiny_ur5(8);
    let device = select(DeviceChoice::Cpu).unwrap();
    let conv = Convergence {
        max_epochs: 60,
        patience: 3,
        lr_patience: 1,
        lr_factor: 0.5,
        min_improvement: 1e-3,
        min_epochs: 0,
    };
    let fit = FitConfig {
        batch: 64,
        learning_rate: 1e-2,
        ..FitConfig::paper()
    };
    let model_cfg = InverseModelConfig::inverse(vec![32, 32], 6, JointOutput::Sigmoid);
    let run = |fit: &FitConfig, kill_at: Option<usize>| {
        let tdev = autodiff_device(&device, fit.seed);
        let model = model_cfg.init(&tdev, fit.seed).unwrap();
        let train = data.train();
        let set = joint_set(
            &data,
            &data.positions[train.clone()],
            &data.joints[train],
            JointOutput::Sigmoid,
            &tdev,
        );
        let loss = |m: &selfmodel::ik::mlp::Mlp, b: &Batch| {
            let l = mse(m, b);
            if Some(b.step) == kill_at {
                l.mul_scalar(f32::NAN)
            } else {
                l
            }
        };
        fit_converged(model, &set, fit, &conv, "DRL", loss, |m| {
            validation_cm(m, &robot.chain, &data, 512, &device)
        })
    };
    let (whole, whole_log) = run(&fit, None).unwrap();
    assert!(
        whole_log.stopped_on_plateau && whole_log.epochs > 12,
        "{}",
        whole_log.summary()
    );
    assert!(
        whole_log
            .curve
            .iter()
            .any(|p| p.learning_rate < fit.learning_rate)
    );
    let tmp = common::tempdir();
    let dir = tmp.path().to_path_buf();
    let kept = FitConfig {
        checkpoint: Some(FitCheckpoint {
            dir: dir.clone(),
            settings: serde_json::json!("test"),
        }),
        ..fit.clone()
    };
    let steps_per_epoch = data.train().len().div_ceil(64);
    let killed = run(&kept, Some(11 * steps_per_epoch + 2));
    assert!(killed.is_err(), "the NaN loss must stop the run");
    let (resumed, log) = run(&kept, None).unwrap();
    let key = |l: &selfmodel::train::convergence::ConvergenceLog| {
        l.curve
            .iter()
            .map(|p| (p.epoch, p.learning_rate, p.validation))
            .collect::<Vec<_>>()
    };
    assert_eq!(key(&log), key(&whole_log));
    assert_eq!(log.best_epoch, whole_log.best_epoch);
    let answers = |m: &selfmodel::ik::mlp::Mlp| {
        predict(
            &burn::module::Module::valid(m),
            &data,
            &data.positions[data.test()],
            256,
            &device,
        )
    };
    assert_eq!(answers(&resumed), answers(&whole));
    // Only the best epoch's weights are left beside the checkpoint.
    let best_files: Vec<_> = std::fs::read_dir(dir.join("drl"))
        .unwrap()
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| n.starts_with("best-"))
        .collect();
    assert_eq!(best_files, [format!("best-{}.bpk", log.best_epoch)]);
    // A checkpoint made with other settings is not continued: the run starts afresh.
    let other = FitConfig {
        checkpoint: Some(FitCheckpoint {
            dir: dir.clone(),
            settings: serde_json::json!("other"),
        }),
        ..fit.clone()
    };
    let (_, fresh) = run(&other, None).unwrap();
    assert_eq!(key(&fresh), key(&whole_log));
}

/// The GAN's own loop keeps a checkpoint every epoch: a run stopped at a cap of 4 epochs and
/// continued with the full cap gives the uninterrupted run's curve and generator, and a
/// finished run asked again loads its best generator without training.
#[test]
fn a_gan_run_continued_from_its_checkpoint_gives_the_uninterrupted_run() {
    use selfmodel::ik::paper::cgan::{GanConfig, train_gan};
    use selfmodel::train::convergence::FitCheckpoint;
    let (robot, data) = tiny_ur5(9);
    let device = select(DeviceChoice::Cpu).unwrap();
    let gan = |max_epochs: usize, checkpoint: Option<std::path::PathBuf>| GanConfig {
        noise: 2,
        generator_hidden: vec![32, 32],
        discriminator_hidden: vec![32, 32],
        fit: FitConfig {
            batch: 64,
            learning_rate: 2e-3,
            converge: Some(Convergence {
                max_epochs,
                patience: 3,
                lr_patience: 1,
                lr_factor: 0.5,
                min_improvement: 1e-3,
                min_epochs: 0,
            }),
            checkpoint: checkpoint.map(|dir| FitCheckpoint {
                dir,
                settings: serde_json::json!("test"),
            }),
            ..FitConfig::paper()
        },
        best_of: 2,
    };
    let run = |cfg: &GanConfig| {
        train_gan(&robot.chain, &data, cfg, JointOutput::Sigmoid, &device).unwrap()
    };
    let (whole, whole_log) = run(&gan(12, None));
    let whole_log = whole_log.unwrap();
    assert!(whole_log.epochs > 4, "{}", whole_log.summary());
    let tmp = common::tempdir();
    let dir = tmp.path().to_path_buf();
    let (_, cut) = run(&gan(4, Some(dir.clone())));
    assert_eq!(cut.unwrap().epochs, 4);
    let (resumed, log) = run(&gan(12, Some(dir.clone())));
    let log = log.unwrap();
    let key = |l: &selfmodel::train::convergence::ConvergenceLog| {
        l.curve
            .iter()
            .map(|p| (p.epoch, p.learning_rate, p.validation, p.train_loss))
            .collect::<Vec<_>>()
    };
    assert_eq!(key(&log), key(&whole_log));
    let targets = &data.positions[data.test()];
    let answers =
        |g: &selfmodel::ik::paper::cgan::Generator| g.sample(&data, targets, 256, 7, &device);
    assert_eq!(answers(&resumed), answers(&whole));
    // Finished: asked again, it trains nothing and answers the same.
    let t = std::time::Instant::now();
    let (again, _) = run(&gan(12, Some(dir.clone())));
    assert_eq!(answers(&again), answers(&whole));
    assert!(t.elapsed().as_secs_f64() < 5.0);
}
