//! The inverse kinematic model of the EMSSL paper (Table I): an MLP from a normalised end
//! position `[n, 3]` to normalised joints `[n, dof]` in [0, 1] (see [`crate::ik_data`]):
//! 3 -> 1024 -> 512 -> 256 -> 128 -> dof, ReLU on the hidden layers, sigmoid on the output.
//! The same MLP, with other widths and a linear output where asked, is the learned forward
//! model of distal supervised learning and the generator and discriminator of the conditional
//! GAN.

use burn::module::Module;
use burn::nn::{Linear, LinearConfig};
use burn::tensor::activation::{relu, sigmoid};
use burn::tensor::{Device, Tensor};

use crate::error::{Error, Result};

/// The MLP's shape.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct InverseModelConfig {
    pub inputs: usize,
    pub hidden: Vec<usize>,
    pub outputs: usize,
    /// Sigmoid on the output (the inverse model's normalised joints); linear otherwise.
    #[serde(default = "yes")]
    pub sigmoid_output: bool,
}

fn yes() -> bool {
    true
}

impl InverseModelConfig {
    /// The paper's: 3 -> 1024 -> 512 -> 256 -> 128 -> `dof`.
    pub fn paper(dof: usize) -> Self {
        InverseModelConfig {
            inputs: 3,
            hidden: vec![1024, 512, 256, 128],
            outputs: dof,
            sigmoid_output: true,
        }
    }

    /// 3 -> 128 -> 64 -> `dof`, for tests.
    pub fn quick(dof: usize) -> Self {
        InverseModelConfig {
            inputs: 3,
            hidden: vec![128, 64],
            outputs: dof,
            sigmoid_output: true,
        }
    }

    pub fn init(&self, device: &Device, seed: u64) -> Result<Mlp> {
        if self.inputs == 0 || self.outputs == 0 || self.hidden.contains(&0) {
            return Err(Error::Config(format!(
                "MLP: layer widths must be positive ({self:?})"
            )));
        }
        let mut widths = vec![self.inputs];
        widths.extend(&self.hidden);
        widths.push(self.outputs);
        Ok(crate::device::seeded(device, seed, || Mlp {
            layers: widths
                .windows(2)
                .map(|w| LinearConfig::new(w[0], w[1]).init(device))
                .collect(),
            sigmoid_output: self.sigmoid_output,
        }))
    }
}

/// Linear layers with ReLU between them and, where configured, a sigmoid on the output.
#[derive(Module, Debug)]
pub struct Mlp {
    layers: Vec<Linear>,
    #[module(skip)]
    sigmoid_output: bool,
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
        if self.sigmoid_output { sigmoid(x) } else { x }
    }
}
