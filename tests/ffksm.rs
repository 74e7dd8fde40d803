//! FFKSM's building blocks against their slow references: the positional encoding and the
//! virtual frame.

mod common;

use burn::tensor::{Device, Tensor, TensorData};
use selfmodel::self_models::ffksm::encoding::{
    encode, encode_into, encode_reference, encoded_width,
};
use selfmodel::self_models::ffksm::virtual_frame::{
    JointsFrame, VirtualFrame, to_virtual, to_virtual_reference,
};

fn values(n: usize, seed: u32, scale: f64) -> Vec<f64> {
    (0..n)
        .map(|i| {
            let v = (i as u32)
                .wrapping_mul(2_654_435_761)
                .wrapping_add(seed.wrapping_mul(97));
            scale * ((v >> 8) as f64 / (1 << 23) as f64 - 1.0)
        })
        .collect()
}

/// A test arm of `joints` joints whose shoulder sits above its base (the first joint turns
/// about z 0.04 m up, the second about y one link higher), and its virtual frame for a scene
/// shrunk `scale` times.
fn offset_arm(joints: usize, scale: f64) -> (selfmodel::sim::robot::Robot, VirtualFrame) {
    let dir = common::tempdir();
    let urdf = common::write_arm(dir.path(), "arm", joints, false);
    let robot =
        selfmodel::sim::urdf_loader::load_urdf(&urdf, nalgebra::Isometry3::identity()).unwrap();
    let frame = JointsFrame::of_chain(&robot.chain, scale).unwrap();
    (robot, VirtualFrame::Joints(frame))
}

fn tensor(v: &[f64], dims: [usize; 2], dev: &Device) -> Tensor<2> {
    let v: Vec<f32> = v.iter().map(|&x| x as f32).collect();
    Tensor::from_data(TensorData::new(v, dims), dev)
}

#[test]
fn positional_encoding_widths_and_values_match_the_reference() {
    // The reimplementation's L = 5 (point 33, joints 22) and the original's L = 10 (63, 42).
    assert_eq!(
        [5, 10].map(|l| [encoded_width(3, l), encoded_width(2, l)]),
        [[33, 22], [63, 42]]
    );
    let dev = Device::flex();
    for (d, bands) in [(3, 5), (2, 5), (3, 10)] {
        let n = 7;
        let x = values(n * d, d as u32, 1.5);
        let ours = encode(tensor(&x, [n, d], &dev), bands);
        assert_eq!(ours.dims(), [n, encoded_width(d, bands)]);
        let ours = ours.into_data().try_to_vec::<f32>().unwrap();
        let reference: Vec<f64> = x
            .chunks(d)
            .flat_map(|p| encode_reference(p, bands))
            .collect();
        let worst = ours
            .iter()
            .zip(&reference)
            .map(|(&a, &b)| (a as f64 - b).abs())
            .fold(0.0, f64::max);
        // 2^9 x in f32 loses ~1e-4 of phase at |x| = 1.5.
        assert!(worst < 2e-3, "d {d}, L {bands}: max difference {worst}");
        // The host encoding of the hand-written training step: the same layout and values.
        let width = encoded_width(d, bands);
        let mut host = vec![0f32; n * width];
        for (p, out) in x.chunks(d).zip(host.chunks_mut(width)) {
            let p: Vec<f32> = p.iter().map(|&v| v as f32).collect();
            encode_into(&p, bands, out);
        }
        let worst = host
            .iter()
            .zip(&reference)
            .map(|(&a, &b)| (a as f64 - b).abs())
            .fold(0.0, f64::max);
        assert!(
            worst < 2e-3,
            "host, d {d}, L {bands}: max difference {worst}"
        );
    }
}

