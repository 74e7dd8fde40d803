//! Helpers shared by the integration tests (`mod common;`).
#![allow(dead_code)]

use nalgebra::{Isometry3, Point3};
use selfmodel::sim::bvh::Bvh;
use selfmodel::sim::kinematics::KinematicChain;
use selfmodel::sim::robot::Robot;
use selfmodel::sim::shape::Shape;

/// A robot of one fixed link holding `shapes`.
pub fn static_robot(shapes: Vec<Shape>) -> Robot {
    Robot {
        name: "static".into(),
        chain: KinematicChain::new(vec!["body".into()], vec![], Isometry3::identity(), None)
            .unwrap(),
        geometry: vec![Bvh::new(shapes)],
    }
}

/// The 12 triangles of an axis-aligned cube of half size `h` at the origin.
pub fn cube_triangles(h: f64) -> Vec<[Point3<f64>; 3]> {
    let v = |x: f64, y: f64, z: f64| Point3::new(x * h, y * h, z * h);
    let quads = [
        [
            v(-1., -1., -1.),
            v(1., -1., -1.),
            v(1., 1., -1.),
            v(-1., 1., -1.),
        ],
        [
            v(-1., -1., 1.),
            v(1., -1., 1.),
            v(1., 1., 1.),
            v(-1., 1., 1.),
        ],
        [
            v(-1., -1., -1.),
            v(1., -1., -1.),
            v(1., -1., 1.),
            v(-1., -1., 1.),
        ],
        [
            v(-1., 1., -1.),
            v(1., 1., -1.),
            v(1., 1., 1.),
            v(-1., 1., 1.),
        ],
        [
            v(-1., -1., -1.),
            v(-1., 1., -1.),
            v(-1., 1., 1.),
            v(-1., -1., 1.),
        ],
        [
            v(1., -1., -1.),
            v(1., 1., -1.),
            v(1., 1., 1.),
            v(1., -1., 1.),
        ],
    ];
    quads
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect()
}

/// An ASCII STL of a cube of half size `h`.
pub fn cube_stl_ascii(h: f64) -> String {
    let mut s = String::from("solid cube\n");
    for t in cube_triangles(h) {
        s += "facet normal 0 0 0\nouter loop\n";
        for p in t {
            s += &format!("vertex {} {} {}\n", p.x, p.y, p.z);
        }
        s += "endloop\nendfacet\n";
    }
    s + "endsolid cube\n"
}

/// A binary STL of a cube of half size `h`.
pub fn cube_stl_binary(h: f64) -> Vec<u8> {
    let tris: Vec<stl_io::Triangle> = cube_triangles(h)
        .iter()
        .map(|t| stl_io::Triangle {
            normal: stl_io::Normal::new([0.0, 0.0, 0.0]),
            vertices: t.map(|p| stl_io::Vertex::new([p.x as f32, p.y as f32, p.z as f32])),
        })
        .collect();
    let mut out = Vec::new();
    stl_io::write_stl(&mut out, tris.iter()).unwrap();
    out
}

/// A fresh folder under the system temp dir, removed when dropped. (Not the `tempfile` crate:
/// a dev-dependency would change shared dependencies' features and make `cargo run` rebuild
/// burn after `cargo test`.)
pub struct TempDir(std::path::PathBuf);

impl TempDir {
    pub fn path(&self) -> &std::path::Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

pub fn tempdir() -> TempDir {
    use std::sync::atomic::{AtomicUsize, Ordering};
    static NEXT: AtomicUsize = AtomicUsize::new(0);
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .subsec_nanos();
    let dir = std::env::temp_dir().join(format!(
        "selfmodel-test-{}-{}-{nanos}",
        std::process::id(),
        NEXT.fetch_add(1, Ordering::Relaxed)
    ));
    std::fs::create_dir_all(&dir).unwrap();
    TempDir(dir)
}

/// Mean PSNR (dB) of an all-black prediction on the first `n` test images of `spec` (all
/// when `None`): the constant predictor a trained self-model must beat.
pub fn black_psnr(spec: &selfmodel::self_models::harness::DataSpec, n: Option<usize>) -> f64 {
    let (data, _, test) = spec.load().unwrap();
    let test = test.start..test.start + n.unwrap_or(test.len()).min(test.len());
    let px = data.width * data.height;
    test.clone()
        .map(|i| {
            let truth: Vec<f32> = data.image(i).iter().map(|&v| v as f32 / 255.0).collect();
            selfmodel::eval::evaluation::psnr_db(&vec![0.0; px], &truth)
        })
        .sum::<f64>()
        / test.len() as f64
}
