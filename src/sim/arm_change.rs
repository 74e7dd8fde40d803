//! Changes to an arm's geometry that a learned inverse model must adapt to (EMSSL paper section
//! IV-C): every link lengthened by the same amount (the paper's Table IV), and, beyond the
//! paper, one link bent at its base (a changed joint offset).
//!
//! "A link" of a general kinematic chain is a joint origin's translation (the vector from one
//! joint to the next, in the parent link's frame) and the end-effector offset (the last link).
//! For the UR5 from DH parameters these are d1, a2, a3, d4, d5 and d6: six lengths.
//!
//! [`Damage`] is what a self-model must notice (self-modeling paper section VI): one link of
//! a robot bent, lengthened, shortened or with its far part missing, in its kinematics and in
//! its geometry, so the damaged robot renders as it would look.

use nalgebra::{Isometry3, Point3, Unit, UnitQuaternion, Vector3};

use crate::core::error::{Error, Result};
use crate::sim::bvh::Bvh;
use crate::sim::kinematics::KinematicChain;
use crate::sim::robot::Robot;
use crate::sim::shape::Shape;

/// Links shorter than this (metres) are joints that share a place; they are not lengthened.
const MIN_LINK_M: f64 = 1e-3;

/// One change of the arm.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum ArmChange {
    /// Every link (every joint origin's translation and the end-effector offset longer than
    /// 1 mm) lengthened by `cm` along itself.
    Lengthen { cm: f64 },
    /// The link that carries movable joint `joint` (0-based, joint-vector order) to its place
    /// rotated by `deg` at its base: the joint's origin turned about the axis perpendicular to
    /// the link and to the previous joint's axis, so the link leaves the plane that joint
    /// moves it in.
    Bend { joint: usize, deg: f64 },
}

impl ArmChange {
    /// A short label for tables: `links +3 cm`, `link to joint 3 bent 3 deg`.
    pub fn label(&self) -> String {
        match self {
            ArmChange::Lengthen { cm } => format!("links +{cm} cm"),
            ArmChange::Bend { joint, deg } => format!("link to joint {} bent {deg} deg", joint + 1),
        }
    }

    /// The changed arm.
    pub fn apply(&self, chain: &KinematicChain) -> Result<KinematicChain> {
        let mut changed = chain.clone();
        match *self {
            ArmChange::Lengthen { cm } => {
                let grow = |v: Vector3<f64>| {
                    let n = v.norm();
                    if n > MIN_LINK_M {
                        v * ((n + cm / 100.0) / n)
                    } else {
                        v
                    }
                };
                for joint in &mut changed.joints {
                    joint.origin.translation.vector = grow(joint.origin.translation.vector);
                }
                changed.tip_offset = grow(changed.tip_offset.coords).into();
            }
            ArmChange::Bend { joint, deg } => {
                let j = chain
                    .joints
                    .iter()
                    .enumerate()
                    .filter(|(_, jt)| jt.kind.is_movable())
                    .map(|(j, _)| j)
                    .find(|&j| chain.value_index(j) == Some(joint))
                    .ok_or_else(|| {
                        Error::Config(format!(
                            "bend: the arm has {} movable joints, not {}",
                            chain.dof(),
                            joint + 1
                        ))
                    })?;
                let link = chain.joints[j].origin.translation.vector;
                if link.norm() <= MIN_LINK_M {
                    return Err(Error::Config(format!(
                        "bend: the link to joint {} has no length to bend",
                        joint + 1
                    )));
                }
                // The previous joint's axis, in the frame the link is expressed in.
                let parent = chain.joints[j].parent;
                let previous_axis = chain
                    .joints
                    .iter()
                    .find(|jt| jt.child == parent)
                    .map_or(Vector3::z(), |jt| jt.axis.into_inner());
                let axis = perpendicular(&link, &previous_axis);
                let bend = Isometry3::from_parts(
                    nalgebra::Translation3::identity(),
                    UnitQuaternion::from_axis_angle(&axis, deg.to_radians()),
                );
                changed.joints[j].origin = bend * chain.joints[j].origin;
            }
        }
        Ok(changed)
    }
}

