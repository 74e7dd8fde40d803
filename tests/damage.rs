//! Damage in the simulator: a damaged arm renders differently from a healthy one where the
//! damaged link (and what it carries) is, and nowhere else.

mod common;

use selfmodel::sim::arm_change::Damage;
use selfmodel::sim::bvh::Bvh;
use selfmodel::sim::camera::Camera;
use selfmodel::sim::ray_caster::{RayCaster, RenderOptions};
use selfmodel::sim::robot::Robot;

fn silhouette(robot: &Robot, q: &[f64]) -> Vec<u8> {
    RayCaster::new(robot, Camera::paper(), RenderOptions::default())
        .render(q)
        .silhouette
}

/// The robot with only the links in `keep` drawn.
fn only(robot: &Robot, keep: &[usize]) -> Robot {
    let mut r = robot.clone();
    for (l, g) in r.geometry.iter_mut().enumerate() {
        if !keep.contains(&l) {
            *g = Bvh::new(Vec::new());
        }
    }
    r
}

/// The link `link` and every link below it in the tree.
fn subtree(robot: &Robot, link: usize) -> Vec<usize> {
    let mut out = vec![link];
    let mut i = 0;
    while i < out.len() {
        let l = out[i];
        out.extend(
            robot
                .chain
                .joints
                .iter()
                .filter(|j| j.parent == l)
                .map(|j| j.child),
        );
        i += 1;
    }
    out
}

#[test]
fn a_damaged_arm_renders_differently_where_the_link_is_and_nowhere_else() {
    let healthy = selfmodel::sim::arm4::arm4();
    let poses = [
        vec![0.3, -0.5, 0.8, 0.2],
        vec![-0.7, 0.4, -0.3, 1.0],
        vec![1.2, 0.9, 0.6, -0.8],
    ];
    let damages = [
        Damage::Bend { link: 1, deg: 10.0 },
        Damage::Length { link: 1, cm: 3.0 },
        Damage::Length { link: 2, cm: -3.0 },
        Damage::Truncate {
            link: 3,
            fraction: 0.5,
        },
    ];
    for d in damages {
        let damaged = d.apply(&healthy).unwrap();
        // Link k of the joint vector is chain link k + 1 on arm4 (link 0 is the base).
        let link = d.link() + 1;
        let region: Vec<usize> = match d {
            Damage::Truncate { .. } => vec![link],
            _ => subtree(&healthy, link),
        };
        let mut changed_total = 0;
        for q in &poses {
            let (h, x) = (silhouette(&healthy, q), silhouette(&damaged, q));
            let (mh, mx) = (
                silhouette(&only(&healthy, &region), q),
                silhouette(&only(&damaged, &region), q),
            );
            let changed: Vec<usize> = (0..h.len()).filter(|&i| h[i] != x[i]).collect();
            let outside = changed
                .iter()
                .filter(|&&i| mh[i] == 0 && mx[i] == 0)
                .count();
            assert_eq!(
                outside,
                0,
                "{}: {outside} changed pixels away from the link",
                d.label()
            );
            changed_total += changed.len();
        }
        assert!(
            changed_total >= 20,
            "{}: only {changed_total} pixels changed",
            d.label()
        );
    }
    // A change of nothing (the geometry tessellated, stretched by 0) renders the healthy arm.
    let same = Damage::Length { link: 2, cm: 0.0 }.apply(&healthy).unwrap();
    for q in &poses {
        let (h, x) = (silhouette(&healthy, q), silhouette(&same, q));
        let differ = (0..h.len()).filter(|&i| h[i] != x[i]).count();
        assert!(
            differ <= 2,
            "{differ} pixels differ after a change of nothing"
        );
    }
}

#[test]
fn damage_is_refused_where_it_cannot_apply() {
    let arm = selfmodel::sim::arm4::arm4();
    assert!(Damage::Bend { link: 4, deg: 3.0 }.apply(&arm).is_err());
    assert!(Damage::Length { link: 0, cm: -50.0 }.apply(&arm).is_err());
    assert!(
        Damage::Truncate {
            link: 3,
            fraction: 1.5
        }
        .apply(&arm)
        .is_err()
    );
}

#[test]
fn the_roc_area_is_one_for_separated_scores_and_a_half_for_equal_ones() {
    use selfmodel::body::damage::{roc_auc, threshold_at};
    assert_eq!(roc_auc(&[0.1, 0.2, 0.3], &[0.4, 0.5]), 1.0);
    assert_eq!(roc_auc(&[0.4, 0.5], &[0.1, 0.2, 0.3]), 0.0);
    assert_eq!(roc_auc(&[0.2; 4], &[0.2; 3]), 0.5);
    // 1 of 100 healthy scores is above the 1% threshold at most.
    let healthy: Vec<f64> = (0..100).map(|i| i as f64).collect();
    let t = threshold_at(&healthy, 0.01);
    assert!(
        healthy.iter().filter(|&&s| s > t).count() <= 1,
        "threshold {t}"
    );
}

