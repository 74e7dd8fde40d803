//! What every study shares: how it is asked to run ([`RunOptions`]), what the registry knows
//! of it ([`Experiment`]) and how self-model rows are written.

use std::path::Path;

use crate::studies::models::{Studied, run_studied};
use selfmodel::core::device::DeviceChoice;
use selfmodel::core::error::{Error, Result};
use selfmodel::report::table::{write_csv, write_markdown_report};
use selfmodel::self_models::result::ModelResult;
use selfmodel::self_models::{
    model::SelfModel,
    run_config::{SELF_MODEL_PRESETS, SelfModelRun},
};
use selfmodel::sim::robots::{BuiltinRobot, RobotSpec};
use selfmodel::train::config::LrSchedule;

/// How to run an experiment: the preset and the switches every experiment understands.
#[derive(Clone, Debug)]
pub struct RunOptions {
    pub preset: String,
    pub device: DeviceChoice,
    /// Train and test on the paper-compatible dataset (the ground-plane artefact).
    pub paper_compatible: bool,
    /// Continue from the checkpoints in the output folder.
    pub resume: bool,
    /// Override the training steps (a shortened run says so in its results).
    pub steps: Option<usize>,
    /// Self-models: images per training batch instead of the preset's (`--batch`), with the
    /// learning rate and steps rescaled ([`RunOptions::apply`]).
    pub batch: Option<usize>,
    /// Train the self-models on the first N poses of a longer trajectory, tested on the
    /// preset's number of poses after them (`--train-samples`).
    pub train_samples: Option<usize>,
    /// Where experiments may already have written their results (`reproduce`'s root): `table1`
    /// gathers rows found there, of the same preset, dataset, steps and training poses, instead of training
    /// the same models a second time.
    pub reuse_root: Option<std::path::PathBuf>,
    /// The robot (`--robot`, `--urdf`, `--arm4-scene`): the arm of the inverse-kinematics
    /// experiments (default ur5) or the robot a self-model learns (default arm4).
    pub robot: Option<selfmodel::sim::robots::BuiltinRobot>,
    pub urdf: Option<std::path::PathBuf>,
    /// Place the URDF as the papers' scene places arm4 (else its root link at the origin).
    pub arm4_scene: bool,
    /// The URDF's end-effector link (`--tip`).
    pub tip: Option<String>,
    /// The URDF's visual or collision geometry (`--geometry`).
    pub geometry: selfmodel::sim::urdf_loader::GeometryKind,
    /// Which movable joints are the joint vector (`--joints`, `--tips`).
    pub joints: selfmodel::sim::kinematics::JointGroup,
    /// Train and test the self-models on this dataset file instead of rendering (`--dataset`).
    pub dataset: Option<std::path::PathBuf>,
    /// The camera the self-models' data is rendered from (`--eye`, `--target`, `--fov`,
    /// `--size`, `--view`).
    pub camera: CameraChoice,
    /// The forward model's latencies of `emssl_sampling_speed`, instead of its preset's.
    pub latencies: Option<Vec<selfmodel::ik::paper::sampling_pass::Latency>>,
    /// `table1`'s models (registry names), instead of every one marked for Table I; the
    /// data-scale ablation's (instead of NeuroKin).
    pub models: Option<Vec<String>>,
    /// The data-scale ablation's training-pose counts, instead of the paper's sizes.
    pub sizes: Option<Vec<usize>>,
    /// Self-models: the dtype the network trains in (`--precision`, f32 master weights).
    pub precision: selfmodel::train::precision::Precision,
    /// Self-models: the learning rate along training (`--schedule`).
    pub schedule: selfmodel::train::config::LrSchedule,
}

impl RunOptions {
    /// A preset with the defaults: CPU, clean dataset, fresh run.
    pub fn preset(preset: &str) -> Self {
        RunOptions {
            preset: preset.into(),
            device: DeviceChoice::Cpu,
            paper_compatible: false,
            resume: false,
            steps: None,
            batch: None,
            train_samples: None,
            reuse_root: None,
            robot: None,
            urdf: None,
            arm4_scene: false,
            tip: None,
            geometry: Default::default(),
            joints: Default::default(),
            camera: CameraChoice::default(),
            dataset: None,
            latencies: None,
            models: None,
            sizes: None,
            precision: Default::default(),
            schedule: Default::default(),
        }
    }

