//! Training a pose model: joint samples within the robot's limits, their poses as the
//! flow's conditions, the flow fitted.

use std::path::Path;

use burn::tensor::Device;

use crate::core::error::Result;
use crate::ik::data::IkData;
use crate::ik::flow::{Draws, FlowIk, fit_flow, sample_rows};
use crate::ik::solve::collision::CollisionCheck;
use crate::ik::solve::levenberg_marquardt::{PoseTarget, pose_error};
use crate::sim::robot::Robot;
use crate::sim::robots::RobotSpec;

use super::conditions::{condition_rows, condition_width};
use super::saved::{SavedModel, save_model};
use super::{LearnedIk, LearnedIkConfig};

/// What [`train`] writes into its folder (a name ending in `/`: a folder of its own): no
/// file a run reads may be one of them.
pub const WRITTEN: &[&str] = &[
    "model.json",
    "model.bpk",
    "validation_curve.csv",
    crate::sim::collision::cache::FILE,
    "checkpoint/",
];

/// Train a model of `robot` (as `spec` names it) and save it into `dir`.
pub fn train(
    spec: &RobotSpec,
    robot: &Robot,
    cfg: &LearnedIkConfig,
    dir: &Path,
    device: &Device,
) -> Result<LearnedIk> {
    let chain = &robot.chain;
    let check = match &cfg.collisions {
        Some(c) => c.check(spec, None)?,
        None => None,
    };
    let keep = check.as_ref().map(|c| move |q: &[f64]| c.valid(q));
    let keep = keep.as_ref().map(|k| k as &crate::ik::data::Keep);
    let mut data = IkData::generate_where(chain, &cfg.data, keep)?;
    let targets: Vec<Vec<PoseTarget>> = data.joints[data.train()]
        .iter()
        .map(|q| PoseTarget::of(chain, q))
        .collect();
    let tips = chain.tip_names();
    if tips.len() > 1 {
        // Several tips share one position normalisation: the box of all their positions.
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for t in targets.iter().flatten() {
            for k in 0..3 {
                lo[k] = lo[k].min(t.position[k]);
                hi[k] = hi[k].max(t.position[k]);
            }
        }
        data.position_bounds = [lo, hi];
    }
    let width = condition_width(cfg.position_only, tips.len());
    let validation: Vec<Vec<PoseTarget>> = data.joints[data.validation()]
        .iter()
        .map(|q| PoseTarget::of(chain, q))
        .collect();
    let val_rows = condition_rows(&data, &validation, cfg.position_only);
    let batch = cfg.flow.fit.inference_batch;
    // A run to convergence keeps a checkpoint after every epoch in `dir/checkpoint/`: the same
    // command, run again after a kill, continues from its last epoch to the same model.
    let checkpoint = dir.join("checkpoint");
    let mut flow_cfg = cfg.flow.clone();
    flow_cfg.fit.checkpoint = Some(crate::train::convergence::FitCheckpoint {
        dir: checkpoint.clone(),
        settings: serde_json::json!({ "config": cfg, "robot": chain.fingerprint() }),
    });
    let trained = fit_flow(
        &data,
        condition_rows(&data, &targets, cfg.position_only),
        width,
        &flow_cfg,
        device,
        |m: &FlowIk| {
            // One sample per validation target: its mean position error (cm).
            let q = sample_rows(m, &data, &val_rows, Draws::one(batch, 0x7A1), device)
                .pop()
                .unwrap_or_default();
            let n = q.len().max(1) as f64;
            q.iter()
                .zip(&validation)
                .map(|(q, t)| 100.0 * pose_error(chain, q, t).0)
                .sum::<f64>()
                / n
        },
    )?;
    let fresh = !dir.exists() || dir.read_dir().is_ok_and(|mut d| d.next().is_none());
    let description = SavedModel::describe(cfg, spec, chain, tips, &data);
    let saved = save_model(dir, &trained, description, checkpoint.as_path());
    if saved.is_err() && fresh {
        // A run that could not save (a full disk) leaves no empty or partial folder.
        for name in ["model.bpk", "model.json", "validation_curve.csv"] {
            let _ = std::fs::remove_file(dir.join(name));
        }
        let _ = std::fs::remove_dir(dir);
    }
    let saved = saved?;
    // The collision model kept beside the model, so `ik solve --scene` need not fit it again
    // (a robot without collision geometry has none to keep).
    let kept = match check {
        Some(c) => Some(c),
        None => CollisionCheck::for_robot(spec, None, None, true, 0.0).ok(),
    };
    if let Some(c) = kept {
        c.keep_in(dir)?;
    }
    Ok(LearnedIk {
        saved,
        flow: trained.model,
        data,
        device: device.clone(),
    })
}
