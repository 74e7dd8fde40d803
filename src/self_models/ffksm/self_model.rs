//! FFKSM as a [`SelfModel`]: loading and fitting (the field framed to the scene).

use std::sync::Arc;

use burn::module::Module;

use crate::core::device::DeviceChoice;
use crate::core::error::{Error, Result};
use crate::self_models::ffksm::accelerated_marcher::AcceleratedConfig;
use crate::self_models::ffksm::virtual_frame::{JointsFrame, VirtualFrame};
use crate::self_models::{
    data_spec::DataSpec,
    model::{Fit, LoadContext, Loaded, SelfModel, Trained},
};
use crate::sim::camera::Camera;
use crate::train::config::TrainConfig;

use super::{
    config::{DenseGradients, Ffksm, TrainMarcher},
    renderer::{FfksmRenderer, FfksmShared, FfksmState, PAPERS_ARM_REACH_M},
    training::{fingerprint, train_field},
};

impl SelfModel for Ffksm {
    const KIND: &'static str = "ffksm";
    type Renderer = FfksmRenderer;

    fn image(&self) -> [usize; 2] {
        self.image
    }

    fn fingerprint(&self, train: &TrainConfig, data: &DataSpec) -> serde_json::Value {
        fingerprint(self, train, data)
    }

    fn dof(&self) -> Option<usize> {
        Some(self.field.dof)
    }

    fn needs_robot(&self) -> bool {
        true
    }

    fn renders_any_view(&self) -> bool {
        true
    }

    fn set_dof(&mut self, dof: usize) {
        self.field.dof = dof;
    }

    /// Its field, as fitted to the scene, marched by the renderer it was saved with, on the
    /// robot and from the camera it was trained with.
    fn load(&self, weights: &std::path::Path, ctx: &LoadContext) -> Result<Loaded> {
        let state: FfksmState = serde_json::from_value(ctx.state.clone())
            .map_err(|e| Error::data(weights, format!("its saved state: {e}")))?;
        let robot = ctx
            .robot
            .ok_or_else(|| Error::Config("FFKSM loads with its robot".into()))?;
        let field = crate::train::checkpoint::load_module(
            state.fitted.field.init(ctx.device, 0)?,
            weights,
        )?;
        let shared = Arc::new(FfksmShared {
            field,
            model: state.fitted,
            camera: ctx.camera.clone(),
            robot: robot.clone(),
            device: ctx.device.clone(),
            stats: Default::default(),
        });
        Ok(Some(Box::new(FfksmRenderer {
            shared,
            accelerated: state.accelerated,
            label: state.label,
        })))
    }

    /// Train the field; it renders two ways: dense marching (the paper's) and the
    /// accelerated marcher.
    fn fit(&self, fit: &Fit) -> Result<Trained<FfksmRenderer>> {
        let (this, marched) = self.fitted_to_scene(fit);
        let this = &this;
        let hand_written = this.dense_gradients == DenseGradients::HandWrittenOnCpu
            && matches!(fit.device_choice, DeviceChoice::Cpu | DeviceChoice::Ndarray);
        let (field, log, restarts, train_evals) = train_field(this, fit.label, fit, hand_written)?;
        let mut note = marched.into_iter().collect::<Vec<_>>();
        note.push(format!(
            "trained with {} marching, {train_evals:.0} evaluations per step",
            match self.train_marcher {
                TrainMarcher::Dense if hand_written => "dense (hand-written gradients)",
                TrainMarcher::Dense => "dense",
                TrainMarcher::Skipping => "skipping",
            }
        ));
        if restarts > 0 {
            note.push(format!("{restarts} restarts after collapse"));
        }
        if this
            .restart
            .as_ref()
            .is_some_and(|r| r.max_restarts > 0 && restarts >= r.max_restarts)
        {
            note.push("the last try trained without the collapse check".into());
        }
        let shared = Arc::new(FfksmShared {
            field,
            model: this.clone(),
            camera: fit.camera.clone(),
            robot: fit.robot.clone(),
            device: fit.device.clone(),
            stats: Default::default(),
        });
        let renderer = |accelerated: Option<AcceleratedConfig>, label: &str| FfksmRenderer {
            shared: shared.clone(),
            accelerated,
            label: label.to_string(),
        };
        Ok(Trained {
            parameters: shared.field.num_params(),
            renderers: [
                this.reference_renderers
                    .then(|| ("dense marching".into(), renderer(None, "dense marching"))),
                Some((
                    "accelerated".into(),
                    renderer(Some(this.accelerated.clone()), "accelerated"),
                )),
            ]
            .into_iter()
            .flatten()
            .collect(),
            log,
            note: note.join("; "),
        })
    }
}

