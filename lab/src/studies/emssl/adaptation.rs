//! Table IV of the EMSSL paper (sections III-C and IV-C): fast adaptation of a trained inverse
//! model when the arm changes.
//!
//! The base model is Table II's EMSSL model of the `paper-schedule` preset in one joint range
//! (the same data, network, optimiser, schedule and seed, so on the UR5 at +-90 degrees it is
//! that preset's model). Then
//! the arm changes ([`ArmChange`]: every link 1, 3 and 5 cm longer, as in the paper, and one
//! link bent) and two approaches adapt the model with further EMSSL iterations:
//!
//! 1. **learned link parameters**: a small sample of the changed arm's (joints, position)
//!    pairs fits its link parameters through a differentiable forward model
//!    ([`selfmodel::ik::paper::calibration`]); EMSSL then runs on that updated model, and the changed
//!    arm is only ever touched for the sample;
//! 2. **the arm itself**: EMSSL runs with the changed arm as its forward model (no link
//!    parameters), so every sampling pass moves the real arm once per desired position.
//!
//! The stopping rule (written into every row): adaptation stops at the first iteration whose
//! reach error on the desired training positions, measured through the forward model the
//! approach uses, is within `target_factor` of the base model's own reach error on the
//! unchanged arm ("back to where it was"), or after `patience` iterations without a new best,
//! or at `max_iterations`. The kept model is the one with the lowest such reach error. "Before"
//! and "after" are test errors on the changed arm (evaluation only). The desired positions
//! after the change are where the changed arm goes with the same random joints; the network's
//! input normalisation stays the base model's.

use std::path::{Path, PathBuf};

use burn::module::Module;
use burn::tensor::Device;

use crate::studies::emssl::table2::IkComparisonConfig;
use selfmodel::core::atomic_file::write_json;
use selfmodel::core::device::DeviceChoice;
use selfmodel::core::error::{Error, Result};
use selfmodel::core::preset::Preset;
use selfmodel::ik::data::{DistanceErrors, IkData, distances};
use selfmodel::ik::learning::{FitConfig, test_errors};
use selfmodel::ik::mlp::{InverseModelConfig, Mlp};
use selfmodel::ik::paper::calibration::{CalibrationConfig, calibrate};
use selfmodel::ik::paper::emssl::{EmsslConfig, EmsslIteration, emssl, emssl_from};
use selfmodel::sim::arm_change::ArmChange;
use selfmodel::sim::kinematics::KinematicChain;
use selfmodel::sim::robot::Robot;
use selfmodel::train::trainer::autodiff_device;

/// Everything Table IV's run depends on.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AdaptationConfig {
    pub preset: String,
    /// The base model's setup (Table II's), in the joint range `range_deg`.
    pub base: IkComparisonConfig,
    pub range_deg: f64,
    /// The built-in arms adapted (`ur5`, `arm4`), unless `--robot` / `--urdf` names one.
    pub robots: Vec<String>,
    pub changes: Vec<ArmChange>,
    /// One adaptation iteration's training (the learning rate of the first; it decays by
    /// `emssl.learning_rate_decay`).
    pub fit: FitConfig,
    /// The adaptation's EMSSL schedule (its `target_reach_cm` is set per run, see below).
    pub emssl: EmsslConfig,
    /// Stop once the reach error on the training goals is at most this times the base
    /// model's on the unchanged arm.
    pub target_factor: f64,
    pub calibration: CalibrationConfig,
}

impl Preset for AdaptationConfig {
    /// Table II's `paper-schedule` preset at +-90 degrees for the base model; the UR5 and arm4; links 1,
    /// 3 and 5 cm longer and the link to joint 3 bent 3 degrees. Adaptation: the paper's 10
    /// epochs a iteration at 3e-4 (a fifth of the paper's rate: the model is already trained),
    /// decaying by 0.9; exploration noise 0.01 decaying by 0.9; up to 20 iterations, patience
    /// 3, target 1.1 times the base reach error; 100 calibration samples.
    fn paper() -> Self {
        AdaptationConfig {
            preset: "paper".into(),
            base: IkComparisonConfig::paper_schedule(),
            range_deg: 90.0,
            robots: vec!["ur5".into(), "arm4".into()],
            changes: vec![
                ArmChange::Lengthen { cm: 1.0 },
                ArmChange::Lengthen { cm: 3.0 },
                ArmChange::Lengthen { cm: 5.0 },
                ArmChange::Bend { joint: 2, deg: 3.0 },
            ],
            fit: FitConfig {
                learning_rate: 3e-4,
                ..FitConfig::paper()
            },
            emssl: EmsslConfig {
                max_iterations: 20,
                agreement: 0.0,
                patience: 3,
                exploration: 0.01,
                exploration_decay: 0.9,
                exploration_floor: 0.0,
                learning_rate_decay: 0.9,
                target_reach_cm: None,
                ..EmsslConfig::paper()
            },
            target_factor: 1.1,
            calibration: CalibrationConfig::paper(),
        }
    }

