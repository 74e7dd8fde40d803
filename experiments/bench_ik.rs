//! Our learned full-pose IK beside the Robotics Toolbox's ik_LM and TRAC-IK, on the same
//! random reachable targets in the same sitting.
//!
//! `cargo run --release --bin bench_ik -- --model runs/ik_models/panda --out reports/ik_pose/panda`

use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use selfmodel::core::spread::format_significant;
use selfmodel_lab::cli::run_main;
use selfmodel_lab::studies::bench::ik::{
    BenchIkConfig, EQUAL_PRECISION_MM_DEG, default_out, run, summary_rows,
};

/// Benchmark a model `ik train` saved: share of targets solved exactly (1 mm, 0.572 degrees,
/// inside the limits) and exact solutions/s at several budgets, the family of k answers, the
/// model alone; with the references (scripts/ik_reference.py) on the same targets.
#[derive(Parser)]
#[command(version)]
struct Args {
    /// A folder `ik train` wrote (full pose, not --position-only).
    #[arg(long)]
    model: PathBuf,
    /// paper (10,000 targets) or quick (200).
    #[arg(long, default_value = "paper")]
    preset: String,
    /// Samples a target for the family of answers.
    #[arg(long, default_value_t = 10)]
    k: usize,
    /// The Python that runs the references (roboticstoolbox-python, pytracik).
    #[arg(long, default_value = "python3")]
    python: PathBuf,
    /// Leave the references out.
    #[arg(long)]
    no_references: bool,
    /// Output folder [default: runs/bench_ik/<model folder>; the committed results were
    /// written with --out reports/ik_pose/<robot>].
    #[arg(long)]
    out: Option<PathBuf>,
}

/// The ranking at equal precision in one line a thread count: ours at its default budget
/// against the reference with the most answers within the common precision a second.
fn equal_precision_line(rows: &[selfmodel_lab::studies::bench::ik::BenchIkRow]) -> String {
    let (mm, deg) = EQUAL_PRECISION_MM_DEG;
    let mut text = String::new();
    let ours = rows.iter().filter(|r| {
        r.standard && r.k == 1 && r.solver == "selfmodel flow + LM" && r.precise_per_s.is_some()
    });
    for o in ours {
        let best = rows
            .iter()
            .filter(|r| !r.solver.starts_with("selfmodel") && r.threads == o.threads)
            .filter(|r| r.precise_per_s.is_some())
            .max_by(|a, b| {
                a.precise_per_s
                    .partial_cmp(&b.precise_per_s)
                    .expect("finite")
            });
        if let (Some(b), Some(v)) = (best, o.vs_best_reference_precise) {
            text += &format!(
                "at equal precision ({} mm, {} degrees), {} threads or processes: ours {:.0}/s, the best reference {} at {} {:.0}/s: {:.1}x\n",
                format_significant(mm, 2),
                format_significant(deg, 2),
                o.threads,
                o.precise_per_s.unwrap_or(0.0),
                b.solver,
                b.tolerance.as_deref().unwrap_or("-"),
                b.precise_per_s.unwrap_or(0.0),
                v
            );
        }
    }
    text
}

fn main() -> ExitCode {
    let args = Args::parse();
    selfmodel_lab::cli::git_revision();
    run_main(|| {
        if args.k == 0 {
            return Err(selfmodel::Error::Config("--k must be at least 1".into()));
        }
        let cfg = BenchIkConfig::named(&args.preset, args.k)?;
        let device = selfmodel::core::device::select(selfmodel::core::device::DeviceChoice::Cpu)?;
        let out = args.out.clone().unwrap_or_else(|| default_out(&args.model));
        let python = (!args.no_references).then_some(args.python.as_path());
        let rows = run(&cfg, &args.model, &out, python, &device)?;
        let mut text = format!(
            "{:<34} {:<22} {:<26} {:>7} {:>8} {:>10} {:>9} {:>20} {:>22}\n",
            "solver",
            "budget",
            "tolerance",
            "threads",
            "exact %",
            "exact/s",
            "distinct",
            "p98 error mm, deg",
            "within precision %, /s"
        );
        for r in summary_rows(&rows) {
            let p98 = match (r.pos_err_mm_p98, r.rot_err_deg_p98) {
                (Some(p), Some(d)) => {
                    format!("{}, {}", format_significant(p, 2), format_significant(d, 2))
                }
                _ => "-".into(),
            };
            let precise = match (r.precise_pct, r.precise_per_s) {
                (Some(pct), Some(per_s)) => format!("{pct:.2}, {per_s:.0}"),
                _ => "-".into(),
            };
            text += &format!(
                "{:<34} {:<22} {:<26} {:>7} {:>8.2} {:>10.0} {:>9} {:>20} {:>22}\n",
                r.solver,
                r.budget,
                r.tolerance.as_deref().unwrap_or("-"),
                r.threads,
                r.exact_pct,
                r.exact_per_s,
                r.distinct_mean.map_or("-".into(), |d| format!("{d:.1}")),
                p98,
                precise
            );
        }
        text += &equal_precision_line(&rows);
        if let Some(a) = rows.iter().find(|r| r.solver.contains("alone")) {
            text += &format!(
                "the model alone: {:.1} mm, {:.2} degrees mean ({:.1} mm, {:.2} degrees median)\n",
                a.pos_err_mm_mean.unwrap_or(f64::NAN),
                a.rot_err_deg_mean.unwrap_or(f64::NAN),
                a.pos_err_mm_median.unwrap_or(f64::NAN),
                a.rot_err_deg_median.unwrap_or(f64::NAN)
            );
        }
        text += &format!(
            "bench_ik ({} preset, {} targets, {}): wrote {}/results.csv (+ results.md, success_against_time.png)\n",
            cfg.preset,
            cfg.targets,
            rows.first().map_or("", |r| r.cpu.as_str()),
            out.display()
        );
        print!("{text}");
        // What the command printed, for the docs (which include it, not a typed copy).
        selfmodel::core::atomic_file::write_bytes(&out.join("console.txt"), text.as_bytes())?;
        Ok(())
    })
}
