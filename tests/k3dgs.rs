//! K-3DGS against its references: tensor forward kinematics against the foundation's,
//! projection against the simulator's camera, culled splatting against dense splatting, the
//! anisotropic projection against its formula in f64, and a tiny trained model.

mod common;

use burn::tensor::{Device, Tensor, TensorData};
use selfmodel::sim::tensor_kinematics::TensorChain;

#[test]
fn tensor_forward_kinematics_matches_the_foundations_for_every_link() {
    let dev = Device::flex();
    let chain = selfmodel::sim::arm4::chain();
    let tc = TensorChain::new(&chain);
    let qs: Vec<Vec<f64>> = (0..5)
        .map(|i| {
            (0..4)
                .map(|k| ((i * 7 + k * 3) % 11) as f64 * 0.37 - 1.8)
                .collect()
        })
        .collect();
    let flat: Vec<f32> = qs.iter().flatten().map(|&v| v as f32).collect();
    let q = Tensor::<2>::from_data(TensorData::new(flat, [5, 4]), &dev);
    let (r, t) = tc.link_frames(q);
    assert_eq!(r.dims(), [5, tc.links(), 3, 3]);
    let r = r.into_data().try_to_vec::<f32>().unwrap();
    let t = t.into_data().try_to_vec::<f32>().unwrap();
    for (b, q) in qs.iter().enumerate() {
        for (l, frame) in chain.link_frames(q).iter().enumerate() {
            let m = frame.rotation.to_rotation_matrix();
            for i in 0..3 {
                let tt = t[(b * tc.links() + l) * 3 + i] as f64;
                assert!(
                    (tt - frame.translation.vector[i]).abs() < 1e-5,
                    "pose {b} link {l}"
                );
                for j in 0..3 {
                    let rr = r[((b * tc.links() + l) * 3 + i) * 3 + j] as f64;
                    assert!(
                        (rr - m[(i, j)]).abs() < 1e-5,
                        "pose {b} link {l} R[{i}][{j}]"
                    );
                }
            }
        }
    }
}

/// `n` Gaussians in front of the paper's camera (around the origin), deterministic.
fn scene(n: usize, dev: &Device) -> (Tensor<3>, Tensor<1>, Tensor<1>) {
    let v = |i: usize, k: u32| {
        (((i as u32)
            .wrapping_mul(2_654_435_761)
            .wrapping_add(k * 40503))
            >> 8) as f32
            / (1 << 24) as f32
    };
    let means: Vec<f32> = (0..n)
        .flat_map(|i| {
            [
                0.3 * (v(i, 1) - 0.5),
                0.5 * (v(i, 2) - 0.5),
                0.5 * (v(i, 3) - 0.5),
            ]
        })
        .collect();
    let scales: Vec<f32> = (0..n).map(|i| 0.005 + 0.02 * v(i, 4)).collect();
    let opacity: Vec<f32> = (0..n).map(|i| 0.2 + 0.7 * v(i, 5)).collect();
    (
        Tensor::from_data(TensorData::new(means, [1, n, 3]), dev),
        Tensor::from_data(TensorData::new(scales, [n]), dev),
        Tensor::from_data(TensorData::new(opacity, [n]), dev),
    )
}

