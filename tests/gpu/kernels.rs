//! Our GPU kernels (`kernels::cube`) on wgpu (lavapipe in CI) against burn's own operations:
//! the convolutions against burn's on the CPU (no kernel of burn's compiled and tuned for
//! them on lavapipe, minutes there), Adam, batch norm and the loss against burn's on the same
//! device. Part of `tests/gpu.rs`.

use burn::module::{Module, ModuleVisitor, Param};
use burn::optim::{AdamConfig, GradientsParams, ModuleOptimizer};
use burn::tensor::{Distribution, Tensor};
use selfmodel::core::device::{DeviceChoice, select, with_seed};
use selfmodel::core::preset::Preset;
use selfmodel::self_models::neurokin::{NeuroKin, NeuroKinConfig};
use selfmodel::train::adam::{self, clip_global_norm};
use selfmodel::train::trainer::autodiff_device;

/// Every parameter of a module, flattened, in visiting order.
fn values<M: Module>(m: &M) -> Vec<Vec<f32>> {
    struct Collect(Vec<Vec<f32>>);
    impl ModuleVisitor for Collect {
        fn visit_float<const D: usize>(&mut self, p: &Param<Tensor<D>>) {
            self.0
                .push(p.val().into_data().try_to_vec::<f32>().unwrap());
        }
    }
    let mut c = Collect(Vec::new());
    m.visit(&mut c);
    c.0
}

fn largest_difference(a: &[Vec<f32>], b: &[Vec<f32>]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .flat_map(|(x, y)| {
            assert_eq!(x.len(), y.len());
            x.iter().zip(y).map(|(p, q)| (p - q).abs())
        })
        .fold(0.0, f32::max)
}

/// burn's Adam with our settings: the reference of the fused step.
fn burns_adam() -> ModuleOptimizer {
    ModuleOptimizer::from(AdamConfig::new().with_epsilon(1e-5).build())
}

/// A copy of the gradients (`GradientsParams` is not `Clone`).
fn copy(model: &NeuroKin, grads: &GradientsParams) -> GradientsParams {
    struct Copy<'a>(&'a GradientsParams, GradientsParams);
    impl ModuleVisitor for Copy<'_> {
        fn visit_float<const D: usize>(&mut self, p: &Param<Tensor<D>>) {
            if let Some(g) = self.0.get::<D>(p.id) {
                self.1.register(p.id, g);
            }
        }
    }
    let mut c = Copy(grads, GradientsParams::new());
    model.visit(&mut c);
    c.1
}

/// A gradient for every parameter of `model`, drawn from N(0, 0.1^2) (seeded): what Adam
/// is given, without a forward and backward pass to compute it (the optimiser is what is
/// tested; a pass would compile and tune the model's products on lavapipe for minutes).
fn random_grads(model: &NeuroKin, seed: u64) -> GradientsParams {
    struct Draw(GradientsParams);
    impl ModuleVisitor for Draw {
        fn visit_float<const D: usize>(&mut self, p: &Param<Tensor<D>>) {
            let v = p.val().inner();
            let g = Tensor::<D>::random(v.shape(), Distribution::Normal(0.0, 0.1), &v.device());
            self.0.register(p.id, g);
        }
    }
    let device = model.devices()[0].clone();
    with_seed(&device, seed, || {
        let mut d = Draw(GradientsParams::new());
        model.visit(&mut d);
        d.0
    })
}

