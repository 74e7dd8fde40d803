//! Random reachable pose targets (the tip's pose at joints drawn within the ranges) and the
//! targets file `ik targets` writes and `ik solve`, `bench_ik` and the reference script read:
//! `x,y,z,qw,qx,qy,qz` (each tip's `A.x,...` for several), then the joints that reach them.

use crate::ik::solve::collision::CollisionCheck;
use crate::ik::solve::learned::target_columns;
use crate::ik::solve::levenberg_marquardt::PoseTarget;
use crate::sim::robot::Robot;

/// Draws a kept joint vector may take: past them the scene is said to leave no room.
pub const MAX_DRAWS_PER_KEPT: usize = 1000;

/// Joint vectors drawn uniformly within `ranges` (seeded) that `check` accepts (every draw
/// without a check): `n` of them from at most [`MAX_DRAWS_PER_KEPT`] draws each, fewer where
/// the scene leaves little room or Ctrl-C ([`crate::core::interrupt`]) ends the draws.
pub fn kept_draws<'a>(
    ranges: &'a [[f64; 2]],
    seed: u64,
    n: usize,
    check: Option<&'a CollisionCheck>,
) -> impl Iterator<Item = Vec<f64>> + 'a {
    let draws = n.saturating_mul(if check.is_some() {
        MAX_DRAWS_PER_KEPT
    } else {
        1
    });
    crate::sim::trajectory::babbling_rows(ranges, seed)
        .take(draws)
        .take_while(|_| !crate::core::interrupt::requested())
        .filter(move |q| check.is_none_or(|c| c.valid(q)))
        .take(n)
}

/// The random reachable targets of `robot` for `model` and the joints that reach them.
pub fn random_targets(
    robot: &Robot,
    ranges: &[[f64; 2]],
    n: usize,
    seed: u64,
) -> (Vec<Vec<PoseTarget>>, Vec<Vec<f64>>) {
    let qs = crate::sim::trajectory::babbling(n, ranges, seed);
    let targets = qs.iter().map(|q| PoseTarget::of(&robot.chain, q)).collect();
    (targets, qs)
}

/// The targets as CSV ([`target_columns`]: `x,y,z,qw,qx,qy,qz`, or each tip's `A.x,...`
/// where `tips` names several) followed by the joints that reach them, in columns named after
/// the joints (what `ik solve` and the reference script read).
pub fn targets_csv(
    targets: &[Vec<PoseTarget>],
    joints: &[Vec<f64>],
    names: &[String],
    tips: &[String],
) -> String {
    let mut bytes = Vec::new();
    let rows = targets
        .iter()
        .cloned()
        .zip(joints.iter().map(Vec::as_slice));
    write_targets_csv(&mut bytes, rows, names, tips).expect("writing to memory");
    String::from_utf8(bytes).expect("CSV text")
}

/// [`targets_csv`] row by row into `w`, each row's targets made as it is written (`ik targets`
/// streams ten million rows this way instead of holding them).
pub fn write_targets_csv<Q: AsRef<[f64]>>(
    w: &mut impl std::io::Write,
    rows: impl Iterator<Item = (Vec<PoseTarget>, Q)>,
    names: &[String],
    tips: &[String],
) -> std::io::Result<()> {
    let columns = target_columns(tips, false);
    let taken: Vec<&str> = columns.iter().map(String::as_str).collect();
    let mut header = columns.join(",");
    for c in crate::ik::solve::learned::joint_columns(names, &taken) {
        header += &format!(",{c}");
    }
    writeln!(w, "{header}")?;
    for (target, q) in rows {
        let cells: Vec<String> = target
            .iter()
            .flat_map(|t| {
                let p = t.position;
                let o = t.orientation.expect("a pose target").coords;
                [p.x, p.y, p.z, o.w, o.x, o.y, o.z]
            })
            .chain(q.as_ref().iter().copied())
            .map(|v| v.to_string())
            .collect();
        writeln!(w, "{}", cells.join(","))?;
    }
    Ok(())
}
