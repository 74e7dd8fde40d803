//! Kinematic chains (trees) on nalgebra and their forward kinematics.
//!
//! Joint values are in SI units inside the library: radians for revolute and continuous
//! joints, metres for prismatic ones. Datasets and command lines use degrees for rotational
//! joints; [`KinematicChain::to_si`] and [`KinematicChain::from_si`] convert.

use nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};
use rayon::prelude::*;

use crate::core::error::{Error, Result};

/// The URDF joint types the simulator supports.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum JointKind {
    Revolute,
    Continuous,
    Prismatic,
    Fixed,
}

impl JointKind {
    /// Whether the joint has a joint value (everything but `Fixed`).
    pub fn is_movable(self) -> bool {
        self != JointKind::Fixed
    }
    /// Whether the joint value is an angle.
    pub fn is_rotational(self) -> bool {
        matches!(self, JointKind::Revolute | JointKind::Continuous)
    }
}

/// One joint: the child link's frame is `parent * origin * motion(q)`.
#[derive(Clone, Debug)]
pub struct Joint {
    pub name: String,
    pub kind: JointKind,
    /// Index of the parent link.
    pub parent: usize,
    /// Index of the child link.
    pub child: usize,
    /// Pose of the joint frame in the parent link's frame.
    pub origin: Isometry3<f64>,
    /// Rotation or translation axis in the joint frame.
    pub axis: Unit<Vector3<f64>>,
    /// Position limits in SI units, where the robot states them.
    pub limits: Option<[f64; 2]>,
    /// A URDF `<mimic>`: this joint's value is `multiplier * leader + offset`, not an input.
    pub mimic: Option<Mimic>,
}

/// A joint that follows another (URDF `<mimic joint multiplier offset>`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mimic {
    /// Index of the leader joint, in the list given to [`KinematicChain::new`] (afterwards in
    /// [`KinematicChain::joints`]).
    pub leader: usize,
    pub multiplier: f64,
    pub offset: f64,
}

/// Where a joint's value comes from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum JointValue {
    /// A fixed joint: no value.
    Fixed,
    /// `scale * q[index] + offset` of the joint vector `q` (an input: scale 1, offset 0; a
    /// mimic joint of an input: its multiplier and offset).
    Input {
        index: usize,
        scale: f64,
        offset: f64,
    },
    /// A movable joint held still: off the chain from the root to the tip (a Panda's fingers
    /// when the tip is its hand), or a mimic of one.
    Held(f64),
}

impl JointValue {
    /// The value for the joint vector `q` (SI); 0 for a fixed joint.
    pub fn of(self, q: &[f64]) -> f64 {
        match self {
            JointValue::Fixed => 0.0,
            JointValue::Input {
                index,
                scale,
                offset,
            } => scale * q[index] + offset,
            JointValue::Held(v) => v,
        }
    }
}

impl Joint {
    /// The joint's motion for value `q` (SI).
    pub fn motion(&self, q: f64) -> Isometry3<f64> {
        match self.kind {
            JointKind::Revolute | JointKind::Continuous => Isometry3::from_parts(
                Translation3::identity(),
                UnitQuaternion::from_axis_angle(&self.axis, q),
            ),
            JointKind::Prismatic => Isometry3::from_parts(
                Translation3::from(self.axis.into_inner() * q),
                UnitQuaternion::identity(),
            ),
            JointKind::Fixed => Isometry3::identity(),
        }
    }
}

/// Sampling range of rotational joints the robot gives no limits for (continuous joints):
/// +-90 degrees, the workspace of both self-modeling papers.
pub const DEFAULT_ROTATIONAL_RANGE: [f64; 2] =
    [-std::f64::consts::FRAC_PI_2, std::f64::consts::FRAC_PI_2];

/// `limits` narrowed to `[-half, half]` where that is tighter. An end the limits leave wider
/// (within 1e-9) is exactly `-half` or `half`, so a robot without tighter limits samples the
/// very numbers it sampled before limits were read.
pub fn narrow(limits: [f64; 2], half: f64) -> [f64; 2] {
    let lo = if limits[0] > -half + 1e-9 {
        limits[0]
    } else {
        -half
    };
    let hi = if limits[1] < half - 1e-9 {
        limits[1]
    } else {
        half
    };
    [lo, hi]
}

