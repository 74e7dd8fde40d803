//! 2-D convolution on the CPU by im2col and one GEMM per image: the forward pass, the
//! transposed convolution and the weight gradient, each with a direct loop reference beside it.
//!
//! The forward pass, `y_n[o, p] = W[o, (c, kh, kw)] · col_n[(c, kh, kw), p]`, reads and writes
//! NCHW directly. flex's own forward kernel transposes to NHWC and builds its columns a few
//! channels at a time; in a NeuroKin training step that copying was ~20% of the profile.
//!
//! burn-backend's default `conv2d_weight_backward` (which the flex backend uses) computes the
//! weight gradient as a convolution whose kernel is the activations: at NeuroKin's 100x100
//! head that is most of a training step. Here, per image `n`,
//!
//! `dWᵀ[(c, kh, kw), o] += col_n[(c, kh, kw), p] · G_n[o, p]ᵀ`, with `p` the output pixel,
//!
//! one `CKK x P x O` GEMM on an im2col buffer of one image (so memory stays `CKK x P` floats per
//! worker), transposed to `dW` once at the end. Images are split into a fixed number of chunks
//! whatever the thread count, each chunk sums its images in order, and the chunk sums are added
//! in order: the result does not depend on the scheduling.
//!
//! The same kernel gives a transposed convolution's weight gradient: for `y = conv_t(x, w)`
//! with stride `s` and padding `p`, `dW_t[c, o, kh, kw] = Σ x[n, c, i, j] · dy[n, o, i·s − p +
//! kh, j·s − p + kw]`, which is [`weight_grad`] with the convolution input `dy` and the output
//! gradient `x` (see [`crate::kernels::cpu_extension`]). Its input gradient is the forward convolution of
//! `dy`; [`transpose_backward`] computes both from one im2col of `dy`.
//!
//! A transposed convolution's forward pass is the adjoint of a convolution: `col_n = Wᵀ · x_n`,
//! then col2im (the adjoint of im2col) scatters the columns into the output ([`transpose`]).
//!
//! Every GEMM goes through one checked call, [`matmul`], whose operand layouts are chosen so
//! that gemm packs contiguous memory (see there).
//!
//! All tensors are row-major NCHW `f32` slices; groups 1, dilation 1.

use rayon::prelude::*;

use crate::kernels::parallel_output::{self, zeroed_in_parallel};

/// Shapes and hyper-parameters of a convolution `y = conv(x, w)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ConvGeometry {
    pub batch: usize,
    pub c_in: usize,
    /// Input height and width.
    pub input: [usize; 2],
    pub c_out: usize,
    pub kernel: [usize; 2],
    pub stride: [usize; 2],
    /// Zero padding on each side (symmetric).
    pub padding: [usize; 2],
}

impl ConvGeometry {
    /// The convolution of `x` `[batch, c_in, H, W]` with a weight `[c_out, c_in, kh, kw]`.
    pub fn conv(
        x: [usize; 4],
        weight: [usize; 4],
        stride: [usize; 2],
        padding: [usize; 2],
    ) -> Self {
        let [batch, c_in, h, w] = x;
        let [c_out, _, kh, kw] = weight;
        ConvGeometry {
            batch,
            c_in,
            input: [h, w],
            c_out,
            kernel: [kh, kw],
            stride,
            padding,
        }
    }

    /// The convolution whose adjoint is the transposed convolution of `x` `[batch, c, h, w]`
    /// with a weight `[c, c_out, kh, kw]` (PyTorch's layout) onto an `output` grid: it reads
    /// that grid with the same kernel, stride and padding and lands on `x`'s.
    pub fn transposed(
        x: [usize; 4],
        weight: [usize; 4],
        output: [usize; 2],
        stride: [usize; 2],
        padding: [usize; 2],
    ) -> Self {
        let [c, c_out, kh, kw] = weight;
        ConvGeometry {
            batch: x[0],
            c_in: c_out,
            input: output,
            c_out: c,
            kernel: [kh, kw],
            stride,
            padding,
        }
    }

