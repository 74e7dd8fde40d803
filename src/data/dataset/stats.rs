//! What the stats JSON beside a dataset holds: occupancy, joint ranges, depth, border and empty
//! images.

use serde::{Deserialize, Serialize};

use super::Dataset;

/// Min, max, mean and standard deviation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    pub min: f64,
    pub max: f64,
    pub mean: f64,
    pub std: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct JointStats {
    pub name: String,
    pub degrees: Summary,
}

/// What the stats JSON holds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DatasetStats {
    pub samples: usize,
    pub train: usize,
    pub test: usize,
    pub width: usize,
    pub height: usize,
    pub focal_px: f64,
    /// Fraction of robot pixels per image.
    pub occupancy: Summary,
    pub joints: Vec<JointStats>,
    /// Depth of robot pixels (m).
    pub depth_m: Option<Summary>,
    /// Images in which the robot touches the image border (it may be cut off), and those in
    /// which it is not seen at all.
    #[serde(default)]
    pub border_images: usize,
    #[serde(default)]
    pub empty_images: usize,
}

impl Dataset {
    /// Summary statistics (the stats JSON beside a dataset).
    pub fn stats(&self, joint_names: &[String]) -> DatasetStats {
        let n = self.len();
        let occ: Vec<f64> = (0..n)
            .map(|i| {
                self.image(i).iter().filter(|&&v| v >= 128).count() as f64
                    / (self.width * self.height) as f64
            })
            .collect();
        let summary = |v: &[f64]| {
            let mean = v.iter().sum::<f64>() / v.len() as f64;
            let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / v.len() as f64;
            Summary {
                min: v.iter().cloned().fold(f64::INFINITY, f64::min),
                max: v.iter().cloned().fold(f64::NEG_INFINITY, f64::max),
                mean,
                std: var.sqrt(),
            }
        };
        let joints = (0..self.dof())
            .map(|j| {
                let col: Vec<f64> = self.angles.iter().map(|q| q[j]).collect();
                JointStats {
                    name: joint_names
                        .get(j)
                        .cloned()
                        .unwrap_or_else(|| format!("joint{j}")),
                    degrees: summary(&col),
                }
            })
            .collect();
        let hits: Vec<f64> = self
            .depth
            .iter()
            .filter(|&&d| d > 0.0)
            .map(|&d| d as f64)
            .collect();
        let (w, h) = (self.width, self.height);
        let on_border = |img: &[u8]| {
            (0..w).any(|c| img[c] > 0 || img[(h - 1) * w + c] > 0)
                || (0..h).any(|r| img[r * w] > 0 || img[r * w + w - 1] > 0)
        };
        let border_images = (0..n).filter(|&i| on_border(self.image(i))).count();
        let empty_images = (0..n)
            .filter(|&i| self.image(i).iter().all(|&v| v == 0))
            .count();
        DatasetStats {
            border_images,
            empty_images,
            samples: n,
            train: self.n_train,
            test: n - self.n_train,
            width: self.width,
            height: self.height,
            focal_px: self.focal,
            occupancy: summary(&occ),
            joints,
            depth_m: if hits.is_empty() {
                None
            } else {
                Some(summary(&hits))
            },
        }
    }
}