    /// The robot the options name, `default` where they name none.
    pub fn robot_spec(&self, default: BuiltinRobot) -> RobotSpec {
        match (&self.urdf, self.robot) {
            (Some(path), _) => {
                let mut spec = if self.arm4_scene {
                    RobotSpec::urdf_in_arm4_scene(path.clone())
                } else {
                    RobotSpec::Urdf {
                        path: path.clone(),
                        base_xyz: [0.0; 3],
                        base_rpy: [0.0; 3],
                        tip: None,
                        geometry: Default::default(),
                        joints: Default::default(),
                    }
                };
                if let RobotSpec::Urdf {
                    tip,
                    geometry,
                    joints,
                    ..
                } = &mut spec
                {
                    *tip = self.tip.clone();
                    *geometry = self.geometry;
                    *joints = self.joints.clone();
                }
                spec
            }
            (None, robot) => RobotSpec::Builtin(robot.unwrap_or(default)),
        }
    }

    /// Where a run on a robot other than the experiment's own (`default`) writes by default:
    /// `runs/robots/<robot>/`, named by the URDF's file stem (`panda`, `ur5`), or
    /// `<name>_dh` for a built-in robot (the built-in UR5 is drawn from its DH parameters).
    /// `None` for the experiment's own robot.
    pub fn robot_folder(&self, default: BuiltinRobot) -> Option<std::path::PathBuf> {
        let name = match (&self.urdf, self.robot) {
            (Some(path), _) => path
                .file_stem()
                .map_or("urdf".into(), |s| s.to_string_lossy().into_owned()),
            (None, Some(b)) if b != default => format!("{}_dh", b.name()),
            _ => return None,
        };
        Some(std::path::Path::new(RUNS).join("robots").join(name))
    }

    /// The arm of the inverse-kinematics experiments (default ur5), named for reports by its
    /// `label`: its kinematics only (no mesh is read).
    pub fn ik_robot(&self) -> Result<selfmodel::sim::robot::Robot> {
        let spec = self.robot_spec(BuiltinRobot::Ur5);
        let robot = spec.load_kinematics()?;
        spec.require_movable(&robot, "inverse kinematics")?;
        Ok(robot)
    }

    /// Apply the switches to a self-model run: the robot, its camera (the papers' arm, and a
    /// URDF in its scene, keep the papers' camera; any other robot is framed automatically
    /// unless `--eye` places the camera), the steps; paper reference figures only for the
    /// papers' arm.
    pub fn apply<M: SelfModel>(&self, cfg: SelfModelRun<M>) -> Result<SelfModelRun<M>> {
        let mut cfg = cfg.paper_compatible(self.paper_compatible).on_robot(
            self.robot_spec(BuiltinRobot::Arm4),
            &self.camera,
            self.arm4_scene,
            self.dataset.as_deref(),
        )?;
        if !self.precision.is_f32() {
            if !cfg.model.autocasts() {
                return Err(Error::Config(format!(
                    "{}: --precision {} applies to the decoders (neurokin, resneurokin_d); this model trains in f32 only",
                    cfg.name, self.precision
                )));
            }
            cfg.train.precision = self.precision;
        }
        if self.schedule != cfg.train.schedule {
            cfg.train.schedule = self.schedule;
            let msg = match self.schedule {
                LrSchedule::Cosine => "learning rate along a half cosine to 1% at the last step",
                LrSchedule::Constant => "learning rate constant",
            };
            add_note(&mut cfg.note, msg.into());
        }
        let rebatched = self.override_batch(&mut cfg.train, &mut cfg.note);
        cfg.steps_override = self
            .override_steps(&mut cfg.train.steps, &mut cfg.note)
            .or(rebatched);
        if let Some(n) = self.train_samples.filter(|&n| n != cfg.data.dataset.train) {
            let d = &mut cfg.data.dataset;
            let samples = n + d.samples - d.train;
            let msg = format!(
                "trained on the first {n} samples of a {samples}-sample trajectory instead of the preset's {}",
                d.train
            );
            (d.samples, d.train) = (samples, n);
            add_note(&mut cfg.note, msg);
        }
        Ok(cfg)
    }

