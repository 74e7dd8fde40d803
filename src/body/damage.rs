//! Damage read from what the camera sees (self-modeling paper section VI-B and VI-D2): the
//! robot is commanded to k poses; the self-model renders what a healthy robot would look like
//! there; where the images disagree with it, something has changed.
//!
//! - Detection: each image's residual is `1 - IoU` between the self-model's silhouette
//!   (thresholded at 0.5) and the observed one; the score of k images is their mean. Its
//!   threshold comes from healthy images ([`threshold_at`]), its power from the ROC
//!   ([`roc_auc`]).
//! - Localisation: each movable link's mask at the commanded pose (the simulator renders the
//!   link alone, dilated by [`MASK_DILATION_PX`]) and the share of it the residual covers; the
//!   shares of k images averaged and standardised against healthy images, the damaged link is
//!   the one nearest the base whose share stands out ([`localise`]): a bend or a change of
//!   length moves the link and everything it carries, a missing part only the link.
//! - Localisation by synthesis: the robot's description damaged in each way we can name
//!   (every link bent either way, longer, shorter, its far part missing: [`hypotheses`])
//!   says which pixels each damage would change at the commanded poses ([`change_masks`]);
//!   the hypothesis whose pixels the residual covers most, against healthy trials, names
//!   the link ([`best_hypothesis`]).
//! - Identification: the damage of that family, over a grid of sizes, whose renders match
//!   the observed silhouettes best ([`identify`]): the robot's description repaired, from
//!   which the simulator renders as many images of the damaged arm as training wants.

use burn::tensor::{Device, Tensor, TensorData};

use crate::body::observations::host;
use crate::core::error::Result;
use crate::self_models::model::Render;
use crate::sim::bvh::Bvh;
use crate::sim::camera::Camera;
use crate::sim::ray_caster::{RayCaster, RenderOptions};
use crate::sim::robot::Robot;

/// Pixels a link's mask is grown by: a bent or longer link leaves its healthy outline by a
/// few pixels before the links it carries do.
pub const MASK_DILATION_PX: usize = 2;

/// The self-model's silhouettes (probabilities, `n * H * W`) for `angles` (degrees), in
/// batches of `batch`.
pub fn predicted(
    renderer: &dyn Render,
    device: &Device,
    angles: &[Vec<f64>],
    batch: usize,
) -> Result<Vec<f32>> {
    let mut out = Vec::new();
    for part in angles.chunks(batch.max(1)) {
        let dof = part[0].len();
        let q: Vec<f32> = part.iter().flatten().map(|&v| v as f32).collect();
        let (sil, _) = renderer.render(Tensor::from_data(
            TensorData::new(q, [part.len(), dof]),
            device,
        ));
        out.extend(host(sil)?);
    }
    Ok(out)
}

/// `1 - IoU` of a predicted silhouette (probabilities) against an observed one, both
/// thresholded at 0.5 (0 where both are empty).
pub fn residual(predicted: &[f32], observed: &[f32]) -> f64 {
    let (mut inter, mut union) = (0usize, 0usize);
    for (&p, &o) in predicted.iter().zip(observed) {
        let (p, o) = (p >= 0.5, o >= 0.5);
        inter += (p && o) as usize;
        union += (p || o) as usize;
    }
    if union == 0 {
        0.0
    } else {
        1.0 - inter as f64 / union as f64
    }
}

/// Per movable link (joint-vector order), its mask alone at `angles` (degrees), dilated by
/// [`MASK_DILATION_PX`]: `[pose][link][pixel]`.
pub fn link_masks(robot: &Robot, camera: &Camera, angles: &[Vec<f64>]) -> Vec<Vec<Vec<bool>>> {
    let chain = &robot.chain;
    let links: Vec<usize> = chain
        .joints
        .iter()
        .enumerate()
        .filter(|(j, jt)| jt.kind.is_movable() && chain.value_index(*j).is_some())
        .map(|(j, _)| {
            (
                chain.value_index(j).expect("an input"),
                chain.joints[j].child,
            )
        })
        .collect::<std::collections::BTreeMap<usize, usize>>()
        .into_values()
        .collect();
    let alone: Vec<Robot> = links
        .iter()
        .map(|&l| {
            let mut r = robot.clone();
            for (i, g) in r.geometry.iter_mut().enumerate() {
                if i != l {
                    *g = Bvh::new(Vec::new());
                }
            }
            r
        })
        .collect();
    let (w, h) = (camera.width, camera.height);
    angles
        .iter()
        .map(|q| {
            let si = chain.to_si(q);
            alone
                .iter()
                .map(|r| {
                    let sil = RayCaster::new(r, camera.clone(), RenderOptions::default())
                        .render(&si)
                        .silhouette;
                    dilate(&sil, w, h, MASK_DILATION_PX)
                })
                .collect()
        })
        .collect()
}

