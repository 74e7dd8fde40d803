//! The GPU check: everything issue 48 measures on a GPU machine, in one binary and one run
//! of a few minutes (a GPU machine here has no Rust toolchain: the binary is built on a CPU
//! machine with `--features wgpu,cuda` and carried; `scripts/gpu_check.sh` packs and runs it;
//! `--device` picks the backend measured).
//!
//! Parts, in order (`--parts` picks some):
//! - `decoders`: `bench_decoders` on the GPU at the paper's batches, beside PyTorch on the
//!   same GPU (`torch_gpu_reference.py --extra`, its lines kept for `fill`);
//! - `neurokin`: `neurokin --preset paper --device wgpu` end to end at the paper's batch (32) and
//!   at a larger one (`--batch 256`), with the quality each reaches;
//! - `equivalence`: NeuroKin, K-3DGS and FFKSM trained from the same seed on the CPU and the
//!   GPU ([`selfmodel::self_models::device_equivalence`]);
//! - `counts`: kernel launches, host reads and uploads per NeuroKin training step on the GPU,
//!   and PyTorch's kernels for the same step counted by torch.profiler
//!   (`scripts/torch_step_kernels.py`) where `--torch` is given;
//! - `k3dgs`: K-3DGS's paper preset (three variants) on the GPU, and the isotropic one on 2
//!   CPU threads of the same machine (the 5x target);
//! - `fill`: `decoders` at batches that fill the GPU (inference 4,096, training 1,024), last of
//!   the GPU parts since the first sitting hung there;
//! - `cpu`: `bench_decoders` on the CPU at each of `--threads`, beside PyTorch at as many
//!   threads (`torch_reference.py --threads N`);
//! - `split`: at the largest of `--threads`, the CPU figures again under each work per thread
//!   of [`SPLIT_WORK`] (how a lone image's GEMM is split, `SELFMODEL_GEMM_WORK_PER_THREAD`),
//!   beside PyTorch at as many threads: what batch 1 loses from 8 to 16 threads;
//! - outside the default order, run by `scripts/gpu_check.sh`: `peak` (the GPU's bandwidth and
//!   matrix-product rate), `roofline` (each kernel of the profiled step against its bound,
//!   [`selfmodel::eval::roofline`]) and `summary` ([`crate::studies::bench::gpu_summary`]).
//!
//! Each part appends to `console.txt` and writes its CSV as it finishes, so a run stopped by
//! the machine's time limit keeps what it measured; `scripts/gpu_check.sh run` starts one
//! process a part, each under its own time limit.

use std::path::{Path, PathBuf};
use std::time::Instant;

#[cfg(feature = "cube")]
use crate::studies::bench::decoders::run_python;
use crate::studies::bench::decoders::{
    Batches, BenchRow, attach_torch, console_table, run_batches, run_torch,
};
use crate::studies::run::RunOptions;
use selfmodel::core::device::DeviceChoice;
use selfmodel::core::error::{Error, Result};
use selfmodel::report::table::write_csv;

/// The parts of the check.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Part {
    Counts,
    Decoders,
    Neurokin,
    /// NeuroKin's paper preset at batch 256 in each precision the GPU computes in
    /// (`ablation_precision`: f32, bf16, f16, flex32).
    Precision,
    K3dgs,
    Equivalence,
    Fill,
    Cpu,
    Split,
    /// The bandwidth and matrix-product rate this GPU reaches (`peak.csv`): the roofline's
    /// bounds.
    Peak,
    /// Each kernel of the profiled batch-256 step against its bound (`kernels.csv`): from the
    /// `profile` run's `profile.txt`, `launches.csv` and `peak.csv` in `--out`.
    Roofline,
    /// Every ratio against PyTorch of the backends measured into the sub-folders of `--out`
    /// (`cuda/`, `wgpu/`), and which backend is faster at each figure: printed last.
    Summary,
}

/// The works per thread (multiply-adds) the `split` part tries: 0 is every thread, 2^30 one
/// thread for every layer of NeuroKin at batch 1.
pub const SPLIT_WORK: [usize; 5] = [0, 1 << 18, 1 << 20, 1 << 22, 1 << 30];

impl Part {
    pub const ALL: [Part; 9] = [
        Part::Decoders,
        Part::Neurokin,
        Part::Equivalence,
        Part::Precision,
        Part::Counts,
        Part::K3dgs,
        Part::Fill,
        Part::Cpu,
        Part::Split,
    ];
}

