//! Our CPU kernels: the convolution, its transpose and its weight gradient against their direct
//! references, and the backend extension's convolutions and bilinear resize against burn's
//! own ops, values and every gradient.

use burn::tensor::ops::{ConvOptions, ConvTransposeOptions};
use burn::tensor::{Device, Distribution, Tensor, TensorData, Tolerance};
use selfmodel::kernels::conv_gemm::{
    ConvGeometry, forward, forward_reference, transpose, transpose_backward, transpose_reference,
    weight_grad, weight_grad_reference,
};
use selfmodel::kernels::cpu_extension::{
    conv_transpose2d, conv2d, linear_layer, relu, resize_bilinear, sigmoid,
};
use selfmodel::train::losses::{bce_with_logits, bce_with_logits_composed};

fn values(n: usize, seed: u32) -> Vec<f32> {
    // A cheap deterministic sequence in [-1, 1).
    (0..n)
        .map(|i| {
            let v = (i as u32)
                .wrapping_mul(2_654_435_761)
                .wrapping_add(seed.wrapping_mul(97));
            (v >> 8) as f32 / (1 << 23) as f32 - 1.0
        })
        .collect()
}

#[test]
fn kernels_match_their_references() {
    let cases = [
        // batch, c_in, input, c_out, kernel, stride, padding
        (3, 4, [9, 7], 5, [3, 3], [1, 1], [1, 1]),
        (17, 2, [6, 6], 3, [4, 4], [2, 2], [1, 1]),
        (2, 3, [8, 5], 2, [1, 1], [1, 1], [0, 0]),
        (4, 2, [5, 5], 3, [3, 3], [1, 1], [2, 2]),
        (1, 1, [7, 9], 2, [3, 2], [2, 3], [0, 1]),
        // A lone image (fewer images than threads): im2col and col2im over its channels.
        (1, 6, [12, 10], 4, [4, 4], [2, 2], [1, 1]),
        (1, 5, [9, 9], 3, [3, 3], [1, 1], [1, 1]),
        // 64 output pixels or more (the GEMMs' other layout).
        (2, 3, [18, 18], 4, [4, 4], [2, 2], [1, 1]),
        (3, 2, [10, 9], 3, [3, 3], [1, 1], [1, 1]),
    ];
    for (batch, c_in, input, c_out, kernel, stride, padding) in cases {
        let g = ConvGeometry {
            batch,
            c_in,
            input,
            c_out,
            kernel,
            stride,
            padding,
        };
        let [oh, ow] = g.output();
        let x = values(batch * c_in * input[0] * input[1], 1);
        let go = values(batch * c_out * oh * ow, 2);
        let worst = |fast: Vec<f32>, slow: Vec<f32>| {
            assert_eq!(fast.len(), slow.len());
            fast.iter()
                .zip(&slow)
                .map(|(a, b)| (a - b).abs())
                .fold(0f32, f32::max)
        };
        let dw = worst(weight_grad(&x, &go, &g), weight_grad_reference(&x, &go, &g));
        assert!(dw < 1e-4, "{g:?}: weight gradient max difference {dw}");
        let w = values(c_out * c_in * kernel[0] * kernel[1], 3);
        let y = worst(forward(&x, &w, &g), forward_reference(&x, &w, &g));
        assert!(y < 1e-4, "{g:?}: forward max difference {y}");
        let t = worst(transpose(&go, &w, &g), transpose_reference(&go, &w, &g));
        assert!(t < 1e-4, "{g:?}: transposed convolution max difference {t}");
        if batch == 1 {
            // The lone image's result (its work spread over the threads) is, to the bit, what
            // it gets as one image of a batch (each image on one thread).
            let pair = ConvGeometry { batch: 2, ..g };
            let two = |v: &[f32]| [v, v].concat();
            let half = |v: Vec<f32>| v[..v.len() / 2].to_vec();
            assert_eq!(
                forward(&x, &w, &g),
                half(forward(&two(&x), &w, &pair)),
                "{g:?}"
            );
            assert_eq!(
                transpose(&go, &w, &g),
                half(transpose(&two(&go), &w, &pair)),
                "{g:?}"
            );
        }
        // The transposed convolution of `go` (its input) back onto `x`'s grid, with `x` as its
        // output gradient: input gradient `forward(x, w)`, weight gradient
        // `weight_grad(x, go)`.
        let (dx, dw) = transpose_backward(&go, &w, &x, &g);
        let dx = worst(dx, forward_reference(&x, &w, &g));
        let dw = worst(dw, weight_grad_reference(&x, &go, &g));
        assert!(
            dx < 1e-4 && dw < 1e-4,
            "{g:?}: transposed backward {dx} {dw}"
        );
    }
}