    /// Table II's quick preset, the UR5 only, links 3 cm longer and one bend; seconds.
    fn quick() -> Self {
        let p = Self::paper();
        AdaptationConfig {
            preset: "quick".into(),
            base: IkComparisonConfig::quick(),
            robots: vec!["ur5".into()],
            changes: vec![
                ArmChange::Lengthen { cm: 3.0 },
                ArmChange::Bend { joint: 2, deg: 3.0 },
            ],
            fit: FitConfig {
                learning_rate: 1e-3,
                ..IkComparisonConfig::quick().fit
            },
            emssl: EmsslConfig {
                max_iterations: 6,
                ..p.emssl
            },
            calibration: CalibrationConfig {
                samples: 50,
                stages: vec![(300, 3e-3), (200, 3e-4)],
                seed: 0,
            },
            ..p
        }
    }
}

/// One change, one approach: a row of Table IV.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct AdaptationRow {
    pub robot: String,
    pub change: String,
    pub approach: String,
    /// Test errors (cm) of the base model on the unchanged arm, on the changed arm before
    /// adaptation, and of the kept model after.
    pub unchanged_cm: f64,
    pub before_cm: f64,
    pub after_cm: f64,
    pub after_median_cm: f64,
    /// The iteration at which the target was met (`None`: not within the run) and the
    /// iterations run.
    pub iterations_to_target: Option<usize>,
    pub iterations_run: usize,
    /// The target (cm) of the stopping rule and the reach error of the kept model.
    pub target_reach_cm: f64,
    pub kept_reach_cm: f64,
    /// (joints, position) pairs taken from the changed arm: the calibration sample, or every
    /// forward-model call of the EMSSL iterations.
    pub arm_samples: usize,
    /// Approach 1: mean distance (mm) between the learned forward model's and the changed
    /// arm's end positions on the test joints (0 for approach 2).
    pub forward_model_error_mm: f64,
    pub seconds: f64,
    pub stopping_rule: String,
    /// The paper's Table IV (lengthened links only; its arm unnamed).
    pub paper_before_cm: Option<f64>,
    pub paper_after_cm: Option<f64>,
    pub paper_iterations: Option<usize>,
    pub git_revision: String,
    pub device: String,
    pub preset: String,
}

/// One adaptation iteration, for the curves.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct AdaptationCurveRow {
    pub robot: String,
    pub change: String,
    pub approach: String,
    /// 0: the base model before adaptation.
    pub iteration: usize,
    pub test_mean_cm: f64,
    pub train_reach_cm: f64,
    pub forward_calls: usize,
}

/// The paper's Table IV: (before, after, iterations) for links lengthened by `cm`, on the
/// 6-joint arm of its Table II (our UR5); none for any other robot (arm4 is ours).
fn paper_reference(robot: &str, change: &ArmChange) -> Option<(f64, f64, usize)> {
    if robot != "ur5" {
        return None;
    }
    match change {
        ArmChange::Lengthen { cm } if *cm == 1.0 => Some((2.98, 0.28, 2)),
        ArmChange::Lengthen { cm } if *cm == 3.0 => Some((8.87, 0.30, 3)),
        ArmChange::Lengthen { cm } if *cm == 5.0 => Some((14.78, 0.36, 7)),
        _ => None,
    }
}

/// The base model and what it reached on the unchanged arm, cached in `dir/base_<robot>/`.
struct Base {
    file: PathBuf,
    /// The base model for inference (its trainable copies are loaded from `file`).
    model: Mlp,
    train_reach_cm: f64,
    test: DistanceErrors,
}

#[derive(serde::Serialize, serde::Deserialize)]
struct BaseState {
    base: IkComparisonConfig,
    range_deg: f64,
    robot: String,
    train_reach_cm: f64,
    iterations: usize,
    git_revision: String,
}