/// How to run the check.
#[derive(Clone, Debug)]
pub struct GpuCheck {
    /// Where its output goes (`reports/gpu/<gpu name>`).
    pub out: PathBuf,
    /// A Python with torch (CUDA) installed, for PyTorch's side; none: ours only.
    pub python: Option<PathBuf>,
    /// The folder of `torch_reference.py` and `torch_gpu_reference.py`.
    pub bench_dir: PathBuf,
    /// CPU thread counts of the `cpu` part.
    pub threads: Vec<usize>,
    pub parts: Vec<Part>,
    /// Tiny models and the quick presets: a smoke test of the check itself (lavapipe).
    pub quick: bool,
    /// This binary, run again for what needs its own thread count (`cpu`, K-3DGS on 2 CPU
    /// threads): rayon's pool is sized once per process.
    pub exe: PathBuf,
    /// The GPU backend measured (`wgpu` or `cuda`; a build with both runs the check once
    /// for each, `scripts/gpu_check.sh`).
    pub device: DeviceChoice,
}

/// Kernel launches, host reads and uploads of one training step.
#[derive(Clone, Debug, serde::Serialize)]
pub struct StepCounts {
    pub model: String,
    pub batch: usize,
    pub launches_per_step: f64,
    pub reads_per_step: f64,
    pub uploads_per_step: f64,
    pub steps: usize,
    pub log_every: usize,
}

/// The check's console: printed, and kept in `console.txt` as it grows.
struct Console {
    path: PathBuf,
    text: String,
}

impl Console {
    fn say(&mut self, line: impl AsRef<str>) -> Result<()> {
        let line = line.as_ref();
        println!("{line}");
        self.text += line;
        self.text += "\n";
        selfmodel::core::atomic_file::write_bytes(&self.path, self.text.as_bytes())
    }
}

/// The compiler of this build's kernels on `device` (`wgpu<wgsl>`, `wgpu<spirv>`, `cuda`).
#[cfg(feature = "cube")]
fn gpu_compiler(device: DeviceChoice) -> String {
    selfmodel::core::device::select(device)
        .ok()
        .and_then(|d| selfmodel::kernels::cube::compiler(&d))
        .unwrap_or("no GPU")
        .to_string()
}

#[cfg(not(feature = "cube"))]
fn gpu_compiler(_: DeviceChoice) -> String {
    "none (built without the wgpu or cuda feature)".to_string()
}

/// Run the check's parts in order.
pub fn run(check: &GpuCheck) -> Result<()> {
    std::fs::create_dir_all(&check.out).map_err(|e| Error::io(&check.out, e))?;
    // The console goes on from an earlier run into the same folder: the script runs each part
    // in a process of its own, under its own time limit, so a part that hangs costs only itself.
    let path = check.out.join("console.txt");
    let text = std::fs::read_to_string(&path).unwrap_or_default();
    let mut console = Console { path, text };
    let preset = if check.quick { "quick" } else { "paper" };
    console.say(format!(
        "gpu_check at {} ({preset}), CPU: {}, --device {}: GPU kernels compiled by {}",
        selfmodel::core::provenance::git_revision(),
        selfmodel::eval::compute_peak::machine_label(true),
        check.device,
        gpu_compiler(check.device)
    ))?;
    for &part in &check.parts {
        let t0 = Instant::now();
        console.say(format!("== {part:?}"))?;
        let done = match part {
            Part::Counts => counts(check, &mut console),
            Part::Decoders => decoders(check, &mut console),
            Part::Neurokin => neurokin(check, &mut console),
            Part::Precision => precision(check, &mut console),
            Part::K3dgs => k3dgs(check, &mut console),
            Part::Equivalence => equivalence(check, &mut console),
            Part::Fill => fill(check, &mut console),
            Part::Cpu => cpu(check, &mut console),
            Part::Split => split(check, &mut console),
            Part::Summary => summary(check, &mut console),
            Part::Peak => peak(check, &mut console),
            Part::Roofline => roofline(check, &mut console),
        };
        // A part that fails is reported and the check goes on to the next.
        if let Err(e) = done {
            console.say(format!("{part:?} failed: {e}"))?;
        }
        console.say(format!("({part:?}: {:.0} s)", t0.elapsed().as_secs_f64()))?;
    }
    Ok(())
}

