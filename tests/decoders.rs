//! The direct decoders: architectures as published, and tiny trained models that must beat a
//! constant predictor.

mod common;

use burn::tensor::Device;
use selfmodel::core::device::DeviceChoice;
use selfmodel::core::preset::Preset;
use selfmodel::eval::evaluation::{Predictions, score};
use selfmodel::self_models::mean_silhouette::MeanSilhouette;
use selfmodel::self_models::neurokin::NeuroKinConfig;
use selfmodel::self_models::resneurokin_d::ResNeuroKinDConfig;
use selfmodel::self_models::{harness::run, model::SelfModel, run_config::SelfModelRun};
use selfmodel_lab::studies::models::Studied;

#[test]
fn parameter_counts_match_the_notebooks() {
    let dev = Device::flex();
    assert_eq!(
        NeuroKinConfig::paper()
            .init(&dev, 0)
            .unwrap()
            .trainable_params(),
        5_189_857
    );
    assert_eq!(
        NeuroKinConfig::text64()
            .init(&dev, 0)
            .unwrap()
            .trainable_params(),
        2_800_385
    );
    assert_eq!(
        ResNeuroKinDConfig::paper()
            .init(&dev, 0)
            .unwrap()
            .trainable_params(),
        78_971_714
    );
}

#[test]
fn output_shapes_are_the_image_size() {
    let dev = Device::flex();
    let q = burn::tensor::Tensor::<2>::zeros([2, 4], &dev);
    let nk = NeuroKinConfig::paper().init(&dev, 0).unwrap();
    assert_eq!(nk.predict(q.clone()).dims(), [2, 1, 100, 100]);
    let nk64 = NeuroKinConfig::text64().init(&dev, 0).unwrap();
    assert_eq!(nk64.forward(q.clone()).dims(), [2, 1, 64, 64]);
    assert_eq!(nk64.predict(q).dims(), [2, 1, 100, 100]);
    for layers in [2, 6] {
        let cfg = NeuroKinConfig {
            upsampling_layers: layers,
            ..NeuroKinConfig::quick()
        };
        let m = cfg.init(&dev, 0).unwrap();
        let q = burn::tensor::Tensor::<2>::zeros([1, 4], &dev);
        assert_eq!(m.predict(q).dims(), [1, 1, 32, 32], "{layers} layers");
    }
}

/// PSNR and IoU of the best constant image (MeanSilhouette) on the run's data and test set.
fn constant_predictor<M: SelfModel>(cfg: &SelfModelRun<M>) -> (f64, f64) {
    let mut constant = MeanSilhouette::preset_run(&cfg.preset).unwrap();
    constant.data = cfg.data.clone();
    constant.model.image = cfg.model.image();
    let dir = common::tempdir();
    let q = run(&constant, dir.path(), DeviceChoice::Cpu, false)
        .unwrap()
        .quality;
    // Every run saves its model: the constant loads and scores as its run did.
    common::the_saved_model_scores_as_its_run(&constant, dir.path(), &q);
    (q.psnr_db_test, q.iou_test)
}

/// Training seeds the device's global RNG: tests that train run one at a time so each gets
/// the same initialisation as the binary would.
static TRAINING: std::sync::Mutex<()> = std::sync::Mutex::new(());

#[test]
fn tiny_neurokin_beats_a_constant_predictor() {
    let _serial = TRAINING.lock().unwrap_or_else(|e| e.into_inner());
    let dir = common::tempdir();
    let mut cfg = selfmodel::self_models::neurokin::neurokin_run("quick").unwrap();
    cfg.train.steps = 1000;
    let out = run(&cfg, dir.path(), DeviceChoice::Cpu, false).unwrap();
    // The mean training image is a strong constant on the quick set (its 200 Lorenz samples
    // move little), so the tiny model must beat it on IoU (where the arm is) by a margin.
    let (c_psnr, c_iou) = constant_predictor(&cfg);
    let q = &out.quality;
    eprintln!(
        "NeuroKin IoU {:.3} ({:.2} dB), constant IoU {c_iou:.3} ({c_psnr:.2} dB)",
        q.iou_test, q.psnr_db_test
    );
    assert!(
        q.iou_test > c_iou + 0.1,
        "NeuroKin IoU {:.3} ({:.2} dB) vs constant IoU {c_iou:.3} ({c_psnr:.2} dB)",
        q.iou_test,
        q.psnr_db_test
    );
    for f in [
        "results.csv",
        "results.md",
        "config.json",
        "curve.csv",
        "qualitative.png",
        "training_curve.png",
        "model/model.json",
        "model/model.bpk",
        "model/probe.npz",
    ] {
        assert!(dir.path().join(f).is_file(), "{f} missing");
    }
    common::the_saved_model_scores_as_its_run(&cfg, dir.path(), q);
}

