//! A joint encoder that follows the kinematic tree (the self-modeling paper's future work,
//! Section VI-D4: "graph networks over the kinematic tree" for robots of 30+ joints), beside
//! NeuroKin's flat MLP.
//!
//! Each joint `j` has a state `h_j` of `width` values. Its input is its angle as
//! `(a / 90, sin a, cos a)` (`a` in degrees) through a shared linear map, plus a learned
//! embedding of the joint (its place in the tree); its message is the state of the joint above
//! it (the nearest input joint on the way to the root) through a second shared map:
//!
//! `h_j = relu(U x_j + e_j + M h_parent(j))`, `h_parent = 0` at the root,
//!
//! computed from the root down: the whole tree in as many rounds as it is deep (every round
//! updates every joint at once; after `k` rounds the joints `k` deep are final), as forward
//! kinematics composes transforms down a chain. The states are summed over the joints and read
//! out by an MLP to the latent: `sum_j h_j -> hidden -> latent`, the flat encoder's last two
//! widths.
//!
//! [`matched_width`] picks the state width that gives the encoder as many parameters as the
//! flat MLP it replaces, so the two are compared at the same size.

use burn::module::{Module, Param};
use burn::nn::{Linear, LinearConfig};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Int, Tensor, TensorData};

use crate::core::error::{Error, Result};

/// The tree encoder.
#[derive(Module, Debug)]
pub struct TreeEncoder {
    input: Linear,
    message: Linear,
    embedding: Param<Tensor<2>>,
    readout: Vec<Linear>,
    /// For each joint, its parent's row in `[zeros; states]` (0: no parent).
    parents: Tensor<1, Int>,
    #[module(skip)]
    rounds: usize,
    #[module(skip)]
    dof: usize,
    #[module(skip)]
    width: usize,
}

/// Parameters of the flat MLP encoder with layer widths `widths` (input first).
pub fn flat_params(widths: &[usize]) -> usize {
    widths.windows(2).map(|w| w[0] * w[1] + w[1]).sum()
}

/// Parameters of a tree encoder of `dof` joints, state `width`, read out through `readout`
/// (widths after the pooled state: hidden..., latent).
pub fn tree_params(dof: usize, width: usize, readout: &[usize]) -> usize {
    let mut widths = vec![width];
    widths.extend(readout);
    4 * width + width * width + dof * width + flat_params(&widths)
}

/// The state width at which the tree encoder has about as many parameters as the flat MLP
/// `dof -> hidden... -> latent` (the largest width not above it; at least 8).
pub fn matched_width(dof: usize, hidden: &[usize], latent: usize) -> usize {
    let mut flat = vec![dof];
    flat.extend(hidden);
    flat.push(latent);
    let target = flat_params(&flat);
    let readout = &flat[flat.len().saturating_sub(2).max(1)..];
    (8..4096)
        .take_while(|&w| tree_params(dof, w, readout) <= target)
        .last()
        .unwrap_or(8)
}

/// Whether `parents` is a tree (every chain of parents ends at a root joint).
pub fn check_tree(parents: &[Option<usize>]) -> Result<()> {
    depths(parents).map(|_| ())
}

/// The depth of each joint in the tree of `parents` (a root joint is 1); an error for a
/// parent out of range or a cycle.
fn depths(parents: &[Option<usize>]) -> Result<Vec<usize>> {
    let n = parents.len();
    parents
        .iter()
        .enumerate()
        .map(|(j, _)| {
            let (mut k, mut d) = (j, 1);
            while let Some(p) = parents[k] {
                if p >= n || d > n {
                    return Err(Error::Config(format!(
                        "tree encoder: joint {j}'s chain of parents leaves the {n} joints or loops"
                    )));
                }
                (k, d) = (p, d + 1);
            }
            Ok(d)
        })
        .collect()
}

impl TreeEncoder {
    /// A tree encoder of the joints whose parents are `parents` (`None`: a root joint), state
    /// `width`, read out through `readout` (hidden..., latent).
    pub fn new(
        parents: &[Option<usize>],
        width: usize,
        readout: &[usize],
        device: &Device,
    ) -> Result<Self> {
        let dof = parents.len();
        if dof == 0 || width == 0 || readout.is_empty() {
            return Err(Error::Config(
                "tree encoder: it needs joints, a state width and a latent width".into(),
            ));
        }
        let rounds = depths(parents)?.into_iter().max().unwrap_or(1);
        let rows: Vec<i64> = parents
            .iter()
            .map(|p| p.map_or(0, |p| p as i64 + 1))
            .collect();
        let mut widths = vec![width];
        widths.extend(readout);
        let embedding = Tensor::<2>::random(
            [dof, width],
            burn::tensor::Distribution::Normal(0.0, 0.1),
            device,
        );
        Ok(TreeEncoder {
            input: LinearConfig::new(3, width).init(device),
            message: LinearConfig::new(width, width)
                .with_bias(false)
                .init(device),
            embedding: Param::from_tensor(embedding),
            readout: widths
                .windows(2)
                .map(|w| LinearConfig::new(w[0], w[1]).init(device))
                .collect(),
            parents: Tensor::from_data(TensorData::new(rows, [dof]), device),
            rounds,
            dof,
            width,
        })
    }

