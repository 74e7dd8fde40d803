//! Which movable joints make the joint vector ([`JointGroup`]): the chain to the tip, the
//! chains to several tips, every joint, joints by name, or an SRDF planning group.

use crate::core::error::{Error, Result};

/// Which movable joints of a tree make the joint vector; the others are held.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JointGroup {
    /// The chain from the root to the tip (`tip`; the default).
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
    /// the tip (unless `tip` names another).
    Members {
        joints: Vec<String>,
        tips: Vec<String>,
    },
}

impl JointGroup {
    pub fn is_chain(&self) -> bool {
        *self == JointGroup::Chain
    }

    /// `joints`, `tips` and `group` (with `srdf`, else the SRDF file beside the
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
                    "`group`, `joints` and `tips` name the joint vector in different ways: give one"
                        .into(),
                ));
            }
            let file = match (srdf, urdf) {
                (Some(file), _) => file.to_path_buf(),
                (None, Some(urdf)) => crate::sim::srdf::find_beside(urdf)?,
                (None, None) => {
                    return Err(Error::Config(
                        "`group` needs a robot description (`urdf`)".into(),
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
                "`srdf` names the SRDF file of `group`: give `group` too".into(),
            ));
        }
        match (joints, tips) {
            (Some(_), Some(_)) => Err(Error::Config(
                "`joints` and `tips` name the joint vector two ways: give one".into(),
            )),
            (Some([all]), None) if all == "all" => Ok(JointGroup::All),
            (Some(names), None) if !names.is_empty() => Ok(JointGroup::Named(names.to_vec())),
            (None, Some(tips)) if !tips.is_empty() => Ok(JointGroup::Tips(tips.to_vec())),
            (None, None) => Ok(JointGroup::Chain),
            _ => Err(Error::Config(
                "`joints` and `tips` need at least one name".into(),
            )),
        }
    }
}

/// A `tip` given beside a group with tips must be one of them: another would train the
/// group's joints for a link they were not chosen for.
pub(super) fn refuse_another_tip(
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
        "`tip` \"{}\" is not a tip of {group} ({}): name one of them, or leave `tip` out",
        links[tip],
        names.join(", ")
    )))
}
