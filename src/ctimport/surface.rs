//! From a well-composed voxel mask to a closed surface in world millimetres: surface nets
//! (`fast-surface-nets`) on the mask's ±1 field, mapped through the volume's voxel-to-world
//! transform, oriented outwards; and the checks the importer promises — every edge shared by
//! exactly two faces in opposite directions, one connected piece, no self-intersections
//! (edge-through-triangle tests over a uniform grid, exact for non-coplanar intersections).

use super::mask::Mask;
use super::volume::LabelVolume;
use crate::geometry::Mesh;
use fast_surface_nets::ndshape::{RuntimeShape, Shape};
use fast_surface_nets::{SurfaceNetsBuffer, surface_nets};
use glam::DVec3;
use std::collections::HashMap;

/// Extracts the surface of `mask` (which must carry at least one empty voxel of padding on every
/// side) in the world coordinates of `vol`, outward-facing. Only the largest connected piece is
/// kept (a well-composed single component gives one piece; this guards the rest).
pub fn extract(mask: &Mask, vol: &LabelVolume) -> Mesh {
    let shape = RuntimeShape::<u32, 3>::new(mask.dims.map(|d| d as u32));
    let mut sdf = vec![1.0f32; shape.usize()];
    for (n, &inside) in mask.data.iter().enumerate() {
        if inside {
            let [i, j, k] = super::mask::unflatten(mask.dims, n);
            sdf[shape.linearize([i as u32, j as u32, k as u32]) as usize] = -1.0;
        }
    }
    let mut buffer = SurfaceNetsBuffer::default();
    let max = mask.dims.map(|d| d as u32 - 1);
    surface_nets(&sdf, &shape, [0; 3], max, &mut buffer);
    let origin = DVec3::new(
        mask.origin[0] as f64,
        mask.origin[1] as f64,
        mask.origin[2] as f64,
    );
    let vertices: Vec<DVec3> = buffer
        .positions
        .iter()
        .map(|p| vol.world(origin + DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64)))
        .collect();
    let faces: Vec<[u32; 3]> = buffer
        .indices
        .chunks_exact(3)
        .map(|t| [t[0], t[1], t[2]])
        .collect();
    let mut mesh = largest_piece(&Mesh::new(vertices, faces));
    if mesh.signed_volume() < 0.0 {
        for f in &mut mesh.faces {
            f.swap(1, 2);
        }
    }
    mesh
}

/// The connected piece (through shared vertices) with the most faces, vertices renumbered in
/// first-use order.
pub fn largest_piece(mesh: &Mesh) -> Mesh {
    let n = mesh.vertices.len();
    let mut parent: Vec<usize> = (0..n).collect();
    fn find(p: &mut [usize], mut x: usize) -> usize {
        while p[x] != x {
            p[x] = p[p[x]];
            x = p[x];
        }
        x
    }
    for f in &mesh.faces {
        let a = find(&mut parent, f[0] as usize);
        for &v in &f[1..] {
            let b = find(&mut parent, v as usize);
            parent[b] = a;
        }
    }
    let mut faces_per_root: HashMap<usize, usize> = HashMap::new();
    for f in &mesh.faces {
        *faces_per_root
            .entry(find(&mut parent, f[0] as usize))
            .or_insert(0) += 1;
    }
    let Some((&root, _)) = faces_per_root
        .iter()
        .max_by_key(|(r, c)| (**c, usize::MAX - **r))
    else {
        return Mesh::default();
    };
    let faces: Vec<[u32; 3]> = mesh
        .faces
        .iter()
        .filter(|f| find(&mut parent, f[0] as usize) == root)
        .copied()
        .collect();
    compact(&mesh.vertices, &faces)
}

/// Drops unused vertices, renumbering in first-use order.
pub fn compact(vertices: &[DVec3], faces: &[[u32; 3]]) -> Mesh {
    let mut map = vec![u32::MAX; vertices.len()];
    let mut out = Vec::new();
    let faces = faces
        .iter()
        .map(|f| {
            f.map(|v| {
                let v = v as usize;
                if map[v] == u32::MAX {
                    map[v] = out.len() as u32;
                    out.push(vertices[v]);
                }
                map[v]
            })
        })
        .collect();
    Mesh::new(out, faces)
}

/// What the topology check found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct Topology {
    /// Edges used by one face only (holes).
    pub open_edges: usize,
    /// Edges used by more than two faces, or twice in the same direction.
    pub non_manifold_edges: usize,
    /// V − E + F (2 for a closed surface of genus 0).
    pub euler_characteristic: i64,
}

impl Topology {
    pub fn is_closed_manifold(&self) -> bool {
        self.open_edges == 0 && self.non_manifold_edges == 0
    }
}

pub fn topology(mesh: &Mesh) -> Topology {
    // Directed use count per undirected edge.
    let mut edges: HashMap<(u32, u32), (u32, u32)> = HashMap::new();
    for f in &mesh.faces {
        for e in 0..3 {
            let (a, b) = (f[e], f[(e + 1) % 3]);
            let entry = edges.entry((a.min(b), a.max(b))).or_insert((0, 0));
            if a < b {
                entry.0 += 1;
            } else {
                entry.1 += 1;
            }
        }
    }
    let mut t = Topology::default();
    for &(fwd, back) in edges.values() {
        match (fwd, back) {
            (1, 1) => {}
            (1, 0) | (0, 1) => t.open_edges += 1,
            _ => t.non_manifold_edges += 1,
        }
    }
    t.euler_characteristic =
        mesh.vertices.len() as i64 - edges.len() as i64 + mesh.faces.len() as i64;
    t
}

