//! Smoke test driven by the registry: every experiment runs on its quick preset, as
//! `reproduce` runs them (table1 gathers the rows the decoders have just written).

mod common;

use selfmodel::core::preset::Preset;
use selfmodel::studies::registry::EXPERIMENTS;

#[test]
fn every_experiment_runs_on_its_quick_preset() {
    let root = common::tempdir();
    for e in EXPERIMENTS {
        if e.name == "mesh_fidelity" && !selfmodel::cli::shared_arm_urdf().exists() {
            eprintln!("skipped mesh_fidelity: the shared meshes are not beside the repository");
            continue;
        }
        let dir = root.path().join(e.default_dir);
        let mut opts = selfmodel::studies::registry::RunOptions::preset("quick");
        opts.reuse_root = Some(root.path().to_path_buf());
        let summary = (e.run)(&opts, &dir).unwrap_or_else(|err| panic!("{} failed: {err}", e.name));
        assert!(!summary.is_empty());
        assert!(
            std::fs::read_dir(&dir).unwrap().count() > 0,
            "{} wrote nothing",
            e.name
        );
    }
    // table1 reused every in-table1 experiment's rows instead of training them again.
    let table1 = root.path().join("reports/table1");
    let rows = selfmodel::self_models::result::read_results(&table1.join("results.csv")).unwrap();
    let expected: usize = EXPERIMENTS
        .iter()
        .filter(|e| e.in_table1)
        .map(|e| {
            let csv = root.path().join(e.default_dir).join("results.csv");
            selfmodel::self_models::result::read_results(&csv)
                .unwrap()
                .len()
        })
        .sum();
    assert_eq!(rows.len(), expected);
    for e in EXPERIMENTS.iter().filter(|e| e.in_table1) {
        assert!(
            !table1.join(e.name).exists(),
            "table1 trained {} again",
            e.name
        );
    }

    // A shortened run (`--steps`) is never taken for the preset's: table1 trains that model.
    let neurokin = selfmodel::studies::registry::find("neurokin").unwrap();
    let mut short = selfmodel::studies::registry::RunOptions::preset("quick");
    short.steps = Some(3);
    (neurokin.run)(&short, &root.path().join(neurokin.default_dir)).unwrap();
    let table1_exp = selfmodel::studies::registry::find("table1").unwrap();
    let mut opts = selfmodel::studies::registry::RunOptions::preset("quick");
    opts.reuse_root = Some(root.path().to_path_buf());
    (table1_exp.run)(&opts, &table1).unwrap();
    assert!(
        table1.join("neurokin").join("results.csv").is_file(),
        "table1 took a 3-step run for the quick preset's"
    );

    // An experiment of several models still running (no combined results.csv yet): table1
    // gathers the rows of the models it has finished instead of training it.
    let ffksm = root.path().join("reports/ffksm");
    std::fs::remove_file(ffksm.join("results.csv")).unwrap();
    std::fs::remove_dir_all(ffksm.join("ffksm_original")).unwrap();
    let table1 = root.path().join("reports/table1_partial");
    (table1_exp.run)(&opts, &table1).unwrap();
    assert!(!table1.join("ffksm").exists(), "table1 trained ffksm again");
    let rows = selfmodel::self_models::result::read_results(&table1.join("results.csv")).unwrap();
    let ffksm_rows: Vec<&str> = rows
        .iter()
        .filter(|r| r.model.starts_with("FFKSM"))
        .map(|r| r.model.as_str())
        .collect();
    assert_eq!(ffksm_rows.len(), 4, "{ffksm_rows:?}");
    assert!(ffksm_rows.iter().all(|m| !m.contains("original")));
}

#[test]
fn arm4_matches_the_mesh_robot_closely() {
    if !selfmodel::cli::shared_arm_urdf().exists() {
        eprintln!("skipped: the shared meshes are not beside the repository");
        return;
    }
    let dir = common::tempdir();
    let rows = selfmodel::studies::mesh_fidelity::run(
        &selfmodel::studies::mesh_fidelity::FidelityConfig::quick(),
        dir.path(),
    )
    .unwrap();
    assert!(
        rows[0].mean_iou > 0.97,
        "arm4 vs mesh IoU {}",
        rows[0].mean_iou
    );
    let csv = std::fs::read_to_string(dir.path().join("results.csv")).unwrap();
    assert!(csv.starts_with("ours,reference,poses,mean_iou"));
    assert!(dir.path().join("results.md").is_file());
}
