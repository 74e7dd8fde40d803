//! Learning a changed arm's link parameters from a small sample of its (joints, end position)
//! pairs by gradient descent through a differentiable forward model: the first fast-adaptation
//! approach of the EMSSL paper (section III-C, Figure 4).
//!
//! The parameters are every joint origin's translation (metres, starting at the nominal arm's)
//! and a rotation correction (roll, pitch, yaw in radians, starting at zero) composed with
//! the nominal origin rotation, plus the end-effector offset: 6 per joint and 3 for the tool,
//! 39 for the UR5. The forward kinematics in tensors ([`TensorChain::end_effector_with`]) is
//! differentiable in all of them; Adam fits them to the sampled positions by mean squared
//! error, in stages of falling learning rate. The result is an ordinary
//! [`KinematicChain`], the updated forward model.

use burn::module::{Module, Param};
use burn::tensor::{Device, Tensor, TensorData};
use nalgebra::{Point3, UnitQuaternion, Vector3};

use crate::core::error::{Error, Result};
use crate::ik::data::distances;
use crate::sim::kinematics::KinematicChain;
use crate::sim::tensor_kinematics::TensorChain;
use crate::train::{
    batcher::{Batch, TrainSet},
    config::TrainConfig,
    trainer::{Trainer, autodiff_device},
};

/// How the link parameters are learned.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CalibrationConfig {
    /// (joints, position) pairs sampled from the changed arm.
    pub samples: usize,
    /// Full-batch Adam steps and their learning rate, stage after stage.
    pub stages: Vec<(usize, f64)>,
    pub seed: u64,
}

impl CalibrationConfig {
    /// 100 samples; 1,500 steps at 1e-3, then 1,500 at 1e-4 and 1,000 at 1e-5.
    pub fn paper() -> Self {
        CalibrationConfig {
            samples: 100,
            stages: vec![(1500, 1e-3), (1500, 1e-4), (1000, 1e-5)],
            seed: 0,
        }
    }
}

/// The learnable link parameters of a chain.
#[derive(Module, Debug)]
pub struct LinkParameters {
    /// Joint origin translations `[J, 3]` (metres).
    translations: Param<Tensor<2>>,
    /// Rotation corrections `[J, 3]` (roll, pitch, yaw; radians), applied before the nominal
    /// origin rotation.
    angles: Param<Tensor<2>>,
    /// End-effector offset `[1, 3]` (metres).
    tip: Param<Tensor<2>>,
    /// Nominal origin rotations `[J, 3, 3]`.
    #[module(skip)]
    nominal_rotations: Tensor<3>,
    #[module(skip)]
    chain: TensorChain,
}

/// Rotations `Rz(yaw) Ry(pitch) Rx(roll)` `[J, 3, 3]` of angles `[J, 3]` (nalgebra's
/// `from_euler_angles(roll, pitch, yaw)`).
fn euler_matrices(angles: Tensor<2>) -> Tensor<3> {
    let [j, _] = angles.dims();
    let part = |k: usize| angles.clone().slice([0..j, k..k + 1]);
    let (sa, ca) = (part(0).sin(), part(0).cos());
    let (sb, cb) = (part(1).sin(), part(1).cos());
    let (sc, cc) = (part(2).sin(), part(2).cos());
    let entries = vec![
        cb.clone() * cc.clone(),
        sa.clone() * sb.clone() * cc.clone() - ca.clone() * sc.clone(),
        ca.clone() * sb.clone() * cc.clone() + sa.clone() * sc.clone(),
        cb.clone() * sc.clone(),
        sa.clone() * sb.clone() * sc.clone() + ca.clone() * cc.clone(),
        ca.clone() * sb.clone() * sc - sa.clone() * cc,
        sb.neg(),
        sa * cb.clone(),
        ca * cb,
    ];
    Tensor::cat(entries, 1).reshape([j, 3, 3])
}

impl LinkParameters {
    /// The nominal arm's parameters on `device`.
    pub fn new(chain: &KinematicChain, device: &Device) -> Self {
        let tensor_chain = TensorChain::new(chain);
        let (r, t, tip) = tensor_chain.origin_rows();
        let j = tensor_chain.joint_count();
        LinkParameters {
            translations: Param::from_tensor(Tensor::from_data(TensorData::new(t, [j, 3]), device)),
            angles: Param::from_tensor(Tensor::zeros([j, 3], device)),
            tip: Param::from_tensor(Tensor::from_data(
                TensorData::new(tip.to_vec(), [1, 3]),
                device,
            )),
            nominal_rotations: Tensor::from_data(TensorData::new(r, [j, 3, 3]), device),
            chain: tensor_chain,
        }
    }

    /// End positions `[B, 3]` (metres) for joints `q` `[B, dof]` (radians).
    pub fn forward(&self, q: Tensor<2>) -> Tensor<2> {
        let rotations = euler_matrices(self.angles.val()).matmul(self.nominal_rotations.clone());
        self.chain
            .end_effector_with(q, rotations, self.translations.val(), self.tip.val())
    }