#[test]
fn virtual_frames_match_nalgebra_and_undo_the_first_two_joints() {
    let dev = Device::flex();
    let n = 9;
    let p = values(n * 3, 1, 0.4);
    let a = values(n * 2, 2, 3.0);
    let a0: Vec<f64> = a.iter().step_by(2).copied().collect();
    let a1: Vec<f64> = a.iter().skip(1).step_by(2).copied().collect();
    let angles = |v: &[f64]| {
        Tensor::<1>::from_data(
            v.iter().map(|&x| x as f32).collect::<Vec<_>>().as_slice(),
            &dev,
        )
    };
    let (robot, joints) = offset_arm(5, 1.7);
    for frame in [
        VirtualFrame::Reimplementation,
        VirtualFrame::Original,
        joints.clone(),
    ] {
        let frame = &frame;
        let ours = to_virtual(frame, tensor(&p, [n, 3], &dev), angles(&a0), angles(&a1))
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        for i in 0..n {
            let r =
                to_virtual_reference(frame, [p[3 * i], p[3 * i + 1], p[3 * i + 2]], a0[i], a1[i]);
            for k in 0..3 {
                assert!(
                    (ours[3 * i + k] as f64 - r[k]).abs() < 1e-5,
                    "{frame:?} point {i}: {:?} vs {r:?}",
                    &ours[3 * i..3 * i + 3]
                );
            }
        }
    }
    // The reimplementation's frame undoes p = Ry(a1) Rz(a0) v: a point fixed in the frame of
    // the first two joints has the same virtual coordinates whatever those joints are.
    let v = [0.1, -0.05, 0.2];
    for (a0, a1) in [(0.0, 0.0), (0.7, -0.4), (-2.0, 1.3)] {
        let rz = nalgebra::Rotation3::from_axis_angle(&nalgebra::Vector3::z_axis(), a0);
        let ry = nalgebra::Rotation3::from_axis_angle(&nalgebra::Vector3::y_axis(), a1);
        let world = ry * (rz * nalgebra::Vector3::from(v));
        let back = to_virtual_reference(&VirtualFrame::Reimplementation, world.into(), a0, a1);
        for k in 0..3 {
            assert!((back[k] - v[k]).abs() < 1e-12);
        }
    }
    // The robot's own frame undoes its first two joints, pivots included, in the shrunk
    // scene: a point on the third link (distal joints still) keeps its virtual coordinates,
    // while the paper's frame, turning about the origin, lets it move.
    let scale = 1.7;
    let on_link = nalgebra::Point3::new(0.02, -0.01, 0.05);
    let seen = |frame: &VirtualFrame, a0: f64, a1: f64| {
        let q = [a0, a1, 0.0, 0.0, 0.0];
        let world = robot.chain.link_frames(&q)[robot.chain.joints[2].child] * on_link;
        to_virtual_reference(frame, (world.coords / scale).into(), a0, a1)
    };
    let rest = seen(&joints, 0.0, 0.0);
    for (a0, a1) in [(0.7, -0.4), (-2.0, 1.3), (1.1, 0.6)] {
        let moved = seen(&joints, a0, a1);
        for k in 0..3 {
            assert!((moved[k] - rest[k]).abs() < 1e-12, "{moved:?} vs {rest:?}");
        }
    }
    let (paper_rest, paper_moved) = (
        seen(&VirtualFrame::Original, 0.0, 0.0),
        seen(&VirtualFrame::Original, 0.7, -0.4),
    );
    let drift: f64 = (0..3)
        .map(|k| (paper_rest[k] - paper_moved[k]).powi(2))
        .sum();
    assert!(
        drift.sqrt() > 0.01,
        "the paper's frame drifts {}",
        drift.sqrt()
    );
}

#[test]
fn occupancy_field_parameter_counts_match_both_implementations() {
    use selfmodel::core::preset::Preset;
    use selfmodel::self_models::ffksm::field::OccupancyFieldConfig;
    let dev = Device::flex();
    let paper = OccupancyFieldConfig::paper().init(&dev, 0).unwrap();
    let original = OccupancyFieldConfig::original().init(&dev, 0).unwrap();
    use burn::module::Module;
    assert_eq!(paper.num_params(), 93_922);
    assert_eq!(original.num_params(), 83_810);
}

#[test]
fn every_joint_and_coordinate_reaches_the_occupancy_output() {
    // The reimplementation lost two joints to a slicing bug for 2,000 steps: each of the four
    // angles and three coordinates must change the output and receive a gradient.
    use selfmodel::core::preset::Preset;
    use selfmodel::self_models::ffksm::field::OccupancyFieldConfig;
    let dev = Device::flex().autodiff();
    for cfg in [
        OccupancyFieldConfig::paper(),
        OccupancyFieldConfig::original(),
    ] {
        let field = cfg.init(&dev, 3).unwrap();
        let n = 16;
        let points = tensor(&values(n * 3, 5, 0.3), [n, 3], &dev).require_grad();
        let angles = tensor(&values(n * 4, 6, 1.2), [n, 4], &dev).require_grad();
        let out = field.forward(points.clone(), angles.clone());
        assert_eq!(out.dims(), [n, 2]);
        let grads = out.sum().backward();
        for (name, g, width) in [
            ("angle", angles.grad(&grads).unwrap(), 4),
            ("coordinate", points.grad(&grads).unwrap(), 3),
        ] {
            let g = g.into_data().try_to_vec::<f32>().unwrap();
            for k in 0..width {
                let norm: f32 = g.iter().skip(k).step_by(width).map(|v| v * v).sum();
                assert!(
                    norm > 1e-12,
                    "{:?}: {name} {k} gets no gradient",
                    cfg.virtual_frame
                );
            }
        }
    }
}

