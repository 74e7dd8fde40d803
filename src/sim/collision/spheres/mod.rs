//! Spheres fitted to a link's collision geometry, as cuRobo's robot files give them, covering
//! all of its surface: the surface sampled (`surface`: every mesh vertex, and points no
//! farther apart than `spacing_m`), the spheres placed by a budget ([`SphereBudget`]), then
//! grown until every sample is inside one and each radius by the farthest a point of the
//! surface lies from its nearest sample: every point of the surface is inside a sphere, so a
//! pair of links whose surfaces meet has spheres that meet.
//!
//! Placed as `clusters` places them (the samples clustered, each cluster enclosed: the fewest
//! no wider than the link, or a number a link), or as `cover` does (a greedy cover by spheres
//! centred inside the link, found on a grid by `volume`, or on its surface, each standing at
//! most a protrusion `p` outside it, so none stands more than `p` plus that reach outside).

pub mod clearance;
pub mod clusters;
pub mod cover;
pub mod surface;
pub mod volume;

use nalgebra::Point3;

use crate::core::error::{Error, Result};
use crate::sim::collision::exact::ExactShapes;
pub use crate::sim::collision::sphere::Sphere;
use crate::sim::shape::Shape;
pub use surface::{MAX_SURFACE_POINTS, surface_point_count, surface_points};

/// How many spheres a link gets, and how they are placed.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SphereBudget {
    /// Clustered: the fewest (up to `most`) no wider than 1.25 times the link's half-width.
    Shaped { most: usize },
    /// Clustered: this many (fewer where the link has fewer surface samples).
    PerLink(usize),
    /// Covered: the fewest the greedy cover needs to stand at most `mm` outside the link (and
    /// the samples' reach past it), up to `most` (then the least protrusion `most` reach).
    Protrusion { mm: f64, most: usize },
}

/// How spheres are fitted.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SphereFit {
    /// The surface is sampled this finely (m).
    pub spacing_m: f64,
    pub budget: SphereBudget,
}

impl Default for SphereFit {
    fn default() -> Self {
        Self {
            spacing_m: 0.003,
            budget: SphereBudget::Shaped { most: 16 },
        }
    }
}

/// The most spheres a link may be given.
pub const MAX_PER_LINK: usize = 256;

impl SphereFit {
    /// The default fit with a budget as a user gives it: `per_link` spheres, or the fewest
    /// (up to [`MAX_PER_LINK`]) within `protrusion_mm`; neither: the default's.
    pub fn with_budget(per_link: Option<usize>, protrusion_mm: Option<f64>) -> Result<Self> {
        let budget = match (per_link, protrusion_mm) {
            (Some(_), Some(_)) => {
                return Err(Error::Config(
                    "`spheres_per_link` and `protrusion_mm`: give one (a number of spheres a link, or a protrusion target), not both".into(),
                ));
            }
            (Some(n), None) if !(1..=MAX_PER_LINK).contains(&n) => {
                return Err(Error::Config(format!(
                    "`spheres_per_link` {n}: give 1 to {MAX_PER_LINK}"
                )));
            }
            (Some(n), None) => SphereBudget::PerLink(n),
            (None, Some(mm)) if !(mm.is_finite() && mm > 0.0 && mm <= 1000.0) => {
                return Err(Error::Config(format!(
                    "`protrusion_mm` {}: give a distance above 0 and at most 1000 mm",
                    crate::core::error::short_number(mm)
                )));
            }
            (None, Some(mm)) => SphereBudget::Protrusion {
                mm,
                most: MAX_PER_LINK,
            },
            (None, None) => Self::default().budget,
        };
        Ok(Self {
            budget,
            ..Self::default()
        })
    }
}

/// Spheres covering one link's collision shapes (none for a link without any; a sphere among
/// them is its own). A surface beyond [`MAX_SURFACE_POINTS`] samples is refused (the caller
/// names the link); Ctrl-C ends the fit between two clusterings or covers.
pub fn fit_link(shapes: &[Shape], fit: &SphereFit) -> Result<Vec<Sphere>> {
    let mut spheres: Vec<Sphere> = shapes
        .iter()
        .filter_map(|s| match s {
            Shape::Sphere { center, radius } => Some(Sphere {
                center: [center.x, center.y, center.z],
                radius: *radius,
            }),
            _ => None,
        })
        .collect();
    let spacing = fit.spacing_m;
    let count = surface_point_count(shapes, spacing);
    if count > MAX_SURFACE_POINTS {
        return Err(Error::Config(format!(
            "its collision geometry would take {count:.1e} samples at {} mm to cover (at most {MAX_SURFACE_POINTS:.0e}): is it tens or hundreds of metres across? check its size and scale",
            1e3 * spacing
        )));
    }
    let all = surface_points(shapes, spacing);
    let samples = surface::distinct_points(all.clone(), spacing);
    let reach = surface::sample_reach(shapes, spacing);
    if samples.is_empty() {
        return Ok(spheres);
    }
    let mut best = match fit.budget {
        SphereBudget::Shaped { most } => clusters::shaped(&samples, most, spacing)?,
        SphereBudget::PerLink(n) => clusters::enclosed(&samples, n),
        SphereBudget::Protrusion { mm, most } => {
            // The cover's spheres are chosen for the surface alone: each shrunk to what only
            // it covers. (A clustered fit is left whole: its spheres fill the link's inside,
            // which a mesh obstacle read as its spheres needs.)
            let mut s = covered(shapes, (&samples, &all), (spacing, reach), 1e-3 * mm, most)?;
            tighten(&mut s, &all);
            s
        }
    };
    grow(&mut best, &all, reach);
    spheres.extend(best);
    Ok(spheres)
}

