//! More than one camera: camera poses as vectors a network reads, cameras on a sphere around
//! the robot.

mod common;

use selfmodel::sim::camera::Camera;
use selfmodel::sim::ray_caster::{RayCaster, RenderOptions};

#[test]
fn a_camera_pose_round_trips_through_its_vector() {
    let base = Camera::paper();
    let mut cameras = vec![base.clone()];
    cameras.extend(base.on_sphere([0.0, 0.05, 0.1], 1.3, 8, 15.0, [-20.0, 45.0]));
    // Neither looking at the origin nor upright.
    cameras.push(Camera {
        eye: [0.3, -0.8, 0.5],
        target: [0.1, 0.2, -0.1],
        up: [0.2, 0.1, 1.0],
        ..base.clone()
    });
    for c in &cameras {
        let v = c.to_vector();
        let back = Camera::from_vector(&v, c).unwrap();
        let (a, b) = (c.pose_matrix(), back.pose_matrix());
        assert!((a - b).abs().max() < 1e-9, "{c:?} came back as {back:?}");
        let again = back.to_vector();
        assert!(v.iter().zip(&again).all(|(x, y)| (x - y).abs() < 1e-12));
        // The same image: same rays.
        for (row, col) in [(0.0, 0.0), (50.0, 20.0), (99.0, 99.0)] {
            let (r1, r2) = (c.ray(row, col), back.ray(row, col));
            assert!((r1.dir - r2.dir).norm() < 1e-9 && (r1.origin - r2.origin).norm() < 1e-12);
        }
    }
    assert!(Camera::from_vector(&[0.0; 9], &base).is_err());
    assert!(Camera::from_vector(&[0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 2.0, 0.0, 0.0], &base).is_err());
}

#[test]
fn an_orbited_camera_turns_about_its_target_and_keeps_looking_at_it() {
    // A framed camera looks at a target off the origin (as for a URDF robot).
    let framed = Camera::paper().looking_from([0.1, -0.2, 0.4], 1.7, 0.3, 0.2);
    let (yaw, elevation, radius) = framed.spherical();
    let turned = framed.orbited(40.0);
    assert_eq!(turned.target, framed.target);
    let (yaw2, elevation2, radius2) = turned.spherical();
    assert!((yaw2 - yaw - 40f64.to_radians()).abs() < 1e-9);
    assert!((elevation2 - elevation).abs() < 1e-9 && (radius2 - radius).abs() < 1e-9);
    // A camera read back from a dataset's record has lost its target (it sits 1 m ahead of
    // the eye); the point on its axis nearest the robot's centre is the pivot to turn about.
    let pose = framed.pose_matrix();
    let recorded = Camera::from_record(
        &std::array::from_fn(|i| pose[(i / 4, i % 4)]),
        framed.focal_px(),
        framed.width,
        framed.height,
    );
    let pivot = recorded.axis_point_nearest(framed.target.into());
    assert!((0..3).all(|k| (pivot[k] - framed.target[k]).abs() < 1e-9));
    let (a, b) = (recorded.orbited_about(pivot, 40.0), framed.orbited(40.0));
    assert!((0..3).all(|k| (a.eye[k] - b.eye[k]).abs() < 1e-9));
    assert!(a.angle_to(&b) < 1e-6, "they look along the same axis");
    // The papers' camera (target at the origin) turns about the world z axis.
    let paper = Camera::paper().orbited(90.0);
    assert!((paper.eye[0]).abs() < 1e-12 && (paper.eye[1] - 1.0).abs() < 1e-12);
}

#[test]
fn a_held_out_camera_sees_what_no_training_camera_sees() {
    let arm = selfmodel::sim::arm4::arm4();
    let base = Camera::paper();
    let training = base.on_sphere([0.0, 0.0, 0.0], 1.0, 4, 0.0, [0.0, 20.0]);
    let held_out = base.looking_from([0.0, 0.0, 0.0], 1.0, 30f64.to_radians(), 10f64.to_radians());
    let q = [0.4, -0.3, 0.7, 0.2];
    let render = |c: &Camera| {
        RayCaster::new(&arm, c.clone(), RenderOptions::default())
            .render(&q)
            .silhouette
    };
    let seen = render(&held_out);
    assert!(seen.iter().any(|&v| v > 0), "the robot is in view");
    for c in &training {
        let other = render(c);
        let inter = seen
            .iter()
            .zip(&other)
            .filter(|(a, b)| **a > 0 && **b > 0)
            .count();
        let union = seen
            .iter()
            .zip(&other)
            .filter(|(a, b)| **a > 0 || **b > 0)
            .count();
        let iou = inter as f64 / union.max(1) as f64;
        assert!(
            iou < 0.9,
            "held-out view too like the training camera at {:?}: IoU {iou:.3}",
            c.eye
        );
    }
    // The first training camera is the papers' view.
    assert!((training[0].pose_matrix() - base.pose_matrix()).abs().max() < 1e-12);
}

