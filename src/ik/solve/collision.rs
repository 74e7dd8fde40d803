//! Collision-free answers: the check an IK answer must pass, built from a saved model's robot
//! (its collision geometry, the SRDF beside it or named) and a scene. An answer is exact and
//! collision-free only when no checked pair of its links, and none of its moving links and an
//! obstacle, come closer than the margin: on the links' exact shapes, the spheres their broad
//! phase (the default, [`CollisionMode::Exact`]), or on the spheres alone.

use std::path::Path;

use nalgebra::{DMatrix, DVector, Matrix6xX, Point3};

use crate::core::error::{Error, Result};
use crate::ik::solve::levenberg_marquardt::{Avoid, Pushed};
use crate::sim::collision::cache;
use crate::sim::collision::contacts::Placement;
use crate::sim::collision::model::{CollisionMode, CollisionModel};
use crate::sim::collision::pairs::PairSampling;
use crate::sim::collision::scene::Scene;
use crate::sim::collision::spheres::SphereFit;
use crate::sim::kinematics::TipPath;
use crate::sim::robot::Robot;
use crate::sim::robots::RobotSpec;
use crate::sim::urdf_loader::GeometryKind;

/// What an answer is checked against.
#[derive(Clone)]
pub struct CollisionCheck {
    pub model: CollisionModel,
    pub scene: Option<Scene>,
    /// Whether the robot is checked against itself.
    pub self_collision: bool,
    /// The distance kept (m).
    pub margin: f64,
    /// The robot with its collision geometry (what the spheres were fitted to).
    pub robot: Robot,
    /// From the root to each link's origin: the links' Jacobians, for the contacts' rows.
    link_paths: Vec<TipPath>,
    /// What the collision model was computed from ([`cache::key`]).
    key: String,
    /// How far a point of the collision geometry may lie outside the spheres (m): 0 for
    /// fitted spheres (they cover every point); `None` for a user's spheres.
    sphere_slack: Option<f64>,
}

