//! A transposed convolution (the decoders' upsampling layers) as matrix products: forward, the
//! columns `xᵀ W` (one product) folded into the output with the bias ([`col2im`]), two
//! launches where burn's takes two layout copies, a product and its col2im; backward, from one
//! im2col of the output gradient ([`columns`]): `dx = cols · Wᵀ`, `dW = Σₙ xₙ · colsₙ`, and the
//! bias gradient a sum by channel, where burn's runs two direct convolutions with their layout
//! copies and a reduction after a copy (about eight launches a layer, against five here).
//!
//! For `y = convᵀ(x, W)` with `W` `[c_in, c_out, k, k]`, stride `s` and padding `p`,
//! `cols[n, (iy, ix), (co, ky, kx)] = dy[n, co, iy·s − p + ky, ix·s − p + kx]` (0 outside).
//! The slow reference is burn's own backward pass; `tests/gpu_kernels.rs` compares the two.

use burn::tensor::DType;
use burn_cubecl::tensor::CubeTensor;
use cubecl::prelude::*;

use super::batch_norm::channel_total;
use super::multi_tensor::{BLOCK, at};
use super::{elementwise, empty_f32};

/// `cols` `[N, Hi·Wi, c_out·k·k]` from `dy` `[N, c_out, Ho, Wo]` (any strides).
#[cube(launch)]
#[allow(clippy::too_many_arguments)]
pub fn columns(
    dy: &Tensor<f32>,
    cols: &mut Tensor<f32>,
    in_h: u32,
    in_w: u32,
    kernel: u32,
    stride: u32,
    padding: u32,
) {
    let k = ABSOLUTE_POS;
    if k < cols.len() {
        let (in_h, in_w) = (in_h as usize, in_w as usize);
        let (kernel, stride, padding) = (kernel as usize, stride as usize, padding as usize);
        let (c_out, out_h, out_w) = (dy.shape(1), dy.shape(2), dy.shape(3));
        let width = c_out * kernel * kernel;
        let q = k % width;
        let pix = (k / width) % (in_h * in_w);
        let n = k / (width * in_h * in_w);
        let (co, kk) = (q / (kernel * kernel), q % (kernel * kernel));
        let (ky, kx) = (kk / kernel, kk % kernel);
        let (iy, ix) = (pix / in_w, pix % in_w);
        // oy = iy s − p + ky, kept unsigned: oy + p = iy s + ky.
        let (oyp, oxp) = (iy * stride + ky, ix * stride + kx);
        let mut v = 0.0;
        if oyp >= padding && oxp >= padding && oyp - padding < out_h && oxp - padding < out_w {
            let i = ((n * c_out + co) * out_h + oyp - padding) * out_w + oxp - padding;
            v = dy[at(dy, i)];
        }
        cols[k] = v;
    }
}

/// The layer's output from the columns of its input, `cols = xᵀ W` `[N, Hi·Wi, c_out·k·k]`:
/// `y[n, co, oy, ox] = b[co] + Σ cols[n, (iy, ix), (co, ky, kx)]` over `oy = iy·s − p + ky`
/// (and the same across), contiguous out.
#[cube(launch)]
#[allow(clippy::too_many_arguments)]
pub fn col2im(
    cols: &Tensor<f32>,
    bias: &Tensor<f32>,
    y: &mut Tensor<f32>,
    in_h: u32,
    in_w: u32,
    kernel: u32,
    stride: u32,
    padding: u32,
) {
    let k = ABSOLUTE_POS;
    if k < y.len() {
        let (in_h, in_w) = (in_h as usize, in_w as usize);
        let (kernel, stride, padding) = (kernel as usize, stride as usize, padding as usize);
        let (c_out, out_h, out_w) = (y.shape(1), y.shape(2), y.shape(3));
        let ox = k % out_w;
        let oy = (k / out_w) % out_h;
        let co = (k / (out_w * out_h)) % c_out;
        let n = k / (out_w * out_h * c_out);
        let width = c_out * kernel * kernel;
        let mut acc = bias[co];
        for ky in 0..kernel {
            // iy·s = oy + p − ky, kept unsigned.
            let ty = oy + padding;
            if ty >= ky && (ty - ky) % stride == 0 && (ty - ky) / stride < in_h {
                let iy = (ty - ky) / stride;
                for kx in 0..kernel {
                    let tx = ox + padding;
                    if tx >= kx && (tx - kx) % stride == 0 && (tx - kx) / stride < in_w {
                        let ix = (tx - kx) / stride;
                        let i = (n * in_h * in_w + iy * in_w + ix) * width
                            + (co * kernel + ky) * kernel
                            + kx;
                        acc += cols[at(cols, i)];
                    }
                }
            }
        }
        y[k] = acc;
    }
}

/// `sums[c] = Σ t[n, c, ...]` (any strides): a layer's bias gradient.
#[cube(launch)]
pub fn channel_sums(t: &Tensor<f32>, sums: &mut Tensor<f32>, #[comptime] block: usize) {
    let channels = t.shape(1);
    let plane = t.len() / (t.shape(0) * channels);
    let sum = channel_total(t, 0.0, channels, plane, false, block);
    if UNIT_POS == 0 {
        sums[CUBE_POS_X as usize] = sum;
    }
}

/// [`columns`] of `dy` for an input of `in_hw`.
pub fn launch_columns(
    dy: CubeTensor,
    in_hw: [usize; 2],
    kernel: usize,
    stride: usize,
    padding: usize,
) -> CubeTensor {
    let dims = dy.meta.shape().clone();
    assert!(
        dims.len() == 4 && dy.dtype == DType::F32,
        "an f32 [N, C, H, W] gradient"
    );
    let shape = [dims[0], in_hw[0] * in_hw[1], dims[1] * kernel * kernel];
    let cols = empty_f32(&dy, shape);
    let (cube_count, cube_dim) = elementwise(&dy, shape.iter().product());
    columns::launch(
        &dy.client,
        cube_count,
        cube_dim,
        dy.clone().into_tensor_arg(),
        cols.clone().into_tensor_arg(),
        in_hw[0] as u32,
        in_hw[1] as u32,
        kernel as u32,
        stride as u32,
        padding as u32,
    );
    cols
}

/// [`col2im`]: the layer's output `[N, c_out, Ho, Wo]` from its columns and bias.
#[allow(clippy::too_many_arguments)]
pub fn launch_col2im(
    cols: CubeTensor,
    bias: CubeTensor,
    in_hw: [usize; 2],
    out: [usize; 4],
    kernel: usize,
    stride: usize,
    padding: usize,
) -> CubeTensor {
    let y = empty_f32(&cols, out);
    let (cube_count, cube_dim) = elementwise(&cols, out.iter().product());
    col2im::launch(
        &cols.client,
        cube_count,
        cube_dim,
        cols.clone().into_tensor_arg(),
        bias.into_tensor_arg(),
        y.clone().into_tensor_arg(),
        in_hw[0] as u32,
        in_hw[1] as u32,
        kernel as u32,
        stride as u32,
        padding as u32,
    );
    y
}

/// [`channel_sums`] of `t` `[N, C, ...]`.
pub fn launch_channel_sums(t: CubeTensor) -> CubeTensor {
    let channels = t.meta.shape()[1];
    let sums = empty_f32(&t, [channels]);
    channel_sums::launch(
        &t.client,
        CubeCount::new_1d(channels as u32),
        CubeDim::new_1d(BLOCK as u32),
        t.clone().into_tensor_arg(),
        sums.clone().into_tensor_arg(),
        BLOCK,
    );
    sums
}