#[test]
fn a_multi_view_dataset_holds_every_pose_from_every_camera_and_records_each_camera() {
    let arm = selfmodel::sim::arm4::arm4();
    let base = Camera {
        width: 32,
        height: 32,
        ..Camera::paper()
    };
    let cameras = base.on_sphere([0.0, 0.0, 0.0], 1.0, 4, 0.0, [0.0, 20.0]);
    let angles: Vec<Vec<f64>> = (0..5)
        .map(|i| vec![10.0 * i as f64, -15.0, 20.0, 5.0 * i as f64])
        .collect();
    let data = selfmodel::data::dataset::Dataset::render_views(
        &arm,
        &angles,
        &cameras,
        3,
        &RenderOptions::default(),
    )
    .unwrap();
    assert_eq!(data.len(), 20);
    assert_eq!(data.split(), (0..12, 12..20));
    for p in 0..5 {
        for (c, camera) in cameras.iter().enumerate() {
            let i = p * 4 + c;
            assert_eq!(data.angles[i], angles[p]);
            let recorded = data.camera_of(i);
            assert!((recorded.pose_matrix() - camera.pose_matrix()).abs().max() < 1e-9);
            let direct = RayCaster::new(&arm, camera.clone(), RenderOptions::default())
                .render(&arm.chain.to_si(&angles[p]))
                .silhouette;
            assert_eq!(data.image(i), direct.as_slice());
        }
    }
    // A camera of another size is refused.
    let mut odd = cameras.clone();
    odd[1].width = 48;
    assert!(
        selfmodel::data::dataset::Dataset::render_views(
            &arm,
            &angles,
            &odd,
            3,
            &RenderOptions::default()
        )
        .is_err()
    );
}

/// Camera-conditioned and multi-head NeuroKin on four cameras: on held-out poses seen from
/// the trained cameras, each beats the best constant of each camera (its mean training
/// image), so it reads both the joints and the camera.
#[test]
fn a_tiny_camera_conditioned_model_renders_a_trained_camera_better_than_a_constant() {
    use selfmodel::core::device::DeviceChoice;
    use selfmodel::eval::evaluation::{iou, psnr_db};
    use selfmodel::self_models::neurokin::{CameraUse, neurokin_run};
    use selfmodel::self_models::{camera_input::camera_input, harness::fit_run};
    let cameras = 4;
    let mut base = neurokin_run("quick").unwrap();
    base.data.dataset.views = Some(selfmodel::data::dataset::Views {
        cameras,
        radius: None,
        elevation_deg: [0.0, 30.0],
    });
    base.train.steps = 1000;
    let robot = base.data.robot.load().unwrap();
    let placed = base.data.dataset.cameras(&robot).unwrap();
    assert_eq!(placed.len(), cameras);
    assert!(
        (placed[0].pose_matrix() - Camera::paper().pose_matrix())
            .abs()
            .max()
            < 1e-9
    );
    for camera_use in [
        CameraUse::Input,
        CameraUse::Heads(placed.iter().map(camera_input).collect()),
    ] {
        let mut run = base.clone();
        run.model.camera = camera_use.clone();
        let dir = common::tempdir();
        let fitted = fit_run(&run, dir.path(), DeviceChoice::Cpu, false)
            .unwrap()
            .erased();
        let data = &fitted.data;
        let px = data.width * data.height;
        // Per camera: the mean training image.
        let mut mean = vec![vec![0f32; px]; cameras];
        let mut count = vec![0f32; cameras];
        for i in fitted.train_range.clone() {
            let c = i % cameras;
            count[c] += 1.0;
            for (m, &v) in mean[c].iter_mut().zip(data.image(i)) {
                *m += v as f32 / 255.0;
            }
        }
        for (m, n) in mean.iter_mut().zip(&count) {
            m.iter_mut().for_each(|v| *v /= n);
        }
        let pred: Vec<f32> = fitted.trained.renderers[0]
            .1
            .render(fitted.test_set.inputs.clone())
            .0
            .into_data()
            .convert::<f32>()
            .try_into_vec::<f32>()
            .unwrap();
        let (mut model, mut constant) = ((0.0, 0.0), (0.0, 0.0));
        let n = fitted.test_range.len();
        for (k, i) in fitted.test_range.clone().enumerate() {
            let truth = &fitted.truth[k * px..(k + 1) * px];
            let p = &pred[k * px..(k + 1) * px];
            let m = &mean[i % cameras];
            model.0 += psnr_db(p, truth) / n as f64;
            model.1 += iou(p, truth) / n as f64;
            constant.0 += psnr_db(m, truth) / n as f64;
            constant.1 += iou(m, truth) / n as f64;
        }
        eprintln!(
            "{camera_use:?}: {:.2} dB IoU {:.3}; per-camera constant {:.2} dB IoU {:.3}",
            model.0, model.1, constant.0, constant.1
        );
        assert!(
            model.0 > constant.0 + 0.5 && model.1 > constant.1,
            "{camera_use:?}: {model:?} against the constant's {constant:?}"
        );
    }
}

