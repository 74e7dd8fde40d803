//! Regenerate the README, `docs/` and every `results.md` under `reports/` from the CSVs the
//! experiments wrote: `cargo run --release --bin reports` (`--check`: change nothing, fail if
//! any is stale).

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use selfmodel_lab::cli::run_main;
use selfmodel_lab::studies::docs;

/// Generate the documents from the results: README.md and docs/*.md from their sources in
/// docs/src/ (every number read from reports/), and the Markdown tables beside every CSV.
#[derive(Parser)]
#[command(version)]
struct Args {
    /// Write nothing; exit non-zero, naming them, if any generated file is stale.
    #[arg(long)]
    check: bool,
    /// Also redraw the figures drawn from one CSV beside them (Pareto plots, training
    /// curves) from that CSV.
    #[arg(long)]
    figures: bool,
    /// The repository root.
    #[arg(long, default_value = ".")]
    root: PathBuf,
}

fn main() -> ExitCode {
    let args = Args::parse();
    run_main(|| {
        if args.check {
            let stale = docs::stale(&args.root)?;
            if stale.is_empty() {
                println!("reports: every generated document is up to date");
                return Ok(());
            }
            let names: Vec<String> = stale.iter().map(|p| p.display().to_string()).collect();
            return Err(selfmodel::Error::Config(format!(
                "stale generated documents: {} (run `cargo run --release --bin reports`)",
                names.join(", ")
            )));
        }
        if args.figures {
            let n = docs::redraw_figures(&args.root)?;
            println!("reports: {n} figures redrawn from their CSVs");
        }
        let changed = docs::write_all(&args.root)?;
        println!("reports: {changed} generated documents rewritten");
        Ok(())
    })
}