/// A rotational joint's limits as one turn of values: as stated when they span a turn or
/// less; wider, `[-pi, pi]` where they hold it (a wider range repeats poses), else the turn
/// from the lower limit.
pub fn one_turn(limits: [f64; 2]) -> [f64; 2] {
    use std::f64::consts::PI;
    if limits[1] - limits[0] <= 2.0 * PI + 1e-9 {
        limits
    } else if limits[0] <= -PI + 1e-9 && limits[1] >= PI - 1e-9 {
        [-PI, PI]
    } else {
        [limits[0], limits[0] + 2.0 * PI]
    }
}

/// Whether `q` lies within `ranges` (with `tol` of slack, SI units).
pub fn within(q: &[f64], ranges: &[[f64; 2]], tol: f64) -> bool {
    q.iter()
        .zip(ranges)
        .all(|(&v, r)| v >= r[0] - tol && v <= r[1] + tol)
}

/// Which movable joints of a tree make the joint vector; the others are held.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JointGroup {
    /// The chain from the root to the tip (`--tip`; the default).
    #[default]
    Chain,
    /// The union of the chains from the root to each of these links (`--tips A,B`: both
    /// hands of a humanoid, with the waist they share).
    Tips(Vec<String>),
    /// Every movable joint of the tree (`--joints all`).
    All,
    /// These joints, by name (`--joints a,b,c`), in the tree's order whatever order they are
    /// named in.
    Named(Vec<String>),
    /// A planning group of an SRDF file (`--group NAME`, MoveIt's format; the file beside
    /// the URDF or `--srdf FILE`): the joints it lists and those of its links, chains and
    /// subgroups; its chains' tip links are its tips. Resolved when the description is
    /// loaded ([`crate::sim::srdf`]) into [`JointGroup::Members`].
    Srdf {
        file: std::path::PathBuf,
        group: String,
    },
    /// Joints by name with these links as the tips (what an SRDF group resolves to): fixed
    /// joints among them are skipped, a mimic joint makes its leader an input, and one tip is
    /// the tip (unless `--tip` names another).
    Members {
        joints: Vec<String>,
        tips: Vec<String>,
    },
}

impl JointGroup {
    pub fn is_chain(&self) -> bool {
        *self == JointGroup::Chain
    }

    /// `--joints`, `--tips` and `--group` (with `--srdf`, else the SRDF file beside the
    /// description at `urdf`) as given on a command line (none: the chain to the tip).
    pub fn from_args(
        joints: Option<&[String]>,
        tips: Option<&[String]>,
        group: Option<&str>,
        srdf: Option<&std::path::Path>,
        urdf: Option<&std::path::Path>,
    ) -> Result<Self> {
        if let Some(group) = group {
            if joints.is_some() || tips.is_some() {
                return Err(Error::Config(
                    "--group, --joints and --tips name the joint vector in different ways: give one"
                        .into(),
                ));
            }
            let file = match (srdf, urdf) {
                (Some(file), _) => file.to_path_buf(),
                (None, Some(urdf)) => crate::sim::srdf::find_beside(urdf)?,
                (None, None) => {
                    return Err(Error::Config(
                        "--group needs a robot description (--urdf)".into(),
                    ));
                }
            };
            return Ok(JointGroup::Srdf {
                file,
                group: group.to_string(),
            });
        }
        if srdf.is_some() {
            // As the command line reads it (and Python the same way): the file of a group.
            return Err(Error::Config(
                "--srdf names the SRDF file of --group: give --group too".into(),
            ));
        }
        match (joints, tips) {
            (Some(_), Some(_)) => Err(Error::Config(
                "--joints and --tips name the joint vector two ways: give one".into(),
            )),
            (Some([all]), None) if all == "all" => Ok(JointGroup::All),
            (Some(names), None) if !names.is_empty() => Ok(JointGroup::Named(names.to_vec())),
            (None, Some(tips)) if !tips.is_empty() => Ok(JointGroup::Tips(tips.to_vec())),
            (None, None) => Ok(JointGroup::Chain),
            _ => Err(Error::Config(
                "--joints and --tips need at least one name".into(),
            )),
        }
    }
}

/// A `--tip` given beside a group with tips must be one of them: another would train the
/// group's joints for a link they were not chosen for.
fn refuse_another_tip(
    given: bool,
    tip: usize,
    tips: &[usize],
    links: &[&String],
    group: &str,
) -> Result<()> {
    if !given || tips.is_empty() || tips.contains(&tip) {
        return Ok(());
    }
    let names: Vec<&str> = tips.iter().map(|&t| links[t].as_str()).collect();
    Err(Error::Config(format!(
        "--tip \"{}\" is not a tip of {group} ({}): name one of them, or leave --tip out",
        links[tip],
        names.join(", ")
    )))
}