#[test]
fn a_gaussian_lands_on_the_pixel_where_the_simulator_draws_its_point() {
    use selfmodel::self_models::k3dgs::splatting::project_isotropic;
    use selfmodel::sim::camera::Camera;
    use selfmodel::sim::ray_caster::RayCaster;
    let dev = Device::flex();
    let robot = selfmodel::sim::arm4::arm4();
    let camera = Camera::paper();
    let q = robot.chain.to_si(&[20.0, -30.0, 40.0, 10.0]);
    let frame = RayCaster::new(&robot, camera.clone(), Default::default()).render(&q);
    // Points the simulator drew: the eye plus depth along the ray of robot pixels.
    let picks: Vec<usize> = (0..camera.width * camera.height)
        .filter(|&p| frame.depth[p] > 0.0)
        .step_by(37)
        .take(20)
        .collect();
    assert!(picks.len() >= 10);
    let cf = camera.frame();
    let points: Vec<f32> = picks
        .iter()
        .flat_map(|&p| {
            let ray = cf.ray((p / camera.width) as f64, (p % camera.width) as f64);
            let x = ray.origin + ray.dir * frame.depth[p] as f64;
            [x.x as f32, x.y as f32, x.z as f32]
        })
        .collect();
    let n = picks.len();
    let g = project_isotropic(
        Tensor::from_data(TensorData::new(points, [1, n, 3]), &dev),
        Tensor::ones([n], &dev).mul_scalar(0.01),
        Tensor::ones([n], &dev),
        &camera,
    );
    let rows = g.row.into_data().try_to_vec::<f32>().unwrap();
    let cols = g.col.into_data().try_to_vec::<f32>().unwrap();
    let depth = g.depth.into_data().try_to_vec::<f32>().unwrap();
    for (k, &p) in picks.iter().enumerate() {
        let (r, c) = ((p / camera.width) as f32, (p % camera.width) as f32);
        assert!(
            (rows[k] - r).abs() < 1e-3 && (cols[k] - c).abs() < 1e-3,
            "pixel {p}: ({}, {})",
            rows[k],
            cols[k]
        );
        assert!((depth[k] - frame.depth[p]).abs() < 1e-4);
    }
}

#[test]
fn culled_splatting_matches_the_dense_reference() {
    use selfmodel::self_models::k3dgs::splatting::{
        Compositing, project_isotropic, render_culled, render_dense,
    };
    use selfmodel::sim::camera::Camera;
    let dev = Device::flex();
    let camera = Camera {
        width: 40,
        height: 30,
        ..Camera::paper()
    };
    let (means, scales, opacity) = scene(60, &dev);
    let g = project_isotropic(means, scales, opacity, &camera);
    let worst = |a: Tensor<2>, b: Tensor<2>| {
        let (a, b) = (
            a.into_data().try_to_vec::<f32>().unwrap(),
            b.into_data().try_to_vec::<f32>().unwrap(),
        );
        a.iter()
            .zip(&b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f32::max)
    };
    for mode in [
        Compositing::Alpha,
        Compositing::SigmoidSum { temperature: 10.0 },
    ] {
        let (ds, dd) = render_dense(&g, 30, 40, mode);
        // Wide enough that every dropped footprint is below exp(-18).
        let (cs, cd) = render_culled(&g, 30, 40, mode, 6.0);
        assert!(worst(ds.clone(), cs) < 1e-4, "{mode:?} silhouette");
        // Depth where something is drawn (elsewhere it is a ratio of vanishing weights).
        let drawn: Vec<f32> = render_dense(&g, 30, 40, Compositing::Alpha)
            .0
            .into_data()
            .try_to_vec::<f32>()
            .unwrap();
        let (dd, cd) = (
            dd.into_data().try_to_vec::<f32>().unwrap(),
            cd.into_data().try_to_vec::<f32>().unwrap(),
        );
        let depth_worst = drawn
            .iter()
            .zip(dd.iter().zip(&cd))
            .filter(|(s, _)| **s > 0.05)
            .map(|(_, (a, b))| (a - b).abs())
            .fold(0.0, f32::max);
        assert!(
            depth_worst < 1e-3,
            "{mode:?} depth differs by {depth_worst}"
        );
        // At 3 sigma a dropped footprint weighs at most exp(-4.5) of its opacity.
        let (cs, _) = render_culled(&g, 30, 40, mode, 3.0);
        assert!(worst(ds, cs) < 0.1, "{mode:?} silhouette at 3 sigma");
    }
}