#[test]
fn ray_marching_samples_and_composites_as_the_paper_defines() {
    use selfmodel::self_models::ffksm::marcher::{
        MarchConfig, composite, composite_reference, sample_points,
    };
    use selfmodel::sim::camera::Camera;
    let dev = Device::flex();
    let march = MarchConfig::paper();
    // Bin centres, and stratified samples inside their bins.
    let centres = march.depths(2, None);
    assert_eq!(centres.len(), 128);
    assert!((centres[0] - (0.6 + 0.4 / 64.0)).abs() < 1e-12);
    let jittered = march.depths(2, Some(7));
    let step = 0.8 / 64.0;
    for (i, t) in jittered.iter().enumerate() {
        let lo = 0.6 + (i % 64) as f64 * step;
        assert!(
            *t >= lo && *t < lo + step,
            "sample {i} at {t} leaves its bin"
        );
    }
    // The centre pixel's ray is the camera axis: depth 1 m from eye [1, 0, 0] is the origin.
    let cam = Camera::paper();
    let centre = 50 * cam.width + 50;
    let p = sample_points(&cam, &[centre], &[1.0], &dev)
        .into_data()
        .try_to_vec::<f32>()
        .unwrap();
    assert!(p.iter().all(|v| v.abs() < 1e-6), "{p:?}");
    // Compositing against the per-ray reference, negative densities clamped by the ReLU.
    let raw = values(3 * 5 * 2, 9, 2.0);
    let ours = composite(tensor(&raw, [15, 2], &dev), 5)
        .into_data()
        .try_to_vec::<f32>()
        .unwrap();
    for r in 0..3 {
        let ray: Vec<(f64, f64)> = (0..5)
            .map(|k| (raw[(r * 5 + k) * 2], raw[(r * 5 + k) * 2 + 1]))
            .collect();
        assert!((ours[r] as f64 - composite_reference(&ray)).abs() < 1e-5);
    }
}

#[test]
fn dense_rendering_is_the_same_in_chunks_and_counts_its_evaluations() {
    use selfmodel::core::preset::Preset;
    use selfmodel::self_models::ffksm::field::OccupancyFieldConfig;
    use selfmodel::self_models::ffksm::marcher::{MarchConfig, expected_depth, render_dense};
    use selfmodel::sim::camera::Camera;
    let dev = Device::flex();
    let field = OccupancyFieldConfig::quick().init(&dev, 1).unwrap();
    let cam = Camera::paper();
    let march = MarchConfig {
        samples: 8,
        ..MarchConfig::paper()
    };
    let pixels: Vec<usize> = (0..37).map(|i| i * 211 % 10_000).collect();
    let angles = [0.3, -0.2, 0.5, 0.1];
    let render = |chunk| {
        render_dense(
            &field,
            (&cam, &angles[..]),
            &pixels,
            &march,
            None,
            chunk,
            &dev,
        )
    };
    let (whole, whole_depth, evals) = render(1000);
    let (parts, parts_depth, _) = render(5);
    assert_eq!(evals, 37 * 8);
    assert_eq!(whole.dims(), [37]);
    let close = |a: Tensor<1>, b: Tensor<1>| {
        let (a, b) = (
            a.into_data().try_to_vec::<f32>().unwrap(),
            b.into_data().try_to_vec::<f32>().unwrap(),
        );
        a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-5)
    };
    assert!(close(whole, parts));
    assert!(close(whole_depth, parts_depth));
    // Expected depth of one ray whose only weight sits at the second sample: that sample's depth.
    let raw = tensor(&[-1.0, 1.0, 50.0, 1.0, -1.0, 1.0], [3, 2], &dev);
    let d = expected_depth(raw, &[0.7, 0.9, 1.1], 3)
        .into_data()
        .try_to_vec::<f32>()
        .unwrap();
    assert!((d[0] - 0.9).abs() < 1e-5, "{d:?}");
}

