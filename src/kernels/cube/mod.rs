//! Our GPU kernels, in CubeCL (burn's kernel language), for what burn runs as many launches:
//! behind the `wgpu` feature, as [`crate::kernels::cpu_extension`] is for the CPU.
//!
//! - [`multi_tensor`]: the kernels (the sum of squares of many tensors; Adam over many
//!   parameters);
//! - [`launch`]: launching them on burn's CubeCL tensors (contiguity, outputs, the device's
//!   binding limit);
//! - [`batch_norm`]: a batch-norm layer's statistics, parameter and input gradients, a launch
//!   each;
//! - [`channel_reduce`]: sums by channel (bias gradients, batch-norm statistics and gradients)
//!   in two launches that fill the GPU;
//! - [`loss`]: the binary cross-entropy on logits and its gradient;
//! - [`im2col`]: a convolution's columns and their sum back into an image (col2im), the kernels
//!   around the matrix products of [`convolution`];
//! - [`extension`]: our kernels as operations of burn's backends (a backend extension), the
//!   layers among them in burn's autodiff graph with their backward passes;
//! - [`convolution`]: the convolutions and transposed convolutions as such layers;
//! - here: the bridge to burn's tensors. On a GPU burn's tensors are lazy (burn's fusion
//!   backend records operations and runs them in blocks); [`run_lazily`] records one of ours
//!   the same way, so it runs in order with the rest and nothing waits for the device.
//!
//! Each kernel has its slow reference in burn's own operations beside its caller, and
//! `tests/gpu/kernels.rs` compares them on lavapipe.

mod autodiff;
pub mod batch_norm;
pub mod channel_reduce;
pub mod conv_layer;
pub mod convolution;
pub mod extension;
pub mod im2col;
pub mod launch;
pub mod loss;
pub mod multi_tensor;

use burn::backend::fusion::FusionTensor;
use burn::backend::fusion::custom::{
    CustomOpIr, HandleContainer, OperationFn, OperationIr, StreamId, TensorIr,
};
use burn::backend::{BackendTensor, DispatchAutodiffContext, DispatchTensor, DispatchTensorKind};
use burn::tensor::{DType, Shape, Tensor};
use burn_cubecl::CubeBackend;
use burn_cubecl::fusion::FusionCubeRuntime;
use burn_cubecl::tensor::CubeTensor;

/// `t` as it is where contiguous, else a contiguous copy.
fn contiguous(t: CubeTensor) -> CubeTensor {
    if t.is_contiguous() {
        t
    } else {
        burn_cubecl::kernel::into_contiguous(t)
    }
}

/// Whether `t` holds f32 values, as our kernels read them: `F32`, or `Flex32`, whose storage is
/// f32 (burn's cast between the two hands the tensor back unchanged, still marked `Flex32`:
/// `--precision flex32`'s batch norm, whose input is cast to f32, reached our kernels so).
pub fn holds_f32(t: &CubeTensor) -> bool {
    matches!(t.dtype, DType::F32 | DType::Flex32)
}

/// A new contiguous f32 tensor of `shape` on `like`'s device (its values unset).
fn empty_f32(like: &CubeTensor, shape: impl Into<Shape>) -> CubeTensor {
    burn_cubecl::ops::numeric::empty_device_dtype(
        like.client.clone(),
        like.device.clone(),
        shape.into(),
        DType::F32,
    )
}

/// Workgroups and their size for a kernel with a unit an element, `n` elements, on `like`'s
/// device (more than 65,535 workgroups spread over a second dimension).
fn elementwise(
    like: &CubeTensor,
    n: usize,
) -> (cubecl::prelude::CubeCount, cubecl::prelude::CubeDim) {
    let dim = cubecl::prelude::CubeDim::new_1d(multi_tensor::BLOCK as u32);
    (
        cubecl::calculate_cube_count_elemwise(&like.client, n, dim),
        dim,
    )
}

thread_local! {
    /// The elements the kernel being launched on this thread works over ([`over_elements`]).
    static ELEMENTS: std::cell::Cell<Option<u64>> = const { std::cell::Cell::new(None) };
}

/// Run `launch` (one of our kernels' launches) saying it works over `elements` elements:
/// `eval::device_counts` records them beside the launch's workgroups, and the workgroup guard
/// (`tests/gpu/counts.rs`) holds a large kernel to filling the GPU.
pub fn over_elements<T>(elements: usize, launch: impl FnOnce() -> T) -> T {
    let before = ELEMENTS.with(|e| e.replace(Some(elements as u64)));
    let out = launch();
    ELEMENTS.with(|e| e.set(before));
    out
}

