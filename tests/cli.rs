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
    common::assert_ok(&out);
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
    // --train-samples sizes a self-model's data: not inverse kinematics', nor the data-scale
    // ablation's (it sets its own sizes).
    let out = run(
        env!("CARGO_BIN_EXE_emssl_table2"),
        &["--train-samples", "50"],
    );
    assert_clean_failure(&out, &["--train-samples", "emssl_table2"], d);
    let out = run(
        env!("CARGO_BIN_EXE_ablation_data_scale"),
        &["--train-samples", "50"],
    );
    assert_clean_failure(&out, &["--train-samples", "ablation_data_scale"], d);
    // Its sizes and models are its own: named, each at least 1, models it can scale.
    let out = run(env!("CARGO_BIN_EXE_neurokin"), &["--sizes", "50"]);
    assert_clean_failure(&out, &["--sizes", "neurokin"], d);
    let out = run(
        env!("CARGO_BIN_EXE_ablation_data_scale"),
        &["--sizes", "50,0"],
    );
    assert_clean_failure(&out, &["--sizes", "at least 1"], d);
    let out = run(
        env!("CARGO_BIN_EXE_ablation_data_scale"),
        &["--models", "nearest_pose"],
    );
    assert_clean_failure(&out, &["nearest_pose", "link_splat"], d);
    // mesh_fidelity compares the papers' arm with its meshes: it has no --robot.
    let out = run(env!("CARGO_BIN_EXE_mesh_fidelity"), &["--robot", "ur5"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("unexpected argument '--robot'"));
    // Inverse kinematics renders nothing: the camera options and --geometry are refused.
    let out = run(env!("CARGO_BIN_EXE_emssl_table2"), &["--eye", "1,0,0"]);
    assert_clean_failure(&out, &["--eye", "emssl_table2"], d);
    // --tip needs a URDF; a --tip that is no link lists the links.
    let out = run(env!("CARGO_BIN_EXE_neurokin"), &["--tip", "hand"]);
    assert!(!out.status.success());
    let robots = common::tempdir();
    let urdf = robots.path().join("arm.urdf");
    std::fs::write(&urdf, common::arm_urdf(2, false)).unwrap();
    let out = run(
        env!("CARGO_BIN_EXE_neurokin"),
        &["--urdf", urdf.to_str().unwrap(), "--tip", "hand"],
    );
    assert_clean_failure(&out, &["--tip \"hand\" is not a link", "l2"], d);
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
    common::assert_ok(&out);
    let d = selfmodel::data::dataset::Dataset::load(&npz).unwrap();
    assert_eq!(d.angles[1], vec![30.0, -20.0, 45.0, 10.0]);
    assert_ne!(d.image(0), d.image(1));
}

/// Run `bin` with `args`; it must fail with one `error:` line holding every needle, and leave
/// nothing at `out` (the output path it was given). `Err` says what went wrong, naming the
/// command.
fn refusal(bin: &str, args: &[&str], needles: &[&str], out: &Path) -> Result<(), String> {
    let name = Path::new(bin)
        .file_name()
        .unwrap_or_default()
        .to_string_lossy();
    let o = Command::new(bin).args(args).output().unwrap();
    if o.status.success() {
        return Err(format!("{name} {args:?} succeeded"));
    }
    let err = String::from_utf8_lossy(&o.stderr);
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    // clap's own errors add a "For more information" line.
    if !lines.first().is_some_and(|l| l.starts_with("error: ")) {
        return Err(format!("{name} {args:?}: not an error line: {err}"));
    }
    if !lines[1..]
        .iter()
        .all(|l| l.starts_with("For more information"))
    {
        return Err(format!("{name} {args:?}: more than one line: {err}"));
    }
    if let Some(n) = needles.iter().find(|n| !lines[0].contains(*n)) {
        return Err(format!("{name} {args:?}: expected \"{n}\" in: {err}"));
    }
    if out.exists() {
        return Err(format!("{name} {args:?} left {}", out.display()));
    }
    Ok(())
}

/// [`refusal`], failing the test at once.
fn fails_cleanly(bin: &str, args: &[&str], needles: &[&str], out: &Path) {
    if let Err(e) = refusal(bin, args, needles, out) {
        panic!("{e}");
    }
}

