//! FFKSM's occupancy field (self-modeling paper section IV-B; Hu, Lin, Lipson 2024): density
//! and visibility of a 3-D point given the arm's joint angles.
//!
//! The point (metres, world frame) goes into the virtual frame of the first two joints
//! ([`crate::self_models::ffksm::virtual_frame`]) and is positionally encoded; the two distal joints (radians) are
//! encoded separately. Each goes through its own encoder (Linear, ReLU, Linear); the
//! predictive module maps their concatenation to `[density, visibility]`, its output bias
//! initialised to 0.1.
//!
//! - `paper` (the reimplementation's code): L = 5 (33 and 22 inputs), predictive module
//!   256->128->128->32->2 with ReLUs throughout: 93,922 parameters.
//! - `original` (the authors' trained model): L = 10 (63 and 42 inputs), predictive module
//!   256->128->32->2 with no ReLU before the output layer: 83,810 parameters.

use burn::module::{Module, Param};
use burn::nn::{Linear, LinearConfig};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor, TensorData};

use crate::core::error::{Error, Result};
use crate::core::preset::Preset;
use crate::self_models::ffksm::encoding::{encode, encoded_width};
use crate::self_models::ffksm::virtual_frame::{VirtualFrame, to_virtual};

/// The field's architecture.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct OccupancyFieldConfig {
    /// Frequency bands L of both positional encodings.
    pub bands: usize,
    /// Width of both encoders' layers.
    pub encoder_width: usize,
    /// Hidden widths of the predictive module, before its 2 outputs.
    pub predictive_hidden: Vec<usize>,
    /// A ReLU between the last hidden layer and the output (the reimplementation has one).
    pub relu_before_output: bool,
    pub virtual_frame: VirtualFrame,
    /// Initial bias of both outputs.
    pub output_bias: f32,
    /// The robot's joint count: the first two set the virtual frame, the rest (at least one
    /// input, zero when the robot has only two joints) go through the kinematic encoder.
    #[serde(default = "four", skip_serializing_if = "is_four")]
    pub dof: usize,
}

fn four() -> usize {
    4
}

fn is_four(v: &usize) -> bool {
    *v == 4
}

/// The kinematic encoder's inputs for `dof` joints: the joints after the first two, at least
/// one.
pub fn distal_width(dof: usize) -> usize {
    dof.max(3) - 2
}

/// The kinematic encoder's input for one pose (radians): the joints after the first two, or
/// one zero for a robot of two joints or fewer.
pub fn distal_of(angles: &[f32]) -> Vec<f32> {
    if angles.len() > 2 {
        angles[2..].to_vec()
    } else {
        vec![0.0]
    }
}

impl Preset for OccupancyFieldConfig {
    /// The reimplementation's code: 93,922 parameters.
    fn paper() -> Self {
        OccupancyFieldConfig {
            bands: 5,
            encoder_width: 128,
            predictive_hidden: vec![128, 128, 32],
            relu_before_output: true,
            virtual_frame: VirtualFrame::Reimplementation,
            output_bias: 0.1,
            dof: 4,
        }
    }

    /// Tiny, for tests.
    fn quick() -> Self {
        OccupancyFieldConfig {
            bands: 3,
            encoder_width: 16,
            predictive_hidden: vec![16, 8],
            ..Self::paper()
        }
    }
}

impl OccupancyFieldConfig {
    /// The original authors' trained model (`ffksm_original`): 83,810 parameters.
    pub fn original() -> Self {
        OccupancyFieldConfig {
            bands: 10,
            predictive_hidden: vec![128, 32],
            relu_before_output: false,
            virtual_frame: VirtualFrame::Original,
            ..Self::paper()
        }
    }

    pub fn validate(&self) -> Result<()> {
        if self.encoder_width == 0 || self.predictive_hidden.contains(&0) || self.dof == 0 {
            return Err(Error::Config(format!(
                "occupancy field: layer widths must be positive ({self:?})"
            )));
        }
        Ok(())
    }

    /// Build the field with parameters drawn from `seed`.
    pub fn init(&self, device: &Device, seed: u64) -> Result<OccupancyField> {
        self.validate()?;
        Ok(crate::core::device::seeded(device, seed, |d| self.build(d)))
    }