/// Value and gradients (input, weight, bias) of `f(x, w, b)` under a fixed upstream gradient.
fn value_and_grads(
    f: impl Fn(Tensor<4>, Tensor<4>, Tensor<1>) -> Tensor<4>,
    x: &Tensor<4>,
    w: &Tensor<4>,
    b: &Tensor<1>,
) -> [TensorData; 4] {
    let x = x.clone().require_grad();
    let w = w.clone().require_grad();
    let b = b.clone().require_grad();
    let y = f(x.clone(), w.clone(), b.clone());
    // A non-uniform upstream gradient: sum(y * y) / 2 has gradient y.
    let grads = (y.clone() * y.clone()).sum().div_scalar(2.0).backward();
    [
        y.into_data(),
        x.grad(&grads).unwrap().into_data(),
        w.grad(&grads).unwrap().into_data(),
        b.grad(&grads).unwrap().into_data(),
    ]
}

fn assert_close(ours: [TensorData; 4], burns: [TensorData; 4], what: &str) {
    for (name, (a, b)) in ["output", "input grad", "weight grad", "bias grad"]
        .iter()
        .zip(ours.iter().zip(&burns))
    {
        println!("{what}: {name}");
        a.assert_approx_eq::<f32>(b, Tolerance::rel_abs(1e-4, 1e-4));
    }
}

#[test]
fn conv2d_gradients_match_burn() {
    let dev = Device::flex().autodiff();
    for (k, s, p) in [(3, 1, 1), (1, 1, 0), (3, 2, 1)] {
        let x = Tensor::<4>::random([5, 3, 11, 9], Distribution::Default, &dev);
        let w = Tensor::<4>::random([4, 3, k, k], Distribution::Default, &dev);
        let b = Tensor::<1>::random([4], Distribution::Default, &dev);
        let options = ConvOptions::new([s, s], [p, p], [1, 1], 1);
        let ours = value_and_grads(|x, w, b| conv2d(x, w, Some(b), options.clone()), &x, &w, &b);
        let burns = value_and_grads(
            |x, w, b| burn::tensor::module::conv2d(x, w, Some(b), options.clone()),
            &x,
            &w,
            &b,
        );
        assert_close(ours, burns, &format!("conv2d k{k} s{s} p{p}"));
    }
}

#[test]
fn conv_transpose2d_gradients_match_burn() {
    let dev = Device::flex().autodiff();
    for (k, s, p) in [(4, 2, 1), (3, 1, 2), (3, 2, 0)] {
        let x = Tensor::<4>::random([5, 4, 6, 7], Distribution::Default, &dev);
        let w = Tensor::<4>::random([4, 3, k, k], Distribution::Default, &dev);
        let b = Tensor::<1>::random([3], Distribution::Default, &dev);
        let options = ConvTransposeOptions::new([s, s], [p, p], [0, 0], [1, 1], 1);
        let ours = value_and_grads(
            |x, w, b| conv_transpose2d(x, w, Some(b), options.clone()),
            &x,
            &w,
            &b,
        );
        let burns = value_and_grads(
            |x, w, b| burn::tensor::module::conv_transpose2d(x, w, Some(b), options.clone()),
            &x,
            &w,
            &b,
        );
        assert_close(ours, burns, &format!("conv_transpose2d k{k} s{s} p{p}"));
    }
}

