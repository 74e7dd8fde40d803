//! Learned inverse kinematics: data, normalisation and error statistics.

mod common;

use selfmodel::ik::data::{DistanceErrors, IkData, IkDataConfig, reach_errors};

#[test]
fn ik_data_is_seeded_split_and_normalised_both_ways() {
    let robot = selfmodel::sim::dh_robot::ur5([-1.0, 1.0]);
    let cfg = IkDataConfig {
        samples: 500,
        train: 350,
        range_deg: 90.0,
        seed: 3,
        validation: 0,
    };
    let a = IkData::generate(&robot.chain, &cfg).unwrap();
    let b = IkData::generate(&robot.chain, &cfg).unwrap();
    assert_eq!(a.joints, b.joints);
    assert_eq!((a.train().len(), a.test().len()), (350, 150));
    let r = 90f64.to_radians();
    assert!(a.joints.iter().flatten().all(|&q| (-r..=r).contains(&q)));
    // Normalised training positions lie in [0, 1]; joints round-trip.
    for (q, p) in a.joints.iter().zip(&a.positions).take(350) {
        assert!(
            a.normalise_position(p)
                .iter()
                .all(|&v| (-1e-6..=1.0 + 1e-6).contains(&v))
        );
        let back = a.joints_from_normalised(&a.normalise_joints(q));
        assert!(back.iter().zip(q).all(|(x, y)| (x - y).abs() < 1e-5));
    }
    // The data's own joints reach their positions exactly.
    let e = reach_errors(&robot.chain, &a.positions, &a.joints);
    assert!(e.iter().all(|&v| v < 1e-12));
    assert!(IkData::generate(&robot.chain, &IkDataConfig { train: 500, ..cfg }).is_err());
}

#[test]
fn distance_error_statistics_are_in_centimetres() {
    let e = DistanceErrors::from_metres(&[0.01, 0.02, 0.03, 0.04, 0.10]);
    assert!((e.mean_cm - 4.0).abs() < 1e-9);
    assert!((e.median_cm - 3.0).abs() < 1e-9);
    assert!((e.max_cm - 10.0).abs() < 1e-9);
    // 10 cm is not above 10 cm; 10.5 is.
    assert_eq!(e.above_10cm_pct, 0.0);
    let tail = DistanceErrors::from_metres(&[0.01, 0.105, 0.30, 0.02]);
    assert!((tail.above_10cm_pct - 50.0).abs() < 1e-9);
    assert_eq!(e.targets, 5);
}

use selfmodel::core::device::{DeviceChoice, select};
use selfmodel::ik::flow::Draws;
use selfmodel::ik::learning::{FitConfig, test_errors};
use selfmodel::ik::mlp::InverseModelConfig;
use selfmodel::ik::paper::cgan::{GanConfig, train_gan};
use selfmodel::ik::paper::distal_learning::{DistalConfig, dsl};
use selfmodel::ik::paper::{
    direct_regression::drl,
    emssl::{EmsslConfig, emssl},
};
use selfmodel::ik::solve::damped_least_squares::{DlsConfig, solve, solve_batch};

fn ur5_data(samples: usize, range_deg: f64) -> (selfmodel::sim::robot::Robot, IkData) {
    let r = range_deg.to_radians();
    let robot = selfmodel::sim::dh_robot::ur5([-r, r]);
    let cfg = IkDataConfig {
        samples,
        train: samples * 4 / 5,
        range_deg,
        seed: 1,
        validation: 0,
    };
    let data = IkData::generate(&robot.chain, &cfg).unwrap();
    (robot, data)
}

/// Mean error (cm) of answering every test target with the training set's joint vectors in
/// order: what an inverse model that ignores its input scores.
fn ignorant_cm(robot: &selfmodel::sim::robot::Robot, data: &IkData) -> f64 {
    let targets = &data.positions[data.test()];
    let joints = &data.joints[..targets.len()];
    DistanceErrors::from_metres(&reach_errors(&robot.chain, targets, joints)).mean_cm
}

#[test]
fn the_analytic_position_jacobian_matches_finite_differences() {
    for robot in [
        selfmodel::sim::dh_robot::ur5([-3.0, 3.0]),
        selfmodel::sim::arm4::arm4(),
    ] {
        let chain = &robot.chain;
        for i in 0..5 {
            let q: Vec<f64> = (0..chain.dof())
                .map(|k| ((i * 7 + k * 3) % 11) as f64 * 0.23 - 1.1)
                .collect();
            let jac = chain.position_jacobian(&q);
            let h = 1e-6;
            for k in 0..chain.dof() {
                let (mut a, mut b) = (q.clone(), q.clone());
                a[k] += h;
                b[k] -= h;
                let fd = (chain.end_effector(&a) - chain.end_effector(&b)) / (2.0 * h);
                assert!(
                    (jac.column(k) - fd).norm() < 1e-7,
                    "{} pose {i} joint {k}",
                    robot.name
                );
            }
        }
    }
}