/// Train the base model (Table II's EMSSL), or load it when `dir/base_<robot>/` holds one of
/// the same configuration.
fn base_model(
    cfg: &AdaptationConfig,
    robot: &Robot,
    data: &IkData,
    dir: &Path,
    device: &Device,
) -> Result<Base> {
    let robot_name = robot.label.as_str();
    let folder = dir.join(format!("base_{}", file_name(robot_name)));
    let file = folder.join("model.bpk");
    let state_path = folder.join("base.json");
    let model_cfg = cfg.base.model(robot.dof());
    let same = std::fs::read_to_string(&state_path)
        .ok()
        .and_then(|t| serde_json::from_str::<BaseState>(&t).ok())
        .filter(|s| s.base == cfg.base && s.range_deg == cfg.range_deg && s.robot == robot_name);
    let (model, train_reach_cm) = match same {
        Some(state) if file.exists() => {
            eprintln!(
                "{robot_name}: reusing the base model in {} (trained at {})",
                folder.display(),
                state.git_revision
            );
            (
                load(&model_cfg, &file, device, cfg.base.fit.seed)?,
                state.train_reach_cm,
            )
        }
        _ => {
            let (model, curve) = emssl(
                &robot.chain,
                data,
                &model_cfg,
                &cfg.base.fit,
                &cfg.base.emssl,
                device,
                None,
            )?;
            let reach = curve
                .iter()
                .map(|c| c.train_reach_cm)
                .fold(f64::INFINITY, f64::min);
            std::fs::create_dir_all(&folder).map_err(|e| Error::io(&folder, e))?;
            selfmodel::train::checkpoint::save_module(&model, &file)?;
            write_json(
                &state_path,
                &BaseState {
                    base: cfg.base.clone(),
                    range_deg: cfg.range_deg,
                    robot: robot_name.into(),
                    train_reach_cm: reach,
                    iterations: curve.len(),
                    git_revision: selfmodel::core::provenance::git_revision(),
                },
            )?;
            (model, reach)
        }
    };
    let (test, _) = test_errors(
        &model,
        &robot.chain,
        data,
        cfg.base.fit.inference_batch,
        device,
    );
    Ok(Base {
        file,
        model,
        train_reach_cm,
        test,
    })
}

/// The saved model `file` on `device` (an autodiff device gives a trainable model).
fn load(model_cfg: &InverseModelConfig, file: &Path, device: &Device, seed: u64) -> Result<Mlp> {
    model_cfg
        .init(device, seed)?
        .try_load_file(file)
        .map_err(|e| {
            Error::data(
                file,
                format!("the cached base model cannot be read ({e}); delete it and the command trains it again"),
            )
        })
}

fn file_name(name: &str) -> String {
    name.chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect()
}

/// The IK data of the changed arm: the same joints, the positions the changed arm reaches,
/// the base model's normalisation.
fn changed_data(data: &IkData, changed: &KinematicChain) -> IkData {
    IkData {
        positions: changed.end_effector_batch(&data.joints),
        ..data.clone()
    }
}

