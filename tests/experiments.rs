//! Smoke tests generated from the registry: one test per experiment, each on its `quick`
//! preset into one shared folder as `reproduce` runs them, so a failure names its experiment
//! and hides none after it. Then the checks of how `table1` gathers their rows. A new
//! registry entry is tested with no edit here. Run one: `cargo test --release --test
//! experiments -- quick/neurokin`.

mod common;

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use libtest_mimic::{Arguments, Failed, Trial};
use selfmodel::core::preset::Preset;
use selfmodel_lab::studies::registry::{EXPERIMENTS, Experiment, RunOptions, find};

/// The folder every trial shares (made by `main`, removed when the trials end).
static ROOT: OnceLock<PathBuf> = OnceLock::new();

fn root() -> &'static Path {
    ROOT.get().expect("main sets the root")
}

fn quick() -> RunOptions {
    let mut opts = RunOptions::preset("quick");
    opts.reuse_root = Some(root().to_path_buf());
    opts
}

/// Run `e` on its quick preset into the shared root, unless a filtered run already did.
fn run_quick(e: &Experiment) -> Result<String, Failed> {
    let dir = root().join(e.default_dir);
    let summary = (e.run)(&quick(), &dir).map_err(|err| format!("{} failed: {err}", e.name))?;
    if summary.is_empty() {
        return Err(format!("{} gave an empty summary", e.name).into());
    }
    if std::fs::read_dir(&dir).map_or(0, |d| d.count()) == 0 {
        return Err(format!("{} wrote nothing", e.name).into());
    }
    Ok(summary)
}

fn smoke(e: &'static Experiment) -> Trial {
    Trial::test(format!("quick/{}", e.name), move || {
        if e.name == "mesh_fidelity" && !selfmodel::sim::robots::shared_arm_urdf().exists() {
            eprintln!("skipped mesh_fidelity: the shared meshes are not beside the repository");
            return Ok(());
        }
        run_quick(e).map(|_| ())
    })
}

/// The in-Table-I experiments' results, run first where a filtered run skipped them.
fn table1_inputs() -> Result<usize, Failed> {
    let mut rows = 0;
    for e in EXPERIMENTS.iter().filter(|e| e.in_table1) {
        let csv = root().join(e.default_dir).join("results.csv");
        if !csv.is_file() {
            run_quick(e)?;
        }
        rows += selfmodel::self_models::result::read_results(&csv)
            .map_err(|err| err.to_string())?
            .len();
    }
    Ok(rows)
}

fn table1_reuses_every_row() -> Result<(), Failed> {
    let expected = table1_inputs()?;
    let table1 = root().join("reports/table1_reuse");
    (find("table1").unwrap().run)(&quick(), &table1).map_err(|e| e.to_string())?;
    let rows = selfmodel::self_models::result::read_results(&table1.join("results.csv"))
        .map_err(|e| e.to_string())?;
    if rows.len() != expected {
        return Err(format!("table1 has {} rows, the experiments {expected}", rows.len()).into());
    }
    for e in EXPERIMENTS.iter().filter(|e| e.in_table1) {
        if table1.join(e.name).exists() {
            return Err(format!("table1 trained {} again", e.name).into());
        }
    }
    Ok(())
}

/// A shortened run (`--steps`) is never taken for the preset's: table1 trains that model.
fn table1_retrains_a_shortened_run() -> Result<(), Failed> {
    table1_inputs()?;
    let neurokin = find("neurokin").unwrap();
    let mut short = RunOptions::preset("quick");
    short.steps = Some(3);
    let dir = root().join("shortened").join(neurokin.default_dir);
    (neurokin.run)(&short, &dir).map_err(|e| e.to_string())?;
    let mut opts = quick();
    // A root whose neurokin rows are the 3-step run's, the rest as before.
    let alt = root().join("shortened");
    for e in EXPERIMENTS
        .iter()
        .filter(|e| e.in_table1 && e.name != "neurokin")
    {
        copy_dir(&root().join(e.default_dir), &alt.join(e.default_dir));
    }
    opts.reuse_root = Some(alt.clone());
    let table1 = alt.join("reports/table1");
    (find("table1").unwrap().run)(&opts, &table1).map_err(|e| e.to_string())?;
    if !table1.join("neurokin").join("results.csv").is_file() {
        return Err("table1 took a 3-step run for the quick preset's".into());
    }
    Ok(())
}