#[test]
fn damped_least_squares_reaches_reachable_targets_and_respects_the_range() {
    let (robot, data) = ur5_data(300, 90.0);
    let targets = &data.positions[data.test()];
    let cfg = DlsConfig::standard();
    let ranges = data.ranges.clone();
    let home = vec![vec![0.0; 6]; targets.len()];
    let from_home = solve_batch(&robot.chain, targets, &home, &ranges, &cfg);
    let converged = from_home
        .iter()
        .filter(|s| s.error_m < cfg.tolerance_m)
        .count();
    assert!(
        converged * 10 >= targets.len() * 7,
        "{converged} of {} converged",
        targets.len()
    );
    for s in &from_home {
        assert!(
            s.joints
                .iter()
                .zip(&data.ranges)
                .all(|(v, r)| (r[0]..=r[1]).contains(v))
        );
        // The reported error is the real one.
        let t = targets[from_home.iter().position(|x| std::ptr::eq(x, s)).unwrap()];
        assert!(((robot.chain.end_effector(&s.joints) - t).norm() - s.error_m).abs() < 1e-12);
    }
    // From a start 0.05 rad away from a solution it converges in a handful of iterations.
    let q = &data.joints[data.n_train];
    let start: Vec<f64> = q.iter().map(|v| v + 0.05).collect();
    let s = solve(&robot.chain, &targets[0], &start, &ranges, &cfg);
    assert!(s.error_m < cfg.tolerance_m && s.iterations <= 8, "{s:?}");
}

#[test]
fn a_tiny_emssl_beats_direct_regression_on_a_redundant_arm() {
    let (robot, data) = ur5_data(5000, 90.0);
    let device = select(DeviceChoice::Cpu).unwrap();
    let model = InverseModelConfig {
        hidden: vec![256, 128],
        ..InverseModelConfig::quick(6)
    };
    let fit = FitConfig {
        epochs: 5,
        batch: 64,
        ..FitConfig::paper()
    };
    let (direct, _) = drl(
        &robot.chain,
        &data,
        &model,
        &FitConfig {
            epochs: 20,
            ..fit.clone()
        },
        &device,
    )
    .unwrap();
    let (drl_err, _) = test_errors(&direct, &robot.chain, &data, 512, &device);
    let rule = EmsslConfig {
        max_iterations: 15,
        patience: 5,
        ..EmsslConfig::paper()
    };
    let (learned, curve) = emssl(&robot.chain, &data, &model, &fit, &rule, &device, None).unwrap();
    let (emssl_err, _) = test_errors(&learned, &robot.chain, &data, 512, &device);
    let ignorant = ignorant_cm(&robot, &data);
    eprintln!(
        "DRL {:.2} cm, EMSSL {:.2} cm after {} iterations, input-blind {ignorant:.2} cm",
        drl_err.mean_cm,
        emssl_err.mean_cm,
        curve.len()
    );
    assert!(drl_err.mean_cm < ignorant);
    assert!(
        emssl_err.mean_cm < 0.8 * drl_err.mean_cm,
        "EMSSL {:.2} cm against DRL {:.2} cm",
        emssl_err.mean_cm,
        drl_err.mean_cm
    );
    // The kept model is the one with the lowest reach error on the training goals, and the
    // curve's reach errors fell from the first iteration.
    let best = curve
        .iter()
        .map(|c| c.train_reach_cm)
        .fold(f64::INFINITY, f64::min);
    assert!(best < 0.5 * curve[0].train_reach_cm, "{curve:?}");
    // Each iteration counts its optimiser steps: 5 epochs of the training goals in batches of 64.
    let per_iteration = 5 * data.train().len().div_ceil(64);
    assert!(curve.iter().all(|c| c.steps == per_iteration), "{curve:?}");
    // Seeded: the same run again gives the same curve.
    let (_, again) = emssl(&robot.chain, &data, &model, &fit, &rule, &device, None).unwrap();
    assert_eq!(
        curve.iter().map(|c| c.test.mean_cm).collect::<Vec<_>>(),
        again.iter().map(|c| c.test.mean_cm).collect::<Vec<_>>()
    );
}

