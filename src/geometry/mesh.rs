//! Triangle meshes of the preoperative structures (millimetres): validation with errors that
//! say which vertex or face is wrong, normals, simple measures, and the unit icosphere the
//! procedural anatomy and the tests build on.

use glam::DVec3;
use std::collections::HashMap;

/// Why a mesh is unusable. Indices are 0-based as in [`Mesh`]; the messages count vertices and
/// faces from 1, as OBJ files and modelling tools do.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MeshError {
    #[error("mesh has no vertices")]
    NoVertices,
    #[error("mesh has no faces")]
    NoFaces,
    #[error(
        "vertex {} has a non-finite coordinate ({}, {}, {})",
        .vertex + 1, .position_mm.x, .position_mm.y, .position_mm.z
    )]
    NonFiniteVertex { vertex: usize, position_mm: DVec3 },
    #[error(
        "vertex {} has a coordinate of {distance_mm:.3e} mm: a mesh is in millimetres, within 1 km of its origin",
        .vertex + 1
    )]
    FarVertex { vertex: usize, distance_mm: f64 },
    #[error(
        "face {} refers to vertex {} but the mesh has {vertex_count} vertices",
        .face + 1,
        *.vertex as u64 + 1
    )]
    VertexOutOfRange {
        face: usize,
        vertex: u32,
        vertex_count: u32,
    },
    #[error("face {} is degenerate (repeats a vertex: {:?})", .face + 1, .corners.map(|i| i + 1))]
    RepeatedVertex { face: usize, corners: [u32; 3] },
    #[error("face {} is degenerate (zero area)", .face + 1)]
    ZeroArea { face: usize },
}

/// An indexed triangle mesh. Vertex order matters: shape catalogs and PCA modes rely on it.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Mesh {
    pub vertices: Vec<DVec3>,
    pub faces: Vec<[u32; 3]>,
}

impl Mesh {
    pub fn new(vertices: Vec<DVec3>, faces: Vec<[u32; 3]>) -> Self {
        Self { vertices, faces }
    }

    /// Checks what every later stage relies on; the error says which element is wrong.
    /// Degenerate faces (repeated index, or zero area) are refused: they have no normal and
    /// usually mean a broken export.
    pub fn validate(&self) -> Result<(), MeshError> {
        if self.vertices.is_empty() {
            return Err(MeshError::NoVertices);
        }
        if self.faces.is_empty() {
            return Err(MeshError::NoFaces);
        }
        if let Some(i) = self.vertices.iter().position(|v| !v.is_finite()) {
            return Err(MeshError::NonFiniteVertex {
                vertex: i,
                position_mm: self.vertices[i],
            });
        }
        // Squared extents of 1e300 overflow to infinity, and every face then looked like
        // zero area: a vertex that far is said as what it is.
        if let Some(i) = self
            .vertices
            .iter()
            .position(|v| v.abs().max_element() > 1e6)
        {
            return Err(MeshError::FarVertex {
                vertex: i,
                distance_mm: self.vertices[i].abs().max_element(),
            });
        }
        let n = self.vertices.len() as u32;
        let extent = self
            .bounding_box()
            .map(|(lo, hi)| (hi - lo).max_element())
            .unwrap_or(0.0);
        for (fi, f) in self.faces.iter().enumerate() {
            if let Some(&bad) = f.iter().find(|&&i| i >= n) {
                return Err(MeshError::VertexOutOfRange {
                    face: fi,
                    vertex: bad,
                    vertex_count: n,
                });
            }
            if f[0] == f[1] || f[1] == f[2] || f[0] == f[2] {
                return Err(MeshError::RepeatedVertex {
                    face: fi,
                    corners: *f,
                });
            }
            let area2 = self.face_cross(fi).length();
            if area2 <= 1e-12 * extent * extent {
                return Err(MeshError::ZeroArea { face: fi });
            }
        }
        Ok(())
    }

    fn face_cross(&self, face: usize) -> DVec3 {
        let [a, b, c] = self.faces[face].map(|i| self.vertices[i as usize]);
        (b - a).cross(c - a)
    }

    /// Area-weighted vertex normals (unit length; zero for unreferenced vertices).
    pub fn vertex_normals(&self) -> Vec<DVec3> {
        vertex_normals(&self.vertices, &self.faces)
    }

    pub fn bounding_box(&self) -> Option<(DVec3, DVec3)> {
        let first = *self.vertices.first()?;
        Some(
            self.vertices
                .iter()
                .fold((first, first), |(lo, hi), v| (lo.min(*v), hi.max(*v))),
        )
    }

    /// Mean of the vertices (the centroid the contract reports), mm.
    pub fn vertex_mean(&self) -> DVec3 {
        vertex_mean(&self.vertices)
    }