    /// Output height and width, `(in + 2p − k) / s + 1`.
    pub fn output(&self) -> [usize; 2] {
        [0, 1].map(|d| (self.input[d] + 2 * self.padding[d] - self.kernel[d]) / self.stride[d] + 1)
    }

    /// Rows of the im2col matrix: `c_in · kh · kw`.
    fn patch(&self) -> usize {
        self.c_in * self.kernel[0] * self.kernel[1]
    }

    /// Whether the im2col matrix is the image itself (1x1 kernel, stride 1, no padding).
    fn im2col_is_identity(&self) -> bool {
        self.kernel == [1, 1] && self.stride == [1, 1] && self.padding == [0, 0]
    }

    /// Length of the im2col buffer one image needs (none when it is the image itself).
    fn columns_len(&self) -> usize {
        let [oh, ow] = self.output();
        if self.im2col_is_identity() {
            0
        } else {
            self.patch() * oh * ow
        }
    }

    fn check(&self, x: &[f32], grad_out: &[f32]) {
        let [oh, ow] = self.output();
        assert_eq!(
            x.len(),
            self.batch * self.c_in * self.input[0] * self.input[1]
        );
        assert_eq!(grad_out.len(), self.batch * self.c_out * oh * ow);
    }
}

/// Where a matrix's elements lie in a slice: element `(i, j)` at
/// `i * row_stride + j * col_stride`. Only row-major and column-major matrices and their
/// transposes can be made, so no two elements share a place.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Layout {
    rows: usize,
    cols: usize,
    row_stride: usize,
    col_stride: usize,
}

impl Layout {
    pub(crate) fn row_major(rows: usize, cols: usize) -> Self {
        Layout {
            rows,
            cols,
            row_stride: cols,
            col_stride: 1,
        }
    }

    /// A `rows x cols` block of a row-major matrix `row_stride` wide (at least `cols`).
    pub(crate) fn row_major_block(rows: usize, cols: usize, row_stride: usize) -> Self {
        assert!(row_stride >= cols);
        Layout {
            rows,
            cols,
            row_stride,
            col_stride: 1,
        }
    }

    fn column_major(rows: usize, cols: usize) -> Self {
        Layout {
            rows,
            cols,
            row_stride: 1,
            col_stride: rows,
        }
    }

    /// The transpose, over the same elements.
    pub(crate) fn t(self) -> Self {
        Layout {
            rows: self.cols,
            cols: self.rows,
            row_stride: self.col_stride,
            col_stride: self.row_stride,
        }
    }

    /// Elements a slice must hold.
    fn span(&self) -> usize {
        if self.rows == 0 || self.cols == 0 {
            0
        } else {
            (self.rows - 1) * self.row_stride + (self.cols - 1) * self.col_stride + 1
        }
    }
}

/// `dst = lhs · rhs`, or `dst += lhs · rhs` with `accumulate`: the one call into gemm, with
/// every shape and length checked. gemm copies `lhs` (after its own choice of orientation)
/// into panels, fast when the panel runs along contiguous elements and one float at a time
/// when not: the layouts the callers pass are chosen for that (measured).
pub(crate) fn matmul(
    (dst, d): (&mut [f32], Layout),
    (lhs, l): (&[f32], Layout),
    (rhs, r): (&[f32], Layout),
    accumulate: bool,
    parallelism: gemm::Parallelism,
) {
    assert!(
        d.rows == l.rows && d.cols == r.cols && l.cols == r.rows,
        "{d:?} {l:?} {r:?}"
    );
    assert!(d.span() <= dst.len() && l.span() <= lhs.len() && r.span() <= rhs.len());
    let stride = |s: usize| s as isize;
    // SAFETY: every element the layouts address lies inside its slice (asserted above); the
    // layouts of `dst` never address one element twice; `dst` is borrowed mutably, so it
    // aliases neither input.
    unsafe {
        gemm::gemm(
            d.rows,
            d.cols,
            l.cols,
            dst.as_mut_ptr(),
            stride(d.col_stride),
            stride(d.row_stride),
            accumulate,
            lhs.as_ptr(),
            stride(l.col_stride),
            stride(l.row_stride),
            rhs.as_ptr(),
            stride(r.col_stride),
            stride(r.row_stride),
            if accumulate { 1.0 } else { 0.0 },
            1.0,
            false,
            false,
            false,
            parallelism,
        );
    }
}

