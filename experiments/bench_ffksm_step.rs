//! One dense FFKSM training step: burn's autodiff against the hand-written step, both
//! architectures, in the same sitting.
//!
//! `cargo run --release --bin bench_ffksm_step`

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use selfmodel::core::device::DeviceChoice;
use selfmodel_lab::cli::run_main;

/// Time one dense FFKSM training step of a whole 100x100 image (640,000 network evaluations)
/// through burn's autodiff (the reference) and through the hand-written step: for each, one
/// warm-up step, then the median of the repeats, back to back; with the GFLOP/s of the step's
/// matrix products.
#[derive(Parser)]
#[command(version, allow_negative_numbers = true)]
struct Args {
    #[arg(long, value_enum, default_value_t = DeviceChoice::Cpu)]
    device: DeviceChoice,
    /// Timed steps per path and architecture, after one warm-up step.
    #[arg(long, default_value_t = 5)]
    repeats: usize,
    /// Tiny fields and images, for a smoke test.
    #[arg(long)]
    quick: bool,
    /// Write the table here as CSV (and its Markdown beside it).
    #[arg(long, default_value = "runs/bench_ffksm_step/results.csv")]
    out: PathBuf,
}

fn main() -> ExitCode {
    let args = Args::parse();
    // The revision the run starts from, before it writes anything.
    selfmodel_lab::cli::git_revision();
    run_main(|| {
        let rows =
            selfmodel_lab::studies::bench::ffksm_step::run(args.device, args.quick, args.repeats)?;
        println!(
            "{:<24} {:<13} {:>9} {:>9} {:>9} {:>8}",
            "model", "path", "median s", "min s", "GFLOP/s", "speedup"
        );
        for r in &rows {
            println!(
                "{:<24} {:<13} {:>9.3} {:>9.3} {:>9.1} {:>7.2}x",
                r.model, r.path, r.seconds_median, r.seconds_min, r.gflop_per_s, r.speedup
            );
        }
        if let Some(dir) = args.out.parent() {
            std::fs::create_dir_all(dir).map_err(|e| selfmodel::Error::io(dir, e))?;
        }
        selfmodel::report::table::write_table(
            &args.out,
            &rows,
            "One dense FFKSM training step: burn's autodiff against the hand-written step",
            &format!(
                "A whole 100x100 image, 64 samples per ray (640,000 evaluations), forward, loss and backward to every parameter's gradient (no optimiser step). Median and fastest of {} steps per path, back to back after one warm-up step; `gflop` counts the matrix products from the layer shapes; `speedup` is the autodiff median over this path's.",
                args.repeats
            ),
        )
    })
}
