//! The data a self-model run trains and tests on ([`DataSpec`]): the robot, the rendered
//! dataset (or a dataset file), the train and test splits.

use std::ops::Range;

use crate::core::error::{Error, Result};
use crate::core::preset::Preset;
use crate::data::dataset::{Dataset, DatasetConfig};
use crate::sim::camera::Camera;
use crate::sim::robot::Robot;
use crate::sim::robots::RobotSpec;

/// The data a run trains and tests on.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DataSpec {
    /// The robot seen (the papers' arm4 unless `robot`/`urdf` says otherwise).
    #[serde(default)]
    pub robot: RobotSpec,
    /// Rendered in-process (0.4 s for the paper's 2,000 samples).
    pub dataset: DatasetConfig,
    /// Train on only the first this-many samples of the training split.
    pub train_samples: Option<usize>,
    /// Test on these samples instead of the test split (indices into the dataset).
    pub test: Option<Range<usize>>,
    /// Train and test on this dataset file instead of rendering `dataset` (`dataset`: what
    /// the `dataset` binary writes, or silhouettes captured elsewhere in its format; the
    /// camera comes from its `poses` and `focal`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub file: Option<std::path::PathBuf>,
}

impl DataSpec {
    /// What of the data a checkpoint's fingerprint records: all of it, except the robot when
    /// it is the papers' arm4 (checkpoints from before the robot was recorded then still
    /// resume; any other robot is part of the fingerprint).
    pub fn fingerprint(&self) -> serde_json::Value {
        let mut print = serde_json::to_value(self).expect("a DataSpec serialises");
        if self.robot == RobotSpec::default()
            && let Some(fields) = print.as_object_mut()
        {
            fields.remove("robot");
        }
        print
    }

    /// The paper's 2,000-sample dataset (clean: no ground-plane artefact).
    pub fn paper() -> Self {
        DataSpec {
            robot: RobotSpec::default(),
            dataset: DatasetConfig::paper(),
            train_samples: None,
            test: None,
            file: None,
        }
    }

    /// The paper's dataset made large: 12,500 samples of the same Lorenz trajectory, the
    /// last 500 the test set (NeuroKin went from 25.2 dB on the paper's 1,600 training images
    /// to 28.9 dB on 9,600 in `ablation_data_scale`: data is what the simulator makes free).
    pub fn large() -> Self {
        let mut data = Self::paper();
        data.dataset.samples = 12_500;
        data.dataset.train = 12_000;
        data
    }

    /// The paper's 2,000 Lorenz samples (1,600 train) at 32x32 pixels, same camera and field
    /// of view (fewer samples would cover too little of the trajectory: 200 consecutive
    /// samples barely move the arm).
    pub fn quick() -> Self {
        let mut dataset = DatasetConfig::paper();
        dataset.preset = "quick".into();
        dataset.camera = Camera {
            width: 32,
            height: 32,
            ..Camera::paper()
        };
        DataSpec {
            robot: RobotSpec::default(),
            dataset,
            train_samples: None,
            test: None,
            file: None,
        }
    }

    /// `clean`, `paper_compatible` or `file` (a dataset read from `dataset`).
    pub fn label(&self) -> &'static str {
        if self.file.is_some() {
            "file"
        } else if self.dataset.render.ground_artifact {
            "paper_compatible"
        } else {
            "clean"
        }
    }

    /// Render the dataset and pick the train and test samples.
    pub fn load(&self) -> Result<(Dataset, Range<usize>, Range<usize>)> {
        self.load_with_robot()
            .map(|(_, data, train, test)| (data, train, test))
    }

    /// The camera `data` was rendered (or captured) with: the config's camera, unless it was
    /// framed automatically or read from a file (then the dataset's record of it).
    pub fn camera(&self, data: &Dataset) -> Camera {
        self.configured_camera()
            .cloned()
            .unwrap_or_else(|| data.camera())
    }

    /// The config's camera when the data is rendered from it as it stands: `None` when it is
    /// framed automatically or the data is read from a file (then only the dataset's record
    /// says where the camera was).
    pub fn configured_camera(&self) -> Option<&Camera> {
        (self.file.is_none() && self.dataset.framing.is_none()).then_some(&self.dataset.camera)
    }

    /// [`DataSpec::load`] with the robot it rendered (loaded once: a URDF reads its meshes).
    pub fn load_with_robot(&self) -> Result<(Robot, Dataset, Range<usize>, Range<usize>)> {
        let robot = self.robot.load()?;
        let data = match &self.file {
            Some(path) => {
                let data = Dataset::load(path)?;
                // A dataset that names its joints is read only with the robot that made it.
                let names = robot.chain.joint_names();
                if !data.joint_names.is_empty()
                    && !self.robot.is_papers_arm()
                    && data.joint_names != names
                {
                    return Err(Error::data(
                        path,
                        format!(
                            "its joints are [{}] but the robot description ({}) has [{}]: give the robot that made the dataset (`urdf`, `tip`, `joints`, `tips`)",
                            data.joint_names.join(", "),
                            self.robot.label(),
                            names.join(", ")
                        ),
                    ));
                }
                let empty = data.empty_images();
                if 2 * empty > data.len() {
                    return Err(Error::data(
                        path,
                        format!(
                            "{empty} of its {} silhouettes are empty: \"images\" must show the robot (uint8, 255 where it is)",
                            data.len()
                        ),
                    ));
                }
                data
            }
            None => {
                let data = Dataset::generate(&robot, &self.dataset, None)?;
                data.check_in_view()?;
                data
            }
        };
        let (train, test) = data.split();
        if train.is_empty() {
            return Err(Error::Config(format!(
                "the dataset{} has no training samples (n_train 0): a self-model needs some",
                self.file
                    .as_ref()
                    .map_or(String::new(), |f| format!(" {}", f.display()))
            )));
        }
        let train = match self.train_samples {
            Some(k) if k > train.len() => {
                return Err(Error::Config(format!(
                    "train_samples {k} is more than the {} training samples",
                    train.len()
                )));
            }
            Some(k) => train.start..train.start + k,
            None => train,
        };
        let test = self.test.clone().unwrap_or(test);
        if test.end > data.len() || test.is_empty() {
            return Err(Error::Config(format!(
                "test range {test:?} is outside the {} samples",
                data.len()
            )));
        }
        Ok((robot, data, train, test))
    }
}
