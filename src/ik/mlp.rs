//! The inverse kinematic model of the EMSSL paper (Table I): an MLP from a normalised end
//! position `[n, 3]` to normalised joints `[n, dof]` in [0, 1] (see [`crate::ik::data`]):
//! 3 -> 1024 -> 512 -> 256 -> 128 -> dof, ReLU on the hidden layers, sigmoid on the output.
//! The same MLP, with other widths and a linear output where asked, is the learned forward
//! model of distal supervised learning and the generator and discriminator of the conditional
//! GAN.

use burn::module::Module;
use burn::nn::{Linear, LinearConfig};
use burn::tensor::activation::{relu, sigmoid};
use burn::tensor::{Device, Tensor};

use crate::core::error::{Error, Result};
use crate::ik::data::JointOutput;

/// The MLP's shape.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct InverseModelConfig {
    pub inputs: usize,
    pub hidden: Vec<usize>,
    pub outputs: usize,
    /// Sigmoid on the output (the inverse model's normalised joints); linear otherwise.
    #[serde(default = "yes")]
    pub sigmoid_output: bool,
    /// The outputs are (cos, sin) pairs scaled onto the unit circle (the wrapped joint output,
    /// [`JointOutput::Wrapped`]); overrides `sigmoid_output`.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub unit_pairs: bool,
}

fn yes() -> bool {
    true
}

impl InverseModelConfig {
    /// Floating-point operations of its matrix products per input row: 2 per multiply-add of
    /// every layer.
    pub fn flop_per_row(&self) -> f64 {
        let mut widths = vec![self.inputs];
        widths.extend(&self.hidden);
        widths.push(self.outputs);
        widths.windows(2).map(|w| 2.0 * (w[0] * w[1]) as f64).sum()
    }

    /// The paper's: 3 -> 1024 -> 512 -> 256 -> 128 -> `dof`.
    pub fn paper(dof: usize) -> Self {
        Self::inverse(vec![1024, 512, 256, 128], dof, JointOutput::Sigmoid)
    }

    /// An inverse model: 3 -> `hidden` -> the joints of a `dof`-joint arm under `output`.
    pub fn inverse(hidden: Vec<usize>, dof: usize, output: JointOutput) -> Self {
        Self::with_output(3, hidden, dof, output)
    }

    /// `inputs` -> `hidden` -> the joints of a `dof`-joint arm under `output`.
    pub fn with_output(inputs: usize, hidden: Vec<usize>, dof: usize, output: JointOutput) -> Self {
        InverseModelConfig {
            inputs,
            hidden,
            outputs: output.width(dof),
            sigmoid_output: output == JointOutput::Sigmoid,
            unit_pairs: output == JointOutput::Wrapped,
        }
    }

    /// 3 -> 128 -> 64 -> `dof`, for tests.
    pub fn quick(dof: usize) -> Self {
        Self::inverse(vec![128, 64], dof, JointOutput::Sigmoid)
    }

    pub fn init(&self, device: &Device, seed: u64) -> Result<Mlp> {
        if self.inputs == 0 || self.outputs == 0 || self.hidden.contains(&0) {
            return Err(Error::Config(format!(
                "MLP: layer widths must be positive ({self:?})"
            )));
        }
        if self.unit_pairs && self.outputs % 2 != 0 {
            return Err(Error::Config(format!(
                "MLP: (cos, sin) pairs need an even output width ({self:?})"
            )));
        }
        let mut widths = vec![self.inputs];
        widths.extend(&self.hidden);
        widths.push(self.outputs);
        Ok(crate::core::device::seeded(device, seed, |d| Mlp {
            layers: widths
                .windows(2)
                .map(|w| LinearConfig::new(w[0], w[1]).init(d))
                .collect(),
            head: match (self.unit_pairs, self.sigmoid_output) {
                (true, _) => Head::UnitPairs,
                (false, true) => Head::Sigmoid,
                (false, false) => Head::Linear,
            },
        }))
    }
}

/// What the last layer's outputs go through.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Head {
    Linear,
    Sigmoid,
    /// Consecutive pairs scaled onto the unit circle: (cos, sin) per joint.
    UnitPairs,
}

/// Linear layers with ReLU between them and, where configured, a sigmoid or unit pairs on the
/// output.
#[derive(Module, Debug)]
pub struct Mlp {
    layers: Vec<Linear>,
    #[module(skip)]
    head: Head,
}

impl Mlp {
    /// Outputs `[n, outputs]` (in (0, 1) with the sigmoid) for inputs `[n, inputs]`.
    pub fn forward(&self, x: Tensor<2>) -> Tensor<2> {
        let last = self.layers.len() - 1;
        let mut x = x;
        for (i, layer) in self.layers.iter().enumerate() {
            x = layer.forward(x);
            if i < last {
                x = relu(x);
            }
        }
        match self.head {
            Head::Linear => x,
            Head::Sigmoid => sigmoid(x),
            Head::UnitPairs => unit_pairs(x),
        }
    }

    /// The joint output this network writes (an inverse model's): wrapped for unit pairs,
    /// the normalised sigmoid otherwise.
    pub fn joint_output(&self) -> JointOutput {
        match self.head {
            Head::UnitPairs => JointOutput::Wrapped,
            _ => JointOutput::Sigmoid,
        }
    }
}

/// `[n, 2k]` as k consecutive (x, y) pairs, each scaled to unit length.
pub fn unit_pairs(x: Tensor<2>) -> Tensor<2> {
    let [n, w] = x.dims();
    let pairs = x.reshape([n, w / 2, 2]);
    let norm = (pairs.clone().square().sum_dim(2) + 1e-8).sqrt();
    (pairs / norm).reshape([n, w])
}
