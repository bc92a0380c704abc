//! The priors the objective adds to the image terms (paper §II-C leaves them out; DESIGN.md
//! "Unobservable directions"): damping of the pose towards the previous frame, a strain prior
//! pulling the affine's linear part towards a rotation, the shape prior of the PCA model with
//! its temporal damping, and damping of the cameras' intrinsics. Silhouettes leave some
//! directions nearly free (depth against scale, some shears, k1); the priors hold them.
//!
//! Each prior's precisions are set once per step, relative to the curvature the normal
//! equations hold when it is added (the data's, plus Levenberg–Marquardt, plus the priors
//! added before it): `optimizer::step` adds them in a fixed order. With its precisions fixed,
//! each prior is an exact quadratic in its residuals, and the energy it adds to the step's
//! objective is the one whose curvature it puts into the normal equations.

use super::objective::{NormalEquations, Prior};
use super::state::{Block, FitState};
use crate::geometry::Affine;
use crate::geometry::pose::{nearest_rotation, rotation_to_vector};
use glam::{DMat3, DVec3};
use nalgebra::DMatrix;

/// Mean of the diagonal of `h` over `range`.
fn mean_diagonal(h: &DMatrix<f64>, range: std::ops::Range<usize>) -> f64 {
    let len = range.len() as f64;
    range.map(|k| h[(k, k)]).sum::<f64>() / len
}

/// 0.5 Σ λ_k r_k².
fn quadratic(lambda: &[f64], residuals: &[f64]) -> f64 {
    lambda
        .iter()
        .zip(residuals)
        .map(|(l, r)| 0.5 * l * r * r)
        .sum()
}

/// Tikhonov damping of the pose towards the previous frame's, for the rigid or the affine
/// block: silhouettes leave some rotations and depth nearly free; the damping keeps them still
/// unless the data move them. Rotations and the linear part get one precision for the group,
/// so weakly observed directions are held as firmly as the rest; translation gets one per axis,
/// relative to its own information, so depth (seen only through size and disparity) still
/// converges.
pub struct PoseDamping {
    block: Block,
    previous: Affine,
    /// The model centre (preoperative coordinates) whose posed position measures translation.
    centre_pre: DVec3,
    lambda: Vec<f64>,
}

impl PoseDamping {
    /// The damping of `block` (None unless rigid or affine) towards `previous`, `weight` times
    /// the curvature of `h`, and depth (the translation along the camera's axis) `depth_weight`
    /// times its curvature.
    pub fn new(
        block: Block,
        previous: &FitState,
        centre_pre: DVec3,
        weight: f64,
        depth_weight: f64,
        h: &DMatrix<f64>,
    ) -> Option<Self> {
        let linear = match block {
            Block::Rigid => 0..3,
            Block::Affine => 0..9,
            _ => return None,
        };
        let translation = linear.end..linear.end + 3;
        let group = mean_diagonal(h, linear.clone());
        let depth = translation.end - 1;
        let lambda = linear
            .map(|_| weight * group)
            .chain(translation.map(|k| {
                let w = if k == depth { depth_weight } else { weight };
                w * h[(k, k)]
            }))
            .collect();
        Some(Self {
            block,
            previous: previous.affine,
            centre_pre,
            lambda,
        })
    }

    /// How far `state`'s pose is from the previous one, in the block's parameters: rotation
    /// vector (rad) and the model centre's displacement (mm) for the rigid block, q1…q12 for the
    /// affine.
    fn deviation(&self, state: &FitState) -> Vec<f64> {
        match self.block {
            Block::Rigid => {
                let rotation = rotation_to_vector(
                    nearest_rotation(state.affine.linear() * self.previous.linear().inverse())
                        .unwrap_or(DMat3::IDENTITY),
                );
                let shift =
                    state.affine.apply(self.centre_pre) - self.previous.apply(self.centre_pre);
                rotation
                    .to_array()
                    .into_iter()
                    .chain(shift.to_array())
                    .collect()
            }
            _ => (0..12)
                .map(|k| state.affine.q[k] - self.previous.q[k])
                .collect(),
        }
    }
}

impl Prior for PoseDamping {
    fn energy(&self, state: &FitState) -> f64 {
        quadratic(&self.lambda, &self.deviation(state))
    }

    fn add_normal_equations(&self, state: &FitState, eq: &mut NormalEquations) {
        for (k, (lam, d)) in self.lambda.iter().zip(self.deviation(state)).enumerate() {
            eq.h[(k, k)] += lam;
            eq.b[k] -= lam * d;
        }
    }
}