#[test]
fn the_one_pose_fast_path_is_the_general_forward() {
    use selfmodel::core::preset::Preset;
    use selfmodel::self_models::ffksm::field::OccupancyFieldConfig;
    let dev = Device::flex();
    let n = 11;
    let points = tensor(&values(n * 3, 4, 0.4), [n, 3], &dev);
    let pose = [0.4f32, -0.9, 1.3, -0.2];
    let repeated: Vec<f64> = (0..n).flat_map(|_| pose.map(|v| v as f64)).collect();
    let joints = OccupancyFieldConfig {
        virtual_frame: offset_arm(4, 2.3).1,
        ..OccupancyFieldConfig::original()
    };
    for cfg in [
        OccupancyFieldConfig::paper(),
        OccupancyFieldConfig::original(),
        joints,
    ] {
        let field = cfg.init(&dev, 2).unwrap();
        let general = field
            .forward(points.clone(), tensor(&repeated, [n, 4], &dev))
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        let fast = field
            .forward_pose(points.clone(), &pose)
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        let worst = general
            .iter()
            .zip(&fast)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f32::max);
        assert!(worst < 1e-5, "{:?}: differs by {worst}", cfg.virtual_frame);
    }
}

#[test]
fn the_accelerated_marcher_with_every_cell_occupied_is_dense_marching() {
    use selfmodel::core::preset::Preset;
    use selfmodel::self_models::ffksm::accelerated_marcher::{
        AcceleratedConfig, render_accelerated,
    };
    use selfmodel::self_models::ffksm::field::OccupancyFieldConfig;
    use selfmodel::self_models::ffksm::marcher::{MarchConfig, render_dense};
    use selfmodel::sim::camera::Camera;
    let dev = Device::flex();
    let field = OccupancyFieldConfig::quick().init(&dev, 5).unwrap();
    let cam = Camera {
        width: 20,
        height: 14,
        ..Camera::paper()
    };
    let march = MarchConfig {
        samples: 12,
        ..MarchConfig::paper()
    };
    let angles = [0.2, 0.4, -0.3, 0.8];
    let mut cfg = AcceleratedConfig::paper();
    cfg.grid.density_threshold = f32::NEG_INFINITY;
    cfg.grid.block = 3;
    cfg.termination = None;
    let fast = render_accelerated(&field, (&cam, &angles[..]), &march, &cfg, &dev);
    let all: Vec<usize> = (0..cam.width * cam.height).collect();
    let (sil, depth, evals) =
        render_dense(&field, (&cam, &angles[..]), &all, &march, None, 64, &dev);
    assert_eq!(fast.evaluations, evals + fast.grid_evaluations);
    assert_eq!(fast.grid_occupancy, 1.0);
    for (name, dense, ours) in [
        ("silhouette", sil, &fast.silhouette),
        ("depth", depth, &fast.depth),
    ] {
        let dense = dense.into_data().try_to_vec::<f32>().unwrap();
        let worst = dense
            .iter()
            .zip(ours)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f32::max);
        assert!(worst < 1e-4, "{name} differs by {worst}");
    }
}