/// `out[O x P] = w[O x CKK] · col[CKK x P]` for one image.
fn gemm_weights_by_columns(
    out: &mut [f32],
    w: &[f32],
    col: &[f32],
    g: &ConvGeometry,
    parallelism: gemm::Parallelism,
) {
    let [oh, ow] = g.output();
    let (pixels, patch) = (oh * ow, g.patch());
    matmul(
        (out, Layout::row_major(g.c_out, pixels)),
        (w, Layout::row_major(g.c_out, patch)),
        (col, Layout::row_major(patch, pixels)),
        false,
        parallelism,
    );
}

/// `dwᵀ[CKK x O] += col[CKK x P] · go[O x P]ᵀ` for one image. The transposed gradient keeps
/// gemm's packed operand, `col`, contiguous along its rows: `dw = go · colᵀ` packs `col` one
/// strided float at a time, 3-4x slower at 64x64 pixels (measured).
fn gemm_accumulate_weight_grad_t(dwt: &mut [f32], go: &[f32], col: &[f32], g: &ConvGeometry) {
    let [oh, ow] = g.output();
    let (pixels, patch) = (oh * ow, g.patch());
    matmul(
        (dwt, Layout::row_major(patch, g.c_out)),
        (col, Layout::row_major(patch, pixels)),
        (go, Layout::row_major(g.c_out, pixels).t()),
        true,
        gemm::Parallelism::None,
    );
}

/// `dst` `[cols, rows]` = the transpose of the row-major `src` `[rows, cols]`.
fn transpose_into(src: &[f32], rows: usize, cols: usize, dst: &mut [f32]) {
    assert!(src.len() == rows * cols && dst.len() == rows * cols);
    for (i, row) in src.chunks(cols).enumerate() {
        for (j, &v) in row.iter().enumerate() {
            dst[j * rows + i] = v;
        }
    }
}

/// `dw` `[O, CKK]` from the chunk sums of `dwᵀ` `[CKK, O]`, added in order.
fn weight_grad_from_chunks(chunk_sums: Vec<Vec<f32>>, g: &ConvGeometry) -> Vec<f32> {
    let patch = g.patch();
    let mut total = vec![0f32; g.c_out * patch];
    for part in chunk_sums {
        for (t, v) in total.iter_mut().zip(part) {
            *t += v;
        }
    }
    let mut dw = vec![0f32; g.c_out * patch];
    transpose_into(&total, patch, g.c_out, &mut dw);
    dw
}

/// The im2col matrix of one image `[c_in, H, W]`: the image itself for a 1x1 kernel with
/// stride 1 and no padding, else [`im2col`] into `buffer` (of [`ConvGeometry::columns_len`]).
fn columns<'a>(
    image: &'a [f32],
    g: &ConvGeometry,
    buffer: &'a mut [f32],
    spread: Spread,
) -> &'a [f32] {
    if g.im2col_is_identity() {
        image
    } else {
        im2col(image, g, buffer, spread);
        buffer
    }
}

/// Whether a lone image's im2col and col2im run over its channels on every thread (when
/// there are fewer images than threads, as its GEMM does) or on the calling one. Each
/// channel's rows or plane are written by one thread in the same order either way: the same
/// result to the bit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Spread {
    OneThread,
    Channels,
}

impl Spread {
    fn of(parallelism: gemm::Parallelism) -> Self {
        match parallelism {
            gemm::Parallelism::None => Spread::OneThread,
            _ => Spread::Channels,
        }
    }

