//! The units of a run: one method in one range, kept with its settings so `--resume` reuses
//! it and claimed so parallel processes share the work; a range's run over its units.

use std::path::{Path, PathBuf};

use burn::module::Module;
use nalgebra::Point3;

use selfmodel::core::atomic_file::write_json;
use selfmodel::core::device::DeviceChoice;
use selfmodel::core::error::{Error, Result};
use selfmodel::ik::data::{DistanceErrors, IkData, IkDataConfig, distances};
use selfmodel::ik::flow::{Draws, FlowIk, sample};
use selfmodel::ik::paper::emssl::EmsslIteration;
use selfmodel::ik::paper::method::{
    Answers, IkMethod, IkTask, MethodOutput, ValidationRow, file_name, timed,
};
use selfmodel::ik::solve::damped_least_squares::{IkSolution, solve_with_restarts, solver_detail};
use selfmodel::sim::robot::Robot;

use super::{
    config::IkComparisonConfig,
    predictions::{read_predictions, write_predictions},
    report::{IkRow, paper_reference, set_ratios},
};

/// What one method (a unit of the run) produced in one range, kept for `--resume`.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub(super) struct Unit {
    /// The settings it ran with: reused only if they are unchanged.
    settings: serde_json::Value,
    rows: Vec<IkRow>,
    curves: Vec<ValidationRow>,
    emssl_curve: Vec<EmsslIteration>,
}

/// An EMSSL iteration with the revision of the run that trained it (a reused unit's, not
/// this process's).
pub type RevisedIteration = (EmsslIteration, String);

impl Unit {
    /// Its EMSSL curve, each iteration stamped with the revision its rows carry.
    fn revised_curve(&self) -> Vec<RevisedIteration> {
        let revision = self
            .rows
            .first()
            .map_or_else(selfmodel::core::provenance::git_revision, |r| {
                r.git_revision.clone()
            });
        let stamp = |c: &EmsslIteration| (c.clone(), revision.clone());
        self.emssl_curve.iter().map(stamp).collect()
    }

    /// Append its rows, validation curves and (revised) EMSSL curve to a run's.
    fn append_to(
        self,
        rows: &mut Vec<IkRow>,
        curves: &mut Vec<ValidationRow>,
        emssl_curve: &mut Vec<RevisedIteration>,
    ) {
        emssl_curve.extend(self.revised_curve());
        rows.extend(self.rows);
        curves.extend(self.curves);
    }
}

/// One range's run: the data, the folders and the rows so far. Table II's mechanism (a unit
/// per method, reused by `--resume`, a partial report after each); other studies
/// (`emssl_seeds`) drive it with methods of their own through [`RangeRun::start`] and
/// [`RangeRun::method`].
pub struct RangeRun<'a> {
    cfg: &'a IkComparisonConfig,
    robot: &'a Robot,
    range_deg: f64,
    data: IkData,
    device: burn::tensor::Device,
    device_choice: DeviceChoice,
    dir: PathBuf,
    resume: bool,
    rows: Vec<IkRow>,
    curves: Vec<ValidationRow>,
    emssl_curve: Vec<RevisedIteration>,
    /// Units left to another process running the same command (their rows are not here):
    /// where their rows go among `rows`, their JSON and settings, for the partial report.
    left: Vec<(usize, PathBuf, serde_json::Value)>,
    /// Units whose rows are in `rows` (run here or reused).
    done: usize,
    /// Whether this process has run a unit: until then the report on disk is not rewritten
    /// (a reused unit changes nothing, and a damaged checkpoint met later must not leave a
    /// complete report rewritten as a partial one).
    ran: bool,
    /// Called with this range's rows and curves after every unit it runs (the partial report).
    progress: &'a dyn Fn(&[IkRow], &[ValidationRow]) -> Result<()>,
}

/// What every range of a run shares: the config, the robot, the folder, the device and
/// whether finished units are reused (`--resume`).
#[derive(Clone, Copy)]
pub struct RunScope<'a> {
    pub cfg: &'a IkComparisonConfig,
    pub robot: &'a Robot,
    pub dir: &'a Path,
    pub device: DeviceChoice,
    pub resume: bool,
}

impl<'a> RangeRun<'a> {
    /// The data of `range_deg` (Table II's test set for the config's data seed) and the
    /// folders under the scope's folder; no unit run yet.
    pub fn start(
        scope: RunScope<'a>,
        range_deg: f64,
        progress: &'a dyn Fn(&[IkRow], &[ValidationRow]) -> Result<()>,
    ) -> Result<Self> {
        let RunScope {
            cfg,
            robot,
            dir,
            device: device_choice,
            resume,
        } = scope;
        Ok(RangeRun {
            cfg,
            robot,
            range_deg,
            data: IkData::generate(&robot.chain, &cfg.data(range_deg))?,
            device: selfmodel::core::device::select(device_choice)?,
            device_choice,
            dir: dir.to_path_buf(),
            resume,
            rows: Vec::new(),
            curves: Vec::new(),
            emssl_curve: Vec::new(),
            left: Vec::new(),
            done: 0,
            ran: false,
            progress,
        })
    }

