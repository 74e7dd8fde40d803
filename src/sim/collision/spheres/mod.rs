//! Spheres fitted to a link's collision geometry, as cuRobo's robot files give them, covering
//! all of its surface: the surface cut into triangles (`surface`: every mesh triangle cut
//! into sub-triangles with edges no longer than `spacing_m`), the spheres placed by a budget
//! ([`SphereBudget`]), then grown until every triangle is held whole by one (its three
//! corners inside: a ball is convex), and each radius by how far a curved surface lies
//! outside its triangles: every point of the surface is inside a sphere, so a pair of links
//! whose surfaces meet has spheres that meet.
//!
//! Placed as `clusters` places them (the surface's points clustered, each cluster enclosed:
//! the fewest no wider than the link, or a number a link), or as `cover` does (a greedy cover
//! by spheres centred inside the link, found on a grid by `volume`, or on its surface, each
//! standing at most a protrusion `p` outside it).

pub mod clearance;
pub mod clusters;
pub mod cover;
pub mod holding;
pub mod surface;
pub mod volume;

use nalgebra::Point3;

use crate::core::error::{Error, Result};
use crate::sim::collision::exact::ExactShapes;
pub use crate::sim::collision::sphere::Sphere;
use crate::sim::shape::Shape;
pub use surface::{MAX_SURFACE_POINTS, Surface, surface_point_count, surface_points};

/// How many spheres a link gets, and how they are placed.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SphereBudget {
    /// Clustered: the fewest (up to `most`) no wider than 1.25 times the link's half-width.
    Shaped { most: usize },
    /// Clustered: this many (fewer where the link has fewer surface samples).
    PerLink(usize),
    /// Covered: the fewest the greedy cover needs to stand at most `mm` outside the link, up
    /// to `most` (then the least protrusion `most` reach).
    Protrusion { mm: f64, most: usize },
    /// Covered as `Protrusion`, each point of the surface standing out at most `share` of the
    /// least distance other links come to it over free configurations (and at most `mm`):
    /// fine where links come close, coarse elsewhere ([`crate::sim::collision::where_close`]).
    WhereClose { mm: f64, share: f64, most: usize },
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

/// The most spheres a link may be given fine where links come close
/// ([`SphereBudget::WhereClose`]): a flat face another link passes close to wherever it goes
/// takes thousands of small spheres, which the checks' sphere trees
/// ([`crate::sim::collision::sphere_tree`]) afford.
pub const MAX_WHERE_CLOSE_PER_LINK: usize = 4096;

/// How much of the least distance other links come to a point its spheres may stand out
/// there ([`SphereBudget::WhereClose`]): half, so two links' spheres meet only where the
/// links come closer than they did in any configuration the fit looked at.
pub const WHERE_CLOSE_SHARE: f64 = 0.5;