#[test]
fn distal_learning_and_the_conditional_gan_learn_something_of_the_arm() {
    let (robot, data) = ur5_data(4000, 90.0);
    let device = select(DeviceChoice::Cpu).unwrap();
    let ignorant = ignorant_cm(&robot, &data);
    let fit = FitConfig {
        batch: 64,
        ..FitConfig::paper()
    };
    let distal = dsl(
        &robot.chain,
        &data,
        &InverseModelConfig::quick(6),
        &fit,
        &DistalConfig {
            forward_hidden: vec![128, 64],
            forward_epochs: 20,
            inverse_epochs: 10,
            forward: Default::default(),
            inverse_steps: None,
        },
        &device,
    )
    .unwrap();
    // The forward model beats predicting the mean training position.
    let n = data.n_train as f64;
    let mean = data.positions[data.train()]
        .iter()
        .fold(nalgebra::Vector3::zeros(), |a, p| a + p.coords / n);
    let constant = 100.0
        * data.positions[data.test()]
            .iter()
            .map(|p| (p.coords - mean).norm())
            .sum::<f64>()
        / data.test().len() as f64;
    assert!(
        distal.forward_test_cm < 0.5 * constant,
        "forward model {:.2} cm, constant {constant:.2} cm",
        distal.forward_test_cm
    );
    let (e, _) = test_errors(&distal.inverse, &robot.chain, &data, 512, &device);
    assert!(e.mean_cm < 0.5 * ignorant, "DSL {:.2} cm", e.mean_cm);

    let (gan, _) = train_gan(
        &robot.chain,
        &data,
        &GanConfig {
            noise: 3,
            generator_hidden: vec![256, 128],
            discriminator_hidden: vec![256, 128],
            fit: FitConfig {
                epochs: 50,
                batch: 64,
                learning_rate: 1e-3,
                ..FitConfig::paper()
            },
            best_of: 5,
        },
        selfmodel::ik::data::JointOutput::Sigmoid,
        &device,
    )
    .unwrap();
    let targets = &data.positions[data.test()];
    let one = gan.sample(&data, targets, 512, 7, &device);
    let one = DistanceErrors::from_metres(&reach_errors(&robot.chain, targets, &one));
    let best = gan.best_of(
        &robot.chain,
        &data,
        targets,
        Draws {
            k: 5,
            batch: 512,
            seed: 7,
        },
        &device,
    );
    let best = DistanceErrors::from_metres(&reach_errors(&robot.chain, targets, &best));
    eprintln!(
        "CGAN {:.2} cm, best of 5 {:.2} cm, input-blind {ignorant:.2} cm",
        one.mean_cm, best.mean_cm
    );
    assert!(one.mean_cm < 0.6 * ignorant);
    assert!(best.mean_cm < one.mean_cm);
}

#[test]
fn predictions_csv_holds_the_answers_and_where_they_reach() {
    let (robot, data) = ur5_data(50, 90.0);
    let tmp = common::tempdir();
    let dir = tmp.path().to_path_buf();
    let path = dir.join("p.csv");
    let targets = &data.positions[data.test()];
    let joints = &data.joints[..targets.len()];
    let reached = robot.chain.end_effector_batch(joints);
    let names = robot.chain.joint_names();
    selfmodel_lab::studies::emssl::table2::write_predictions(
        &path, targets, joints, &reached, &names,
    )
    .unwrap();
    // The joints read back, whatever their columns are named.
    assert_eq!(
        selfmodel_lab::studies::emssl::table2::read_predictions(&path).unwrap(),
        joints
            .iter()
            .map(|q| q
                .iter()
                .map(|v| format!("{v:.9}").parse().unwrap())
                .collect())
            .collect::<Vec<Vec<f64>>>()
    );
    let mut reader = csv::Reader::from_path(&path).unwrap();
    let header: Vec<String> = reader.headers().unwrap().iter().map(String::from).collect();
    assert_eq!(header.len(), 3 + 6 + 3);
    assert_eq!(header[3..9], names[..]);
    for (i, rec) in reader.records().enumerate() {
        let v: Vec<f64> = rec.unwrap().iter().map(|x| x.parse().unwrap()).collect();
        let reached = robot.chain.end_effector(&v[3..9]);
        for k in 0..3 {
            assert!((v[k] - targets[i][k]).abs() < 1e-8);
            assert!((v[9 + k] - reached[k]).abs() < 1e-6);
        }
    }
}