/// LinkSplat (a decoder fed where each link is) on the quick preset: it must beat the
/// constant image by NeuroKin's margin, and its saved model (anchors in its state) must load
/// and score as its run did.
#[test]
fn tiny_link_splat_beats_a_constant_predictor() {
    let _serial = TRAINING.lock().unwrap_or_else(|e| e.into_inner());
    let dir = common::tempdir();
    let mut cfg = selfmodel::self_models::link_splat::link_splat_run("quick").unwrap();
    cfg.train.steps = 600;
    let out = run(&cfg, dir.path(), DeviceChoice::Cpu, false).unwrap();
    let (c_psnr, c_iou) = constant_predictor(&cfg);
    let q = &out.quality;
    eprintln!(
        "LinkSplat IoU {:.3} ({:.2} dB), constant IoU {c_iou:.3} ({c_psnr:.2} dB)",
        q.iou_test, q.psnr_db_test
    );
    assert!(
        q.iou_test > c_iou + 0.1 && q.psnr_db_test > c_psnr,
        "LinkSplat IoU {:.3} ({:.2} dB) vs constant IoU {c_iou:.3} ({c_psnr:.2} dB)",
        q.iou_test,
        q.psnr_db_test
    );
    common::the_saved_model_scores_as_its_run(&cfg, dir.path(), q);
}

#[test]
fn tiny_resneurokin_d_learns_silhouette_and_metric_depth() {
    let _serial = TRAINING.lock().unwrap_or_else(|e| e.into_inner());
    let dir = common::tempdir();
    let mut cfg = selfmodel::self_models::resneurokin_d::resneurokin_d_run("quick").unwrap();
    cfg.train.steps = 400;
    let out = run(&cfg, dir.path(), DeviceChoice::Cpu, false).unwrap();
    let (c_psnr, c_iou) = constant_predictor(&cfg);
    assert!(
        out.quality.iou_test > c_iou + 0.1,
        "IoU {:.3} ({:.2} dB) vs constant IoU {c_iou:.3} ({c_psnr:.2} dB)",
        out.quality.iou_test,
        out.quality.psnr_db_test
    );
    // Depth on robot pixels must be closer than predicting 0 (the background value), whose
    // error is the mean true depth of the robot pixels.
    let (data, _, test) = cfg.data.load().unwrap();
    let (mut sum, mut n) = (0.0f64, 0usize);
    for i in test {
        for (&d, &s) in data.depth_map(i).iter().zip(data.image(i)) {
            if s >= 128 {
                sum += d as f64;
                n += 1;
            }
        }
    }
    let zero_mm = 1000.0 * sum / n as f64;
    let mae = out.quality.depth_mae_mm.unwrap();
    assert!(
        mae < 0.97 * zero_mm,
        "depth error {mae:.0} mm vs {zero_mm:.0} mm for zero"
    );
    common::the_saved_model_scores_as_its_run(&cfg, dir.path(), &out.quality);
}

#[test]
fn same_seed_same_model_while_another_thread_builds_models() {
    let dev = Device::flex();
    let cfg = NeuroKinConfig::paper();
    let q = burn::tensor::Tensor::<2>::ones([1, 4], &dev);
    let reference = cfg.init(&dev, 5).unwrap().forward(q.clone()).into_data();
    let stop = std::sync::atomic::AtomicBool::new(false);
    std::thread::scope(|s| {
        s.spawn(|| {
            while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                // Another test building its own model at the same time.
                let _ = NeuroKinConfig::quick().init(&dev, 9).unwrap();
            }
        });
        let again: Vec<_> = (0..2)
            .map(|_| cfg.init(&dev, 5).unwrap().forward(q.clone()).into_data())
            .collect();
        stop.store(true, std::sync::atomic::Ordering::Relaxed);
        again
    })
    .into_iter()
    .for_each(|again| assert_eq!(again, reference, "seed 5 gave another model"));
}