/// A unit vector perpendicular to `link` and, where they are not parallel, to `other`.
fn perpendicular(link: &Vector3<f64>, other: &Vector3<f64>) -> Unit<Vector3<f64>> {
    let c = link.cross(other);
    if c.norm() > 1e-9 * link.norm() {
        return Unit::new_normalize(c);
    }
    let any = if link.x.abs() < 0.9 * link.norm() {
        Vector3::x()
    } else {
        Vector3::y()
    };
    Unit::new_normalize(link.cross(&any))
}

/// Damage to one link of a robot. "Link k" is the link the k-th joint of the joint vector
/// moves (0-based; on `arm4`, link 0 is L1); its length runs from its joint to the next joint
/// towards the tip (the tip itself for the last link), the direction `u` of the damage.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Damage {
    /// The link bent at its base by `deg`, about the axis perpendicular to it and to its
    /// joint's axis: the link and everything beyond leave the plane the joint moves them in
    /// (the joint's axis stays; a turn about it would be an encoder offset instead).
    Bend { link: usize, deg: f64 },
    /// The link longer by `cm` (shorter where negative): the joints it carries moved along it,
    /// its geometry stretched along it between its joint and the next.
    Length { link: usize, cm: f64 },
    /// The far `fraction` of the link's geometry along it missing (the parts beyond stay
    /// attached: on the last link, a broken-off tip); kinematics unchanged.
    Truncate { link: usize, fraction: f64 },
}

/// Triangles edges longer than this (m) are split before geometry is stretched or cut, so
/// the piecewise map and the cut follow the link closely.
const TESSELLATION_M: f64 = 0.01;

impl Damage {
    /// `bend`, `lengthen`, `shorten` or `truncate`.
    pub fn kind(&self) -> &'static str {
        match self {
            Damage::Bend { .. } => "bend",
            Damage::Length { cm, .. } if *cm < 0.0 => "shorten",
            Damage::Length { .. } => "lengthen",
            Damage::Truncate { .. } => "truncate",
        }
    }

    /// The damage's size in its unit (degrees, centimetres, or the share missing in %).
    pub fn size(&self) -> f64 {
        match *self {
            Damage::Bend { deg, .. } => deg,
            Damage::Length { cm, .. } => cm.abs(),
            Damage::Truncate { fraction, .. } => 100.0 * fraction,
        }
    }

    pub fn link(&self) -> usize {
        match *self {
            Damage::Bend { link, .. }
            | Damage::Length { link, .. }
            | Damage::Truncate { link, .. } => link,
        }
    }

    /// `bend 3 deg, link 2` (links counted from 1, as on the arm).
    pub fn label(&self) -> String {
        let unit = match self {
            Damage::Bend { .. } => "deg",
            Damage::Length { .. } => "cm",
            Damage::Truncate { .. } => "%",
        };
        format!(
            "{} {} {unit}, link {}",
            self.kind(),
            self.size(),
            self.link() + 1
        )
    }

    /// The damaged robot.
    pub fn apply(&self, robot: &Robot) -> Result<Robot> {
        let chain = &robot.chain;
        let joint = chain
            .joints
            .iter()
            .enumerate()
            .find(|(j, jt)| jt.kind.is_movable() && chain.value_index(*j) == Some(self.link()))
            .map(|(j, _)| j)
            .ok_or_else(|| {
                Error::Config(format!(
                    "damage: the robot has {} links that joints move, not {}",
                    chain.dof(),
                    self.link() + 1
                ))
            })?;
        let link = chain.joints[joint].child;
        let along = link_vector(chain, link);
        let length = along.norm();
        if length <= MIN_LINK_M {
            return Err(Error::Config(format!(
                "damage: link {} (\"{}\") has no length to damage",
                self.link() + 1,
                chain.links[link]
            )));
        }
        let u = Unit::new_normalize(along);
        let mut out = robot.clone();
        match *self {
            Damage::Bend { deg, .. } => {
                let axis = chain.joints[joint].axis;
                let bend = UnitQuaternion::from_axis_angle(
                    &perpendicular(&u.into_inner(), &axis.into_inner()),
                    deg.to_radians(),
                );
                // parent * origin * B * motion(B^-1 a, q) = parent * origin * motion(a, q) * B:
                // the bend follows the joint's motion about its unchanged axis.
                let j = &mut out.chain.joints[joint];
                j.origin *= Isometry3::from_parts(nalgebra::Translation3::identity(), bend);
                j.axis = Unit::new_normalize(bend.inverse() * axis.into_inner());
            }
            Damage::Length { cm, .. } => {
                let delta = cm / 100.0;
                if length + delta <= MIN_LINK_M {
                    return Err(Error::Config(format!(
                        "damage: link {} is {:.1} cm long; it cannot be shortened by {}",
                        self.link() + 1,
                        100.0 * length,
                        -cm
                    )));
                }
                for j in out.chain.joints.iter_mut().filter(|j| j.parent == link) {
                    j.origin.translation.vector += u.into_inner() * delta;
                }
                if out.chain.tip_link == link {
                    out.chain.tip_offset += u.into_inner() * delta;
                }
                let stretch = |p: Point3<f64>| {
                    let s = p.coords.dot(&u).clamp(0.0, length) / length;
                    p + u.into_inner() * (s * delta)
                };
                out.geometry[link] = Bvh::new(
                    triangles(robot.geometry[link].shapes())
                        .into_iter()
                        .map(|t| Shape::Triangle(t.map(stretch)))
                        .collect(),
                );
            }
            Damage::Truncate { fraction, .. } => {
                if !(fraction > 0.0 && fraction < 1.0) {
                    return Err(Error::Config(format!(
                        "damage: the share of a link missing must be between 0 and 1, not {fraction}"
                    )));
                }
                let tris = triangles(robot.geometry[link].shapes());
                let extent = |f: fn(f64, f64) -> f64, init: f64| {
                    tris.iter()
                        .flat_map(|t| t.iter().map(|p| p.coords.dot(&u)))
                        .fold(init, f)
                };
                let (lo, hi) = (
                    extent(f64::min, f64::INFINITY),
                    extent(f64::max, f64::NEG_INFINITY),
                );
                let cut = hi - fraction * (hi - lo);
                out.geometry[link] = Bvh::new(
                    tris.into_iter()
                        .filter(|t| {
                            let centroid = (t[0].coords + t[1].coords + t[2].coords) / 3.0;
                            centroid.dot(&u) <= cut
                        })
                        .map(Shape::Triangle)
                        .collect(),
                );
            }
        }
        Ok(out)
    }
}

