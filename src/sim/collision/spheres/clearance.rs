//! How close the other links come to each point of a link's surface: for each surface sample,
//! the least distance, over a robot's free configurations, from it to the links it is checked
//! against (capped). Where that clearance is large a sphere may stand far out; where it is
//! small, a sphere standing out would meet the other link's while the meshes keep apart (a
//! false alarm). What a per-sample allowance ([`super::cover::cover_within`]) is made from.

use nalgebra::{Isometry3, Point3};
use rayon::prelude::*;

use crate::sim::collision::exact::ExactShapes;

/// Each link's samples' clearance (m, at most `cap`): `samples[l]` in link `l`'s frame,
/// `links[l]` its exact shapes, `pairs` the checked pairs, `frames(k)` the link frames of
/// configuration `k` of `configurations` (`None`: it is not free, and left out).
pub fn clearances(
    samples: &[Vec<Point3<f64>>],
    links: &[ExactShapes],
    pairs: &[(usize, usize)],
    (configurations, frames): (
        usize,
        &(dyn Fn(usize) -> Option<Vec<Isometry3<f64>>> + Sync),
    ),
    cap: f64,
) -> Vec<Vec<f64>> {
    let start = || {
        samples
            .iter()
            .map(|s| vec![cap; s.len()])
            .collect::<Vec<_>>()
    };
    (0..configurations)
        .into_par_iter()
        .fold(start, |mut least, k| {
            if let Some(f) = frames(k) {
                for &(a, b) in pairs {
                    if links[a].gap(&f[a], &links[b], &f[b], cap) >= cap {
                        continue;
                    }
                    for (l, m) in [(a, b), (b, a)] {
                        lower(&mut least[l], &samples[l], (&f[l], &links[m], &f[m]), cap);
                    }
                }
            }
            least
        })
        .reduce(start, |mut x, y| {
            for (xs, ys) in x.iter_mut().zip(&y) {
                for (a, b) in xs.iter_mut().zip(ys) {
                    *a = a.min(*b);
                }
            }
            x
        })
}

/// `least` lowered to each of `samples`' distances (link at `fl`) from `other` (at `fm`),
/// where it comes within `cap`.
fn lower(
    least: &mut [f64],
    samples: &[Point3<f64>],
    (fl, other, fm): (&Isometry3<f64>, &ExactShapes, &Isometry3<f64>),
    cap: f64,
) {
    let to_other = fm.inverse() * fl;
    for (x, s) in least.iter_mut().zip(samples) {
        let p = to_other * s;
        if let Some(b) = &other.bound
            && (p - b.center()).norm() - b.radius >= *x
        {
            continue;
        }
        *x = x.min(other.surface_distance(&p)).min(cap);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, Vector3};

    /// Two boxes along x, 30 mm apart in one configuration and 50 mm in another (and 1 mm in
    /// one that is not free, left out): the samples of the first box's face towards the
    /// second have their distance to it at 30 mm; those of its far face, beyond the cap, the
    /// cap.
    #[test]
    fn a_face_s_clearance_is_its_least_distance_over_the_free_configurations() {
        let half = Vector3::new(0.05, 0.05, 0.05);
        let shape = ExactShapes::cuboid(&Isometry3::identity(), &half);
        let links = vec![shape.clone(), shape];
        let face: Vec<Point3<f64>> = (0..5)
            .map(|i| Point3::new(0.05, -0.04 + 0.02 * i as f64, 0.0))
            .collect();
        let far = vec![Point3::new(-0.05, 0.0, 0.0)];
        let samples = vec![[face.clone(), far.clone()].concat(), Vec::new()];
        let apart = [0.03, 0.05, 0.001];
        let frames = |k: usize| {
            (k < 2).then(|| {
                let x = 0.1 + apart[k];
                vec![
                    Isometry3::identity(),
                    Isometry3::from(Translation3::new(x, 0.0, 0.0)),
                ]
            })
        };
        let cap = 0.08;
        let c = clearances(&samples, &links, &[(0, 1)], (3, &frames), cap);
        for (k, p) in face.iter().enumerate() {
            assert!(
                (c[0][k] - 0.03).abs() < 1e-9,
                "face sample {p}: {}",
                c[0][k]
            );
        }
        assert_eq!(c[0][face.len()], cap, "the far face");
    }
}