/// Each joint's place in a depth-first walk of the tree from the root (link 0), a link's
/// child joints taken in the order they were given (`given[j]`: joint `j`'s index as given).
fn depth_first_rank(joints: &[Joint], given: &[usize]) -> Vec<usize> {
    let children = |link: usize| {
        let mut c: Vec<usize> = (0..joints.len())
            .filter(|&j| joints[j].parent == link)
            .collect();
        c.sort_by_key(|&j| given[j]);
        c
    };
    let mut rank = vec![usize::MAX; joints.len()];
    let mut stack: Vec<usize> = children(0).into_iter().rev().collect();
    let mut next = 0;
    while let Some(j) = stack.pop() {
        rank[j] = next;
        next += 1;
        stack.extend(children(joints[j].child).into_iter().rev());
    }
    rank
}

/// A tree of links connected by joints, placed in the scene by `base`.
#[derive(Clone, Debug)]
pub struct KinematicChain {
    /// Link names; index 0 is the root.
    pub links: Vec<String>,
    /// Joints in an order where every parent link comes before its child.
    pub joints: Vec<Joint>,
    /// Pose of the root link in the world (the scene placement).
    pub base: Isometry3<f64>,
    /// The end effector: a point in the frame of a link.
    pub tip_link: usize,
    pub tip_offset: Point3<f64>,
    /// The links a [`JointGroup::Tips`] group names (their origins are its tips, see
    /// [`Self::tips`]); empty for every other group.
    group_tips: Vec<usize>,
    /// Indices into `joints` of the inputs, in the order of the joint vector.
    dofs: Vec<usize>,
    /// For each joint, where its value comes from.
    values: Vec<JointValue>,
}

impl KinematicChain {
    /// Build a chain from links and joints given in any order. The root is the one link that
    /// is no joint's child; joints are sorted parent-first. `tip` defaults to the origin of
    /// the last link of the longest path from the root.
    ///
    /// The joint vector (the inputs) is the movable joints on the path from the root to the
    /// tip that mimic no other, and the leaders of mimic joints on it, in depth-first order
    /// from the root with each link's children in the order given (root to tip along a chain,
    /// whatever order the URDF lists them in), as Pinocchio, KDL and TRAC-IK order them.
    /// A mimic joint follows its leader; a movable joint off that path is held at 0, or at
    /// the limit nearest 0 when 0 is outside its limits.
    pub fn new(
        links: Vec<String>,
        joints: Vec<Joint>,
        base: Isometry3<f64>,
        tip: Option<(usize, Point3<f64>)>,
    ) -> Result<Self> {
        Self::with_group(links, joints, base, tip, &JointGroup::Chain)
    }

