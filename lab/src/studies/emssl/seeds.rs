//! Table II settled: EMSSL against DSL over seeds, and why a good DSL can win.
//!
//! One Table II run per method is one draw: at +-90 degrees DSL and EMSSL differ by a few
//! percent, inside the run-to-run spread. This study trains Table II's EMSSL and its DSL
//! (trained to convergence) with several seeds (a seed changes the networks' initialisation,
//! the data order and EMSSL's exploration noise; the data and the test targets stay those of
//! the config's data seed), and two DSL variants per seed:
//!
//! - `dsl matched budget`: DSL's inverse network given exactly as many optimiser steps as
//!   EMSSL of the same seed took (iterations and polishing rounds; its forward model trains as
//!   DSL's does, on top), the best epoch on the validation split kept;
//! - `dsl exact forward`: the inverse network trained through the arm's exact, differentiable
//!   forward kinematics instead of a learned forward model: DSL's ceiling.
//!
//! Each run is a unit of Table II's mechanism ([`RangeRun`]) under `runs/seed_<s>/`, so a
//! killed study continues with `--resume`, and a second process started with the same
//! command takes the units nobody holds (both cores train; a last `--resume` gathers every
//! row). Writes `results.csv` (`method,range,seed,mean_cm,
//! median_cm,p95_cm`, then the share above 10 cm, the optimiser steps and provenance),
//! `summary.csv` (per method: mean and spread over the seeds) and `validation_curves.png`.

use std::path::{Path, PathBuf};

use crate::studies::emssl::table2::{IkComparisonConfig, IkRow, RangeRun, RunScope};
use selfmodel::core::atomic_file::write_json;
use selfmodel::core::device::DeviceChoice;
use selfmodel::core::error::{Error, Result};
use selfmodel::core::preset::Preset;
use selfmodel::ik::data::JointOutput;
use selfmodel::ik::paper::distal_learning::{DistalConfig, DistalForward};
use selfmodel::ik::paper::method::IkMethod;
use selfmodel::sim::robot::Robot;
use selfmodel::train::config::TrainConfig;

/// The study's protocol: Table II's config at the study's scale, the range and the seeds.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SeedsConfig {
    pub preset: String,
    pub range_deg: f64,
    /// Table II's data, networks, EMSSL schedule and convergence rule (its `fit.seed` is
    /// replaced by each seed).
    pub table: IkComparisonConfig,
    pub seeds: Vec<u64>,
    /// The seeds the two DSL variants run with (each of `seeds`).
    #[serde(default)]
    pub variant_seeds: Vec<u64>,
}

impl Preset for SeedsConfig {
    /// Table II's paper preset (EMSSL's best schedule, DSL to convergence) on the 20,000-goal
    /// protocol of `reports/emssl_study` (22,000 training samples, 2,000 of them to stop on,
    /// 30,000 test targets): the full protocol takes about 1.6 hours per EMSSL-and-DSL pair
    /// on 2 cores, this one about 35 minutes. +-90 degrees, seeds 0, 1, 2; the DSL variants
    /// with seed 0 (each as long as EMSSL; more seeds: add them, and `--resume`).
    fn paper() -> Self {
        let t = IkComparisonConfig::paper();
        SeedsConfig {
            preset: "paper".into(),
            range_deg: 90.0,
            table: IkComparisonConfig {
                ranges_deg: vec![90.0],
                samples: 52_000,
                train: 22_000,
                validation: 2_000,
                wrapped_ranges_deg: Vec::new(),
                prediction_sample_rows: 0,
                ..t
            },
            seeds: vec![0, 1, 2],
            variant_seeds: vec![0],
        }
    }

