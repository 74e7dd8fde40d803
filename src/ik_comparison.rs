//! Table II of the EMSSL paper: learned inverse kinematics by embodied self-supervision
//! (EMSSL) against direct regression (DRL), distal supervised learning (DSL) and a conditional
//! GAN, in two joint ranges, plus (beyond the paper) the numerical solver a roboticist would
//! use instead (damped least squares from the home pose) and EMSSL's answers refined by it.
//!
//! Every method answers the same held-out targets (30,000 in the paper preset); the error is
//! the distance (cm) between the target and the forward kinematics of the answer. Each method
//! writes its answers as CSV (target, joints, reached position) so anyone can check them.
//! `solutions_per_s` is the rate of answering the test targets once trained (inference in
//! batches of the inference batch size, and the solver's iterations where it runs): the median
//! of three passes over all of them after a warm-up pass.

use std::io::Write;
use std::path::Path;
use std::time::Instant;

use nalgebra::Point3;

use crate::atomic_file::{write_atomic, write_json};
use crate::conditional_gan::{GanConfig, train_gan};
use crate::device::DeviceChoice;
use crate::distal_learning::{DistalConfig, dsl};
use crate::error::{Error, Result};
use crate::ik_data::{DistanceErrors, IkData, IkDataConfig, distances};
use crate::inverse_learning::{EmsslConfig, EmsslIteration, FitConfig, drl, emssl, predict};
use crate::inverse_model::InverseModelConfig;
use crate::numerical_ik::{DlsConfig, solve_batch};
use crate::preset::Preset;
use crate::robot::Robot;

/// The presets of both inverse-kinematics experiments.
pub const IK_PRESETS: &[&str] = &["paper", "quick"];

/// Everything Table II's run depends on.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct IkComparisonConfig {
    pub preset: String,
    /// Each joint drawn from `[-r, r]` degrees, one table block per `r`.
    pub ranges_deg: Vec<f64>,
    pub samples: usize,
    pub train: usize,
    pub data_seed: u64,
    /// Hidden widths of the inverse model (3 -> hidden -> dof).
    pub hidden: Vec<usize>,
    /// One EMSSL iteration's training, and DRL's and DSL's optimiser (their epochs below).
    pub fit: FitConfig,
    pub emssl: EmsslConfig,
    pub drl_epochs: usize,
    pub dsl: DistalConfig,
    pub gan: GanConfig,
    /// The numerical solver from the home pose (all joints 0).
    pub dls: DlsConfig,
    /// The same solver started from EMSSL's answers.
    pub refine: DlsConfig,
}

impl Preset for IkComparisonConfig {
    /// The paper's data (100,000 samples, 70,000 to train, +-90 and +-180 degrees) and Table
    /// I (the network, Adam 1.5e-3, batches 128 and 512, up to 200 iterations of 10 epochs).
    /// The paper gives no schedule for the baselines: each trains 20 epochs (two EMSSL
    /// iterations' worth of steps each pass) with the same optimiser.
    fn paper() -> Self {
        IkComparisonConfig {
            preset: "paper".into(),
            ranges_deg: vec![90.0, 180.0],
            samples: 100_000,
            train: 70_000,
            data_seed: 0,
            hidden: vec![1024, 512, 256, 128],
            fit: FitConfig::paper(),
            emssl: EmsslConfig::paper(),
            drl_epochs: 20,
            dsl: DistalConfig {
                forward_hidden: vec![1024, 512, 256, 128],
                forward_epochs: 20,
                inverse_epochs: 20,
            },
            gan: GanConfig {
                noise: 3,
                generator_hidden: vec![1024, 512, 256, 128],
                discriminator_hidden: vec![512, 256, 128],
                fit: FitConfig {
                    epochs: 20,
                    learning_rate: 2e-4,
                    ..FitConfig::paper()
                },
                best_of: 10,
            },
            dls: DlsConfig::standard(),
            refine: DlsConfig::standard(),
        }
    }

    /// 5,000 samples, small networks, a few epochs: seconds.
    fn quick() -> Self {
        let p = Self::paper();
        IkComparisonConfig {
            preset: "quick".into(),
            samples: 5_000,
            train: 4_000,
            hidden: vec![256, 128],
            fit: FitConfig {
                epochs: 5,
                batch: 64,
                ..FitConfig::paper()
            },
            emssl: EmsslConfig {
                max_iterations: 15,
                patience: 5,
                ..EmsslConfig::paper()
            },
            drl_epochs: 20,
            dsl: DistalConfig {
                forward_hidden: vec![128, 64],
                forward_epochs: 20,
                inverse_epochs: 10,
            },
            gan: GanConfig {
                generator_hidden: vec![128, 64],
                discriminator_hidden: vec![128, 64],
                fit: FitConfig {
                    epochs: 10,
                    batch: 64,
                    ..p.gan.fit.clone()
                },
                best_of: 5,
                ..p.gan.clone()
            },
            ..p
        }
    }
}