/// The strain prior of the affine block: silhouettes barely see stretch along the optical axis
/// against depth, so the linear part is pulled towards its nearest rotation (CT is metric);
/// real tissue stretch survives where the data insist. The pull splits in two orthogonal
/// parts: towards the nearest similarity s·R (shear and uneven stretch, weight λ) and of its
/// scale s towards 1 (weight λ_s), energy 0.5 λ ‖A − s R‖²_F + 0.5 λ_s · 3 (s − 1)², whose
/// gradient in A is exactly λ (A − s R) + λ_s (s − 1) R (R is A's polar rotation and s =
/// tr(RᵀA) / 3 its best scale; both minimise, so their own derivatives drop out). With
/// λ_s = λ this is 0.5 λ ‖A − R‖²_F. A tissue's own deformation often changes its size a
/// little; held at λ, that change shows as depth instead (measured with true probabilities,
/// `ENDOFUSE_TRUTH_PROBABILITIES`: the default phantom seed 303 +1.2 mm deep, +0.0 mm with its
/// deformation switched off; scale weight 0.1 / 0.01: +0.85 / +0.74 mm). With the forest's
/// probabilities the looser scale did not pay: over the 54 tuning scenes of
/// `benches/fit_heldout.py` (LSC), `priors.strain_scale` 1 / 0.1 gave the kidney +0.96 / +0.66
/// mm deep, the hidden tumour 2.23 / 2.19 mm (worst 7.75 / 9.11), fx error 0.82 / 0.87 %,
/// Dice 0.938 / 0.938, so it stays at 1.
pub struct StrainPrior {
    lambda: f64,
    lambda_scale: f64,
}

impl StrainPrior {
    /// `weight` times the mean curvature of `h` over the linear part (q1…q9), and
    /// `scale_weight` times that for the uniform scale.
    pub fn new(weight: f64, scale_weight: f64, h: &DMatrix<f64>) -> Self {
        let lambda = weight * mean_diagonal(h, 0..9);
        Self {
            lambda,
            lambda_scale: scale_weight * lambda,
        }
    }

    /// The polar rotation R of the linear part (q1…q9), A − R and s − 1 (None for a degenerate
    /// linear part). The energy and gradient are written as the old single pull plus the scale's
    /// difference: ‖A − R‖² = ‖A − s R‖² + 3 (s − 1)² (A − s R is orthogonal to R), so that
    /// with λ_s = λ they are the same numbers as before, bit for bit.
    fn parts(state: &FitState) -> Option<([f64; 9], [f64; 9], f64)> {
        let rotation = nearest_rotation(state.affine.linear())?;
        let r = Affine::from_linear_translation(rotation, DVec3::ZERO).q;
        let q = &state.affine.q;
        let scale = (0..9).map(|k| r[k] * q[k]).sum::<f64>() / 3.0;
        Some((
            std::array::from_fn(|k| r[k]),
            std::array::from_fn(|k| q[k] - r[k]),
            scale - 1.0,
        ))
    }

    /// Adds the prior's curvature over q1…q9 at polar rotation `rotation` (row-major) to the
    /// top-left of `h`: λ on every direction but uniform scale, λ_s on that one (R / √3).
    fn add_curvature_at(&self, rotation: &[f64; 9], h: &mut DMatrix<f64>) {
        for r in 0..9 {
            for q in 0..9 {
                let identity = if r == q { self.lambda } else { 0.0 };
                h[(r, q)] +=
                    identity + (self.lambda_scale - self.lambda) * rotation[r] * rotation[q] / 3.0;
            }
        }
    }

    /// The curvature its steps add at `state`, for the joint information (the identity's
    /// rotation where the linear part is degenerate).
    pub fn add_curvature(&self, state: &FitState, h: &mut DMatrix<f64>) {
        let rotation =
            Self::parts(state).map_or([1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0], |p| p.0);
        self.add_curvature_at(&rotation, h);
    }
}

impl Prior for StrainPrior {
    fn energy(&self, state: &FitState) -> f64 {
        Self::parts(state).map_or(0.0, |(_, off_rotation, scale)| {
            quadratic(&[self.lambda; 9], &off_rotation)
                + 0.5 * (self.lambda_scale - self.lambda) * 3.0 * scale * scale
        })
    }

    fn add_normal_equations(&self, state: &FitState, eq: &mut NormalEquations) {
        let Some((rotation, off_rotation, scale)) = Self::parts(state) else {
            return;
        };
        self.add_curvature_at(&rotation, &mut eq.h);
        let scale_pull = (self.lambda_scale - self.lambda) * scale;
        for k in 0..9 {
            eq.b[k] -= self.lambda * off_rotation[k] + scale_pull * rotation[k];
        }
    }
}

/// The shape block's prior: the PCA model's Mahalanobis prior on the weights,
/// 0.5 · weight · Σ (w_k / σ_k)², and a temporal Tikhonov damping towards the previous frame's
/// weights (tissue deforms slowly, and must not mimic a zoom), relative to the data.
pub struct ShapePrior<'a> {
    weight: f64,
    sigma_mm: &'a [f64],
    previous: Vec<f64>,
    damping: f64,
}