/// Adam over every parameter in a few launches (with the global-norm clipping inside)
/// against burn's Adam after burn's clipping, step by step on the same gradients; then the
/// optimiser states: the fused step's loads into burn's and the two go on alike.
#[test]
fn the_fused_adam_step_is_burns() {
    let device = select(DeviceChoice::Wgpu).unwrap();
    let tdev = autodiff_device(&device, 0);
    let cfg = NeuroKinConfig::quick();
    let model = cfg.init(&tdev, 3).unwrap();
    let (mut fused, mut reference) = (model.clone(), model);
    let (mut opt_fused, mut opt_reference) = (adam::adam(), burns_adam());
    let max_norm = 0.05;
    for step in 0..3 {
        // The same gradients for both (the parameters differ by rounding only).
        let mut g_ref = random_grads(&reference, 5 + step);
        let g_fused = copy(&reference, &g_ref);
        let norm = clip_global_norm(&reference, &mut g_ref, max_norm).unwrap();
        let norm: f32 = norm.into_scalar();
        assert!(
            norm > max_norm,
            "step {step}: the norm {norm} is not clipped"
        );
        reference = opt_reference.step(1e-3, reference, g_ref);
        fused = adam::step(&mut opt_fused, 1e-3, fused, g_fused, Some(max_norm));
        let d = largest_difference(&values(&fused), &values(&reference));
        eprintln!("step {step}: norm {norm:.4}, largest parameter difference {d:.2e}");
        assert!(d < 1e-5, "step {step}: parameters differ by {d}");
    }
    // The state of the fused steps is burn's: it loads into burn's Adam.
    let record = opt_fused.to_record();
    let mut opt_loaded = burns_adam().load_record(record);
    let g = random_grads(&reference, 9);
    let g2 = copy(&reference, &g);
    let a = opt_loaded.step(1e-3, reference.clone(), g);
    let b = opt_reference.step(1e-3, reference, g2);
    let d = largest_difference(&values(&a), &values(&b));
    assert!(d < 1e-5, "the loaded state steps {d} away from burn's own");
}

/// A batch-norm layer in training on our kernels (statistics and parameter gradients in two
/// launches each, the input gradient in one), with and without the ReLU after it, against
/// burn's `BatchNorm` (and ReLU): outputs, running statistics and every gradient. A small
/// plain input (one chunk a channel), and a channels-last view of 1.2 M elements whose sums
/// run over hundreds of chunks.
#[test]
fn batch_norm_on_our_kernels_is_burns() {
    let device = select(DeviceChoice::Wgpu).unwrap();
    let tdev = autodiff_device(&device, 0);
    let (x, w) = with_seed(&tdev, 7, || {
        (
            Tensor::<4>::random([5, 3, 7, 6], Distribution::Normal(0.5, 2.0), &tdev).require_grad(),
            Tensor::<4>::random([5, 3, 7, 6], Distribution::Default, &tdev),
        )
    });
    // Within f32 rounding of sums that cancel (Σ g (x - mean)), in another order than burn's.
    batch_norm_case(x, w, &[1.5, 0.7, -0.3], 5e-6);
    // [N, H, W, C] seen as [N, C, H, W]: a convolution's output, channels last.
    let (x, w) = with_seed(&tdev, 8, || {
        (
            Tensor::<4>::random([32, 40, 40, 24], Distribution::Normal(3.0, 0.5), &tdev)
                .permute([0, 3, 1, 2])
                .require_grad(),
            Tensor::<4>::random([32, 24, 40, 40], Distribution::Default, &tdev),
        )
    });
    let gamma: Vec<f32> = (0..24).map(|c| 0.5 + 0.1 * c as f32).collect();
    // Everything within 3e-6 but the γ gradient without the ReLU, `Σ dy·x̂` over 51,200
    // elements that cancel to ~1/150 of their magnitude: the mean's last bit (the CPU's and ours
    // round differently) moves it by ~1e-4 of itself.
    batch_norm_case(x, w, &gamma, 2e-4);
}

