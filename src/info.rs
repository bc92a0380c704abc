//! The readable summary `endofuse info` prints: what a scene holds, in the words an analyst
//! would use to check it before a long run.

use crate::scene::{SEED_BACKGROUND, Scene};
use crate::shape::{CatalogSource, JointShapeModel};
use std::fmt::Write;

/// The summary of `scene`, whose structures' joint shape model is `shape`.
pub fn summary(scene: &Scene, shape: &JointShapeModel) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "scene: {}", scene.origin);
    let _ = writeln!(
        s,
        "frames: {} at {} fps ({:.1} s)",
        scene.frame_count,
        scene.fps,
        scene.frame_count as f64 / scene.fps
    );
    let _ = writeln!(s, "cameras ({}):", scene.cameras.len());
    for (i, c) in scene.cameras.iter().enumerate() {
        let k = &c.intrinsics;
        let _ = write!(
            s,
            "  {:<8} {}×{}  fx {:.1}  fy {:.1}  cx {:.1}  cy {:.1}  k1 {:.4}  k2 {:.4}  p1 {:.4}  p2 {:.4}",
            c.name, c.width, c.height, k.fx, k.fy, k.cx, k.cy, k.k1, k.k2, k.p1, k.p2
        );
        if k.k3 != 0.0 {
            let _ = write!(s, "  k3 {:.4}", k.k3);
        }
        if i > 0 {
            let _ = write!(s, "  baseline {:.2} mm", c.baseline_mm());
        }
        s.push('\n');
    }
    let _ = writeln!(s, "structures ({}):", scene.structures.len());
    for st in &scene.structures {
        let count = st.mesh.vertices.len();
        let catalog = match &st.catalog {
            Some(c) => format!("catalog of {} shapes", c.len()),
            None => "no catalog".into(),
        };
        let _ = writeln!(
            s,
            "  {:<12} label {:<3} {:<8} {:>5} vertices {:>5} faces  {}  {}  ({})",
            st.name,
            st.label,
            if st.visible { "visible" } else { "hidden" },
            count,
            st.mesh.faces.len(),
            surface(&st.mesh),
            catalog,
            st.mesh_path.display()
        );
    }
    let pca = &shape.pca;
    let source = match shape.source {
        CatalogSource::Given => "from the given catalogs",
        CatalogSource::Transferred => "from the organ's catalog, carried to the other structures",
        CatalogSource::Generated => "from generated push/pull deformations",
    };
    // A unit mode spreads over every vertex: report what 1σ does to a vertex, RMS.
    let per_vertex = (pca.mean.len().max(1) as f64).sqrt();
    let sigmas: Vec<String> = pca
        .sigma_mm
        .iter()
        .take(4)
        .map(|v| format!("{:.2}", v / per_vertex))
        .collect();
    let _ = writeln!(
        s,
        "shape model: joint over {} structures, {} shapes {source}; {} PCA mode{} {:.1}% of the variance (1σ moves a vertex {}{} mm RMS)",
        scene.structures.len(),
        pca.sample_count,
        pca.mode_count(),
        if pca.mode_count() == 1 {
            " explains"
        } else {
            "s explain"
        },
        100.0 * pca.explained_share,
        sigmas.join(", "),
        if pca.mode_count() > 4 { ", …" } else { "" }
    );
    match &scene.initial_pose {
        Some(p) => {
            let t = p.translation_mm();
            let scale = p.linear().determinant().cbrt();
            let _ = writeln!(
                s,
                "initial pose: given, translation ({:.1}, {:.1}, {:.1}) mm, scale {:.3}",
                t.x, t.y, t.z, scale
            );
        }
        None => {
            let _ = writeln!(s, "initial pose: none (automatic initialisation)");
        }
    }
    let frames = scene.seeds.seeded_frames();
    if frames.is_empty() {
        let _ = writeln!(s, "seeds: none");
    } else {
        let counts = scene.seeds.pixel_counts();
        let classes: Vec<String> = counts
            .iter()
            .map(|(&v, &n)| {
                let name = if v == SEED_BACKGROUND {
                    "background".to_string()
                } else {
                    scene
                        .structure_by_label(v)
                        .map(|s| s.name.clone())
                        .unwrap_or_else(|| format!("label {v}"))
                };
                format!("{name} {n} px")
            })
            .collect();
        let _ = writeln!(s, "seeds: frames {}: {}", list(&frames), classes.join(", "));
        // What `track` and `classify` would refuse, said here rather than after loading.
        let mut missing: Vec<String> = Vec::new();
        if !counts.contains_key(&SEED_BACKGROUND) {
            missing.push("background/tools (seed value 255)".into());
        }
        missing.extend(
            scene
                .structures
                .iter()
                .filter(|st| st.visible && !counts.contains_key(&st.label))
                .map(|st| format!("'{}' (label {})", st.name, st.label)),
        );
        if !missing.is_empty() {
            let _ = writeln!(
                s,
                "  not painted yet: {} — track and classify need a stroke of every class",
                missing.join(", ")
            );
        }
    }
    let gt = &scene.ground_truth;
    let gt_frames = scene.ground_truth_frames();
    let mut parts = Vec::new();
    if !gt_frames.is_empty() {
        parts.push(format!("labels for {} frames", gt_frames.len()));
    }
    if let (Some(t), Some(root)) = (&gt.hidden, &scene.root) {
        for st in scene.structures.iter().filter(|s| !s.visible) {
            if root
                .join(t.expand(0, &scene.cameras[0].name, &st.name))
                .exists()
            {
                parts.push(format!("hidden masks of {}", st.name));
            }
        }
    }
    if let Some(tr) = &gt.trajectory {
        parts.push(format!("trajectory ({} frames)", tr.frames.len()));
    }
    let _ = writeln!(
        s,
        "ground truth: {}",
        if parts.is_empty() {
            "none".into()
        } else {
            parts.join(", ")
        }
    );
    if scene.zoom_changes.is_empty() {
        let _ = writeln!(s, "zoom changes: none");
    } else {
        let z: Vec<String> = scene
            .zoom_changes
            .iter()
            .map(|(a, b)| format!("{a}–{b}"))
            .collect();
        let _ = writeln!(s, "zoom changes: frames {}", z.join(", "));
    }
    s
}