/// FFKSM and K-3DGS on a four-camera dataset: each sample is rendered from its own camera
/// (rendering a batch whose rows carry their cameras gives what rendering each camera does),
/// and on held-out poses it beats a black image on every trained camera; K-3DGS also beats
/// the per-camera constant (the quick FFKSM, like its single-view test, only black).
#[test]
fn a_tiny_3d_model_trains_on_several_cameras_and_renders_each_sample_from_its_own() {
    use selfmodel::core::device::DeviceChoice;
    use selfmodel::eval::evaluation::{iou, psnr_db};
    use selfmodel::self_models::ffksm::{FfksmVariant, ffksm_run};
    use selfmodel::self_models::harness::{Fitted, fit_run};
    use selfmodel::self_models::k3dgs::{K3dgsVariant, k3dgs_run};
    let cameras = 4;
    let views = Some(selfmodel::data::dataset::Views {
        cameras,
        radius: None,
        elevation_deg: [0.0, 30.0],
    });
    let check = |name: &str, fitted: Fitted<Box<dyn selfmodel::Render>>, beat_constant: bool| {
        let data = &fitted.data;
        let px = data.width * data.height;
        let renderer = fitted.trained.renderers.last().unwrap().1.as_ref();
        let host = |t: burn::tensor::Tensor<4>| {
            t.into_data()
                .convert::<f32>()
                .try_into_vec::<f32>()
                .unwrap()
        };
        let n = fitted.test_range.len();
        assert_eq!(fitted.test_set.inputs.dims()[1], data.dof() + 9);
        let pred = host(renderer.render(fitted.test_set.inputs.clone()).0);
        // Per camera: the same poses through render_view.
        for c in 0..cameras {
            let rows: Vec<usize> = (0..n)
                .filter(|k| (fitted.test_range.start + k) % cameras == c)
                .collect();
            let angles = fitted.test_set.inputs.clone().slice([0..n, 0..data.dof()]);
            let picked = angles.select(
                0,
                burn::tensor::Tensor::<1, burn::tensor::Int>::from_data(
                    burn::tensor::TensorData::new(
                        rows.iter().map(|&r| r as i64).collect::<Vec<_>>(),
                        [rows.len()],
                    ),
                    &fitted.device,
                ),
            );
            let view = host(renderer.render_view(&data.camera_of(c), picked).unwrap());
            for (j, &k) in rows.iter().enumerate() {
                let (a, b) = (&pred[k * px..(k + 1) * px], &view[j * px..(j + 1) * px]);
                let diff = a
                    .iter()
                    .zip(b)
                    .map(|(x, y)| (x - y).abs())
                    .fold(0f32, f32::max);
                assert!(diff < 1e-4, "{name}: camera {c}, test image {k}: {diff}");
            }
        }
        // Against the per-camera mean training image.
        let mut mean = vec![vec![0f32; px]; cameras];
        let mut count = vec![0f32; cameras];
        for i in fitted.train_range.clone() {
            count[i % cameras] += 1.0;
            for (m, &v) in mean[i % cameras].iter_mut().zip(data.image(i)) {
                *m += v as f32 / 255.0;
            }
        }
        let (mut model, mut constant) = ([0.0; 2], [0.0; 2]);
        let (mut per_camera, mut black) = (vec![0.0; cameras], vec![0.0; cameras]);
        for (k, i) in fitted.test_range.clone().enumerate() {
            let c = i % cameras;
            let truth = &fitted.truth[k * px..(k + 1) * px];
            let m: Vec<f32> = mean[c].iter().map(|v| v / count[c]).collect();
            let p = &pred[k * px..(k + 1) * px];
            model[0] += psnr_db(p, truth) / n as f64;
            model[1] += iou(p, truth) / n as f64;
            constant[0] += psnr_db(&m, truth) / n as f64;
            constant[1] += iou(&m, truth) / n as f64;
            per_camera[c] += psnr_db(p, truth);
            black[c] += psnr_db(&vec![0.0; px], truth);
        }
        eprintln!(
            "{name} on {cameras} cameras: {model:.3?} (dB, IoU); per-camera constant {constant:.3?}; per camera {per_camera:.1?} against black {black:.1?} (summed dB)"
        );
        for c in 0..cameras {
            assert!(
                per_camera[c] > black[c],
                "{name}, camera {c}: no better than black"
            );
        }
        if beat_constant {
            assert!(
                model[0] > constant[0] + 0.5 && model[1] > constant[1] + 0.05,
                "{name}: {model:?} against the constant's {constant:?}"
            );
        }
    };
    let mut run = k3dgs_run("quick", K3dgsVariant::Anisotropic).unwrap();
    run.data.dataset.views = views.clone();
    // One image a step: the quick preset's 300 steps for each of the four cameras.
    run.train.steps *= cameras;
    let dir = common::tempdir();
    check(
        "K-3DGS",
        fit_run(&run, dir.path(), DeviceChoice::Cpu, false)
            .unwrap()
            .erased(),
        true,
    );
    let mut run = ffksm_run("quick", FfksmVariant::Original).unwrap();
    run.data.dataset.views = views;
    run.train.steps *= cameras;
    let dir = common::tempdir();
    check(
        "FFKSM",
        fit_run(&run, dir.path(), DeviceChoice::Cpu, false)
            .unwrap()
            .erased(),
        false,
    );
}

