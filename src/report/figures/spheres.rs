//! A robot's collision spheres drawn over its collision meshes: both rendered by the ray
//! caster from two sides, every joint at the middle of its range, the pixels coloured by which covers them (mesh and
//! spheres; spheres only, the check's conservative excess; mesh only, which would be a hole
//! in the cover and should not appear).

use std::path::Path;

use crate::core::error::Result;
use crate::sim::bvh::Bvh;
use crate::sim::camera::Camera;
use crate::sim::collision::spheres::Sphere;
use crate::sim::ray_caster::{RayCaster, RenderOptions};
use crate::sim::robot::Robot;
use crate::sim::shape::Shape;

/// Pixels covered by both, by the spheres alone, by the mesh alone (RGB).
const BOTH: [u8; 3] = [70, 90, 120];
const SPHERES_ONLY: [u8; 3] = [245, 175, 90];
const MESH_ONLY: [u8; 3] = [220, 30, 30];

/// Write `path`: `robot` (loaded with its collision geometry) and `spheres` (per link, in its
/// frame) with every joint at the middle of its range, seen from the front and from the side, `size` pixels square each.
/// Returns the share of mesh pixels the spheres do not cover (0 where the cover holds).
pub fn collision_spheres(
    robot: &Robot,
    spheres: &[Vec<Sphere>],
    path: &Path,
    size: usize,
) -> Result<f64> {
    let ranges = robot.chain.joint_ranges();
    // Every joint at the middle of its range: a bent arm shows more than a straight one.
    let home: Vec<f64> = ranges.iter().map(|r| 0.5 * (r[0] + r[1])).collect();
    let ball_robot = Robot {
        geometry: spheres
            .iter()
            .map(|s| {
                Bvh::new(
                    s.iter()
                        .map(|s| Shape::Sphere {
                            center: s.center(),
                            radius: s.radius,
                        })
                        .collect(),
                )
            })
            .collect(),
        ..robot.clone()
    };
    let frames = robot.chain.link_frames(&home);
    let points: Vec<_> = spheres
        .iter()
        .zip(&frames)
        .flat_map(|(s, f)| s.iter().map(move |s| f * s.center()))
        .collect();
    let base = Camera {
        width: size,
        height: size,
        ..Camera::paper()
    };
    let mut panels = Vec::new();
    let (mut uncovered, mut mesh) = (0usize, 0usize);
    for direction in [[1.0, -0.6, 0.35], [0.0, 1.0, 0.2]] {
        let camera = base.framing(&points, direction, 0.12)?;
        let render =
            |r: &Robot| RayCaster::new(r, camera.clone(), RenderOptions::default()).render(&home);
        let (m, b) = (render(robot), render(&ball_robot));
        let mut rgb = vec![255u8; size * size * 3];
        for (i, (&a, &c)) in m.silhouette.iter().zip(&b.silhouette).enumerate() {
            let colour = match (a > 0, c > 0) {
                (true, true) => BOTH,
                (false, true) => SPHERES_ONLY,
                (true, false) => MESH_ONLY,
                (false, false) => continue,
            };
            rgb[3 * i..3 * i + 3].copy_from_slice(&colour);
        }
        mesh += m.silhouette.iter().filter(|&&a| a > 0).count();
        uncovered += (m.silhouette.iter().zip(&b.silhouette))
            .filter(|(a, c)| **a > 0 && **c == 0)
            .count();
        panels.push(rgb);
    }
    // The two views side by side, a white column between them.
    let gap = 8;
    let width = 2 * size + gap;
    let mut out = vec![255u8; width * size * 3];
    for (p, panel) in panels.iter().enumerate() {
        for row in 0..size {
            let dst = (row * width + p * (size + gap)) * 3;
            out[dst..dst + size * 3].copy_from_slice(&panel[row * size * 3..(row + 1) * size * 3]);
        }
    }
    super::save_rgb(path, &out, width as u32, size as u32)?;
    Ok(uncovered as f64 / mesh.max(1) as f64)
}
