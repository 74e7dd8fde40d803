//! Convolutions as matrix products, the GPU kernels around the product: [`columns`] (im2col:
//! the patches a convolution multiplies, `[N, h·w, C·k·k]`), [`col2im`] (the sum of columns
//! back into an image, with a bias); a layer's bias gradient is
//! [`super::channel_reduce::launch_channel_sums`].
//!
//! For a patch grid of `h × w`, kernel `k`, stride `s` and padding `p`,
//! `cols[n, (i, j), (c, ky, kx)] = t[n, c, i·s − p + ky, j·s − p + kx]` (0 outside):
//! - a convolution's forward pass is `W · colsᵀ` on the columns of its input (the grid its
//!   output), and its input gradient the col2im of `dy · W`;
//! - a transposed convolution's forward pass is the col2im of `xᵀ W` (the grid its input),
//!   and its gradients come from the columns of its output gradient.
//!
//! `kernels::cube::convolution` puts them in burn's autodiff graph; the slow references are
//! burn's own `conv2d` and `conv_transpose2d` and their backward passes, which
//! `tests/gpu/kernels.rs` compares them with.

use burn_cubecl::tensor::CubeTensor;
use cubecl::prelude::*;

use super::{elementwise, empty_f32, holds_f32, over_elements};

/// The patch grid as the kernels read it (see [`Patches`]).
#[derive(CubeLaunch, CubeType)]
pub struct PatchGrid {
    in_h: usize,
    in_w: usize,
    kernel: usize,
    stride: usize,
    padding: usize,
}

/// `cols` `[N, h·w, C·k·k]` from `t` `[N, C, H, W]` (any strides) for a grid of `h × w`.
#[cube(launch)]
pub fn columns(t: &Tensor<f32>, cols: &mut Tensor<f32>, grid: PatchGrid) {
    let k = ABSOLUTE_POS;
    if k < cols.len() {
        let (c_out, out_h, out_w) = (t.shape(1), t.shape(2), t.shape(3));
        let (kernel, stride, padding) = (grid.kernel, grid.stride, grid.padding);
        let width = c_out * kernel * kernel;
        let q = k % width;
        let pix = (k / width) % (grid.in_h * grid.in_w);
        let n = k / (width * grid.in_h * grid.in_w);
        let (co, kk) = (q / (kernel * kernel), q % (kernel * kernel));
        let (ky, kx) = (kk / kernel, kk % kernel);
        let (iy, ix) = (pix / grid.in_w, pix % grid.in_w);
        // oy = iy s − p + ky, kept unsigned: oy + p = iy s + ky.
        let (oyp, oxp) = (iy * stride + ky, ix * stride + kx);
        let mut v = 0.0;
        if oyp >= padding && oxp >= padding && oyp - padding < out_h && oxp - padding < out_w {
            // Through the image's strides (a channels-last view is read in place), from the
            // indices already at hand: no division by its shape per element.
            v = t[n * t.stride(0)
                + co * t.stride(1)
                + (oyp - padding) * t.stride(2)
                + (oxp - padding) * t.stride(3)];
        }
        cols[k] = v;
    }
}

