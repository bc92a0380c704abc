//! Shape: the PCA model of eq. 1 and where its catalog comes from. One **joint** model spans all
//! structures of a scene (visible and hidden): sample k of the catalog is one deformation of
//! the whole anatomy, so fitting the kidney's shape also predicts where a hidden tumour went.
//!
//! Catalog sources, in order: catalogs given for every structure with equal sizes are paired
//! sample by sample; structures lacking one (or with a different count) follow the anchor's
//! catalog by displacement transfer; with no catalog at all, smooth push/pull fields are
//! generated and applied to all structures jointly.

pub mod deform;
pub mod pca;

pub use deform::{DeformationField, DeformationSpread};

/// Why a joint shape model cannot be built from the structures' catalogs.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ShapeError {
    #[error("shape catalog is empty")]
    EmptyCatalog,
    #[error("catalog shape {index} has {got} vertices, the first has {expected}")]
    SampleSize {
        /// 1-based, as a user counts the catalog's files.
        index: usize,
        got: usize,
        expected: usize,
    },
}
pub use pca::PcaModel;

use crate::geometry::Mesh;
use crate::rng::Rng;
use glam::DVec3;

/// Samples generated when a scene gives no catalog. The paper's DeformIt catalogs had ~40, but
/// random push/pull fields vary more than 40 samples can show: their first 12 modes then span
/// little of a new field. Hidden-tumour error (LSC, 22 phantoms): mean 2.08 → 2.05 mm, worst
/// 4.12 → 3.73 mm with 200; 400 and 1000 were no better. Costs ~0.3 s when a scene loads.
pub const GENERATED_CATALOG_SIZE: usize = 200;
/// Share of variance the kept modes must explain.
pub const VARIANCE_SHARE: f64 = 0.95;
/// At most this many modes, whatever the share.
pub const MAX_MODES: usize = 12;
/// Seed of generated catalogs: fixed, so a scene always gets the same model.
pub const CATALOG_SEED: u64 = 0x0CA7_A106;

/// Where the joint model's samples came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CatalogSource {
    /// Every structure's catalog was given, sample by sample.
    Given,
    /// The anchor's catalog was given; the other structures follow it.
    Transferred,
    /// Generated push/pull deformations.
    Generated,
}

/// The joint PCA model of all structures, with the vertex range of each structure.
#[derive(Debug, Clone, PartialEq)]
pub struct JointShapeModel {
    pub pca: PcaModel,
    /// (first vertex, vertex count) of each structure inside the joint vectors.
    pub parts: Vec<(usize, usize)>,
    pub source: CatalogSource,
}

impl JointShapeModel {
    /// Deformed vertices of every structure for joint weights `w`.
    pub fn instance(&self, w: &[f64]) -> Vec<Vec<DVec3>> {
        self.split(&self.pca.instance(w))
    }

    pub fn split(&self, joint: &[DVec3]) -> Vec<Vec<DVec3>> {
        self.parts
            .iter()
            .map(|&(s, n)| joint[s..s + n].to_vec())
            .collect()
    }

    /// Mode `k` restricted to structure `part` (∂P/∂w_k of eq. 17 before the pose).
    pub fn mode_part(&self, k: usize, part: usize) -> &[DVec3] {
        let (s, n) = self.parts[part];
        &self.pca.modes[k][s..s + n]
    }

    pub fn mode_count(&self) -> usize {
        self.pca.mode_count()
    }
}

/// The joint model of a scene's structures (their meshes and the catalogs given with them);
/// the anchor (the organ, whose surface carries generated forces) is the largest visible
/// structure.
pub fn joint_model_of(
    structures: &[crate::scene::Structure],
) -> Result<JointShapeModel, ShapeError> {
    let meshes: Vec<&Mesh> = structures.iter().map(|s| &s.mesh).collect();
    let catalogs: Vec<Option<Vec<Vec<DVec3>>>> =
        structures.iter().map(|s| s.catalog.clone()).collect();
    let size = |s: &crate::scene::Structure| {
        s.mesh
            .bounding_box()
            .map(|(lo, hi)| (hi - lo).length())
            .unwrap_or(0.0)
    };
    let anchor = structures
        .iter()
        .enumerate()
        .filter(|(_, s)| s.visible)
        .max_by(|a, b| size(a.1).total_cmp(&size(b.1)))
        .map(|(i, _)| i)
        .unwrap_or(0);
    build_joint_model(&meshes, &catalogs, anchor)
}