    /// [`Self::new`] with the joint vector `group` names: the chain to the tip, the chains
    /// to several links, every movable joint, or joints by name; the joint vector keeps the
    /// depth-first order, and the movable joints outside it are held.
    pub fn with_group(
        links: Vec<String>,
        joints: Vec<Joint>,
        base: Isometry3<f64>,
        tip: Option<(usize, Point3<f64>)>,
        group: &JointGroup,
    ) -> Result<Self> {
        let n = links.len();
        if n == 0 {
            return Err(Error::Config("a robot needs at least one link".into()));
        }
        let mut parent_joint = vec![None; n];
        for (j, joint) in joints.iter().enumerate() {
            if joint.parent >= n || joint.child >= n {
                return Err(Error::Config(format!(
                    "joint \"{}\": link index out of range",
                    joint.name
                )));
            }
            if parent_joint[joint.child].replace(j).is_some() {
                return Err(Error::Config(format!(
                    "link \"{}\" is the child of two joints",
                    links[joint.child]
                )));
            }
        }
        let roots: Vec<usize> = (0..n).filter(|&l| parent_joint[l].is_none()).collect();
        if roots.is_empty() {
            return Err(Error::Config(
                "the links must form one tree, but every link is some joint's child: the joints form a cycle".into(),
            ));
        }
        if roots.len() != 1 {
            return Err(Error::Config(format!(
                "the links must form one tree, found {} roots: {}",
                roots.len(),
                roots
                    .iter()
                    .map(|&r| links[r].as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        }
        // Breadth-first from the root; reorder links so the root is 0.
        let root = roots[0];
        let mut order_links = vec![root];
        let mut order_joints = Vec::with_capacity(joints.len());
        let mut depth = vec![0usize; n];
        let mut i = 0;
        while i < order_links.len() {
            let l = order_links[i];
            for (j, joint) in joints.iter().enumerate() {
                if joint.parent == l {
                    depth[joint.child] = depth[l] + 1;
                    order_links.push(joint.child);
                    order_joints.push(j);
                }
            }
            i += 1;
        }
        if order_links.len() != n {
            return Err(Error::Config("the joints contain a cycle".into()));
        }
        let mut new_index = vec![0; n];
        for (new, &old) in order_links.iter().enumerate() {
            new_index[old] = new;
        }
        let deepest = (0..n).max_by_key(|&l| (depth[l], l)).unwrap_or(root);
        let joints: Vec<Joint> = order_joints
            .iter()
            .map(|&j| {
                let mut joint = joints[j].clone();
                joint.parent = new_index[joint.parent];
                joint.child = new_index[joint.child];
                joint
            })
            .collect();
        let (mut tip_link, mut tip_offset) = match tip {
            Some((l, p)) => (new_index[l], p),
            None => (new_index[deepest], Point3::origin()),
        };
        // The group's joints (indices into the sorted joints): the joints on the path from
        // the root to the tip, or to each of several links, every joint, or joints by name.
        let mut on_path = vec![false; joints.len()];
        let mut mark_path = |mut link: usize| {
            while let Some(j) = joints.iter().position(|j| j.child == link) {
                on_path[j] = true;
                link = joints[j].parent;
            }
        };
        let sorted_links: Vec<&String> = order_links.iter().map(|&l| &links[l]).collect();
        let mut group_tips = Vec::new();
        match group {
            JointGroup::Chain => mark_path(tip_link),
            JointGroup::Tips(tips) => {
                for t in tips {
                    let l = sorted_links.iter().position(|l| *l == t).ok_or_else(|| {
                        Error::Config(format!(
                            "--tips: \"{t}\" is not a link of this robot; its links: {}",
                            sorted_links
                                .iter()
                                .map(|l| l.as_str())
                                .collect::<Vec<_>>()
                                .join(", ")
                        ))
                    })?;
                    if group_tips.contains(&l) {
                        return Err(Error::Config(format!("--tips names \"{t}\" twice")));
                    }
                    mark_path(l);
                    group_tips.push(l);
                }
                refuse_another_tip(
                    tip.is_some(),
                    tip_link,
                    &group_tips,
                    &sorted_links,
                    "--tips",
                )?;
            }
            JointGroup::All => on_path.iter_mut().for_each(|p| *p = true),
            JointGroup::Named(names) => {
                for name in names {
                    let j = joints
                        .iter()
                        .position(|j| &j.name == name && j.kind.is_movable() && j.mimic.is_none())
                        .ok_or_else(|| {
                            Error::Config(format!(
                                "--joints: \"{name}\" is not a movable joint of this robot (mimic joints follow their leader); its movable joints: {}",
                                joints
                                    .iter()
                                    .filter(|j| j.kind.is_movable() && j.mimic.is_none())
                                    .map(|j| j.name.as_str())
                                    .collect::<Vec<_>>()
                                    .join(", ")
                            ))
                        })?;
                    on_path[j] = true;
                }
            }
            JointGroup::Members {
                joints: names,
                tips,
            } => {
                for name in names {
                    let j = joints.iter().position(|j| &j.name == name).ok_or_else(|| {
                        Error::Config(format!("group: \"{name}\" is not a joint of this robot"))
                    })?;
                    on_path[j] = true;
                }
                for t in tips {
                    let l = sorted_links.iter().position(|l| *l == t).ok_or_else(|| {
                        Error::Config(format!(
                            "group: its tip \"{t}\" is not a link of this robot"
                        ))
                    })?;
                    group_tips.push(l);
                }
                refuse_another_tip(
                    tip.is_some(),
                    tip_link,
                    &group_tips,
                    &sorted_links,
                    "the group",
                )?;
                if group_tips.len() == 1 {
                    if tip.is_none() {
                        (tip_link, tip_offset) = (group_tips[0], Point3::origin());
                    }
                    group_tips.clear();
                }
            }
            JointGroup::Srdf { file, group } => {
                return Err(Error::Config(format!(
                    "group \"{group}\" of {}: an SRDF group is resolved as its description loads (urdf_loader)",
                    file.display()
                )));
            }
        }
        // Where mimic leaders went in the sorted order.
        let mut sorted_of = vec![0; joints.len()];
        for (new, &old) in order_joints.iter().enumerate() {
            sorted_of[old] = new;
        }
        let mut joints = joints;
        for j in joints.iter_mut() {
            if let Some(m) = &mut j.mimic {
                if m.leader >= sorted_of.len() {
                    return Err(Error::Config(format!(
                        "joint \"{}\": mimics a joint index out of range",
                        j.name
                    )));
                }
                m.leader = sorted_of[m.leader];
            }
        }
        // A mimic joint on the path makes its leader (followed to the joint that mimics no
        // other) an input, wherever that leader is.
        let mut drives_tip = on_path.clone();
        for j in 0..joints.len() {
            if !on_path[j] {
                continue;
            }
            let mut k = j;
            let mut hops = 0;
            while let Some(m) = joints[k].mimic {
                k = m.leader;
                hops += 1;
                if hops > joints.len() {
                    break;
                }
            }
            drives_tip[k] = true;
        }
        // The inputs in depth-first order from the root, children in the order the joints
        // were given in (as Pinocchio and KDL order a tree): root to tip along a chain, however
        // the file lists them.
        let rank = depth_first_rank(&joints, &order_joints);
        let mut dofs: Vec<usize> = (0..joints.len())
            .filter(|&j| joints[j].kind.is_movable() && joints[j].mimic.is_none() && drives_tip[j])
            .collect();
        dofs.sort_by_key(|&j| rank[j]);
        let held = |joint: &Joint| {
            let [lo, hi] = joint.limits.unwrap_or([f64::NEG_INFINITY, f64::INFINITY]);
            0f64.clamp(lo, hi)
        };
        let mut values: Vec<Option<JointValue>> = joints
            .iter()
            .map(|j| (!j.kind.is_movable()).then_some(JointValue::Fixed))
            .collect();
        for (k, &j) in dofs.iter().enumerate() {
            values[j] = Some(JointValue::Input {
                index: k,
                scale: 1.0,
                offset: 0.0,
            });
        }
        for j in 0..joints.len() {
            if values[j].is_none() && joints[j].mimic.is_none() {
                values[j] = Some(JointValue::Held(held(&joints[j])));
            }
        }
        // Mimic joints, following chains of leaders (a cycle is an error).
        for j in 0..joints.len() {
            let mut path = vec![j];
            while values[*path.last().unwrap()].is_none() {
                let m = joints[*path.last().unwrap()]
                    .mimic
                    .expect("unset joints mimic");
                if path.contains(&m.leader) {
                    return Err(Error::Config(format!(
                        "joint \"{}\": its <mimic> leaders form a cycle",
                        joints[j].name
                    )));
                }
                path.push(m.leader);
            }
            let mut value = values[path.pop().unwrap()].unwrap();
            while let Some(f) = path.pop() {
                let m = joints[f].mimic.unwrap();
                value = match value {
                    JointValue::Input {
                        index,
                        scale,
                        offset,
                    } => JointValue::Input {
                        index,
                        scale: m.multiplier * scale,
                        offset: m.multiplier * offset + m.offset,
                    },
                    JointValue::Held(v) => JointValue::Held(m.multiplier * v + m.offset),
                    JointValue::Fixed => JointValue::Held(m.offset),
                };
                values[f] = Some(value);
            }
        }
        let values = values
            .into_iter()
            .map(|v| v.expect("every joint set"))
            .collect();
        Ok(KinematicChain {
            links: order_links.iter().map(|&l| links[l].clone()).collect(),
            joints,
            base,
            tip_link,
            tip_offset,
            group_tips,
            dofs,
            values,
        })
    }

    /// Number of joint values (movable joints).
    pub fn dof(&self) -> usize {
        self.dofs.len()
    }

    /// The index in the joint vector of joint `j` (of [`Self::joints`]) when it is an input;
    /// `None` when it is fixed, held or a mimic.
    pub fn value_index(&self, j: usize) -> Option<usize> {
        match self.values[j] {
            JointValue::Input {
                index,
                scale: 1.0,
                offset: 0.0,
            } if self.joints[j].mimic.is_none() => Some(index),
            _ => None,
        }
    }

    /// Where joint `j`'s value comes from (of [`Self::joints`]).
    pub fn joint_value(&self, j: usize) -> JointValue {
        self.values[j]
    }

    /// The input joints, in joint-vector order.
    pub fn movable_joints(&self) -> impl Iterator<Item = &Joint> {
        self.dofs.iter().map(|&j| &self.joints[j])
    }

    /// The input joints' names, in joint-vector order.
    pub fn joint_names(&self) -> Vec<String> {
        self.movable_joints().map(|j| j.name.clone()).collect()
    }

    /// The joint vector as a tree: for each input, the nearest input above it on the way to
    /// the root (its index in the joint vector), `None` for one with no input above it.
    pub fn input_parents(&self) -> Vec<Option<usize>> {
        self.dofs
            .iter()
            .map(|&j| {
                let mut link = self.joints[j].parent;
                while let Some(p) = self.joints.iter().position(|k| k.child == link) {
                    if let Some(i) = self.dofs.iter().position(|&d| d == p) {
                        return Some(i);
                    }
                    link = self.joints[p].parent;
                }
                None
            })
            .collect()
    }

    /// Sampling range of each joint value (SI): the stated limits (a rotational joint's
    /// narrowed to +-180 degrees: a wider range repeats poses), else
    /// [`DEFAULT_ROTATIONAL_RANGE`] for rotational joints without limits. A prismatic joint
    /// without limits has none to sample: `[0, 0]`.
    pub fn joint_ranges(&self) -> Vec<[f64; 2]> {
        self.movable_joints()
            .map(|j| match (j.limits, j.kind.is_rotational()) {
                (Some(l), true) => narrow(l, std::f64::consts::PI),
                (Some(l), false) => l,
                (None, true) => DEFAULT_ROTATIONAL_RANGE,
                (None, false) => [0.0, 0.0],
            })
            .collect()
    }

    /// The ranges of the inverse-kinematics experiments: each joint's limits narrowed to
    /// `+-half` (radians) where that is tighter; a rotational joint without limits gets
    /// `[-half, half]`, a prismatic one its limits. At `half` of a half turn or more (every
    /// pose the joint can take) a rotational joint keeps limits within one turn as stated,
    /// wherever they lie ([`one_turn`]): limits offset around pi, `[0.82, 5.46]`, are not cut
    /// at pi.
    pub fn ranges_within(&self, half: f64) -> Vec<[f64; 2]> {
        let full_turn = half >= std::f64::consts::PI - 1e-12;
        self.movable_joints()
            .map(|j| match (j.limits, j.kind.is_rotational()) {
                (Some(l), true) if full_turn => one_turn(l),
                (Some(l), true) => narrow(l, half),
                (None, true) => [-half, half],
                (Some(l), false) => l,
                (None, false) => [0.0, 0.0],
            })
            .collect()
    }

    /// [`Self::joint_ranges`] in user units (degrees for rotational joints).
    pub fn joint_ranges_user(&self) -> Vec<[f64; 2]> {
        self.movable_joints()
            .zip(self.joint_ranges())
            .map(|(j, r)| {
                if j.kind.is_rotational() {
                    r.map(f64::to_degrees)
                } else {
                    r
                }
            })
            .collect()
    }

    /// Joint values from user units (degrees for rotational joints, metres otherwise) to SI.
    pub fn to_si(&self, q: &[f64]) -> Vec<f64> {
        self.movable_joints()
            .zip(q)
            .map(|(j, &v)| {
                if j.kind.is_rotational() {
                    v.to_radians()
                } else {
                    v
                }
            })
            .collect()
    }

    /// Joint values from SI to user units.
    pub fn from_si(&self, q: &[f64]) -> Vec<f64> {
        self.movable_joints()
            .zip(q)
            .map(|(j, &v)| {
                if j.kind.is_rotational() {
                    v.to_degrees()
                } else {
                    v
                }
            })
            .collect()
    }

    /// World pose of every link for joint values `q` (SI, length [`Self::dof`]).
    pub fn link_frames(&self, q: &[f64]) -> Vec<Isometry3<f64>> {
        assert_eq!(
            q.len(),
            self.dof(),
            "joint vector length must equal the robot's DOF"
        );
        let mut frames = vec![self.base; self.links.len()];
        for (joint, value) in self.joints.iter().zip(&self.values) {
            frames[joint.child] = frames[joint.parent] * joint.origin * joint.motion(value.of(q));
        }
        frames
    }

    /// World pose of the frame of joint `j` (before its motion) and its axis in the world.
    pub fn joint_frames(&self, q: &[f64]) -> Vec<(Point3<f64>, Vector3<f64>)> {
        let frames = self.link_frames(q);
        self.joints
            .iter()
            .map(|j| {
                let f = frames[j.parent] * j.origin;
                (f * Point3::origin(), f * j.axis.into_inner())
            })
            .collect()
    }

    /// World position of the end effector.
    pub fn end_effector(&self, q: &[f64]) -> Point3<f64> {
        self.link_frames(q)[self.tip_link] * self.tip_offset
    }

    /// The end effector's position Jacobian `[3, dof]` (m per SI unit) at `q`, analytic:
    /// column k is `axis_k x (p_tip - o_k)` for a rotational joint and `axis_k` for a
    /// prismatic one, zero for a joint that does not move the tip; a mimic joint on the path
    /// adds its own column, times its multiplier, to its leader's. The first three rows of
    /// [`Self::pose_jacobian`].
    pub fn position_jacobian(&self, q: &[f64]) -> nalgebra::Matrix3xX<f64> {
        self.pose_jacobian(q).fixed_rows::<3>(0).into_owned()
    }

    /// World pose of the end effector: the tip link's orientation at the tip point.
    pub fn tip_pose(&self, q: &[f64]) -> Isometry3<f64> {
        let frame = self.link_frames(q)[self.tip_link];
        Isometry3::from_parts(
            Translation3::from((frame * self.tip_offset).coords),
            frame.rotation,
        )
    }

    /// The end effector's pose Jacobian `[6, dof]` at `q`, analytic: rows 0-2 the position
    /// Jacobian ([`Self::position_jacobian`]), rows 3-5 the angular velocity per unit joint
    /// speed (the world axis of a rotational joint, zero for a prismatic one), a mimic
    /// joint's part added to its leader's column times its multiplier.
    pub fn pose_jacobian(&self, q: &[f64]) -> nalgebra::Matrix6xX<f64> {
        let frames = self.link_frames(q);
        let tip = frames[self.tip_link] * self.tip_offset;
        let mut moves_tip = vec![false; self.joints.len()];
        let mut link = self.tip_link;
        while let Some(j) = self.joints.iter().position(|j| j.child == link) {
            moves_tip[j] = true;
            link = self.joints[j].parent;
        }
        let mut jac = nalgebra::Matrix6xX::zeros(self.dof());
        for (j, joint) in self.joints.iter().enumerate() {
            let (JointValue::Input { index, scale, .. }, true) = (self.values[j], moves_tip[j])
            else {
                continue;
            };
            let f = frames[joint.parent] * joint.origin;
            let axis = f * joint.axis.into_inner();
            let (linear, angular) = if joint.kind.is_rotational() {
                (axis.cross(&(tip - f * Point3::origin())), axis)
            } else {
                (axis, Vector3::zeros())
            };
            let mut column = jac.column(index).into_owned();
            column.fixed_rows_mut::<3>(0).axpy(scale, &linear, 1.0);
            column.fixed_rows_mut::<3>(3).axpy(scale, &angular, 1.0);
            jac.set_column(index, &column);
        }
        jac
    }

    /// The end effectors inverse kinematics drives, as (link, point in its frame): the links
    /// a [`JointGroup::Tips`] group names, at their origins (the tip's own point where one is
    /// the tip link), else the one tip.
    pub fn tips(&self) -> Vec<(usize, Point3<f64>)> {
        if self.group_tips.is_empty() {
            return vec![(self.tip_link, self.tip_offset)];
        }
        self.group_tips
            .iter()
            .map(|&l| {
                let at = if l == self.tip_link {
                    self.tip_offset
                } else {
                    Point3::origin()
                };
                (l, at)
            })
            .collect()
    }

    /// The names of the links of [`Self::tips`].
    pub fn tip_names(&self) -> Vec<String> {
        self.tips()
            .iter()
            .map(|&(l, _)| self.links[l].clone())
            .collect()
    }

    /// World pose of each tip ([`Self::tips`]): its link's orientation at its point.
    pub fn tip_poses(&self, q: &[f64]) -> Vec<Isometry3<f64>> {
        let frames = self.link_frames(q);
        self.tips()
            .iter()
            .map(|&(l, p)| {
                Isometry3::from_parts(
                    Translation3::from((frames[l] * p).coords),
                    frames[l].rotation,
                )
            })
            .collect()
    }

    /// The joints from the root to the tip, for the fast pose and Jacobian of
    /// [`TipPath`] (what an IK solver evaluates thousands of times a target).
    pub fn tip_path(&self) -> TipPath {
        self.path_to(self.tip_link, self.tip_offset)
    }

    /// A [`TipPath`] to each of [`Self::tips`].
    pub fn tip_paths(&self) -> Vec<TipPath> {
        self.tips()
            .into_iter()
            .map(|(l, p)| self.path_to(l, p))
            .collect()
    }

    /// The joints from the root to the point `at` of `link`, constant parts folded.
    pub fn path_to(&self, link: usize, at: Point3<f64>) -> TipPath {
        let mut on_path = Vec::new();
        let mut link = link;
        while let Some(j) = self.joints.iter().position(|j| j.child == link) {
            on_path.push(j);
            link = self.joints[j].parent;
        }
        on_path.reverse();
        // Constant transforms (fixed and held joints) fold into the next joint's origin.
        let mut pending = self.base;
        let mut steps = Vec::new();
        for j in on_path {
            let joint = &self.joints[j];
            match (self.values[j], joint.kind) {
                (
                    JointValue::Input {
                        index,
                        scale,
                        offset,
                    },
                    kind,
                ) if kind != JointKind::Fixed => {
                    steps.push(PathStep {
                        origin: pending * joint.origin,
                        axis: joint.axis.into_inner(),
                        rotational: kind.is_rotational(),
                        index,
                        scale,
                        offset,
                    });
                    pending = Isometry3::identity();
                }
                (value, _) => pending = pending * joint.origin * joint.motion(value.of(&[])),
            }
        }
        TipPath {
            steps,
            tip: pending * Translation3::from(at.coords),
            dof: self.dof(),
        }
    }

    /// Link frames for a batch of joint vectors (rows of `qs`, SI), in parallel.
    pub fn link_frames_batch(&self, qs: &[Vec<f64>]) -> Vec<Vec<Isometry3<f64>>> {
        qs.par_iter().map(|q| self.link_frames(q)).collect()
    }

    /// End-effector positions for a batch of joint vectors (SI), in parallel.
    pub fn end_effector_batch(&self, qs: &[Vec<f64>]) -> Vec<Point3<f64>> {
        qs.par_iter().map(|q| self.end_effector(q)).collect()
    }
}

/// One movable joint on the path to the tip: `origin` (everything constant since the previous
/// movable joint folded in), then the motion about (or along) `axis` by
/// `scale * q[index] + offset`.
#[derive(Clone, Debug)]
struct PathStep {
    origin: Isometry3<f64>,
    axis: Vector3<f64>,
    rotational: bool,
    index: usize,
    scale: f64,
    offset: f64,
}

/// The chain from the root to the tip with its constant parts folded together: the tip's
/// pose and pose Jacobian in one pass over the movable joints on the path (the fast path of
/// [`KinematicChain::tip_pose`] and [`KinematicChain::pose_jacobian`], which it matches; a
/// test compares them).
#[derive(Clone, Debug)]
pub struct TipPath {
    steps: Vec<PathStep>,
    /// From the last movable joint's frame to the tip (its link's orientation).
    tip: Isometry3<f64>,
    dof: usize,
}

impl TipPath {
    /// The motion of `step`'s joint at `q`.
    fn motion(step: &PathStep, q: &[f64]) -> Isometry3<f64> {
        let v = step.scale * q[step.index] + step.offset;
        if step.rotational {
            Isometry3::from_parts(
                Translation3::identity(),
                UnitQuaternion::from_scaled_axis(step.axis * v),
            )
        } else {
            Isometry3::from_parts(
                Translation3::from(step.axis * v),
                UnitQuaternion::identity(),
            )
        }
    }

    /// The tip's world pose at `q`.
    pub fn pose(&self, q: &[f64]) -> Isometry3<f64> {
        let mut f = Isometry3::identity();
        for s in &self.steps {
            f = f * s.origin * Self::motion(s, q);
        }
        f * self.tip
    }

    /// The tip's world pose at `q` and its pose Jacobian written into `jac` (`[6, dof]`:
    /// linear rows, then angular).
    pub fn pose_and_jacobian(
        &self,
        q: &[f64],
        jac: &mut nalgebra::Matrix6xX<f64>,
    ) -> Isometry3<f64> {
        if jac.ncols() != self.dof {
            *jac = nalgebra::Matrix6xX::zeros(self.dof);
        } else {
            jac.fill(0.0);
        }
        // Each movable joint's world origin and axis, then the tip.
        let mut axes = Vec::with_capacity(self.steps.len());
        let mut f = Isometry3::identity();
        for s in &self.steps {
            let at = f * s.origin;
            axes.push((at * Point3::origin(), at * s.axis));
            f = at * Self::motion(s, q);
        }
        let pose = f * self.tip;
        let tip = Point3::from(pose.translation.vector);
        for (s, (o, axis)) in self.steps.iter().zip(axes) {
            let (linear, angular) = if s.rotational {
                (axis.cross(&(tip - o)), axis)
            } else {
                (axis, Vector3::zeros())
            };
            let mut col = jac.column_mut(s.index);
            col.fixed_rows_mut::<3>(0).axpy(s.scale, &linear, 1.0);
            col.fixed_rows_mut::<3>(3).axpy(s.scale, &angular, 1.0);
        }
        pose
    }
}