#[test]
fn restarts_take_the_solver_to_every_reachable_target_where_one_start_stalls() {
    use selfmodel::ik::solve::damped_least_squares::{Restarts, solve_with_restarts};
    let (robot, data) = ur5_data(3_000, 90.0);
    let targets = &data.positions[data.test()];
    let home = vec![vec![0.0; 6]; targets.len()];
    let ranges = data.ranges.clone();
    let cfg = DlsConfig::standard();
    let once = solve_batch(&robot.chain, targets, &home, &ranges, &cfg);
    let stalled = once.iter().filter(|s| s.error_m >= cfg.tolerance_m).count();
    assert!(
        stalled > 0,
        "every target converged from home: the restarts are untested"
    );
    // The "model" offers the true joints of every second stalled target (as a flow's sample
    // would); random starts must do the rest.
    let truth = &data.joints[data.test()];
    let (solved, restarted) = solve_with_restarts(
        &robot.chain,
        targets,
        &home,
        &ranges,
        &cfg,
        &Restarts::standard(),
        |idx| {
            vec![
                idx.iter()
                    .enumerate()
                    .map(|(j, &i)| {
                        if j % 2 == 0 {
                            truth[i].clone()
                        } else {
                            vec![0.0; 6]
                        }
                    })
                    .collect(),
            ]
        },
    );
    assert_eq!(restarted, stalled);
    let left = solved
        .iter()
        .filter(|s| s.error_m >= cfg.tolerance_m)
        .count();
    assert_eq!(
        left, 0,
        "{left} of {stalled} stalled targets still unsolved"
    );
    // Targets that converged the first time keep that answer.
    for (a, b) in once.iter().zip(&solved) {
        if a.error_m < cfg.tolerance_m {
            assert_eq!(a.joints, b.joints);
        }
    }
    // Within the range.
    assert!(solved.iter().all(|s| {
        s.joints
            .iter()
            .zip(&data.ranges)
            .all(|(q, r)| q.abs() <= r[1] + 1e-12)
    }));
}

/// A unit reused by `--resume` keeps the provenance of the run that trained it: its rows and
/// its EMSSL curve carry that run's revision, not the reusing process's.
#[test]
fn reused_units_keep_the_revision_that_trained_them() {
    use selfmodel_lab::studies::emssl::table2::{IkComparisonConfig, run};
    let tmp = common::tempdir();
    let dir = tmp.path().to_path_buf();
    let mut cfg = IkComparisonConfig::named("quick").unwrap();
    cfg.ranges_deg = vec![90.0];
    let robot = selfmodel::sim::dh_robot::ur5([-1.0, 1.0]);
    let device = selfmodel::core::device::DeviceChoice::Cpu;
    let first = run(&cfg, &robot, &dir, device, false).unwrap().rows;
    // Stamp every unit as trained by an earlier revision.
    let units = dir.join("units").join("90");
    for entry in std::fs::read_dir(&units).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "json") {
            let text = std::fs::read_to_string(&path).unwrap();
            let stamped = text.replace(&first[0].git_revision, "earlier-revision");
            std::fs::write(&path, stamped).unwrap();
        }
    }
    let again = run(&cfg, &robot, &dir, device, true).unwrap().rows;
    assert_eq!(again.len(), first.len());
    assert!(again.iter().all(|r| r.git_revision == "earlier-revision"));
    let curve = std::fs::read_to_string(dir.join("emssl_curve.csv")).unwrap();
    let mut lines = curve.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = header.iter().position(|&h| h == "git_revision").unwrap();
    let revisions: Vec<String> = lines
        .map(|l| l.split(',').nth(col).unwrap().to_string())
        .collect();
    assert!(!revisions.is_empty());
    assert!(
        revisions.iter().all(|r| r == "earlier-revision"),
        "{revisions:?}"
    );
}