/// The damages localisation by synthesis weighs, for a robot with `links` links that joints
/// move: each link bent 4 degrees either way, 2 cm longer and shorter, 40% of it missing
/// (their sizes stand for any: the pixels they change are where any size changes them).
pub fn hypotheses(links: usize) -> Vec<crate::sim::arm_change::Damage> {
    use crate::sim::arm_change::Damage;
    (0..links)
        .flat_map(|link| {
            [
                Damage::Bend { link, deg: 4.0 },
                Damage::Bend { link, deg: -4.0 },
                Damage::Length { link, cm: 2.0 },
                Damage::Length { link, cm: -2.0 },
                Damage::Truncate {
                    link,
                    fraction: 0.4,
                },
            ]
        })
        .collect()
}

/// Per pose, per hypothesis: the pixels the damage would change (healthy render against the
/// damaged one), grown by 1 pixel: `[pose][hypothesis][pixel]`. A hypothesis that cannot
/// apply to the robot (a link too short to shorten) changes nothing.
pub fn change_masks(
    robot: &Robot,
    camera: &Camera,
    angles: &[Vec<f64>],
    hypotheses: &[crate::sim::arm_change::Damage],
) -> Vec<Vec<Vec<bool>>> {
    let si: Vec<Vec<f64>> = angles.iter().map(|q| robot.chain.to_si(q)).collect();
    let render = |r: &Robot| {
        RayCaster::new(r, camera.clone(), RenderOptions::default()).render_batch(&si, None)
    };
    let healthy = render(robot);
    let (w, h) = (camera.width, camera.height);
    let per_hypothesis: Vec<Vec<Vec<bool>>> = hypotheses
        .iter()
        .map(|d| match d.apply(robot) {
            Ok(damaged) => render(&damaged)
                .iter()
                .zip(&healthy)
                .map(|(a, b)| {
                    let diff: Vec<u8> = a
                        .silhouette
                        .iter()
                        .zip(&b.silhouette)
                        .map(|(x, y)| u8::from(x != y))
                        .collect();
                    dilate(&diff, w, h, 1)
                })
                .collect(),
            Err(_) => vec![vec![false; w * h]; angles.len()],
        })
        .collect();
    (0..angles.len())
        .map(|i| per_hypothesis.iter().map(|m| m[i].clone()).collect())
        .collect()
}

/// The damages [`identify`] tries on each link of `links`: bent by 1 to 12 degrees either way,
/// longer or shorter by 0.5 to 6 cm, its far 10 to 60% missing.
pub fn candidates(links: usize) -> Vec<crate::sim::arm_change::Damage> {
    use crate::sim::arm_change::Damage;
    (0..links)
        .flat_map(|link| {
            let bends = (1..=12).flat_map(move |d| {
                [-1.0, 1.0].map(|s| Damage::Bend {
                    link,
                    deg: s * d as f64,
                })
            });
            let lengths = (1..=12).flat_map(move |c| {
                [-1.0, 1.0].map(|s| Damage::Length {
                    link,
                    cm: s * 0.5 * c as f64,
                })
            });
            let cuts = (1..=6).map(move |f| Damage::Truncate {
                link,
                fraction: 0.1 * f as f64,
            });
            bends.chain(lengths).chain(cuts)
        })
        .collect()
}

/// The candidate damage ([`candidates`] of every link) whose silhouettes of `robot` at
/// `angles` (degrees) from `camera` match `observed` (`[n, H * W]` in [0, 1]) best, by mean
/// IoU, and that IoU. `None` if no candidate applies to the robot.
pub fn identify(
    robot: &Robot,
    camera: &Camera,
    options: &RenderOptions,
    angles: &[Vec<f64>],
    observed: &[f32],
) -> Option<(crate::sim::arm_change::Damage, f64)> {
    let px = camera.width * camera.height;
    candidates(robot.dof())
        .into_iter()
        .filter_map(|d| {
            let damaged = d.apply(robot).ok()?;
            let seen = crate::sim::ray_caster::silhouettes(&damaged, camera, options, angles);
            let iou: f64 = (0..angles.len())
                .map(|i| {
                    crate::eval::evaluation::iou(
                        &seen[i * px..(i + 1) * px],
                        &observed[i * px..(i + 1) * px],
                    )
                })
                .sum::<f64>()
                / angles.len().max(1) as f64;
            Some((d, iou))
        })
        .max_by(|a, b| a.1.total_cmp(&b.1))
}

/// The hypothesis (index) whose change the residual covers most, in standard scores against
/// healthy trials.
pub fn best_hypothesis(shares: &[f64], baseline: &ShareBaseline) -> usize {
    baseline
        .z(shares)
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .map_or(0, |(i, _)| i)
}