/// The inputs an adversarial user tried (issue 20): each rejected with one line, a non-zero
/// exit and nothing written.
#[test]
fn malformed_inputs_are_rejected_with_one_line_and_no_output() {
    let dir = common::tempdir();
    let d = dir.path();
    let out = d.join("out");
    let o = out.to_str().unwrap();
    let npz_out = d.join("out.npz");
    let n = npz_out.to_str().unwrap();
    let write = |name: &str, text: &str| {
        let p = d.join(name);
        std::fs::write(&p, text).unwrap();
        p.to_str().unwrap().to_string()
    };
    // Every case runs; the test fails at the end naming each command that misbehaved.
    let failed = std::cell::RefCell::new(Vec::new());
    let check = |bin: &str, args: &[&str], needles: &[&str], out: &Path| {
        if let Err(e) = refusal(bin, args, needles, out) {
            failed.borrow_mut().push(e);
        }
    };
    let bin = |name: &str| match name {
        "dataset" => env!("CARGO_BIN_EXE_dataset"),
        "fit" => env!("CARGO_BIN_EXE_fit_arm4_geometry"),
        "reproduce" => env!("CARGO_BIN_EXE_reproduce"),
        "bench" => env!("CARGO_BIN_EXE_bench_ffksm_step"),
        "speed" => env!("CARGO_BIN_EXE_emssl_sampling_speed"),
        "table2" => env!("CARGO_BIN_EXE_emssl_table2"),
        _ => unreachable!(),
    };
    // Unbounded work is refused before it starts (it aborted on allocation, or ran forever).
    check(
        bin("dataset"),
        &[
            "--preset",
            "quick",
            "--samples",
            "1000000000000",
            "--out",
            n,
        ],
        &["GiB", "--samples"],
        &npz_out,
    );
    // A grid step giving millions of points a joint, and one too coarse for the samples
    // asked (it said "1 joint vectors for 40 samples").
    for (step, needles) in [
        ("1e-9", &["grid step", "--grid-step"][..]),
        (
            "1e6",
            &["gives 1 joint vectors", "--grid-step", "--samples"][..],
        ),
    ] {
        check(
            bin("dataset"),
            &[
                "--preset",
                "quick",
                "--sampler",
                "grid",
                "--grid-step",
                step,
                "--out",
                n,
            ],
            needles,
            &npz_out,
        );
    }
    // An --out that cannot be written is refused before any work (it said "File exists"
    // after training, or "Not a directory").
    let a_file = write("a_file", "x");
    let under_file = format!("{a_file}/out.npz");
    check(
        bin("dataset"),
        &["--preset", "quick", "--out", &under_file],
        &["is a file, not a folder"],
        Path::new(&under_file),
    );
    let folder = format!("{}/", d.join("folder").display());
    check(
        bin("dataset"),
        &["--preset", "quick", "--out", &folder],
        &["is a folder", "dataset.npz"],
        &d.join("folder"),
    );
    check(
        env!("CARGO_BIN_EXE_ik"),
        &[
            "train",
            "--preset",
            "quick",
            "--out",
            &format!("{a_file}/model"),
        ],
        &["is a file, not a folder"],
        &d.join("a_file/model"),
    );
    check(
        env!("CARGO_BIN_EXE_neurokin"),
        &["--preset", "quick", "--out", &format!("{a_file}/run")],
        &["is a file, not a folder"],
        &d.join("a_file/run"),
    );
    // A camera looking straight down is one (it was "must span a frame").
    let down = d.join("down.npz");
    let looked_down = Command::new(bin("dataset"))
        .args(["--preset", "quick", "--eye", "0,0,2", "--out"])
        .arg(&down)
        .output()
        .unwrap();
    common::assert_ok(&looked_down);
    // A robot with no movable joint (40 identical images were written).
    let arm = common::write_arm(d, "still", 2, false);
    check(
        bin("dataset"),
        &[
            "--preset",
            "quick",
            "--urdf",
            arm.to_str().unwrap(),
            "--tip",
            "base",
            "--out",
            n,
        ],
        &["no movable joint", "--tip"],
        &npz_out,
    );
    // A dataset without training samples (the mean silhouette scored one anyway).
    let empty_train = d.join("no_train.npz");
    let data = selfmodel::data::dataset::Dataset::generate(
        &selfmodel::sim::arm4::arm4(),
        &<selfmodel::data::dataset::DatasetConfig as selfmodel::core::preset::Preset>::quick(),
        None,
    )
    .unwrap();
    selfmodel::data::dataset::Dataset { n_train: 0, ..data }
        .save(&empty_train)
        .unwrap();
    check(
        env!("CARGO_BIN_EXE_mean_silhouette"),
        &[
            "--preset",
            "quick",
            "--dataset",
            empty_train.to_str().unwrap(),
            "--out",
            o,
        ],
        &["no training samples"],
        &out,
    );
    // A camera kilometres away (its frame was NaN at 1e150 m, and 1e300 took a minute).
    check(
        bin("dataset"),
        &["--preset", "quick", "--eye", "1e150,0,0", "--out", n],
        &["within 1000 m"],
        &npz_out,
    );
    // A self-model refusing its settings leaves no folder (it left config.json behind).
    for args in [["--train-samples", "1000000000000"], ["--fov", "0"]] {
        check(
            env!("CARGO_BIN_EXE_neurokin"),
            &["--preset", "quick", args[0], args[1], "--out", o],
            &[],
            &out,
        );
    }
    // A typo in the first row is not a header; a header is a row of names.
    let typo = write("typo.csv", "1O,20,30,40\n1,2,3,4\n");
    check(
        bin("dataset"),
        &["--angles", &typo, "--out", n],
        &["line 1", "1O,20,30,40"],
        &npz_out,
    );
    let semi = write("semi.csv", "10;20;30;40\n");
    check(
        bin("dataset"),
        &["--angles", &semi, "--out", n],
        &["separate the joints with commas"],
        &npz_out,
    );
    let huge = write("huge.csv", "a,b,c,d\n100000,1,2,3\n");
    check(
        bin("dataset"),
        &["--angles", &huge, "--out", n],
        &["row 1", "outside +-360"],
        &npz_out,
    );
    let huger = write("huger.csv", "1,2,3,1e308\n");
    check(
        bin("dataset"),
        &["--angles", &huger, "--out", n],
        &["row 1: 1e308 is outside +-360"],
        &npz_out,
    );
    // A header claiming 2^62 rows.
    let forged = d.join("forged.npz");
    {
        use std::io::Write;
        let dict = "{'descr': '<f8', 'fortran_order': False, 'shape': (4611686018427387904, 4), }";
        let pad = (64 - (10 + dict.len() + 1) % 64) % 64;
        let header = format!("{dict}{}\n", " ".repeat(pad));
        let mut npy = b"\x93NUMPY\x01\x00".to_vec();
        npy.extend((header.len() as u16).to_le_bytes());
        npy.extend(header.as_bytes());
        npy.extend([0u8; 96]);
        let mut zip = zip::ZipWriter::new(std::fs::File::create(&forged).unwrap());
        zip.start_file("angles.npy", zip::write::SimpleFileOptions::default())
            .unwrap();
        zip.write_all(&npy).unwrap();
        zip.finish().unwrap();
    }
    check(
        bin("dataset"),
        &["--angles", forged.to_str().unwrap(), "--out", n],
        &["more elements than the file holds"],
        &npz_out,
    );
    check(
        bin("dataset"),
        &["--size", "100000", "--out", n],
        &["GiB limit", "--size"],
        &npz_out,
    );
    check(
        bin("dataset"),
        &["--samples", "-5", "--out", n],
        &["invalid value '-5'"],
        &npz_out,
    );
    let geometry = d.join("g.json");
    for cell in ["0", "-1"] {
        check(
            bin("fit"),
            &["--cell", cell, "--out", geometry.to_str().unwrap()],
            &["not a voxel size"],
            &geometry,
        );
    }
    check(
        bin("reproduce"),
        &["--only", "nonsense", "--root", o],
        &["no such experiment"],
        &out,
    );
    let bench = d.join("b.csv");
    check(
        bin("bench"),
        &[
            "--repeats",
            "0",
            "--quick",
            "--out",
            bench.to_str().unwrap(),
        ],
        &["at least one timed step"],
        &bench,
    );
    check(
        bin("speed"),
        &[
            "--preset",
            "quick",
            "--latency",
            "sleep:99999999999",
            "--out",
            o,
        ],
        &["at most 10000 us"],
        &out,
    );
    let fixed = write(
        "fixed.urdf",
        r#"<robot name="f"><link name="base"/><link name="a"/><joint name="j" type="fixed"><parent link="base"/><child link="a"/></joint></robot>"#,
    );
    check(
        bin("table2"),
        &["--preset", "quick", "--urdf", &fixed, "--out", o],
        &["no movable joints"],
        &out,
    );
    let limit = r#"<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/>"#;
    let cycle = write(
        "cycle.urdf",
        &format!(
            r#"<robot name="c"><link name="a"/><link name="b"/><joint name="j1" type="revolute"><parent link="a"/><child link="b"/>{limit}</joint><joint name="j2" type="revolute"><parent link="b"/><child link="a"/>{limit}</joint></robot>"#
        ),
    );
    check(
        bin("table2"),
        &["--preset", "quick", "--urdf", &cycle, "--out", o],
        &["the joints form a cycle"],
        &out,
    );
    // Checked before the first file is written: no config.json left behind.
    let neurokin = env!("CARGO_BIN_EXE_neurokin");
    check(
        neurokin,
        &["--preset", "quick", "--urdf", &fixed, "--out", o],
        &["no movable joints"],
        &out,
    );
    #[cfg(not(feature = "wgpu"))]
    check(
        neurokin,
        &["--preset", "quick", "--device", "wgpu", "--out", o],
        &["--device wgpu is not compiled in", "cargo feature `wgpu`"],
        &out,
    );
    let failed = failed.into_inner();
    assert!(
        failed.is_empty(),
        "{} refusals went wrong:\n{}",
        failed.len(),
        failed.join("\n")
    );
}