#[test]
fn resize_bilinear_and_its_gradient_match_burn() {
    let dev = Device::flex().autodiff();
    for (input, output) in [([30, 30], [100, 100]), ([7, 9], [5, 13]), ([1, 4], [3, 4])] {
        let x = Tensor::<4>::random([3, 2, input[0], input[1]], Distribution::Default, &dev);
        let run = |resize: &dyn Fn(Tensor<4>) -> Tensor<4>| {
            let x = x.clone().require_grad();
            let y = resize(x.clone());
            let grads = (y.clone() * y.clone()).sum().div_scalar(2.0).backward();
            [y.into_data(), x.grad(&grads).unwrap().into_data()]
        };
        let ours = run(&|x| resize_bilinear(x, output));
        // The GPU path (two matrix products), run here on the CPU against the same reference.
        let matmul = run(&|x| selfmodel::kernels::bilinear_resize::resize_matmul(x, output));
        let burns = run(&|x| {
            let mut options = burn::tensor::ops::InterpolateOptions::new(
                burn::tensor::ops::InterpolateMode::Bilinear,
            )
            .with_output_size(output);
            options.align_corners = false;
            burn::tensor::module::interpolate(x, options)
        });
        for (name, (a, b)) in ["output", "input grad"].iter().zip(ours.iter().zip(&burns)) {
            println!("resize {input:?} -> {output:?}: {name}");
            a.assert_approx_eq::<f32>(b, Tolerance::rel_abs(1e-4, 1e-5));
        }
        for (name, (a, b)) in ["output", "input grad"]
            .iter()
            .zip(matmul.iter().zip(&burns))
        {
            println!("resize {input:?} -> {output:?} by matmul: {name}");
            a.assert_approx_eq::<f32>(b, Tolerance::rel_abs(1e-4, 1e-5));
        }
    }
}

/// ReLU on our parallel kernel: values and gradients equal to burn's, to the bit, over more
/// than one parallel chunk, NaN kept (as PyTorch does), on a non-contiguous input too.
#[test]
fn relu_and_its_gradient_equal_burns() {
    let dev = Device::flex().autodiff();
    let mut v = values(3 * 5 * 70 * 70, 7);
    v[11] = f32::NAN;
    v[40_000] = 0.0;
    let x = Tensor::<4>::from_data(TensorData::new(v, [3, 5, 70, 70]), &dev);
    let upstream = Tensor::<4>::random([3, 5, 70, 70], Distribution::Default, &dev);
    let run = |f: &dyn Fn(Tensor<4>) -> Tensor<4>, x: Tensor<4>| {
        let x = x.require_grad();
        let y = f(x.clone());
        let grads = (y.clone() * upstream.clone()).sum().backward();
        [y.into_data(), x.grad(&grads).unwrap().into_data()]
    };
    for (what, input) in [("contiguous", x.clone()), ("transposed", x.swap_dims(2, 3))] {
        let ours = run(&|x| relu(x), input.clone());
        let burns = run(&|x| burn::tensor::activation::relu(x), input);
        for (name, (a, b)) in ["output", "input grad"].iter().zip(ours.iter().zip(&burns)) {
            println!("relu, {what}: {name}");
            let (a, b) = (a.as_slice::<f32>().unwrap(), b.as_slice::<f32>().unwrap());
            assert_eq!(a.len(), b.len());
            for (i, (p, q)) in a.iter().zip(b).enumerate() {
                assert!(
                    p.to_bits() == q.to_bits(),
                    "{what} {name} [{i}]: {p} vs {q}"
                );
            }
        }
    }
}