/// Adapt one robot to every change with both approaches.
pub fn adapt_robot(
    cfg: &AdaptationConfig,
    robot: &Robot,
    dir: &Path,
    device_choice: DeviceChoice,
) -> Result<(Vec<AdaptationRow>, Vec<AdaptationCurveRow>)> {
    let robot_name = robot.label.as_str();
    let device = selfmodel::core::device::select(device_choice)?;
    let data = IkData::generate(&robot.chain, &cfg.base.data(cfg.range_deg))?;
    let base = base_model(cfg, robot, &data, dir, &device)?;
    let model_cfg = cfg.base.model(robot.dof());
    let batch = cfg.base.fit.inference_batch;
    let target = base.train_reach_cm * cfg.target_factor;
    let emssl_cfg = EmsslConfig {
        target_reach_cm: Some(target),
        ..cfg.emssl.clone()
    };
    let rule = format!(
        "stop at reach error on the training goals <= {target:.3} cm ({} x the base model's {:.3} cm on the unchanged arm), or {} iterations without a new best, or {} iterations",
        cfg.target_factor, base.train_reach_cm, cfg.emssl.patience, cfg.emssl.max_iterations
    );
    let mut rows = Vec::new();
    let mut curves = Vec::new();
    for change in &cfg.changes {
        let changed = change.apply(&robot.chain)?;
        let cdata = changed_data(&data, &changed);
        let (before, _) = test_errors(&base.model, &changed, &cdata, batch, &device);
        let test_joints = &data.joints[data.test()];
        // Approach 1: the link parameters from a small sample, then EMSSL on that model.
        let t0 = std::time::Instant::now();
        let sample = &data.joints[..cfg.calibration.samples.min(data.n_train)];
        let (learned, calibration) = calibrate(
            &robot.chain,
            sample,
            &changed.end_effector_batch(sample),
            &cfg.calibration,
            &device,
        )?;
        let model_error_mm = 1e3
            * distances(
                &learned.end_effector_batch(test_joints),
                &changed.end_effector_batch(test_joints),
            )
            .iter()
            .sum::<f64>()
            / test_joints.len().max(1) as f64;
        for (approach, forward, calibration_samples) in [
            (
                "1: learned link parameters",
                &learned,
                Some(calibration.samples),
            ),
            ("2: the changed arm", &changed, None),
        ] {
            let start = if calibration_samples.is_some() {
                t0
            } else {
                std::time::Instant::now()
            };
            let tdev = autodiff_device(&device, cfg.fit.seed);
            let model = load(&model_cfg, &base.file, &tdev, cfg.base.fit.seed)?;
            let (kept, curve) = emssl_from(
                model, &tdev, forward, &changed, &cdata, &cfg.fit, &emssl_cfg, &device,
            )?;
            let (after, _) = test_errors(&kept, &changed, &cdata, batch, &device);
            let reached = curve.iter().find(|c| c.train_reach_cm <= target);
            let kept_reach = curve
                .iter()
                .map(|c| c.train_reach_cm)
                .fold(f64::INFINITY, f64::min);
            let arm_samples = calibration_samples
                .unwrap_or_else(|| curve.last().map_or(0, |c: &EmsslIteration| c.forward_calls));
            let paper = paper_reference(robot_name, change);
            rows.push(AdaptationRow {
                robot: robot_name.into(),
                change: change.label(),
                approach: approach.into(),
                unchanged_cm: base.test.mean_cm,
                before_cm: before.mean_cm,
                after_cm: after.mean_cm,
                after_median_cm: after.median_cm,
                iterations_to_target: reached.map(|c| c.iteration),
                iterations_run: curve.len(),
                target_reach_cm: target,
                kept_reach_cm: kept_reach,
                arm_samples,
                forward_model_error_mm: if calibration_samples.is_some() {
                    model_error_mm
                } else {
                    0.0
                },
                seconds: start.elapsed().as_secs_f64(),
                stopping_rule: rule.clone(),
                paper_before_cm: paper.map(|p| p.0),
                paper_after_cm: paper.map(|p| p.1),
                paper_iterations: paper.map(|p| p.2),
                git_revision: selfmodel::core::provenance::git_revision(),
                device: device_choice.to_string(),
                preset: cfg.preset.clone(),
            });
            let point =
                |iteration, test_mean_cm, train_reach_cm, forward_calls| AdaptationCurveRow {
                    robot: robot_name.into(),
                    change: change.label(),
                    approach: approach.into(),
                    iteration,
                    test_mean_cm,
                    train_reach_cm,
                    forward_calls,
                };
            curves.push(point(0, before.mean_cm, f64::NAN, 0));
            curves.extend(curve.iter().map(|c| {
                point(
                    c.iteration,
                    c.test.mean_cm,
                    c.train_reach_cm,
                    c.forward_calls,
                )
            }));
        }
        eprintln!(
            "{robot_name}, {}: calibration fit {:.2} -> {:.3} mm on {} samples",
            change.label(),
            calibration.fit_before_mm,
            calibration.fit_after_mm,
            calibration.samples
        );
    }
    Ok((rows, curves))
}

/// The rows (and curve rows) already in `dir` for robots other than `running`, of the same
/// preset: a run of one robot (`--robot arm4`) adds its rows to the others' instead of
/// replacing the table. Each row keeps the revision it was written at. None when `dir` has
/// no table yet.
fn rows_of_other_robots(
    dir: &Path,
    running: &[&str],
    preset: &str,
) -> Result<(Vec<AdaptationRow>, Vec<AdaptationCurveRow>)> {
    let (table, curve) = (dir.join("results.csv"), dir.join("adaptation_curve.csv"));
    if !table.exists() || !curve.exists() {
        return Ok((Vec::new(), Vec::new()));
    }
    let rows: Vec<AdaptationRow> = selfmodel::report::table::read_csv(&table)?;
    let kept: Vec<AdaptationRow> = rows
        .into_iter()
        .filter(|r| r.preset == preset && !running.contains(&r.robot.as_str()))
        .collect();
    let curves: Vec<AdaptationCurveRow> = selfmodel::report::table::read_csv(&curve)?;
    let curves = curves
        .into_iter()
        .filter(|c| kept.iter().any(|r| r.robot == c.robot))
        .collect();
    Ok((kept, curves))
}