/// The vector along link `link` in its own frame: to the next joint towards the tip (the
/// longest such, where it carries several), or to the tip on the tip's link.
pub fn link_vector(chain: &KinematicChain, link: usize) -> Vector3<f64> {
    if chain.tip_link == link {
        return chain.tip_offset.coords;
    }
    chain
        .joints
        .iter()
        .filter(|j| j.parent == link)
        .map(|j| j.origin.translation.vector)
        .max_by(|a, b| a.norm().total_cmp(&b.norm()))
        .unwrap_or_else(Vector3::zeros)
}

/// Every shape as triangles no longer than [`TESSELLATION_M`] on a side (boxes and cylinders
/// tessellated, spheres as latitude-longitude meshes), in the link frame.
pub fn triangles(shapes: &[Shape]) -> Vec<[Point3<f64>; 3]> {
    let mut out = Vec::new();
    for s in shapes {
        match s {
            Shape::Triangle(t) => split(*t, &mut out),
            Shape::Cuboid { pose, half } => {
                // Each face a grid of quads, two triangles each.
                for axis in 0..3 {
                    for sign in [-1.0, 1.0] {
                        let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
                        let corner = |x: f64, y: f64| {
                            let mut v = Vector3::zeros();
                            v[axis] = sign * half[axis];
                            v[a] = half[a] * x;
                            v[b] = half[b] * y;
                            pose * Point3::from(v)
                        };
                        grid(&mut out, 2.0 * half[a], 2.0 * half[b], |x, y| {
                            corner(2.0 * x - 1.0, 2.0 * y - 1.0)
                        });
                    }
                }
            }
            Shape::Cylinder {
                pose,
                radius,
                half_length,
            } => {
                let at = |x: f64, y: f64| {
                    let phi = std::f64::consts::TAU * x;
                    pose * Point3::new(
                        radius * phi.cos(),
                        radius * phi.sin(),
                        half_length * (2.0 * y - 1.0),
                    )
                };
                grid(
                    &mut out,
                    std::f64::consts::TAU * radius,
                    2.0 * half_length,
                    at,
                );
                for z in [-*half_length, *half_length] {
                    let n = ((std::f64::consts::TAU * radius / TESSELLATION_M).ceil() as usize)
                        .clamp(8, 64);
                    for k in 0..n {
                        let p = |k: usize| {
                            let phi = std::f64::consts::TAU * k as f64 / n as f64;
                            pose * Point3::new(radius * phi.cos(), radius * phi.sin(), z)
                        };
                        split([pose * Point3::new(0.0, 0.0, z), p(k), p(k + 1)], &mut out);
                    }
                }
            }
            Shape::Sphere { center, radius } => {
                let at = |x: f64, y: f64| {
                    let (phi, theta) = (std::f64::consts::TAU * x, std::f64::consts::PI * y);
                    center
                        + Vector3::new(
                            theta.sin() * phi.cos(),
                            theta.sin() * phi.sin(),
                            theta.cos(),
                        ) * *radius
                };
                grid(
                    &mut out,
                    std::f64::consts::TAU * radius,
                    std::f64::consts::PI * radius,
                    at,
                );
            }
        }
    }
    out
}