/// Where a check's spheres come from.
#[derive(Clone, Copy, Debug)]
pub enum Spheres<'a> {
    /// Fitted to the robot's collision meshes.
    Fitted(SphereFit),
    /// The collision model kept in this folder (a saved IK model's, written by
    /// [`CollisionCheck::keep_in`]) where it was computed from the same robot, SRDF and
    /// settings (the fit included); fitted otherwise.
    KeptIn(&'a Path, SphereFit),
    /// A user's file in cuRobo's format (a `collision_spheres` block).
    File(&'a Path),
}

/// What answers (or training samples) are checked against, as a command or a caller names it
/// (`ik train`, `ik targets`, `ik solve`, Python's `IkSolver.solve`): the one value every one of
/// them builds its check from ([`Self::check`]).
///
/// # Examples
///
/// Nothing asked, nothing checked; a built-in robot (drawn, not measured) has no collision
/// geometry to check:
///
/// ```
/// use selfmodel::ik::solve::collision::CollisionOptions;
/// use selfmodel::{BuiltinRobot, RobotSpec};
///
/// let ur5 = RobotSpec::Builtin(BuiltinRobot::Ur5);
/// let none = CollisionOptions::default();
/// assert!(!none.any() && none.check(&ur5, None)?.is_none());
/// let itself = CollisionOptions { self_collision: true, margin: 0.005, ..Default::default() };
/// let Err(err) = itself.check(&ur5, None) else { panic!("checked") };
/// assert!(err.to_string().contains("no collision geometry"), "{err}");
/// # Ok::<(), selfmodel::Error>(())
/// ```
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CollisionOptions {
    /// Obstacles (cuRobo's world configuration).
    pub scene: Option<std::path::PathBuf>,
    /// Check against the robot itself (it always is once any option asks for a check).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub self_collision: bool,
    /// The SRDF whose `<disable_collisions>` say which links may touch (else the one beside the
    /// URDF, else the pairs computed).
    pub srdf: Option<std::path::PathBuf>,
    /// A user's spheres (cuRobo's format) instead of fitted ones.
    pub spheres: Option<std::path::PathBuf>,
    /// How spheres are fitted where no user's are given.
    #[serde(default)]
    pub fit: SphereFit,
    /// The distance kept (m).
    pub margin: f64,
    /// On what a collision is decided: the exact shapes behind the spheres (the default), or
    /// the spheres alone.
    #[serde(default)]
    pub mode: CollisionMode,
}

impl CollisionOptions {
    /// Whether any option asks for a check.
    pub fn any(&self) -> bool {
        self.scene.is_some() || self.self_collision || self.srdf.is_some() || self.spheres.is_some()
    }

    /// The files a check reads (the scene and the meshes it names, the spheres files, the
    /// SRDF): what an output must not be.
    pub fn inputs(&self) -> Result<Vec<std::path::PathBuf>> {
        let mut files = Vec::new();
        if let Some(scene) = &self.scene {
            files.extend(Scene::files(scene)?);
        }
        if let Some(spheres) = &self.spheres {
            files.extend(crate::sim::collision::user_spheres::files(spheres)?);
        }
        files.extend(self.srdf.clone());
        Ok(files)
    }

    /// The check for `spec`'s robot, where any option asks for one: the user's spheres, else
    /// the collision model kept in `kept` (a saved IK model's folder) where it was made from the
    /// same robot and settings, else spheres fitted now.
    pub fn check(&self, spec: &RobotSpec, kept: Option<&Path>) -> Result<Option<CollisionCheck>> {
        if !self.any() {
            return Ok(None);
        }
        let scene = self.scene.as_deref().map(Scene::read).transpose()?;
        let spheres = match (&self.spheres, kept) {
            (Some(file), _) => Spheres::File(file),
            (None, Some(dir)) => Spheres::KeptIn(dir, self.fit),
            (None, None) => Spheres::Fitted(self.fit),
        };
        let srdf = self.srdf.as_deref();
        let check = CollisionCheck::with_spheres(spec, spheres, srdf, scene, true, self.margin)?;
        Ok(Some(check.deciding(self.mode)))
    }
}

/// How far past the margin the solver pushes a contact (m): an answer pushed apart keeps a
/// little more than the margin, so the last steps to the target do not bring it back.
const PUSH_PAST_MARGIN_M: f64 = 0.002;

/// The largest margin accepted (m).
const MAX_MARGIN_M: f64 = 1.0;

impl CollisionCheck {
    /// The check for `spec`'s robot: its collision spheres, the allowed pairs of `srdf` (else
    /// of the SRDF beside its URDF, else computed), the obstacles of `scene`.
    pub fn for_robot(
        spec: &RobotSpec,
        srdf: Option<&Path>,
        scene: Option<Scene>,
        self_collision: bool,
        margin: f64,
    ) -> Result<Self> {
        Self::with_spheres(
            spec,
            Spheres::Fitted(SphereFit::default()),
            srdf,
            scene,
            self_collision,
            margin,
        )
    }

    /// [`Self::for_robot`] with the spheres from `spheres`.
    pub fn with_spheres(
        spec: &RobotSpec,
        spheres: Spheres,
        srdf: Option<&Path>,
        scene: Option<Scene>,
        self_collision: bool,
        margin: f64,
    ) -> Result<Self> {
        if !(margin.is_finite() && (0.0..=MAX_MARGIN_M).contains(&margin)) {
            return Err(Error::Config(format!(
                "`margin` {}: give a distance from 0 to 1 m",
                crate::core::error::short_number(margin)
            )));
        }
        let path = match spec {
            RobotSpec::Urdf { path, .. } => path,
            RobotSpec::Builtin(b) => {
                return Err(Error::Config(format!(
                    "the built-in {} has no collision geometry (its shapes are drawn, not measured): give a URDF with <collision> elements (`urdf`) to check collisions",
                    b.name()
                )));
            }
        };
        let robot = spec.with_geometry(GeometryKind::Collision).load()?;
        // Read through the bounded reader whether named or found beside the URDF: a FIFO, a
        // device or a folder is refused, not waited on.
        let (allowed, srdf_text) = match srdf
            .map(Path::to_path_buf)
            .or_else(|| crate::sim::srdf::find_beside(path).ok())
        {
            Some(file) => {
                let text = crate::core::input_file::read_xml(&file, "SRDF file")?;
                let parsed = crate::sim::srdf::Srdf::parse(&file, &text)?;
                (
                    crate::sim::collision::allowed_by_srdf(&robot, &parsed)?,
                    Some(text),
                )
            }
            None => (None, None),
        };
        if let (Some(named), None) = (srdf, &allowed) {
            // One named for collisions must say which links may touch.
            return Err(Error::Config(format!(
                "`srdf` {}: it has no <disable_collisions>, so it would change nothing: give the SRDF that lists them (MoveIt's setup assistant writes one) or leave `srdf` out",
                named.display()
            )));
        }
        let fit = match spheres {
            Spheres::Fitted(fit) | Spheres::KeptIn(_, fit) => fit,
            Spheres::File(_) => SphereFit::default(),
        };
        let sampling = PairSampling::default();
        let mut key = cache::key(&robot, srdf_text.as_deref(), &fit, &sampling);
        if let Spheres::File(file) = spheres {
            // A model from a user's spheres is never taken for a fitted one.
            let text = crate::core::input_file::read_user_file(
                file,
                "spheres file",
                crate::sim::collision::MAX_YAML_BYTES,
            )?;
            key += &format!("-{}", crate::core::input_file::fnv(&text));
        }
        let kept = match spheres {
            Spheres::KeptIn(dir, _) => cache::read(dir, &key, &robot, &fit)?,
            _ => None,
        };
        let model = match (kept, spheres) {
            (Some(model), _) => model,
            (None, Spheres::File(file)) => {
                let given = crate::sim::collision::user_spheres::read(file, &robot.chain.links)?;
                crate::sim::collision::model_with(&robot, given, None, allowed, &sampling)?
            }
            (None, _) => crate::sim::collision::model_for(&robot, allowed, &fit, &sampling)?,
        };
        let link_paths = (0..robot.chain.links.len())
            .map(|l| robot.chain.path_to(l, Point3::origin()))
            .collect();
        // Fitted spheres cover every point of the links' surfaces; a user's may not.
        let sphere_slack = (!matches!(spheres, Spheres::File(_))).then_some(0.0);
        Ok(Self {
            model,
            scene,
            self_collision,
            margin,
            robot,
            link_paths,
            key,
            sphere_slack,
        }
        .deciding(CollisionMode::Exact))
    }

    /// This check deciding by `mode`: on the links' exact shapes behind the spheres, or on
    /// the spheres alone.
    pub fn deciding(mut self, mode: CollisionMode) -> Self {
        if mode == self.model.mode() {
            return self;
        }
        self.model = match mode {
            CollisionMode::Spheres => self.model.spheres_only(),
            CollisionMode::Exact => {
                let links = crate::sim::collision::exact_links(&self.robot);
                self.model.with_exact(links, self.sphere_slack)
            }
        };
        self
    }

    /// The clearance at `q` (m, negative where something overlaps), at most `cap`.
    pub fn clearance(&self, q: &[f64], cap: f64) -> f64 {
        let frames = self.robot.chain.link_frames(q);
        let own = if self.self_collision {
            self.model.self_clearance(&frames, cap)
        } else {
            cap
        };
        match &self.scene {
            Some(s) => self.model.scene_clearance(&frames, s, own),
            None => own,
        }
    }

    /// Whether `q` keeps the margin (the first pair or obstacle closer ends the check).
    pub fn valid(&self, q: &[f64]) -> bool {
        let frames = self.robot.chain.link_frames(q);
        if self.self_collision && self.model.self_collides(&frames, self.margin) {
            return false;
        }
        !(self.scene.as_ref()).is_some_and(|s| self.model.scene_collides(&frames, s, self.margin))
    }
}

impl CollisionCheck {
    /// Keep the collision model (spheres and checked pairs) in `dir`, for
    /// [`Spheres::KeptIn`]: the same robot then needs no fitting or pair sampling.
    pub fn keep_in(&self, dir: &Path) -> Result<()> {
        cache::write(dir, &self.key, &self.robot, &self.model)
    }

    /// The contacts at `q` closer than `within` (m), each with its row `dgap/dq`: `n . v`
    /// summed over its two sides, `v` the velocity its sphere's centre gets from each joint
    /// (the link's linear Jacobian plus its angular one crossed with the centre's offset from
    /// the link origin), `n` the direction away from the other side. Analytic; a test
    /// compares it with finite differences of the gaps.
    pub fn contact_rows(&self, q: &[f64], within: f64) -> Vec<(Placement, DVector<f64>)> {
        self.contact_rows_at(q, &self.robot.chain.link_frames(q), within)
    }

    /// [`Self::contact_rows`] with `q`'s link frames already computed.
    fn contact_rows_at(
        &self,
        q: &[f64],
        frames: &[nalgebra::Isometry3<f64>],
        within: f64,
    ) -> Vec<(Placement, DVector<f64>)> {
        let near = (self.model).contacts(frames, self.scene.as_ref(), self.self_collision, within);
        let n = q.len();
        let mut jacobians: Vec<Option<(Point3<f64>, Matrix6xX<f64>)>> =
            vec![None; self.link_paths.len()];
        near.into_iter()
            .map(|c| {
                let mut row = DVector::<f64>::zeros(n);
                for &(link, center, away) in std::iter::once(&c.first).chain(c.second.as_ref()) {
                    let (origin, jac) = jacobians[link].get_or_insert_with(|| {
                        let mut jac = Matrix6xX::zeros(n);
                        let pose = self.link_paths[link].pose_and_jacobian(q, &mut jac);
                        (Point3::from(pose.translation.vector), jac)
                    });
                    let lever = (center - *origin).cross(&away);
                    for k in 0..n {
                        let col = jac.column(k);
                        row[k] +=
                            away.dot(&col.fixed_rows::<3>(0)) + lever.dot(&col.fixed_rows::<3>(3));
                    }
                }
                (c, row)
            })
            .collect()
    }
}

impl Avoid for CollisionCheck {
    fn valid(&self, q: &[f64]) -> bool {
        CollisionCheck::valid(self, q)
    }

    /// Each contact closer than the margin plus 2 mm: its row ([`Self::contact_rows`]) and
    /// how far its gap is short of that; at a trial step, each contact's gap moved by how far
    /// its points, carried by their links, move along its directions.
    fn push_apart(&self, q: &[f64], jtj: &mut DMatrix<f64>, g: &mut DVector<f64>) -> Pushed<'_> {
        let within = self.margin + PUSH_PAST_MARGIN_M;
        let mut energy = 0.0;
        let frames = self.robot.chain.link_frames(q);
        let contacts = self.contact_rows_at(q, &frames, within);
        // Each contact's gap, and each side's link, point in the link's frame and world, and
        // direction.
        let mut carried = Vec::with_capacity(contacts.len());
        for (c, row) in &contacts {
            let short = within - c.gap;
            jtj.ger(1.0, row, row, 1.0);
            g.axpy(short, row, 1.0);
            energy += 0.5 * short * short;
            let sides: Vec<_> = std::iter::once(&c.first)
                .chain(c.second.as_ref())
                .map(|&(link, p, away)| (link, frames[link].inverse_transform_point(&p), p, away))
                .collect();
            carried.push((c.gap, sides));
        }
        let at = move |q: &[f64]| {
            if carried.is_empty() {
                return 0.0;
            }
            let frames = self.robot.chain.link_frames(q);
            carried
                .iter()
                .map(|(gap, sides)| {
                    let moved: f64 = (sides.iter())
                        .map(|(link, local, p, away)| away.dot(&(frames[*link] * local - p)))
                        .sum();
                    0.5 * (within - gap - moved).max(0.0).powi(2)
                })
                .sum()
        };
        Pushed {
            energy,
            at: Box::new(at),
        }
    }
}
