//! What the lab knows of each self-model that the model itself does not. A model of the
//! library knows its config, its training and how it renders, nothing of any study; here are
//! its run on each preset of Table I ([`Studied::preset_run`]), the paper's figures printed
//! beside its rows ([`paper_figures`]), whether it is a lower bound rather than a model
//! ([`Studied::LOWER_BOUND`]), and the reports of its own a study writes beside the
//! harness's ([`Studied::reports`]: FFKSM's renderers and novel views, K-3DGS's speeds).
//! [`run_studied`] runs one through the library's harness with all of these.

pub mod ffksm_reports;
pub mod k3dgs_reports;
pub mod paper_figures;

use std::path::Path;

use selfmodel::core::device::DeviceChoice;
use selfmodel::core::error::Result;
use selfmodel::self_models::ffksm::{Ffksm, FfksmVariant, ffksm_run};
use selfmodel::self_models::harness::{RunOutcome, run_with};
use selfmodel::self_models::k3dgs::{K3dgs, K3dgsVariant, k3dgs_run};
use selfmodel::self_models::link_splat::{LinkSplatConfig, link_splat_run};
use selfmodel::self_models::mean_silhouette::{MeanSilhouette, mean_silhouette_run};
use selfmodel::self_models::model::{ReportContext, SelfModel};
use selfmodel::self_models::nearest_pose::{NearestPose, nearest_pose_run};
use selfmodel::self_models::neurokin::{NeuroKinConfig, neurokin_run};
use selfmodel::self_models::resneurokin_d::{ResNeuroKinDConfig, resneurokin_d_run};
use selfmodel::self_models::result::ModelResult;
use selfmodel::self_models::run_config::SelfModelRun;

/// A self-model as the lab's studies run it.
pub trait Studied: SelfModel {
    /// Whether it is a lower bound every self-model must beat (a constant image), not a
    /// model: figures draw it as a line.
    const LOWER_BOUND: bool = false;
    /// Its run on a preset of [`selfmodel::self_models::run_config::SELF_MODEL_PRESETS`]
    /// (what the registry runs).
    fn preset_run(preset: &str) -> Result<SelfModelRun<Self>>;
    /// Reports of its own, written into `ctx.dir` once the run is evaluated, and what they
    /// add to its rows (one per renderer, in order) before the rows are written.
    fn reports(_rows: &mut [ModelResult], _ctx: &ReportContext<Self::Renderer>) -> Result<()> {
        Ok(())
    }
}

/// Train, evaluate, time and report `cfg` into `dir` through the library's harness, with what
/// the lab adds: the paper's figures beside its rows where it runs on the papers' set-up, the
/// lower bound's flag, and its own reports.
pub fn run_studied<M: Studied>(
    cfg: &SelfModelRun<M>,
    dir: &Path,
    device: DeviceChoice,
    resume: bool,
) -> Result<RunOutcome> {
    run_with(cfg, dir, device, resume, |rows, ctx| {
        let paper = paper_figures::of_run(cfg);
        for row in rows.iter_mut() {
            paper.fill(row);
            row.lower_bound = M::LOWER_BOUND;
        }
        M::reports(rows, ctx)
    })
}

impl Studied for NeuroKinConfig {
    fn preset_run(preset: &str) -> Result<SelfModelRun<Self>> {
        neurokin_run(preset)
    }
}

impl Studied for LinkSplatConfig {
    fn preset_run(preset: &str) -> Result<SelfModelRun<Self>> {
        link_splat_run(preset)
    }
}

impl Studied for ResNeuroKinDConfig {
    fn preset_run(preset: &str) -> Result<SelfModelRun<Self>> {
        resneurokin_d_run(preset)
    }
}

impl Studied for NearestPose {
    fn preset_run(preset: &str) -> Result<SelfModelRun<Self>> {
        nearest_pose_run(preset)
    }
}

impl Studied for MeanSilhouette {
    const LOWER_BOUND: bool = true;

    fn preset_run(preset: &str) -> Result<SelfModelRun<Self>> {
        mean_silhouette_run(preset)
    }
}

impl Studied for Ffksm {
    fn preset_run(preset: &str) -> Result<SelfModelRun<Self>> {
        ffksm_run(preset, FfksmVariant::Reimplementation)
    }

    /// Each row's note starts with its renderer's network evaluations per image;
    /// `renderers.csv`, `novel_views.csv` and `novel_views.png` from the accelerated marcher.
    fn reports(rows: &mut [ModelResult], ctx: &ReportContext<Self::Renderer>) -> Result<()> {
        ffksm_reports::write(rows, ctx)
    }
}

impl Studied for K3dgs {
    fn preset_run(preset: &str) -> Result<SelfModelRun<Self>> {
        k3dgs_run(preset, K3dgsVariant::Isotropic)
    }

    /// `render_speed.csv`, `gaussian_counts.csv` and `gaussians.png`.
    fn reports(_rows: &mut [ModelResult], ctx: &ReportContext<Self::Renderer>) -> Result<()> {
        k3dgs_reports::write(ctx)
    }
}