#[cfg(feature = "cube")]
fn counts(check: &GpuCheck, console: &mut Console) -> Result<()> {
    use selfmodel::eval::device_counts::DeviceCounts;
    let mut rows = Vec::new();
    let mut sources = Vec::new();
    let mut launches = Vec::new();
    let (steps, log_every) = (24, 8);
    selfmodel::eval::device_counts::log_launches();
    for batch in [32, 256] {
        let preset = if check.quick { "quick" } else { "paper" };
        let (per_step, _) = selfmodel::self_models::step_counts::neurokin_step_counts(
            check.device,
            preset,
            batch,
            steps,
            log_every,
        )?;
        // The last step's launches in order, each with its workgroups and (ours) elements:
        // what a profile of the same steps is read beside (the roofline of issue 71).
        let log = selfmodel::eval::device_counts::launch_log();
        let last = per_step.last().map_or(0, |c| c.launches as usize);
        launches.extend(
            log[log.len().saturating_sub(last)..]
                .iter()
                .enumerate()
                .map(|(i, l)| selfmodel::eval::roofline::StepLaunch {
                    batch,
                    index: i,
                    kernel: l.kernel.clone(),
                    operations: l.operations.clone(),
                    workgroups: l.workgroups,
                    elements: l.elements,
                    block: l.block,
                    block_bytes: l.work.bytes,
                    block_flops: l.work.flops,
                }),
        );
        // Counted from the end of the first epoch (kernels compiled and tuned by then).
        let counted = &per_step[4..];
        let c = counted
            .iter()
            .fold(DeviceCounts::default(), |a, s| a.plus(s));
        let k = counted.len() as f64;
        let row = StepCounts {
            model: "NeuroKin".into(),
            batch,
            launches_per_step: c.launches as f64 / k,
            reads_per_step: c.reads as f64 / k,
            uploads_per_step: c.uploads as f64 / k,
            steps: counted.len(),
            log_every,
        };
        console.say(format!(
            "NeuroKin training step, batch {batch}: {:.1} kernel launches, {:.3} host reads ({} in {} steps: the loss, every {log_every}), {:.2} uploads (the epoch's indices and noise)",
            row.launches_per_step, row.reads_per_step, c.reads, row.steps, row.uploads_per_step
        ))?;
        let mut kernels: Vec<_> = c.kernels.into_iter().collect();
        kernels.sort_by(|a, b| b.1.cmp(&a.1));
        for (name, n) in kernels.iter().take(8) {
            console.say(format!("  {:>6.1} x {name}", *n as f64 / k))?;
        }
        // Which operations each launch ran for (burn's fusion blocks): where copies and
        // reductions come from.
        let mut by_source: Vec<_> = c.sources.into_iter().collect();
        by_source.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
        console.say("  by the operations they ran for:")?;
        for (name, n) in &by_source {
            console.say(format!("  {:>6.1} x {name}", *n as f64 / k))?;
            let (kernel, operations) = name.split_once(" <- ").unwrap_or((name, "?"));
            sources.push(LaunchSource {
                model: "NeuroKin".into(),
                batch,
                kernel: kernel.into(),
                operations: operations.into(),
                launches_per_step: *n as f64 / k,
            });
        }
        rows.push(row);
    }
    write_csv(&check.out.join("counts_sources.csv"), &sources)?;
    write_csv(&check.out.join("launches.csv"), &launches)?;
    write_csv(&check.out.join("counts.csv"), &rows)?;
    if let Some(py) = &check.python {
        torch_counts(check, py, console)?;
    }
    Ok(())
}