#[test]
fn a_tiny_trained_ffksm_beats_black_and_renders_the_same_with_fewer_evaluations() {
    use selfmodel::core::device::DeviceChoice;
    use selfmodel::self_models::ffksm::{
        FfksmVariant, NovelViewRow, RendererRow, centre_crop, ffksm_run,
    };
    // The curriculum's crop: the central pixels, row by row.
    assert_eq!(centre_crop(4, 6, 2), vec![8, 9, 14, 15]);
    let mut cfg = ffksm_run("quick", FfksmVariant::Reimplementation).unwrap();
    cfg.model.novel_views_deg = vec![30.0];
    let tmp = common::tempdir();
    let dir = tmp.path().to_path_buf();
    // With the study's reports of the field's own (its renderers compared, novel views).
    let out =
        selfmodel_lab::studies::models::run_studied(&cfg, &dir, DeviceChoice::Cpu, false).unwrap();
    assert!(
        out.rows[1].note.contains("network evaluations per image"),
        "{}",
        out.rows[1].note
    );
    // Its saved field loads with its robot and camera and renders as its run did.
    common::the_saved_model_scores_as_its_run(&cfg, &dir, &out.quality);
    let read = selfmodel::report::table::read_csv::<RendererRow>;
    let renderers = read(&dir.join("renderers.csv")).unwrap();
    let novel_views =
        selfmodel::report::table::read_csv::<NovelViewRow>(&dir.join("novel_views.csv")).unwrap();
    // A constant black image on the same test images.
    let black = common::black_psnr(&cfg.data, None);
    let [dense, fast] = [&renderers[0], &renderers[1]];
    assert!(
        dense.psnr_db_test > black + 1.0 && dense.iou_test > 0.2,
        "trained {:.2} dB (IoU {:.3}) against black {black:.2} dB",
        dense.psnr_db_test,
        dense.iou_test
    );
    assert!(
        (fast.psnr_db_test - dense.psnr_db_test).abs() <= 0.1,
        "accelerated {:.3} dB, dense {:.3} dB",
        fast.psnr_db_test,
        dense.psnr_db_test
    );
    assert!(
        fast.fewer_evaluations > 2.0,
        "only {:.2}x fewer",
        fast.fewer_evaluations
    );
    assert_eq!(novel_views.len(), 2);
    for f in [
        "results.csv",
        "renderers.csv",
        "novel_views.csv",
        "qualitative.png",
        "novel_views.png",
        "training_curve.png",
        "config.json",
    ] {
        assert!(dir.join(f).is_file(), "{f} missing");
    }
}

#[test]
fn a_field_that_renders_black_is_restarted_then_trained_once_without_the_check() {
    use selfmodel::core::device::DeviceChoice;
    use selfmodel::self_models::ffksm::{FfksmVariant, ffksm_run};
    let mut cfg = ffksm_run("quick", FfksmVariant::Original).unwrap();
    // Every density starts far below zero: ReLU gives no gradient and the image stays black.
    cfg.model.field.output_bias = -50.0;
    cfg.train.steps = 40;
    if let Some(r) = cfg.model.restart.as_mut() {
        r.every = 10;
        r.until = 20;
        r.max_restarts = 2;
    }
    let tmp = common::tempdir();
    let dir = tmp.path().to_path_buf();
    // After `max_restarts` collapses the last try trains to the end, and its row says so (a
    // robot the field cannot pick up gets a row with its low score, not an error).
    let out = selfmodel::self_models::harness::run(&cfg, &dir, DeviceChoice::Cpu, false).unwrap();
    let note = &out.result.note;
    assert!(
        note.contains("2 restarts after collapse")
            && note.contains("the last try trained without the collapse check"),
        "{note}"
    );
    assert_eq!(out.log.step, 40);
    assert!(
        out.result.iou_test < 0.05,
        "a black field: IoU {}",
        out.result.iou_test
    );
    // The restarts are kept beside the checkpoint, so a resumed run reports them.
    let kept = std::fs::read_to_string(dir.join("checkpoint/restarts.json")).unwrap();
    assert_eq!(kept.trim(), "2");
}