/// Pairs of faces that cross each other without sharing a vertex: an edge of one passes through
/// the other's interior. Faces sharing a vertex are skipped (neighbours on a smooth surface).
pub fn self_intersections(mesh: &Mesh) -> usize {
    let Some((lo, hi)) = mesh.bounding_box() else {
        return 0;
    };
    let tri = |f: &[u32; 3]| f.map(|v| mesh.vertices[v as usize]);
    let mean_edge = mesh
        .faces
        .iter()
        .map(|f| {
            let [a, b, _] = tri(f);
            (a - b).length()
        })
        .sum::<f64>()
        / mesh.faces.len().max(1) as f64;
    let cell = (mean_edge * 2.0).max(1e-6);
    let dims = ((hi - lo) / cell).ceil().max(DVec3::ONE);
    let (gx, gy) = (dims.x as usize + 1, dims.y as usize + 1);
    let key = |p: DVec3| {
        let c = ((p - lo) / cell).floor();
        (c.x as usize, c.y as usize, c.z as usize)
    };
    let mut grid: HashMap<usize, Vec<u32>> = HashMap::new();
    for (n, f) in mesh.faces.iter().enumerate() {
        let [a, b, c] = tri(f);
        let (l, h) = (key(a.min(b).min(c)), key(a.max(b).max(c)));
        for z in l.2..=h.2 {
            for y in l.1..=h.1 {
                for x in l.0..=h.0 {
                    grid.entry(x + gx * (y + gy * z))
                        .or_default()
                        .push(n as u32);
                }
            }
        }
    }
    let mut pairs = std::collections::HashSet::new();
    for cellfaces in grid.values() {
        for (x, &fa) in cellfaces.iter().enumerate() {
            for &fb in &cellfaces[x + 1..] {
                let (p, q) = (mesh.faces[fa as usize], mesh.faces[fb as usize]);
                if p.iter().any(|v| q.contains(v)) {
                    continue;
                }
                let (ta, tb) = (tri(&p), tri(&q));
                if triangles_cross(&ta, &tb) || triangles_cross(&tb, &ta) {
                    pairs.insert((fa.min(fb), fa.max(fb)));
                }
            }
        }
    }
    pairs.len()
}

/// Does an edge of `a` pass through triangle `b`?
fn triangles_cross(a: &[DVec3; 3], b: &[DVec3; 3]) -> bool {
    (0..3).any(|e| segment_hits_triangle(a[e], a[(e + 1) % 3], b))
}

/// Möller–Trumbore on the segment p→q, strictly inside both.
fn segment_hits_triangle(p: DVec3, q: DVec3, t: &[DVec3; 3]) -> bool {
    let dir = q - p;
    let (e1, e2) = (t[1] - t[0], t[2] - t[0]);
    let h = dir.cross(e2);
    let det = e1.dot(h);
    if det.abs() < 1e-12 {
        return false;
    }
    let inv = 1.0 / det;
    let s = p - t[0];
    let u = inv * s.dot(h);
    if !(1e-9..=1.0 - 1e-9).contains(&u) {
        return false;
    }
    let qv = s.cross(e1);
    let v = inv * dir.dot(qv);
    if v < 1e-9 || u + v > 1.0 - 1e-9 {
        return false;
    }
    let along = inv * e2.dot(qv);
    along > 1e-9 && along < 1.0 - 1e-9
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ctimport::volume::WorldTransform;
    use glam::DMat3;

    fn ball(radius_vox: f64, spacing: DVec3) -> (Mask, LabelVolume) {
        let n = (2.0 * radius_vox) as usize + 6;
        let mut m = Mask::new([n; 3], [0; 3]);
        let c = DVec3::splat(n as f64 / 2.0);
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    let p = DVec3::new(i as f64, j as f64, k as f64) - c;
                    let idx = m.index(i, j, k);
                    m.data[idx] = p.length() <= radius_vox;
                }
            }
        }
        let vol = LabelVolume {
            dims: [n; 3],
            labels: Vec::new(),
            linear: DMat3::from_diagonal(spacing),
            offset_mm: DVec3::ZERO,
            transform: WorldTransform::Pixdim,
            datatype: String::new(),
        };
        (m, vol)
    }

    #[test]
    fn a_voxel_ball_gives_a_closed_outward_surface_of_its_volume() {
        let (mut m, vol) = ball(9.0, DVec3::new(0.8, 0.8, 2.0));
        let voxels = m.count() as f64 * vol.voxel_volume_mm3();
        crate::ctimport::mask::make_well_composed(&mut m);
        let mesh = extract(&m, &vol);
        let t = topology(&mesh);
        assert!(t.is_closed_manifold(), "{t:?}");
        assert_eq!(t.euler_characteristic, 2);
        assert_eq!(self_intersections(&mesh), 0);
        let v = mesh.signed_volume();
        assert!(
            v > 0.0 && (v / voxels - 1.0).abs() < 0.03,
            "{v} vs {voxels}"
        );
    }

    #[test]
    fn crossing_faces_are_found() {
        // Two triangles through each other, and one far away.
        let v = vec![
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(2.0, 0.0, 0.0),
            DVec3::new(0.0, 2.0, 0.0),
            DVec3::new(0.5, 0.5, -1.0),
            DVec3::new(0.5, 0.5, 1.0),
            DVec3::new(1.5, 1.5, 0.5),
            DVec3::new(9.0, 9.0, 9.0),
            DVec3::new(10.0, 9.0, 9.0),
            DVec3::new(9.0, 10.0, 9.0),
        ];
        let crossing = Mesh::new(v.clone(), vec![[0, 1, 2], [3, 4, 5]]);
        assert_eq!(self_intersections(&crossing), 1);
        let apart = Mesh::new(v, vec![[0, 1, 2], [6, 7, 8]]);
        assert_eq!(self_intersections(&apart), 0);
    }
}