    /// `f(channel, block)` over consecutive blocks of `len` elements of `data`, one per
    /// channel, at least ~16k elements a rayon job.
    fn each_channel(self, data: &mut [f32], len: usize, f: impl Fn(usize, &mut [f32]) + Sync) {
        match self {
            Spread::OneThread => data.chunks_mut(len).enumerate().for_each(|(c, b)| f(c, b)),
            Spread::Channels => data
                .par_chunks_mut(len)
                .with_min_len(((1 << 14) / len.max(1)).max(1))
                .enumerate()
                .for_each(|(c, b)| f(c, b)),
        }
    }
}

/// The environment variable that sets [`image_parallelism`]'s work per thread (multiply-adds;
/// 0, the default: every thread, gemm's own rule), for the GPU check's thread sweep.
pub const WORK_PER_THREAD_VAR: &str = "SELFMODEL_GEMM_WORK_PER_THREAD";

/// How one image's GEMM of `macs` multiply-adds is split when there are fewer images
/// (`batch`) than threads (with as many images as threads, each image's GEMM runs on one):
/// over every thread, or, with a work per thread set ([`WORK_PER_THREAD_VAR`]), over at most
/// `macs / work` threads, so that no thread's share is too small to pay for waking it. The
/// split is over output rows and pixels, never over the sum: the result is the same at any
/// thread count.
fn image_parallelism(batch: usize, macs: usize) -> gemm::Parallelism {
    static WORK: std::sync::OnceLock<usize> = std::sync::OnceLock::new();
    let threads = rayon::current_num_threads();
    if batch >= threads {
        return gemm::Parallelism::None;
    }
    let work = *WORK.get_or_init(|| {
        std::env::var(WORK_PER_THREAD_VAR)
            .ok()
            .and_then(|v| v.trim().parse().ok())
            .unwrap_or(0)
    });
    if work == 0 {
        return gemm::Parallelism::Rayon(0);
    }
    match (macs / work).min(threads) {
        0 | 1 => gemm::Parallelism::None,
        n => gemm::Parallelism::Rayon(n),
    }
}

/// Images per chunk: at most `CHUNKS` chunks, whatever the number of threads.
const CHUNKS: usize = 8;

/// `y` `[batch, c_out, Ho, Wo]` = the convolution of `x` `[batch, c_in, H, W]` with `w`
/// `[c_out, c_in, kh, kw]`, no bias. Images run in parallel; a lone image runs its GEMM on all
/// threads (split over output rows and pixels, never over the sum, so results do not depend on
/// the scheduling).
pub fn forward(x: &[f32], w: &[f32], g: &ConvGeometry) -> Vec<f32> {
    let [oh, ow] = g.output();
    let pixels = oh * ow;
    let patch = g.patch();
    let image_in = g.c_in * g.input[0] * g.input[1];
    assert_eq!(x.len(), g.batch * image_in);
    assert_eq!(w.len(), g.c_out * patch);
    let parallelism = image_parallelism(g.batch, g.c_out * pixels * patch);
    zeroed_in_parallel(
        g.batch * g.c_out * pixels,
        g.c_out * pixels,
        || vec![0f32; g.columns_len()],
        |buffer, n, out| {
            let col = columns(
                &x[n * image_in..(n + 1) * image_in],
                g,
                buffer,
                Spread::of(parallelism),
            );
            gemm_weights_by_columns(out, w, col, g, parallelism);
        },
    )
}

/// `dW` of shape `[c_out, c_in, kh, kw]`, from the input `x` `[batch, c_in, H, W]` and the
/// output gradient `grad_out` `[batch, c_out, Ho, Wo]`.
pub fn weight_grad(x: &[f32], grad_out: &[f32], g: &ConvGeometry) -> Vec<f32> {
    weight_grad_chunks(x, grad_out, g, None)
}

