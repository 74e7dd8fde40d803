//! A robot's collision spheres drawn over its collision meshes: both rendered by the ray
//! caster from two sides, every joint at the middle of its range, the pixels coloured by which covers them (mesh and
//! spheres; spheres only, the check's conservative excess; mesh only, which would be a hole
//! in the cover and should not appear). A title, a legend of the three colours and a 10 cm
//! scale bar in each view say what is drawn.

use std::path::Path;

use plotters::prelude::*;

use super::{FONT, draw_err, register_font};
use crate::report::canvas::Canvas;

use crate::core::error::Result;
use nalgebra::Point3;

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
    let mut scales = Vec::new();
    let (mut uncovered, mut mesh) = (0usize, 0usize);
    for direction in [[1.0, -0.6, 0.35], [0.0, 1.0, 0.2]] {
        let camera = base.framing(&points, direction, 0.12)?;
        // Pixels per metre at the point the camera looks at (the robot's middle).
        let distance = (Point3::from(camera.eye) - Point3::from(camera.target)).norm();
        let metres_across = 2.0 * distance * (camera.fov_deg.to_radians() / 2.0).tan();
        scales.push(size as f64 / metres_across.max(1e-9));
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
    // The two views side by side, a white column between them, under the title and legend.
    let gap = 8;
    let top = 48;
    let width = 2 * size + gap;
    let height = top + size;
    let mut out = vec![255u8; width * height * 3];
    for (p, panel) in panels.iter().enumerate() {
        for row in 0..size {
            let dst = ((top + row) * width + p * (size + gap)) * 3;
            out[dst..dst + size * 3].copy_from_slice(&panel[row * size * 3..(row + 1) * size * 3]);
        }
    }
    let count: usize = spheres.iter().map(Vec::len).sum();
    let title = format!(
        "{}: {count} collision spheres over its collision meshes, every joint at mid-range",
        robot.name
    );
    label(
        &mut out,
        (width, height),
        &title,
        &scales,
        (size, gap, top),
        path,
    )?;
    super::save_rgb(path, &out, width as u32, height as u32)?;
    Ok(uncovered as f64 / mesh.max(1) as f64)
}

/// The title, the colours' legend and a 10 cm bar in each view (`px_per_m` each), drawn into
/// `buf` (`size` pixels a view, `gap` between them, the views `top` pixels down).
fn label(
    buf: &mut [u8],
    (width, height): (usize, usize),
    title: &str,
    px_per_m: &[f64],
    (size, gap, top): (usize, usize, usize),
    path: &Path,
) -> Result<()> {
    register_font();
    let root = Canvas::with_buffer(buf, (width as u32, height as u32)).into_drawing_area();
    let text = |px: f64| (FONT, px).into_font().color(&BLACK);
    let err = |e| draw_err(path, e);
    root.draw(&Text::new(title.to_string(), (6, 4), text(13.0)))
        .map_err(err)?;
    let mut x = 6;
    for (colour, what) in [
        (BOTH, "mesh and spheres"),
        (SPHERES_ONLY, "spheres only (the check's excess)"),
        (MESH_ONLY, "mesh only (a hole: none expected)"),
    ] {
        let rgb = RGBColor(colour[0], colour[1], colour[2]);
        root.draw(&Rectangle::new([(x, 26), (x + 12, 38)], rgb.filled()))
            .map_err(err)?;
        root.draw(&Text::new(what.to_string(), (x + 16, 25), text(12.0)))
            .map_err(err)?;
        x += 24 + 7 * what.len() as i32;
    }
    for (p, &scale) in px_per_m.iter().enumerate() {
        let bar = (0.1 * scale).round() as i32;
        let (x0, y0) = ((p * (size + gap)) as i32 + 10, (top + size) as i32 - 12);
        root.draw(&Rectangle::new(
            [(x0, y0), (x0 + bar, y0 + 3)],
            BLACK.filled(),
        ))
        .map_err(err)?;
        root.draw(&Text::new("10 cm".to_string(), (x0, y0 - 15), text(12.0)))
            .map_err(err)?;
    }
    root.present().map_err(err)?;
    Ok(())
}