    /// `--batch B`: train on batches of B images instead of the preset's b. The rule (Adam's
    /// square-root scaling, Malladi et al. 2022, "On the SDEs and Scaling Rules for Adaptive
    /// Gradient Algorithms"): the learning rate times sqrt(B / b), and the steps times b / B
    /// (rounded up), so the run sees the same number of epochs. `--steps` still sets the steps
    /// outright. Schedules a model counts in steps of its own (FFKSM's curriculum, K-3DGS's
    /// densification interval) are not rescaled. Says so in `note`; returns the new step
    /// count, if the batch changed.
    fn override_batch(
        &self,
        train: &mut selfmodel::train::config::TrainConfig,
        note: &mut String,
    ) -> Option<usize> {
        let new = self.batch.filter(|&b| b != train.batch)?;
        let old = train.batch;
        let ratio = new as f64 / old as f64;
        train.learning_rate *= ratio.sqrt();
        train.steps = ((train.steps as f64 / ratio).ceil() as usize).max(1);
        train.batch = new;
        add_note(
            note,
            format!(
                "batch {new} instead of the preset's {old}: learning rate x sqrt({new}/{old}) = {:.3e}, {} steps (the same epochs)",
                train.learning_rate, train.steps
            ),
        );
        Some(train.steps)
    }

    /// `--steps N`: set `steps` and say so in `note`; returns the override, if any.
    fn override_steps(&self, steps: &mut usize, note: &mut String) -> Option<usize> {
        let new = self.steps.filter(|s| s != steps)?;
        add_note(note, format!("{new} steps instead of the preset's {steps}"));
        *steps = new;
        Some(new)
    }
}

/// Append `msg` to a run's note, `; `-separated.
fn add_note(note: &mut String, msg: String) {
    *note = if note.is_empty() {
        msg
    } else {
        format!("{note}; {msg}")
    };
}

use selfmodel::data::dataset::CameraChoice;

/// Where runs write unless told otherwise (git-ignored).
pub const RUNS: &str = "runs";

/// One experiment.
#[derive(Clone, Copy)]
pub struct Experiment {
    /// The binary's name (`cargo run --release --bin NAME`).
    pub name: &'static str,
    /// One line: what it reproduces.
    pub about: &'static str,
    /// Where `reproduce` writes it, relative to the repository root.
    pub default_dir: &'static str,
    /// The presets it understands (`paper` and `quick` always).
    pub presets: &'static [&'static str],
    /// Whether it trains self-models whose rows belong in Table I.
    pub in_table1: bool,
    /// Whether it accepts `--robot` / `--urdf` (the inverse-kinematics experiments).
    pub takes_robot: bool,
    /// Whether several processes may run it into one folder at once (each takes its own
    /// units: `emssl_table2`); every other experiment locks its folder for the run.
    pub shares_output: bool,
    /// Run into a folder; returns a one-line summary.
    pub run: fn(opts: &RunOptions, dir: &Path) -> Result<String>,
}

/// Write `rows` as `dir/results.csv` and `results.md`.
pub fn write_rows(dir: &Path, rows: &[ModelResult], title: &str, note: &str) -> Result<()> {
    let csv = dir.join("results.csv");
    write_csv(&csv, rows)?;
    write_markdown_report(&csv, title, note)
}