/// PyTorch's step counted by torch.profiler on the same GPU
/// (`scripts/torch_step_kernels.py`, packed beside the other PyTorch scripts), kept in
/// `torch_counts.csv`; where it cannot run, the console says why and the part goes on.
#[cfg(feature = "cube")]
fn torch_counts(check: &GpuCheck, python: &Path, console: &mut Console) -> Result<()> {
    let packed = check.bench_dir.join("torch_step_kernels.py");
    let script = if packed.is_file() {
        packed
    } else {
        PathBuf::from("scripts/torch_step_kernels.py")
    };
    let bench = check.bench_dir.to_string_lossy().into_owned();
    let text = match run_python(python, &script, &["--bench".into(), bench]) {
        Ok(text) => text,
        Err(e) => return console.say(format!("PyTorch's step was not counted: {e}")),
    };
    let rows: Vec<TorchCounts> = text.lines().filter_map(TorchCounts::parse).collect();
    for r in &rows {
        let what = if r.device == "cuda" {
            "kernels"
        } else {
            "aten operators (no CUDA GPU: not a launch count)"
        };
        console.say(format!(
            "PyTorch's NeuroKin step, batch {} ({}): {:.1} {what}, {:.1} copies or fills",
            r.batch, r.optimizer, r.kernels_per_step, r.memory_ops_per_step
        ))?;
    }
    write_csv(&check.out.join("torch_counts.csv"), &rows)
}

/// A line of `torch_step_kernels.py`: what one PyTorch training step launched.
#[cfg(feature = "cube")]
#[derive(Clone, Debug, serde::Serialize)]
struct TorchCounts {
    model: String,
    batch: usize,
    /// `adam_foreach` (PyTorch's default) or `adam_fused`.
    optimizer: String,
    kernels_per_step: f64,
    memory_ops_per_step: f64,
    /// `cuda` (device kernels), or `cpu_aten` (a machine without a GPU: aten operators).
    device: String,
}

#[cfg(feature = "cube")]
impl TorchCounts {
    fn parse(line: &str) -> Option<Self> {
        let f: Vec<&str> = line.split_whitespace().collect();
        let [model, batch, optimizer, kernels, memory, device] = f[..] else {
            return None;
        };
        Some(TorchCounts {
            model: model.into(),
            batch: batch.parse().ok()?,
            optimizer: optimizer.into(),
            kernels_per_step: kernels.parse().ok()?,
            memory_ops_per_step: memory.parse().ok()?,
            device: device.into(),
        })
    }
}

/// Launches a step of one kernel for one set of operations (a fusion block's kinds).
#[cfg(feature = "cube")]
#[derive(Clone, Debug, serde::Serialize)]
struct LaunchSource {
    model: String,
    batch: usize,
    kernel: String,
    operations: String,
    launches_per_step: f64,
}

#[cfg(not(feature = "cube"))]
fn counts(_: &GpuCheck, _: &mut Console) -> Result<()> {
    Err(Error::Device(
        "counting needs a GPU backend (rebuild with --features wgpu or cuda)".into(),
    ))
}

fn decoders(check: &GpuCheck, console: &mut Console) -> Result<()> {
    gpu_decoders(check, console, Batches::Paper, "decoders_gpu.csv")
}

/// The batches that fill a GPU, after every other GPU part: on the first H200 sitting burn's
/// autotuned matmul asked for more workgroups than wgpu allows (65,535 a dimension) at these
/// batches, and the process hung.
fn fill(check: &GpuCheck, console: &mut Console) -> Result<()> {
    gpu_decoders(check, console, Batches::Fill, "decoders_fill.csv")
}

/// `bench_decoders` on the GPU at `batches`, each figure said as it is measured, beside
/// PyTorch on the same GPU (run once, with `--extra`, its lines kept in `torch_gpu.txt`).
fn gpu_decoders(
    check: &GpuCheck,
    console: &mut Console,
    batches: Batches,
    csv: &str,
) -> Result<()> {
    let mut rows = run_batches(check.device, check.quick, batches, &mut |r| {
        console.say(format!(
            "  {} {}: {:.1} images/s",
            r.model, r.figure, r.ours
        ))
    })?;
    if let Some(py) = &check.python {
        let kept = check.out.join("torch_gpu.txt");
        let torch = match std::fs::read_to_string(&kept) {
            Ok(text) => Ok(text),
            Err(_) => {
                let script = check.bench_dir.join("torch_gpu_reference.py");
                run_torch(py, &script, 0, !check.quick, None).and_then(|out| {
                    selfmodel::core::atomic_file::write_bytes(&kept, out.as_bytes())?;
                    Ok(out)
                })
            }
        };
        torch_side(&mut rows, torch, console)?;
    }
    console.say(console_table(&rows))?;
    write_csv(&check.out.join(csv), &rows)
}

