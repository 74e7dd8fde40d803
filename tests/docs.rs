//! The README, docs/ and every generated `results.md` equal what `reports` writes from the
//! checked-in CSVs and `docs/src/` (run `cargo run --release --bin reports` after a change).

mod common;

use std::path::Path;

use selfmodel_lab::studies::docs::{generate, render, stale};

#[test]
fn generated_documents_are_up_to_date() {
    let root = selfmodel_lab::workspace();
    let stale = stale(&root).unwrap();
    assert!(
        stale.is_empty(),
        "stale generated documents (run `cargo run --release --bin reports`): {stale:?}"
    );
    let files = generate(&root).unwrap();
    assert!(files.iter().any(|(p, _)| p == Path::new("README.md")));
    assert!(files.iter().any(|(p, _)| p.starts_with("docs")));
}

#[test]
fn directives_read_the_csv() {
    let tmp = common::tempdir();
    let dir = tmp.path().to_path_buf();
    std::fs::write(
        dir.join("t.csv"),
        "model,psnr,note\na,21.23456,x\nb,19.5,y\n",
    )
    .unwrap();
    let table = render(
        &dir,
        "{{table t.csv | cols: model, psnr | where: note=y | names: M, P}}",
    )
    .unwrap();
    assert_eq!(table, "| M | P |\n|---|---|\n| b | 19.50 |");
    let value = render(&dir, "PSNR {{value t.csv | row: model=a | col: psnr}} dB").unwrap();
    assert_eq!(value, "PSNR 21.23 dB");
    assert!(render(&dir, "{{value t.csv | row: model=c | col: psnr}}").is_err());
    assert!(render(&dir, "{{table t.csv | cols: nope}}").is_err());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The README lists `cargo run --release --bin NAME` for every experiment of the registry:
/// each must be a binary of the lab crate (a missing one failed a newcomer's first command).
#[test]
fn every_listed_experiment_is_a_binary() {
    let root = selfmodel_lab::workspace();
    let manifest = std::fs::read_to_string(root.join("lab/Cargo.toml")).unwrap();
    let missing: Vec<&str> = selfmodel_lab::studies::registry::EXPERIMENTS
        .iter()
        .map(|e| e.name)
        .filter(|name| {
            !manifest.contains(&format!(
                "[[bin]]\nname = \"{name}\"\npath = \"../experiments/{name}.rs\""
            )) || !root
                .join("experiments")
                .join(format!("{name}.rs"))
                .is_file()
        })
        .collect();
    assert!(
        missing.is_empty(),
        "experiments without a binary: {missing:?}"
    );
}

/// A metric that is not a number is an error naming the file, the row and the column: in a
/// quoted value (NaN included) and in a table column of numbers.
#[test]
fn a_non_numeric_metric_is_an_error_naming_file_row_and_column() {
    let tmp = common::tempdir();
    let dir = tmp.path().to_path_buf();
    std::fs::write(dir.join("m.csv"), "model,psnr\na,21.5\nb,abc\nc,NaN\n").unwrap();
    let err = render(&dir, "{{table m.csv}}").unwrap_err().to_string();
    assert!(
        err.contains("m.csv")
            && err.contains("row 2")
            && err.contains("`psnr`")
            && err.contains("abc"),
        "{err}"
    );
    let err = render(&dir, "{{value m.csv | row: model=c | col: psnr}}")
        .unwrap_err()
        .to_string();
    assert!(err.contains("row 3") && err.contains("NaN"), "{err}");
    // A column of text stays text; a number quoted in prose still reads.
    std::fs::write(
        dir.join("n.csv"),
        "model,psnr,note\na,21.5,fine\nb,20,also fine\n",
    )
    .unwrap();
    assert!(
        render(&dir, "{{table n.csv}}")
            .unwrap()
            .contains("also fine")
    );
    assert_eq!(
        render(&dir, "{{value n.csv | row: model=b | col: psnr}}").unwrap(),
        "20"
    );
}

/// A user's run leaves the checkout as it was: every experiment's default output is under
/// `runs/`, which git ignores (the committed reports need an explicit `--out reports/...`).
#[test]
fn every_default_output_is_under_the_git_ignored_runs_folder() {
    let ignore = std::fs::read_to_string(selfmodel_lab::workspace().join(".gitignore")).unwrap();
    assert!(ignore.lines().any(|l| l.trim() == "/runs/"));
    for e in selfmodel_lab::studies::registry::EXPERIMENTS {
        for preset in e.presets {
            let dir = e.dir_for(preset);
            assert!(
                dir.starts_with("runs"),
                "{} {preset}: {}",
                e.name,
                dir.display()
            );
        }
    }
    // A quick run from a clean folder writes there and nowhere else.
    let tmp = common::tempdir();
    let cwd = tmp.path().to_path_buf();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_mean_silhouette"))
        .args(["--preset", "quick"])
        .current_dir(&cwd)
        .output()
        .unwrap();
    common::assert_ok(&out);
    let top: Vec<String> = std::fs::read_dir(&cwd)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(top, ["runs"]);
    assert!(cwd.join("runs/mean_silhouette_quick/results.csv").is_file());
    let _ = std::fs::remove_dir_all(&cwd);
}