/// `--resume` over a finished run whose EMSSL unit must run again from a damaged checkpoint
/// fails with one message naming the file, and leaves the complete report as it was (it was
/// rewritten as a partial one before the checkpoint was read).
#[test]
fn a_damaged_emssl_checkpoint_fails_before_the_report_is_rewritten() {
    use selfmodel_lab::studies::emssl::table2::{IkComparisonConfig, run};
    let tmp = common::tempdir();
    let dir = tmp.path().to_path_buf();
    let mut cfg = IkComparisonConfig::named("quick").unwrap();
    cfg.ranges_deg = vec![90.0];
    let robot = selfmodel::sim::dh_robot::ur5([-1.0, 1.0]);
    let device = selfmodel::core::device::DeviceChoice::Cpu;
    let first = run(&cfg, &robot, &dir, device, false).unwrap();
    assert_eq!(first.units_done, first.units);
    assert!(first.partial_note().is_none());
    let units = dir.join("units").join("90");
    let checkpoint = std::fs::read_dir(&units)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.is_dir() && p.join("best.bpk").exists())
        .expect("an EMSSL checkpoint with its best model");
    let name = checkpoint
        .file_name()
        .unwrap()
        .to_string_lossy()
        .to_string();
    let unit = units.join(format!("{}.json", name.trim_end_matches("_checkpoint")));
    assert!(unit.exists(), "{unit:?}");
    std::fs::remove_file(&unit).unwrap();
    std::fs::write(checkpoint.join("best.bpk"), b"not a checkpoint").unwrap();
    let before: Vec<(std::path::PathBuf, Vec<u8>)> = ["results.csv", "results.md", "table2.md"]
        .iter()
        .map(|f| (dir.join(f), std::fs::read(dir.join(f)).unwrap()))
        .collect();
    let err = run(&cfg, &robot, &dir, device, true)
        .err()
        .expect("a damaged checkpoint is an error")
        .to_string();
    assert!(err.contains("best.bpk"), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    for (path, bytes) in before {
        assert!(
            std::fs::read(&path).unwrap() == bytes,
            "{path:?} was rewritten"
        );
    }
}

#[test]
fn dsl_through_the_exact_forward_kinematics_beats_a_learned_forward_model() {
    let (robot, data) = ur5_data(4000, 90.0);
    let device = select(DeviceChoice::Cpu).unwrap();
    let ignorant = ignorant_cm(&robot, &data);
    let fit = FitConfig {
        batch: 64,
        ..FitConfig::paper()
    };
    let learned = DistalConfig {
        forward_hidden: vec![128, 64],
        forward_epochs: 20,
        inverse_epochs: 10,
        forward: selfmodel::ik::paper::distal_learning::DistalForward::Learned,
        inverse_steps: None,
    };
    let exact = DistalConfig {
        forward: selfmodel::ik::paper::distal_learning::DistalForward::Exact,
        ..learned.clone()
    };
    let model = InverseModelConfig::quick(6);
    let errors = |cfg: &DistalConfig| {
        let d = dsl(&robot.chain, &data, &model, &fit, cfg, &device).unwrap();
        assert_eq!(
            d.forward.is_none(),
            cfg.forward == selfmodel::ik::paper::distal_learning::DistalForward::Exact
        );
        test_errors(&d.inverse, &robot.chain, &data, 512, &device)
            .0
            .mean_cm
    };
    let (through_network, through_arm) = (errors(&learned), errors(&exact));
    eprintln!(
        "DSL {through_network:.2} cm, through the exact forward kinematics {through_arm:.2} cm, input-blind {ignorant:.2} cm"
    );
    assert!(through_arm < 0.5 * ignorant);
    assert!(
        through_arm < through_network,
        "exact {through_arm:.2} cm, learned {through_network:.2} cm"
    );
}

#[test]
fn a_matched_budget_trains_the_inverse_network_for_exactly_its_steps() {
    let robot = selfmodel::sim::dh_robot::ur5([-1.5, 1.5]);
    let data = IkData::generate(
        &robot.chain,
        &IkDataConfig {
            samples: 1500,
            train: 1000,
            range_deg: 90.0,
            seed: 3,
            validation: 200,
        },
    )
    .unwrap();
    let device = select(DeviceChoice::Cpu).unwrap();
    let fit = FitConfig {
        batch: 100,
        converge: Some(selfmodel::train::convergence::Convergence {
            max_epochs: 3,
            ..selfmodel::train::convergence::Convergence::standard()
        }),
        ..FitConfig::paper()
    };
    // 800 training goals in batches of 100: 8 steps an epoch; 60 steps round up to 8 epochs,
    // whatever the convergence rule's cap of 3 says.
    let cfg = DistalConfig {
        forward_hidden: vec![32],
        forward_epochs: 2,
        inverse_epochs: 2,
        forward: selfmodel::ik::paper::distal_learning::DistalForward::Exact,
        inverse_steps: Some(60),
    };
    let model = InverseModelConfig {
        hidden: vec![32],
        ..InverseModelConfig::quick(6)
    };
    let d = dsl(&robot.chain, &data, &model, &fit, &cfg, &device).unwrap();
    let log = d.inverse_log.expect("a run to a budget keeps its curve");
    assert_eq!(log.epochs, 8);
    assert_eq!(log.curve.len(), 8);
}