    /// Table II's quick preset on 3,000 samples, two seeds: seconds.
    fn quick() -> Self {
        let t = IkComparisonConfig::preset("quick").expect("quick exists");
        SeedsConfig {
            preset: "quick".into(),
            range_deg: 90.0,
            table: IkComparisonConfig {
                ranges_deg: vec![90.0],
                samples: 3_000,
                train: 2_000,
                validation: 300,
                hidden: vec![64, 32],
                wrapped_ranges_deg: Vec::new(),
                prediction_sample_rows: 0,
                emssl: selfmodel::ik::paper::emssl::EmsslConfig {
                    max_iterations: 6,
                    ..t.emssl.clone()
                },
                ..t
            },
            seeds: vec![0, 1],
            variant_seeds: vec![0, 1],
        }
    }
}

/// One run: a method with one seed.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct SeedRow {
    /// `emssl`, `dsl`, `dsl matched budget`, `dsl exact forward`.
    pub method: String,
    /// The joint range (+- degrees).
    pub range: f64,
    pub seed: u64,
    pub mean_cm: f64,
    pub median_cm: f64,
    pub p95_cm: f64,
    /// Share of test targets more than 10 cm off (%).
    pub above_10cm_pct: Option<f64>,
    /// Optimiser steps of the network answering (EMSSL: every iteration and polishing round;
    /// DSL: the inverse network's, its forward model's not counted).
    pub optimiser_steps: usize,
    /// DSL: epochs of the inverse network; EMSSL: iterations (polishing rounds included).
    pub epochs: Option<usize>,
    pub validation_cm: Option<f64>,
    pub train_seconds: f64,
    pub targets: usize,
    pub robot: String,
    pub detail: String,
    pub git_revision: String,
    pub device: String,
    pub preset: String,
}

/// A method over its seeds.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct SeedSummary {
    pub method: String,
    pub range: f64,
    pub seeds: usize,
    /// Mean over the seeds of the runs' mean errors, its sample standard deviation and range.
    pub mean_cm: f64,
    pub sd_cm: f64,
    pub min_cm: f64,
    pub max_cm: f64,
    /// The standard deviation as a share of the mean (%).
    pub spread_pct: f64,
    pub median_cm: f64,
    pub p95_cm: f64,
    pub above_10cm_pct: Option<f64>,
    pub optimiser_steps: f64,
    pub robot: String,
    pub preset: String,
}

