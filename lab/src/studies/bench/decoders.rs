//! Speed of the direct decoders, side by side with PyTorch: inference images/s at batch 1 and
//! 256 and training images/s (forward, backward, Adam step) at the paper's batch, for both
//! NeuroKin architectures. `../shared/bench/torch_reference.py` measures the same workloads;
//! `bench_decoders --torch PYTHON` runs it in the same sitting and prints the ratios.

use burn::optim::GradientsParams;
use burn::tensor::{Device, Distribution, Tensor};

use selfmodel::core::device::DeviceChoice;
use selfmodel::core::error::Result;
use selfmodel::core::preset::Preset;
use selfmodel::core::timing::with_caller_share;
use selfmodel::eval::inference_speed::{SpeedConfig, measure};
use selfmodel::kernels::cpu_extension::sigmoid;
use selfmodel::self_models::neurokin::{NeuroKinArch, NeuroKinConfig};
use selfmodel::train::losses::{bce_with_logits, mse};
use selfmodel::train::trainer::autodiff_device;

/// One measured figure, named as torch_reference.py names it.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct BenchRow {
    /// The CPU threads it ran on, where a sweep over them set it (the GPU check's `cpu` and
    /// `split` parts); no column otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub threads: Option<usize>,
    /// The `split` part's multiply-adds a thread must have before a lone image's GEMM takes
    /// it (0: every thread); no column otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub work_per_thread: Option<usize>,
    pub model: String,
    pub figure: String,
    pub ours: f64,
    pub torch: Option<f64>,
    /// `ours / torch`: above 1 is faster than PyTorch.
    pub ratio: Option<f64>,
    /// The share of our measurement's wall time the calling thread was on a CPU
    /// ([`selfmodel::core::timing::with_caller_share`]): work on one thread, which more threads do
    /// not shorten. Empty in CSVs written before it was measured.
    #[serde(default)]
    pub caller_busy: Option<f64>,
    /// `paper` (the paper's models and batches) or `quick`.
    pub preset: String,
    pub device: String,
    pub git_revision: String,
}

impl BenchRow {
    fn new(
        model: &str,
        figure: String,
        (ours, caller_busy): (f64, Option<f64>),
        quick: bool,
        device: DeviceChoice,
    ) -> Self {
        BenchRow {
            threads: None,
            work_per_thread: None,
            model: model.into(),
            figure,
            ours,
            torch: None,
            ratio: None,
            caller_busy,
            preset: if quick { "quick" } else { "paper" }.into(),
            device: device.to_string(),
            git_revision: selfmodel::core::provenance::git_revision(),
        }
    }
}

/// Median seconds of `repeats` training steps after `warmup`.
fn train_rate(
    cfg: &NeuroKinConfig,
    batch: usize,
    device: &Device,
    warmup: usize,
    repeats: usize,
) -> Result<f64> {
    let tdev = autodiff_device(device, 0);
    let model = cfg.init(&tdev, 0)?;
    let mut optim = selfmodel::train::adam::adam();
    let native = cfg.native_size();
    let (q, y) = selfmodel::core::device::with_seed(&tdev, 1, || {
        let q = Tensor::<2>::random([batch, cfg.dof], Distribution::Normal(0.0, 30.0), &tdev);
        let y = Tensor::<4>::random(
            [batch, 1, native[0], native[1]],
            Distribution::Bernoulli(0.1),
            &tdev,
        );
        (q, y)
    });
    let mut slot = Some(model);
    let seconds = selfmodel::core::timing::median_seconds(
        selfmodel::core::timing::Repeats::exactly(warmup, repeats),
        || {
            let model = slot.take().expect("the model between steps");
            let z = model.forward(q.clone());
            let loss = match cfg.arch {
                NeuroKinArch::Code => bce_with_logits(z, y.clone()),
                NeuroKinArch::Text64 => mse(sigmoid(z), y.clone()),
            };
            let grads = GradientsParams::from_grads(loss.backward(), &model);
            slot = Some(optim.step(1e-3, model, grads));
            let _ = tdev.sync();
        },
    );
    Ok(batch as f64 / seconds)
}

/// Which batches to measure.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Batches {
    /// The paper's: inference at 1 and 256, training at 32 (NeuroKin-64: 128).
    Paper,
    /// Those that fill a GPU, as `torch_gpu_reference.py --extra` measures them: inference at
    /// 4,096, training at 1,024.
    Fill,
    Both,
}

impl Batches {
    fn infer(self) -> Vec<usize> {
        match self {
            Batches::Paper => vec![1, 256],
            Batches::Fill => vec![4096],
            Batches::Both => vec![1, 256, 4096],
        }
    }

    fn train(self, paper: usize) -> Vec<usize> {
        match self {
            Batches::Paper => vec![paper],
            Batches::Fill => vec![1024],
            Batches::Both => vec![paper, 1024],
        }
    }
}

