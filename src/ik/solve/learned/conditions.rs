//! What the flow is conditioned on: each target's tips as rows (the position normalised over
//! the training positions' bounds, then the unit quaternion with `w >= 0`), and their width.

use crate::ik::data::IkData;
use crate::ik::solve::levenberg_marquardt::PoseTarget;

/// The condition rows of `targets` (for each tip, its position normalised, then its
/// quaternion with `w >= 0`).
pub(super) fn condition_rows(
    data: &IkData,
    targets: &[Vec<PoseTarget>],
    position_only: bool,
) -> Vec<f32> {
    let tips = targets.first().map_or(1, Vec::len);
    let mut rows = Vec::with_capacity(targets.len() * tips * 7);
    for t in targets.iter().flatten() {
        rows.extend(data.normalise_position(&t.position));
        if !position_only {
            let q = t
                .orientation
                .expect("a full-pose model's targets have orientations");
            let c = q.coords; // (x, y, z, w)
            let sign = if c.w < 0.0 { -1.0 } else { 1.0 };
            rows.extend([c.w, c.x, c.y, c.z].map(|v| (sign * v) as f32));
        }
    }
    rows
}

/// The condition width of a model: 3 or 7 values a tip.
pub(super) fn condition_width(position_only: bool, tips: usize) -> usize {
    tips.max(1) * if position_only { 3 } else { 7 }
}