#[test]
fn anisotropic_projection_is_the_jacobian_formula_in_f64() {
    use nalgebra::{Matrix2, Matrix2x3, Matrix3, Vector3};
    use selfmodel::self_models::k3dgs::splatting::project_anisotropic;
    use selfmodel::sim::camera::Camera;
    let dev = Device::flex();
    let camera = Camera::paper().orbited(25.0);
    let centres = [[0.05, -0.1, 0.2], [-0.12, 0.08, -0.05], [0.0, 0.0, 0.0]];
    let axes: Vec<Matrix3<f64>> = (0..3)
        .map(|i| {
            Matrix3::from_fn(|r, c| {
                0.01 * (((i * 9 + r * 3 + c) * 7 % 11) as f64 - 5.0) / 5.0
                    + if r == c { 0.02 } else { 0.0 }
            })
        })
        .collect();
    let means: Vec<f32> = centres.iter().flatten().map(|&v| v as f32).collect();
    let a: Vec<f32> = axes
        .iter()
        .flat_map(|m| (0..9).map(move |k| m[(k / 3, k % 3)] as f32))
        .collect();
    let g = project_anisotropic(
        Tensor::from_data(TensorData::new(means, [1, 3, 3]), &dev),
        Tensor::from_data(TensorData::new(a, [1, 3, 3, 3]), &dev),
        Tensor::ones([3], &dev),
        &camera,
    );
    let conic: Vec<Vec<f32>> = g
        .conic
        .iter()
        .map(|t| t.clone().into_data().try_to_vec::<f32>().unwrap())
        .collect();
    let f = camera.frame();
    let w = Matrix3::from_rows(&[f.right.transpose(), f.up.transpose(), f.fwd.transpose()]);
    for (i, c) in centres.iter().enumerate() {
        let p = w * (Vector3::from(*c) - f.eye.coords);
        let (x, y, z) = (p.x, p.y, p.z);
        let j = Matrix2x3::new(
            0.0,
            -f.focal / z,
            f.focal * y / (z * z),
            f.focal / z,
            0.0,
            -f.focal * x / (z * z),
        );
        let sigma = j * w * axes[i] * axes[i].transpose() * w.transpose() * j.transpose()
            + Matrix2::identity() * 0.3;
        let inv = sigma.try_inverse().unwrap();
        for (k, (r, cc)) in [(0, 0), (0, 1), (1, 1)].into_iter().enumerate() {
            let ours = conic[k][i] as f64;
            assert!(
                (ours - inv[(r, cc)]).abs() <= 1e-3 * inv[(r, cc)].abs().max(1e-3),
                "Gaussian {i} conic {k}: {ours} vs {}",
                inv[(r, cc)]
            );
        }
    }
}

#[test]
fn a_tiny_k3dgs_learns_the_arm_and_keeps_its_gaussians_within_bounds() {
    use selfmodel::core::device::DeviceChoice;
    use selfmodel::self_models::k3dgs::{K3dgsVariant, k3dgs_run};
    use selfmodel_lab::studies::models::{k3dgs_reports::CountRow, run_studied};
    let cfg = k3dgs_run("quick", K3dgsVariant::IsotropicAlpha).unwrap();
    let tmp = common::tempdir();
    let dir = tmp.path().to_path_buf();
    // With the study's reports of K-3DGS's own (speeds, counts, the Gaussians' figure).
    let out = run_studied(&cfg, &dir, DeviceChoice::Cpu, false).unwrap();
    let counts: Vec<(usize, usize)> =
        selfmodel::report::table::read_csv::<CountRow>(&dir.join("gaussian_counts.csv"))
            .unwrap()
            .into_iter()
            .map(|c| (c.step, c.gaussians))
            .collect();
    let black = common::black_psnr(&cfg.data, None);
    let r = &out.result;
    assert!(
        r.psnr_db_test > black + 3.0 && r.iou_test > 0.6,
        "{:.2} dB (IoU {:.3}) against black {black:.2} dB",
        r.psnr_db_test,
        r.iou_test
    );
    let d = &cfg.model.densification;
    assert!(counts.len() > 2, "the set never changed: {counts:?}");
    assert!(
        counts
            .iter()
            .skip(1)
            .all(|&(_, n)| n >= d.min_gaussians && n <= d.max_gaussians),
        "{counts:?}"
    );
    for f in [
        "results.csv",
        "render_speed.csv",
        "gaussians.png",
        "qualitative.png",
        "training_curve.png",
    ] {
        assert!(dir.join(f).is_file(), "{f} missing");
    }
    // Its saved model (the Gaussians densification left, on the robot's chain) loads and
    // scores as its run did.
    common::the_saved_model_scores_as_its_run(&cfg, &dir, &out.quality);
}
