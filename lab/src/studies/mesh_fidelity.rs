//! How closely the built-in `arm4` (fitted boxes) matches the mesh robot, and how closely our
//! ray caster matches PyBullet: silhouette IoU over random poses.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use selfmodel::core::atomic_file::write_json;
use selfmodel::core::error::{Error, Result};
use selfmodel::core::preset::Preset;
use selfmodel::core::provenance::git_revision;
use selfmodel::data::dataset::Dataset;
use selfmodel::eval::metrics::{shift_rows, silhouette_iou};
use selfmodel::report::table::{write_csv, write_markdown_report};
use selfmodel::sim::arm4::{arm4, scene_base};
use selfmodel::sim::camera::Camera;
use selfmodel::sim::ray_caster::{RayCaster, RenderOptions};
use selfmodel::sim::robot::Robot;
use selfmodel::sim::robots::shared_arm_urdf;
use selfmodel::sim::trajectory::babbling;
use selfmodel::sim::urdf_loader::load_urdf;

/// PyBullet's TinyRenderer draws the point straight ahead one row higher than our camera
/// model (row 49 against 50): its images are shifted down by this many rows to compare.
pub const PYBULLET_ROW_SHIFT: isize = 1;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FidelityConfig {
    pub preset: String,
    /// Random poses, uniform within the joint ranges (+-90 degrees).
    pub poses: usize,
    pub seed: u64,
    /// The papers' URDF with its STL meshes.
    pub urdf: PathBuf,
    /// PyBullet renders (images and angles, from `scripts/pybullet_render.py`) to compare
    /// against as well, when the file exists. Paper preset: `data/pybullet.npz`.
    pub pybullet: Option<PathBuf>,
    pub camera: Camera,
}

impl Preset for FidelityConfig {
    fn paper() -> Self {
        FidelityConfig {
            preset: "paper".into(),
            poses: 100,
            seed: 7,
            urdf: shared_arm_urdf(),
            pybullet: Some(crate::workspace().join("data/pybullet.npz")),
            camera: Camera::paper(),
        }
    }
    fn quick() -> Self {
        FidelityConfig {
            preset: "quick".into(),
            poses: 5,
            pybullet: None,
            ..Self::paper()
        }
    }
}

/// One comparison, one CSV row.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FidelityRow {
    pub ours: String,
    pub reference: String,
    pub poses: usize,
    pub mean_iou: f64,
    pub median_iou: f64,
    pub min_iou: f64,
    pub row_shift_px: isize,
    pub preset: String,
    pub device: String,
    pub git_revision: String,
}

/// Per-pose IoU of two robots rendered by our ray caster (angles in user units).
pub fn iou_between(a: &Robot, b: &Robot, camera: &Camera, angles: &[Vec<f64>]) -> Vec<f64> {
    let ra = RayCaster::new(a, camera.clone(), RenderOptions::default());
    let rb = RayCaster::new(b, camera.clone(), RenderOptions::default());
    let qa: Vec<Vec<f64>> = angles.iter().map(|q| a.chain.to_si(q)).collect();
    let qb: Vec<Vec<f64>> = angles.iter().map(|q| b.chain.to_si(q)).collect();
    let fa = ra.render_batch(&qa, None);
    let fb = rb.render_batch(&qb, None);
    fa.iter()
        .zip(&fb)
        .map(|(x, y)| silhouette_iou(&x.silhouette, &y.silhouette))
        .collect()
}

/// Per-pose IoU of our render of `robot` against given images, shifted by `row_shift` rows.
pub fn iou_against(
    robot: &Robot,
    camera: &Camera,
    reference: &Dataset,
    row_shift: isize,
) -> Vec<f64> {
    let caster = RayCaster::new(robot, camera.clone(), RenderOptions::default());
    let q: Vec<Vec<f64>> = reference
        .angles
        .iter()
        .map(|q| robot.chain.to_si(q))
        .collect();
    caster
        .render_batch(&q, None)
        .iter()
        .enumerate()
        .map(|(i, f)| {
            silhouette_iou(
                &f.silhouette,
                &shift_rows(reference.image(i), reference.width, row_shift),
            )
        })
        .collect()
}