/// The summary of `rows`, one line per method (and range, robot), in first-seen order.
pub fn summarise(rows: &[SeedRow]) -> Vec<SeedSummary> {
    let mut keys: Vec<(String, f64, String)> = Vec::new();
    for r in rows {
        let k = (r.method.clone(), r.range, r.robot.clone());
        if !keys.contains(&k) {
            keys.push(k);
        }
    }
    keys.into_iter()
        .map(|(method, range, robot)| {
            let runs: Vec<&SeedRow> = rows
                .iter()
                .filter(|r| r.method == method && r.range == range && r.robot == robot)
                .collect();
            let n = runs.len() as f64;
            let avg = |f: &dyn Fn(&SeedRow) -> f64| runs.iter().map(|r| f(r)).sum::<f64>() / n;
            let mean = avg(&|r| r.mean_cm);
            let sd = if runs.len() > 1 {
                (runs.iter().map(|r| (r.mean_cm - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
            } else {
                0.0
            };
            let above: Option<Vec<f64>> = runs.iter().map(|r| r.above_10cm_pct).collect();
            SeedSummary {
                method,
                range,
                seeds: runs.len(),
                mean_cm: mean,
                sd_cm: sd,
                min_cm: runs.iter().map(|r| r.mean_cm).fold(f64::INFINITY, f64::min),
                max_cm: runs.iter().map(|r| r.mean_cm).fold(0.0, f64::max),
                spread_pct: 100.0 * sd / mean.max(1e-12),
                median_cm: avg(&|r| r.median_cm),
                p95_cm: avg(&|r| r.p95_cm),
                above_10cm_pct: above.map(|v| v.iter().sum::<f64>() / n),
                optimiser_steps: avg(&|r| r.optimiser_steps as f64),
                robot,
                preset: runs[0].preset.clone(),
            }
        })
        .collect()
}

/// Table II's config for one seed.
fn seeded(cfg: &SeedsConfig, seed: u64) -> IkComparisonConfig {
    let mut t = cfg.table.clone();
    t.fit.seed = seed;
    t
}

/// Run every seed's EMSSL and DSL, then every seed's two DSL variants (so the comparison the
/// study is for comes first), writing the tables after each run.
pub fn run(
    cfg: &SeedsConfig,
    robot: &Robot,
    dir: &Path,
    device: DeviceChoice,
    resume: bool,
) -> Result<String> {
    if cfg.seeds.is_empty() {
        return Err(Error::Config("emssl_seeds: no seeds to run".into()));
    }
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    write_json(&dir.join("config.json"), cfg)?;
    let dof = robot.dof();
    let tables: Vec<IkComparisonConfig> = cfg.seeds.iter().map(|&s| seeded(cfg, s)).collect();
    let quiet = |_: &[IkRow], _: &[selfmodel::ik::paper::method::ValidationRow]| Ok(());
    let mut runs: Vec<RangeRun> = Vec::new();
    let seed_dirs: Vec<PathBuf> = (cfg.seeds.iter())
        .map(|seed| dir.join("runs").join(format!("seed_{seed}")))
        .collect();
    for (t, seed_dir) in tables.iter().zip(&seed_dirs) {
        let scope = RunScope {
            cfg: t,
            robot,
            dir: seed_dir,
            device,
            resume,
        };
        runs.push(RangeRun::start(scope, cfg.range_deg, &quiet)?);
    }
    let write = |runs: &[RangeRun]| write_outputs(cfg, dir, runs);
    for i in 0..runs.len() {
        let t = &tables[i];
        eprintln!("emssl_seeds: seed {}", cfg.seeds[i]);
        runs[i].method(&t.emssl_method(dof, JointOutput::Sigmoid))?;
        write(&runs)?;
        runs[i].method(&t.dsl_method("DSL", dof, JointOutput::Sigmoid, t.dsl.clone()))?;
        write(&runs)?;
    }
    for i in 0..runs.len() {
        if !cfg.variant_seeds.contains(&cfg.seeds[i]) {
            continue;
        }
        let t = &tables[i];
        let steps = emssl_steps(&runs[i])?;
        let variants: [(&str, DistalConfig); 2] = [
            (
                "DSL matched budget",
                DistalConfig {
                    inverse_steps: Some(steps),
                    ..t.dsl.clone()
                },
            ),
            (
                "DSL exact forward",
                DistalConfig {
                    forward: DistalForward::Exact,
                    ..t.dsl.clone()
                },
            ),
        ];
        for (name, dsl) in variants {
            eprintln!("emssl_seeds: seed {}, {name}", cfg.seeds[i]);
            let m = t.dsl_method(name, dof, JointOutput::Sigmoid, dsl);
            runs[i].method(&m as &dyn IkMethod)?;
            write(&runs)?;
        }
    }
    let rows = write(&runs)?;
    Ok(summarise(&rows)
        .iter()
        .map(|s| {
            format!(
                "+-{:.0} {}: {:.3} cm mean over {} seeds (sd {:.3}, {:.1}%), p95 {:.2} cm",
                s.range, s.method, s.mean_cm, s.seeds, s.sd_cm, s.spread_pct, s.p95_cm
            )
        })
        .collect::<Vec<_>>()
        .join("; "))
}

/// The optimiser steps of the EMSSL run in `run` (its iterations and polishing rounds).
fn emssl_steps(run: &RangeRun) -> Result<usize> {
    let steps = steps_so_far(run);
    if steps == 0 {
        return Err(Error::Training(
            "emssl_seeds: the EMSSL run records no optimiser steps (a unit from before they were counted): run without --resume".into(),
        ));
    }
    Ok(steps)
}

/// The optimiser steps of the EMSSL iterations `run` holds (0 before its EMSSL unit).
fn steps_so_far(run: &RangeRun) -> usize {
    run.emssl_curve().iter().map(|(c, _)| c.steps).sum()
}

/// A Table II row of one seed's run as a row of this study.
fn seed_row(r: &IkRow, seed: u64, steps_per_epoch: usize, emssl_steps: usize) -> SeedRow {
    let steps = if r.method.starts_with("EMSSL") {
        emssl_steps
    } else {
        r.epochs.unwrap_or(0) * steps_per_epoch
    };
    SeedRow {
        method: r.method.to_lowercase(),
        range: r.range_deg,
        seed,
        mean_cm: r.mean_cm,
        median_cm: r.median_cm,
        p95_cm: r.p95_cm,
        above_10cm_pct: r.above_10cm_pct,
        optimiser_steps: steps,
        epochs: r.epochs,
        validation_cm: r.validation_cm,
        train_seconds: r.train_seconds,
        targets: r.targets,
        robot: r.robot.clone(),
        detail: r.detail.clone(),
        git_revision: r.git_revision.clone(),
        device: r.device.clone(),
        preset: r.preset.clone(),
    }
}

/// `results.csv`, `summary.csv` (+ Markdown) and the validation curves of the runs so far.
fn write_outputs(cfg: &SeedsConfig, dir: &Path, runs: &[RangeRun]) -> Result<Vec<SeedRow>> {
    let mut rows = Vec::new();
    let mut curves: Vec<(String, Vec<(usize, f64)>)> = Vec::new();
    for (run, &seed) in runs.iter().zip(&cfg.seeds) {
        let per_epoch =
            TrainConfig::steps_for_epochs(1, run.data().train().len(), cfg.table.fit.batch);
        let steps = steps_so_far(run);
        rows.extend(
            run.rows_with_others()
                .iter()
                .map(|r| seed_row(r, seed, per_epoch, steps)),
        );
        for name in ["EMSSL", "DSL"] {
            let curve: Vec<(usize, f64)> = run
                .curves()
                .iter()
                .filter(|c| c.method == name)
                .map(|c| (c.epoch, c.validation_cm))
                .collect();
            if !curve.is_empty() {
                curves.push((format!("{name}, seed {seed}"), curve));
            }
        }
    }
    // Method by method, seeds in order.
    let order = ["emssl", "dsl", "dsl matched budget", "dsl exact forward"];
    rows.sort_by_key(|r| {
        (
            order
                .iter()
                .position(|m| *m == r.method)
                .unwrap_or(order.len()),
            r.seed,
        )
    });
    let note = format!(
        "Table II's {} preset on {} training samples ({} of them to stop on) and {} test targets at +-{:.0} degrees, one row per run; a seed changes the initialisation, the data order and EMSSL's exploration, never the data. `optimiser_steps`: EMSSL's over its iterations and polishing rounds; DSL's inverse network's (its forward model's not counted). `dsl matched budget`: DSL's inverse network given EMSSL's steps of the same seed; `dsl exact forward`: trained through the arm's exact forward kinematics (DSL's ceiling).",
        cfg.table.preset,
        cfg.table.train,
        cfg.table.validation,
        cfg.table.samples - cfg.table.train,
        cfg.range_deg
    );
    selfmodel::report::table::write_table(
        &dir.join("results.csv"),
        &rows,
        "EMSSL against DSL over seeds",
        &note,
    )?;
    selfmodel::report::table::write_table(
        &dir.join("summary.csv"),
        &summarise(&rows),
        "EMSSL against DSL: mean and spread over seeds",
        "Per method: the mean over seeds of each run's mean error, its sample standard deviation (`sd_cm`, and as a share of the mean: `spread_pct`), the lowest and highest run; the median, 95th percentile and share above 10 cm averaged over the runs. From `results.csv`.",
    )?;
    if !curves.is_empty() {
        selfmodel::report::figures::curves(
            &dir.join("validation_curves.png"),
            &format!(
                "Validation error over seeds, +-{:.0} deg (EMSSL: per iteration)",
                cfg.range_deg
            ),
            "epoch (EMSSL: iteration)",
            "validation distance error (cm, log)",
            &curves,
        )?;
    }
    Ok(rows)
}
