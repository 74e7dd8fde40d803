//! How long a collision check of one configuration takes: the robot's forward kinematics
//! (every link frame), then its links against each other (the checked pairs) and against a
//! scene's obstacles, on the spheres alone and on the exact shapes behind them, on one thread, median of repeats over random configurations; beside it
//! the forward kinematics alone, so the check's own cost shows; and `spheres.png`, the
//! spheres over the meshes ([`selfmodel::report::figures::collision_spheres`]).

use std::path::Path;

use rand::SeedableRng;
use rand::rngs::StdRng;

use selfmodel::core::error::Result;
use selfmodel::core::timing::{Repeats, median_seconds};
use selfmodel::ik::solve::collision::CollisionCheck;
use selfmodel::sim::collision::model::CollisionMode;
use selfmodel::sim::collision::scene::Scene;
use selfmodel::sim::robots::RobotSpec;

/// One timing.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct CollisionTiming {
    pub robot: String,
    pub what: String,
    pub spheres: usize,
    pub checked_pairs: usize,
    pub obstacles: usize,
    pub configurations: usize,
    pub us_per_configuration: f64,
    /// The share of configurations found in collision (at the margin).
    pub colliding_pct: f64,
    pub cpu: String,
    pub git_revision: String,
}

/// Time checks of `n` random configurations of `spec`'s robot against itself and `scene`.
pub fn run(spec: &RobotSpec, scene: &Path, n: usize, out: &Path) -> Result<Vec<CollisionTiming>> {
    let scene = Scene::read(scene)?;
    let obstacles = scene.obstacles.len();
    let check = CollisionCheck::for_robot(spec, None, Some(scene), true, 0.0)?;
    let robot = &check.robot;
    let mut rng = StdRng::seed_from_u64(7);
    let ranges = robot.chain.joint_ranges();
    let qs: Vec<Vec<f64>> = (0..n)
        .map(|_| selfmodel::sim::trajectory::uniform_in(&mut rng, &ranges))
        .collect();
    let repeats = Repeats {
        warmup: 1,
        min_repeats: 5,
        min_seconds: 0.5,
    };
    let per = |s: f64| 1e6 * s / n.max(1) as f64;
    let fk = per(median_seconds(repeats, || {
        for q in &qs {
            std::hint::black_box(robot.chain.link_frames(q));
        }
    }));
    let cpu = selfmodel::eval::compute_peak::machine_label(false);
    let revision = selfmodel::core::provenance::git_revision();
    let row = |what: String, us: f64, obstacles: usize, colliding_pct: f64| CollisionTiming {
        robot: spec.label(),
        what,
        spheres: check.model.spheres.iter().map(Vec::len).sum(),
        checked_pairs: check.model.pairs.len(),
        obstacles,
        configurations: n,
        us_per_configuration: us,
        colliding_pct,
        cpu: cpu.clone(),
        git_revision: revision.clone(),
    };
    let mut rows = vec![row(
        "forward kinematics (every link frame)".into(),
        fk,
        0,
        0.0,
    )];
    for mode in [CollisionMode::Spheres, CollisionMode::Exact] {
        let check = check.clone().deciding(mode);
        let full = per(median_seconds(repeats, || {
            for q in &qs {
                std::hint::black_box(check.valid(q));
            }
        }));
        let colliding = qs.iter().filter(|q| !check.valid(q)).count();
        // A free configuration is checked to the end (a colliding one stops at its first hit).
        let free: Vec<&Vec<f64>> = qs.iter().filter(|q| check.valid(q)).collect();
        let free_us =
            1e6 * median_seconds(repeats, || {
                for q in &free {
                    std::hint::black_box(check.valid(q));
                }
            }) / free.len().max(1) as f64;
        // None free (a scene around another robot): nothing to time.
        let free_us = if free.is_empty() { f64::NAN } else { free_us };
        rows.extend([
            row(
                format!("forward kinematics + self and scene check ({mode})"),
                full,
                obstacles,
                100.0 * colliding as f64 / n.max(1) as f64,
            ),
            row(
                format!("the check alone, the difference ({mode})"),
                full - fk,
                obstacles,
                0.0,
            ),
            row(
                format!("forward kinematics + check, free configurations only ({mode})"),
                free_us,
                obstacles,
                0.0,
            ),
        ]);
    }
    let uncovered = selfmodel::report::figures::collision_spheres(
        robot,
        &check.model.spheres,
        &out.join("spheres.png"),
        360,
    )?;
    eprintln!(
        "bench_collision: spheres.png: {:.3}% of the mesh's pixels outside the spheres",
        100.0 * uncovered
    );
    selfmodel::report::table::write_table(
        &out.join("results.csv"),
        &rows,
        "A collision check of one configuration",
        "One thread, median of at least five passes over the same random configurations within the joint limits, after a warm-up pass; margin 0. `spheres`: decided on the spheres alone; `exact`: the spheres and convex hulls as the broad phase, the collision meshes and primitives deciding the rest.",
    )?;
    Ok(rows)
}