/// Whether a mesh is a closed surface, in words: an open or non-manifold one still fits (its
/// back faces are not culled, its holes' borders give no contour), but a CT surface should be
/// closed, and a hole often means an export went wrong.
fn surface(mesh: &crate::geometry::Mesh) -> String {
    if crate::fit::model::is_closed(&mesh.faces) {
        return if mesh.signed_volume() < 0.0 {
            "closed, wound inwards".into()
        } else {
            "closed".into()
        };
    }
    let mut uses: std::collections::HashMap<(u32, u32), u32> = Default::default();
    for f in &mesh.faces {
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            *uses.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    let open = uses.values().filter(|&&n| n == 1).count();
    let shared = uses.values().filter(|&&n| n > 2).count();
    match (open, shared) {
        (0, 0) => "not closed (faces wound inconsistently)".into(),
        (o, 0) => format!("open ({o} edges on one face only)"),
        (0, n) => format!("not closed ({n} edges on 3+ faces)"),
        (o, n) => format!("open ({o} edges on one face only, {n} on 3+)"),
    }
}

/// "0, 1, 2" or "0–9, 20" for a sorted list.
fn list(v: &[usize]) -> String {
    let mut out: Vec<String> = Vec::new();
    let mut i = 0;
    while i < v.len() {
        let mut j = i;
        while j + 1 < v.len() && v[j + 1] == v[j] + 1 {
            j += 1;
        }
        out.push(if j - i >= 2 {
            format!("{}–{}", v[i], v[j])
        } else {
            (i..=j)
                .map(|k| v[k].to_string())
                .collect::<Vec<_>>()
                .join(", ")
        });
        i = j + 1;
    }
    out.join(", ")
}

#[cfg(test)]
mod tests {
    use super::surface;
    use crate::geometry::Mesh;
    use glam::DVec3;

    fn tetrahedron(faces: Vec<[u32; 3]>) -> Mesh {
        let v = vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z];
        Mesh::new(v, faces)
    }

    /// A closed tetrahedron either way round, and with a face missing.
    #[test]
    fn surfaces_are_told_closed_inwards_or_open() {
        let outward = vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
        assert_eq!(surface(&tetrahedron(outward.clone())), "closed");
        let inward: Vec<[u32; 3]> = outward.iter().map(|&[a, b, c]| [a, c, b]).collect();
        assert_eq!(surface(&tetrahedron(inward)), "closed, wound inwards");
        assert_eq!(
            surface(&tetrahedron(outward[..3].to_vec())),
            "open (3 edges on one face only)"
        );
    }
}
