//! Planning groups of an SRDF file (MoveIt's semantic robot description, `--group NAME`):
//! which joints of a robot description a named group moves, and which links are its tips.
//!
//! A `<group>` lists `<joint name>` (that joint), `<link name>` (the joint whose child it is),
//! `<chain base_link tip_link>` (the joints from the base down to the tip; from the base up to
//! the two links' common ancestor and down to the tip where the base is not above the tip) and
//! `<group name>` (another group's members), as MoveIt reads them. Its chains' tip links are
//! its tips. Joints a group lists that the URDF lacks are refused unless the SRDF declares
//! them as `<virtual_joint>`s (the joint that places a mobile robot in the world).

use std::path::{Path, PathBuf};

use crate::core::error::{Error, Result};

/// One `<group>` as the file writes it.
#[derive(Clone, Debug, Default, PartialEq)]
struct Group {
    name: String,
    joints: Vec<String>,
    links: Vec<String>,
    /// (base link, tip link)
    chains: Vec<(String, String)>,
    groups: Vec<String>,
}

/// The groups of an SRDF file.
#[derive(Clone, Debug, PartialEq)]
pub struct Srdf {
    path: PathBuf,
    groups: Vec<Group>,
    virtual_joints: Vec<String>,
    /// `<disable_collisions link1 link2 reason>`: the pairs of links never checked.
    disabled: Vec<(String, String, String)>,
}

/// What a group resolves to on a robot's tree: its joints (in the order met, each once) and
/// its chains' tip links.
#[derive(Clone, Debug, PartialEq)]
pub struct GroupMembers {
    pub joints: Vec<String>,
    pub tips: Vec<String>,
}

/// The deepest nesting of subgroups followed (MoveIt's own files nest two or three).
const MAX_GROUP_DEPTH: usize = 64;

/// A joint of the tree, as (name, parent link, child link).
pub type TreeJoint = (String, String, String);

impl Srdf {
    pub fn read(path: &Path) -> Result<Self> {
        let text = crate::core::input_file::read_xml(path, "SRDF file")?;
        Self::parse(path, &text)
    }

