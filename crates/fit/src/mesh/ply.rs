//! A [`Mesh`] as a binary little-endian PLY file, the form MeshLab, Blender, trimesh and
//! Open3D all read: `element vertex` with `float x, y, z` and `uchar red, green, blue`, then
//! `element face` with `property list uchar int vertex_indices` (three a face).
//!
//! Written by hand: the format is a text header and two packed arrays, and the PLY crates
//! build a map of named properties per vertex, which costs more than the mesh itself.

use std::io::{self, Write};

use super::Mesh;
use crate::mesh::marching::MAX_VERTICES;

impl Mesh {
    /// Writes the mesh to `out` as binary little-endian PLY, with `comment` (one line) in the
    /// header.
    ///
    /// Errors: from `out`, or ([`io::ErrorKind::InvalidInput`]) a mesh whose colours are not
    /// one per vertex, a triangle with an index out of range, more vertices than a PLY `int`
    /// can index, a comment with a line break.
    pub fn write_ply<W: Write>(&self, comment: &str, out: W) -> io::Result<()> {
        check(self, comment).map_err(|m| io::Error::new(io::ErrorKind::InvalidInput, m))?;
        let mut out = io::BufWriter::with_capacity(1 << 20, out);
        write!(
            out,
            "ply\nformat binary_little_endian 1.0\ncomment {comment}\nelement vertex {}\n\
             property float x\nproperty float y\nproperty float z\n\
             property uchar red\nproperty uchar green\nproperty uchar blue\n\
             element face {}\nproperty list uchar int vertex_indices\nend_header\n",
            self.positions.len(),
            self.triangles.len()
        )?;
        let mut record = [0u8; 15];
        for (p, c) in self.positions.iter().zip(&self.colors) {
            for (a, x) in p.iter().enumerate() {
                record[4 * a..4 * a + 4].copy_from_slice(&x.to_le_bytes());
            }
            record[12..15].copy_from_slice(c);
            out.write_all(&record)?;
        }
        let mut face = [3u8; 13];
        for t in &self.triangles {
            for (a, &i) in t.iter().enumerate() {
                // Checked above: every index fits an `int`.
                face[1 + 4 * a..5 + 4 * a].copy_from_slice(&(i as i32).to_le_bytes());
            }
            out.write_all(&face)?;
        }
        out.flush()
    }
}

/// Why `mesh` cannot be written, if it cannot.
fn check(mesh: &Mesh, comment: &str) -> Result<(), String> {
    let n = mesh.positions.len();
    if mesh.colors.len() != n {
        return Err(format!("{} colours for {n} vertices", mesh.colors.len()));
    }
    if n > MAX_VERTICES {
        return Err(format!("{n} vertices: a PLY int indexes {MAX_VERTICES} at most"));
    }
    if let Some(t) = mesh.triangles.iter().find(|t| t.iter().any(|&i| i as usize >= n)) {
        return Err(format!("triangle {t:?} of a mesh of {n} vertices"));
    }
    if comment.contains(['\n', '\r']) {
        return Err(format!("the comment {comment:?} has a line break"));
    }
    Ok(())
}
