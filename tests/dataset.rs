//! Datasets: npz round trip, the papers' file layout, and every bad input.

mod common;

use std::path::{Path, PathBuf};

use selfmodel::Error;
use selfmodel::core::preset::Preset;
use selfmodel::data::dataset::{Dataset, DatasetConfig, read_angles};
use selfmodel::data::npz::{Array, read_npz, write_npz};
use selfmodel::sim::arm4::arm4;

fn fixture() -> PathBuf {
    selfmodel_lab::workspace().join("data/fixtures/papers_format.npz")
}

#[test]
fn npz_round_trip_keeps_every_array() {
    let dir = common::tempdir();
    let robot = arm4();
    let data = Dataset::generate(&robot, &DatasetConfig::quick(), None).unwrap();
    let path = dir.path().join("d.npz");
    data.save(&path).unwrap();
    let back = Dataset::load(&path).unwrap();
    assert_eq!(data, back);
    let raw = read_npz(&path).unwrap();
    let keys: Vec<&str> = raw.keys().map(String::as_str).collect();
    assert_eq!(
        keys,
        [
            "angles",
            "depth",
            "focal",
            "images",
            "joint_names",
            "n_train",
            "poses"
        ]
    );
    // The joints name the columns of `angles`, as NumPy strings.
    assert_eq!(raw["joint_names"].dtype_name(), "unicode text");
    assert_eq!(back.joint_names, robot.chain.joint_names());
    assert_eq!(back.joint_names.len(), 4);
    assert_eq!(raw["images"].shape, [40, 100, 100]);
    assert_eq!(raw["images"].dtype_name(), "uint8");
    assert_eq!(raw["angles"].dtype_name(), "float64");
    assert_eq!(raw["depth"].dtype_name(), "float32");
    assert_eq!(raw["poses"].shape, [40, 4, 4]);
    // Only the temporary-free result is left in the folder.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

#[test]
fn a_file_in_the_papers_layout_loads() {
    let d = Dataset::load(&fixture()).unwrap();
    assert_eq!(d.len(), 3);
    assert_eq!(d.angles[2], vec![45.5, 12.25, -3.0, 89.0]);
    assert_eq!(d.focal, 130.2545);
    assert_eq!(d.n_train, 2); // 80% when the file has no split
    assert!(d.depth.iter().all(|&v| v == 0.0));
    assert_eq!(d.image(1)[20 * 100 + 50], 255);
}

#[test]
fn dataset_is_deterministic_and_silhouettes_are_binary() {
    let robot = arm4();
    let mut cfg = DatasetConfig::quick();
    cfg.sampler = selfmodel::sim::trajectory::SamplerKind::Babbling;
    let a = Dataset::generate(&robot, &cfg, None).unwrap();
    let b = Dataset::generate(&robot, &cfg, None).unwrap();
    assert_eq!(a, b);
    assert!(a.images.iter().all(|&v| v == 0 || v == 255));
    // Depth is set exactly where the silhouette is.
    assert!(
        a.images
            .iter()
            .zip(&a.depth)
            .all(|(&s, &d)| (s == 255) == (d > 0.0))
    );
    let stats = a.stats(&[]);
    assert!(stats.occupancy.min > 0.01 && stats.occupancy.max < 0.2);
}

fn expect_data_error(path: &Path, needle: &str) {
    match Dataset::load(path) {
        Err(e @ (Error::Data { .. } | Error::Io { .. })) => {
            let msg = e.to_string();
            assert!(
                msg.contains(&path.display().to_string()),
                "error does not name the file: {msg}"
            );
            assert!(msg.contains(needle), "expected \"{needle}\" in: {msg}");
        }
        other => panic!(
            "expected a data error for {}, got {other:?}",
            path.display()
        ),
    }
}

fn write(dir: &Path, name: &str, arrays: &[(&str, Array)]) -> PathBuf {
    let path = dir.join(name);
    let refs: Vec<(&str, &Array)> = arrays.iter().map(|(k, a)| (*k, a)).collect();
    write_npz(&path, &refs).unwrap();
    path
}

#[test]
fn bad_dataset_files_are_clear_errors() {
    let dir = common::tempdir();
    let d = dir.path();
    expect_data_error(&d.join("missing.npz"), "No such file");
    let corrupt = d.join("corrupt.npz");
    std::fs::write(&corrupt, b"this is not a zip file").unwrap();
    expect_data_error(&corrupt, "not an .npz file");

    let images = || Array::u8(&[2, 4, 4], vec![0; 32]);
    let angles = || Array::f64(&[2, 4], vec![0.0; 8]);
    let focal = || Array::scalar(130.0);
    let poses = || Array::f64(&[4, 4], vec![0.0; 16]);
    let p = write(
        d,
        "nokey.npz",
        &[("images", images()), ("focal", focal()), ("poses", poses())],
    );
    expect_data_error(&p, "missing key \"angles\"");
    let names = |v: &[&str]| Array::text(v.iter().map(|s| s.to_string()).collect());
    for (file, joint_names, needle) in [
        ("names3.npz", names(&["a", "b", "c"]), "must be 4 strings"),
        (
            "names2x.npz",
            names(&["a", "b", "a", "d"]),
            "names \"a\" twice",
        ),
        (
            "namesf.npz",
            Array::f64(&[4], vec![0.0; 4]),
            "must be 4 strings",
        ),
    ] {
        let p = write(
            d,
            file,
            &[
                ("images", images()),
                ("angles", angles()),
                ("focal", focal()),
                ("poses", poses()),
                ("joint_names", joint_names),
            ],
        );
        expect_data_error(&p, needle);
    }
    let p = write(
        d,
        "textposes.npz",
        &[
            ("images", images()),
            ("angles", angles()),
            ("focal", focal()),
            ("poses", Array::text(vec!["x".into(); 16])),
        ],
    );
    expect_data_error(&p, "\"poses\" must be float");
    // A negative depth (resneurokin_d trained on it), NaN in a camera pose (k3dgs).
    let p = write(
        d,
        "negdepth.npz",
        &[
            ("images", images()),
            ("angles", angles()),
            ("focal", focal()),
            ("poses", poses()),
            ("depth", Array::f32(&[2, 4, 4], vec![-1.0; 32])),
        ],
    );
    expect_data_error(&p, "\"depth\" of sample 0 is -1");
    let mut nan_poses = vec![0.0; 16];
    nan_poses[3] = f64::NAN;
    let p = write(
        d,
        "nanposes.npz",
        &[
            ("images", images()),
            ("angles", angles()),
            ("focal", focal()),
            ("poses", Array::f64(&[4, 4], nan_poses)),
        ],
    );
    expect_data_error(&p, "\"poses\" holds NaN");
    let p = write(
        d,
        "dtype.npz",
        &[
            ("images", Array::f32(&[2, 4, 4], vec![0.0; 32])),
            ("angles", angles()),
            ("focal", focal()),
            ("poses", poses()),
        ],
    );
    expect_data_error(&p, "\"images\" must be uint8");
    let p = write(
        d,
        "shape.npz",
        &[
            ("images", Array::u8(&[32], vec![0; 32])),
            ("angles", angles()),
            ("focal", focal()),
            ("poses", poses()),
        ],
    );
    expect_data_error(&p, "shape (N, H, W)");
    let p = write(
        d,
        "rows.npz",
        &[
            ("images", images()),
            ("angles", Array::f64(&[3, 4], vec![0.0; 12])),
            ("focal", focal()),
            ("poses", poses()),
        ],
    );
    expect_data_error(&p, "has 3 rows");
    let mut nan = vec![0.0; 8];
    nan[5] = f64::NAN;
    let p = write(
        d,
        "nan.npz",
        &[
            ("images", images()),
            ("angles", Array::f64(&[2, 4], nan)),
            ("focal", focal()),
            ("poses", poses()),
        ],
    );
    expect_data_error(&p, "row 1 is NaN or infinite");
    let p = write(
        d,
        "empty.npz",
        &[
            ("images", Array::u8(&[0, 4, 4], vec![])),
            ("angles", Array::f64(&[0, 4], vec![])),
            ("focal", focal()),
            ("poses", poses()),
        ],
    );
    expect_data_error(&p, "zero samples");
}

#[test]
fn impossible_configs_are_refused() {
    let robot = arm4();
    let mut cfg = DatasetConfig::quick();
    cfg.samples = 0;
    assert!(
        matches!(Dataset::generate(&robot, &cfg, None), Err(Error::Config(m)) if m.contains("at least 1 sample"))
    );
    let mut cfg = DatasetConfig::quick();
    cfg.train = 41;
    assert!(
        matches!(Dataset::generate(&robot, &cfg, None), Err(Error::Config(m)) if m.contains("impossible split"))
    );
}

#[test]
fn angle_files_are_checked() {
    let dir = common::tempdir();
    let csv = dir.path().join("a.csv");
    std::fs::write(&csv, "j0,j1,j2,j3\n1,2,3,4\n5,6,7,8\n").unwrap();
    assert_eq!(
        read_angles(&csv, 4).unwrap(),
        vec![vec![1.0, 2.0, 3.0, 4.0], vec![5.0, 6.0, 7.0, 8.0]]
    );
    std::fs::write(&csv, "1,2,3,4\n5,NaN,7,8\n").unwrap();
    assert!(
        read_angles(&csv, 4)
            .unwrap_err()
            .to_string()
            .contains("row 2 has a NaN")
    );
    std::fs::write(&csv, "1,2,3\n").unwrap();
    assert!(
        read_angles(&csv, 4)
            .unwrap_err()
            .to_string()
            .contains("row 1 has 3 values")
    );
    std::fs::write(&csv, "j0,j1,j2,j3\n").unwrap();
    assert!(
        read_angles(&csv, 4)
            .unwrap_err()
            .to_string()
            .contains("zero samples")
    );
    std::fs::write(&csv, "1,2,3,4\nx,y,z,w\n").unwrap();
    assert!(
        read_angles(&csv, 4)
            .unwrap_err()
            .to_string()
            .contains("line 2")
    );
    // The papers' npz works as an angle file.
    assert_eq!(read_angles(&fixture(), 4).unwrap().len(), 3);
}

#[test]
fn a_failed_write_leaves_no_file() {
    let dir = common::tempdir();
    let target = dir.path().join("out.npz");
    let result = selfmodel::core::atomic_file::write_atomic(&target, |w| {
        std::io::Write::write_all(w, b"half of a file").unwrap();
        Err(Error::Config("interrupted".into()))
    });
    assert!(result.is_err());
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        0,
        "partial or temporary file left"
    );
    // An existing result survives a failed rewrite untouched.
    std::fs::write(&target, b"old").unwrap();
    let _ =
        selfmodel::core::atomic_file::write_atomic(&target, |_| Err(Error::Config("no".into())));
    assert_eq!(std::fs::read(&target).unwrap(), b"old");
}