/// Measure both NeuroKin architectures on `choice` at the paper's batches.
pub fn run(choice: DeviceChoice, quick: bool) -> Result<Vec<BenchRow>> {
    run_batches(choice, quick, Batches::Paper, &mut |_| Ok(()))
}

/// [`run`] at `batches`, handing each row to `measured` as soon as it is measured (a GPU
/// check keeps what it has when a later batch fails).
pub fn run_batches(
    choice: DeviceChoice,
    quick: bool,
    batches: Batches,
    measured: &mut dyn FnMut(&BenchRow) -> Result<()>,
) -> Result<Vec<BenchRow>> {
    let device = &selfmodel::core::device::select(choice)?;
    let speed = if quick {
        SpeedConfig::quick()
    } else {
        SpeedConfig::paper()
    };
    let mut rows = Vec::new();
    for (name, cfg, batch) in [
        ("neurokin", NeuroKinConfig::paper(), 32),
        ("neurokin64", NeuroKinConfig::text64(), 128),
    ] {
        let cfg = if quick {
            NeuroKinConfig {
                image: [32, 32],
                ..NeuroKinConfig::quick()
            }
        } else {
            cfg
        };
        let model = cfg.init(device, 0)?;
        for b in batches.infer() {
            let one = SpeedConfig {
                batches: vec![b],
                ..speed.clone()
            };
            let (timings, busy) =
                with_caller_share(|| measure(|q| model.predict(q), cfg.dof, device, &one));
            for t in timings {
                let row = BenchRow::new(
                    name,
                    format!("infer_b{}_img_per_s", t.batch),
                    (t.images_per_second(), busy),
                    quick,
                    choice,
                );
                measured(&row)?;
                rows.push(row);
            }
        }
        let (w, r) = if quick { (1, 2) } else { (3, 10) };
        for b in batches.train(batch) {
            let row = BenchRow::new(
                name,
                format!("train_b{b}_img_per_s"),
                {
                    let (rate, busy) = with_caller_share(|| train_rate(&cfg, b, device, w, r));
                    (rate?, busy)
                },
                quick,
                choice,
            );
            measured(&row)?;
            rows.push(row);
        }
    }
    Ok(rows)
}

/// Run a PyTorch reference script (`torch_reference.py` on the CPU, `torch_gpu_reference.py`
/// on a GPU) with `python` at `threads` threads (`extra`: the batches that fill a GPU;
/// `seconds`: how long it times each figure, else the script's default) and return its
/// `model figure value` lines.
pub fn run_torch(
    python: &std::path::Path,
    script: &std::path::Path,
    threads: usize,
    extra: bool,
    seconds: Option<f64>,
) -> Result<String> {
    let mut args = vec!["--threads".to_string(), threads.to_string()];
    if extra {
        args.push("--extra".into());
    }
    if let Some(s) = seconds {
        args.extend(["--seconds".into(), s.to_string()]);
    }
    run_python(python, script, &args)
}

/// Run `script` with `python` and `args`; its standard output, or an error with the last line
/// it wrote to standard error.
pub fn run_python(
    python: &std::path::Path,
    script: &std::path::Path,
    args: &[String],
) -> Result<String> {
    let out = std::process::Command::new(python)
        .arg(script)
        .args(args)
        .output()
        .map_err(|e| selfmodel::Error::io(python, e))?;
    if !out.status.success() {
        return Err(selfmodel::Error::Config(format!(
            "{} failed: {}",
            script.display(),
            String::from_utf8_lossy(&out.stderr)
                .lines()
                .last()
                .unwrap_or("")
        )));
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// The rows as the console shows them: model, figure, ours, PyTorch's, ratio, and the share
/// of our time the calling thread was busy.
pub fn console_table(rows: &[BenchRow]) -> String {
    let mut text = format!(
        "{:<11} {:<22} {:>10} {:>10} {:>8} {:>12}\n",
        "model", "figure", "selfmodel", "pytorch", "ratio", "caller busy"
    );
    for r in rows {
        let (t, ratio) = match r.torch {
            Some(t) => (format!("{t:.1}"), format!("{:.2}x", r.ours / t)),
            None => ("-".into(), "-".into()),
        };
        let busy = r
            .caller_busy
            .map_or("-".into(), |b| format!("{:.0}%", 100.0 * b));
        text += &format!(
            "{:<11} {:<22} {:>10.1} {:>10} {:>8} {:>12}\n",
            r.model, r.figure, r.ours, t, ratio, busy
        );
    }
    text
}

/// Fill the `torch` column from torch_reference.py's output lines (`model figure value`).
pub fn attach_torch(rows: &mut [BenchRow], torch_output: &str) {
    for line in torch_output.lines() {
        let parts: Vec<&str> = line.split_whitespace().collect();
        if let [model, figure, value] = parts[..]
            && let Ok(v) = value.parse::<f64>()
            && let Some(r) = rows
                .iter_mut()
                .find(|r| r.model == model && r.figure == figure)
        {
            r.torch = Some(v);
            r.ratio = Some(r.ours / v);
        }
    }
}
