//! Our collision checks against the exact meshes: random configurations of a robot (uniform
//! in its joint ranges, seeded), the robot against itself, each decided by the spheres alone,
//! by the exact narrow phase behind them, and by Pinocchio and coal on the exact collision
//! meshes ([`super::pinocchio`]), the same pairs checked, at zero margin. False alarms: of the
//! configurations free on the meshes, the share a check calls colliding; misses: of those
//! colliding on the meshes, the share it calls free. Each check's time a configuration
//! (forward kinematics included, one thread) beside them. And the pairs themselves: every
//! pair of links with geometry, checked or why not (`pairs.csv`), and how many configurations
//! a check calls free collide on the meshes in a pair skipped as never colliding (Pinocchio on
//! those pairs): a pair switched off wrongly shows there.

use std::path::{Path, PathBuf};

use rand::SeedableRng;
use rand::rngs::StdRng;

use selfmodel::core::error::{Error, Result};
use selfmodel::core::timing::{Repeats, median_seconds};
use selfmodel::ik::solve::collision::{CollisionCheck, Spheres};
use selfmodel::sim::collision::model::CollisionMode;
use selfmodel::sim::collision::sphere_score::{LinkFitScore, score_robot};
use selfmodel::sim::collision::spheres::SphereFit;
use selfmodel::sim::robots::RobotSpec;

use super::pinocchio::{Reference, agreement_pct, pct, write_reference_inputs};

/// What the comparison runs.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct AgreementConfig {
    /// Random configurations.
    pub configurations: usize,
    /// Their seed: another than the pairs' sampling's (0), so a pair skipped as never
    /// colliding is tested on configurations it was not decided on.
    pub seed: u64,
    /// How our spheres are fitted.
    pub fit: SphereFit,
    /// Spheres of another's (cuRobo's robot file) scored beside ours, on the same pairs.
    pub spheres_file: Option<PathBuf>,
}

/// One check on the robot's random configurations.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct AgreementRow {
    pub robot: String,
    /// `spheres` (alone) or `exact` (the narrow phase behind them).
    pub check: String,
    /// `fitted` (ours), or the file they were read from.
    pub spheres_from: String,
    pub configurations: usize,
    pub checked_pairs: usize,
    pub spheres: usize,
    /// The share of the configurations colliding on the exact meshes (Pinocchio).
    pub mesh_colliding_pct: Option<f64>,
    /// Of the configurations free on the meshes, the share this check calls colliding.
    pub false_alarms_pct: Option<f64>,
    /// Of the configurations colliding on the meshes, the share this check calls free.
    pub misses_pct: Option<f64>,
    /// The share this check calls colliding.
    pub colliding_pct: f64,
    /// Of the configurations this check calls free, the share colliding on the meshes in a
    /// pair of links skipped as never colliding (or by an SRDF's reason of its own).
    pub colliding_in_never_pairs_pct: Option<f64>,
    /// Forward kinematics and the check, one thread, median of repeats.
    pub us_per_configuration: f64,
    pub cpu: String,
    pub git_revision: String,
}

/// What [`run`] writes into its folder.
const WRITTEN: &[&str] = &[
    "config.json",
    "results.csv",
    "results.md",
    "pairs.json",
    "random_joints.csv",
    "random_joints_exact_meshes.csv",
    "never_pairs.json",
    "random_joints_never_pairs_exact_meshes.csv",
    "pairs.csv",
    "links.csv",
    "links.md",
    "protrusion.png",
];

/// One pair of links with geometry: checked, or why not.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct PairRow {
    pub link_a: String,
    pub link_b: String,
    /// `checked`, or the reason it is not: `adjacent` (a joint's parent and child),
    /// `default` (colliding at home), `always`, `never` (over the sampled configurations) or
    /// `user` (an SRDF's other reason).
    pub status: String,
}

/// Compare both checks of `spec`'s robot (its collision geometry, the pairs its SRDF or the
/// computed matrix leaves checked), and the spheres of `cfg.spheres_file` alone, with
/// Pinocchio's, through `python` where given, into `out`; each link's spheres scored.
pub fn run(
    spec: &RobotSpec,
    cfg: &AgreementConfig,
    python: Option<&Path>,
    out: &Path,
) -> Result<(Vec<AgreementRow>, Vec<LinkFitScore>)> {
    use selfmodel::core::atomic_file::{OutKind, check_out, refuse_overwrite, refuse_writing_over};
    if cfg.seed == selfmodel::sim::collision::pairs::PairSampling::default().seed {
        return Err(Error::Config(format!(
            "`seed` {}: the pairs checked are decided on the configurations of that seed, so a pair skipped as never colliding would never collide in them; give another",
            cfg.seed
        )));
    }
    if cfg.configurations == 0 {
        return Err(Error::Config("`configurations`: give at least one".into()));
    }
    check_out(out, OutKind::Folder)?;
    let inputs = spec.files();
    let inputs: Vec<&Path> = inputs.iter().map(|p| p.as_path()).collect();
    refuse_overwrite(out, &inputs, None)?;
    refuse_writing_over(out, WRITTEN, &inputs)?;
    selfmodel::core::atomic_file::nothing_left_on_failure(out, WRITTEN, || {
        measure(spec, cfg, python, out)
    })
}