    /// The rows of the units run or reused so far, in order.
    pub fn rows(&self) -> &[IkRow] {
        &self.rows
    }

    /// [`RangeRun::rows`] with those of the units left to another process that has finished
    /// them since, each in its place.
    pub fn rows_with_others(&self) -> Vec<IkRow> {
        self.merged().0
    }

    /// The EMSSL iterations of the units so far (with the revision that trained them).
    pub fn emssl_curve(&self) -> &[RevisedIteration] {
        &self.emssl_curve
    }

    pub fn data(&self) -> &IkData {
        &self.data
    }

    /// The validation curves of the units so far.
    pub fn curves(&self) -> &[ValidationRow] {
        &self.curves
    }

    fn targets(&self) -> &[Point3<f64>] {
        &self.data.positions[self.data.test()]
    }

    fn predictions_dir(&self) -> PathBuf {
        self.dir.join(format!("predictions_{:.0}", self.range_deg))
    }

    fn predictions_path(&self, method: &str) -> PathBuf {
        self.predictions_dir()
            .join(format!("{}.csv", file_name(method)))
    }

    /// Where this range's units and the files of its methods are kept.
    fn files(&self) -> PathBuf {
        self.dir
            .join("units")
            .join(format!("{:.0}", self.range_deg))
    }

    fn unit_path(&self, unit: &str) -> PathBuf {
        self.files().join(format!("{}.json", file_name(unit)))
    }