impl IkComparisonConfig {
    pub fn data(&self, range_deg: f64) -> IkDataConfig {
        IkDataConfig {
            samples: self.samples,
            train: self.train,
            range_deg,
            seed: self.data_seed,
            validation: 0,
        }
    }

    pub fn model(&self, dof: usize) -> InverseModelConfig {
        InverseModelConfig::inverse(self.hidden.clone(), dof, crate::ik_data::JointOutput::Sigmoid)
    }
}

/// One method in one joint range: a row of Table II.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct IkRow {
    pub robot: String,
    pub range_deg: f64,
    pub method: String,
    pub mean_cm: f64,
    pub median_cm: f64,
    pub p95_cm: f64,
    pub max_cm: f64,
    pub targets: usize,
    /// Test targets answered per second, trained model given.
    pub solutions_per_s: f64,
    pub train_seconds: f64,
    /// Method-specific facts: iterations, the solver's convergence, the forward model's error.
    pub detail: String,
    /// The paper's Table II, for reference (its arm is unnamed; ours is `robot`).
    pub paper_mean_cm: Option<f64>,
    pub git_revision: String,
    pub device: String,
    pub preset: String,
}

/// The paper's Table II mean errors (cm).
fn paper_reference(method: &str, range_deg: f64) -> Option<f64> {
    let column = match range_deg {
        r if r == 90.0 => 0,
        r if r == 180.0 => 1,
        _ => return None,
    };
    let values = match method {
        "EMSSL" => [0.28, 1.78],
        "DSL" => [0.39, 2.37],
        "CGAN" => [0.48, 2.57],
        "DRL" => [2.34, 31.69],
        _ => return None,
    };
    Some(values[column])
}

/// Write answers as CSV: target x, y, z (m), joints q1.. (rad), reached x, y, z (m) (where the
/// forward kinematics of the joints puts the end effector).
pub fn write_predictions(
    path: &Path,
    targets: &[Point3<f64>],
    joints: &[Vec<f64>],
    reached: &[Point3<f64>],
) -> Result<()> {
    let dof = joints.first().map_or(0, Vec::len);
    write_atomic(path, |w| {
        let io = |e| Error::io(path, e);
        let qs: Vec<String> = (1..=dof).map(|k| format!("q{k}")).collect();
        writeln!(
            w,
            "target_x,target_y,target_z,{},reached_x,reached_y,reached_z",
            qs.join(",")
        )
        .map_err(io)?;
        for ((t, q), r) in targets.iter().zip(joints).zip(reached) {
            let q: Vec<String> = q.iter().map(|v| format!("{v:.9}")).collect();
            writeln!(
                w,
                "{:.9},{:.9},{:.9},{},{:.9},{:.9},{:.9}",
                t.x,
                t.y,
                t.z,
                q.join(","),
                r.x,
                r.y,
                r.z
            )
            .map_err(io)?;
        }
        Ok(())
    })
}

/// What one range's run produced.
pub struct RangeOutcome {
    pub rows: Vec<IkRow>,
    pub emssl_curve: Vec<EmsslIteration>,
}