fn row(
    ours: &str,
    reference: &str,
    ious: &[f64],
    shift: isize,
    cfg: &FidelityConfig,
) -> FidelityRow {
    let mut s = ious.to_vec();
    s.sort_by(f64::total_cmp);
    FidelityRow {
        ours: ours.into(),
        reference: reference.into(),
        poses: s.len(),
        mean_iou: s.iter().sum::<f64>() / s.len() as f64,
        median_iou: s[s.len() / 2],
        min_iou: s[0],
        row_shift_px: shift,
        preset: cfg.preset.clone(),
        device: "cpu (ray caster)".into(),
        git_revision: git_revision(),
    }
}

/// Run the comparison and write `results.csv`, `results.md`, `config.json` and `angles.csv`
/// (the poses, for `scripts/pybullet_render.py`) to `out`. The PyBullet rows are added when
/// `cfg.pybullet` names a file that exists.
pub fn run(cfg: &FidelityConfig, out: &Path) -> Result<Vec<FidelityRow>> {
    if !cfg.urdf.is_file() {
        return Err(Error::Config(format!(
            "{}: the papers' URDF is not there; point --urdf at 4dof_1st.urdf (shared/robots/4dof_1st)",
            cfg.urdf.display()
        )));
    }
    let mesh = load_urdf(&cfg.urdf, scene_base())?;
    let boxes = arm4();
    let ranges = boxes.chain.joint_ranges_user();
    let angles = babbling(cfg.poses, &ranges, cfg.seed);
    let mut rows = vec![row(
        "arm4 (fitted boxes)",
        "mesh robot (our ray caster)",
        &iou_between(&boxes, &mesh, &cfg.camera, &angles),
        0,
        cfg,
    )];
    if let Some(path) = cfg.pybullet.as_deref().filter(|p| p.is_file()) {
        // Our own datasets carry depth and a split; PyBullet's renders carry neither.
        let keys = selfmodel::data::npz::read_npz(path)?;
        if keys.contains_key("depth") || keys.contains_key("n_train") {
            return Err(Error::data(
                path,
                "a dataset written by our own `dataset`, not PyBullet's renders: comparing our renderer with itself says nothing; make the reference with scripts/pybullet_render.py",
            ));
        }
        let reference = Dataset::load(path)?;
        if reference.dof() != mesh.dof() {
            return Err(Error::data(
                path,
                format!(
                    "angles have {} columns, the robot has {}",
                    reference.dof(),
                    mesh.dof()
                ),
            ));
        }
        for (name, robot) in [
            ("mesh robot (our ray caster)", &mesh),
            ("arm4 (fitted boxes)", &boxes),
        ] {
            for shift in [0, PYBULLET_ROW_SHIFT] {
                rows.push(row(
                    name,
                    "PyBullet TinyRenderer",
                    &iou_against(robot, &cfg.camera, &reference, shift),
                    shift,
                    cfg,
                ));
            }
        }
    }
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    let csv = out.join("results.csv");
    write_csv(&csv, &rows)?;
    write_markdown_report(
        &csv,
        "Silhouette fidelity of the simulator",
        "Mean silhouette IoU over random poses (uniform in +-90 degrees). `arm4` is the built-in robot \
         drawn with boxes fitted to the papers' STL meshes; the mesh robot is `4dof_1st.urdf` with its \
         meshes. `row_shift_px` 1: PyBullet's image moved down one row, since its TinyRenderer puts the \
         point straight ahead at row 49 where our camera model puts it at row 50.",
    )?;
    write_json(&out.join("config.json"), cfg)?;
    let mut text = String::from("# joint angles in degrees, one pose per row\n");
    for q in &angles {
        text += &(q
            .iter()
            .map(|v| format!("{v:.6}"))
            .collect::<Vec<_>>()
            .join(",")
            + "\n");
    }
    selfmodel::core::atomic_file::write_bytes(&out.join("angles.csv"), text.as_bytes())?;
    Ok(rows)
}