/// `mask` (non-zero: set) grown by `px` pixels (a square neighbourhood).
fn dilate(mask: &[u8], w: usize, h: usize, px: usize) -> Vec<bool> {
    let mut out = vec![false; w * h];
    for r in 0..h {
        for c in 0..w {
            if mask[r * w + c] == 0 {
                continue;
            }
            for rr in r.saturating_sub(px)..=(r + px).min(h - 1) {
                for cc in c.saturating_sub(px)..=(c + px).min(w - 1) {
                    out[rr * w + cc] = true;
                }
            }
        }
    }
    out
}

/// The share of each link's mask that the residual (pixels where prediction and observation
/// disagree) covers, for one image.
pub fn link_shares(predicted: &[f32], observed: &[f32], masks: &[Vec<bool>]) -> Vec<f64> {
    masks
        .iter()
        .map(|m| {
            let (mut hit, mut size) = (0usize, 0usize);
            for ((&p, &o), &inside) in predicted.iter().zip(observed).zip(m) {
                if inside {
                    size += 1;
                    hit += ((p >= 0.5) != (o >= 0.5)) as usize;
                }
            }
            if size == 0 {
                0.0
            } else {
                hit as f64 / size as f64
            }
        })
        .collect()
}

/// How healthy images' averaged link shares spread: per link, mean and standard deviation.
#[derive(Clone, Debug, PartialEq)]
pub struct ShareBaseline {
    pub mean: Vec<f64>,
    pub sd: Vec<f64>,
}

impl ShareBaseline {
    /// From the averaged shares of healthy trials (`[trial][link]`).
    pub fn new(trials: &[Vec<f64>]) -> Self {
        let links = trials.first().map_or(0, Vec::len);
        let n = trials.len().max(1) as f64;
        let mean: Vec<f64> = (0..links)
            .map(|l| trials.iter().map(|t| t[l]).sum::<f64>() / n)
            .collect();
        let sd = (0..links)
            .map(|l| {
                let v = trials.iter().map(|t| (t[l] - mean[l]).powi(2)).sum::<f64>() / n;
                v.sqrt().max(1e-6)
            })
            .collect();
        ShareBaseline { mean, sd }
    }

    /// The shares as standard scores against the healthy spread.
    pub fn z(&self, shares: &[f64]) -> Vec<f64> {
        shares
            .iter()
            .zip(self.mean.iter().zip(&self.sd))
            .map(|(s, (m, sd))| (s - m) / sd)
            .collect()
    }
}

/// The damaged link (joint-vector order) from the averaged shares of k images: the one
/// nearest the base whose standard score exceeds `z_threshold`, else the highest scoring.
pub fn localise(shares: &[f64], baseline: &ShareBaseline, z_threshold: f64) -> usize {
    let z = baseline.z(shares);
    z.iter().position(|&v| v > z_threshold).unwrap_or_else(|| {
        z.iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .map_or(0, |(i, _)| i)
    })
}

/// The area under the ROC curve of a score meant to be higher on damaged than on healthy
/// trials: the chance that a damaged trial outscores a healthy one (ties count half).
pub fn roc_auc(healthy: &[f64], damaged: &[f64]) -> f64 {
    if healthy.is_empty() || damaged.is_empty() {
        return f64::NAN;
    }
    let mut wins = 0.0;
    for d in damaged {
        for h in healthy {
            wins += if d > h {
                1.0
            } else if d == h {
                0.5
            } else {
                0.0
            };
        }
    }
    wins / (healthy.len() * damaged.len()) as f64
}

/// The ROC curve: (false alarm rate, detection rate) at every threshold, from (0, 0) to
/// (1, 1).
pub fn roc_curve(healthy: &[f64], damaged: &[f64]) -> Vec<(f64, f64)> {
    let mut thresholds: Vec<f64> = healthy.iter().chain(damaged).copied().collect();
    thresholds.sort_by(|a, b| b.total_cmp(a));
    thresholds.dedup();
    let rate =
        |v: &[f64], t: f64| v.iter().filter(|&&s| s >= t).count() as f64 / v.len().max(1) as f64;
    let mut out = vec![(0.0, 0.0)];
    out.extend(
        thresholds
            .iter()
            .map(|&t| (rate(healthy, t), rate(damaged, t))),
    );
    out.push((1.0, 1.0));
    out
}

/// The threshold that healthy trials exceed at rate `false_alarms` (a quantile of their
/// scores): a score above it is called damage.
pub fn threshold_at(healthy: &[f64], false_alarms: f64) -> f64 {
    let mut v = healthy.to_vec();
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        return f64::INFINITY;
    }
    let i = (((1.0 - false_alarms) * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1;
    v[i]
}