/// Run every method in one joint range, writing predictions under `dir/predictions_<r>/`.
pub fn run_range(
    cfg: &IkComparisonConfig,
    robot: &Robot,
    robot_name: &str,
    range_deg: f64,
    dir: &Path,
    device_choice: DeviceChoice,
) -> Result<RangeOutcome> {
    let device = crate::device::select(device_choice)?;
    let data = IkData::generate(&robot.chain, &cfg.data(range_deg))?;
    let model_cfg = cfg.model(robot.dof());
    let targets = &data.positions[data.test()];
    let ranges = vec![data.range; robot.dof()];
    let pred_dir = dir.join(format!("predictions_{range_deg:.0}"));
    let mut rows = Vec::new();
    let mut add = |method: &str,
                   joints: &[Vec<f64>],
                   train_seconds: f64,
                   solve_seconds: f64,
                   detail: String|
     -> Result<()> {
        // "EMSSL + DLS" -> emssl_dls.csv
        let file = method
            .to_lowercase()
            .split(|c: char| !c.is_ascii_alphanumeric())
            .filter(|w| !w.is_empty())
            .collect::<Vec<_>>()
            .join("_");
        let reached = robot.chain.end_effector_batch(joints);
        write_predictions(
            &pred_dir.join(format!("{file}.csv")),
            targets,
            joints,
            &reached,
        )?;
        let e = DistanceErrors::from_metres(&distances(targets, &reached));
        rows.push(IkRow {
            robot: robot_name.to_string(),
            range_deg,
            method: method.to_string(),
            mean_cm: e.mean_cm,
            median_cm: e.median_cm,
            p95_cm: e.p95_cm,
            max_cm: e.max_cm,
            targets: e.targets,
            solutions_per_s: targets.len() as f64 / solve_seconds.max(1e-12),
            train_seconds,
            detail,
            paper_mean_cm: paper_reference(method, range_deg),
            git_revision: crate::cli::git_revision(),
            device: device_choice.to_string(),
            preset: cfg.preset.clone(),
        });
        Ok(())
    };
    let batch = cfg.fit.inference_batch;
    // Seconds to answer every test target: one warm-up pass, then the median of three.
    let timed = |f: &mut dyn FnMut()| {
        f();
        let mut t: Vec<f64> = (0..3)
            .map(|_| {
                let t = Instant::now();
                f();
                t.elapsed().as_secs_f64()
            })
            .collect();
        t.sort_by(f64::total_cmp);
        t[1]
    };

    // Direct regression.
    let t = Instant::now();
    let (model, _) = drl(
        &robot.chain,
        &data,
        &model_cfg,
        &FitConfig {
            epochs: cfg.drl_epochs,
            ..cfg.fit.clone()
        },
        &device,
    )?;
    let train_s = t.elapsed().as_secs_f64();
    let mut joints = Vec::new();
    let solve_s = timed(&mut || joints = predict(&model, &data, targets, batch, &device));
    add(
        "DRL",
        &joints,
        train_s,
        solve_s,
        format!("{} epochs", cfg.drl_epochs),
    )?;

    // Distal supervised learning.
    let t = Instant::now();
    let distal = dsl(&robot.chain, &data, &model_cfg, &cfg.fit, &cfg.dsl, &device)?;
    let train_s = t.elapsed().as_secs_f64();
    let solve_s = timed(&mut || joints = predict(&distal.inverse, &data, targets, batch, &device));
    add(
        "DSL",
        &joints,
        train_s,
        solve_s,
        format!(
            "forward model {} epochs, test error {:.2} cm; inverse {} epochs",
            cfg.dsl.forward_epochs, distal.forward_test_cm, cfg.dsl.inverse_epochs
        ),
    )?;

    // Conditional GAN: one sample, and the best of k.
    let t = Instant::now();
    let (generator, _) = train_gan(
        &robot.chain,
        &data,
        &cfg.gan,
        crate::ik_data::JointOutput::Sigmoid,
        &device,
    )?;
    let train_s = t.elapsed().as_secs_f64();
    let seed = cfg.gan.fit.seed ^ 0x5EED;
    let solve_s = timed(&mut || joints = generator.sample(&data, targets, batch, seed, &device));
    add(
        "CGAN",
        &joints,
        train_s,
        solve_s,
        format!("{} epochs, one sample", cfg.gan.fit.epochs),
    )?;
    let k = cfg.gan.best_of;
    let solve_s = timed(&mut || {
        joints = generator.best_of(&robot.chain, &data, targets, k, batch, seed, &device)
    });
    add(
        &format!("CGAN best of {k}"),
        &joints,
        train_s,
        solve_s,
        format!("the sample of {k} the forward model puts closest"),
    )?;

    // EMSSL.
    let t = Instant::now();
    let (model, curve) = emssl(
        &robot.chain,
        &data,
        &model_cfg,
        &cfg.fit,
        &cfg.emssl,
        &device,
    )?;
    let train_s = t.elapsed().as_secs_f64();
    let best = curve
        .iter()
        .min_by(|a, b| a.train_reach_cm.total_cmp(&b.train_reach_cm))
        .map_or(0, |c| c.iteration);
    let solve_s = timed(&mut || joints = predict(&model, &data, targets, batch, &device));
    let emssl_joints = joints.clone();
    add(
        "EMSSL",
        &joints,
        train_s,
        solve_s,
        format!(
            "{} iterations run, the model of iteration {best} kept (lowest reach error on the training goals)",
            curve.len()
        ),
    )?;

    // The numerical solver from the home pose, and from EMSSL's answers (whose training and
    // inference count towards the refined answers).
    let home = vec![vec![0.0; robot.dof()]; targets.len()];
    for (method, starts, dls, (before_train_s, before_solve_s)) in [
        ("DLS from home", &home, &cfg.dls, (0.0, 0.0)),
        (
            "EMSSL + DLS",
            &emssl_joints,
            &cfg.refine,
            (train_s, solve_s),
        ),
    ] {
        let mut solutions = Vec::new();
        let s = timed(&mut || solutions = solve_batch(&robot.chain, targets, starts, &ranges, dls));
        let converged = solutions
            .iter()
            .filter(|x| x.error_m < dls.tolerance_m)
            .count();
        let mean_iterations = solutions.iter().map(|x| x.iterations).sum::<usize>() as f64
            / solutions.len().max(1) as f64;
        let joints: Vec<Vec<f64>> = solutions.into_iter().map(|x| x.joints).collect();
        add(
            method,
            &joints,
            before_train_s,
            s + before_solve_s,
            format!(
                "{:.1}% within {} mm, {mean_iterations:.1} iterations on average (cap {})",
                100.0 * converged as f64 / targets.len().max(1) as f64,
                dls.tolerance_m * 1e3,
                dls.max_iterations
            ),
        )?;
    }
    Ok(RangeOutcome {
        rows,
        emssl_curve: curve,
    })
}

