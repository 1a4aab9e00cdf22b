//! Triangle meshes as binary PLY (with normals) and binary STL, in patient LPS mm.
//!
//! 3D Slicer reads models as LPS unless the file says otherwise, and both files say so in
//! their header comment ("SPACE=LPS"), as Slicer itself writes.

use std::path::Path;

use glam::{DMat3, DVec3, Vec3};

use voyage_core::{Geometry, Mesh, Result};
use voyage_io::write_atomic;

/// Volume-local → patient: a rotation and a translation, applied in f64.
struct ToPatient {
    rot: DMat3,
    origin: DVec3,
}

impl ToPatient {
    fn new(g: &Geometry) -> Self {
        ToPatient {
            rot: g.direction_mat(),
            origin: DVec3::from_array(g.origin),
        }
    }
    fn point(&self, p: [f32; 3]) -> [f32; 3] {
        (self.origin + self.rot * Vec3::from_array(p).as_dvec3())
            .as_vec3()
            .to_array()
    }
    fn normal(&self, n: [f32; 3]) -> [f32; 3] {
        (self.rot * Vec3::from_array(n).as_dvec3())
            .as_vec3()
            .to_array()
    }
}

/// Binary little-endian PLY: vertices with normals, triangles as vertex lists.
pub fn write_ply(path: &Path, mesh: &Mesh, geometry: &Geometry) -> Result<()> {
    let tp = ToPatient::new(geometry);
    write_atomic(path, |w| {
        write!(
            w,
            "ply\nformat binary_little_endian 1.0\ncomment SPACE=LPS\ncomment voyage colon surface (mm)\n\
             element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
             property float nx\nproperty float ny\nproperty float nz\n\
             element face {}\nproperty list uchar int vertex_indices\nend_header\n",
            mesh.positions.len(),
            mesh.triangles.len()
        )?;
        let mut buf = Vec::with_capacity(mesh.positions.len() * 24);
        for (p, n) in mesh.positions.iter().zip(&mesh.normals) {
            for v in tp.point(*p).iter().chain(tp.normal(*n).iter()) {
                buf.extend_from_slice(&v.to_le_bytes());
            }
        }
        w.write_all(&buf)?;
        buf.clear();
        for t in &mesh.triangles {
            buf.push(3);
            for &i in t {
                buf.extend_from_slice(&i.to_le_bytes());
            }
        }
        w.write_all(&buf)
    })
}

/// Binary STL: an 80-byte header, the count, then per triangle its normal and three corners.
pub fn write_stl(path: &Path, mesh: &Mesh, geometry: &Geometry) -> Result<()> {
    let tp = ToPatient::new(geometry);
    write_atomic(path, |w| {
        let mut header = [b' '; 80];
        let text = b"SPACE=LPS voyage colon surface (mm)";
        header[..text.len()].copy_from_slice(text);
        w.write_all(&header)?;
        w.write_all(&(mesh.triangles.len() as u32).to_le_bytes())?;
        let mut buf = Vec::with_capacity(mesh.triangles.len() * 50);
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|i| Vec3::from_array(tp.point(mesh.positions[i as usize])));
            let n = (b - a).cross(c - a).normalize_or_zero();
            for v in [n, a, b, c] {
                for x in v.to_array() {
                    buf.extend_from_slice(&x.to_le_bytes());
                }
            }
            buf.extend_from_slice(&[0, 0]);
        }
        w.write_all(&buf)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tetra() -> Mesh {
        Mesh {
            positions: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
            ],
            normals: vec![[0.0, 0.0, 1.0]; 4],
            triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        }
    }

    #[test]
    fn ply_and_stl_sizes_and_patient_frame() {
        let dir = std::env::temp_dir().join(format!("voyage-mesh-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let g = Geometry::new([2, 2, 2], [1.0; 3], [10.0, 20.0, 30.0]).unwrap();
        let m = tetra();
        let ply = dir.join("m.ply");
        write_ply(&ply, &m, &g).unwrap();
        let bytes = std::fs::read(&ply).unwrap();
        let end = bytes
            .windows(11)
            .position(|w| w == b"end_header\n")
            .unwrap()
            + 11;
        assert_eq!(bytes.len() - end, 4 * 24 + 4 * 13);
        let x = f32::from_le_bytes(bytes[end..end + 4].try_into().unwrap());
        assert_eq!(x, 10.0, "vertex 0 moved to the patient frame");
        let stl = dir.join("m.stl");
        write_stl(&stl, &m, &g).unwrap();
        let bytes = std::fs::read(&stl).unwrap();
        assert_eq!(bytes.len(), 84 + 50 * 4);
        assert_eq!(u32::from_le_bytes(bytes[80..84].try_into().unwrap()), 4);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