/// PyTorch's figures beside ours; where PyTorch could not run, ours are kept and the console
/// says why.
fn torch_side(rows: &mut [BenchRow], torch: Result<String>, console: &mut Console) -> Result<()> {
    match torch {
        Ok(out) => {
            attach_torch(rows, &out);
            Ok(())
        }
        Err(e) => console.say(format!("PyTorch's side did not run: {e}")),
    }
}

/// Run a registry experiment into `out/<leaf>` with `opts`, and say its summary.
fn experiment(
    name: &str,
    opts: &RunOptions,
    out: &Path,
    leaf: &str,
    console: &mut Console,
) -> Result<()> {
    let e = crate::studies::registry::find(name)?;
    let dir = out.join(leaf);
    let t0 = Instant::now();
    let summary = e.run_in(opts, &dir)?;
    // The results beside the console: what comes back from a GPU machine is at most two
    // folders deep.
    let results = dir.join("results.csv");
    if results.is_file() {
        std::fs::copy(&results, out.join(format!("{leaf}_results.csv")))
            .map_err(|e| Error::io(&results, e))?;
    }
    console.say(format!(
        "{name} {leaf}: {summary} ({:.0} s end to end)",
        t0.elapsed().as_secs_f64()
    ))
}

fn gpu_options(check: &GpuCheck) -> RunOptions {
    let mut opts = RunOptions::preset(if check.quick { "quick" } else { "paper" });
    opts.device = check.device;
    opts
}

fn neurokin(check: &GpuCheck, console: &mut Console) -> Result<()> {
    let opts = gpu_options(check);
    experiment("neurokin", &opts, &check.out, "neurokin_b32", console)?;
    let big = RunOptions {
        batch: Some(256),
        ..opts
    };
    experiment("neurokin", &big, &check.out, "neurokin_b256", console)
}

/// The training precisions side by side at batch 256 (where a step is bound by arithmetic, not
/// launches, and tensor cores can tell).
fn precision(check: &GpuCheck, console: &mut Console) -> Result<()> {
    let opts = RunOptions {
        batch: Some(256),
        ..gpu_options(check)
    };
    experiment(
        "ablation_precision",
        &opts,
        &check.out,
        "precision_b256",
        console,
    )
}

fn k3dgs(check: &GpuCheck, console: &mut Console) -> Result<()> {
    experiment("k3dgs", &gpu_options(check), &check.out, "k3dgs", console)?;
    // The isotropic model on 2 CPU threads of this machine, in a process of its own.
    let t0 = Instant::now();
    let out = child(check, "k3dgs-cpu", 2)?;
    console.say(format!(
        "K-3DGS (isotropic) on 2 CPU threads: {} ({:.0} s end to end)",
        out.trim(),
        t0.elapsed().as_secs_f64()
    ))
}

/// K-3DGS (isotropic) on the CPU, in this process (run as a child with 2 threads).
pub fn k3dgs_cpu(check: &GpuCheck) -> Result<String> {
    use selfmodel::self_models::k3dgs::{K3dgsVariant, k3dgs_run};
    let cfg = k3dgs_run(
        if check.quick { "quick" } else { "paper" },
        K3dgsVariant::Isotropic,
    )?;
    let dir = check.out.join("k3dgs_cpu_2threads");
    let out = selfmodel::self_models::harness::run(&cfg, &dir, DeviceChoice::Cpu, false)?;
    Ok(format!(
        "{:.2} dB, IoU {:.3}, trained in {:.1} s ({:.0} images/s)",
        out.result.psnr_db_test,
        out.result.iou_test,
        out.result.train_time_s,
        out.result.train_img_per_s
    ))
}