/// A run killed mid-write (SIGKILL) leaves its hidden temporary file; the next write of the
/// same file removes it, but not the one of a process still writing.
#[test]
fn a_killed_writers_temporary_file_is_removed_by_the_next_write() {
    let dir = common::tempdir();
    let target = dir.path().join("d.npz");
    let mut dead = std::process::Command::new("true").spawn().unwrap();
    dead.wait().unwrap();
    let mut live = std::process::Command::new("sleep")
        .arg("30")
        .spawn()
        .unwrap();
    let temp = |pid: u32| dir.path().join(format!(".d.npz.tmp-{pid}"));
    std::fs::write(temp(dead.id()), b"half").unwrap();
    std::fs::write(temp(live.id()), b"half").unwrap();
    selfmodel::core::atomic_file::write_bytes(&target, b"whole").unwrap();
    assert!(!temp(dead.id()).exists(), "the dead writer's file was kept");
    assert!(temp(live.id()).exists(), "a live writer's file was removed");
    assert_eq!(std::fs::read(&target).unwrap(), b"whole");
    live.kill().unwrap();
    live.wait().unwrap();
}

/// A member whose zip64 header claims 2^62 bytes (or 2^64 - 1) is a clear error, not an
/// allocation of that size (which aborted the process).
#[test]
fn an_npz_member_claiming_an_impossible_size_is_refused_without_allocating_it() {
    use selfmodel::data::npz::{Array, read_npz, write_npz};
    let dir = common::tempdir();
    let path = dir.path().join("forged.npz");
    write_npz(&path, &[("a", &Array::f64(&[3], vec![1.0, 2.0, 3.0]))]).unwrap();
    let good = std::fs::read(&path).unwrap();
    for claim in [1u64 << 62, u64::MAX] {
        let mut bytes = good.clone();
        // Every zip64 extra field (id 0x0001): its first value is the uncompressed size.
        let mut patched = 0;
        let mut i = 0;
        while i + 12 <= bytes.len() {
            if bytes[i..i + 2] == [1, 0] && bytes[i + 2] >= 8 && bytes[i + 3] == 0 {
                let size = u64::from_le_bytes(bytes[i + 4..i + 12].try_into().unwrap());
                if size > 0 && size < 1 << 20 {
                    bytes[i + 4..i + 12].copy_from_slice(&claim.to_le_bytes());
                    patched += 1;
                }
            }
            i += 1;
        }
        assert!(patched >= 1, "no zip64 size field found");
        std::fs::write(&path, &bytes).unwrap();
        let start = std::time::Instant::now();
        // Whatever the zip reader makes of the claim, the answer is a clean one (an error
        // naming the file, or the three real values), quickly and without a huge allocation.
        match read_npz(&path) {
            Ok(arrays) => assert_eq!(arrays["a"].to_f64(), vec![1.0, 2.0, 3.0]),
            Err(e) => assert!(e.to_string().contains("forged.npz"), "{e}"),
        }
        assert!(start.elapsed().as_secs_f64() < 5.0);
    }
}