impl Ffksm {
    /// This config for the scene `fit` renders: as it is for the papers' camera; for any other
    /// camera (a robot framed automatically), rays are marched over the depths the robot
    /// occupies over its training poses, 5% wider each way, instead of the papers' [0.6, 1.4]
    /// m (and the row's note says so).
    fn fitted_to_scene(&self, fit: &Fit) -> (Ffksm, Option<String>) {
        let paper = Camera::paper();
        let c = fit.camera;
        if (c.eye, c.target, c.up, c.fov_deg) == (paper.eye, paper.target, paper.up, paper.fov_deg)
        {
            return (self.clone(), None);
        }
        let [n, dof] = fit.train_set.inputs.dims();
        let user: Vec<f32> = fit
            .train_set
            .inputs
            .clone()
            .into_data()
            .convert::<f32>()
            .try_to_vec::<f32>()
            .expect("float inputs");
        let si: Vec<Vec<f64>> = user
            .chunks(dof.max(1))
            .take(n)
            .map(|q| {
                fit.robot
                    .chain
                    .to_si(&q.iter().map(|&v| v as f64).collect::<Vec<_>>())
            })
            .collect();
        let frame = c.frame();
        // The robot's points over its training poses: their depths and their reach.
        let points = crate::data::dataset::swept_points(fit.robot, &si);
        let depths: Vec<f64> = points
            .iter()
            .filter_map(|p| frame.project(p).map(|(_, _, z)| z))
            .collect();
        let (lo, hi) = depths
            .iter()
            .fold((f64::INFINITY, 0f64), |(l, h), &z| (l.min(z), h.max(z)));
        if !(lo.is_finite() && hi > lo) {
            return (self.clone(), None);
        }
        let pad = 0.05 * (hi - lo);
        let mut this = self.clone();
        // The papers' arm reaches about 0.45 m from the origin: shrink the scene to that.
        let reach = points.iter().map(|p| p.coords.norm()).fold(0f64, f64::max);
        this.scene_scale = (reach / PAPERS_ARM_REACH_M).max(1e-6);
        this.march.near = (lo - pad).max(1e-3) / this.scene_scale;
        this.march.far = (hi + pad) / this.scene_scale;
        let mut said = format!(
            "rays marched over depths {:.3} to {:.3} m (where the robot is), the scene shrunk {:.2}x about the base for the field",
            (lo - pad).max(1e-3),
            hi + pad,
            this.scene_scale
        );
        // The robot's own first two joints, with their axes and pivots, set the virtual frame.
        match JointsFrame::of_chain(&fit.robot.chain, this.scene_scale) {
            Some(frame) => {
                this.field.virtual_frame = VirtualFrame::Joints(frame);
                said += "; the virtual frame is the robot's first two joints'";
            }
            None => {
                said +=
                    "; the paper's virtual frame (the first two joints do not alone place a link)"
            }
        }
        (this, Some(said))
    }

    /// `camera` in the field's units (shrunk by [`Ffksm::scene_scale`] about the origin): the
    /// same image, every depth divided by the scale.
    pub(super) fn field_camera(&self, camera: &Camera) -> Camera {
        let shrink = |v: [f64; 3]| v.map(|x| x / self.scene_scale);
        Camera {
            eye: shrink(camera.eye),
            target: shrink(camera.target),
            ..camera.clone()
        }
    }
}
