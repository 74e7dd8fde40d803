//! STL meshes (binary and ASCII) as triangles, via the `stl_io` crate.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use nalgebra::{Isometry3, Point3, Vector3};

use crate::core::error::{Error, Result};
use crate::sim::shape::Shape;

/// Read an STL file and return its triangles, scaled by `scale` and placed by `pose`
/// (the URDF `<visual><origin>`), in the link frame.
pub fn load_stl(path: &Path, scale: Vector3<f64>, pose: &Isometry3<f64>) -> Result<Vec<Shape>> {
    let file = File::open(path).map_err(|e| Error::Mesh {
        path: path.into(),
        msg: format!("cannot open mesh: {e}"),
    })?;
    let mut reader = BufReader::new(file);
    let bad = |e: std::io::Error| Error::Mesh {
        path: path.into(),
        msg: format!("not a valid STL file: {e}"),
    };
    let triangles = stl_io::create_stl_reader(&mut reader).map_err(bad)?;
    let mut shapes = Vec::new();
    for t in triangles {
        let t = t.map_err(bad)?;
        let v = t.vertices.map(|v| {
            let p = Point3::new(
                v[0] as f64 * scale.x,
                v[1] as f64 * scale.y,
                v[2] as f64 * scale.z,
            );
            pose * p
        });
        if v.iter().any(|p| !p.coords.iter().all(|c| c.is_finite())) {
            return Err(Error::Mesh {
                path: path.into(),
                msg: "a vertex is NaN or infinite".into(),
            });
        }
        shapes.push(Shape::Triangle(v));
    }
    if shapes.is_empty() {
        return Err(Error::Mesh {
            path: path.into(),
            msg: "the mesh has no triangles".into(),
        });
    }
    Ok(shapes)
}
