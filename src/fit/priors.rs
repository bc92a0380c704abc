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
    /// the curvature of `h`.
    pub fn new(
        block: Block,
        previous: &FitState,
        centre_pre: DVec3,
        weight: f64,
        h: &DMatrix<f64>,
    ) -> Option<Self> {
        let linear = match block {
            Block::Rigid => 0..3,
            Block::Affine => 0..9,
            _ => return None,
        };
        let translation = linear.end..linear.end + 3;
        let group = mean_diagonal(h, linear.clone());
        let lambda = linear
            .map(|_| weight * group)
            .chain(translation.map(|k| weight * h[(k, k)]))
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
/// real tissue stretch survives where the data insist. Energy 0.5 λ ‖A − polar(A)‖²_F, whose
/// gradient in A is exactly λ (A − polar(A)).
pub struct StrainPrior {
    lambda: f64,
}

impl StrainPrior {
    /// `weight` times the mean curvature of `h` over the linear part (q1…q9).
    pub fn new(weight: f64, h: &DMatrix<f64>) -> Self {
        Self {
            lambda: weight * (0..9).map(|k| h[(k, k)]).sum::<f64>() / 9.0,
        }
    }

    /// q1…q9 minus those of the nearest rotation (None for a degenerate linear part).
    fn strain(state: &FitState) -> Option<[f64; 9]> {
        let rotation = nearest_rotation(state.affine.linear())?;
        let target = Affine::from_linear_translation(rotation, DVec3::ZERO);
        Some(std::array::from_fn(|k| state.affine.q[k] - target.q[k]))
    }
}

impl Prior for StrainPrior {
    fn energy(&self, state: &FitState) -> f64 {
        Self::strain(state).map_or(0.0, |s| quadratic(&[self.lambda; 9], &s))
    }

    fn add_normal_equations(&self, state: &FitState, eq: &mut NormalEquations) {
        let Some(strain) = Self::strain(state) else {
            return;
        };
        for (k, s) in strain.iter().enumerate() {
            eq.h[(k, k)] += self.lambda;
            eq.b[k] -= self.lambda * s;
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

    /// The Mahalanobis part alone, 0.5 · weight · Σ (w_k / σ_k)².
    pub fn mahalanobis_energy(&self, state: &FitState) -> f64 {
        state
            .shape
            .iter()
            .zip(self.sigma_mm)
            .map(|(w, s)| 0.5 * self.weight * (w / s.max(1e-9)).powi(2))
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
        for (k, s) in self.sigma_mm.iter().enumerate() {
            let inv = self.weight / (s * s).max(1e-12);
            let lam = self.damping;
            let w = state.shape[k];
            eq.h[(k, k)] += inv + lam;
            eq.b[k] -= inv * w + lam * (w - self.previous[k]);
        }
    }
}

/// Precision of each corrected intrinsic (fx, fy, cx, cy, k1) relative to its own curvature:
/// k1 is held far harder, since zoom barely moves distortion (paper §IV-A) and a free k1
/// mimics a focal change.
pub const CAMERA_RELATIVE_DAMPING: [f64; 5] = [1.0, 1.0, 1.0, 1.0, 100.0];

/// Tikhonov damping of the rig's intrinsics towards the previous frame's. The rig moves by one
/// shared increment (`optimizer::shared_camera_increment`), so camera 0's change stands for
/// all: the prior acts on the five shared parameters.
pub struct CameraDamping {
    previous: [f64; 5],
    lambda: [f64; 5],
}

impl CameraDamping {
    /// `weight` times [`CAMERA_RELATIVE_DAMPING`] times each parameter's curvature in `h`
    /// (the rig's five shared parameters).
    pub fn new(previous: &FitState, weight: f64, h: &DMatrix<f64>) -> Self {
        Self {
            previous: previous.intrinsics[0].corrected(),
            lambda: std::array::from_fn(|k| weight * CAMERA_RELATIVE_DAMPING[k] * h[(k, k)]),
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
