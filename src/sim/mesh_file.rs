//! Mesh files as triangles: STL (binary and ASCII), COLLADA (`.dae`, with its node transforms
//! and `<unit>`) and Wavefront OBJ, read by the `mesh-loader` crate (from the openrr project).

use std::path::Path;

use nalgebra::{Isometry3, Point3, Vector3};

use crate::core::error::{Error, Result};
use crate::core::input_file::{MAX_MESH_BYTES, catch_panic, read_regular};
use crate::sim::shape::Shape;

/// The mesh formats a robot description may name.
pub const MESH_EXTENSIONS: &[&str] = &["stl", "dae", "obj"];

/// Read a mesh file and return its triangles, scaled by `scale` and placed by `pose` (the
/// URDF `<origin>` of the visual or collision element), in the link frame.
pub fn load_mesh(path: &Path, scale: Vector3<f64>, pose: &Isometry3<f64>) -> Result<Vec<Shape>> {
    let bad = |msg: String| Error::Mesh {
        path: path.into(),
        msg,
    };
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_lowercase())
        .unwrap_or_default();
    if !MESH_EXTENSIONS.contains(&ext.as_str()) {
        return Err(bad(format!(
            "unsupported mesh format \".{ext}\" (supported: STL, COLLADA .dae, OBJ); convert it to one of them"
        )));
    }
    let read = |p: &Path| read_regular(p, "mesh", MAX_MESH_BYTES);
    let mut bytes = read(path).map_err(|e| bad(format!("cannot read mesh: {e}")))?;
    if ext == "stl" && binary_stl_saying_solid(&bytes) {
        // A binary STL whose free-form 80-byte header begins with "solid" (some exporters
        // write it) is read as ASCII by its first word: the header says nothing else, so
        // another first word makes it read as what its size says it is.
        bytes[..5].copy_from_slice(b"mesh ");
    }
    if ext == "dae"
        && let Some(unit) = collada_unit(&bytes)
        && !(unit.is_finite() && unit > 0.0)
    {
        return Err(bad(format!(
            "its <unit meter=\"{unit}\"> is not a positive length (metres per unit of the file)"
        )));
    }
    if ext == "obj"
        && let Some(line) = obj_face_index_zero(&bytes)
    {
        return Err(bad(format!(
            "line {line}: a face refers to vertex 0; OBJ numbers vertices from 1 (or from -1 backwards)"
        )));
    }
    // The loader reads what the mesh names (an OBJ's `mtllib`) through the same checks, and
    // a panic of the loader on a damaged file is an error of that file.
    let scene = catch_panic(|| {
        mesh_loader::Loader::default().load_from_slice_with_reader(&bytes, path, |p| {
            read(p).map_err(|e| std::io::Error::new(e.kind(), format!("{}: {e}", p.display())))
        })
    })
    .map_err(|panic| {
        bad(format!(
            "a damaged {} file (the mesh loader failed: {panic}); export it again",
            ext.to_uppercase()
        ))
    })?
    .map_err(|e| bad(format!("not a valid {} file: {e}", ext.to_uppercase())))?;
    let mut shapes = Vec::new();
    for mesh in &scene.meshes {
        let vertex = |i: u32| -> Result<Point3<f64>> {
            let v = mesh.vertices.get(i as usize).ok_or_else(|| {
                bad(format!(
                    "a face refers to vertex {i}, but the mesh has {}",
                    mesh.vertices.len()
                ))
            })?;
            let p = Point3::new(
                v[0] as f64 * scale.x,
                v[1] as f64 * scale.y,
                v[2] as f64 * scale.z,
            );
            if !p.coords.iter().all(|c| c.is_finite()) {
                return Err(bad("a vertex is NaN or infinite".into()));
            }
            Ok(pose * p)
        };
        for f in &mesh.faces {
            shapes.push(Shape::Triangle([
                vertex(f[0])?,
                vertex(f[1])?,
                vertex(f[2])?,
            ]));
        }
    }
    if shapes.is_empty() {
        return Err(bad("the mesh has no triangles".into()));
    }
    Ok(shapes)
}

/// The `meter` of a COLLADA file's `<unit>`, where it states one (NaN where it is no number).
fn collada_unit(bytes: &[u8]) -> Option<f64> {
    let text = std::str::from_utf8(bytes).ok()?;
    let at = text.find("<unit")?;
    let tag = &text[at..at + text[at..].find('>')?];
    let value = tag.split("meter=").nth(1)?;
    let value = value.trim_start_matches(['"', '\'']);
    let end = value.find(['"', '\'']).unwrap_or(value.len());
    Some(value[..end].trim().parse().unwrap_or(f64::NAN))
}

/// The first line (1-based) of an OBJ file with a face index of 0, which OBJ does not have.
fn obj_face_index_zero(bytes: &[u8]) -> Option<usize> {
    let text = String::from_utf8_lossy(bytes);
    text.lines().enumerate().find_map(|(i, line)| {
        let rest = line.trim_start().strip_prefix("f ")?;
        rest.split_whitespace()
            .any(|v| v.split('/').next().is_some_and(|n| n.trim() == "0"))
            .then_some(i + 1)
    })
}

/// Whether `bytes` are a binary STL whose header begins with "solid": 84 bytes of header and
/// count, then exactly 50 bytes a triangle (an ASCII STL of that exact size would have to end
/// inside a number).
fn binary_stl_saying_solid(bytes: &[u8]) -> bool {
    if !bytes.starts_with(b"solid") || bytes.len() < 84 {
        return false;
    }
    let count = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as u64;
    count > 0 && 84 + 50 * count == bytes.len() as u64
}