/// Both gradients of the transposed convolution [`transpose`]`(x, w, g)` from its output
/// gradient `grad_out` `[batch, c_in, H, W]` (the input of the convolution `g`): the input
/// gradient `dx = forward(grad_out, w)` `[batch, c_out, Ho, Wo]` and the weight gradient
/// `dw = weight_grad(grad_out, x)` `[c_out, c_in, kh, kw]`. Both multiply the same im2col
/// matrix of `grad_out`, built once per image here instead of twice.
pub fn transpose_backward(
    x: &[f32],
    w: &[f32],
    grad_out: &[f32],
    g: &ConvGeometry,
) -> (Vec<f32>, Vec<f32>) {
    let mut dx = parallel_output::zeros(x.len());
    let dw = weight_grad_chunks(grad_out, x, g, Some((w, &mut dx)));
    (dx, dw)
}

/// [`weight_grad`] of the convolution `g` over a fixed number of image chunks (each sums its
/// images in order, the chunk sums are added in order: the result does not depend on the
/// scheduling). With `forward_into = Some((w, y))` it also writes `y = forward(x, w)` from the
/// same im2col matrices ([`transpose_backward`]).
fn weight_grad_chunks(
    x: &[f32],
    grad_out: &[f32],
    g: &ConvGeometry,
    forward_into: Option<(&[f32], &mut [f32])>,
) -> Vec<f32> {
    g.check(x, grad_out);
    let [oh, ow] = g.output();
    let patch = g.patch();
    let image_in = g.c_in * g.input[0] * g.input[1];
    let image_out = g.c_out * oh * ow;
    let per_chunk = g.batch.div_ceil(CHUNKS).max(1);
    let chunks = g.batch.div_ceil(per_chunk);
    let (w, outputs): (Option<&[f32]>, Vec<Option<&mut [f32]>>) = match forward_into {
        Some((w, y)) => {
            assert_eq!(y.len(), grad_out.len());
            (
                Some(w),
                y.chunks_mut(per_chunk * image_out).map(Some).collect(),
            )
        }
        None => (None, (0..chunks).map(|_| None).collect()),
    };
    let chunk_sums: Vec<Vec<f32>> = outputs
        .into_par_iter()
        .enumerate()
        .map(|(chunk, mut y_chunk)| {
            let mut dwt = vec![0f32; g.c_out * patch];
            let mut buffer = vec![0f32; g.columns_len()];
            let first = chunk * per_chunk;
            for n in first..(first + per_chunk).min(g.batch) {
                let image = &x[n * image_in..(n + 1) * image_in];
                let col = columns(image, g, &mut buffer, Spread::OneThread);
                if let (Some(w), Some(y)) = (w, y_chunk.as_deref_mut()) {
                    let y_n = &mut y[(n - first) * image_out..(n - first + 1) * image_out];
                    gemm_weights_by_columns(y_n, w, col, g, gemm::Parallelism::None);
                }
                let go = &grad_out[n * image_out..(n + 1) * image_out];
                gemm_accumulate_weight_grad_t(&mut dwt, go, col, g);
            }
            dwt
        })
        .collect();
    weight_grad_from_chunks(chunk_sums, g)
}

