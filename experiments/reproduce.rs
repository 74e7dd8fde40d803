//! Run every registered experiment on one preset: `cargo run --release --bin reproduce`.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use clap::Parser;
use selfmodel_lab::cli::run_main;
use selfmodel_lab::studies::registry::EXPERIMENTS;

/// Reproduce everything: each experiment of the registry in turn, into its default folder.
#[derive(Parser)]
#[command(version)]
struct Args {
    /// paper (the papers' settings) or quick (tiny, seconds).
    #[arg(long, default_value = "paper")]
    preset: String,
    /// Write each experiment into ROOT/<its committed folder> (reports/..., data/) [default:
    /// runs/, git-ignored; `--root .` regenerates the committed reports].
    #[arg(long)]
    root: Option<PathBuf>,
    /// Run only these experiments (names as in --list).
    #[arg(long, value_delimiter = ',')]
    only: Vec<String>,
    /// List the experiments and exit.
    #[arg(long)]
    list: bool,
}

fn main() -> ExitCode {
    let args = Args::parse();
    // The revision the run starts from, before it writes anything.
    selfmodel_lab::cli::git_revision();
    run_main(|| {
        if args.list {
            for e in EXPERIMENTS {
                println!("{:<16} {}", e.name, e.about);
            }
            return Ok(());
        }
        if let Some(unknown) = args
            .only
            .iter()
            .find(|o| !EXPERIMENTS.iter().any(|e| e.name == o.as_str()))
        {
            return Err(selfmodel::Error::Config(format!(
                "--only {unknown}: no such experiment (reproduce --list names them)"
            )));
        }
        let root = args
            .root
            .clone()
            .unwrap_or_else(|| PathBuf::from(selfmodel_lab::studies::run::RUNS));
        for e in EXPERIMENTS
            .iter()
            .filter(|e| args.only.is_empty() || args.only.iter().any(|o| o == e.name))
        {
            let start = Instant::now();
            let mut opts = selfmodel_lab::studies::registry::RunOptions::preset(&args.preset);
            // table1 gathers the rows the decoders' own experiments just wrote.
            opts.reuse_root = Some(root.clone());
            let summary = e.run_in(&opts, &root.join(e.default_dir))?;
            println!(
                "{:<16} {:>7.1} s  {summary}",
                e.name,
                start.elapsed().as_secs_f64()
            );
        }
        Ok(())
    })
}