    fn build(&self, device: &Device) -> OccupancyField {
        let w = self.encoder_width;
        let encoder = |inputs: usize| {
            vec![
                LinearConfig::new(inputs, w).init(device),
                LinearConfig::new(w, w).init(device),
            ]
        };
        let mut widths = vec![2 * w];
        widths.extend(&self.predictive_hidden);
        widths.push(2);
        let mut predictive: Vec<Linear> = widths
            .windows(2)
            .map(|p| LinearConfig::new(p[0], p[1]).init(device))
            .collect();
        if let Some(out) = predictive.last_mut()
            && let Some(bias) = out.bias.take()
        {
            let filled = bias.val().ones_like().mul_scalar(self.output_bias);
            out.bias = Some(Param::from_tensor(filled));
        }
        OccupancyField {
            coordinates: encoder(encoded_width(3, self.bands)),
            kinematics: encoder(encoded_width(distal_width(self.dof), self.bands)),
            predictive,
            bands: self.bands,
            relu_before_output: self.relu_before_output,
            virtual_frame: self.virtual_frame.clone(),
        }
    }
}

/// The occupancy field network.
#[derive(Module, Debug)]
pub struct OccupancyField {
    coordinates: Vec<Linear>,
    kinematics: Vec<Linear>,
    predictive: Vec<Linear>,
    #[module(skip)]
    bands: usize,
    #[module(skip)]
    relu_before_output: bool,
    #[module(skip)]
    virtual_frame: VirtualFrame,
}

/// Linear, ReLU, Linear.
fn encoder(layers: &[Linear], x: Tensor<2>) -> Tensor<2> {
    layers[1].forward(relu(layers[0].forward(x)))
}

impl OccupancyField {
    /// `[density, visibility]` `[n, 2]` (raw) of points `[n, 3]` (metres, world frame) for
    /// joint angles `[n, 4]` (radians), one row per point.
    ///
    /// The general form, one pose per point; [`OccupancyField::forward_pose`] is the fast path
    /// for many points of one pose and is tested against this.
    pub fn forward(&self, points: Tensor<2>, angles: Tensor<2>) -> Tensor<2> {
        let [n, dof] = angles.dims();
        let joint = |i: usize| {
            if i < dof {
                angles.clone().slice([0..n, i..i + 1]).reshape([n])
            } else {
                Tensor::zeros([n], &angles.device())
            }
        };
        let p = to_virtual(&self.virtual_frame, points, joint(0), joint(1));
        let distal = if dof > 2 {
            angles.clone().slice([0..n, 2..dof])
        } else {
            Tensor::zeros([n, 1], &angles.device())
        };
        let a = encoder(&self.coordinates, encode(p, self.bands));
        let b = encoder(&self.kinematics, encode(distal, self.bands));
        let x = self.predictive[0].forward(Tensor::cat(vec![a, b], 1));
        self.predictive_rest(x)
    }

    /// `[density, visibility]` `[n, 2]` of points `[n, 3]` (metres, world frame) all seen in
    /// one pose `angles` (radians). The same function as [`OccupancyField::forward`] with the
    /// angles repeated, computed once per pose where it does not depend on the point: the
    /// virtual frame is one rigid map (a 3x3 rotation and a shift), the kinematic encoder runs on one row, and its half
    /// of the predictive module's first layer (`W_b b + bias`) is added to every row. That
    /// leaves ~58k multiply-adds per point of the paper preset's ~94k.
    pub fn forward_pose(&self, points: Tensor<2>, angles: &[f32]) -> Tensor<2> {
        let device = points.device();
        let (rotation, shift) = self.affine_rows(angles);
        let p = points.matmul(Tensor::from_data(
            TensorData::new(rotation.to_vec(), [3, 3]),
            &device,
        )) + Tensor::<2>::from_data(TensorData::new(shift.to_vec(), [1, 3]), &device);
        let distal = distal_of(angles);
        let width = distal.len();
        let distal = Tensor::<2>::from_data(TensorData::new(distal, [1, width]), &device);
        let x = self.forward_virtual(p, distal);
        self.predictive_rest(x)
    }