fn equivalence(check: &GpuCheck, console: &mut Console) -> Result<()> {
    use selfmodel::self_models::device_equivalence::compare;
    use selfmodel::self_models::ffksm::{FfksmVariant, ffksm_run};
    use selfmodel::self_models::k3dgs::{K3dgsVariant, TrainSplatting, k3dgs_run};
    use selfmodel::self_models::neurokin::neurokin_run;
    let dir = check.out.join("equivalence_runs");
    let mut k3dgs = k3dgs_run("quick", K3dgsVariant::IsotropicAlpha)?;
    k3dgs.model.train_splatting = TrainSplatting::Dense;
    let rows = vec![
        compare(
            neurokin_run("quick")?,
            6,
            check.device,
            &dir.join("neurokin"),
        )?,
        compare(k3dgs, 6, check.device, &dir.join("k3dgs"))?,
        compare(
            ffksm_run("quick", FfksmVariant::Reimplementation)?,
            6,
            check.device,
            &dir.join("ffksm"),
        )?,
    ];
    for e in &rows {
        let pass = e.max_loss_rel <= 1e-3 && e.max_image_abs <= 1e-3;
        console.say(format!(
            "{}: losses within {:.1e} (relative), images within {:.1e} ({}): {}",
            e.model,
            e.max_loss_rel,
            e.max_image_abs,
            e.worst_image,
            if pass {
                "pass"
            } else {
                "FAIL (tolerance 1e-3)"
            }
        ))?;
    }
    let _ = std::fs::remove_dir_all(&dir);
    write_csv(&check.out.join("equivalence.csv"), &rows)
}

/// This binary again, as `--child WHAT` with `threads` rayon threads; its standard output.
fn child(check: &GpuCheck, what: &str, threads: usize) -> Result<String> {
    child_with(check, what, threads, &[])
}