impl SphereFit {
    /// The default fit with a budget as a user gives it: `per_link` spheres, or the fewest
    /// (up to [`MAX_PER_LINK`]) within `protrusion_mm` (with `where_close`: and within
    /// [`WHERE_CLOSE_SHARE`] of how close other links come, up to
    /// [`MAX_WHERE_CLOSE_PER_LINK`]); neither: the default's.
    pub fn with_budget(
        per_link: Option<usize>,
        protrusion_mm: Option<f64>,
        where_close: bool,
    ) -> Result<Self> {
        if where_close && protrusion_mm.is_none() {
            return Err(Error::Config(
                "`where_close` bounds a protrusion: give `protrusion_mm` too (the most a sphere may stand out where no link comes close)".into(),
            ));
        }
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
            (None, Some(mm)) if where_close => SphereBudget::WhereClose {
                mm,
                share: WHERE_CLOSE_SHARE,
                most: MAX_WHERE_CLOSE_PER_LINK,
            },
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
/// names the link); Ctrl-C ends the fit between two clusterings or covers. (A budget
/// [`SphereBudget::WhereClose`] fits a link alone within its `mm` everywhere: what other links
/// come close to is the robot's, [`crate::sim::collision::where_close`].)
pub fn fit_link(shapes: &[Shape], fit: &SphereFit) -> Result<Vec<Sphere>> {
    let spacing = fit.spacing_m;
    fit_surface(shapes, spacing, |surface, samples| match fit.budget {
        SphereBudget::Shaped { most } => clusters::shaped(samples, most, spacing),
        SphereBudget::PerLink(n) => Ok(clusters::enclosed(samples, n)),
        SphereBudget::Protrusion { mm, most } | SphereBudget::WhereClose { mm, most, .. } => {
            let allowance = vec![1e-3 * mm; surface.points.len()];
            cover_tight(shapes, (surface, samples, spacing), &allowance, most)
        }
    })
}

/// [`fit_link`] covering with an allowance of its own for each point of the link's surface
/// (`allowance[k]` for [`Surface::of`]`(shapes, spacing).points[k]`, m), up to `most` spheres
/// (beyond: the allowances raised to the least floor with which `most` do).
pub fn fit_link_within(
    shapes: &[Shape],
    spacing: f64,
    allowance: &[f64],
    most: usize,
) -> Result<Vec<Sphere>> {
    fit_surface(shapes, spacing, |surface, samples| {
        cover_tight(shapes, (surface, samples, spacing), allowance, most)
    })
}

/// The sphere shapes of `shapes`, and the spheres `place(surface, distinct points)` puts on
/// the rest of their surface cut `spacing` fine, grown to hold all of it.
fn fit_surface(
    shapes: &[Shape],
    spacing: f64,
    place: impl FnOnce(&Surface, &[Point3<f64>]) -> Result<Vec<Sphere>>,
) -> Result<Vec<Sphere>> {
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
    let count = surface_point_count(shapes, spacing);
    if count > MAX_SURFACE_POINTS {
        return Err(Error::Config(format!(
            "its collision geometry would take {count:.1e} samples at {} mm to cover (at most {MAX_SURFACE_POINTS:.0e}): is it tens or hundreds of metres across? check its size and scale",
            1e3 * spacing
        )));
    }
    let surface = Surface::of(shapes, spacing);
    let samples = surface::distinct_points(surface.points.clone(), spacing);
    if samples.is_empty() {
        return Ok(spheres);
    }
    let mut best = place(&surface, &samples)?;
    grow(&mut best, &surface);
    spheres.extend(best);
    Ok(spheres)
}

/// The cover's spheres ([`covered`]), each shrunk to what only it holds ([`tighten`]). They
/// are chosen for the surface alone (a clustered fit is left whole: its spheres fill the
/// link's inside, which a mesh obstacle read as its spheres needs).
fn cover_tight(
    shapes: &[Shape],
    (surface, samples, spacing): (&Surface, &[Point3<f64>], f64),
    allowance: &[f64],
    most: usize,
) -> Result<Vec<Sphere>> {
    let reach = surface::sample_reach(shapes, spacing);
    let mut s = covered(shapes, surface, (samples, spacing, reach), allowance, most)?;
    tighten(&mut s, surface);
    Ok(s)
}

/// The greedy cover's spheres of `surface` (of `shapes`; its distinct points `samples`,
/// `spacing` apart, no point of the surface farther than `reach` from one) standing at most
/// `allowance` outside (one a point of the surface), or, where that takes more than `most`,
/// every allowance raised to the least floor with which `most` do (the smallest allowances,
/// which take the most spheres, are the ones raised).
fn covered(
    shapes: &[Shape],
    surface: &Surface,
    (samples, spacing, reach): (&[Point3<f64>], f64, f64),
    allowance: &[f64],
    most: usize,
) -> Result<Vec<Sphere>> {
    let Some(volume) = volume::Volume::of(samples, spacing, reach, 2.0 * spacing + reach) else {
        return Ok(Vec::new());
    };
    let (lo, hi) = surface::bounds(samples);
    let size = (hi - lo).norm().max(reach);
    let exact = ExactShapes::of_link(shapes);
    let candidates = cover::Candidates::of(&volume, &exact, samples);
    let chosen = |floor: f64| -> Result<Vec<Sphere>> {
        crate::core::interrupt::check(|| "stopped fitting collision spheres".into())?;
        let raised: Vec<f64> = allowance.iter().map(|a| a.max(floor)).collect();
        Ok(cover::cover_within(&candidates, surface, &raised))
    };
    let least = allowance
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min)
        .max(1e-6);
    let first = chosen(least)?;
    if first.len() <= most.max(1) {
        return Ok(first);
    }
    // The least floor (within 5%) whose cover takes at most `most` spheres: doubled until one
    // does (one sphere of the link's size covers it all), then halved between.
    let (mut lo, mut hi, mut best) = (least, least, first);
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

/// Each sphere shrunk about its centre to the farthest corner of the triangles that no other
/// sphere holds (and left out where there are none), largest first: every triangle stays
/// held, and a sphere the cover needed when it was chosen but others made redundant since no
/// longer stands out.
fn tighten(spheres: &mut Vec<Sphere>, surface: &Surface) {
    let mut holding = holding_for(surface, spheres);
    // How many kept spheres hold each triangle.
    let mut holders = holding.holders(spheres);
    let mut order: Vec<usize> = (0..spheres.len()).collect();
    order.sort_by(|&a, &b| spheres[b].radius.total_cmp(&spheres[a].radius));
    let mut keep = vec![true; spheres.len()];
    for &i in &order {
        let c = spheres[i].center();
        let mine = holding.held_by(&spheres[i]);
        let needed = (mine.iter().filter(|&&t| holders[t as usize] == 1))
            .map(|&t| holding.reach_of(&c, t))
            .fold(None, |m: Option<f64>, d| Some(m.map_or(d, |m| m.max(d))));
        match needed {
            Some(r) => spheres[i].radius = r,
            None => keep[i] = false,
        }
        let still = |t: u32| keep[i] && holding.reach_of(&c, t) <= spheres[i].radius;
        for &t in &mine {
            if !still(t) {
                holders[t as usize] -= 1;
            }
        }
    }
    let mut k = keep.into_iter();
    spheres.retain(|_| k.next().unwrap_or(true));
}

/// `surface`'s triangles ready to be asked which of `spheres` hold them (kept in cubes of half
/// the largest radius).
fn holding_for<'a>(surface: &'a Surface, spheres: &[Sphere]) -> holding::Holding<'a> {
    let cell = spheres.iter().map(|s| s.radius).fold(1e-4, f64::max) / 2.0;
    holding::Holding::new(surface, cell)
}