/// Our layer on the GPU against burn's on the CPU (whose sums are blocked: burn's on lavapipe
/// sum 51,200 elements a channel with errors of 1e-3).
fn batch_norm_case(x: Tensor<4>, w: Tensor<4>, gamma: &[f32], tolerance: f32) {
    use burn::nn::BatchNormConfig;
    let tdev = x.device();
    let channels = x.dims()[1];
    let mut ours = BatchNormConfig::new(channels).init(&tdev);
    ours.gamma = Param::from_tensor(Tensor::<1>::from_floats(gamma, &tdev));
    let (cpu, x_cpu) = (cpu(), on(&x, &cpu()));
    let w_cpu = Tensor::<4>::from_data(w.to_data(), &cpu);
    let mut burns = BatchNormConfig::new(channels).init(&cpu);
    burns.gamma = Param::from_tensor(Tensor::<1>::from_floats(gamma, &cpu));
    let to_gpu = |t: Tensor<1>| Tensor::<1>::from_data(t.to_data(), &tdev);
    let mut worst = 0.0f32;
    let mut compare = |what: &str, a: Tensor<1>, b: Tensor<1>| {
        let (a, b) = (
            a.into_data().try_to_vec::<f32>().unwrap(),
            b.into_data().try_to_vec::<f32>().unwrap(),
        );
        let scale = b.iter().fold(1.0f32, |m, v| m.max(v.abs()));
        let d = largest_difference(&[a], &[b]) / scale;
        eprintln!("{what}: largest difference {d:.2e} (relative to the largest value)");
        worst = worst.max(d);
    };
    for relu in [false, true, true] {
        let y_ours = selfmodel::kernels::batch_norm(&ours, x.clone(), relu);
        let mut y_burns = burns.forward(x_cpu.clone());
        if relu {
            y_burns = burn::tensor::activation::relu(y_burns);
        }
        let g_ours = (y_ours.clone() * w.clone()).sum().backward();
        let g_burns = (y_burns.clone() * w_cpu.clone()).sum().backward();
        compare(
            "output",
            y_ours.flatten(0, 3),
            to_gpu(y_burns.flatten(0, 3)),
        );
        compare(
            "running mean",
            ours.running_mean.value(),
            to_gpu(burns.running_mean.value()),
        );
        compare(
            "running variance",
            ours.running_var.value(),
            to_gpu(burns.running_var.value()),
        );
        compare(
            "x gradient",
            x.grad(&g_ours).unwrap().flatten(0, 3),
            to_gpu(x_cpu.grad(&g_burns).unwrap().flatten(0, 3)),
        );
        for (name, a, b) in [
            ("gamma", &ours.gamma, &burns.gamma),
            ("beta", &ours.beta, &burns.beta),
        ] {
            compare(
                &format!("{name} gradient"),
                a.val().grad(&g_ours).unwrap(),
                to_gpu(b.val().grad(&g_burns).unwrap()),
            );
        }
    }
    assert!(
        worst < tolerance,
        "batch norm of {:?} differs from burn's by {worst} (relative)",
        x.dims()
    );
}

/// The binary cross-entropy on logits on our kernels (two launches forward, one backward)
/// against burn's composition: the loss and the logits' gradient.
#[test]
fn the_logit_cross_entropy_on_our_kernels_is_burns() {
    use selfmodel::train::losses::{bce_with_logits, bce_with_logits_composed};
    let device = select(DeviceChoice::Wgpu).unwrap();
    let tdev = autodiff_device(&device, 0);
    for (i, shape) in [[3, 1, 5, 7], [64, 1, 40, 40]].into_iter().enumerate() {
        let (z, y) = with_seed(&tdev, 11 + i as u64, || {
            (
                Tensor::<4>::random(shape, Distribution::Normal(0.0, 20.0), &tdev).require_grad(),
                Tensor::<4>::random(shape, Distribution::Bernoulli(0.3), &tdev),
            )
        });
        let ours = bce_with_logits(z.clone(), y.clone());
        let burns = bce_with_logits_composed(z.clone(), y.clone());
        let (a, b): (f32, f32) = (ours.clone().into_scalar(), burns.clone().into_scalar());
        let g_ours = z.grad(&ours.mul_scalar(3.0).backward()).unwrap();
        let g_burns = z.grad(&burns.mul_scalar(3.0).backward()).unwrap();
        let g = |t: Tensor<4>| vec![t.into_data().try_to_vec::<f32>().unwrap()];
        let scale = g(g_burns.clone())[0]
            .iter()
            .fold(0.0f32, |m, v| m.max(v.abs()));
        let dg = largest_difference(&g(g_ours), &g(g_burns)) / scale;
        eprintln!("{shape:?}: loss {a} against {b}, gradient differs by {dg:.2e} (relative)");
        assert!(
            (a - b).abs() <= 1e-5 * b.abs(),
            "{shape:?}: loss {a} against {b}"
        );
        assert!(dg < 1e-5, "{shape:?}: gradients differ by {dg} (relative)");
    }
}

