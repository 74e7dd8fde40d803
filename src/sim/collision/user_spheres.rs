//! Spheres a user supplies, as cuRobo's robot files give them: a YAML file with a
//! `collision_spheres` block (link name -> list of `{center: [x, y, z], radius: r}`, metres, in
//! the link's frame), at the top level or under `robot_cfg.kinematics` (there inline, or the
//! path of a spheres file relative to the robot file, as cuRobo's own configs name it).
//! Spheres with a radius of 0 or less are cuRobo's placeholders and are skipped; a link the
//! robot does not have is refused.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::core::error::{Error, Result};
use crate::sim::collision::spheres::Sphere;

#[derive(Deserialize)]
struct Entry {
    center: [f64; 3],
    radius: f64,
}

type Block = BTreeMap<String, Vec<Entry>>;

#[derive(Deserialize)]
#[serde(untagged)]
enum SpheresField {
    Inline(Block),
    File(PathBuf),
}

#[derive(Deserialize)]
struct Kinematics {
    #[serde(default)]
    collision_spheres: Option<SpheresField>,
}

#[derive(Deserialize)]
struct RobotCfg {
    kinematics: Kinematics,
}

#[derive(Deserialize)]
struct SpheresFile {
    #[serde(default)]
    collision_spheres: Option<SpheresField>,
    #[serde(default)]
    robot_cfg: Option<RobotCfg>,
}

/// The most nested spheres files followed (a robot file naming a spheres file).
const MAX_DEPTH: usize = 4;

/// The largest radius of a link's sphere (m): beyond it a typo (a humanoid is 1.3 m tall).
const MAX_RADIUS_M: f64 = 10.0;
/// The farthest a sphere's centre lies from its link's origin (m).
const MAX_CENTER_M: f64 = 100.0;

/// The files read for the spheres of `path`: it, and the spheres files it names in turn.
pub fn files(path: &Path) -> Result<Vec<PathBuf>> {
    let mut files = vec![path.to_path_buf()];
    let mut at = path.to_path_buf();
    for _ in 0..MAX_DEPTH {
        let file: SpheresFile =
            crate::sim::collision::read_yaml(&at, "spheres file", "a cuRobo spheres file")?;
        let field = file
            .collision_spheres
            .or(file.robot_cfg.and_then(|r| r.kinematics.collision_spheres));
        let Some(SpheresField::File(next)) = field else {
            break;
        };
        at = at.parent().unwrap_or(Path::new(".")).join(next);
        files.push(at.clone());
    }
    Ok(files)
}

/// The spheres of `path` for the links `links` (index as in the chain's links).
pub fn read(path: &Path, links: &[String]) -> Result<Vec<Vec<Sphere>>> {
    let block = read_block(path, 0)?;
    let mut out = vec![Vec::new(); links.len()];
    for (link, entries) in block {
        let Some(i) = links.iter().position(|l| *l == link) else {
            return Err(Error::Config(format!(
                "{}: the spheres of \"{link}\", a link the robot does not have (its links: {})",
                path.display(),
                links.join(", ")
            )));
        };
        for e in entries {
            let finite = e
                .center
                .iter()
                .all(|v| v.is_finite() && v.abs() <= MAX_CENTER_M);
            if !(finite && e.radius.is_finite() && e.radius <= MAX_RADIUS_M) {
                return Err(Error::Config(format!(
                    "{}: a sphere of \"{link}\" is not finite numbers of metres (a centre within {MAX_CENTER_M} m of its link, a radius of at most {MAX_RADIUS_M} m)",
                    path.display()
                )));
            }
            if e.radius > 0.0 {
                out[i].push(Sphere {
                    center: e.center,
                    radius: e.radius,
                });
            }
        }
    }
    Ok(out)
}

fn read_block(path: &Path, depth: usize) -> Result<Block> {
    let file: SpheresFile =
        crate::sim::collision::read_yaml(path, "spheres file", "a cuRobo spheres file")?;
    let field = file
        .collision_spheres
        .or(file.robot_cfg.and_then(|r| r.kinematics.collision_spheres))
        .ok_or_else(|| {
            Error::Config(format!(
                "{}: no collision_spheres block (at the top level or under robot_cfg.kinematics)",
                path.display()
            ))
        })?;
    match field {
        SpheresField::Inline(block) => Ok(block),
        SpheresField::File(next) if depth < MAX_DEPTH => read_block(
            &path.parent().unwrap_or(Path::new(".")).join(next),
            depth + 1,
        ),
        SpheresField::File(_) => Err(Error::Config(format!(
            "{}: spheres files name each other more than {MAX_DEPTH} deep",
            path.display()
        ))),
    }
}