/// The elements of the launch under way on this thread ([`over_elements`]); `None` for
/// burn's kernels.
pub fn launch_elements() -> Option<u64> {
    ELEMENTS.with(|e| e.get())
}

/// A lazy tensor of burn's fusion backend on a CubeCL device.
pub type LazyTensor = FusionTensor<FusionCubeRuntime>;

/// A float tensor on a CubeCL device (wgpu) as burn's fusion backend holds it, with the
/// autodiff context to give it back; the tensor itself where it lives elsewhere.
pub fn lazy<const D: usize>(
    t: Tensor<D>,
) -> std::result::Result<(LazyTensor, DispatchAutodiffContext), Tensor<D>> {
    let dispatch = t.into_dispatch();
    match dispatch.kind {
        DispatchTensorKind::Cube(BackendTensor::Float(f)) => Ok((f, dispatch.autodiff)),
        kind => Err(Tensor::from_dispatch(DispatchTensor {
            kind,
            autodiff: dispatch.autodiff,
        })),
    }
}

/// Whether `t` is a float tensor on a CubeCL device, where [`lazy`] takes it.
pub fn is_lazy<const D: usize>(t: &Tensor<D>) -> bool {
    matches!(
        t.clone().into_dispatch().kind,
        DispatchTensorKind::Cube(BackendTensor::Float(_))
    )
}

/// Whether `t` is what our kernels take: an f32 tensor on a CubeCL device (another dtype,
/// `precision`'s, runs on burn's ops).
pub fn on_kernels<const D: usize>(t: &Tensor<D>) -> bool {
    t.dtype() == burn::tensor::DType::F32 && is_lazy(t)
}

/// The largest buffer `t`'s device allocates, in bytes, where `t` is on a CubeCL device.
pub fn max_buffer_bytes<const D: usize>(t: &Tensor<D>) -> Option<u64> {
    let (f, _) = lazy(t.clone()).ok()?;
    Some(f.client.device().client().properties().memory.max_page_size)
}

/// The shader compiler burn's CubeCL runtime compiles our kernels and burn's with on `device`
/// (`wgpu<wgsl>`, or `wgpu<spirv>` in a `vulkan` build on a Vulkan device); `None` off a
/// CubeCL device.
pub fn compiler(device: &burn::tensor::Device) -> Option<&'static str> {
    let (f, _) = lazy(Tensor::<1>::zeros([1], device)).ok()?;
    Some(f.client.device().client().name())
}

/// Back from [`lazy`].
pub fn tensor<const D: usize>(t: LazyTensor, autodiff: DispatchAutodiffContext) -> Tensor<D> {
    Tensor::from_dispatch(DispatchTensor {
        kind: DispatchTensorKind::Cube(BackendTensor::Float(t)),
        autodiff,
    })
}

/// Records `run` (CubeCL tensors in, CubeCL tensors out) as one operation of burn's fusion
/// backend on the inputs' device: it runs when burn runs the operations before it, and its
/// outputs (of these shapes and types) are lazy tensors like any other.
pub fn run_lazily(
    id: &str,
    inputs: Vec<LazyTensor>,
    outputs: &[(Shape, DType)],
    run: impl Fn(Vec<CubeTensor>) -> Vec<CubeTensor> + Send + Sync + 'static,
) -> Vec<LazyTensor> {
    let client = inputs
        .first()
        .expect("an operation of no input has no device")
        .client
        .clone();
    let inputs: Vec<TensorIr> = inputs.into_iter().map(|t| t.into_ir()).collect();
    let outputs: Vec<TensorIr> = outputs
        .iter()
        .map(|(shape, dtype)| TensorIr::uninit(client.create_empty_handle(), shape.clone(), *dtype))
        .collect();
    let ids: Vec<_> = outputs.iter().map(|o| o.id).collect();
    let desc = CustomOpIr {
        id: id.into(),
        inputs: inputs.clone(),
        outputs,
        scalars: Vec::new(),
    };
    let op = OperationFn(
        move |handles: &mut HandleContainer<
            <FusionCubeRuntime as burn::backend::fusion::FusionRuntime>::FusionHandle,
        >| {
            let tensors = inputs
                .iter()
                .map(|ir| handles.get_float_tensor::<CubeBackend>(ir))
                .collect();
            let results = run(tensors);
            assert_eq!(results.len(), ids.len(), "{} outputs expected", ids.len());
            for (id, t) in ids.iter().zip(results) {
                handles.register_float_tensor::<CubeBackend>(id, t);
            }
            Ok(())
        },
    );
    client.register(StreamId::current(), OperationIr::Custom(desc), op)
}