    /// What a method works with in this range.
    fn task<'t>(&'t self, files: &'t Path, predictions: &'t Path) -> IkTask<'t> {
        IkTask {
            chain: &self.robot.chain,
            data: &self.data,
            targets: self.targets(),
            device: &self.device,
            batch: self.cfg.fit.inference_batch,
            range_deg: self.range_deg,
            files,
            predictions,
        }
    }

    /// Run one method as a unit (reused where it is done with the same settings).
    pub fn method(&mut self, method: &dyn IkMethod) -> Result<()> {
        let (files, predictions) = (self.files(), self.predictions_dir());
        let required = method.required(&self.task(&files, &predictions));
        self.unit(&method.name(), &method.settings(), &required, |r| {
            method.run(&r.task(&files, &predictions))
        })
    }

    /// Run `unit` unless `--resume` finds it done with the same `settings` and the files in
    /// `required` (what later units read) present: `body` returns its answers (each written
    /// as predictions and made a row), curves and EMSSL curve. A reused unit's rows come from
    /// its JSON (committed); its full predictions are there only where it ran in this checkout.
    fn unit<S: serde::Serialize>(
        &mut self,
        unit: &str,
        settings: &S,
        required: &[PathBuf],
        body: impl FnOnce(&Self) -> Result<MethodOutput>,
    ) -> Result<()> {
        let settings = serde_json::to_value((settings, &self.data_settings()))
            .map_err(|e| Error::Config(format!("settings of {unit}: {e}")))?;
        let path = self.unit_path(unit);
        if self.resume
            && let Some(old) = std::fs::read_to_string(&path)
                .ok()
                .and_then(|t| serde_json::from_str::<Unit>(&t).ok())
                .filter(|u| u.settings != settings)
        {
            eprintln!(
                "emssl_table2: +-{:.0} deg {unit}: {} was made with other settings ({}); running it again",
                self.range_deg,
                path.display(),
                selfmodel::core::json_diff::differences(&old.settings, &settings).join("; ")
            );
        }
        if self.resume
            && let Some(done) = std::fs::read_to_string(&path)
                .ok()
                .and_then(|t| serde_json::from_str::<Unit>(&t).ok())
                .filter(|u| u.settings == settings)
            && required.iter().all(|p| p.exists())
        {
            eprintln!(
                "emssl_table2: +-{:.0} deg {unit}: reused from {}",
                self.range_deg,
                path.display()
            );
            done.append_to(&mut self.rows, &mut self.curves, &mut self.emssl_curve);
            self.done += 1;
            return self.report_progress();
        }
        // Another process running the same command may hold this unit: leave it to it.
        let _claim = match selfmodel::core::atomic_file::Claim::take(&path.with_extension("claim"))?
        {
            selfmodel::core::atomic_file::Claimed::Mine(c) => c,
            selfmodel::core::atomic_file::Claimed::Other(pid) => {
                eprintln!(
                    "emssl_table2: +-{:.0} deg {unit}: left to process {pid}, which runs it",
                    self.range_deg
                );
                self.left.push((self.rows.len(), path.clone(), settings));
                return self.report_progress();
            }
        };
        eprintln!("emssl_table2: +-{:.0} deg {unit}", self.range_deg);
        let MethodOutput {
            answers,
            curves,
            emssl_curve,
        } = body(self)?;
        let mut rows = Vec::new();
        for a in answers {
            rows.push(self.row(a)?);
        }
        let done = Unit {
            settings,
            rows,
            curves,
            emssl_curve,
        };
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
        }
        write_json(&path, &done)?;
        done.append_to(&mut self.rows, &mut self.curves, &mut self.emssl_curve);
        self.done += 1;
        self.ran = true;
        self.report_progress()
    }

    /// This process's rows, curves and EMSSL curve, with those of the units left to other
    /// processes that have finished since (read from their JSON), each in its place, and the
    /// number of units they come from.
    fn merged(&self) -> (Vec<IkRow>, Vec<ValidationRow>, Vec<RevisedIteration>, usize) {
        let mut done_units = self.done;
        let mut rows = Vec::new();
        let mut curves = self.curves.clone();
        let mut emssl_curve = self.emssl_curve.clone();
        let mut next = 0;
        for (at, path, settings) in &self.left {
            rows.extend_from_slice(&self.rows[next..*at]);
            next = *at;
            if let Some(done) = std::fs::read_to_string(path)
                .ok()
                .and_then(|t| serde_json::from_str::<Unit>(&t).ok())
                .filter(|u| &u.settings == settings)
            {
                done.append_to(&mut rows, &mut curves, &mut emssl_curve);
                done_units += 1;
            }
        }
        rows.extend_from_slice(&self.rows[next..]);
        (rows, curves, emssl_curve, done_units)
    }

    /// The partial report after a unit, once this process has run one.
    fn report_progress(&self) -> Result<()> {
        if !self.ran {
            return Ok(());
        }
        let (rows, curves, _, _) = self.merged();
        (self.progress)(&rows, &curves)
    }

    fn data_settings(&self) -> (IkDataConfig, &Vec<usize>) {
        (self.cfg.data(self.range_deg), &self.cfg.hidden)
    }

    /// Write a method's answers (all, and the committed sample) and make its row.
    fn row(&self, a: Answers) -> Result<IkRow> {
        let targets = self.targets();
        let reached = self.robot.chain.end_effector_batch(&a.joints);
        let path = self.predictions_path(&a.method);
        let names = self.robot.chain.joint_names();
        write_predictions(&path, targets, &a.joints, &reached, &names)?;
        let k = self.cfg.prediction_sample_rows.min(targets.len());
        if k > 0 {
            write_predictions(
                &self
                    .dir
                    .join("predictions_sample")
                    .join(format!("{:.0}", self.range_deg))
                    .join(format!("{}.csv", file_name(&a.method))),
                &targets[..k],
                &a.joints[..k],
                &reached[..k],
                &names,
            )?;
        }
        let d = distances(targets, &reached);
        let within = d.iter().filter(|&&e| e < 1e-5).count();
        let e = DistanceErrors::from_metres(&d);
        let base = a.method.split(" (").next().unwrap_or(&a.method);
        // The paper's figures are for its (UR5-like) arm: beside the built-in UR5's rows only.
        let paper = if a.method.contains("best of")
            || a.method.contains("wrapped")
            || self.robot.label != selfmodel::sim::robots::BuiltinRobot::Ur5.name()
        {
            None
        } else {
            paper_reference(base, self.range_deg)
        };
        Ok(IkRow {
            robot: self.robot.label.to_string(),
            range_deg: self.range_deg,
            method: a.method.clone(),
            mean_cm: e.mean_cm,
            median_cm: e.median_cm,
            p95_cm: e.p95_cm,
            max_cm: e.max_cm,
            above_10cm_pct: Some(e.above_10cm_pct),
            targets: e.targets,
            ratio_to_drl: None,
            within_0_01mm_pct: 100.0 * within as f64 / targets.len().max(1) as f64,
            outside_limits: Some(self.data.outside_limits(&a.joints)),
            diversity_rad: a.diversity_rad,
            solutions_per_s: targets.len() as f64 / a.solve_seconds.max(1e-12),
            train_seconds: a.train_seconds,
            epochs: a.epochs,
            validation_cm: a.validation_cm,
            detail: a.detail,
            paper_mean_cm: paper,
            paper_ratio_to_drl: paper
                .zip(paper_reference("DRL", self.range_deg))
                .map(|(m, d)| m / d),
            git_revision: selfmodel::core::provenance::git_revision(),
            device: self.device_choice.to_string(),
            preset: self.cfg.preset.clone(),
        })
    }
}