/// An experiment of several models still running (no combined results.csv yet): table1
/// gathers the rows of the models it has finished instead of training it.
fn table1_takes_the_finished_models_of_a_running_experiment() -> Result<(), Failed> {
    table1_inputs()?;
    let alt = root().join("partial");
    for e in EXPERIMENTS.iter().filter(|e| e.in_table1) {
        copy_dir(&root().join(e.default_dir), &alt.join(e.default_dir));
    }
    let ffksm = alt.join("reports/ffksm");
    std::fs::remove_file(ffksm.join("results.csv")).unwrap();
    std::fs::remove_dir_all(ffksm.join("ffksm_original")).unwrap();
    let mut opts = quick();
    opts.reuse_root = Some(alt.clone());
    let table1 = alt.join("reports/table1");
    (find("table1").unwrap().run)(&opts, &table1).map_err(|e| e.to_string())?;
    if table1.join("ffksm").exists() {
        return Err("table1 trained ffksm again".into());
    }
    let rows = selfmodel::self_models::result::read_results(&table1.join("results.csv"))
        .map_err(|e| e.to_string())?;
    let ffksm_rows: Vec<&str> = rows
        .iter()
        .filter(|r| r.model.starts_with("FFKSM"))
        .map(|r| r.model.as_str())
        .collect();
    if ffksm_rows.len() != 4 || ffksm_rows.iter().any(|m| m.contains("original")) {
        return Err(format!("FFKSM rows: {ffksm_rows:?}").into());
    }
    Ok(())
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), target).unwrap();
        }
    }
}

fn arm4_matches_the_mesh_robot_closely() -> Result<(), Failed> {
    if !selfmodel::sim::robots::shared_arm_urdf().exists() {
        eprintln!("skipped: the shared meshes are not beside the repository");
        return Ok(());
    }
    let dir = common::tempdir();
    let rows = selfmodel_lab::studies::mesh_fidelity::run(
        &selfmodel_lab::studies::mesh_fidelity::FidelityConfig::quick(),
        dir.path(),
    )
    .map_err(|e| e.to_string())?;
    if rows[0].mean_iou <= 0.97 {
        return Err(format!("arm4 vs mesh IoU {}", rows[0].mean_iou).into());
    }
    let csv = std::fs::read_to_string(dir.path().join("results.csv")).unwrap();
    if !csv.starts_with("ours,reference,poses,mean_iou") || !dir.path().join("results.md").is_file()
    {
        return Err("mesh_fidelity's results are not as expected".into());
    }
    Ok(())
}

/// The robots every self-model must take on its quick preset: a 2-joint and a 7-joint URDF
/// (asymmetric limits; the 7-joint one with a gripper held off the chain to its tip `hand`,
/// a fixed joint with a zero axis and a mimic finger) and the built-in UR5.
fn robot_options(robot: &str) -> RunOptions {
    let mut opts = RunOptions::preset("quick");
    match robot {
        "urdf_2_joints" => {
            opts.urdf = Some(common::write_arm(root(), robot, 2, false));
        }
        "urdf_7_joints" => {
            opts.urdf = Some(common::write_arm(root(), robot, 7, true));
            opts.tip = Some("hand".into());
        }
        _ => opts.robot = Some(selfmodel::sim::robots::BuiltinRobot::Ur5),
    }
    opts
}

/// Every self-model (the entries of Table I, and body_from_image) on each robot's quick preset.
fn robot_smoke(e: &'static Experiment, robot: &'static str) -> Trial {
    Trial::test(format!("robots/{robot}/{}", e.name), move || {
        let opts = robot_options(robot);
        let dir = root().join("robots").join(robot).join(e.name);
        let summary =
            (e.run)(&opts, &dir).map_err(|err| format!("{} on {robot}: {err}", e.name))?;
        let rows = selfmodel::self_models::result::read_results(&dir.join("results.csv"));
        if e.in_table1 {
            let rows = rows.map_err(|err| err.to_string())?;
            if rows.is_empty() || rows.iter().any(|r| r.paper_psnr_db.is_some()) {
                return Err(format!(
                    "{}: rows {} with the paper's figures on {robot}",
                    e.name,
                    rows.len()
                )
                .into());
            }
        }
        if summary.contains("paper PSNR") {
            return Err(format!("{}: the paper's column printed for {robot}", e.name).into());
        }
        Ok(())
    })
}

fn main() {
    let mut args = Arguments::from_args();
    let dir = common::tempdir();
    ROOT.set(dir.path().to_path_buf()).unwrap();
    // Training seeds the device's global RNG, and table1 reuses what ran before it: one at a
    // time, in the registry's order.
    args.test_threads = Some(1);
    let mut trials: Vec<Trial> = EXPERIMENTS.iter().map(smoke).collect();
    for robot in ["urdf_2_joints", "urdf_7_joints", "ur5"] {
        for e in EXPERIMENTS
            .iter()
            .filter(|e| e.in_table1 || e.name == "body_from_image")
        {
            trials.push(robot_smoke(e, robot));
        }
    }
    trials.push(Trial::test(
        "table1/reuses_every_row",
        table1_reuses_every_row,
    ));
    trials.push(Trial::test(
        "table1/retrains_a_shortened_run",
        table1_retrains_a_shortened_run,
    ));
    trials.push(Trial::test(
        "table1/takes_the_finished_models_of_a_running_experiment",
        table1_takes_the_finished_models_of_a_running_experiment,
    ));
    trials.push(Trial::test(
        "arm4_matches_the_mesh_robot_closely",
        arm4_matches_the_mesh_robot_closely,
    ));
    let conclusion = libtest_mimic::run(&args, trials);
    drop(dir);
    conclusion.exit();
}