impl<'a> ShapePrior<'a> {
    /// The prior of weight `weight` per σ², and damping `damping` times the mean curvature of
    /// `h`, towards `previous`'s weights.
    pub fn new(
        weight: f64,
        sigma_mm: &'a [f64],
        previous: &FitState,
        damping: f64,
        h: &DMatrix<f64>,
    ) -> Self {
        let n = sigma_mm.len();
        Self {
            weight,
            sigma_mm,
            previous: (0..n)
                .map(|k| previous.shape.get(k).copied().unwrap_or(0.0))
                .collect(),
            damping: damping * mean_diagonal(h, 0..n),
        }
    }

    /// The Mahalanobis precision of weight k, weight / σ_k² (σ² kept above 1e-12 mm²).
    fn precision(&self, k: usize) -> f64 {
        self.weight / (self.sigma_mm[k] * self.sigma_mm[k]).max(1e-12)
    }

    /// The Mahalanobis part alone, 0.5 · weight · Σ (w_k / σ_k)².
    pub fn mahalanobis_energy(&self, state: &FitState) -> f64 {
        state
            .shape
            .iter()
            .enumerate()
            .map(|(k, w)| 0.5 * self.precision(k) * w * w)
            .sum()
    }
}

impl Prior for ShapePrior<'_> {
    fn energy(&self, state: &FitState) -> f64 {
        let damping: Vec<f64> = state
            .shape
            .iter()
            .zip(&self.previous)
            .map(|(w, p)| w - p)
            .collect();
        self.mahalanobis_energy(state) + quadratic(&vec![self.damping; damping.len()], &damping)
    }

    fn add_normal_equations(&self, state: &FitState, eq: &mut NormalEquations) {
        for k in 0..self.sigma_mm.len() {
            let inv = self.precision(k);
            let lam = self.damping;
            let w = state.shape[k];
            eq.h[(k, k)] += inv + lam;
            eq.b[k] -= inv * w + lam * (w - self.previous[k]);
        }
    }
}

/// Tikhonov damping of the rig's intrinsics towards the previous frame's. The rig moves by one
/// shared increment (`optimizer::shared_camera_increment`), so camera 0's change stands for
/// all: the prior acts on the five shared parameters.
pub struct CameraDamping {
    previous: [f64; 5],
    lambda: [f64; 5],
}

impl CameraDamping {
    /// `weight` times `relative[k]` times each parameter's curvature in `h` (the rig's five
    /// shared parameters, fx, fy, cx, cy, k1).
    pub fn new(previous: &FitState, weight: f64, relative: [f64; 5], h: &DMatrix<f64>) -> Self {
        Self {
            previous: previous.intrinsics[0].corrected(),
            lambda: std::array::from_fn(|k| weight * relative[k] * h[(k, k)]),
        }
    }

    fn deviation(&self, state: &FitState) -> [f64; 5] {
        let now = state.intrinsics[0].corrected();
        std::array::from_fn(|k| now[k] - self.previous[k])
    }
}

impl Prior for CameraDamping {
    fn energy(&self, state: &FitState) -> f64 {
        quadratic(&self.lambda, &self.deviation(state))
    }