/// `neurokin --preset quick --steps 40 --out out` (with `--resume`).
fn neurokin_40_steps(out: &std::path::Path, resume: bool) -> std::process::Output {
    let mut args = vec![
        "--preset",
        "quick",
        "--steps",
        "40",
        "--out",
        out.to_str().unwrap(),
    ];
    if resume {
        args.push("--resume");
    }
    Command::new(env!("CARGO_BIN_EXE_neurokin"))
        .args(&args)
        .output()
        .unwrap()
}

/// A finished run resumed scores bit for bit as before; a damaged checkpoint is reported in
/// one line that says what to do.
#[test]
fn a_resumed_checkpoint_scores_the_same_and_a_damaged_one_says_what_to_do() {
    let dir = common::tempdir();
    let out = dir.path().join("nk");
    let run = |resume: bool| neurokin_40_steps(&out, resume);
    assert!(run(false).status.success());
    // An untouched finished run, resumed, scores exactly as it did (BatchNorm included).
    let scores = || {
        let text = std::fs::read_to_string(out.join("results.csv")).unwrap();
        let (head, row) = text.split_once('\n').unwrap();
        let col = |name: &str| head.split(',').position(|c| c == name).unwrap();
        let cells: Vec<String> = row.split(',').map(String::from).collect();
        [
            cells[col("psnr_db_test")].clone(),
            cells[col("iou_test")].clone(),
        ]
    };
    let before = scores();
    let again = run(true);
    assert!(again.status.success());
    assert!(String::from_utf8_lossy(&again.stderr).contains("continuing from step 40"));
    assert_eq!(scores(), before, "the reloaded model scores differently");
    let model = out.join("checkpoint").join("model.bpk");
    let bytes = std::fs::read(&model).unwrap();
    std::fs::write(&model, &bytes[..100]).unwrap();
    let o = run(true);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    let last = err.lines().last().unwrap();
    assert!(
        last.starts_with("error: ")
            && last.contains("model.bpk")
            && last.contains("delete")
            && last.contains("--resume"),
        "{err}"
    );
    assert!(!last.contains("Io(\""), "debug text in: {last}");
}

