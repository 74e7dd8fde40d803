//! The renderer against analytic shapes, and the fast path against the slow reference.

mod common;

use common::{cube_triangles, static_robot};
use nalgebra::{Isometry3, Point3, Vector3};
use selfmodel::eval::metrics::silhouette_iou;
use selfmodel::sim::arm4::arm4;
use selfmodel::sim::camera::Camera;
use selfmodel::sim::ray_caster::{RayCaster, RenderOptions};
use selfmodel::sim::shape::Shape;
use selfmodel::sim::trajectory::babbling;

fn render(shapes: Vec<Shape>) -> selfmodel::sim::ray_caster::Frame {
    let robot = static_robot(shapes);
    RayCaster::new(&robot, Camera::paper(), RenderOptions::default()).render(&[])
}

#[test]
fn paper_camera_focal_length_and_ray_convention() {
    let cam = Camera::paper();
    assert!((cam.focal_px() - 130.2545).abs() < 1e-4);
    let f = cam.focal_px();
    let ray = cam.ray(20.0, 70.0);
    let want = Vector3::new(-1.0, (70.0 - 50.0) / f, -(20.0 - 50.0) / f);
    assert!((ray.dir - want).norm() < 1e-12, "{:?}", ray.dir);
    // Projection inverts the ray.
    let (r, c, depth) = cam.project(&(ray.origin + ray.dir * 0.8)).unwrap();
    assert!((r - 20.0).abs() < 1e-9 && (c - 70.0).abs() < 1e-9 && (depth - 0.8).abs() < 1e-12);
}

#[test]
fn sphere_silhouette_has_the_analytic_area() {
    let radius = 0.1;
    let frame = render(vec![Shape::Sphere {
        center: Point3::origin(),
        radius,
    }]);
    // Seen from distance 1, the sphere's outline is a circle of angular radius asin(r).
    let r_px = Camera::paper().focal_px() * (radius as f64).asin().tan();
    let area = std::f64::consts::PI * r_px * r_px;
    let count = frame.silhouette.iter().filter(|&&v| v == 255).count() as f64;
    assert!(
        (count - area).abs() / area < 0.03,
        "{count} pixels, expected {area:.1}"
    );
    // Depth at the centre is the distance to the front of the sphere.
    assert!((frame.depth[50 * 100 + 50] - 0.9).abs() < 1e-6);
}

#[test]
fn box_depth_is_along_the_camera_axis() {
    let frame = render(vec![Shape::Cuboid {
        pose: Isometry3::identity(),
        half: Vector3::repeat(0.05),
    }]);
    // The front face is the plane x = 0.05: depth 0.95 everywhere on it, not the ray length.
    for (r, c) in [(50, 50), (46, 54), (53, 47)] {
        assert!(
            (frame.depth[r * 100 + c] - 0.95).abs() < 1e-6,
            "depth at ({r},{c}) = {}",
            frame.depth[r * 100 + c]
        );
    }
    // Its silhouette is a square of side 0.1 * f / 0.95 px.
    let side = 0.1 * Camera::paper().focal_px() / 0.95;
    let count = frame.silhouette.iter().filter(|&&v| v == 255).count() as f64;
    assert!(
        (count - side * side).abs() / (side * side) < 0.15,
        "{count} pixels, expected {:.1}",
        side * side
    );
    assert_eq!(
        frame.depth.iter().filter(|&&d| d > 0.0).count() as f64,
        count
    );
}

#[test]
fn cylinder_and_mesh_cube_match_their_primitives() {
    let cube: Vec<Shape> = cube_triangles(0.05)
        .into_iter()
        .map(Shape::Triangle)
        .collect();
    let a = render(cube);
    let b = render(vec![Shape::Cuboid {
        pose: Isometry3::identity(),
        half: Vector3::repeat(0.05),
    }]);
    assert!(silhouette_iou(&a.silhouette, &b.silhouette) > 0.99);
    // An upright cylinder's outline is a rectangle: width from the radius, height from the length.
    let c = render(vec![Shape::Cylinder {
        pose: Isometry3::identity(),
        radius: 0.03,
        half_length: 0.1,
    }]);
    let rows: Vec<usize> = (0..100)
        .filter(|r| c.silhouette[r * 100..(r + 1) * 100].contains(&255))
        .collect();
    let cols: Vec<usize> = (0..100)
        .filter(|&col| (0..100).any(|r| c.silhouette[r * 100 + col] == 255))
        .collect();
    let f = Camera::paper().focal_px();
    let want_rows = 2.0 * 0.1 * f / 0.97; // the front edge of the caps is nearest
    assert!(
        (rows.len() as f64 - want_rows).abs() <= 2.0,
        "{} rows, expected {want_rows:.1}",
        rows.len()
    );
    assert!(
        (cols.len() as f64 - 2.0 * 0.03 * f).abs() <= 2.0,
        "{} columns",
        cols.len()
    );
}

#[test]
fn fast_path_equals_brute_force_reference_on_arm4() {
    let robot = arm4();
    let caster = RayCaster::new(&robot, Camera::paper(), RenderOptions::default());
    for q in babbling(2, &robot.chain.joint_ranges_user(), 11) {
        let q = robot.chain.to_si(&q);
        let fast = caster.render(&q);
        let slow = caster.render_reference(&q);
        assert_eq!(fast, slow);
        assert!(fast.occupancy() > 0.01);
    }
}

#[test]
fn fast_path_equals_reference_from_a_novel_camera() {
    let robot = arm4();
    let caster = RayCaster::new(
        &robot,
        Camera::paper().orbited(60.0),
        RenderOptions::default(),
    );
    let q = robot.chain.to_si(&[30.0, -40.0, 20.0, 60.0]);
    assert_eq!(caster.render(&q), caster.render_reference(&q));
}

#[test]
fn ground_artifact_fills_below_the_horizon_only() {
    let robot = arm4();
    let plain = RayCaster::new(&robot, Camera::paper(), RenderOptions::default()).render(&[0.0; 4]);
    let ground = RayCaster::new(
        &robot,
        Camera::paper(),
        RenderOptions {
            ground_artifact: true,
        },
    )
    .render(&[0.0; 4]);
    for r in 0..100 {
        let (a, b) = (
            &plain.silhouette[r * 100..(r + 1) * 100],
            &ground.silhouette[r * 100..(r + 1) * 100],
        );
        if r > 50 {
            assert!(b.iter().all(|&v| v == 255), "row {r} should be all ground");
        } else {
            assert_eq!(a, b, "row {r} is at or above the horizon");
        }
    }
    assert_eq!(plain.depth, ground.depth);
}