/// Run Table IV for every robot; writes `results.csv` (+ Markdown), `adaptation_curve.csv`,
/// `adaptation_<robot>.png`, `config.json` and the cached base models. `robot` replaces the
/// config's robots when given.
pub fn run(
    cfg: &AdaptationConfig,
    robot: Option<Robot>,
    dir: &Path,
    device: DeviceChoice,
) -> Result<String> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    write_json(&dir.join("config.json"), cfg)?;
    let robots: Vec<Robot> = match robot {
        Some(r) => vec![r],
        None => cfg
            .robots
            .iter()
            .map(|name| match name.as_str() {
                "ur5" => Ok(selfmodel::sim::robots::BuiltinRobot::Ur5.load()),
                "arm4" => Ok(selfmodel::sim::robots::BuiltinRobot::Arm4.load()),
                other => Err(Error::Config(format!(
                    "adaptation: unknown robot \"{other}\" (ur5 or arm4)"
                ))),
            })
            .collect::<Result<_>>()?,
    };
    let names: Vec<&str> = robots.iter().map(|r| r.label.as_str()).collect();
    let (mut rows, mut curves) = rows_of_other_robots(dir, &names, &cfg.preset)?;
    for robot in &robots {
        let (r, c) = adapt_robot(cfg, robot, dir, device)?;
        rows.extend(r);
        curves.extend(c);
    }
    selfmodel::report::table::write_table(
        &dir.join("results.csv"),
        &rows,
        "Table IV: fast adaptation of the EMSSL inverse model to a changed arm",
        &format!(
            "Test distance errors (cm) on {} targets at +-{:.0} degrees. `unchanged_cm`: the base model on the arm it was trained for; `before_cm`: on the changed arm; `after_cm`: the adapted model. `arm_samples`: (joints, position) pairs taken from the changed arm. Approach 1 learns the link parameters from {} samples by gradient descent through a differentiable forward model, then runs EMSSL on it; approach 2 runs EMSSL on the changed arm. `paper_*`: the paper's Table IV, for reference (its arm unnamed; lengthened links only). The stopping rule is in each row.",
            cfg.base.samples - cfg.base.train,
            cfg.range_deg,
            cfg.calibration.samples
        ),
    )?;
    selfmodel::report::table::write_table(
        &dir.join("adaptation_curve.csv"),
        &curves,
        "Fast adaptation: test error against adaptation iteration",
        "Iteration 0 is the base model on the changed arm.",
    )?;
    draw_figures(dir)?;
    Ok(rows
        .iter()
        .filter(|r| names.contains(&r.robot.as_str()))
        .map(|r| {
            format!(
                "{} {} approach {}: {:.2} -> {:.2} cm, target {}",
                r.robot,
                r.change,
                &r.approach[..1],
                r.before_cm,
                r.after_cm,
                r.iterations_to_target
                    .map_or("not met".to_string(), |i| format!("met at iteration {i}"))
            )
        })
        .collect::<Vec<_>>()
        .join("; "))
}

/// Table IV's figures from `adaptation_curve.csv` in `dir`: `adaptation_<robot>.png`, one line
/// per change and approach.
pub fn draw_figures(dir: &Path) -> Result<()> {
    let curves: Vec<AdaptationCurveRow> =
        selfmodel::report::table::read_csv(&dir.join("adaptation_curve.csv"))?;
    let mut robots: Vec<String> = Vec::new();
    for c in &curves {
        if !robots.contains(&c.robot) {
            robots.push(c.robot.clone());
        }
    }
    for name in &robots {
        let mut runs: Vec<(String, Vec<(usize, f64)>)> = Vec::new();
        for c in curves.iter().filter(|c| &c.robot == name) {
            let label = format!("{}, approach {}", c.change, &c.approach[..1]);
            match runs.last_mut() {
                Some((l, pts)) if *l == label => pts.push((c.iteration, c.test_mean_cm)),
                _ => runs.push((label, vec![(c.iteration, c.test_mean_cm)])),
            }
        }
        selfmodel::report::figures::curves(
            &dir.join(format!("adaptation_{}.png", file_name(name))),
            &format!("Fast adaptation of the inverse model ({name})"),
            "adaptation iteration (0: before)",
            "test distance error (cm, log)",
            &runs,
        )?;
    }
    Ok(())
}