/// One run per output folder: a folder locked by a live process is refused with its id (the
/// lock stays); a lock left by a dead process is taken over.
#[test]
fn an_output_folder_in_use_is_refused_and_a_stale_lock_is_taken_over() {
    let dir = common::tempdir();
    let out = dir.path().join("nk");
    std::fs::create_dir_all(&out).unwrap();
    let mut holder = Command::new("sleep").arg("30").spawn().unwrap();
    std::fs::write(out.join(".lock"), holder.id().to_string()).unwrap();
    let run = || {
        Command::new(env!("CARGO_BIN_EXE_neurokin"))
            .args([
                "--preset",
                "quick",
                "--steps",
                "20",
                "--out",
                out.to_str().unwrap(),
            ])
            .output()
            .unwrap()
    };
    let o = run();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{err}");
    assert!(
        err.contains(&format!("in use by process {}", holder.id())),
        "{err}"
    );
    assert!(!out.join("results.csv").exists());
    assert!(out.join(".lock").exists(), "the holder's lock was removed");
    holder.kill().unwrap();
    holder.wait().unwrap();
    let o = run();
    common::assert_ok(&o);
    assert!(out.join("results.csv").exists());
    assert!(!out.join(".lock").exists(), "the lock outlived the run");
}

/// Ctrl-C ends a training run after its current step with a checkpoint saved, a line that
/// says how to continue, and exit code 130; `--resume` continues from that step.
#[test]
fn ctrl_c_saves_a_checkpoint_and_exits_130() {
    let dir = common::tempdir();
    let out = dir.path().join("nk");
    let args = [
        "--preset",
        "quick",
        "--steps",
        "100000",
        "--out",
        out.to_str().unwrap(),
    ];
    let child = Command::new(env!("CARGO_BIN_EXE_neurokin"))
        .args(args)
        .stderr(std::process::Stdio::piped())
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // Wait until it trains (its config is written before the first step).
    let started = std::time::Instant::now();
    while !out.join("config.json").exists() && started.elapsed().as_secs() < 60 {
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    std::thread::sleep(std::time::Duration::from_secs(2));
    let killed = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    let o = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(130), "{err}");
    let last = err.lines().last().unwrap();
    assert!(
        last.starts_with("interrupted: NeuroKin stopped after step") && last.contains("--resume"),
        "{last}"
    );
    let state = std::fs::read_to_string(out.join("checkpoint").join("state.json")).unwrap();
    let step: usize = serde_json::from_str::<serde_json::Value>(&state).unwrap()["log"]["step"]
        .as_u64()
        .unwrap() as usize;
    assert!(
        last.contains(&format!("after step {step};")),
        "{last} / saved step {step}"
    );
}