/// Builds the joint model. `meshes[i]` is structure i's mesh, `catalogs[i]` its optional
/// catalog (vertex arrays already checked against the mesh), `anchor` the structure whose
/// surface carries generated forces and whose catalog others follow (the organ).
pub fn build_joint_model(
    meshes: &[&Mesh],
    catalogs: &[Option<Vec<Vec<DVec3>>>],
    anchor: usize,
) -> Result<JointShapeModel, ShapeError> {
    let mut parts = Vec::new();
    let mut offset = 0;
    for m in meshes {
        parts.push((offset, m.vertices.len()));
        offset += m.vertices.len();
    }
    // Prefer the anchor's catalog; else any structure that has one becomes the anchor.
    let anchor = if catalogs.get(anchor).is_some_and(|c| c.is_some()) {
        Some(anchor)
    } else {
        catalogs.iter().position(|c| c.is_some())
    };
    let anchor_catalog = anchor.and_then(|a| Some((a, catalogs[a].as_ref()?)));
    let (per_structure, source) = match anchor_catalog {
        Some((a, anchor_cat)) => {
            let n = anchor_cat.len();
            let mut all_given = true;
            let per: Vec<Vec<Vec<DVec3>>> = meshes
                .iter()
                .enumerate()
                .map(|(i, m)| match &catalogs[i] {
                    Some(c) if c.len() == n => c.clone(),
                    _ => {
                        all_given = false;
                        anchor_cat
                            .iter()
                            .map(|deformed| {
                                deform::transfer_displacements(
                                    &meshes[a].vertices,
                                    deformed,
                                    &m.vertices,
                                    10.0,
                                )
                            })
                            .collect()
                    }
                })
                .collect();
            (
                per,
                if all_given {
                    CatalogSource::Given
                } else {
                    CatalogSource::Transferred
                },
            )
        }
        None => (
            generate_catalog(
                meshes,
                anchor_or_largest(meshes),
                GENERATED_CATALOG_SIZE,
                CATALOG_SEED,
            ),
            CatalogSource::Generated,
        ),
    };
    let sample_count = per_structure.first().map(|c| c.len()).unwrap_or(0);
    let samples: Vec<Vec<DVec3>> = (0..sample_count)
        .map(|k| {
            per_structure
                .iter()
                .flat_map(|c| c[k].iter().copied())
                .collect()
        })
        .collect();
    let rest: Vec<DVec3> = meshes
        .iter()
        .flat_map(|m| m.vertices.iter().copied())
        .collect();
    let samples: Vec<Vec<DVec3>> = samples
        .into_iter()
        .map(|s| without_affine_part(&rest, &s))
        .collect();
    let pca = if samples.is_empty() {
        PcaModel {
            mean: rest,
            modes: Vec::new(),
            sigma_mm: Vec::new(),
            explained_share: 1.0,
            sample_count: 0,
        }
    } else {
        PcaModel::from_samples(&samples, VARIANCE_SHARE, MAX_MODES)?
    };
    Ok(JointShapeModel { pca, parts, source })
}

/// `sample` with the affine part of its displacement from `rest` taken out: the
/// least-squares d(x) ≈ A (x − c) + t over all vertices. The global affine T already moves,
/// turns, scales and shears the anatomy; a shape mode that can do the same only trades off
/// against it (and against depth), so the modes keep just what T cannot express: how the
/// structures bend, bulge and move relative to each other. Samples whose size differs from
/// `rest`, or degenerate (flat) rests, are returned as they are.
pub fn without_affine_part(rest: &[DVec3], sample: &[DVec3]) -> Vec<DVec3> {
    if rest.len() != sample.len() || rest.is_empty() {
        return sample.to_vec();
    }
    let n = rest.len() as f64;
    let c = rest.iter().copied().sum::<DVec3>() / n;
    let mean_d = rest.iter().zip(sample).map(|(r, s)| *s - *r).sum::<DVec3>() / n;
    // Normal equations: (Σ x xᵀ) Aᵀ = Σ x dᵀ with x = rest − c, d = displacement − mean.
    let mut xx = glam::DMat3::ZERO;
    let mut xd = glam::DMat3::ZERO;
    for (r, s) in rest.iter().zip(sample) {
        let x = *r - c;
        let d = *s - *r - mean_d;
        xx += outer(x, x);
        xd += outer(x, d);
    }
    if xx.determinant().abs() < 1e-9 * n.powi(3) {
        return sample.to_vec();
    }
    // xd = Σ x dᵀ, so Aᵀ = xx⁻¹ xd and A = (xx⁻¹ xd)ᵀ.
    let a = (xx.inverse() * xd).transpose();
    rest.iter()
        .zip(sample)
        .map(|(r, s)| *s - (a * (*r - c) + mean_d))
        .collect()
}

/// x yᵀ.
fn outer(x: DVec3, y: DVec3) -> glam::DMat3 {
    glam::DMat3::from_cols(x * y.x, x * y.y, x * y.z)
}

fn anchor_or_largest(meshes: &[&Mesh]) -> usize {
    meshes
        .iter()
        .enumerate()
        .map(|(i, m)| {
            (
                i,
                m.bounding_box()
                    .map(|(lo, hi)| (hi - lo).length())
                    .unwrap_or(0.0),
            )
        })
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(i, _)| i)
        .unwrap_or(0)
}