/// The sigmoid on our kernel: flex's values and gradients to the bit. The binary
/// cross-entropy on logits in one kernel each way: the value and both gradients of burn's
/// composition of elementwise ops, to the bit (a training run gives the numbers it gave
/// before), over several chunks, with saturated logits.
#[test]
fn sigmoid_and_the_logit_cross_entropy_match_burn() {
    let dev = Device::flex().autodiff();
    let mut v = values(4 * 100 * 100, 3);
    v.iter_mut().step_by(97).for_each(|z| *z *= 60.0);
    let z = Tensor::<4>::from_data(TensorData::new(v, [4, 1, 100, 100]), &dev);
    let y = Tensor::<4>::random([4, 1, 100, 100], Distribution::Default, &dev);
    let upstream = Tensor::<4>::random([4, 1, 100, 100], Distribution::Default, &dev);
    let run = |f: &dyn Fn(Tensor<4>) -> Tensor<4>| {
        let z = z.clone().require_grad();
        let s = f(z.clone());
        let grads = (s.clone() * upstream.clone()).sum().backward();
        [s.into_data(), z.grad(&grads).unwrap().into_data()]
    };
    let ours = run(&|z| sigmoid(z));
    let burns = run(&|z| burn::tensor::activation::sigmoid(z));
    for (name, (a, b)) in ["sigmoid", "sigmoid grad"]
        .iter()
        .zip(ours.iter().zip(&burns))
    {
        println!("{name}");
        assert_eq!(a.as_slice::<f32>().unwrap(), b.as_slice::<f32>().unwrap());
    }
    let loss = |f: &dyn Fn(Tensor<4>, Tensor<4>) -> Tensor<1>| {
        let (z, y) = (z.clone().require_grad(), y.clone().require_grad());
        let l = f(z.clone(), y.clone()).mul_scalar(3.0);
        let grads = l.backward();
        [
            l.into_data(),
            z.grad(&grads).unwrap().into_data(),
            y.grad(&grads).unwrap().into_data(),
        ]
    };
    let ours = loss(&|z, y| bce_with_logits(z, y));
    let burns = loss(&|z, y| bce_with_logits_composed(z, y));
    for (name, (a, b)) in ["loss", "logit grad", "target grad"]
        .iter()
        .zip(ours.iter().zip(&burns))
    {
        println!("bce with logits: {name}");
        assert_eq!(a.as_slice::<f32>().unwrap(), b.as_slice::<f32>().unwrap());
    }
}

/// A layer's bias on our kernel: the output and the bias gradient of burn's broadcast add, to
/// the bit.
#[test]
fn the_bias_add_and_its_gradient_equal_burns() {
    let dev = Device::flex().autodiff();
    let x = Tensor::<4>::random([6, 5, 40, 30], Distribution::Default, &dev);
    let w = Tensor::<4>::random([3, 5, 3, 3], Distribution::Default, &dev);
    let b = Tensor::<1>::random([3], Distribution::Default, &dev);
    let options = ConvOptions::new([1, 1], [1, 1], [1, 1], 1);
    let run = |with_bias: bool| {
        let b = b.clone().require_grad();
        let y = if with_bias {
            conv2d(x.clone(), w.clone(), Some(b.clone()), options.clone())
        } else {
            conv2d(x.clone(), w.clone(), None, options.clone()) + b.clone().reshape([1, 3, 1, 1])
        };
        let grads = (y.clone() * y.clone()).sum().backward();
        [y.into_data(), b.grad(&grads).unwrap().into_data()]
    };
    let (ours, burns) = (run(true), run(false));
    for (name, (a, b)) in ["output", "bias grad"].iter().zip(ours.iter().zip(&burns)) {
        println!("bias: {name}");
        assert_eq!(a.as_slice::<f32>().unwrap(), b.as_slice::<f32>().unwrap());
    }
}