/// `--resume` says what it does where there is nothing to resume: no checkpoint yet, or a
/// model that keeps none (K-3DGS).
#[test]
fn resume_without_a_checkpoint_says_so() {
    let dir = common::tempdir();
    for (bin, said) in [
        (env!("CARGO_BIN_EXE_neurokin"), "no checkpoint in"),
        (env!("CARGO_BIN_EXE_k3dgs"), "K-3DGS keeps no checkpoint"),
    ] {
        let out = dir.path().join(said.replace(' ', "_"));
        let o = Command::new(bin)
            .args(["--preset", "quick", "--steps", "4", "--resume"])
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{err}");
        assert!(
            err.lines()
                .any(|l| l.contains(said) && l.contains("starts from step 0")),
            "{bin}: {err}"
        );
    }
}

/// `ik train`, `ik targets` and `ik solve` on a test arm, and what `ik solve` refuses.
#[test]
fn ik_trains_saves_and_solves_targets_of_your_own() {
    let dir = common::tempdir();
    let d = dir.path();
    let urdf = common::write_arm(d, "arm", 6, true);
    let ik = env!("CARGO_BIN_EXE_ik");
    let model = d.join("model");
    let run = |args: &[&str]| {
        let o = Command::new(ik).args(args).output().unwrap();
        assert!(
            o.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    let said = run(&[
        "train",
        "--urdf",
        urdf.to_str().unwrap(),
        "--tip",
        "hand",
        "--preset",
        "quick",
        "--out",
        model.to_str().unwrap(),
    ]);
    assert!(said.contains("6 joints (j1, j2, j3, j4, j5, j6)"), "{said}");
    let targets = d.join("targets.csv");
    run(&[
        "targets",
        "--model",
        model.to_str().unwrap(),
        "--n",
        "50",
        "--out",
        targets.to_str().unwrap(),
    ]);
    let answers = d.join("answers.csv");
    let said = run(&[
        "solve",
        "--model",
        model.to_str().unwrap(),
        "--targets",
        targets.to_str().unwrap(),
        "--k",
        "2",
        "--out",
        answers.to_str().unwrap(),
    ]);
    assert!(said.contains("50 targets"), "{said}");
    // The precision of the answers, and how they were made beside them.
    assert!(said.contains("pose error median/p98/max "), "{said}");
    let provenance: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("answers.csv.json")).unwrap())
            .unwrap();
    assert_eq!(provenance["tolerance_mm"], 1e-4, "{provenance}");
    assert_eq!(provenance["k"], 2, "{provenance}");
    let text = std::fs::read_to_string(&answers).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next().unwrap(),
        "target,solution,j1,j2,j3,j4,j5,j6,pos_err_mm,rot_err_deg,exact"
    );
    assert_eq!(lines.count(), 100);
    // A bad row is named by its line; nothing is written.
    let bad = d.join("bad.csv");
    std::fs::write(&bad, "x,y,z,qw,qx,qy,qz\n0.1,0.2,0.3,1,0,0,0\n0.1,0.2\n").unwrap();
    let out = d.join("never.csv");
    fails_cleanly(
        ik,
        &[
            "solve",
            "--model",
            model.to_str().unwrap(),
            "--targets",
            bad.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ],
        &["bad.csv", "line 3"],
        &out,
    );
    // Bad input round 3: an unbounded --k, an --out that is the targets or inside the model's
    // folder, and edited model files are refused in one line; nothing is written or replaced.
    let solve = |targets: &Path, k: &str, out: &Path, model: &Path| {
        vec![
            "solve".to_string(),
            "--model".into(),
            model.to_str().unwrap().into(),
            "--targets".into(),
            targets.to_str().unwrap().into(),
            "--k".into(),
            k.into(),
            "--out".into(),
            out.to_str().unwrap().into(),
        ]
    };
    let run = |args: Vec<String>, needles: &[&str], out: &Path| {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        fails_cleanly(ik, &args, needles, out)
    };
    run(
        solve(&targets, "18446744073709551615", &out, &model),
        &["--k"],
        &out,
    );
    // A tolerance that is not two numbers, not finite, not positive, or looser than the
    // success threshold.
    for bad in [
        "NaN,0.0001",
        "-1,0.0001",
        "0.0001,1e9",
        "0.0001",
        "abc,def",
        "2,0.1",
        "0,0",
    ] {
        let mut args = solve(&targets, "1", &out, &model);
        args.push(format!("--tolerance={bad}"));
        run(args, &["--tolerance"], &out);
    }
    let before = std::fs::read(&targets).unwrap();
    let o = Command::new(ik)
        .args(solve(&targets, "1", &targets, &model))
        .output()
        .unwrap();
    assert!(
        !o.status.success() && String::from_utf8_lossy(&o.stderr).contains("the file it reads")
    );
    assert_eq!(
        std::fs::read(&targets).unwrap(),
        before,
        "the targets were replaced"
    );
    let json = model.join("model.json");
    let saved = std::fs::read_to_string(&json).unwrap();
    let o = Command::new(ik)
        .args(solve(&targets, "1", &json, &model))
        .output()
        .unwrap();
    assert!(
        !o.status.success()
            && String::from_utf8_lossy(&o.stderr).contains("inside the model's folder")
    );
    assert_eq!(std::fs::read_to_string(&json).unwrap(), saved);
    // bench_ik writes its sitting beside the model, never into it.
    let o = Command::new(env!("CARGO_BIN_EXE_bench_ik"))
        .args([
            "--model",
            model.to_str().unwrap(),
            "--out",
            model.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("inside the model's folder"),
        "{err}"
    );
    assert_eq!(
        std::fs::read_dir(&model).unwrap().count(),
        2,
        "bench_ik wrote into the model"
    );
    let edited = d.join("edited");
    std::fs::create_dir_all(&edited).unwrap();
    std::fs::copy(model.join("model.bpk"), edited.join("model.bpk")).unwrap();
    let value: serde_json::Value = serde_json::from_str(&saved).unwrap();
    for (edit, needle) in [
        ("/ranges", "joint ranges for 6 joints"),
        ("/ranges/1", "not finite numbers"),
        ("/config/lm/max_iterations", "iterations a start"),
        ("/joint_names/1", "named twice"),
        ("/ranges/2", "empty"),
        ("/config/flow/best_of", "best_of 0"),
        ("/config/flow/clamp", "clamp -1"),
        ("/config/flow/fit/inference_batch", "inference batch 0"),
    ] {
        let mut v = value.clone();
        match edit {
            "/ranges" => {
                v["ranges"].as_array_mut().unwrap().pop();
            }
            "/ranges/1" => v["ranges"][1] = serde_json::json!([1e308, -1e308]),
            "/ranges/2" => v["ranges"][2] = serde_json::json!([0.5, 0.5]),
            "/config/lm/max_iterations" => {
                v["config"]["lm"]["max_iterations"] = serde_json::json!(1_000_000_000_000u64)
            }
            "/config/flow/best_of" => v["config"]["flow"]["best_of"] = serde_json::json!(0),
            "/config/flow/clamp" => v["config"]["flow"]["clamp"] = serde_json::json!(-1.0),
            "/config/flow/fit/inference_batch" => {
                v["config"]["flow"]["fit"]["inference_batch"] = serde_json::json!(0)
            }
            _ => v["joint_names"][1] = v["joint_names"][0].clone(),
        }
        std::fs::write(edited.join("model.json"), v.to_string()).unwrap();
        run(
            solve(&targets, "1", &out, &edited),
            &[needle, "ik train"],
            &out,
        );
    }
    // Damaged weights: bytes flipped (the saved hash differs), or NaN weights saved with a
    // matching hash (an edited model.json).
    std::fs::write(edited.join("model.json"), &saved).unwrap();
    let mut weights = std::fs::read(model.join("model.bpk")).unwrap();
    let mid = weights.len() / 2;
    for b in &mut weights[mid..mid + 64] {
        *b ^= 0x5A;
    }
    std::fs::write(edited.join("model.bpk"), &weights).unwrap();
    run(
        solve(&targets, "1", &out, &edited),
        &["differs from the weights saved", "ik train"],
        &out,
    );
    let mut v = value.clone();
    v.as_object_mut().unwrap().remove("weights_fnv");
    std::fs::write(edited.join("model.json"), v.to_string()).unwrap();
    let nan = f32::NAN.to_le_bytes();
    let mut weights = std::fs::read(model.join("model.bpk")).unwrap();
    let tail = weights.len() - 4096;
    for c in weights[tail..].chunks_mut(4) {
        c.copy_from_slice(&nan);
    }
    std::fs::write(edited.join("model.bpk"), &weights).unwrap();
    let o = Command::new(ik)
        .args(solve(&targets, "1", &out, &edited))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && !out.exists(), "{err}");
    assert!(
        err.contains("not finite") || err.contains("cannot be read"),
        "{err}"
    );
    // The benchmark on the same model: every budget's row, the family, the model alone;
    // every answer inside the limits, and the largest budget solves (nearly) every target.
    let bench = d.join("bench");
    let o = Command::new(env!("CARGO_BIN_EXE_bench_ik"))
        .args(["--model", model.to_str().unwrap(), "--preset", "quick"])
        .args([
            "--no-references",
            "--k",
            "4",
            "--out",
            bench.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    common::assert_ok(&o);
    let rows: Vec<selfmodel_lab::studies::bench::ik::BenchIkRow> =
        selfmodel::report::table::read_csv(&bench.join("results.csv")).unwrap();
    assert!(
        rows.iter()
            .all(|r| r.outside_limits == 0 && r.targets == 200)
    );
    let best = rows
        .iter()
        .filter(|r| r.solver == "selfmodel flow + LM" && r.k == 1)
        .max_by_key(|r| {
            r.budget
                .split(' ')
                .next()
                .unwrap()
                .parse::<usize>()
                .unwrap()
        })
        .unwrap();
    assert!(best.exact_pct >= 99.0, "{best:?}");
    let family = rows.iter().find(|r| r.k == 4).unwrap();
    assert!(family.distinct_mean.unwrap() > 1.0, "{family:?}");
    let alone = rows.iter().find(|r| r.solver.contains("alone")).unwrap();
    assert!(alone.pos_err_mm_mean.unwrap() > 1.0);
    assert!(bench.join("success_against_time.png").exists());
    // A model folder that is not one.
    fails_cleanly(
        ik,
        &[
            "solve",
            "--model",
            d.to_str().unwrap(),
            "--targets",
            targets.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ],
        &["model.json"],
        &out,
    );
}

/// `mesh_fidelity --pybullet` given one of our own datasets (not PyBullet's renders) refuses it
/// in one line and writes nothing.
#[test]
fn mesh_fidelity_refuses_our_own_dataset_as_the_pybullet_reference() {
    if !selfmodel::sim::robots::shared_arm_urdf().exists() {
        eprintln!("skipped: the shared meshes are not beside the repository");
        return;
    }
    let dir = common::tempdir();
    let d = dir.path();
    let ours = d.join("ours.npz");
    let made = dataset(&["--preset", "quick", "--out", ours.to_str().unwrap()]);
    assert!(made.status.success());
    let out = d.join("fidelity");
    fails_cleanly(
        env!("CARGO_BIN_EXE_mesh_fidelity"),
        &[
            "--preset",
            "quick",
            "--pybullet",
            ours.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ],
        &["ours.npz", "not PyBullet's renders"],
        &out,
    );
}

/// A camera that misses the robot: `dataset` refuses it with what to do, and writes nothing.
#[test]
fn a_dataset_with_the_robot_out_of_view_is_refused() {
    let dir = common::tempdir();
    let out = dir.path().join("d.npz");
    fails_cleanly(
        env!("CARGO_BIN_EXE_dataset"),
        &[
            "--preset",
            "quick",
            "--eye",
            "1,0,0",
            "--target",
            "2,0,0",
            "--out",
            out.to_str().unwrap(),
        ],
        &["out of view", "--view"],
        &out,
    );
}

/// Two `emssl_table2` runs into one `--out` share its units: the one that finds a unit run by
/// the other says its report is partial, and how many units it holds, instead of a plain
/// "wrote results.csv".
#[test]
fn a_table2_run_sharing_its_folder_says_its_report_is_partial() {
    let dir = common::tempdir();
    let out = dir.path().join("t2");
    let units = out.join("units").join("90");
    std::fs::create_dir_all(&units).unwrap();
    let mut other = Command::new("sleep").arg("60").spawn().unwrap();
    std::fs::write(units.join("drl.claim"), other.id().to_string()).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_emssl_table2"))
        .args(["--preset", "quick", "--out", out.to_str().unwrap()])
        .output()
        .unwrap();
    other.kill().unwrap();
    other.wait().unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr),
    );
    assert!(o.status.success(), "{stderr}");
    assert!(
        stderr.contains(&format!("DRL: left to process {}", other.id())),
        "{stderr}"
    );
    let note = stdout
        .lines()
        .find(|l| l.contains("results.csv is partial ("))
        .unwrap_or_else(|| panic!("no partial note in: {stdout}"));
    // Every unit of the quick preset but the one held and the refinement that waits for it.
    let (done, of) = note
        .split("partial (")
        .nth(1)
        .and_then(|r| r.split(" units").next())
        .and_then(|r| r.split_once(" of "))
        .map(|(a, b)| (a.parse::<usize>().unwrap(), b.parse::<usize>().unwrap()))
        .unwrap();
    assert_eq!(done + 2, of, "{note}");
    let csv = std::fs::read_to_string(out.join("results.md")).unwrap();
    assert!(csv.contains("partial"), "{csv}");
}