/// The transposed convolution of `x` `[batch, c_out, Ho, Wo]` with `w` `[c_out, c_in, kh, kw]`
/// (PyTorch's `ConvTranspose2d` layout, `[in, out, k, k]` of the layer), no bias: the adjoint
/// of the convolution `g` (whose input is this function's output, `[batch, c_in, H, W]`).
/// Images run in parallel.
pub fn transpose(x: &[f32], w: &[f32], g: &ConvGeometry) -> Vec<f32> {
    let [oh, ow] = g.output();
    let pixels = oh * ow;
    let patch = g.patch();
    let image_out = g.c_in * g.input[0] * g.input[1];
    assert_eq!(x.len(), g.batch * g.c_out * pixels);
    assert_eq!(w.len(), g.c_out * patch);
    let parallelism = image_parallelism(g.batch, g.c_out * pixels * patch);
    // With few pixels, gemm's output rows (pixels) fill its 64-row microkernel poorly: write
    // `col` column-major (one pixel's patch contiguous) and transpose it for col2im. 2.4x faster
    // for NeuroKin-64's 4x4 layer (measured), the same elsewhere.
    let column_major = pixels < 64;
    zeroed_in_parallel(
        g.batch * image_out,
        image_out,
        || (vec![0f32; patch * pixels], vec![0f32; patch * pixels]),
        |(col, scratch), n, out| {
            let xn = &x[n * g.c_out * pixels..(n + 1) * g.c_out * pixels];
            // col[CKK x P] = wᵀ[CKK x O] · x_n[O x P]
            let (dst, layout) = if column_major {
                (&mut *scratch, Layout::column_major(patch, pixels))
            } else {
                (&mut *col, Layout::row_major(patch, pixels))
            };
            let w_t = Layout::row_major(g.c_out, patch).t();
            let x_n = Layout::row_major(g.c_out, pixels);
            matmul((dst, layout), (w, w_t), (xn, x_n), false, parallelism);
            if column_major {
                transpose_into(scratch, pixels, patch, col);
            }
            col2im(col, g, out, Spread::of(parallelism));
        },
    )
}

/// The adjoint of [`im2col`]: add `col[(c, kh, kw), (oy, ox)]` into the image `[c_in, H, W]`
/// (zeros on entry).
fn col2im(col: &[f32], g: &ConvGeometry, image: &mut [f32], spread: Spread) {
    let [h, w] = g.input;
    let [oh, ow] = g.output();
    let [kh, kw] = g.kernel;
    let [sy, sx] = g.stride;
    let [py, px] = g.padding;
    spread.each_channel(image, h * w, |c, plane| {
        for ky in 0..kh {
            for kx in 0..kw {
                let row = &col[((c * kh + ky) * kw + kx) * oh * ow..][..oh * ow];
                // ox range whose ix = ox·sx + kx − px lies in [0, w).
                let lo = px.saturating_sub(kx).div_ceil(sx);
                let hi = ((w + px).saturating_sub(kx)).div_ceil(sx).min(ow);
                for oy in 0..oh {
                    let iy = (oy * sy + ky) as isize - py as isize;
                    if iy < 0 || iy >= h as isize || lo >= hi {
                        continue;
                    }
                    let dst = &mut plane[iy as usize * w..(iy as usize + 1) * w];
                    let src = &row[oy * ow..(oy + 1) * ow];
                    let ix0 = lo * sx + kx - px;
                    if sx == 1 {
                        for (d, &v) in dst[ix0..ix0 + hi - lo].iter_mut().zip(&src[lo..hi]) {
                            *d += v;
                        }
                    } else {
                        for (i, &v) in src[lo..hi].iter().enumerate() {
                            dst[ix0 + i * sx] += v;
                        }
                    }
                }
            }
        }
    });
}

/// One image `[c_in, H, W]` to `col[(c, kh, kw), (oy, ox)]`, zeros where the patch leaves the
/// image.
fn im2col(x: &[f32], g: &ConvGeometry, col: &mut [f32], spread: Spread) {
    let [h, w] = g.input;
    let [oh, ow] = g.output();
    let [kh, kw] = g.kernel;
    let [sy, sx] = g.stride;
    let [py, px] = g.padding;
    spread.each_channel(
        &mut col[..g.c_in * kh * kw * oh * ow],
        kh * kw * oh * ow,
        |c, rows| {
            let plane = &x[c * h * w..(c + 1) * h * w];
            for ky in 0..kh {
                for kx in 0..kw {
                    let row = &mut rows[(ky * kw + kx) * oh * ow..][..oh * ow];
                    for oy in 0..oh {
                        let out = &mut row[oy * ow..(oy + 1) * ow];
                        let iy = (oy * sy + ky) as isize - py as isize;
                        if iy < 0 || iy >= h as isize {
                            out.fill(0.0);
                            continue;
                        }
                        let src = &plane[iy as usize * w..(iy as usize + 1) * w];
                        if sx == 1 {
                            // ix = ox + kx − px: one shifted copy with zeros at the borders.
                            let shift = kx as isize - px as isize;
                            let lo = (-shift).clamp(0, ow as isize) as usize;
                            let hi = (w as isize - shift).clamp(lo as isize, ow as isize) as usize;
                            out[..lo].fill(0.0);
                            out[hi..].fill(0.0);
                            let start = (lo as isize + shift) as usize;
                            out[lo..hi].copy_from_slice(&src[start..start + hi - lo]);
                        } else {
                            // ox range whose ix = ox·sx + kx − px lies in [0, w): a strided copy.
                            let lo = px.saturating_sub(kx).div_ceil(sx).min(ow);
                            let hi = (w + px).saturating_sub(kx).div_ceil(sx).clamp(lo, ow);
                            out[..lo].fill(0.0);
                            out[hi..].fill(0.0);
                            if lo < hi {
                                let ix0 = lo * sx + kx - px;
                                let strided = src[ix0..].iter().step_by(sx);
                                for (o, &v) in out[lo..hi].iter_mut().zip(strided) {
                                    *o = v;
                                }
                            }
                        }
                    }
                }
            }
        },
    );
}