/// A finished multiview run resumed where its git-ignored checkpoints are gone (a fresh
/// clone of a committed run) trains nothing again: each model's kept unit gives the same
/// table (its measured speeds included, which a second measurement would change) and grid.
#[test]
fn a_multiview_run_resumed_without_its_checkpoints_reuses_every_kept_unit() {
    use selfmodel::core::preset::Preset;
    let dir = common::tempdir();
    let mut cfg = selfmodel_lab::studies::multiview::MultiviewConfig::quick();
    cfg.cameras = vec![2];
    cfg.three_d_cameras = vec![1];
    cfg.steps = Some(20);
    let mut opts = selfmodel_lab::studies::registry::RunOptions::preset("quick");
    selfmodel_lab::studies::multiview::run(&cfg, &opts, dir.path()).unwrap();
    let read = |f: &str| std::fs::read(dir.path().join(f)).unwrap();
    let (table, grid) = (read("results.csv"), read("grid.png"));
    let mut units = 0;
    for unit in std::fs::read_dir(dir.path()).unwrap() {
        let unit = unit.unwrap().path();
        if unit.join("checkpoint").is_dir() {
            std::fs::remove_dir_all(unit.join("checkpoint")).unwrap();
        }
        if unit.is_dir() {
            assert!(unit.join("unit.json").is_file(), "{unit:?} kept no unit");
            units += 1;
        }
    }
    // Camera-conditioned and multi-head NeuroKin, FFKSM, K-3DGS.
    assert_eq!(units, 4);
    opts.resume = true;
    selfmodel_lab::studies::multiview::run(&cfg, &opts, dir.path()).unwrap();
    assert!(read("results.csv") == table, "the resumed table differs");
    assert!(read("grid.png") == grid, "the resumed grid differs");
    for unit in std::fs::read_dir(dir.path()).unwrap() {
        assert!(
            !unit.unwrap().path().join("checkpoint").exists(),
            "trained again"
        );
    }
}