fn measure(
    spec: &RobotSpec,
    cfg: &AgreementConfig,
    python: Option<&Path>,
    out: &Path,
) -> Result<(Vec<AgreementRow>, Vec<LinkFitScore>)> {
    let fitted = Spheres::Fitted(cfg.fit);
    // Fitted on every core (the checks are timed on one: the caller's pool).
    let exact = rayon::ThreadPoolBuilder::new()
        .build()
        .map_err(|e| Error::Config(format!("a thread pool: {e}")))?
        .install(|| CollisionCheck::with_spheres(spec, fitted, None, None, true, 0.0))?;
    let given = (cfg.spheres_file.as_deref())
        .map(|file| CollisionCheck::with_spheres(spec, Spheres::File(file), None, None, true, 0.0))
        .transpose()?
        .map(|c| c.deciding(CollisionMode::Spheres));
    let robot = &exact.robot;
    let ranges = robot.chain.joint_ranges();
    let mut rng = StdRng::seed_from_u64(cfg.seed);
    let qs: Vec<Vec<f64>> = (0..cfg.configurations)
        .map(|_| selfmodel::sim::trajectory::uniform_in(&mut rng, &ranges))
        .collect();
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    selfmodel::core::atomic_file::write_json(&out.join("config.json"), cfg)?;
    let names = robot.chain.joint_names();
    let pairs = write_reference_inputs(
        out,
        &exact,
        &names,
        &[("random_joints.csv", qs.iter().map(Vec::as_slice).collect())],
    )?;
    let never_pairs = out.join("never_pairs.json");
    let statuses = pair_statuses(&exact);
    // Adjacent pairs and those touching at home or always are allowed to touch by design.
    let never: Vec<[&str; 2]> = (statuses.iter())
        .filter(|p| !["checked", "adjacent", "default", "always"].contains(&p.status.as_str()))
        .map(|p| [p.link_a.as_str(), p.link_b.as_str()])
        .collect();
    selfmodel::core::atomic_file::write_json(&never_pairs, &never)?;
    selfmodel::report::table::write_table(
        &out.join("pairs.csv"),
        &statuses,
        "The pairs of links with collision geometry: checked, or why not",
        "As MoveIt's setup assistant decides where no SRDF says: `adjacent` (a joint's parent and child), `default` (colliding at the home pose), `always` and `never` (colliding at nearly every or at none of the sampled configurations), each decided on the links' exact shapes; `user`: an SRDF's other reason.",
    )?;
    let (meshes, meshes_never) = match (python, spec) {
        (Some(python), RobotSpec::Urdf { path, .. }) => {
            let reference = |pairs| Reference {
                python,
                urdf: path,
                pairs,
                scene: None,
            };
            let joints = out.join("random_joints.csv");
            (
                reference(pairs).collides(&joints, &out.join("random_joints_exact_meshes.csv"))?,
                reference(never_pairs).collides(
                    &joints,
                    &out.join("random_joints_never_pairs_exact_meshes.csv"),
                )?,
            )
        }
        _ => (None, None),
    };
    // The same model (spheres and pairs, computed once) deciding on the spheres alone.
    let spheres = exact.clone().deciding(CollisionMode::Spheres);
    let cpu = selfmodel::eval::compute_peak::machine_label(false);
    let revision = selfmodel::core::provenance::git_revision();
    let row = |check: &CollisionCheck, from: &str| -> Result<AgreementRow> {
        let calls: Vec<bool> = qs.iter().map(|q| !check.valid(q)).collect();
        selfmodel::core::interrupt::check(|| "stopped checking; nothing was kept".into())?;
        let seconds = median_seconds(
            Repeats {
                warmup: 0,
                min_repeats: 3,
                min_seconds: 0.0,
            },
            || {
                for q in &qs {
                    std::hint::black_box(check.valid(q));
                }
            },
        );
        let agreement = meshes.as_deref().map(|m| agreement_pct(m, &calls));
        let free = calls.iter().filter(|c| !**c).count();
        let in_never = meshes_never.as_deref().map(|never| {
            let hit = (never.iter().zip(&calls))
                .filter(|(n, c)| **n && !**c)
                .count();
            pct(hit, free)
        });
        Ok(AgreementRow {
            robot: spec.label(),
            check: check.model.mode().to_string(),
            spheres_from: from.to_string(),
            configurations: qs.len(),
            checked_pairs: check.model.pairs.len(),
            spheres: check.model.spheres.iter().map(Vec::len).sum(),
            mesh_colliding_pct: (meshes.as_deref())
                .map(|m| pct(m.iter().filter(|c| **c).count(), m.len())),
            false_alarms_pct: agreement.map(|a| a.0),
            misses_pct: agreement.map(|a| a.1),
            colliding_pct: pct(calls.iter().filter(|c| **c).count(), calls.len()),
            colliding_in_never_pairs_pct: in_never,
            us_per_configuration: 1e6 * seconds / qs.len() as f64,
            cpu: cpu.clone(),
            git_revision: revision.clone(),
        })
    };
    let mut rows = vec![row(&spheres, "fitted")?];
    let file_label = (cfg.spheres_file.as_deref())
        .and_then(|f| f.file_name())
        .map(|f| f.to_string_lossy().into_owned())
        .unwrap_or_default();
    if let Some(given) = &given {
        rows.push(row(given, &file_label)?);
    }
    rows.push(row(&exact, "fitted")?);
    let links = write_link_scores(
        &exact,
        given.as_ref().map(|g| (g, file_label.as_str())),
        out,
    )?;
    selfmodel::report::table::write_table(
        &out.join("results.csv"),
        &rows,
        "Collision checks against the exact meshes",
        &format!(
            "{} random configurations (seed {}), the robot against itself at zero margin, the same {} pairs checked by each. The reference: Pinocchio and coal on the URDF's collision meshes (a mesh is its surface). `false_alarms_pct`: of the configurations free on the meshes, the share the check calls colliding; `misses_pct`: of those colliding on the meshes, the share it calls free; `colliding_in_never_pairs_pct`: of those the check calls free, the share colliding on the meshes in a pair skipped as never colliding (`pairs.csv` says why each pair is not checked; adjacent pairs and those touching at home or always may touch by design). Time: forward kinematics and the check, one thread, median of three passes.",
            qs.len(),
            cfg.seed,
            exact.model.pairs.len()
        ),
    )?;
    Ok((rows, links))
}