/// The reference device: the CPU (burn's `flex` backend), tracked. Burn's own operations run
/// there, so no kernel of burn's is compiled and tuned on lavapipe for the comparison.
fn cpu() -> burn::tensor::Device {
    autodiff_device(&select(DeviceChoice::Cpu).unwrap(), 0)
}

/// The GPU: wgpu, tracked.
fn gpu() -> burn::tensor::Device {
    autodiff_device(&select(DeviceChoice::Wgpu).unwrap(), 0)
}

/// A tracked copy of `t` on `device`.
fn on<const D: usize>(t: &Tensor<D>, device: &burn::tensor::Device) -> Tensor<D> {
    Tensor::from_data(t.to_data(), device).require_grad()
}

/// A layer's input, weight and bias on the CPU and their copies on the GPU.
type Layer = (Tensor<4>, Tensor<4>, Tensor<1>);

/// A layer's output and its `x`, weight and bias gradients on our kernels (`ours`, from the
/// GPU copies `g`) against burn's (`burns`, from the CPU inputs `c`), the largest differences
/// relative to burn's largest value, each.
fn layer_differences(g: &Layer, c: &Layer, ours: Tensor<4>, burns: Tensor<4>) -> [f32; 4] {
    let weights = Tensor::<4>::random(burns.dims(), Distribution::Default, &burns.device());
    let g_ours = (ours.clone() * on(&weights, &ours.device()))
        .sum()
        .backward();
    let g_burns = (burns.clone() * weights).sum().backward();
    let v = |t: Tensor<4>| vec![t.into_data().try_to_vec::<f32>().unwrap()];
    let v1 = |t: Tensor<1>| vec![t.into_data().try_to_vec::<f32>().unwrap()];
    let rel = |a: Vec<Vec<f32>>, b: Vec<Vec<f32>>| {
        let scale = b[0].iter().fold(1.0f32, |m, v| m.max(v.abs()));
        largest_difference(&a, &b) / scale
    };
    [
        rel(v(ours), v(burns)),
        rel(
            v(g.0.grad(&g_ours).unwrap()),
            v(c.0.grad(&g_burns).unwrap()),
        ),
        rel(
            v(g.1.grad(&g_ours).unwrap()),
            v(c.1.grad(&g_burns).unwrap()),
        ),
        rel(
            v1(g.2.grad(&g_ours).unwrap()),
            v1(c.2.grad(&g_burns).unwrap()),
        ),
    ]
}

/// A layer's input, weight `w_shape` and bias, tracked, seeded, on the CPU, and their copies
/// on the GPU: `(gpu, cpu)`.
fn layer_inputs(
    seed: u64,
    x_shape: [usize; 4],
    w_shape: [usize; 4],
    bias: usize,
) -> (Layer, Layer) {
    let cpu = cpu();
    let c = with_seed(&cpu, seed, || {
        (
            Tensor::<4>::random(x_shape, Distribution::Default, &cpu).require_grad(),
            Tensor::<4>::random(w_shape, Distribution::Default, &cpu).require_grad(),
            Tensor::<1>::random([bias], Distribution::Default, &cpu).require_grad(),
        )
    });
    let gpu = gpu();
    ((on(&c.0, &gpu), on(&c.1, &gpu), on(&c.2, &gpu)), c)
}