/// The hand-written dense training step against burn's autodiff through the dense marcher and
/// the weighted MSE: the same loss and the same gradient for every parameter, for both
/// architectures (with and without the ReLU before the output, the three virtual frames), on the
/// curriculum's crop and with the robot-pixel weight; and the same numbers bit for bit on one
/// thread as on all of them.
#[test]
fn the_hand_written_dense_step_matches_autodiff() {
    use burn::optim::GradientsParams;
    use selfmodel::core::preset::Preset;
    use selfmodel::self_models::ffksm::dense_step::dense_step;
    use selfmodel::self_models::ffksm::field::OccupancyFieldConfig;
    use selfmodel::self_models::ffksm::marcher::{MarchConfig, render_silhouette};
    use selfmodel::self_models::ffksm::{FfksmVariant, ffksm_run, weighted_mse};

    let cfg = ffksm_run("quick", FfksmVariant::Reimplementation).unwrap();
    let camera = cfg.data.dataset.camera.clone();
    let (h, w) = (camera.height, camera.width);
    let pixels: Vec<usize> = (0..90)
        .map(|i| (h / 4 + i / 9) * w + w / 3 + 2 * (i % 9))
        .collect();
    let truth: Vec<f32> = values(pixels.len(), 5, 1.0)
        .iter()
        .map(|v| if *v > 0.3 { 1.0 } else { v.abs() as f32 * 0.2 })
        .collect();
    let march = MarchConfig {
        samples: 24,
        ..MarchConfig::paper()
    };
    let original = OccupancyFieldConfig {
        bands: 4,
        ..OccupancyFieldConfig::original()
    };
    let small_original = OccupancyFieldConfig {
        encoder_width: 24,
        predictive_hidden: vec![20, 12],
        ..original
    };
    // The robot's own frame adds a shift to the paper's rotation.
    let small_joints = OccupancyFieldConfig {
        virtual_frame: offset_arm(4, 2.0).1,
        ..small_original.clone()
    };
    let fields = [OccupancyFieldConfig::quick(), small_original, small_joints];
    for (f, field_cfg) in fields.iter().enumerate() {
        let dev = Device::flex();
        let tdev = dev.clone().autodiff();
        // The third field starts as the second, only its frame differs.
        let field = field_cfg.init(&tdev, [3, 4, 4][f]).unwrap();
        let angles = [0.3, -0.4, 0.7, 1.1];
        for (robot_weight, jitter) in [(1.0, Some(11u64)), (5.0, None)] {
            let reference = {
                let pred = render_silhouette(
                    &field,
                    (&camera, &angles[..]),
                    &pixels,
                    &march,
                    jitter,
                    &tdev,
                );
                weighted_mse(pred, &truth, robot_weight)
            };
            let loss_ref = reference.clone().into_scalar::<f32>() as f64;
            let grads_ref = GradientsParams::from_grads(reference.backward(), &field);
            let step = || {
                dense_step(
                    &field,
                    (&camera, &angles[..]),
                    &pixels,
                    &truth,
                    robot_weight,
                    &march,
                    jitter,
                    &dev,
                )
            };
            let fast = step();
            assert!(
                (fast.loss - loss_ref).abs() <= 1e-5 * loss_ref.abs().max(1e-6),
                "field {f}: loss {} against autodiff's {loss_ref}",
                fast.loss
            );
            let (coordinates, kinematics, predictive) = field.layers();
            let host1 = |t: Tensor<1>| t.into_data().try_into_vec::<f32>().unwrap();
            let host2 = |t: Tensor<2>| t.into_data().try_into_vec::<f32>().unwrap();
            let mut checked = 0;
            for (l, layer) in coordinates
                .iter()
                .chain(kinematics)
                .chain(predictive)
                .enumerate()
            {
                let pairs = [
                    (
                        host2(grads_ref.get::<2>(layer.weight.id).unwrap()),
                        host2(fast.gradients.get::<2>(layer.weight.id).unwrap()),
                    ),
                    (
                        host1(grads_ref.get::<1>(layer.bias.as_ref().unwrap().id).unwrap()),
                        host1(
                            fast.gradients
                                .get::<1>(layer.bias.as_ref().unwrap().id)
                                .unwrap(),
                        ),
                    ),
                ];
                for (want, got) in pairs {
                    assert_eq!(want.len(), got.len());
                    let scale = want.iter().fold(0f32, |m, v| m.max(v.abs()));
                    assert!(scale > 0.0, "field {f}, layer {l}: no gradient to compare");
                    let worst = want
                        .iter()
                        .zip(&got)
                        .fold(0f32, |m, (a, b)| m.max((a - b).abs()));
                    assert!(
                        worst <= 2e-4 * scale,
                        "field {f}, layer {l}, weight {robot_weight}: gradients differ by {worst} (largest {scale})"
                    );
                    checked += 1;
                }
            }
            assert_eq!(checked, 2 * (4 + predictive.len()));
            // One thread gives the same bits as all of them.
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .build()
                .unwrap();
            let single = pool.install(step);
            assert_eq!(single.loss.to_bits(), fast.loss.to_bits());
            let w0 = coordinates[0].weight.id;
            assert_eq!(
                host2(single.gradients.get::<2>(w0).unwrap()),
                host2(fast.gradients.get::<2>(w0).unwrap())
            );
        }
    }
}