/// How far apart the link scores sample the surface (m).
const SCORE_SPACING_M: f64 = 0.001;

/// Each link's spheres scored (ours, and another's where given): `links.csv`, `links.md` and
/// `protrusion.png`.
fn write_link_scores(
    ours: &CollisionCheck,
    theirs: Option<(&CollisionCheck, &str)>,
    out: &Path,
) -> Result<Vec<LinkFitScore>> {
    let robot = &ours.robot;
    let mut rows = score_robot(robot, &ours.model.spheres, SCORE_SPACING_M, "fitted");
    if let Some((check, from)) = theirs {
        rows.extend(score_robot(
            robot,
            &check.model.spheres,
            SCORE_SPACING_M,
            from,
        ));
    }
    selfmodel::report::table::write_table(
        &out.join("links.csv"),
        &rows,
        "Each link's spheres against its exact geometry",
        "`coverage_pct`: the share of the link's surface (sampled `spacing_mm` apart) inside some sphere, 100 where the spheres are conservative; `protrusion_max_mm` and `protrusion_mean_mm`: how far the outer surface of the link's spheres (256 points a sphere, those inside another sphere left out) lies outside the link, the farthest and the mean (0 where it lies inside), measured to the exact surface.",
    )?;
    // One series a set of spheres, its label saying how many and how much of the links they
    // cover.
    let mut series: Vec<(String, Vec<(String, f64, f64)>)> = Vec::new();
    let mut seen: Vec<&str> = Vec::new();
    for from in rows.iter().map(|r| r.spheres_from.as_str()) {
        if seen.contains(&from) {
            continue;
        }
        seen.push(from);
        let mine: Vec<&LinkFitScore> = rows.iter().filter(|r| r.spheres_from == from).collect();
        let count: usize = mine.iter().map(|r| r.spheres).sum();
        let (lo, hi) = (mine.iter()).fold((f64::INFINITY, 0.0f64), |(lo, hi), r| {
            (lo.min(r.coverage_pct), hi.max(r.coverage_pct))
        });
        let coverage = match lo == hi {
            true => format!("{lo:.0}%"),
            false => format!("{lo:.0}-{hi:.0}%"),
        };
        let bars = (mine.iter())
            .map(|r| (r.link.clone(), r.protrusion_max_mm, r.protrusion_mean_mm))
            .collect();
        series.push((
            format!("{from}: {count} spheres, {coverage} of each link covered"),
            bars,
        ));
    }
    selfmodel::report::figures::bars::protrusion_bars(
        &out.join("protrusion.png"),
        &format!(
            "{}: how far each link's spheres stand outside it",
            robot.name
        ),
        &series,
    )?;
    Ok(rows)
}

/// Every pair of `check`'s links with geometry: checked, or the reason it is not.
fn pair_statuses(check: &CollisionCheck) -> Vec<PairRow> {
    let links = &check.robot.chain.links;
    let has = |l: usize| !check.robot.geometry[l].is_empty();
    let mut rows = Vec::new();
    for a in (0..links.len()).filter(|&l| has(l)) {
        for b in (a + 1..links.len()).filter(|&l| has(l)) {
            let checked = check.model.pairs.contains(&(a, b));
            let reason = (check.model.allowed.as_ref())
                .and_then(|allowed| allowed.reason(&links[a], &links[b]));
            let status = match (checked, reason) {
                (true, _) => "checked".to_string(),
                (false, Some(r)) => format!("{r:?}").to_lowercase(),
                (false, None) => "not checked".to_string(),
            };
            rows.push(PairRow {
                link_a: links[a].clone(),
                link_b: links[b].clone(),
                status,
            });
        }
    }
    rows
}
