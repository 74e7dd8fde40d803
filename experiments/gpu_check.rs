//! The GPU check of issue 48 in one binary (`studies::bench::gpu_check`): built here with
//! `--features wgpu` (or `wgpu,cuda`: both backends in one binary), carried to a GPU machine and
//! run there by `scripts/gpu_check.sh`.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use selfmodel::core::device::DeviceChoice;
use selfmodel_lab::cli::run_main;
use selfmodel_lab::studies::bench::gpu_check::{GpuCheck, Part, cpu_decoders, k3dgs_cpu, run};

/// Measure selfmodel on a GPU beside PyTorch on the same GPU, and on its CPU at several
/// thread counts beside PyTorch at as many: kernel launches and host reads per training step,
/// the decoder benchmark, NeuroKin and K-3DGS end to end, the CPU/GPU equivalence.
#[derive(Parser)]
#[command(version)]
struct Args {
    /// Write here (console.txt and one CSV per part); the script names it after the GPU.
    #[arg(long, default_value = "runs/gpu/check")]
    out: PathBuf,
    /// A Python with torch (CUDA) installed, for PyTorch's side of every figure.
    #[arg(long)]
    torch: Option<PathBuf>,
    /// The folder of torch_reference.py and torch_gpu_reference.py.
    #[arg(long, default_value = "../shared/bench")]
    bench_dir: PathBuf,
    /// CPU thread counts of the `cpu` part.
    #[arg(long, value_delimiter = ',', default_value = "2,4,8,16")]
    threads: Vec<usize>,
    /// The parts to run, in order [default: all].
    #[arg(long, value_enum, value_delimiter = ',')]
    parts: Option<Vec<Part>>,
    /// Tiny models and the quick presets: a smoke test of the check (on lavapipe).
    #[arg(long)]
    quick: bool,
    /// The GPU backend to measure [default: cuda where compiled in, else wgpu].
    #[arg(long, value_enum)]
    device: Option<DeviceChoice>,
    /// Internal: one measurement in a process of its own thread count.
    #[arg(long, hide = true)]
    child: Option<String>,
}

fn main() -> ExitCode {
    let args = Args::parse();
    selfmodel_lab::cli::git_revision();
    run_main(|| {
        let exe = std::env::current_exe().map_err(|e| selfmodel::Error::io("this binary", e))?;
        let check = GpuCheck {
            out: args.out.clone(),
            python: args.torch.clone(),
            bench_dir: args.bench_dir.clone(),
            threads: args.threads.clone(),
            parts: args.parts.clone().unwrap_or_else(|| Part::ALL.to_vec()),
            quick: args.quick,
            exe,
            device: args.device.unwrap_or_else(DeviceChoice::gpu),
        };
        match args.child.as_deref() {
            None => run(&check),
            Some("cpu-decoders") => {
                println!("{}", cpu_decoders(&check)?);
                Ok(())
            }
            Some("k3dgs-cpu") => {
                println!("{}", k3dgs_cpu(&check)?);
                Ok(())
            }
            Some(other) => Err(selfmodel::Error::Config(format!("no child {other}"))),
        }
    })
}
