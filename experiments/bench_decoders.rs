//! Inference and training images/s of both NeuroKin architectures, beside PyTorch's.
//!
//! `cargo run --release --bin bench_decoders -- --torch /tmp/torchref/bin/python`

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use selfmodel::core::device::DeviceChoice;
use selfmodel_lab::cli::run_main;
use selfmodel_lab::studies::bench::decoders::{
    Batches, attach_torch, console_table, run_batches, run_torch,
};

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
    /// Also the batches that fill a GPU: inference at 4,096, training at 1,024 (PyTorch's
    /// script with --extra).
    #[arg(long)]
    fill: bool,
    /// Write the table here as CSV.
    #[arg(long, default_value = "runs/bench_decoders/results.csv")]
    out: PathBuf,
}

fn main() -> ExitCode {
    let args = Args::parse();
    // The revision the run starts from, before it writes anything.
    selfmodel_lab::cli::git_revision();
    run_main(|| {
        let batches = if args.fill {
            Batches::Both
        } else {
            Batches::Paper
        };
        let mut rows = run_batches(args.device, args.quick, batches, &mut |_| Ok(()))?;
        if let Some(py) = &args.torch {
            let threads = rayon::current_num_threads();
            let out = run_torch(py, &args.torch_script, threads, args.fill, None)?;
            attach_torch(&mut rows, &out);
        }
        print!("{}", console_table(&rows));
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