/// A run too long for one sitting, whose checkpoint is small, is carried in git: a copy of
/// `checkpoint/` committed as `checkpoint_carried/` is where `--resume` continues from in a
/// fresh clone (the git-ignored `checkpoint/` gone).
#[test]
fn resume_continues_from_a_carried_checkpoint_where_the_checkpoint_is_gone() {
    let dir = common::tempdir();
    let out = dir.path().join("nk");
    let run = |resume: bool| neurokin_40_steps(&out, resume);
    assert!(run(false).status.success());
    let table = std::fs::read_to_string(out.join("results.csv")).unwrap();
    let psnr = |t: &str| {
        let (head, row) = t.split_once('\n').unwrap();
        let col = head.split(',').position(|c| c == "psnr_db_test").unwrap();
        row.split(',').nth(col).unwrap().to_string()
    };
    std::fs::rename(out.join("checkpoint"), out.join("checkpoint_carried")).unwrap();
    let again = run(true);
    let err = String::from_utf8_lossy(&again.stderr);
    assert!(again.status.success(), "{err}");
    assert!(err.contains("carried checkpoint"), "{err}");
    assert!(err.contains("continuing from step 40"), "{err}");
    let resumed = std::fs::read_to_string(out.join("results.csv")).unwrap();
    assert_eq!(psnr(&resumed), psnr(&table));
    assert!(
        out.join("checkpoint_carried").is_dir(),
        "the carried copy stays"
    );
}

