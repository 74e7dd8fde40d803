//! Lower precision for training, as PyTorch's autocast does it (`precision`): the parameters
//! and Adam's moments stay in f32 (the master weights), each step runs the network on a copy of
//! the parameters cast to the lower dtype, the batch's inputs cast too, and the gradients flow
//! back through the casts into the f32 masters. Losses widen their inputs to f32
//! ([`widened`]), and BatchNorm runs in f32 ([`crate::kernels::batch_norm`]), as autocast keeps
//! reductions and normalisation in f32; f16 scales the loss ([`LOSS_SCALE`]). On a GPU, f16
//! and bf16 matrix products reach tensor cores (f32 through Vulkan does not); `flex32` stores
//! f32 and lets the GPU compute at f16's precision. Our CPU and GPU kernels take f32 only: a
//! lower dtype runs on burn's own ops.

use burn::module::{Module, ModuleMapper, Param};
use burn::tensor::{DType, Device, FloatDType, Tensor};

use crate::core::error::{Error, Result};

/// f16's loss scale, as PyTorch's `GradScaler` without its dynamic part: a mean over a batch
/// of images makes each pixel's gradient about 1 / (batch x pixels), 3e-6 for NeuroKin's paper
/// preset, below f16's smallest normal number (6.1e-5), so the gradients lose their precision or
/// flush to zero on the way back through the network (measured: NeuroKin's paper preset in f16
/// without it stood at a loss of 0.050 after 300 steps where f32 and bf16 stood at 0.013). Times
/// 1,024 they are normal, and a weight's gradient stays below f16's largest number (65,504)
/// while its true value is below 64. A step whose gradients overflow ends the run as a
/// non-finite loss does (the last good checkpoint kept).
pub const LOSS_SCALE: f32 = 1024.0;

/// The dtype a network computes in while it trains.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "lowercase")]
pub enum Precision {
    /// Everything in f32 (the default).
    #[default]
    F32,
    /// bfloat16: f32's range, 8 bits of mantissa.
    Bf16,
    /// IEEE half: 11 bits of mantissa, largest value 65,504.
    F16,
    /// burn's flex32: stored as f32, computed at f16's precision where the GPU can.
    Flex32,
}

impl Precision {
    /// Every precision, in the order a list of choices gives them.
    pub const ALL: [Precision; 4] = [
        Precision::F32,
        Precision::Bf16,
        Precision::F16,
        Precision::Flex32,
    ];

    /// Its name, as configs and command lines give it.
    pub fn name(&self) -> &'static str {
        match self {
            Precision::F32 => "f32",
            Precision::Bf16 => "bf16",
            Precision::F16 => "f16",
            Precision::Flex32 => "flex32",
        }
    }

    pub fn is_f32(&self) -> bool {
        *self == Precision::F32
    }

    /// Refuse a dtype `device` cannot compute in (burn's `supports_dtype`: storage,
    /// conversion and arithmetic; bf16 on many Vulkan devices converts but has no arithmetic,
    /// and the CPU has no flex32), naming those it can.
    pub fn check(&self, device: &Device) -> Result<()> {
        if device.supports_dtype(self.dtype()) {
            return Ok(());
        }
        let can: Vec<String> = Self::ALL
            .iter()
            .filter(|p| device.supports_dtype(p.dtype()))
            .map(|p| p.to_string())
            .collect();
        Err(Error::Config(format!(
            "`precision` {self}: this device cannot compute in {self} (it can in {})",
            can.join(", ")
        )))
    }

    /// What a results row says of a run in this precision (nothing in f32).
    pub fn note(&self) -> String {
        if self.is_f32() {
            return String::new();
        }
        format!("trained in {self} (autocast: f32 master weights and losses), evaluated in f32")
    }

    /// What the loss is multiplied by before its backward pass, and the gradients divided by
    /// after it ([`LOSS_SCALE`] in f16, else 1).
    pub fn loss_scale(&self) -> f32 {
        match self {
            Precision::F16 => LOSS_SCALE,
            _ => 1.0,
        }
    }

    /// The dtype the network computes in.
    pub fn dtype(&self) -> FloatDType {
        match self {
            Precision::F32 => FloatDType::F32,
            Precision::Bf16 => FloatDType::BF16,
            Precision::F16 => FloatDType::F16,
            Precision::Flex32 => FloatDType::Flex32,
        }
    }

    /// `model` with its parameters cast to this precision, through casts autodiff follows back
    /// to the f32 parameters; BatchNorm's parameters and running statistics stay f32.
    /// `None` in f32.
    pub fn autocast<M: Module>(&self, model: &M) -> Option<M> {
        if self.is_f32() {
            return None;
        }
        Some(model.clone().map(&mut Autocast {
            dtype: self.dtype(),
            in_norm: 0,
        }))
    }
}

/// Its [`Precision::name`].
impl std::fmt::Display for Precision {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Casts the parameters outside BatchNorm layers (whose running statistics are the networks'
/// only buffers).
struct Autocast {
    dtype: FloatDType,
    /// How deep inside a BatchNorm the mapper is.
    in_norm: usize,
}

impl ModuleMapper for Autocast {
    fn enter_module(&mut self, _name: &str, container_type: &str) {
        if container_type == "Struct:BatchNorm" || self.in_norm > 0 {
            self.in_norm += 1;
        }
    }

    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.in_norm = self.in_norm.saturating_sub(1);
    }

    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        if self.in_norm > 0 {
            return param;
        }
        let dtype = self.dtype;
        param.map(|t| t.cast(dtype))
    }
}

/// `t` in f32: a loss computed from a lower precision's output (autocast computes losses in
/// f32). No op where it already is.
pub fn widened<const D: usize>(t: Tensor<D>) -> Tensor<D> {
    if t.dtype() == DType::F32 {
        t
    } else {
        t.cast(FloatDType::F32)
    }
}