/// What one range's run produced.
pub struct RangeOutcome {
    pub rows: Vec<IkRow>,
    pub curves: Vec<ValidationRow>,
    pub emssl_curve: Vec<RevisedIteration>,
    /// Units done (their rows are in `rows`) of the range's units; fewer where some were
    /// left to another process (the report then stays partial).
    pub units_done: usize,
    pub units: usize,
}

/// Run every method in one joint range (reusing finished units when `resume`).
pub fn run_range(
    scope: RunScope,
    range_deg: f64,
    progress: &dyn Fn(&[IkRow], &[ValidationRow]) -> Result<()>,
) -> Result<RangeOutcome> {
    let mut run = RangeRun::start(scope, range_deg, progress)?;
    let RunScope { cfg, robot, .. } = scope;
    let chain = &robot.chain;
    let dof = robot.dof();
    let batch = cfg.fit.inference_batch;
    let methods = cfg.methods(range_deg, dof);
    // Every method's unit and the refinement's.
    let units = methods.len() + 1;
    for method in methods {
        run.method(method.as_ref())?;
    }
    let flow_cfg = cfg.flow_method().cfg;
    let ranges = run.data.ranges.clone();

    // EMSSL's answers refined by the solver; where it stalls, restarts from the flow's samples
    // (closest first), then from random joints. The EMSSL variant with the lower validation
    // error is refined; its training and inference count towards the refined answers.
    if !run.left.is_empty() {
        // What this unit starts from is still being made elsewhere.
        eprintln!(
            "emssl_table2: +-{range_deg:.0} deg EMSSL + DLS: left for when the units run \
             elsewhere are done (run the command again with --resume)"
        );
        let (mut rows, curves, emssl_curve, units_done) = run.merged();
        set_ratios(&mut rows);
        return Ok(RangeOutcome {
            rows,
            curves,
            emssl_curve,
            units_done,
            units,
        });
    }
    let emssl_rows: Vec<&IkRow> = run
        .rows
        .iter()
        .filter(|r| r.method.starts_with("EMSSL"))
        .collect();
    let start_row = emssl_rows
        .iter()
        .min_by(|a, b| {
            a.validation_cm
                .unwrap_or(a.mean_cm)
                .total_cmp(&b.validation_cm.unwrap_or(b.mean_cm))
        })
        .copied()
        .cloned()
        .ok_or_else(|| Error::Training("no EMSSL row to refine".into()))?;
    let settings = (&cfg.refine, &cfg.restarts, &start_row.method, &flow_cfg);
    let flow_file = run.files().join("flow_model.bpk");
    run.unit("EMSSL + DLS", &settings, &[], |r| {
        let starts = read_predictions(&r.predictions_path(&start_row.method))?;
        let flow = FlowIk::new(&flow_cfg, dof, &r.device, flow_cfg.fit.seed)?
            .try_load_file(&flow_file)
            .map_err(|e| {
                Error::data(
                    &flow_file,
                    format!("the trained flow cannot be read ({e}); delete it and run again with --resume (the flow's unit then trains it again)"),
                )
            })?;
        let targets = r.targets();
        let mut out: Vec<IkSolution> = Vec::new();
        let mut restarted = 0;
        let s = timed(&mut || {
            let (sol, n) = solve_with_restarts(
                chain,
                targets,
                &starts,
                &ranges,
                &cfg.refine,
                &cfg.restarts,
                |idx: &[usize]| {
                    let t: Vec<Point3<f64>> = idx.iter().map(|&i| targets[i]).collect();
                    sample(&flow, &r.data, &t, Draws { k: cfg.restarts.flow_samples, batch, seed: cfg.restarts.seed }, &r.device)
                },
            );
            out = sol;
            restarted = n;
        });
        let emssl_solve_s = r.targets().len() as f64 / start_row.solutions_per_s;
        let mut a = Answers::new(
            "EMSSL + DLS",
            Vec::new(),
            start_row.train_seconds,
            s + emssl_solve_s,
        );
        a.detail = format!(
            "from {}'s answers; {}",
            start_row.method,
            solver_detail(&out, &cfg.refine, Some(restarted))
        );
        a.joints = out.into_iter().map(|x| x.joints).collect();
        Ok(MethodOutput {
            answers: vec![a],
            ..Default::default()
        })
    })?;

    set_ratios(&mut run.rows);
    Ok(RangeOutcome {
        units_done: run.done,
        units,
        rows: run.rows,
        curves: run.curves,
        emssl_curve: run.emssl_curve,
    })
}
