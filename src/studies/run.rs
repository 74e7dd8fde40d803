//! What every study shares: how it is asked to run ([`RunOptions`]), what the registry knows
//! of it ([`Experiment`]) and how self-model rows are written.

use std::path::Path;

use crate::core::device::DeviceChoice;
use crate::core::error::Result;
use crate::report::table::{write_csv, write_markdown_report};
use crate::self_models::harness::{SELF_MODEL_PRESETS, SelfModel, SelfModelRun};
use crate::self_models::result::ModelResult;
use crate::sim::robots::{BuiltinRobot, RobotSpec};

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
    /// Where experiments may already have written their results (`reproduce`'s root): `table1`
    /// gathers rows found there, of the same preset, dataset and steps, instead of training
    /// the same models a second time.
    pub reuse_root: Option<std::path::PathBuf>,
    /// The robot (`--robot`, `--urdf`, `--arm4-scene`): the arm of the inverse-kinematics
    /// experiments (default ur5) or the robot a self-model learns (default arm4).
    pub robot: Option<crate::sim::robots::BuiltinRobot>,
    pub urdf: Option<std::path::PathBuf>,
    /// Place the URDF as the papers' scene places arm4 (else its root link at the origin).
    pub arm4_scene: bool,
    /// The forward model's latencies of `emssl_sampling_speed`, instead of its preset's.
    pub latencies: Option<Vec<crate::ik::sampling_pass::Latency>>,
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
            reuse_root: None,
            robot: None,
            urdf: None,
            arm4_scene: false,
            latencies: None,
        }
    }

    /// The robot the options name, `default` where they name none.
    pub fn robot_spec(&self, default: BuiltinRobot) -> RobotSpec {
        match (&self.urdf, self.robot) {
            (Some(path), _) if self.arm4_scene => RobotSpec::urdf_in_arm4_scene(path.clone()),
            (Some(path), _) => RobotSpec::Urdf {
                path: path.clone(),
                base_xyz: [0.0; 3],
                base_rpy: [0.0; 3],
            },
            (None, robot) => RobotSpec::Builtin(robot.unwrap_or(default)),
        }
    }

    /// The arm of the inverse-kinematics experiments (default ur5) and its name for reports.
    pub fn ik_robot(&self) -> Result<(crate::sim::robot::Robot, String)> {
        let spec = self.robot_spec(BuiltinRobot::Ur5);
        let robot = spec.load()?;
        if robot.dof() == 0 {
            return Err(crate::Error::Config(format!(
                "{}: this robot has no movable joints (all are fixed); inverse kinematics needs at least one",
                spec.label()
            )));
        }
        Ok((robot, spec.label()))
    }

    /// Apply the switches to a self-model run.
    pub fn apply<M: SelfModel>(&self, cfg: SelfModelRun<M>) -> SelfModelRun<M> {
        let mut cfg = cfg.paper_compatible(self.paper_compatible);
        cfg.data.robot = self.robot_spec(BuiltinRobot::Arm4);
        cfg.steps_override = self.override_steps(&mut cfg.train.steps, &mut cfg.note);
        cfg
    }

    /// `--steps N`: set `steps` and say so in `note`; returns the override, if any.
    fn override_steps(&self, steps: &mut usize, note: &mut String) -> Option<usize> {
        let new = self.steps.filter(|s| s != steps)?;
        let msg = format!("{new} steps instead of the preset's {steps}");
        *note = if note.is_empty() {
            msg
        } else {
            format!("{note}; {msg}")
        };
        *steps = new;
        Some(new)
    }
}

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
            match crate::core::atomic_file::Claim::take(&dir.join(".lock"))? {
                crate::core::atomic_file::Claimed::Mine(c) => Some(c),
                crate::core::atomic_file::Claimed::Other(pid) => {
                    return Err(crate::Error::Config(format!(
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

    /// Where a run on `preset` writes by default: `default_dir` for the paper preset,
    /// `default_dir_<preset>` for any other, so a short or quick run never overwrites the
    /// paper run's reports.
    pub fn dir_for(&self, preset: &str) -> std::path::PathBuf {
        if preset == "paper" {
            self.default_dir.into()
        } else {
            format!("{}_{preset}", self.default_dir).into()
        }
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

/// One self-model on its preset run ([`SelfModel::preset_run`]) through the harness.
pub fn run_self_model<M: SelfModel>(opts: &RunOptions, dir: &Path) -> Result<String> {
    let cfg = opts.apply(M::preset_run(&opts.preset)?);
    let out = crate::self_models::harness::run(&cfg, dir, opts.device, opts.resume)?;
    Ok(summary(std::slice::from_ref(&out.result)))
}

/// One line per row: the model, its PSNR, IoU and speed.
pub fn summary(rows: &[ModelResult]) -> String {
    let width = rows.iter().map(|r| r.model.len()).max().unwrap_or(5).max(5);
    let num = |v: Option<f64>, decimals: usize| match v {
        Some(v) if v.is_finite() => format!("{v:.decimals$}"),
        _ => "-".into(),
    };
    let mut out = format!(
        "{:width$}  {:>8}  {:>6}  {:>9}  {:>11}  {:>10}",
        "model", "PSNR dB", "IoU", "img/s", "paper PSNR", "paper FPS*"
    );
    for r in rows {
        out += &format!(
            "\n{:width$}  {:>8}  {:>6}  {:>9}  {:>11}  {:>10}",
            r.model,
            num(Some(r.psnr_db_test), 2),
            num(Some(r.iou_test), 3),
            num(
                Some(r.infer_b1_img_per_s),
                if r.infer_b1_img_per_s < 10.0 { 1 } else { 0 },
            ),
            num(r.paper_psnr_db, 2),
            num(r.paper_fps, 1),
        );
    }
    out + "\n(PSNR and IoU on the test set; img/s: inference at batch 1 on this machine; *the paper's FPS was training throughput on a T4)"
}