/// A surface `at(x, y)` over the unit square, `w` by `h` metres, as a grid of triangles no
/// coarser than [`TESSELLATION_M`].
fn grid(out: &mut Vec<[Point3<f64>; 3]>, w: f64, h: f64, at: impl Fn(f64, f64) -> Point3<f64>) {
    let cells = |len: f64| ((len / TESSELLATION_M).ceil() as usize).clamp(1, 64);
    let (nx, ny) = (cells(w), cells(h));
    for i in 0..nx {
        for j in 0..ny {
            let p =
                |di: usize, dj: usize| at((i + di) as f64 / nx as f64, (j + dj) as f64 / ny as f64);
            out.push([p(0, 0), p(1, 0), p(1, 1)]);
            out.push([p(0, 0), p(1, 1), p(0, 1)]);
        }
    }
}

/// `t`, split at its longest edge's midpoint until no edge exceeds [`TESSELLATION_M`].
fn split(t: [Point3<f64>; 3], out: &mut Vec<[Point3<f64>; 3]>) {
    let edges = [(0, 1), (1, 2), (2, 0)];
    let (a, b) = edges
        .into_iter()
        .max_by(|x, y| {
            (t[x.0] - t[x.1])
                .norm()
                .total_cmp(&(t[y.0] - t[y.1]).norm())
        })
        .expect("three edges");
    if (t[a] - t[b]).norm() <= TESSELLATION_M {
        out.push(t);
        return;
    }
    let c = 3 - a - b;
    let m = nalgebra::center(&t[a], &t[b]);
    split([t[a], m, t[c]], out);
    split([m, t[b], t[c]], out);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::dh_robot::{chain_from_dh, ur5_parameters};

    #[test]
    fn lengthening_adds_to_every_ur5_length_and_bending_moves_the_tip_out_of_plane() {
        let chain = chain_from_dh(&ur5_parameters(), [-3.2, 3.2]);
        let longer = ArmChange::Lengthen { cm: 3.0 }.apply(&chain).unwrap();
        // All joints at zero: x = a2 + a3, y = -(d4 + d6), z = d1 - d5 (see dh_robot).
        let home = longer.end_effector(&[0.0; 6]);
        let expected = [
            -(0.425 + 0.03) - (0.39225 + 0.03),
            -(0.10915 + 0.03) - (0.0823 + 0.03),
            (0.089159 + 0.03) - (0.09465 + 0.03),
        ];
        for k in 0..3 {
            assert!((home[k] - expected[k]).abs() < 1e-9, "{home:?}");
        }
        // Bending the upper arm (the link to joint 3) by 3 degrees at the shoulder moves the
        // tip about 3 degrees of the arm's reach, and not in the shoulder's plane only.
        let bent = ArmChange::Bend { joint: 2, deg: 3.0 }
            .apply(&chain)
            .unwrap();
        let q = [0.3, -0.4, 0.5, 0.2, 0.1, 0.0];
        let moved = (bent.end_effector(&q) - chain.end_effector(&q)).norm();
        assert!(moved > 0.01 && moved < 0.06, "moved {moved} m");
        assert!(
            ArmChange::Bend { joint: 6, deg: 1.0 }
                .apply(&chain)
                .is_err()
        );
    }
}
