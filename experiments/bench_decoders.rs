//! Inference and training images/s of both NeuroKin architectures, beside PyTorch's.
//!
//! `cargo run --release --bin bench_decoders -- --torch /tmp/torchref/bin/python`

use std::path::PathBuf;
use std::process::{Command, ExitCode};

use clap::Parser;
use selfmodel::cli::run_main;
use selfmodel::core::device::DeviceChoice;
use selfmodel::studies::bench_decoders::{attach_torch, run};

/// Benchmark the direct decoders (warm-up, synchronised, median of repeats) and, with
/// --torch, PyTorch on the same workloads in the same sitting, with the ratios.
#[derive(Parser)]
#[command(version, allow_negative_numbers = true)]
struct Args {
    #[arg(long, value_enum, default_value_t = DeviceChoice::Cpu)]
    device: DeviceChoice,
    /// A Python with torch installed: runs ../shared/bench/torch_reference.py too.
    #[arg(long)]
    torch: Option<PathBuf>,
    /// The PyTorch reference script.
    #[arg(long, default_value = "../shared/bench/torch_reference.py")]
    torch_script: PathBuf,
    /// Tiny models, for a smoke test.
    #[arg(long)]
    quick: bool,
    /// Write the table here as CSV.
    #[arg(long, default_value = "runs/bench_decoders/results.csv")]
    out: PathBuf,
}

fn main() -> ExitCode {
    let args = Args::parse();
    // The revision the run starts from, before it writes anything.
    selfmodel::cli::git_revision();
    run_main(|| {
        let mut rows = run(args.device, args.quick)?;
        if let Some(py) = &args.torch {
            let out = Command::new(py)
                .arg(&args.torch_script)
                .args(["--threads", &rayon::current_num_threads().to_string()])
                .output()
                .map_err(|e| selfmodel::Error::io(py, e))?;
            if !out.status.success() {
                return Err(selfmodel::Error::Config(format!(
                    "{} failed: {}",
                    args.torch_script.display(),
                    String::from_utf8_lossy(&out.stderr)
                        .lines()
                        .last()
                        .unwrap_or("")
                )));
            }
            attach_torch(&mut rows, &String::from_utf8_lossy(&out.stdout));
        }
        println!(
            "{:<11} {:<22} {:>10} {:>10} {:>8}",
            "model", "figure", "selfmodel", "pytorch", "ratio"
        );
        for r in &rows {
            let (t, ratio) = match r.torch {
                Some(t) => (format!("{t:.1}"), format!("{:.2}x", r.ours / t)),
                None => ("-".into(), "-".into()),
            };
            println!(
                "{:<11} {:<22} {:>10.1} {:>10} {:>8}",
                r.model, r.figure, r.ours, t, ratio
            );
        }
        if let Some(dir) = args.out.parent() {
            std::fs::create_dir_all(dir).map_err(|e| selfmodel::Error::io(dir, e))?;
        }
        let cpu = selfmodel::eval::compute_peak::machine_label(true);
        selfmodel::report::table::write_table(
            &args.out,
            &rows,
            "Decoders: selfmodel against PyTorch, same workloads, same sitting",
            &format!(
                "Measured on {cpu}. Images/s, median of timed repeats after a warm-up; `torch` from `../shared/bench/torch_reference.py` run right after ours on the same cores; `ratio` = ours / torch (above 1: faster than PyTorch). Absolute figures hold for this machine only."
            ),
        )
    })
}
