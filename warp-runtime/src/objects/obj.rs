//! Triangle meshes from Wavefront OBJ files (cargo feature `obj`), read by the `tobj` crate:
//! the points and triangle indices a [`Mesh`] is built from.
//!
//! ```ignore
//! let obj = wp::objects::ObjMesh::load("bunny.obj")?;
//! let mesh = obj.to_mesh(&dev)?; // or Mesh::new with obj.points / obj.indices uploaded
//! ```

use std::io::BufRead;
use std::path::Path;

use glam::Vec3;

use super::mesh::Mesh;
use crate::array::Array;
use crate::device::Device;
use crate::error::{Error, Result};

/// A triangle mesh read from an OBJ file: the positions of every object and group of the file
/// in one point array, each polygon triangulated as a fan from its first vertex, indices into
/// `points` (texture coordinates, normals, materials, points and lines are ignored).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ObjMesh {
    /// The vertex positions.
    pub points: Vec<Vec3>,
    /// Three vertex indices per triangle, each below `points.len()`.
    pub indices: Vec<i32>,
}

/// The OBJ text without its texture-coordinate and normal statements (`vt`, `vn`), which
/// `ObjMesh` does not use. Without them tobj never resolves a face's texture-coordinate or
/// normal index, and that is where tobj 4.0.5 overflows: a relative index reaching before
/// the first `vt` / `vn` (`f 1/-4 ...` after one `vt`) becomes an index near `usize::MAX`
/// that it multiplies unchecked (a panic in a debug build, a wrapped index in a release
/// build; found by the `obj` fuzz target). Positions are checked by tobj with saturating
/// arithmetic, and face indices into them by [`ObjMesh::read`] too.
fn positions_and_faces(reader: &mut impl BufRead) -> std::io::Result<String> {
    let mut kept = String::new();
    for line in reader.lines() {
        let line = line?;
        if !matches!(line.split_whitespace().next(), Some("vt" | "vn")) {
            kept.push_str(&line);
            kept.push('\n');
        }
    }
    Ok(kept)
}

impl ObjMesh {
    /// Reads the OBJ file at `path` (material libraries it names are not read).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the path: a file that cannot be read, a line that
    /// does not parse, a face naming a vertex the file does not have, more vertices than an
    /// `i32` indexes.
    pub fn load(path: impl AsRef<Path>) -> Result<ObjMesh> {
        let path = path.as_ref();
        let what = format!("ObjMesh::load(\"{}\")", path.display());
        let file = std::fs::File::open(path).map_err(|e| Error::invalid_in(&what, e))?;
        Self::read(&mut std::io::BufReader::new(file), &what)
    }

    /// Reads OBJ text (as [`load`](ObjMesh::load) reads a file).
    ///
    /// # Errors
    /// As [`load`](ObjMesh::load).
    pub fn parse(text: &str) -> Result<ObjMesh> {
        Self::read(&mut text.as_bytes(), "ObjMesh::parse")
    }

    fn read(reader: &mut impl BufRead, what: &str) -> Result<ObjMesh> {
        let options = tobj::LoadOptions {
            triangulate: true,
            ignore_points: true,
            ignore_lines: true,
            ..Default::default()
        };
        let text = positions_and_faces(reader).map_err(|e| Error::invalid_in(what, e))?;
        // Materials are not needed: every material library resolves to none.
        let (models, _materials) = tobj::load_obj_buf(&mut text.as_bytes(), &options, |_| {
            Ok((Vec::new(), Default::default()))
        })
        .map_err(|e| Error::invalid_in(what, e))?;
        let mut out = ObjMesh::default();
        for model in models {
            let m = model.mesh;
            let base = out.points.len();
            out.points.extend(
                m.positions
                    .chunks_exact(3)
                    .map(|p| Vec3::new(p[0], p[1], p[2])),
            );
            if out.points.len() > i32::MAX as usize {
                return Err(Error::invalid_in(
                    what,
                    format!("{} vertices: more than i32 indexes", out.points.len()),
                ));
            }
            let count = m.positions.len() / 3;
            for &i in &m.indices {
                if i as usize >= count {
                    return Err(Error::invalid_in(
                        what,
                        format!(
                            "object `{}`: a face names vertex {i} of {count}",
                            model.name
                        ),
                    ));
                }
                out.indices.push((base + i as usize) as i32);
            }
        }
        Ok(out)
    }

    /// The number of triangles.
    pub fn triangles(&self) -> usize {
        self.indices.len() / 3
    }

    /// The points and indices uploaded to `device` and built into a [`Mesh`] (no velocities).
    ///
    /// # Errors
    /// As [`Mesh::new`] (a NaN point, say), and device errors.
    pub fn to_mesh(&self, device: &Device) -> Result<Mesh> {
        Mesh::new(
            &Array::from_slice(&self.points, device)?,
            &Array::from_slice(&self.indices, device)?,
            None,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A face whose texture-coordinate or normal index is relative (negative) and reaches
    /// before the first `vt` / `vn`: tobj 4.0.5 turns it into an index near `usize::MAX` and
    /// multiplies it (`vt * 2`), which overflows: a panic in a debug build (found by the `obj`
    /// fuzz target, fuzz/corpus/obj/found_texcoord_index_overflow_806132b2.obj). ObjMesh
    /// ignores texture coordinates and normals, so the face's positions make the triangle.
    #[test]
    fn relative_texcoord_and_normal_indices_before_the_start() {
        for text in [
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/-4 2/1 3/1\n",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//-7 2//1 3//1\n",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\nf 1/-2/-9 2/1/1 3/1/1\n",
        ] {
            let m = ObjMesh::parse(text).unwrap();
            assert_eq!(m.indices, [0, 1, 2], "{text}");
            assert_eq!(m.points.len(), 3);
        }
    }
}