impl Experiment {
    /// Run into `dir`, holding its lock (`dir/.lock`, the holder's process id) unless the
    /// experiment shares its folder: a second run into the same folder is refused with the
    /// holder's id; a lock left by a dead process is taken over. A folder the run created and
    /// left empty (it failed before writing) is removed.
    pub fn run_in(&self, opts: &RunOptions, dir: &Path) -> Result<String> {
        let existed = dir.exists();
        let lock = if self.shares_output {
            None
        } else {
            match selfmodel::core::atomic_file::Claim::take(&dir.join(".lock"))? {
                selfmodel::core::atomic_file::Claimed::Mine(c) => Some(c),
                selfmodel::core::atomic_file::Claimed::Other(pid) => {
                    return Err(selfmodel::Error::Config(format!(
                        "{} is in use by process {pid}, another {} run writing there; wait for it to finish or choose another --out",
                        dir.display(),
                        self.name
                    )));
                }
            }
        };
        let result = (self.run)(opts, dir);
        drop(lock);
        if !existed && std::fs::read_dir(dir).is_ok_and(|mut d| d.next().is_none()) {
            let _ = std::fs::remove_dir(dir);
        }
        result
    }

    /// Where a run on `preset` writes by default: under `runs/` (git-ignored: a user's run
    /// leaves the checkout as it was), the folder `default_dir` names under `reports/`, with
    /// `_<preset>` for any preset but paper. The committed reports are regenerated only with an
    /// explicit `--out reports/...` (or `reproduce --root .`).
    pub fn dir_for(&self, preset: &str) -> std::path::PathBuf {
        let leaf = self
            .default_dir
            .strip_prefix("reports/")
            .unwrap_or(self.default_dir);
        let leaf = if preset == "paper" {
            leaf.to_string()
        } else {
            format!("{leaf}_{preset}")
        };
        std::path::Path::new(RUNS).join(leaf)
    }

    /// A self-model of Table I (run by [`run_self_model`]), written into `default_dir`.
    pub const fn self_model(
        name: &'static str,
        about: &'static str,
        default_dir: &'static str,
        run: fn(&RunOptions, &Path) -> Result<String>,
    ) -> Self {
        Experiment {
            name,
            about,
            default_dir,
            presets: SELF_MODEL_PRESETS,
            in_table1: true,
            takes_robot: true,
            shares_output: false,
            run,
        }
    }
}

/// One self-model on its preset run ([`Studied::preset_run`]) through the harness.
pub fn run_self_model<M: Studied>(opts: &RunOptions, dir: &Path) -> Result<String> {
    let cfg = opts.apply(M::preset_run(&opts.preset)?)?;
    let out = run_studied(&cfg, dir, opts.device, opts.resume)?;
    Ok(summary(std::slice::from_ref(&out.result)))
}

/// One line per row: the model, its PSNR, IoU and speed.
pub fn summary(rows: &[ModelResult]) -> String {
    let width = rows.iter().map(|r| r.model.len()).max().unwrap_or(5).max(5);
    let num = |v: Option<f64>, decimals: usize| match v {
        Some(v) if v.is_finite() => format!("{v:.decimals$}"),
        _ => "-".into(),
    };
    // The paper's columns only where some row has the paper's figures (the papers' arm).
    let paper = rows
        .iter()
        .any(|r| r.paper_psnr_db.is_some() || r.paper_fps.is_some());
    let mut out = format!(
        "{:width$}  {:>8}  {:>6}  {:>9}",
        "model", "PSNR dB", "IoU", "img/s"
    );
    if paper {
        out += &format!("  {:>11}  {:>10}", "paper PSNR", "paper FPS*");
    }
    for r in rows {
        out += &format!(
            "\n{:width$}  {:>8}  {:>6}  {:>9}",
            r.model,
            num(Some(r.psnr_db_test), 2),
            num(Some(r.iou_test), 3),
            num(
                Some(r.infer_b1_img_per_s),
                if r.infer_b1_img_per_s < 10.0 { 1 } else { 0 },
            ),
        );
        if paper {
            out += &format!(
                "  {:>11}  {:>10}",
                num(r.paper_psnr_db, 2),
                num(r.paper_fps, 1)
            );
        }
    }
    out + if paper {
        "\n(PSNR and IoU on the test set; img/s: inference at batch 1 on this machine; *the paper's FPS was training throughput on a T4)"
    } else {
        "\n(PSNR and IoU on the test set; img/s: inference at batch 1 on this machine)"
    }
}