    /// The latent of joint angles `[batch, dof]` (degrees): `[batch, latent]`.
    pub fn forward(&self, angles: Tensor<2>) -> Tensor<2> {
        let [b, _] = angles.dims();
        let a = angles.slice([0..b, 0..self.dof]);
        let radians = a.clone() * (std::f32::consts::PI / 180.0);
        let x = Tensor::stack::<3>(vec![a / 90.0, radians.clone().sin(), radians.cos()], 2);
        let drive = self.input.forward(x) + self.embedding.val().unsqueeze_dim::<3>(0);
        let mut h = relu(drive.clone());
        let zeros = Tensor::<3>::zeros([b, 1, self.width], &h.device());
        for _ in 1..self.rounds {
            let above = Tensor::cat(vec![zeros.clone(), h], 1).select(1, self.parents.clone());
            h = relu(drive.clone() + self.message.forward(above));
        }
        let mut z = h.sum_dim(1).reshape([b, self.width]);
        let last = self.readout.len() - 1;
        for (i, layer) in self.readout.iter().enumerate() {
            z = layer.forward(z);
            if i < last {
                z = relu(z);
            }
        }
        z
    }

    /// Trainable parameters.
    pub fn params(&self) -> usize {
        self.num_params()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn host(t: Tensor<2>) -> (Vec<f32>, usize) {
        let [_, cols] = t.dims();
        (t.into_data().try_to_vec::<f32>().expect("f32"), cols)
    }

    fn linear(l: &Linear, x: &[f32]) -> Vec<f32> {
        let (w, cols) = host(l.weight.val());
        let b = l
            .bias
            .as_ref()
            .map(|b| b.val().into_data().try_to_vec::<f32>().expect("f32"))
            .unwrap_or_else(|| vec![0.0; cols]);
        (0..cols)
            .map(|o| {
                b[o] + x
                    .iter()
                    .enumerate()
                    .map(|(i, v)| v * w[i * cols + o])
                    .sum::<f32>()
            })
            .collect()
    }

    /// The slow reference: each joint's state from its parent's, root first, one joint at a
    /// time on the host; then the sum and the readout.
    fn reference(e: &TreeEncoder, parents: &[Option<usize>], angles: &[f32]) -> Vec<f32> {
        let (embedding, width) = host(e.embedding.val());
        let order = depths(parents).unwrap();
        let mut joints: Vec<usize> = (0..parents.len()).collect();
        joints.sort_by_key(|&j| order[j]);
        let mut h = vec![vec![0f32; width]; parents.len()];
        for j in joints {
            let a = angles[j];
            let r = a.to_radians();
            let u = linear(&e.input, &[a / 90.0, r.sin(), r.cos()]);
            let m = match parents[j] {
                Some(p) => linear(&e.message, &h[p]),
                None => vec![0.0; width],
            };
            h[j] = (0..width)
                .map(|k| (u[k] + embedding[j * width + k] + m[k]).max(0.0))
                .collect();
        }
        let mut z: Vec<f32> = (0..width).map(|k| h.iter().map(|s| s[k]).sum()).collect();
        for (i, layer) in e.readout.iter().enumerate() {
            z = linear(layer, &z);
            if i + 1 < e.readout.len() {
                z.iter_mut().for_each(|v| *v = v.max(0.0));
            }
        }
        z
    }

    #[test]
    fn the_tree_encoder_matches_its_slow_reference_and_the_flat_size() {
        let device = crate::core::device::select(crate::core::device::DeviceChoice::Cpu).unwrap();
        // Two branches off a root joint, one three deep, and a second root joint.
        let parents = [None, Some(0), Some(1), Some(2), Some(0), None];
        let e = TreeEncoder::new(&parents, 16, &[24, 10], &device).unwrap();
        assert_eq!(e.rounds, 4);
        let angles = [30.0f32, -45.0, 80.0, 10.0, -120.0, 5.0];
        let fast = e.forward(Tensor::from_data(
            TensorData::new(angles.to_vec(), [1, 6]),
            &device,
        ));
        let fast = fast.into_data().try_to_vec::<f32>().unwrap();
        let slow = reference(&e, &parents, &angles);
        for (a, b) in fast.iter().zip(&slow) {
            assert!((a - b).abs() < 1e-4 * (1.0 + b.abs()), "{fast:?} {slow:?}");
        }
        assert_eq!(e.params(), tree_params(6, 16, &[24, 10]));
        // At the matched width the two encoders are the same size within a percent.
        for dof in [4, 29] {
            let w = matched_width(dof, &[128, 256], 1024);
            let flat = flat_params(&[dof, 128, 256, 1024]);
            let tree = tree_params(dof, w, &[256, 1024]);
            assert!(
                tree <= flat && tree as f64 > 0.99 * flat as f64,
                "{tree} {flat}"
            );
        }
        assert!(check_tree(&[Some(1), Some(0)]).is_err());
        assert!(check_tree(&[None, Some(7)]).is_err());
    }
}