/// Training with the hand-written dense step follows training with burn's autodiff: the
/// same data, seed and schedule give the same loss curve (to float rounding while rounding is
/// all that separates them) and the same test PSNR.
#[test]
fn training_with_the_hand_written_step_follows_autodiff() {
    use selfmodel::core::device::DeviceChoice;
    use selfmodel::self_models::ffksm::{DenseGradients, FfksmVariant, ffksm_run};
    let mut outcomes = Vec::new();
    for path in [DenseGradients::Autodiff, DenseGradients::HandWrittenOnCpu] {
        let mut cfg = ffksm_run("quick", FfksmVariant::Reimplementation).unwrap();
        cfg.train.steps = 80;
        cfg.train.checkpoint_every = 0;
        let start = cfg.data.dataset.train;
        cfg.data.test = Some(start..start + 3);
        cfg.model.novel_views_deg = vec![];
        cfg.model.dense_gradients = path;
        let tmp = common::tempdir();
        let dir = tmp.path().to_path_buf();
        outcomes.push(
            selfmodel::self_models::harness::run(&cfg, &dir, DeviceChoice::Cpu, false).unwrap(),
        );
    }
    let (a, b) = (&outcomes[0], &outcomes[1]);
    assert!(
        b.rows[0].note.contains("hand-written"),
        "{}",
        b.rows[0].note
    );
    assert!(
        !a.rows[0].note.contains("hand-written"),
        "{}",
        a.rows[0].note
    );
    assert_eq!(a.log.curve.len(), b.log.curve.len());
    let first = a.log.curve[0].1;
    let last = a.log.curve.last().unwrap().1;
    assert!(
        last < 0.8 * first,
        "autodiff did not learn: {first} -> {last}"
    );
    // The same to float rounding for 30 steps (measured: within 1e-7); after that Adam, which
    // divides by the gradients' running size, amplifies the rounding of near-zero components
    // (1e-3 apart by step 64), so later steps are only required to stay close.
    for ((step, la), (_, lb)) in a.log.curve.iter().zip(&b.log.curve) {
        let limit = if *step <= 30 { 1e-6 } else { 2e-2 };
        assert!(
            (la - lb).abs() <= limit * la.abs(),
            "step {step}: autodiff loss {la}, hand-written {lb}"
        );
    }
    let (pa, pb) = (a.rows[0].psnr_db_test, b.rows[0].psnr_db_test);
    assert!((pa - pb).abs() < 0.05, "test PSNR {pa} against {pb}");
}

/// The step benchmark: both paths of both architectures, the same loss on the same step, the
/// reference's speedup 1, and the paper field's arithmetic counted from its layers.
#[test]
fn the_step_benchmark_times_both_paths_on_the_same_step() {
    use selfmodel::core::device::DeviceChoice;
    use selfmodel::core::preset::Preset;
    use selfmodel::self_models::ffksm::field::OccupancyFieldConfig;
    use selfmodel_lab::studies::bench::ffksm_step::run;
    // Per point, forward: 33x128 + 128x128 (coordinate encoder), 128x128 (first layer's
    // coordinate half), 128x128 + 128x32 + 32x2 = 57,536 multiply-adds; backward twice that
    // less the first layer's input gradient (33x128): 110,848.
    let field = OccupancyFieldConfig::paper()
        .init(&Device::flex(), 0)
        .unwrap();
    assert_eq!(field.step_flop(1), 2.0 * (57_536.0 + 110_848.0));
    let rows = run(DeviceChoice::Cpu, true, 1).unwrap();
    assert_eq!(rows.len(), 4);
    for pair in rows.chunks(2) {
        let (a, h) = (&pair[0], &pair[1]);
        assert_eq!(
            (a.path.as_str(), h.path.as_str()),
            ("autodiff", "hand-written")
        );
        assert_eq!(a.speedup, 1.0);
        assert!(a.seconds_median > 0.0 && h.seconds_median > 0.0 && h.gflop > 0.0);
        assert!(
            (a.loss - h.loss).abs() <= 1e-5 * a.loss.abs(),
            "{}: losses {} and {}",
            a.model,
            a.loss,
            h.loss
        );
    }
}