    /// Signed volume (positive when faces wind counter-clockwise seen from outside), mm³.
    pub fn signed_volume(&self) -> f64 {
        self.faces
            .iter()
            .map(|f| {
                let [a, b, c] = f.map(|i| self.vertices[i as usize]);
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    }

    /// Flips every face so that the signed volume is positive (normals point outwards).
    pub fn orient_outwards(&mut self) {
        if self.signed_volume() < 0.0 {
            for f in &mut self.faces {
                f.swap(1, 2);
            }
        }
    }
}

/// Area-weighted unit vertex normals of a vertex array under a face list.
pub fn vertex_normals(vertices: &[DVec3], faces: &[[u32; 3]]) -> Vec<DVec3> {
    let mut normals = vec![DVec3::ZERO; vertices.len()];
    for f in faces {
        let [a, b, c] = f.map(|i| vertices[i as usize]);
        let n = (b - a).cross(c - a);
        for &i in f {
            normals[i as usize] += n;
        }
    }
    for n in &mut normals {
        *n = n.normalize_or_zero();
    }
    normals
}

pub fn vertex_mean(vertices: &[DVec3]) -> DVec3 {
    if vertices.is_empty() {
        return DVec3::ZERO;
    }
    vertices.iter().copied().sum::<DVec3>() / vertices.len() as f64
}

/// Unit icosphere with `subdivisions` rounds of 4-way splits (12, 42, 162, 642, 2562 … vertices),
/// counter-clockwise seen from outside.
pub fn icosphere(subdivisions: u32) -> Mesh {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut vertices: Vec<DVec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| DVec3::new(x, y, z).normalize())
    .collect();
    let mut faces: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        let mut cache: HashMap<(u32, u32), u32> = HashMap::new();
        let mut midpoint = |a: u32, b: u32, verts: &mut Vec<DVec3>| -> u32 {
            let key = (a.min(b), a.max(b));
            *cache.entry(key).or_insert_with(|| {
                verts.push(((verts[a as usize] + verts[b as usize]) * 0.5).normalize());
                (verts.len() - 1) as u32
            })
        };
        let mut next = Vec::with_capacity(faces.len() * 4);
        for [a, b, c] in faces {
            let ab = midpoint(a, b, &mut vertices);
            let bc = midpoint(b, c, &mut vertices);
            let ca = midpoint(c, a, &mut vertices);
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        faces = next;
    }
    let mut mesh = Mesh::new(vertices, faces);
    mesh.orient_outwards();
    mesh
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tetra() -> Mesh {
        Mesh::new(
            vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z],
            vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        )
    }

    #[test]
    fn validation_names_the_bad_element() {
        assert!(tetra().validate().is_ok());
        let mut m = tetra();
        m.vertices[2].y = f64::NAN;
        assert!(m.validate().unwrap_err().to_string().contains("vertex 3"));
        let mut m = tetra();
        m.faces[1] = [0, 1, 9];
        assert!(
            m.validate()
                .unwrap_err()
                .to_string()
                .contains("face 2 refers to vertex 10")
        );
        let mut m = tetra();
        m.faces[0] = [0, 0, 1];
        assert!(m.validate().unwrap_err().to_string().contains("degenerate"));
        let mut m = tetra();
        m.vertices.push(DVec3::new(2.0, 0.0, 0.0));
        m.faces.push([0, 1, 4]);
        assert!(m.validate().unwrap_err().to_string().contains("zero area"));
    }

    #[test]
    fn volume_and_orientation() {
        let mut m = tetra();
        assert!((m.signed_volume() - 1.0 / 6.0).abs() < 1e-12);
        for f in &mut m.faces {
            f.swap(1, 2);
        }
        assert!(m.signed_volume() < 0.0);
        m.orient_outwards();
        assert!(m.signed_volume() > 0.0);
        let n = m.vertex_normals();
        // The apex normal of the origin vertex points away from the tetrahedron.
        assert!(n[0].dot(DVec3::ONE) < 0.0);
    }

    #[test]
    fn icosphere_is_a_closed_outward_unit_sphere() {
        let s = icosphere(3);
        assert_eq!(s.vertices.len(), 642);
        assert_eq!(s.faces.len(), 1280);
        assert!(s.validate().is_ok());
        let vol = s.signed_volume();
        assert!(
            (vol - 4.0 / 3.0 * std::f64::consts::PI).abs() < 0.05,
            "volume {vol}"
        );
        // Closed: every edge is shared by exactly two faces, in opposite directions.
        let mut edges = HashMap::new();
        for f in &s.faces {
            for k in 0..3 {
                *edges.entry((f[k], f[(k + 1) % 3])).or_insert(0) += 1;
            }
        }
        assert!(
            edges
                .iter()
                .all(|(&(a, b), &n)| n == 1 && edges.get(&(b, a)) == Some(&1))
        );
    }
}