    /// The file it was read from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn parse(path: &Path, text: &str) -> Result<Self> {
        let err = |element: &str, msg: String| Error::Urdf {
            path: path.to_path_buf(),
            element: element.into(),
            msg,
        };
        crate::core::input_file::check_xml_depth(text)
            .map_err(|e| err("srdf", format!("not an SRDF file: {e}")))?;
        let doc = roxmltree::Document::parse(text)
            .map_err(|e| err("srdf", format!("not an SRDF file (bad XML: {e})")))?;
        let root = doc.root_element();
        if root.tag_name().name() != "robot" {
            return Err(err(
                "srdf",
                format!(
                    "not an SRDF file: its root element is <{}>, not <robot>",
                    root.tag_name().name()
                ),
            ));
        }
        let name_of = |node: roxmltree::Node, what: &str| {
            node.attribute("name")
                .map(str::to_string)
                .ok_or_else(|| err(what, "has no name attribute".into()))
        };
        let mut groups = Vec::new();
        let mut virtual_joints = Vec::new();
        let mut disabled = Vec::new();
        for node in root.children().filter(|n| n.is_element()) {
            match node.tag_name().name() {
                "virtual_joint" => virtual_joints.push(name_of(node, "<virtual_joint>")?),
                "disable_collisions" => {
                    let (Some(a), Some(b)) = (node.attribute("link1"), node.attribute("link2"))
                    else {
                        return Err(err(
                            "disable_collisions",
                            "needs link1 and link2 attributes".into(),
                        ));
                    };
                    let reason = node.attribute("reason").unwrap_or("User");
                    disabled.push((a.to_string(), b.to_string(), reason.to_string()));
                }
                "group" => {
                    let mut g = Group {
                        name: name_of(node, "<group>")?,
                        ..Group::default()
                    };
                    let element = format!("group \"{}\"", g.name);
                    if groups.iter().any(|o: &Group| o.name == g.name) {
                        return Err(err(&element, "is defined twice: rename one".into()));
                    }
                    for m in node.children().filter(|n| n.is_element()) {
                        match m.tag_name().name() {
                            "joint" => g.joints.push(name_of(m, &element)?),
                            "link" => g.links.push(name_of(m, &element)?),
                            "group" => g.groups.push(name_of(m, &element)?),
                            "chain" => {
                                let (Some(base), Some(tip)) =
                                    (m.attribute("base_link"), m.attribute("tip_link"))
                                else {
                                    return Err(err(
                                        &element,
                                        "a <chain> needs base_link and tip_link".into(),
                                    ));
                                };
                                g.chains.push((base.into(), tip.into()));
                            }
                            _ => {}
                        }
                    }
                    groups.push(g);
                }
                _ => {}
            }
        }
        Ok(Srdf {
            path: path.to_path_buf(),
            groups,
            virtual_joints,
            disabled,
        })
    }

    /// The pairs of links `<disable_collisions>` names, as (link1, link2, reason).
    pub fn disabled_collisions(&self) -> &[(String, String, String)] {
        &self.disabled
    }

    pub fn group_names(&self) -> Vec<&str> {
        self.groups.iter().map(|g| g.name.as_str()).collect()
    }

    /// The joints and tips of group `name` on the tree `tree` (its subgroups' included).
    pub fn resolve(&self, name: &str, tree: &[TreeJoint]) -> Result<GroupMembers> {
        let mut members = GroupMembers {
            joints: Vec::new(),
            tips: Vec::new(),
        };
        let mut done = Vec::new();
        self.collect(name, tree, &mut vec![], &mut done, &mut members)?;
        Ok(members)
    }

    /// Add group `name`'s members to `into`: `open` are the groups being collected above it
    /// (a cycle), `done` those collected already (a group listed twice is added once, not
    /// expanded again: a group listing one subgroup twice at each of 40 levels is 40 visits).
    fn collect(
        &self,
        name: &str,
        tree: &[TreeJoint],
        open: &mut Vec<String>,
        done: &mut Vec<String>,
        into: &mut GroupMembers,
    ) -> Result<()> {
        let err = |msg: String| Error::Urdf {
            path: self.path.clone(),
            element: format!("group \"{name}\""),
            msg,
        };
        let Some(group) = self.groups.iter().find(|g| g.name == name) else {
            return Err(Error::Urdf {
                path: self.path.clone(),
                element: "`group`".into(),
                msg: format!(
                    "\"{name}\" is not a group of this file; its groups: {}",
                    self.group_names().join(", ")
                ),
            });
        };
        if open.iter().any(|g| g == name) {
            return Err(err(format!(
                "its subgroups form a cycle ({} -> {name})",
                open.join(" -> ")
            )));
        }
        if done.iter().any(|g| g == name) {
            return Ok(());
        }
        if open.len() >= MAX_GROUP_DEPTH {
            return Err(err(format!(
                "subgroups nested more than {MAX_GROUP_DEPTH} deep (from \"{}\")",
                open[0]
            )));
        }
        open.push(name.to_string());
        let mut add = |joint: &str| {
            if !into.joints.iter().any(|j| j == joint) {
                into.joints.push(joint.to_string());
            }
        };
        let parent_joint = |link: &str| tree.iter().find(|(_, _, child)| child == link);
        let is_link = |link: &str| tree.iter().any(|(_, p, c)| p == link || c == link);
        for j in &group.joints {
            if tree.iter().any(|(n, _, _)| n == j) {
                add(j);
            } else if !self.virtual_joints.contains(j) {
                return Err(err(format!(
                    "\"{j}\" is not a joint of the robot description"
                )));
            }
        }
        for l in &group.links {
            match parent_joint(l) {
                Some((joint, _, _)) => add(joint),
                None if is_link(l) => {} // the root: no joint moves it
                None => {
                    return Err(err(format!(
                        "\"{l}\" is not a link of the robot description"
                    )));
                }
            }
        }
        for (base, tip) in &group.chains {
            for l in [base, tip] {
                if !is_link(l) {
                    return Err(err(format!(
                        "\"{l}\" is not a link of the robot description"
                    )));
                }
            }
            // The links and joints from `from` up to the root, `from` first.
            let up = |from: &str| {
                let (mut links, mut joints) = (vec![from.to_string()], Vec::new());
                let mut link = from.to_string();
                while let Some((joint, parent, _)) = parent_joint(&link) {
                    if links.len() > tree.len() {
                        break; // not a tree: the URDF loader refuses such a file first
                    }
                    joints.push(joint.clone());
                    links.push(parent.clone());
                    link = parent.clone();
                }
                (links, joints)
            };
            // Through the two links' common ancestor, as MoveIt (KDL) reads a chain whose base
            // is not above its tip (iCub's `chest` -> `l_sole`): the joints from the base up
            // to it, then down to the tip.
            let (base_links, base_joints) = up(base);
            let (tip_links, tip_joints) = up(tip);
            let Some(meet) = tip_links.iter().position(|l| base_links.contains(l)) else {
                return Err(err(format!(
                    "its chain from \"{base}\" to \"{tip}\": the two links share no ancestor"
                )));
            };
            let above = base_links
                .iter()
                .position(|l| *l == tip_links[meet])
                .unwrap_or(0);
            base_joints[..above].iter().for_each(|j| add(j));
            let path: Vec<&str> = tip_joints[..meet].iter().map(String::as_str).collect();
            path.iter().rev().for_each(|j| add(j));
            if !into.tips.contains(tip) {
                into.tips.push(tip.clone());
            }
        }
        for g in &group.groups {
            self.collect(g, tree, open, done, into)?;
        }
        open.pop();
        done.push(name.to_string());
        Ok(())
    }
}