/// A linear layer on our kernel (blocks of output columns on the threads, for few rows) and
/// on burn's: the same values and gradients (input, weight, bias), at batch 1, at a batch of a
/// few rows and at one that leaves the product to gemm.
#[test]
fn linear_layers_and_their_gradients_match_burn() {
    let dev = Device::flex().autodiff();
    let layer = burn::nn::LinearConfig::new(1024, 1200).init(&dev);
    for batch in [1, 7, 100] {
        let x = Tensor::<2>::random([batch, 1024], Distribution::Default, &dev);
        let upstream = Tensor::<2>::random([batch, 1200], Distribution::Default, &dev);
        let run = |f: &dyn Fn(Tensor<2>) -> Tensor<2>| {
            let x = x.clone().require_grad();
            let y = f(x.clone());
            let grads = (y.clone() * upstream.clone()).sum().backward();
            [
                y.into_data(),
                x.grad(&grads).unwrap().into_data(),
                layer.weight.grad(&grads).unwrap().into_data(),
                layer
                    .bias
                    .as_ref()
                    .unwrap()
                    .grad(&grads)
                    .unwrap()
                    .into_data(),
            ]
        };
        let (m, k, n) = (batch, 1024, 1200);
        assert_eq!(
            selfmodel::kernels::linear::by_columns_pays(m, k, n),
            batch < 64
        );
        let ours = run(&|x| linear_layer(&layer, x));
        let burns = run(&|x| layer.forward(x));
        for (name, (a, b)) in ["output", "input grad", "weight grad", "bias grad"]
            .iter()
            .zip(ours.iter().zip(&burns))
        {
            println!("linear, batch {batch}: {name}");
            a.assert_approx_eq::<f32>(b, Tolerance::rel_abs(1e-5, 1e-5));
        }
    }
}

/// Subnormal floats are flushed to zero where the kernels run (rayon's workers, once a device
/// is selected) and nowhere else: the caller's thread keeps its floating-point environment.
/// With subnormal output gradients, the weight gradient is within 1e-37 of its f64 reference
/// (flushing changes nothing a normal float can hold).
#[test]
#[cfg(target_arch = "x86_64")]
fn subnormals_are_flushed_in_the_workers_only() {
    use selfmodel::core::denormals::flushed_on_this_thread;
    use std::hint::black_box;
    let caller = flushed_on_this_thread();
    selfmodel::core::device::select(selfmodel::core::device::DeviceChoice::Cpu).unwrap();
    assert_eq!(
        flushed_on_this_thread(),
        caller,
        "the caller's thread was changed"
    );
    // 1e-39 is subnormal in f32: read as zero (DAZ) on every worker.
    let on_workers = rayon::broadcast(|_| {
        (
            flushed_on_this_thread(),
            black_box(1e-39f32) * black_box(1.0f32) == 0.0,
        )
    });
    assert!(on_workers.iter().all(|&(f, z)| f && z), "{on_workers:?}");
    // On the caller (not flushed here), the same product is the subnormal itself.
    if !caller {
        assert!(black_box(1e-39f32) * black_box(1.0f32) > 0.0);
    }
    let g = ConvGeometry {
        batch: 4,
        c_in: 3,
        input: [8, 8],
        c_out: 2,
        kernel: [4, 4],
        stride: [2, 2],
        padding: [1, 1],
    };
    let [oh, ow] = g.output();
    let x = values(g.batch * g.c_in * 64, 5);
    let tiny: Vec<f32> = values(g.batch * g.c_out * oh * ow, 6)
        .iter()
        .map(|v| v * 1e-39)
        .collect();
    let dw = weight_grad(&x, &tiny, &g);
    let reference = weight_grad_reference(&x, &tiny, &g);
    let worst = dw
        .iter()
        .zip(&reference)
        .map(|(a, b)| (a - b).abs())
        .fold(0f32, f32::max);
    assert!(worst < 1e-37, "{worst}");
}