    /// The nominal chain with these parameters: the updated forward model.
    pub fn to_chain(&self, nominal: &KinematicChain) -> KinematicChain {
        let rows = |t: Tensor<2>| t.into_data().try_into_vec::<f32>().expect("float");
        let t = rows(self.translations.val());
        let a = rows(self.angles.val());
        let tip = rows(self.tip.val());
        let mut chain = nominal.clone();
        for (i, joint) in chain.joints.iter_mut().enumerate() {
            let v = |k: usize, from: &[f32]| from[3 * i + k] as f64;
            joint.origin.translation.vector = Vector3::new(v(0, &t), v(1, &t), v(2, &t));
            let correction = UnitQuaternion::from_euler_angles(v(0, &a), v(1, &a), v(2, &a));
            joint.origin.rotation = correction * joint.origin.rotation;
        }
        chain.tip_offset = Point3::new(tip[0] as f64, tip[1] as f64, tip[2] as f64);
        chain
    }
}

/// What the calibration learned and how well.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct Calibration {
    pub samples: usize,
    /// Mean distance (mm) between the sampled positions and the model's, before and after.
    pub fit_before_mm: f64,
    pub fit_after_mm: f64,
    pub seconds: f64,
}

/// Learn the link parameters of the arm that moved to `positions` (metres) at `joints`
/// (radians), starting from `nominal`. Returns the updated chain.
pub fn calibrate(
    nominal: &KinematicChain,
    joints: &[Vec<f64>],
    positions: &[Point3<f64>],
    cfg: &CalibrationConfig,
    device: &Device,
) -> Result<(KinematicChain, Calibration)> {
    if joints.len() != positions.len() || joints.is_empty() {
        return Err(Error::Config(format!(
            "calibration: {} joint vectors for {} positions",
            joints.len(),
            positions.len()
        )));
    }
    let t0 = std::time::Instant::now();
    let tdev = autodiff_device(device, cfg.seed);
    let n = joints.len();
    let dof = nominal.dof();
    let set = TrainSet {
        inputs: Tensor::from_data(
            TensorData::new(
                joints.iter().flatten().map(|&v| v as f32).collect(),
                [n, dof],
            ),
            &tdev,
        ),
        targets: vec![Tensor::from_data(
            TensorData::new(
                positions
                    .iter()
                    .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
                    .collect(),
                [n, 3, 1, 1],
            ),
            &tdev,
        )],
    };
    let loss = |m: &LinkParameters, b: &Batch| {
        let [k, _] = b.inputs.dims();
        (m.forward(b.inputs.clone()) - b.targets[0].clone().reshape([k, 3]))
            .square()
            .mean()
    };
    let fit_mm = |chain: &KinematicChain| {
        let d = distances(positions, &chain.end_effector_batch(joints));
        1e3 * d.iter().sum::<f64>() / n as f64
    };
    let fit_before_mm = fit_mm(nominal);
    let mut model = LinkParameters::new(nominal, &tdev);
    let mut optim = crate::train::adam::adam();
    for (i, &(steps, learning_rate)) in cfg.stages.iter().enumerate() {
        let train = TrainConfig {
            precision: Default::default(),
            schedule: Default::default(),
            steps,
            batch: n,
            learning_rate,
            grad_clip_norm: None,
            input_noise: 0.0,
            seed: cfg.seed,
            checkpoint_every: 0,
            log_every: 0,
        };
        let label = format!("link parameters, stage {}", i + 1);
        (model, optim, _) = Trainer::new(&train, &label)
            .optimizer(optim)
            .run(model, &set, loss)?;
    }
    let chain = model.valid().to_chain(nominal);
    let fit_after_mm = fit_mm(&chain);
    Ok((
        chain,
        Calibration {
            samples: n,
            fit_before_mm,
            fit_after_mm,
            seconds: t0.elapsed().as_secs_f64(),
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_tensor_euler_rotation_is_nalgebras() {
        let device = crate::core::device::select(crate::core::device::DeviceChoice::Cpu).unwrap();
        let angles = [[0.3, -0.2, 1.1], [0.0, 0.0, 0.0], [-1.2, 0.7, -2.5]];
        let flat: Vec<f32> = angles.iter().flatten().map(|&v| v as f32).collect();
        let m = euler_matrices(Tensor::from_data(TensorData::new(flat, [3, 3]), &device));
        let v = m.into_data().try_into_vec::<f32>().unwrap();
        for (i, a) in angles.iter().enumerate() {
            let r = *nalgebra::Rotation3::from_euler_angles(a[0], a[1], a[2]).matrix();
            for row in 0..3 {
                for col in 0..3 {
                    let ours = v[9 * i + 3 * row + col] as f64;
                    assert!((ours - r[(row, col)]).abs() < 1e-6, "{i} {row} {col}");
                }
            }
        }
    }
}
