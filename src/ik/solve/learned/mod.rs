//! A learned full-pose IK model people can keep and use: a conditional flow (IKFlow-style,
//! [`crate::ik::flow`]) conditioned on the target's position and orientation, trained on joint
//! samples drawn within the robot's limits, saved with the robot's fingerprint, joint names
//! and limits; answers refined to exact by Levenberg-Marquardt ([`crate::ik::solve::levenberg_marquardt`]).
//!
//! A saved model is a folder: `model.bpk` (the flow's weights), `model.json` ([`SavedModel`]:
//! the config, the robot as given and its fingerprint, joint names, ranges, the position
//! normalisation). The condition of a target: its position normalised per axis over the
//! training positions' bounds, then (unless the model is position-only) its unit quaternion
//! (w, x, y, z) with `w >= 0`.

mod answer;
mod columns;
mod conditions;
mod saved;
mod training;

use crate::core::preset::Preset;
use crate::ik::data::{IkData, IkDataConfig};
use crate::ik::flow::{FlowConfig, FlowIk};
use crate::ik::solve::levenberg_marquardt::LmConfig;

pub use answer::{SolveStats, distinct};
pub use columns::{
    MAX_TARGET_COORDINATE, joint_columns, read_targets, target_columns, target_from_values,
};
pub use saved::SavedModel;
pub use training::{WRITTEN, train};

/// How a pose model is trained and answers.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LearnedIkConfig {
    pub preset: String,
    /// Joint samples (drawn within the limits, narrowed to +-`range_deg`).
    pub data: IkDataConfig,
    pub flow: FlowConfig,
    /// Condition on the position only (the EMSSL paper's setting).
    pub position_only: bool,
    pub lm: LmConfig,
    /// Train on collision-free joint samples only (`ik train --scene`, `--self-collision`):
    /// the flow then proposes answers that keep clear. None: every sample within the limits.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub collisions: Option<TrainingCollisions>,
}

/// What the training samples keep clear of: the robot itself (always) and a scene, at a
/// margin, with the pairs of an SRDF (else the one beside the URDF, else computed) and a
/// user's spheres (else fitted), as `ik solve`'s collision options name them.
pub type TrainingCollisions = crate::ik::solve::collision::CollisionOptions;

impl Preset for LearnedIkConfig {
    /// 200,000 samples, the standard flow trained to a validation plateau or 100 epochs
    /// (about 25 s an epoch on 2 CPU cores).
    fn paper() -> Self {
        let mut flow = FlowConfig::standard();
        flow.fit.converge = Some(crate::train::convergence::Convergence {
            max_epochs: 100,
            ..crate::train::convergence::Convergence::standard()
        });
        LearnedIkConfig {
            preset: "paper".into(),
            data: IkDataConfig {
                samples: 210_000,
                train: 200_000,
                range_deg: 180.0,
                seed: 0,
                validation: 5_000,
            },
            flow,
            position_only: false,
            lm: LmConfig::standard(),
            collisions: None,
        }
    }

    /// 3,000 samples, a small flow, 5 epochs: seconds.
    fn quick() -> Self {
        let mut flow = FlowConfig::standard();
        flow.couplings = 4;
        flow.hidden = vec![32, 32];
        flow.fit.epochs = 5;
        flow.fit.converge = None;
        LearnedIkConfig {
            preset: "quick".into(),
            data: IkDataConfig {
                samples: 3_000,
                train: 2_900,
                range_deg: 180.0,
                seed: 0,
                validation: 0,
            },
            flow,
            position_only: false,
            lm: LmConfig::standard(),
            collisions: None,
        }
    }
}

/// A learned full-pose IK model, trained ([`train`]) or loaded ([`LearnedIk::load`]), ready to
/// answer ([`LearnedIk::solve`], or as any solver through
/// [`crate::ik::solve::solver::IkSolver`]).
pub struct LearnedIk {
    pub saved: SavedModel,
    pub flow: FlowIk,
    /// The data's normalisations (joints and positions), rebuilt from `saved`.
    data: IkData,
    /// Where the flow samples (the device it was loaded or trained on).
    device: burn::tensor::Device,
}