/// The SRDF file of the description at `urdf`: the one `.srdf` file in its folder, in
/// `../config/` or `../srdf/` beside it, or in a `*_moveit_config/config/` package beside its
/// package (where MoveIt's setup assistant writes it).
pub fn find_beside(urdf: &Path) -> Result<PathBuf> {
    let dir = urdf.parent().unwrap_or(Path::new("."));
    let package = dir.parent().unwrap_or(Path::new(".."));
    let mut places = vec![
        dir.to_path_buf(),
        package.join("config"),
        package.join("srdf"),
    ];
    if let Some(packages) = package.parent()
        && let Ok(entries) = std::fs::read_dir(packages)
    {
        let mut moveit: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                p.file_name()
                    .is_some_and(|n| n.to_string_lossy().ends_with("_moveit_config"))
            })
            .map(|p| p.join("config"))
            .collect();
        moveit.sort();
        places.extend(moveit);
    }
    let mut found = Vec::new();
    for place in &places {
        let Ok(entries) = std::fs::read_dir(place) else {
            continue;
        };
        let mut here: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                p.is_file()
                    && p.file_name().is_some_and(|n| {
                        let n = n.to_string_lossy();
                        n.ends_with(".srdf") || n.ends_with(".srdf.xml")
                    })
            })
            .collect();
        here.sort();
        found.extend(here);
    }
    let list = |paths: &[PathBuf]| {
        paths
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    };
    match found.len() {
        1 => Ok(found.remove(0)),
        0 => Err(Error::Config(format!(
            "`group`: no SRDF file beside {} (looked in {}); give one with `srdf`",
            urdf.display(),
            list(&places)
        ))),
        _ => Err(Error::Config(format!(
            "`group`: several SRDF files beside {} ({}); choose one with `srdf`",
            urdf.display(),
            list(&found)
        ))),
    }
}