/// The greedy cover's spheres of every sample of `all` (of `shapes`, `spacing` apart, no point
/// of the surface farther than `reach` from one; `samples`: those without duplicates) standing
/// at most `p` outside, or the least protrusion `most` reach.
fn covered(
    shapes: &[Shape],
    (samples, all): (&[Point3<f64>], &[Point3<f64>]),
    (spacing, reach): (f64, f64),
    p: f64,
    most: usize,
) -> Result<Vec<Sphere>> {
    let Some(volume) = volume::Volume::of(samples, spacing, reach, 2.0 * spacing + reach) else {
        return Ok(Vec::new());
    };
    let (lo, hi) = surface::bounds(samples);
    let size = (hi - lo).norm().max(reach);
    let candidates = cover::Candidates::of(&volume, &ExactShapes::of_link(shapes), samples);
    let chosen = |p: f64| -> Result<Vec<Sphere>> {
        crate::core::interrupt::check(|| "stopped fitting collision spheres".into())?;
        Ok(cover::cover(&candidates, all, p))
    };
    let first = chosen(p)?;
    if first.len() <= most.max(1) {
        return Ok(first);
    }
    // The least protrusion (within 5%) whose cover takes at most `most` spheres: doubled from
    // `p` until one does (one sphere of the link's size covers it all), then halved between.
    let (mut lo, mut hi, mut best) = (p, p, first);
    while best.len() > most && hi < size {
        lo = hi;
        hi = (2.0 * hi).min(size);
        best = chosen(hi)?;
    }
    while hi / lo > 1.05 {
        let mid = (lo * hi).sqrt();
        let s = chosen(mid)?;
        if s.len() <= most {
            (hi, best) = (mid, s);
        } else {
            lo = mid;
        }
    }
    Ok(best)
}

/// Each sphere shrunk about its centre to the farthest sample that no other sphere covers (and
/// left out where there is none), largest first: every sample stays covered, and a sphere
/// the cover needed when it was chosen but others made redundant since no longer stands out.
fn tighten(spheres: &mut Vec<Sphere>, samples: &[Point3<f64>]) {
    let mut order: Vec<usize> = (0..spheres.len()).collect();
    order.sort_by(|&a, &b| spheres[b].radius.total_cmp(&spheres[a].radius));
    let mut keep = vec![true; spheres.len()];
    for &i in &order {
        let c = spheres[i].center();
        let needed = samples
            .iter()
            .filter(|p| spheres[i].contains(p, 0.0))
            .filter(|p| {
                !(spheres.iter().enumerate()).any(|(j, o)| j != i && keep[j] && o.contains(p, 0.0))
            })
            .map(|p| (p - c).norm())
            .fold(None, |m: Option<f64>, d| Some(m.map_or(d, |m| m.max(d))));
        match needed {
            Some(r) => spheres[i].radius = r,
            None => keep[i] = false,
        }
    }
    let mut k = keep.into_iter();
    spheres.retain(|_| k.next().unwrap_or(true));
}

/// Every sample of `all` put inside the sphere it sticks out of least, then every radius grown
/// by `reach` (the farthest a point of the surface lies from its nearest sample).
fn grow(spheres: &mut [Sphere], all: &[Point3<f64>], reach: f64) {
    for p in all {
        if spheres.iter().any(|s| s.contains(p, 0.0)) {
            continue;
        }
        if let Some(s) = spheres.iter_mut().min_by(|a, b| {
            let out = |s: &Sphere| (p - s.center()).norm() - s.radius;
            out(a).total_cmp(&out(b))
        }) {
            s.radius = (p - s.center()).norm();
        }
    }
    for s in spheres {
        s.radius += reach;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_long_box_gets_a_row_of_spheres_that_cover_all_its_surface() {
        let shapes = vec![Shape::Cuboid {
            pose: nalgebra::Isometry3::identity(),
            half: nalgebra::Vector3::new(0.3, 0.05, 0.05),
        }];
        let fit = SphereFit::default();
        let spheres = fit_link(&shapes, &fit).unwrap();
        assert!(spheres.len() >= 3, "{} spheres", spheres.len());
        let largest = spheres.iter().map(|s| s.radius).fold(0.0, f64::max);
        assert!(largest < 0.15, "largest radius {largest}");
        // Points the fit never saw (another spacing), each inside a sphere with no slack.
        for p in surface_points(&shapes, 0.0017) {
            assert!(spheres.iter().any(|s| s.contains(&p, 0.0)), "{p}");
        }
    }
}
