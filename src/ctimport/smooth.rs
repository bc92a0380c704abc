//! Surface post-processing: Taubin λ|μ smoothing (a shrinking Laplacian step followed by an
//! inflating one, so the voxel terraces go without the volume going with them) and
//! quadric-error decimation to a target vertex count with meshoptimizer.

use super::surface::compact;
use crate::geometry::Mesh;
use glam::DVec3;

/// Taubin's pass-band constants: λ = 0.5, μ = −0.53 (k_PB ≈ 0.1).
pub const TAUBIN_LAMBDA: f64 = 0.5;
pub const TAUBIN_MU: f64 = -0.53;

/// `iterations` λ|μ pairs with the umbrella (uniform) Laplacian.
pub fn taubin(mesh: &mut Mesh, iterations: usize) {
    let n = mesh.vertices.len();
    let mut neighbours: Vec<Vec<u32>> = vec![Vec::new(); n];
    for f in &mesh.faces {
        for e in 0..3 {
            let (a, b) = (f[e], f[(e + 1) % 3]);
            neighbours[a as usize].push(b);
            neighbours[b as usize].push(a);
        }
    }
    for list in &mut neighbours {
        list.sort_unstable();
        list.dedup();
    }
    let step = |v: &mut Vec<DVec3>, factor: f64| {
        let old = v.clone();
        for (i, list) in neighbours.iter().enumerate() {
            if list.is_empty() {
                continue;
            }
            let mean = list.iter().map(|&j| old[j as usize]).sum::<DVec3>() / list.len() as f64;
            v[i] = old[i] + factor * (mean - old[i]);
        }
    };
    for _ in 0..iterations {
        step(&mut mesh.vertices, TAUBIN_LAMBDA);
        step(&mut mesh.vertices, TAUBIN_MU);
    }
}

/// Simplifies to about `target_vertices` (`regularize`: meshoptimizer's option that trades
/// accuracy for evenly shaped triangles).
/// (a closed triangle mesh has ~2 faces per vertex).
/// Returns the mesh unchanged when it is already small enough.
pub fn decimate(mesh: &Mesh, target_vertices: usize, regularize: bool) -> Mesh {
    if mesh.vertices.len() <= target_vertices {
        return mesh.clone();
    }
    let positions: Vec<[f32; 3]> = mesh
        .vertices
        .iter()
        .map(|v| [v.x as f32, v.y as f32, v.z as f32])
        .collect();
    let indices: Vec<u32> = mesh.faces.iter().flatten().copied().collect();
    let bytes: Vec<u8> = positions
        .iter()
        .flat_map(|p| p.iter().flat_map(|c| c.to_ne_bytes()))
        .collect();
    let Ok(adapter) = meshopt::VertexDataAdapter::new(&bytes, 12, 0) else {
        return mesh.clone();
    };
    // The error bound is generous (relative to the mesh extent): the count is what binds.
    let out = meshopt::simplify(
        &indices,
        &adapter,
        target_vertices * 2 * 3,
        0.05,
        if regularize {
            meshopt::SimplifyOptions::Regularize
        } else {
            meshopt::SimplifyOptions::None
        },
        None,
    );
    let faces: Vec<[u32; 3]> = out
        .chunks_exact(3)
        .map(|t| [t[0], t[1], t[2]])
        .filter(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2])
        .collect();
    compact(&mesh.vertices, &without_folded_pairs(faces))
}

/// Removes pairs of faces on the same three vertices (a collapse that folds a thin part flat
/// leaves two back-to-back faces: zero volume, and four faces on each of their edges).
pub fn without_folded_pairs(faces: Vec<[u32; 3]>) -> Vec<[u32; 3]> {
    let mut count: std::collections::HashMap<[u32; 3], usize> = std::collections::HashMap::new();
    let key = |f: &[u32; 3]| {
        let mut k = *f;
        k.sort_unstable();
        k
    };
    for f in &faces {
        *count.entry(key(f)).or_insert(0) += 1;
    }
    faces.into_iter().filter(|f| count[&key(f)] == 1).collect()
}

/// The uniform offset along vertex normals that gives the mesh `target_mm3`: ΔV ≈ area · δ.
pub fn volume_restoring_offset(mesh: &Mesh, target_mm3: f64) -> f64 {
    let area: f64 = mesh
        .faces
        .iter()
        .map(|f| {
            let [a, b, c] = f.map(|v| mesh.vertices[v as usize]);
            0.5 * (b - a).cross(c - a).length()
        })
        .sum();
    if area <= 0.0 {
        return 0.0;
    }
    (target_mm3 - mesh.signed_volume()) / area
}

/// Every vertex moved by `offset_mm` along its (area-weighted) normal.
pub fn offset_along_normals(mesh: &Mesh, offset_mm: f64) -> Mesh {
    let normals = mesh.vertex_normals();
    Mesh::new(
        mesh.vertices
            .iter()
            .zip(&normals)
            .map(|(&v, &n)| v + n * offset_mm)
            .collect(),
        mesh.faces.clone(),
    )
}