/// `table1 --resume` where every model has finished (its table written) but the checkpoints
/// are gone (a fresh clone of a committed run) reads each model's rows and trains nothing.
#[test]
fn table1_resumed_reads_the_models_it_finished_and_trains_nothing() {
    let dir = common::tempdir();
    let o = dir.path().to_str().unwrap();
    let run = |resume: bool| {
        let mut args = vec!["--preset", "quick", "--out", o];
        if resume {
            args.push("--resume");
        }
        Command::new(env!("CARGO_BIN_EXE_table1"))
            .args(&args)
            .output()
            .unwrap()
    };
    let first = run(false);
    common::assert_ok(&first);
    let table = std::fs::read(dir.path().join("results.csv")).unwrap();
    fn checkpoints(d: &std::path::Path) -> Vec<std::path::PathBuf> {
        let mut found = Vec::new();
        for e in std::fs::read_dir(d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                if p.file_name().unwrap() == "checkpoint" {
                    found.push(p);
                } else {
                    found.extend(checkpoints(&p));
                }
            }
        }
        found
    }
    for c in checkpoints(dir.path()) {
        std::fs::remove_dir_all(c).unwrap();
    }
    let again = run(true);
    let err = String::from_utf8_lossy(&again.stderr);
    assert!(again.status.success(), "{err}");
    assert!(err.contains("rows of the finished run"), "{err}");
    // Measured speeds are in the table: a model trained or timed again would change them.
    assert!(
        std::fs::read(dir.path().join("results.csv")).unwrap() == table,
        "{err}"
    );
    let left = checkpoints(dir.path());
    assert!(left.is_empty(), "trained again: {left:?}");
}