/// `count` joint deformations of all structures: per sample, one random push/pull field on the
/// anchor's surface applied to every structure. Returns `[structure][sample][vertex]`.
pub fn generate_catalog(
    meshes: &[&Mesh],
    anchor: usize,
    count: usize,
    seed: u64,
) -> Vec<Vec<Vec<DVec3>>> {
    let Some(anchor_mesh) = meshes.get(anchor) else {
        return Vec::new();
    };
    let normals = anchor_mesh.vertex_normals();
    let mut rng = Rng::new(seed);
    let fields: Vec<DeformationField> = (0..count)
        .map(|_| {
            DeformationField::random(
                &mut rng,
                anchor_mesh,
                &normals,
                &DeformationSpread::default(),
            )
        })
        .collect();
    meshes
        .iter()
        .map(|m| fields.iter().map(|f| f.apply(&m.vertices)).collect())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scaled_sphere(subdiv: u32, r: f64, c: DVec3) -> Mesh {
        let s = crate::geometry::mesh::icosphere(subdiv);
        Mesh::new(s.vertices.iter().map(|v| *v * r + c).collect(), s.faces)
    }

    #[test]
    fn affine_part_is_removed_from_samples() {
        let organ = scaled_sphere(2, 30.0, DVec3::new(5.0, -3.0, 100.0));
        let rest = organ.vertices.clone();
        let lin =
            glam::DMat3::from_cols_array(&[1.05, 0.02, -0.01, 0.03, 0.97, 0.04, 0.0, -0.02, 1.1]);
        let t = DVec3::new(2.0, -1.0, 3.0);
        // A local bulge near one vertex on top of an affine change.
        let bump_at = rest[0];
        let affine_and_bump: Vec<DVec3> = rest
            .iter()
            .map(|&p| {
                let bump = DVec3::Z * 4.0 * (-(p - bump_at).length_squared() / 200.0).exp();
                lin * p + t + bump
            })
            .collect();
        let cleaned = without_affine_part(&rest, &affine_and_bump);
        // What is left has no affine part of its own ...
        let again = without_affine_part(&rest, &cleaned);
        let drift = cleaned
            .iter()
            .zip(&again)
            .map(|(a, b)| (*a - *b).length())
            .fold(0.0, f64::max);
        assert!(drift < 1e-9, "second removal moved points by {drift}");
        // ... a pure affine change is removed entirely ...
        let pure: Vec<DVec3> = rest.iter().map(|&p| lin * p + t).collect();
        let left = without_affine_part(&rest, &pure)
            .iter()
            .zip(&rest)
            .map(|(a, b)| (*a - *b).length())
            .fold(0.0, f64::max);
        assert!(left < 1e-9, "pure affine left {left} mm");
        // ... and the bulge survives: the cleaned shape still bulges most at the bump.
        let moved: Vec<f64> = cleaned
            .iter()
            .zip(&rest)
            .map(|(a, b)| (*a - *b).length())
            .collect();
        let peak = moved.iter().cloned().fold(0.0, f64::max);
        assert!(
            moved[0] > 0.5 * peak && peak > 2.0,
            "bulge {} of peak {peak}",
            moved[0]
        );
    }

    #[test]
    fn joint_model_moves_the_inner_structure_with_the_organ() {
        let organ = scaled_sphere(3, 30.0, DVec3::ZERO);
        let inner = scaled_sphere(1, 6.0, DVec3::new(15.0, 0.0, 0.0));
        let model = build_joint_model(&[&organ, &inner], &[None, None], 0).unwrap();
        assert_eq!(model.source, CatalogSource::Generated);
        assert!(model.mode_count() >= 3, "{} modes", model.mode_count());
        assert!(model.pca.explained_share >= VARIANCE_SHARE || model.mode_count() == MAX_MODES);
        // Every mode moves the inner structure: its displacement is not zero anywhere.
        for k in 0..model.mode_count() {
            let inner_norm: f64 = model
                .mode_part(k, 1)
                .iter()
                .map(|d| d.length_squared())
                .sum::<f64>()
                .sqrt();
            assert!(
                inner_norm > 1e-4,
                "mode {k} leaves the inner structure still"
            );
        }
        let shapes = model.instance(&[2.0 * model.pca.sigma_mm[0]]);
        assert_eq!(shapes[1].len(), inner.vertices.len());

        // Given only the organ's catalog, the inner structure follows by transfer.
        let cat = generate_catalog(&[&organ], 0, 10, 5).remove(0);
        let model = build_joint_model(&[&organ, &inner], &[Some(cat), None], 0).unwrap();
        assert_eq!(model.source, CatalogSource::Transferred);
        assert_eq!(model.pca.sample_count, 10);
    }
}