/// A row of an EMSSL learning curve (Figure 6), flattened for CSV.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct CurveRow {
    pub robot: String,
    pub range_deg: f64,
    pub iteration: usize,
    pub exploration: f64,
    pub learning_rate: f64,
    pub test_mean_cm: f64,
    pub test_median_cm: f64,
    pub test_p95_cm: f64,
    pub train_reach_cm: f64,
    pub disagreement: f64,
    pub sampling_seconds: f64,
    pub training_seconds: f64,
    pub git_revision: String,
    pub preset: String,
}

impl CurveRow {
    pub fn new(robot: &str, range_deg: f64, preset: &str, c: &EmsslIteration) -> Self {
        CurveRow {
            robot: robot.into(),
            range_deg,
            iteration: c.iteration,
            exploration: c.exploration,
            learning_rate: c.learning_rate,
            test_mean_cm: c.test.mean_cm,
            test_median_cm: c.test.median_cm,
            test_p95_cm: c.test.p95_cm,
            train_reach_cm: c.train_reach_cm,
            disagreement: c.disagreement,
            sampling_seconds: c.sampling_seconds,
            training_seconds: c.training_seconds,
            git_revision: crate::cli::git_revision(),
            preset: preset.into(),
        }
    }
}

/// Write `dir/file` (CSV + Markdown) and `learning_curve.png`: test error against iteration,
/// one line per range.
pub fn write_curves(dir: &Path, file: &str, title: &str, rows: &[CurveRow]) -> Result<()> {
    crate::report::write_table(
        &dir.join(file),
        rows,
        title,
        "Per EMSSL iteration: the exploration noise and learning rate used, the test error after it (evaluation only), the mean distance between the desired training positions and where the noise-free answers take the arm, the disagreement (the stopping criterion) and the seconds of the sampling and training phases.",
    )?;
    let mut ranges: Vec<f64> = rows.iter().map(|r| r.range_deg).collect();
    ranges.dedup();
    let runs: Vec<(String, Vec<(usize, f64)>)> = ranges
        .iter()
        .map(|&r| {
            (
                format!("+-{r:.0} deg, test mean"),
                rows.iter()
                    .filter(|c| c.range_deg == r)
                    .map(|c| (c.iteration, c.test_mean_cm))
                    .collect(),
            )
        })
        .collect();
    crate::figures::curves(
        &dir.join("learning_curve.png"),
        title,
        "EMSSL iteration",
        "test distance error (cm, log)",
        &runs,
    )
}

/// Table II: every method in every range. Writes `results.csv` (+ Markdown), predictions,
/// the EMSSL curves (`emssl_curve.csv`, `learning_curve.png`) and the config.
pub fn run(
    cfg: &IkComparisonConfig,
    robot: &Robot,
    robot_name: &str,
    dir: &Path,
    device: DeviceChoice,
) -> Result<Vec<IkRow>> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    write_json(&dir.join("config.json"), cfg)?;
    let mut rows = Vec::new();
    let mut curve = Vec::new();
    for &r in &cfg.ranges_deg {
        let out = run_range(cfg, robot, robot_name, r, dir, device)?;
        rows.extend(out.rows);
        curve.extend(
            out.emssl_curve
                .iter()
                .map(|c| CurveRow::new(robot_name, r, &cfg.preset, c)),
        );
    }
    crate::report::write_table(
        &dir.join("results.csv"),
        &rows,
        "Table II: learned inverse kinematics, distance error on held-out targets",
        &format!(
            "Robot `{robot_name}` (the UR5 from its standard DH parameters unless stated; the paper does not name its 6-DOF arm), position only. Errors in cm over {} test targets; `paper_mean_cm` is the paper's Table II for reference. `DLS`: damped least squares on the analytic Jacobian (beyond the paper). `predictions_<range>/` holds every method's answers.",
            cfg.samples - cfg.train
        ),
    )?;
    write_curves(
        dir,
        "emssl_curve.csv",
        "EMSSL: test error against iteration",
        &curve,
    )?;
    Ok(rows)
}
