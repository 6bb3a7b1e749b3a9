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
        // Materials are not needed: every material library resolves to none.
        let (models, _materials) =
            tobj::load_obj_buf(reader, &options, |_| Ok((Vec::new(), Default::default())))
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