    /// The first predictive layer's output `[n, hidden]` for virtual-frame points `[n, 3]`
    /// and one row of distal joints `[1, 2]` (radians).
    fn forward_virtual(&self, p: Tensor<2>, distal: Tensor<2>) -> Tensor<2> {
        let a = encoder(&self.coordinates, encode(p, self.bands));
        let b = encoder(&self.kinematics, encode(distal, self.bands));
        let first = &self.predictive[0];
        let w = first.weight.val();
        let [inputs, outputs] = w.dims();
        let half = a.dims()[1];
        let mut pose_part = b.matmul(w.clone().slice([half..inputs, 0..outputs]));
        if let Some(bias) = &first.bias {
            pose_part = pose_part + bias.val().reshape([1, outputs]);
        }
        a.matmul(w.slice([0..half, 0..outputs])) + pose_part
    }

    /// The virtual frame of one pose as a rigid map on row vectors, `p' = p Mᵀ + t`: `Mᵀ`
    /// row-major and `t`, built from
    /// [`crate::self_models::ffksm::virtual_frame::to_virtual_reference`] on the origin and
    /// the unit axes.
    pub(crate) fn affine_rows(&self, angles: &[f32]) -> ([f32; 9], [f32; 3]) {
        let joint = |i: usize| angles.get(i).map_or(0.0, |&a| a as f64);
        let (a0, a1) = (joint(0), joint(1));
        let map = |p: [f64; 3]| {
            crate::self_models::ffksm::virtual_frame::to_virtual_reference(
                &self.virtual_frame,
                p,
                a0,
                a1,
            )
        };
        let t = map([0.0; 3]);
        let mut m = [0f32; 9];
        for (col, e) in [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
            .into_iter()
            .enumerate()
        {
            let v = map(e);
            // Row `col` of Mᵀ is column `col` of M, the image of axis `col` less the shift.
            for k in 0..3 {
                m[3 * col + k] = (v[k] - t[k]) as f32;
            }
        }
        (m, t.map(|v| v as f32))
    }

    /// The layers: the coordinate encoder's two, the kinematic encoder's two, then the
    /// predictive module's (the last one the output).
    pub fn layers(&self) -> (&[Linear], &[Linear], &[Linear]) {
        (&self.coordinates, &self.kinematics, &self.predictive)
    }

    /// Floating-point operations of the matrix products of one dense step with `points`
    /// evaluations: per point, the coordinate encoder, the coordinate half of the first
    /// predictive layer and the rest of the predictive module forward (the kinematic half is
    /// once per pose), and backward twice that (input and weight gradients) less the first
    /// layer's input gradient, which is not needed.
    pub fn step_flop(&self, points: usize) -> f64 {
        let (coordinates, _, predictive) = self.layers();
        let shape = |l: &burn::nn::Linear| l.weight.val().dims();
        let [c_in, c_out] = shape(&coordinates[0]);
        let [_, coordinate] = shape(&coordinates[1]);
        let mut forward = c_in * c_out + c_out * coordinate;
        for (i, layer) in predictive.iter().enumerate() {
            let [inputs, outputs] = shape(layer);
            forward += if i == 0 { coordinate } else { inputs } * outputs;
        }
        let backward = 2 * forward - c_in * c_out;
        2.0 * (forward + backward) as f64 * points as f64
    }

    /// Frequency bands of both positional encodings.
    pub fn bands(&self) -> usize {
        self.bands
    }

    /// Whether a ReLU follows predictive layer `i` (every layer but the output, and the one
    /// feeding the output only when the architecture has a ReLU there).
    pub fn relu_after(&self, i: usize) -> bool {
        let last = self.predictive.len() - 1;
        i != last && (self.relu_before_output || i + 1 != last)
    }

    /// The predictive module after its first layer's affine map `x` `[n, hidden]`.
    fn predictive_rest(&self, mut x: Tensor<2>) -> Tensor<2> {
        for (i, layer) in self.predictive.iter().enumerate() {
            if i > 0 {
                x = layer.forward(x);
            }
            if self.relu_after(i) {
                x = relu(x);
            }
        }
        x
    }
}