/// The image `[N, C, H, W]` whose columns (over a grid of `h × w`) are `cols`
/// `[N, h·w, C·k·k]`, summed where patches overlap:
/// `y[n, c, oy, ox] = b[c] + Σ cols[n, (iy, ix), (c, ky, kx)]` over `oy = iy·s − p + ky`
/// (and the same across), contiguous out; `b` only `with_bias`.
#[cube(launch)]
pub fn col2im(
    cols: &Tensor<f32>,
    bias: &Tensor<f32>,
    y: &mut Tensor<f32>,
    grid: PatchGrid,
    #[comptime] with_bias: bool,
) {
    let k = ABSOLUTE_POS;
    if k < y.len() {
        let (c_out, out_h, out_w) = (y.shape(1), y.shape(2), y.shape(3));
        let (kernel, stride, padding) = (grid.kernel, grid.stride, grid.padding);
        let (in_h, in_w) = (grid.in_h, grid.in_w);
        let ox = k % out_w;
        let oy = (k / out_w) % out_h;
        let co = (k / (out_w * out_h)) % c_out;
        let n = k / (out_w * out_h * c_out);
        let mut acc = 0.0;
        if with_bias {
            acc = bias[co];
        }
        for ky in 0..kernel {
            // iy·s = oy + p − ky, kept unsigned.
            let ty = oy + padding;
            if ty >= ky && (ty - ky) % stride == 0 && (ty - ky) / stride < in_h {
                let iy = (ty - ky) / stride;
                for kx in 0..kernel {
                    let tx = ox + padding;
                    if tx >= kx && (tx - kx) % stride == 0 && (tx - kx) / stride < in_w {
                        let ix = (tx - kx) / stride;
                        // Through the columns' strides (a product's transposed output is read
                        // in place).
                        acc += cols[n * cols.stride(0)
                            + (iy * in_w + ix) * cols.stride(1)
                            + ((co * kernel + ky) * kernel + kx) * cols.stride(2)];
                    }
                }
            }
        }
        y[k] = acc;
    }
}

/// A convolution's patches: a grid of `grid` `[h, w]` patches of `kernel × kernel` pixels,
/// `stride` apart, over the image padded by `padding` on every side.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Patches {
    pub grid: [usize; 2],
    pub kernel: usize,
    pub stride: usize,
    pub padding: usize,
}

/// What columns fold back into ([`col2im`], PyTorch's `fold`): the image `out`
/// `[N, C, H, W]`, the patches the columns are of, and whether a bias is added.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fold {
    pub out: [usize; 4],
    pub patches: Patches,
    pub with_bias: bool,
}

impl Patches {
    /// The columns' width for `channels` channels: `C·k·k`.
    pub fn width(&self, channels: usize) -> usize {
        channels * self.kernel * self.kernel
    }

    fn launch_arg(&self) -> PatchGridLaunch {
        let [in_h, in_w] = self.grid;
        PatchGridLaunch::new(in_h, in_w, self.kernel, self.stride, self.padding)
    }
}

/// [`columns`] of `t` over `patches`.
pub fn launch_columns(t: CubeTensor, patches: Patches) -> CubeTensor {
    let dims = t.meta.shape().clone();
    assert!(
        dims.len() == 4 && holds_f32(&t),
        "an f32 [N, C, H, W] image"
    );
    let [h, w] = patches.grid;
    let shape = [dims[0], h * w, patches.width(dims[1])];
    let cols = empty_f32(&t, shape);
    let (cube_count, cube_dim) = elementwise(&t, shape.iter().product());
    over_elements(shape.iter().product(), || {
        columns::launch(
            &t.client,
            cube_count,
            cube_dim,
            t.clone().into_tensor_arg(),
            cols.clone().into_tensor_arg(),
            patches.launch_arg(),
        )
    });
    cols
}

/// [`col2im`]: the image `out` `[N, C, H, W]` from its columns over `patches`, plus `bias`
/// `[C]` where there is one.
pub fn launch_col2im(
    cols: CubeTensor,
    bias: Option<CubeTensor>,
    patches: Patches,
    out: [usize; 4],
) -> CubeTensor {
    let y = empty_f32(&cols, out);
    let (cube_count, cube_dim) = elementwise(&cols, out.iter().product());
    // Without a bias the kernel reads none: any other buffer stands in (one element).
    let with_bias = bias.is_some();
    let bias = bias.unwrap_or_else(|| empty_f32(&cols, [1]));
    over_elements(cols.meta.num_elements(), || {
        col2im::launch(
            &cols.client,
            cube_count,
            cube_dim,
            cols.clone().into_tensor_arg(),
            bias.into_tensor_arg(),
            y.clone().into_tensor_arg(),
            patches.launch_arg(),
            with_bias,
        )
    });
    y
}