/// Every tap of the convolution `g`: `visit(x_index, y_index, w_index)` for each input element
/// `x[n, c, iy, ix]` that output `y[n, o, oy, ox]` reads through weight `w[o, c, ky, kx]`. The
/// three references below are this one definition, read three ways.
fn taps(g: &ConvGeometry, mut visit: impl FnMut(usize, usize, usize)) {
    let [h, w] = g.input;
    let [oh, ow] = g.output();
    let [kh, kw] = g.kernel;
    for n in 0..g.batch {
        for o in 0..g.c_out {
            for c in 0..g.c_in {
                for ky in 0..kh {
                    for kx in 0..kw {
                        let wi = ((o * g.c_in + c) * kh + ky) * kw + kx;
                        for oy in 0..oh {
                            let iy = (oy * g.stride[0] + ky) as isize - g.padding[0] as isize;
                            if iy < 0 || iy >= h as isize {
                                continue;
                            }
                            for ox in 0..ow {
                                let ix = (ox * g.stride[1] + kx) as isize - g.padding[1] as isize;
                                if ix < 0 || ix >= w as isize {
                                    continue;
                                }
                                let xi = ((n * g.c_in + c) * h + iy as usize) * w + ix as usize;
                                let yi = ((n * g.c_out + o) * oh + oy) * ow + ox;
                                visit(xi, yi, wi);
                            }
                        }
                    }
                }
            }
        }
    }
}

fn to_f32(v: Vec<f64>) -> Vec<f32> {
    v.into_iter().map(|v| v as f32).collect()
}

/// The slow reference of [`forward`]: the definition, summed in `f64`.
pub fn forward_reference(x: &[f32], w: &[f32], g: &ConvGeometry) -> Vec<f32> {
    let [oh, ow] = g.output();
    let mut y = vec![0f64; g.batch * g.c_out * oh * ow];
    taps(g, |xi, yi, wi| y[yi] += x[xi] as f64 * w[wi] as f64);
    to_f32(y)
}

/// The slow reference of [`transpose`]: the definition, summed in `f64`.
pub fn transpose_reference(x: &[f32], w: &[f32], g: &ConvGeometry) -> Vec<f32> {
    let mut y = vec![0f64; g.batch * g.c_in * g.input[0] * g.input[1]];
    taps(g, |yi, xi, wi| y[yi] += x[xi] as f64 * w[wi] as f64);
    to_f32(y)
}

/// The slow reference of [`weight_grad`]: the definition, summed in `f64`.
pub fn weight_grad_reference(x: &[f32], grad_out: &[f32], g: &ConvGeometry) -> Vec<f32> {
    g.check(x, grad_out);
    let mut dw = vec![0f64; g.c_out * g.patch()];
    taps(g, |xi, yi, wi| dw[wi] += x[xi] as f64 * grad_out[yi] as f64);
    to_f32(dw)
}
