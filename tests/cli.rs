//! The binaries at the edge: --help, one-line errors with a non-zero exit, no partial files.

mod common;

use std::path::Path;
use std::process::{Command, Output};

const BINARIES: &[&str] = &[
    env!("CARGO_BIN_EXE_dataset"),
    env!("CARGO_BIN_EXE_mesh_fidelity"),
    env!("CARGO_BIN_EXE_reproduce"),
    env!("CARGO_BIN_EXE_fit_arm4_geometry"),
    env!("CARGO_BIN_EXE_emssl_table2"),
    env!("CARGO_BIN_EXE_emssl_learning_curve"),
    env!("CARGO_BIN_EXE_emssl_study"),
];

fn dataset(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dataset"))
        .args(args)
        .output()
        .unwrap()
}

/// The run failed with exactly one line on stderr that contains every needle, and left no file.
fn assert_clean_failure(out: &Output, needles: &[&str], dir: &Path) {
    assert!(!out.status.success(), "expected failure");
    let err = String::from_utf8_lossy(&out.stderr);
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "expected one line, got: {err}");
    assert!(lines[0].starts_with("error: "), "{err}");
    for n in needles {
        assert!(lines[0].contains(n), "expected \"{n}\" in: {err}");
    }
    let left: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert!(
        left.iter().all(|n| n.to_string_lossy().ends_with(".csv")),
        "files left behind: {left:?}"
    );
}

#[test]
fn every_binary_has_help() {
    for bin in BINARIES {
        let out = Command::new(bin).arg("--help").output().unwrap();
        assert!(out.status.success(), "{bin} --help failed");
        assert!(String::from_utf8_lossy(&out.stdout).contains("Usage:"));
    }
}

#[test]
fn dataset_quick_writes_all_files() {
    let dir = common::tempdir();
    let npz = dir.path().join("q.npz");
    let out = dataset(&["--preset", "quick", "--out", npz.to_str().unwrap()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for f in ["q.npz", "q.stats.json", "q.config.json", "q.preview.png"] {
        assert!(dir.path().join(f).is_file(), "{f} missing");
    }
    assert!(String::from_utf8_lossy(&out.stdout).contains("40 samples (32 train, 8 test)"));
}

#[test]
fn bad_inputs_fail_cleanly() {
    let dir = common::tempdir();
    let d = dir.path();
    let npz = d.join("out.npz");
    let out_arg = npz.to_str().unwrap();

    let bad = d.join("bad.csv");
    std::fs::write(&bad, "10,20,30,40\n10,inf,30,40\n").unwrap();
    let out = dataset(&["--angles", bad.to_str().unwrap(), "--out", out_arg]);
    assert_clean_failure(&out, &["bad.csv", "row 2", "NaN or infinite"], d);

    let out = dataset(&["--samples", "0", "--out", out_arg]);
    assert_clean_failure(&out, &["at least 1 sample"], d);

    let out = dataset(&["--samples", "100", "--train", "200", "--out", out_arg]);
    assert_clean_failure(&out, &["impossible split"], d);

    let out = dataset(&[
        "--urdf",
        d.join("nope.urdf").to_str().unwrap(),
        "--out",
        out_arg,
    ]);
    assert_clean_failure(&out, &["nope.urdf", "No such file"], d);

    let out = dataset(&["--preset", "huge", "--out", out_arg]);
    assert_clean_failure(&out, &["unknown preset \"huge\""], d);
}

#[test]
fn switches_that_do_not_apply_fail_cleanly() {
    let dir = common::tempdir();
    let d = dir.path();
    let out_dir = d.join("out");
    let run = |bin: &str, args: &[&str]| {
        Command::new(bin)
            .args(args)
            .args(["--out", out_dir.to_str().unwrap()])
            .output()
            .unwrap()
    };
    let out = run(env!("CARGO_BIN_EXE_emssl_table2"), &["--steps", "5"]);
    assert_clean_failure(&out, &["--steps", "emssl_table2"], d);
    let out = run(env!("CARGO_BIN_EXE_emssl_learning_curve"), &["--resume"]);
    assert_clean_failure(&out, &["--resume", "emssl_learning_curve"], d);
    let out = run(env!("CARGO_BIN_EXE_k3dgs"), &["--robot", "ur5"]);
    assert_clean_failure(&out, &["--robot", "not k3dgs"], d);
    let out = run(
        env!("CARGO_BIN_EXE_emssl_table2"),
        &["--urdf", d.join("nope.urdf").to_str().unwrap()],
    );
    assert_clean_failure(&out, &["nope.urdf"], d);
    let out = run(
        env!("CARGO_BIN_EXE_emssl_adaptation"),
        &["--latency", "spin:50"],
    );
    assert_clean_failure(&out, &["--latency", "emssl_adaptation"], d);
    // A malformed value is clap's error: it names the value and what a latency looks like.
    let out = run(
        env!("CARGO_BIN_EXE_emssl_sampling_speed"),
        &["--latency", "spin:x"],
    );
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("spin:x"));
}

#[test]
fn render_recorded_poses_from_csv() {
    let dir = common::tempdir();
    let csv = dir.path().join("poses.csv");
    std::fs::write(&csv, "j0,j1,j2,j3\n0,0,0,0\n30,-20,45,10\n-60,10,-30,80\n").unwrap();
    let npz = dir.path().join("poses.npz");
    let out = dataset(&[
        "--angles",
        csv.to_str().unwrap(),
        "--out",
        npz.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let d = selfmodel::data::dataset::Dataset::load(&npz).unwrap();
    assert_eq!(d.angles[1], vec![30.0, -20.0, 45.0, 10.0]);
    assert_ne!(d.image(0), d.image(1));
}