#[test]
fn the_residual_score_separates_a_large_bend_from_healthy_images_on_a_tiny_model() {
    let dir = common::tempdir();
    let opts = selfmodel_lab::studies::registry::RunOptions::preset("quick");
    let cfg =
        <selfmodel_lab::studies::damage::DamageConfig as selfmodel::core::preset::Preset>::quick();
    selfmodel_lab::studies::damage::run(&cfg, &opts, dir.path()).unwrap();
    let rows: Vec<selfmodel_lab::studies::damage::DetectionRow> =
        selfmodel::report::table::read_csv(&dir.path().join("detection.csv")).unwrap();
    let bend = rows
        .iter()
        .find(|r| r.damage == "bend" && r.size == 10.0 && r.k == 10)
        .expect("a 10-degree bend at k = 10");
    assert!(bend.auc >= 0.95, "AUC {}", bend.auc);
    assert!(bend.damaged_score > bend.healthy_score);
    // One image tells less than ten.
    let one = rows
        .iter()
        .find(|r| r.damage == "bend" && r.size == 10.0 && r.k == 1)
        .unwrap();
    assert!(one.auc < bend.auc + 1e-12);
    // Every recovery method ran, and fine-tuning on the damaged arm's images moved the model
    // towards it.
    let recovery: Vec<selfmodel_lab::studies::damage::RecoveryRow> =
        selfmodel::report::table::read_csv(&dir.path().join("recovery.csv")).unwrap();
    for m in [
        "unchanged",
        "fine-tune",
        "replay",
        "EWC",
        "gated experts",
        "re-simulated",
        "from scratch",
    ] {
        assert!(
            recovery
                .iter()
                .any(|r| r.method.split(" (").next() == Some(m)),
            "no {m} row"
        );
    }
    let at = |m: &str| {
        recovery
            .iter()
            .find(|r| r.method == m && r.n == 50)
            .unwrap()
            .psnr_damaged_db
    };
    assert!(at("fine-tune") > at("unchanged"));
    // Resumed, the run reads every recovery row it finished and writes the same table; with
    // one more EWC weight it computes only that one's rows.
    let first = std::fs::read_to_string(dir.path().join("recovery.csv")).unwrap();
    let mut resume = opts.clone();
    resume.resume = true;
    selfmodel_lab::studies::damage::run(&cfg, &resume, dir.path()).unwrap();
    assert_eq!(
        std::fs::read_to_string(dir.path().join("recovery.csv")).unwrap(),
        first
    );
    let mut more = cfg.clone();
    more.recovery.ewc_lambdas.push(1e10);
    selfmodel_lab::studies::damage::run(&more, &resume, dir.path()).unwrap();
    let again: Vec<selfmodel_lab::studies::damage::RecoveryRow> =
        selfmodel::report::table::read_csv(&dir.path().join("recovery.csv")).unwrap();
    for r in &recovery {
        let same = again
            .iter()
            .find(|a| a.method == r.method && a.n == r.n)
            .unwrap();
        assert_eq!(
            (same.psnr_damaged_db, same.seconds),
            (r.psnr_damaged_db, r.seconds)
        );
    }
    assert!(again.iter().any(|r| r.method == "EWC (lambda 1e10)"));
}

#[test]
fn the_ewc_penalty_is_zero_at_the_old_weights_and_grows_away_from_them() {
    use burn::module::Module;
    use burn::tensor::{Tensor, TensorData};
    use selfmodel::core::preset::Preset;
    use selfmodel::self_models::neurokin::NeuroKinConfig;
    use selfmodel::train::{
        batcher::TrainSet,
        config::TrainConfig,
        trainer::{Trainer, autodiff_device},
    };
    let device =
        selfmodel::core::device::select(selfmodel::core::device::DeviceChoice::Cpu).unwrap();
    let tdev = autodiff_device(&device, 3);
    let cfg = NeuroKinConfig::quick();
    let model = cfg.init(&tdev, 3).unwrap();
    let n = 16;
    let angles: Vec<f32> = (0..n * 4).map(|i| ((i * 37) % 90) as f32 - 45.0).collect();
    let images: Vec<f32> = (0..n * 32 * 32).map(|i| ((i / 7) % 2) as f32).collect();
    let set = TrainSet {
        inputs: Tensor::from_data(TensorData::new(angles, [n, 4]), &tdev),
        targets: vec![Tensor::from_data(
            TensorData::new(images, [n, 1, 32, 32]),
            &tdev,
        )],
    };
    let set = cfg.training_set(&set);
    let train = TrainConfig {
        steps: 3,
        batch: 8,
        learning_rate: 1e-3,
        grad_clip_norm: None,
        input_noise: 0.0,
        seed: 1,
        checkpoint_every: 0,
        log_every: 0,
        precision: Default::default(),
        schedule: Default::default(),
    };
    let loss = cfg.training_loss();
    let ewc = selfmodel::train::ewc::Ewc::new(&model, &set, &train, 2, &loss, 100.0).unwrap();
    assert!(!ewc.is_empty());
    let at_old: f32 = ewc.penalty(&model).into_scalar();
    assert_eq!(at_old, 0.0);
    // Training with the penalty runs, and moves the weights away from the anchor.
    let (moved, _) = Trainer::new(&train, "EWC test")
        .quiet()
        .fit(model.clone(), &set, |m, b| loss(m, b) + ewc.penalty(m))
        .unwrap();
    let away: f32 = ewc.penalty(&moved).into_scalar();
    assert!(away > 0.0, "penalty {away} after training");
    let _ = moved.valid();
}

/// The paper preset's healthy model is NeuroKin's named `large` preset (the checkpoint one
/// trains is the other's).
#[test]
fn the_damage_studys_model_is_neurokins_large_preset() {
    use selfmodel::core::preset::Preset;
    use selfmodel::self_models::model::SelfModel;
    let opts = selfmodel_lab::studies::run::RunOptions::preset("paper");
    let ours = selfmodel_lab::studies::damage::model_run(
        &selfmodel_lab::studies::damage::DamageConfig::paper(),
        &opts,
    )
    .unwrap();
    let large = opts
        .apply(selfmodel::self_models::neurokin::neurokin_run("large").unwrap())
        .unwrap();
    assert_eq!(
        ours.model.fingerprint(&ours.train, &ours.data),
        large.model.fingerprint(&large.train, &large.data)
    );
    assert_eq!(large.data.dataset.train, 12_000);
    assert_eq!(large.train.steps, 9_000);
}