/// [`child`] with these environment variables set.
fn child_with(
    check: &GpuCheck,
    what: &str,
    threads: usize,
    env: &[(&str, String)],
) -> Result<String> {
    let mut command = std::process::Command::new(&check.exe);
    command
        .envs(env.iter().map(|(k, v)| (*k, v.as_str())))
        .env("RAYON_NUM_THREADS", threads.to_string())
        .args(["--child", what, "--out"])
        .arg(&check.out);
    if check.quick {
        command.arg("--quick");
    }
    let out = command.output().map_err(|e| Error::io(&check.exe, e))?;
    if !out.status.success() {
        return Err(Error::Config(format!(
            "{what} on {threads} threads failed: {}",
            String::from_utf8_lossy(&out.stderr)
                .lines()
                .last()
                .unwrap_or("")
        )));
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// The CPU decoder figures of this process (run as a child at a thread count), as JSON.
pub fn cpu_decoders(check: &GpuCheck) -> Result<String> {
    let rows = run_batches(DeviceChoice::Cpu, check.quick, Batches::Paper, &mut |_| {
        Ok(())
    })?;
    serde_json::to_string(&rows).map_err(|e| Error::Config(e.to_string()))
}

fn cpu(check: &GpuCheck, console: &mut Console) -> Result<()> {
    let mut all = Vec::new();
    for &t in &check.threads {
        let json = child(check, "cpu-decoders", t)?;
        let mut rows: Vec<BenchRow> = serde_json::from_str(json.trim())
            .map_err(|e| Error::Config(format!("the CPU child's rows: {e}")))?;
        if let Some(py) = &check.python {
            let script = check.bench_dir.join("torch_reference.py");
            torch_side(
                &mut rows,
                run_torch(py, &script, t, false, Some(2.0)),
                console,
            )?;
        }
        console.say(format!("{t} CPU threads (ours and PyTorch's):"))?;
        console.say(console_table(&rows))?;
        all.extend(rows.into_iter().map(|r| BenchRow {
            threads: Some(t),
            ..r
        }));
        write_csv(&check.out.join("cpu_threads.csv"), &all)?;
    }
    Ok(())
}

/// The CPU figures at the largest thread count under each of [`SPLIT_WORK`], beside
/// PyTorch at as many threads (measured once, after ours).
fn split(check: &GpuCheck, console: &mut Console) -> Result<()> {
    let threads = check.threads.iter().copied().max().unwrap_or(1);
    let mut all: Vec<BenchRow> = Vec::new();
    let mut torch: Vec<BenchRow> = Vec::new();
    for work in SPLIT_WORK {
        let var = selfmodel::kernels::conv_gemm::WORK_PER_THREAD_VAR;
        let json = child_with(check, "cpu-decoders", threads, &[(var, work.to_string())])?;
        let rows: Vec<BenchRow> = serde_json::from_str(json.trim())
            .map_err(|e| Error::Config(format!("the CPU child's rows: {e}")))?;
        console.say(format!(
            "{threads} CPU threads, a lone image's GEMM split at {work} multiply-adds a thread (0: every thread):"
        ))?;
        console.say(console_table(&rows))?;
        all.extend(rows.iter().map(|r| BenchRow {
            threads: Some(threads),
            work_per_thread: Some(work),
            ..r.clone()
        }));
        if torch.is_empty() {
            torch = rows;
        }
        write_csv(&check.out.join("gemm_split.csv"), &all)?;
    }
    if let Some(py) = &check.python {
        let script = check.bench_dir.join("torch_reference.py");
        torch_side(
            &mut torch,
            run_torch(py, &script, threads, false, Some(2.0)),
            console,
        )?;
        for row in &mut all {
            if let Some(t) = torch
                .iter()
                .find(|t| t.model == row.model && t.figure == row.figure)
                .and_then(|t| t.torch)
            {
                row.torch = Some(t);
                row.ratio = Some(row.ours / t);
            }
        }
        write_csv(&check.out.join("gemm_split.csv"), &all)?;
    }
    Ok(())
}

/// The bandwidth of an elementwise pass over 1 GiB and the rate of an 8,192² matrix product
/// (1 MiB and 256² with `--quick`), into `peak.csv`.
fn peak(check: &GpuCheck, console: &mut Console) -> Result<()> {
    use selfmodel::eval::compute_peak::{bandwidth_gbytes, matmul_gflops};
    let device = selfmodel::core::device::select(check.device)?;
    let (elements, n) = if check.quick {
        (1 << 18, 256)
    } else {
        (1 << 28, 8192)
    };
    let peak = selfmodel::eval::roofline::Peak {
        gbytes_per_s: bandwidth_gbytes(&device, elements, 5),
        gflops: matmul_gflops(&device, n, 5),
    };
    console.say(format!(
        "{}: {:.0} GB/s (an elementwise pass over {} MiB), {:.0} GFLOP/s (f32 product of {n}²)",
        check.device,
        peak.gbytes_per_s,
        elements * 4 >> 20,
        peak.gflops
    ))?;
    write_csv(&check.out.join("peak.csv"), &[peak])
}

/// Each block of the profiled step at the largest batch against its bound
/// ([`selfmodel::eval::roofline`]), into `kernels.csv`; the ten slowest said.
fn roofline(check: &GpuCheck, console: &mut Console) -> Result<()> {
    use selfmodel::eval::roofline::{Peak, StepLaunch, read_profile, rows};
    use selfmodel::report::table::read_csv;
    let launches: Vec<StepLaunch> = read_csv(&check.out.join("launches.csv"))?;
    let peak: Vec<Peak> = read_csv(&check.out.join("peak.csv"))?;
    let peak = *peak
        .first()
        .ok_or_else(|| Error::Config("peak.csv holds no row: run the peak part".into()))?;
    let batch = launches.iter().map(|l| l.batch).max().unwrap_or(0);
    let step: Vec<StepLaunch> = launches.into_iter().filter(|l| l.batch == batch).collect();
    let profile = read_profile(&check.out.join("profile.txt"))?;
    let rows = rows(&profile, &step, peak)?;
    let total: f64 = rows.iter().map(|r| r.time_us).sum();
    console.say(format!(
        "a NeuroKin step at batch {batch}: {:.2} ms of kernels, {} blocks; the ten slowest against their bound at {:.0} GB/s and {:.0} GFLOP/s:",
        total / 1e3,
        rows.len(),
        peak.gbytes_per_s,
        peak.gflops
    ))?;
    for r in rows.iter().take(10) {
        console.say(format!(
            "  {:>9.1} µs  {:>5.1}x its {} bound ({:.1} µs)  {} <- {}",
            r.time_us, r.ratio, r.bound_by, r.bound_us, r.kernels, r.operations
        ))?;
    }
    write_csv(&check.out.join("kernels.csv"), &rows)
}

/// Every figure of every backend measured under `--out` against PyTorch, and the faster
/// backend at each ([`crate::studies::bench::gpu_summary`]): the check's last lines, kept in
/// `summary.csv`.
fn summary(check: &GpuCheck, console: &mut Console) -> Result<()> {
    let lines = crate::studies::bench::gpu_summary::summarise(&check.out)?;
    if lines.is_empty() {
        return console.say("no figures measured under this folder's backends");
    }
    console.say("every figure against PyTorch (ratio = ours / PyTorch's, same GPU or threads, same sitting; * the faster backend):")?;
    for l in &lines {
        console.say(l.console_line())?;
    }
    write_csv(&check.out.join("summary.csv"), &lines)
}