    fn add_normal_equations(&self, state: &FitState, eq: &mut NormalEquations) {
        for (k, d) in self.deviation(state).iter().enumerate() {
            eq.h[(k, k)] += self.lambda[k];
            eq.b[k] -= self.lambda[k] * d;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::state::apply_increment;
    use crate::geometry::Intrinsics;
    use crate::geometry::pose::rotation_from_vector;

    /// A state off `previous` in every block, and a curvature matrix with distinct diagonals.
    fn states() -> (FitState, FitState, DMatrix<f64>) {
        let previous = FitState {
            affine: Affine::from_linear_translation(
                rotation_from_vector(DVec3::new(0.1, -0.2, 0.05)),
                DVec3::new(3.0, -2.0, 180.0),
            ),
            shape: vec![0.4, -1.0, 0.2],
            intrinsics: vec![Intrinsics::pinhole(1000.0, 1001.0, 480.0, 270.0)],
        };
        let mut state = previous.clone();
        let stretch = DMat3::from_diagonal(DVec3::new(1.03, 0.98, 1.01));
        state.affine = Affine::from_linear_translation(
            stretch * rotation_from_vector(DVec3::new(0.12, -0.21, 0.04)),
            DVec3::new(3.5, -1.0, 183.0),
        );
        state.shape = vec![1.0, -0.5, -0.3];
        state.intrinsics[0] =
            state.intrinsics[0].with_corrected([1012.0, 1009.0, 483.0, 268.0, -0.01]);
        let h = DMatrix::from_fn(12, 12, |r, c| if r == c { 1.0 + r as f64 } else { 0.3 });
        (state, previous, h)
    }

    /// −b of the prior's normal equations against central differences of its energy over
    /// increments of `block`; `tolerance` relative to the largest component.
    fn check(prior: &dyn Prior, state: &FitState, block: Block, n: usize, tolerance: f64) {
        let mut eq = NormalEquations::zeros(n);
        prior.add_normal_equations(state, &mut eq);
        let centre = DVec3::new(1.0, 2.0, -3.0);
        let fd: Vec<f64> = (0..n)
            .map(|k| {
                let h = 1e-6;
                let mut d = vec![0.0; n];
                d[k] = h;
                let plus = prior.energy(&apply_increment(state, block, &d, centre));
                d[k] = -h;
                let minus = prior.energy(&apply_increment(state, block, &d, centre));
                (plus - minus) / (2.0 * h)
            })
            .collect();
        let scale = fd.iter().map(|v| v.abs()).fold(0.0, f64::max);
        assert!(scale > 1e-6, "{block:?}: the prior's gradient vanishes");
        for (k, fd) in fd.iter().enumerate() {
            assert!(
                (-eq.b[k] - fd).abs() <= tolerance * scale,
                "{block:?}[{k}]: normal equations say {}, central differences {fd}",
                -eq.b[k],
            );
            // A parameter the prior pulls on has curvature (the strain prior leaves q10…q12).
            assert!(
                eq.h[(k, k)] > 0.0 || fd.abs() < 1e-9,
                "{block:?}[{k}]: a gradient but no curvature"
            );
        }
    }

    /// Each prior's energy is the quadratic whose gradient and curvature it adds to the normal
    /// equations: the step that accepts on the energy minimises what it solves for.
    #[test]
    fn priors_add_the_gradient_of_their_own_energy() {
        let (state, previous, h) = states();
        let centre = DVec3::new(1.0, 2.0, -3.0);
        let affine = PoseDamping::new(Block::Affine, &previous, centre, 0.7, 2.5, &h).unwrap();
        check(&affine, &state, Block::Affine, 12, 1e-6);
        check(
            &StrainPrior::new(1.3, 1.0, &h),
            &state,
            Block::Affine,
            12,
            1e-5,
        );
        check(
            &StrainPrior::new(1.3, 0.1, &h),
            &state,
            Block::Affine,
            12,
            1e-5,
        );
        check(
            &StrainPrior::new(1.3, 4.0, &h),
            &state,
            Block::Affine,
            12,
            1e-5,
        );
        let sigma = [2.0, 1.0, 0.5];
        let shape = ShapePrior::new(2.0, &sigma, &previous, 0.5, &h);
        check(&shape, &state, Block::Shape, 3, 1e-6);
        check(
            &CameraDamping::new(&previous, 0.01, [1.0, 1.0, 1.0, 1.0, 100.0], &h),
            &state,
            Block::Cameras(1),
            5,
            1e-6,
        );
        // The rigid block's rotation deviation is taken to move one for one with the increment:
        // exact at zero deviation, off by O(|deviation|²) elsewhere (here 0.015 rad).
        let rigid = PoseDamping::new(Block::Rigid, &previous, centre, 0.7, 2.5, &h).unwrap();
        let mut near = previous.clone();
        near.affine = Affine::from_linear_translation(
            rotation_from_vector(DVec3::new(0.01, -0.01, 0.005)) * previous.affine.linear(),
            previous.affine.translation_mm() + DVec3::new(0.5, -0.2, 1.0),
        );
        check(&rigid, &near, Block::Rigid, 6, 1e-3);
        // And none of them has energy at the state it pulls towards.
        assert_eq!(affine.energy(&previous), 0.0);
        assert_eq!(
            CameraDamping::new(&previous, 1.0, [1.0; 5], &h).energy(&previous),
            0.0
        );
    }

    /// Depth's own weight reaches the translation along the camera's axis and nothing else: in
    /// both blocks the last parameter (q12, or the centre's z shift).
    #[test]
    fn depth_has_its_own_pose_damping() {
        let (_, previous, h) = states();
        let centre = DVec3::new(1.0, 2.0, -3.0);
        for (block, n) in [(Block::Affine, 12), (Block::Rigid, 6)] {
            let same = PoseDamping::new(block, &previous, centre, 0.7, 0.7, &h).unwrap();
            let firm = PoseDamping::new(block, &previous, centre, 0.7, 7.0, &h).unwrap();
            for k in 0..n - 1 {
                assert_eq!(same.lambda[k], firm.lambda[k], "{block:?}[{k}]");
            }
            assert!(same.lambda[n - 1] > 0.0);
            assert!(
                (firm.lambda[n - 1] - 10.0 * same.lambda[n - 1]).abs() < 1e-9 * firm.lambda[n - 1]
            );
        }
    }
}