/// `--train-samples N` trains on the first N poses of a longer trajectory and tests on the
/// preset's number of poses after them; the config and the row say so.
#[test]
fn train_samples_lengthens_the_trajectory_and_keeps_the_test_count() {
    let dir = common::tempdir();
    let out_dir = dir.path().join("out");
    let out = Command::new(env!("CARGO_BIN_EXE_mean_silhouette"))
        .args(["--preset", "quick", "--train-samples", "150", "--out"])
        .arg(&out_dir)
        .output()
        .unwrap();
    common::assert_ok(&out);
    let config: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("config.json")).unwrap())
            .unwrap();
    let data = &config["data"]["dataset"];
    let preset = selfmodel::self_models::neurokin::neurokin_run("quick").unwrap();
    let test = preset.data.dataset.samples - preset.data.dataset.train;
    assert_ne!(preset.data.dataset.train, 150);
    assert_eq!(data["train"], 150);
    assert_eq!(data["samples"], 150 + test as u64);
    let rows = selfmodel::self_models::result::read_results(&out_dir.join("results.csv")).unwrap();
    assert_eq!(rows[0].train_samples, 150);
    assert!(
        rows[0].note.contains("first 150 samples"),
        "{}",
        rows[0].note
    );
}

/// `--group NAME` reads the SRDF beside the URDF: the dataset's joints are the group's; with
/// no SRDF there, one line says to give one with --srdf and nothing is written.
#[test]
fn a_group_of_the_srdf_beside_the_urdf_is_the_joint_vector() {
    let dir = common::tempdir();
    let urdf = dir.path().join("two_arms.urdf");
    std::fs::write(&urdf, common::two_armed_urdf()).unwrap();
    let out_dir = dir.path().join("out");
    std::fs::create_dir_all(&out_dir).unwrap();
    let npz = out_dir.join("g.npz");
    let args = |group: &str| {
        vec![
            "--preset".to_string(),
            "quick".into(),
            "--urdf".into(),
            urdf.display().to_string(),
            "--group".into(),
            group.into(),
            "--out".into(),
            npz.display().to_string(),
        ]
    };
    let run = |group: &str| {
        let a = args(group);
        dataset(&a.iter().map(String::as_str).collect::<Vec<_>>())
    };
    assert_clean_failure(&run("left_arm"), &["no SRDF file", "--srdf"], &out_dir);
    std::fs::write(
        dir.path().join("two_arms.srdf"),
        r#"<robot name="two_arms"><group name="left_arm"><chain base_link="base" tip_link="left_hand"/></group></robot>"#,
    )
    .unwrap();
    assert_clean_failure(
        &run("legs"),
        &["\"legs\" is not a group", "left_arm"],
        &out_dir,
    );
    let out = run("left_arm");
    common::assert_ok(&out);
    let data = selfmodel::data::dataset::Dataset::load(&npz).unwrap();
    assert_eq!(data.joint_names, ["waist", "l1", "l2"]);
}