#[test]
fn depth_errors_count_robot_pixels_and_the_constant_baseline_is_the_median() {
    // Four pixels, three of them robot at 1, 2 and 6 m; the background pixel's depth must not
    // count, whatever the prediction there.
    let truth = [1.0, 1.0, 1.0, 0.0];
    let truth_depth = [1.0, 2.0, 6.0, 0.0];
    let pred = Predictions {
        silhouettes: truth.to_vec(),
        depth: Some(vec![1.5, 2.0, 5.0, 9.0]),
        pixels: 4,
        depth_pixels: Default::default(),
    };
    let q = score(&pred, &truth, Some(&truth_depth), 1);
    // |1.5-1| + 0 + |5-6| = 1.5 m over 3 pixels.
    assert!((q.depth_mae_mm.unwrap() - 500.0).abs() < 1e-3);
    // The median, 2 m: (1 + 0 + 4) / 3 m.
    assert!((q.depth_constant_mae_mm.unwrap() - 5000.0 / 3.0).abs() < 1e-3);
    // A renderer that misses the third pixel: its depth error counts the pixels it drew.
    let drawn = Predictions {
        silhouettes: vec![1.0, 0.9, 0.1, 0.0],
        depth_pixels: selfmodel::eval::evaluation::DepthPixels::Drawn,
        ..pred
    };
    let q = score(&drawn, &truth, Some(&truth_depth), 1);
    assert!((q.depth_mae_mm.unwrap() - 250.0).abs() < 1e-3);
}

#[test]
fn bench_decoders_quick_measures_every_figure_and_reads_torch_lines() {
    use selfmodel_lab::studies::bench::decoders::{attach_torch, run};
    let mut rows = run(selfmodel::core::device::DeviceChoice::Cpu, true).unwrap();
    // Two models, each: batch 1, batch 256 and training.
    assert_eq!(rows.len(), 6);
    assert!(rows.iter().all(|r| r.ours.is_finite() && r.ours > 0.0));
    assert!(
        rows.iter()
            .all(|r| r.preset == "quick" && r.device == "cpu")
    );
    let first = (rows[0].model.clone(), rows[0].figure.clone(), rows[0].ours);
    attach_torch(
        &mut rows,
        &format!(
            "torch 2.9, 2 threads\n{} {} {}\n",
            first.0,
            first.1,
            first.2 / 2.0
        ),
    );
    assert_eq!(rows[0].torch, Some(first.2 / 2.0));
    assert!((rows[0].ratio.unwrap() - 2.0).abs() < 1e-9);
    assert!(
        rows[1..]
            .iter()
            .all(|r| r.torch.is_none() && r.ratio.is_none())
    );
}

#[test]
fn the_lookup_table_answers_a_training_pose_with_its_own_images() {
    use selfmodel::self_models::nearest_pose::NearestPose;
    let mut cfg = NearestPose::preset_run("quick").unwrap();
    // Test on eight training poses: each is its own nearest pose.
    cfg.data.test = Some(0..8);
    let dir = common::tempdir();
    let out = run(&cfg, dir.path(), DeviceChoice::Cpu, false).unwrap();
    assert_eq!(out.quality.iou_test, 1.0);
    assert_eq!(out.quality.depth_mae_mm, Some(0.0));
    // Its saved model is its config only (it answers from its training set), and says so.
    let device = selfmodel::core::device::select(DeviceChoice::Cpu).unwrap();
    let e = selfmodel::self_models::loading::load(dir.path(), &device)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("saves no weights that load"), "{e}");
    // And on the held-out poses it beats the best constant image.
    let held_out = NearestPose::preset_run("quick").unwrap();
    let q = run(&held_out, dir.path(), DeviceChoice::Cpu, false)
        .unwrap()
        .quality;
    let (c_psnr, c_iou) = constant_predictor(&held_out);
    assert!(
        q.iou_test > c_iou && q.psnr_db_test > c_psnr,
        "lookup {:.3} ({:.2} dB) against constant {c_iou:.3} ({c_psnr:.2} dB)",
        q.iou_test,
        q.psnr_db_test
    );
}
