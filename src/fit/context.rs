//! What every term of the energy needs to know about one frame: the model (structures, joint
//! shape model), the calibrated cameras, and which forest class each structure is seen as.
//! Also the motion of a model point under each parameter block (eq. 2 and Table II for the
//! affine, eq. 17 for the shape weights, rigid increments about the model centre), shared by the
//! correspondence lines and the stereo term.

use super::model::Model;
use super::state::{Block, FitState};
use crate::geometry::{Affine, RigidPose};
use glam::DVec3;

/// Everything the energy needs about one frame.
pub struct FrameContext<'a> {
    pub model: &'a Model,
    pub cameras: &'a [crate::geometry::Camera],
    /// Forest class of each structure (None for hidden ones).
    pub class_of: Vec<Option<usize>>,
    /// The lens's k1 against focal length (scene.json `k1_vs_focal`): where given, a camera
    /// correction sets k1 from fx; where not, k1 stays as calibrated.
    pub k1_vs_focal: Option<[f64; 3]>,
}

impl<'a> FrameContext<'a> {
    /// The context of a scene: its cameras, and the forest class of each visible structure.
    pub fn new(model: &'a Model, scene: &'a crate::scene::Scene) -> Self {
        let classes = crate::appearance::ClassMap::from_scene(scene);
        let class_of = scene
            .structures
            .iter()
            .map(|s| {
                if s.visible {
                    classes.class_of_label(s.label)
                } else {
                    None
                }
            })
            .collect();
        Self {
            model,
            cameras: &scene.cameras,
            class_of,
            k1_vs_focal: scene.k1_vs_focal,
        }
    }
}

impl FrameContext<'_> {
    /// k1 of camera `m` at focal length `fx` (px) by the scene's relation, if it gives one:
    /// the calibrated k1 moved by the relation's change from the calibrated focal length (each
    /// lens keeps its own calibrated k1; the relation says how zoom changes it).
    pub fn k1_at(&self, m: usize, fx: f64) -> Option<f64> {
        let [c0, c1, c2] = self.k1_vs_focal?;
        let cam = self.cameras.get(m)?;
        let rel = |fx: f64| {
            let inv = cam.width as f64 / fx;
            c0 + c1 * inv + c2 * inv * inv
        };
        Some(cam.intrinsics.k1 + rel(fx) - rel(cam.intrinsics.fx))
    }

    /// ∂k1/∂fx of camera `m` at focal length `fx` by the scene's relation ([`Self::k1_at`]);
    /// 0 where k1 is held as calibrated.
    pub fn k1_slope(&self, m: usize, fx: f64) -> f64 {
        let (Some([_, c1, c2]), Some(cam)) = (self.k1_vs_focal, self.cameras.get(m)) else {
            return 0.0;
        };
        if fx.abs() < 1e-9 {
            return 0.0;
        }
        let w = cam.width as f64;
        -c1 * w / (fx * fx) - 2.0 * c2 * w * w / (fx * fx * fx)
    }

    /// fy/fx of camera `m` as calibrated: a zoom keeps it.
    pub fn calibrated_aspect(&self, m: usize) -> f64 {
        self.cameras
            .get(m)
            .map(|c| c.intrinsics.fy / c.intrinsics.fx)
            .filter(|a| a.is_finite())
            .unwrap_or(1.0)
    }

    /// The structures with an image term (a forest class), in the order their render objects
    /// take in the visibility rasters: a raster's object id `o` is structure `imaged()[o]`.
    pub fn imaged(&self) -> Vec<usize> {
        (0..self.model.structures.len())
            .filter(|&i| self.class_of[i].is_some())
            .collect()
    }

    /// ∂P/∂ξ (camera-0 coordinates, one column per parameter of `block`) of the model point
    /// P = T(Σ wᵢ vᵢ(W)) made of `structure`'s deformed vertices with `weights`; `posed` is P
    /// and `pre` its deformed preoperative position; rigid increments turn about
    /// `rotation_centre`. The cameras do not move model points: empty for camera blocks.
    #[allow(clippy::too_many_arguments)]
    pub fn surface_jacobian(
        &self,
        structure: usize,
        weights: &[(u32, f64)],
        posed: DVec3,
        pre: DVec3,
        state: &FitState,
        block: Block,
        rotation_centre: DVec3,
    ) -> Vec<DVec3> {
        let mut out = Vec::new();
        self.surface_jacobian_into(
            structure,
            weights,
            posed,
            pre,
            state,
            block,
            rotation_centre,
            &mut out,
        );
        out
    }

    /// [`FrameContext::surface_jacobian`] written into `out` (cleared first): the steps take
    /// it for every line, and a fresh vector each time was a quarter of their cost.
    #[allow(clippy::too_many_arguments)]
    pub fn surface_jacobian_into(
        &self,
        structure: usize,
        weights: &[(u32, f64)],
        posed: DVec3,
        pre: DVec3,
        state: &FitState,
        block: Block,
        rotation_centre: DVec3,
        out: &mut Vec<DVec3>,
    ) {
        out.clear();
        match block {
            Block::Affine => {
                // Table II.
                let j = Affine::jacobian(pre);
                out.extend((0..12).map(|k| DVec3::new(j[0][k], j[1][k], j[2][k])));
            }
            Block::Rigid => {
                // Increments about the current pose: P = R(δω)(P₀ − c₀) + c₀ + δt, where P₀ is
                // the posed point and c₀ the model centre: the rigid pose's Jacobian at zero
                // rotation, unit scale, applied to P₀ − c₀ (∂P/∂δω = −[P₀ − c₀]×, ∂P/∂δt = I).
                let j = RigidPose::default().jacobian(posed - rotation_centre);
                out.extend((0..6).map(|k| DVec3::new(j[0][k], j[1][k], j[2][k])));
            }
            Block::Shape => {
                // Eq. 17: ∂P/∂w_k = R·u_k (R: the affine's linear part).
                let lin = state.affine.linear();
                let part = self.model.structures[structure].part;
                out.extend((0..self.model.shape.mode_count()).map(|k| {
                    let u = self.model.shape.mode_part(k, part);
                    lin * weights
                        .iter()
                        .map(|&(v, w)| u[v as usize] * w)
                        .sum::<DVec3>()
                }));
            }
            Block::Cameras(_) => {}
        }
    }

    /// Centre about which rigid increments rotate: the anchor structure's vertex mean.
    pub fn model_centre(&self, deformed: &[Vec<DVec3>]) -> DVec3 {
        crate::geometry::mesh::vertex_mean(&deformed[self.model.anchor])
    }

    /// [`FrameContext::model_centre`] posed by `state`. A mean over the organ's vertices: taken
    /// once per step, not once per line.
    pub fn rotation_centre(&self, state: &FitState, deformed: &[Vec<DVec3>]) -> DVec3 {
        state.affine.apply(self.model_centre(deformed))
    }
}