/// A transposed convolution (the decoders' upsampling layers: k4 s2 p1 and k3 s1 p2) with its
/// gradients from our im2col and two matrix products on the GPU, against burn's
/// `conv_transpose2d` on the CPU.
#[test]
fn transposed_convolution_gradients_on_our_kernels_are_burns() {
    use burn::tensor::ops::ConvTransposeOptions;
    use selfmodel::kernels::cube::convolution::conv_transpose2d;
    for (i, (k, s, p, hw)) in [(4, 2, 1, 5), (3, 1, 2, 9)].into_iter().enumerate() {
        let options = ConvTransposeOptions::new([s, s], [p, p], [0, 0], [1, 1], 1);
        check_layer(
            &format!("k{k} s{s} p{p}"),
            layer_inputs(20 + i as u64, [3, 6, hw, hw + 1], [6, 4, k, k], 4),
            |x, w, b| conv_transpose2d(x, w, b, &options).expect("on our kernels"),
            |x, w, b| burn::tensor::module::conv_transpose2d(x, w, Some(b), options.clone()),
        );
    }
}

/// Our layer `ours` on the GPU copies (tracked, then in inference: the forward pass alone)
/// against burn's `burns` on the CPU inputs.
fn check_layer(
    label: &str,
    (g, c): (Layer, Layer),
    ours: impl Fn(&Tensor<4>, &Tensor<4>, &Tensor<1>) -> Tensor<4>,
    burns: impl FnOnce(Tensor<4>, Tensor<4>, Tensor<1>) -> Tensor<4>,
) {
    let trained = ours(&g.0, &g.1, &g.2);
    let inferred = ours(
        &g.0.clone().inner(),
        &g.1.clone().inner(),
        &g.2.clone().inner(),
    );
    let reference = burns(c.0.clone(), c.1.clone(), c.2.clone());
    assert_layer_is_burns(label, (&g, &c), [trained, inferred], reference);
}

/// Our layer (`[training, inference]` outputs on the GPU) is burn's (`burns`, tracked, on the
/// CPU) within 1e-5 relative: the output, its gradients, and the inference pass.
fn assert_layer_is_burns(
    label: &str,
    (g, c): (&Layer, &Layer),
    [ours, inferred]: [Tensor<4>; 2],
    burns: Tensor<4>,
) {
    let di = relative(inferred, burns.clone().inner());
    let d = layer_differences(g, c, ours, burns);
    eprintln!(
        "{label}: output, x, weight and bias gradients differ by {d:?}, inference by {di:.1e} (relative)"
    );
    assert!(
        d.iter().all(|&e| e < 1e-5) && di < 1e-5,
        "{label}: {d:?} {di}"
    );
}

/// The largest difference of `a` and `b` relative to `b`'s largest value.
fn relative(a: Tensor<4>, b: Tensor<4>) -> f32 {
    let v = |t: Tensor<4>| vec![t.into_data().try_to_vec::<f32>().unwrap()];
    let b = v(b);
    let scale = b[0].iter().fold(1.0f32, |m, v| m.max(v.abs()));
    largest_difference(&v(a), &b) / scale
}

/// A convolution (the NeuroKin head's 3x3 with padding 1 and its 1x1; a strided 3x3) with its
/// gradients from our im2col, matrix products and col2im on the GPU, against burn's `conv2d`
/// on the CPU.
#[test]
fn convolution_gradients_on_our_kernels_are_burns() {
    use burn::tensor::ops::ConvOptions;
    use selfmodel::kernels::cube::convolution::conv2d;
    for (i, (k, s, p, hw)) in [(3, 1, 1, 7), (1, 1, 0, 6), (3, 2, 1, 9)]
        .into_iter()
        .enumerate()
    {
        let options = ConvOptions::new([s, s], [p, p], [1, 1], 1);
        check_layer(
            &format!("k{k} s{s} p{p}"),
            layer_inputs(30 + i as u64, [3, 5, hw, hw + 2], [4, 5, k, k], 4),
            |x, w, b| conv2d(x, w, b, &options).expect("on our kernels"),
            |x, w, b| burn::tensor::module::conv2d(x, w, Some(b), options.clone()),
        );
    }
}
