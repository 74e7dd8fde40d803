//! Errors per joint group (`groups.csv`): the joint vector cut into chains between the
//! kinematic tree's branch points ([`selfmodel::sim::kinematics::KinematicChain::input_chains`]):
//! on the G1's whole body the two legs, the waist and the two arms; on a serial arm one group.

use std::path::Path;

use serde::{Deserialize, Serialize};

use selfmodel::core::error::Result;
use selfmodel::report::table::{write_csv, write_markdown_report};
use selfmodel::sim::robot::Robot;

/// One method's errors on one joint group: a row of `groups.csv`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GroupRow {
    pub method: String,
    /// The group's first and last joints ("left_hip_pitch … left_ankle_roll").
    pub group: String,
    pub joints: usize,
    pub poses: usize,
    pub mean_joint_error_deg: f64,
    pub median_joint_error_deg: f64,
    /// Poses with every joint of the group within 2 degrees.
    pub within_2deg_share: f64,
}

/// The robot's joint groups: each its name and its joints (indices into the joint vector).
pub fn groups(robot: &Robot) -> Vec<(String, Vec<usize>)> {
    let names: Vec<String> = robot
        .chain
        .joint_names()
        .into_iter()
        .map(|n| n.strip_suffix("_joint").unwrap_or(&n).to_string())
        .collect();
    robot
        .chain
        .input_chains()
        .into_iter()
        .map(|chain| {
            let (first, last) = (chain[0], chain[chain.len() - 1]);
            let name = if first == last {
                names[first].clone()
            } else {
                format!("{} … {}", names[first], names[last])
            };
            (name, chain)
        })
        .collect()
}

/// The rows of `method`'s estimates `found` against `truth` (degrees), a row a group.
pub fn group_rows(
    method: &str,
    groups: &[(String, Vec<usize>)],
    found: &[Vec<f64>],
    truth: &[Vec<f64>],
) -> Vec<GroupRow> {
    groups
        .iter()
        .map(|(name, joints)| {
            let errors: Vec<Vec<f64>> = found
                .iter()
                .zip(truth)
                .map(|(f, t)| joints.iter().map(|&j| (f[j] - t[j]).abs()).collect())
                .collect();
            let all: Vec<f64> = errors.iter().flatten().copied().collect();
            let within = errors
                .iter()
                .filter(|e| e.iter().all(|&v| v <= 2.0))
                .count();
            GroupRow {
                method: method.into(),
                group: name.clone(),
                joints: joints.len(),
                poses: truth.len(),
                mean_joint_error_deg: all.iter().sum::<f64>() / all.len().max(1) as f64,
                median_joint_error_deg: selfmodel::core::timing::median(&all),
                within_2deg_share: within as f64 / truth.len().max(1) as f64,
            }
        })
        .collect()
}

/// `groups.csv` and its report in `out`.
pub fn write(rows: &[GroupRow], model: &str, out: &Path) -> Result<()> {
    let csv = out.join("groups.csv");
    write_csv(&csv, rows)?;
    write_markdown_report(
        &csv,
        "Joint angles from a silhouette, per joint group",
        &format!(
            "The clean test images' estimates of `results.csv`, read through {model}, scored per group of joints: the chains between the kinematic tree's branch points, named by their first and last joints. Absolute joint errors in degrees (mean and median over the group's joints of every pose); the share of poses with every joint of the group within 2 degrees. The mean training pose is the floor a method must beat."
        ),
    )
}