/// Every triangle of `surface` no sphere holds put inside the sphere that must grow least to
/// hold it, then every radius grown by the surface's `curvature` (how far it lies outside its
/// triangles).
fn grow(spheres: &mut [Sphere], surface: &Surface) {
    if spheres.is_empty() {
        return;
    }
    let mut holding = holding_for(surface, spheres);
    let holders = holding.holders(spheres);
    for t in 0..holders.len() {
        if holders[t] > 0 {
            continue;
        }
        let need = |s: &Sphere| holding.reach_of(&s.center(), t as u32);
        let grown = (spheres.iter_mut())
            .min_by(|a, b| (need(a) - a.radius).total_cmp(&(need(b) - b.radius)))
            .expect("a sphere");
        grown.radius = grown.radius.max(need(grown));
    }
    for s in spheres {
        s.radius += surface.curvature;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A cylinder's surface (its points read at another spacing lie on the cylinder itself,
    /// past the triangles the fit saw by up to their curvature) is inside the spheres of every
    /// budget, with no slack.
    #[test]
    fn a_cylinder_is_covered_past_its_triangles() {
        let shapes = vec![Shape::Cylinder {
            pose: nalgebra::Isometry3::rotation(nalgebra::Vector3::new(0.3, 0.0, 0.0)),
            radius: 0.04,
            half_length: 0.1,
        }];
        for budget in [
            SphereBudget::Shaped { most: 16 },
            SphereBudget::PerLink(3),
            SphereBudget::Protrusion { mm: 4.0, most: 64 },
        ] {
            // Cut coarsely (9 faces around): the side bulges 2.4 mm past its triangles.
            let fit = SphereFit {
                spacing_m: 0.03,
                budget,
            };
            let spheres = fit_link(&shapes, &fit).unwrap();
            for p in surface_points(&shapes, 0.0017) {
                assert!(
                    spheres.iter().any(|s| s.contains(&p, 0.0)),
                    "{budget:?}: {p}"
                );
            }
        }
    }

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