/// A checkpoint's fingerprint leaves out the robot when it is the papers' arm4, so checkpoints
/// from before the robot was recorded resume; one made for another robot is refused.
#[test]
fn a_checkpoint_without_a_recorded_robot_resumes_and_one_of_another_robot_is_refused() {
    use selfmodel::core::device::DeviceChoice;
    use selfmodel::self_models::ffksm::{FfksmVariant, ffksm_run};
    use selfmodel::self_models::{data_spec::DataSpec, harness::run};
    use selfmodel::sim::robots::RobotSpec;
    let urdf = RobotSpec::Urdf {
        path: "robot.urdf".into(),
        base_xyz: [0.0; 3],
        base_rpy: [0.0; 3],
        tip: None,
        geometry: Default::default(),
        joints: Default::default(),
    };
    let mut other = DataSpec::paper();
    other.robot = urdf.clone();
    assert!(DataSpec::paper().fingerprint().get("robot").is_none());
    assert!(other.fingerprint().get("robot").is_some());

    let mut cfg = ffksm_run("quick", FfksmVariant::Original).unwrap();
    cfg.train.steps = 4;
    cfg.train.checkpoint_every = 2;
    let dir = common::tempdir();
    let out = dir.path().join("run");
    run(&cfg, &out, DeviceChoice::Cpu, false).unwrap();
    let state_path = out.join("checkpoint/state.json");
    let mut state: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&state_path).unwrap()).unwrap();
    let data = &state["fingerprint"]["data"];
    assert!(data.get("dataset").is_some(), "{data}");
    assert!(data.get("robot").is_none(), "{data}");
    cfg.train.steps = 6;
    run(&cfg, &out, DeviceChoice::Cpu, true).expect("the arm4 checkpoint resumes");

    state["fingerprint"]["data"]["robot"] = serde_json::to_value(&urdf).unwrap();
    std::fs::write(&state_path, state.to_string()).unwrap();
    cfg.train.steps = 8;
    let err = run(&cfg, &out, DeviceChoice::Cpu, true)
        .err()
        .expect("another robot's checkpoint must be refused")
        .to_string();
    assert!(err.contains("different configuration"), "{err}");
}

/// `--resume` over a damaged `evaluations.json` is an error naming it, not a run that reports
/// "0 evaluations per step".
#[test]
fn a_damaged_evaluation_count_is_an_error_on_resume() {
    use selfmodel::core::device::DeviceChoice;
    use selfmodel::self_models::ffksm::{FfksmVariant, ffksm_run};
    let mut cfg = ffksm_run("quick", FfksmVariant::Reimplementation).unwrap();
    cfg.train.steps = 20;
    cfg.train.checkpoint_every = 10;
    let dir = common::tempdir();
    selfmodel::self_models::harness::run(&cfg, dir.path(), DeviceChoice::Cpu, false).unwrap();
    let counts = dir.path().join("checkpoint/evaluations.json");
    assert!(counts.is_file());
    std::fs::write(&counts, "[12, oops").unwrap();
    let err = selfmodel::self_models::harness::run(&cfg, dir.path(), DeviceChoice::Cpu, true)
        .err()
        .expect("a damaged count must not pass")
        .to_string();
    assert!(
        err.contains("evaluations.json") && err.contains("damaged") && !err.contains('\n'),
        "{err}"
    );
}

/// `ffksm --resume` with a foreign checkpoint in its second model refuses before it rewrites
/// anything of the first model (it checks every checkpoint first).
#[test]
fn a_foreign_checkpoint_in_a_later_model_is_refused_before_anything_is_written() {
    use selfmodel_lab::studies::registry::{RunOptions, find};
    let dir = common::tempdir();
    let ffksm = find("ffksm").unwrap();
    let mut opts = RunOptions::preset("quick");
    opts.steps = Some(30);
    (ffksm.run)(&opts, dir.path()).unwrap();
    // The second model's checkpoint now claims another configuration.
    let state = dir.path().join("ffksm_original/checkpoint/state.json");
    let text = std::fs::read_to_string(&state).unwrap();
    let mut json: serde_json::Value = serde_json::from_str(&text).unwrap();
    json["fingerprint"] = serde_json::json!({"another": "model"});
    std::fs::write(&state, json.to_string()).unwrap();
    let first = dir.path().join("ffksm/results.csv");
    let before = std::fs::read(&first).unwrap();
    let modified = std::fs::metadata(&first).unwrap().modified().unwrap();
    opts.resume = true;
    let err = (ffksm.run)(&opts, dir.path()).unwrap_err().to_string();
    assert!(
        err.contains("ffksm_original") && err.contains("different configuration"),
        "{err}"
    );
    assert_eq!(std::fs::read(&first).unwrap(), before);
    assert_eq!(
        std::fs::metadata(&first).unwrap().modified().unwrap(),
        modified
    );
}
