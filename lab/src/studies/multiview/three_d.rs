//! The 3-D models (FFKSM and K-3DGS) on the first camera and on N cameras, each kept as a
//! unit, rendering the held-out cameras.

use std::path::Path;

use burn::tensor::Tensor;

use selfmodel::core::error::Result;
use selfmodel::data::dataset::Views;
use selfmodel::self_models::ffksm::{FfksmVariant, ffksm_run};
use selfmodel::self_models::harness::fit_run;
use selfmodel::self_models::k3dgs::{K3dgsVariant, k3dgs_run};

use super::{
    scoring::{Scoring, inputs, rendered, score, scored_renderer},
    units::{KeptUnit, UNIT, kept_unit, unit_fingerprint},
    {MultiviewConfig, MultiviewRow},
};

/// FFKSM (the original model) and K-3DGS trained on the first camera, and on each N of
/// `three_d_cameras` above 1: their rows and grid rows, each model kept as a unit.
#[allow(clippy::type_complexity)]
pub(super) fn three_d(
    cfg: &MultiviewConfig,
    opts: &crate::studies::run::RunOptions,
    out: &Path,
    revision: &str,
    device_name: &str,
) -> Result<(Vec<MultiviewRow>, Vec<(String, Vec<Vec<f32>>)>)> {
    let (mut rows, mut grid) = (Vec::new(), Vec::new());
    if !cfg.three_d {
        return Ok((rows, grid));
    }
    // On N cameras (N = 1: the dataset's own camera, as `ffksm` and `k3dgs` train).
    let views = |n: usize| {
        (n > 1).then_some(Views {
            cameras: n,
            radius: None,
            elevation_deg: cfg.elevation_deg,
        })
    };
    let suffix = |n: usize| {
        if n > 1 {
            format!("_{n}")
        } else {
            String::new()
        }
    };
    // One 3-D model on `n` cameras: trained (or continued from `checkpoint`), then scored on
    // the held-out cameras, rendering them in 3-D; kept as a unit in `unit`.
    let mut three_d_unit =
        |name: &str, n: usize, run: &dyn ThreeDRun, unit: &Path, resume: bool| -> Result<()> {
            let (scored, _) = kept_unit(unit, &run.fingerprint(cfg)?, opts.resume, || {
                let (fitted, robot, options) =
                    run.fit(&unit.join("checkpoint"), opts.device, resume)?;
                let renderer = scored_renderer(&fitted);
                let scored = score(
                    &Scoring {
                        cfg,
                        name,
                        n,
                        fitted: &fitted,
                        robot: &robot,
                        options: &options,
                        revision,
                        device_name,
                    },
                    &|camera, poses| {
                        let (x, width) = inputs(poses, None);
                        let view = |q: Tensor<2>| {
                            renderer
                                .render_view(camera, q)
                                .expect("a 3-D model renders any camera")
                        };
                        rendered(&view, &x, width, &fitted.device)
                    },
                    false,
                );
                Ok((scored, [fitted.data.height, fitted.data.width]))
            })?;
            rows.extend(scored.rows);
            grid.push((format!("{name} ({n})"), scored.grid_row));
            Ok(())
        };
    for &n in &cfg.three_d_cameras {
        let mut run = opts.apply(ffksm_run(&cfg.model_preset, FfksmVariant::Original)?)?;
        run.data.dataset.views = views(n);
        let unit = out.join(format!("ffksm_original{}", suffix(n)));
        let dir = unit.join("checkpoint");
        // The committed FFKSM (original model) of `ffksm`, where this preset trained it:
        // continued from its checkpoint instead of hours of training again.
        let carried = crate::workspace().join("reports/ffksm/ffksm_original/checkpoint_carried");
        let fingerprint = run.fingerprint(cfg)?;
        let kept = opts.resume
            && selfmodel::core::unit_cache::load::<KeptUnit>(&unit.join(UNIT), &fingerprint)
                .is_some();
        if n == 1 && cfg.model_preset == "paper" && !dir.exists() && carried.exists() && !kept {
            selfmodel::self_models::harness::copy_checkpoint(&carried, &dir)?;
        }
        let resume = opts.resume || (n == 1 && dir.exists());
        let name = run.name.clone();
        three_d_unit(&name, n, &run, &unit, resume)?;
        let mut run = opts.apply(k3dgs_run(&cfg.model_preset, K3dgsVariant::Anisotropic)?)?;
        run.data.dataset.views = views(n);
        // No comma: the docs pick rows by name.
        three_d_unit(
            "K-3DGS (anisotropic)",
            n,
            &run,
            &out.join(format!("k3dgs{}", suffix(n))),
            opts.resume,
        )?;
    }
    Ok((rows, grid))
}

/// A trained 3-D model with its robot and render options.
pub(super) type FittedScene = (
    selfmodel::self_models::harness::Fitted<Box<dyn selfmodel::Render>>,
    selfmodel::sim::robot::Robot,
    selfmodel::sim::ray_caster::RenderOptions,
);

/// A 3-D model's run, whichever model it is.
trait ThreeDRun {
    /// Train (or continue from `checkpoint`).
    fn fit(
        &self,
        checkpoint: &Path,
        device: selfmodel::core::device::DeviceChoice,
        resume: bool,
    ) -> Result<FittedScene>;
    /// What its kept unit must have been made with.
    fn fingerprint(&self, cfg: &MultiviewConfig) -> Result<serde_json::Value>;
}

impl<M: selfmodel::self_models::model::SelfModel> ThreeDRun
    for selfmodel::self_models::run_config::SelfModelRun<M>
{
    fn fit(
        &self,
        checkpoint: &Path,
        device: selfmodel::core::device::DeviceChoice,
        resume: bool,
    ) -> Result<FittedScene> {
        Ok((
            fit_run(self, checkpoint, device, resume)?.erased(),
            self.data.robot.load()?,
            self.data.dataset.render.clone(),
        ))
    }
    fn fingerprint(&self, cfg: &MultiviewConfig) -> Result<serde_json::Value> {
        unit_fingerprint(cfg, self)
    }
}
