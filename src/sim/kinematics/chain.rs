//! The kinematic tree ([`KinematicChain`]): built from links and joints given in any order,
//! its joint vector chosen by a [`JointGroup`], and the joint vector's names, ranges and units.

use nalgebra::{Isometry3, Point3};

use super::group::refuse_another_tip;
use super::{DEFAULT_ROTATIONAL_RANGE, Joint, JointGroup, JointValue, narrow, one_turn};
use crate::core::error::{Error, Result};

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
    pub(super) group_tips: Vec<usize>,
    /// Indices into `joints` of the inputs, in the order of the joint vector.
    pub(super) dofs: Vec<usize>,
    /// For each joint, where its value comes from.
    pub(super) values: Vec<JointValue>,
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
        let tree = SortedTree::of(&links, &joints)?;
        let links: Vec<String> = tree.links.iter().map(|&l| links[l].clone()).collect();
        let mut joints = tree.joints;
        let (mut tip_link, mut tip_offset) = match tip {
            Some((l, p)) => (tree.new_index[l], p),
            None => (tree.deepest, Point3::origin()),
        };
        let members = group_members(group, &joints, &links, tip.is_some(), tip_link)?;
        if let Some(t) = members.tip {
            (tip_link, tip_offset) = (t, Point3::origin());
        }
        remap_mimic_leaders(&mut joints, &tree.given)?;
        let dofs = inputs(&joints, &members.on_path, &tree.given);
        let values = joint_values(&joints, &dofs)?;
        Ok(KinematicChain {
            links,
            joints,
            base,
            tip_link,
            tip_offset,
            group_tips: members.tips,
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

    /// The joint vector cut into chains between the tree's branch points (indices into it): a
    /// chain starts at an input with no input above it, or below an input with several below
    /// it, and runs down while each input has exactly one below it. In joint-vector order of
    /// their first inputs. A serial arm is one chain; the G1's whole body five (two legs, the
    /// waist, two arms).
    pub fn input_chains(&self) -> Vec<Vec<usize>> {
        let parents = self.input_parents();
        let mut below = vec![Vec::new(); parents.len()];
        for (i, p) in parents.iter().enumerate() {
            if let Some(p) = *p {
                below[p].push(i);
            }
        }
        (0..parents.len())
            .filter(|&i| parents[i].is_none_or(|p| below[p].len() != 1))
            .map(|start| {
                let mut chain = vec![start];
                while let [next] = below[*chain.last().expect("a chain has a start")][..] {
                    chain.push(next);
                }
                chain
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
}

/// Links and joints sorted breadth-first from the one root (link 0), each joint's parent
/// before its child.
struct SortedTree {
    /// Old link indices in the new order.
    links: Vec<usize>,
    /// `new_index[old]`: where a link went.
    new_index: Vec<usize>,
    /// The joints in the new order, their links renumbered.
    joints: Vec<Joint>,
    /// `given[j]`: sorted joint `j`'s index as given.
    given: Vec<usize>,
    /// The deepest link (the default tip), in the new numbering.
    deepest: usize,
}

impl SortedTree {
    /// Refused: no links, a link the child of two joints, several roots, a cycle.
    fn of(links: &[String], joints: &[Joint]) -> Result<Self> {
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
        let sorted = order_joints
            .iter()
            .map(|&j| {
                let mut joint = joints[j].clone();
                joint.parent = new_index[joint.parent];
                joint.child = new_index[joint.child];
                joint
            })
            .collect();
        Ok(SortedTree {
            links: order_links,
            deepest: new_index[deepest],
            new_index,
            joints: sorted,
            given: order_joints,
        })
    }
}

/// What a group marks: the joints it moves (`on_path`, over the sorted joints), its tips
/// (several), and the tip it sets when it has one (an SRDF group with one tip, no `tip`).
struct Members {
    on_path: Vec<bool>,
    tips: Vec<usize>,
    tip: Option<usize>,
}

/// The group's joints (indices into the sorted `joints`): the joints on the path from the
/// root to the tip, or to each of several links, every joint, or joints by name. `links`:
/// sorted; `tip_given`: whether `tip` named `tip_link`.
fn group_members(
    group: &JointGroup,
    joints: &[Joint],
    links: &[String],
    tip_given: bool,
    tip_link: usize,
) -> Result<Members> {
    let mut on_path = vec![false; joints.len()];
    let mut mark_path = |mut link: usize| {
        while let Some(j) = joints.iter().position(|j| j.child == link) {
            on_path[j] = true;
            link = joints[j].parent;
        }
    };
    let sorted_links: Vec<&String> = links.iter().collect();
    let mut group_tips = Vec::new();
    let mut tip = None;
    match group {
        JointGroup::Chain => mark_path(tip_link),
        JointGroup::Tips(tips) => {
            for t in tips {
                let l = sorted_links.iter().position(|l| *l == t).ok_or_else(|| {
                    Error::Config(format!(
                        "`tips`: \"{t}\" is not a link of this robot; its links: {}",
                        sorted_links
                            .iter()
                            .map(|l| l.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    ))
                })?;
                if group_tips.contains(&l) {
                    return Err(Error::Config(format!("`tips` names \"{t}\" twice")));
                }
                mark_path(l);
                group_tips.push(l);
            }
            refuse_another_tip(tip_given, tip_link, &group_tips, &sorted_links, "`tips`")?;
        }
        JointGroup::All => on_path.iter_mut().for_each(|p| *p = true),
        JointGroup::Named(names) => {
            for name in names {
                let j = joints
                    .iter()
                    .position(|j| &j.name == name && j.kind.is_movable() && j.mimic.is_none())
                    .ok_or_else(|| {
                        Error::Config(format!(
                            "`joints`: \"{name}\" is not a movable joint of this robot (mimic joints follow their leader); its movable joints: {}",
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
            refuse_another_tip(tip_given, tip_link, &group_tips, &sorted_links, "the group")?;
            if group_tips.len() == 1 {
                if !tip_given {
                    tip = Some(group_tips[0]);
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
    Ok(Members {
        on_path,
        tips: group_tips,
        tip,
    })
}

/// Mimic leaders renumbered to the sorted joints (`given[j]`: sorted joint `j`'s index as
/// given).
fn remap_mimic_leaders(joints: &mut [Joint], given: &[usize]) -> Result<()> {
    let mut sorted_of = vec![0; joints.len()];
    for (new, &old) in given.iter().enumerate() {
        sorted_of[old] = new;
    }
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
    Ok(())
}

/// The joint vector: the group's movable joints that mimic no other, and the leaders of the
/// mimic joints among them (followed to the joint that mimics no other, wherever it is), in
/// depth-first order from the root, children in the order the joints were given in (as
/// Pinocchio and KDL order a tree): root to tip along a chain, however the file lists them.
fn inputs(joints: &[Joint], on_path: &[bool], given: &[usize]) -> Vec<usize> {
    let mut drives_tip = on_path.to_vec();
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
    let rank = depth_first_rank(joints, given);
    let mut dofs: Vec<usize> = (0..joints.len())
        .filter(|&j| joints[j].kind.is_movable() && joints[j].mimic.is_none() && drives_tip[j])
        .collect();
    dofs.sort_by_key(|&j| rank[j]);
    dofs
}

/// Where each joint's value comes from: an input of the joint vector (`dofs`), held (a
/// movable joint outside it, at 0 or the limit nearest 0), fixed, or its mimic leader's
/// (following chains of leaders; a cycle is an error).
fn joint_values(joints: &[Joint], dofs: &[usize]) -> Result<Vec<JointValue>> {
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
    Ok(values
        .into_iter()
        .map(|v| v.expect("every joint set"))
        .collect())
}
