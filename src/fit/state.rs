//! What the fit estimates for one frame (paper eq. 12): the global affine T (eq. 2), the joint
//! shape weights W (eq. 1) and every camera's intrinsics π (eq. 8), and the parameter blocks
//! that the block-coordinate optimiser moves one at a time (§II-C: T → W → π).

use super::model::Model;
use crate::geometry::{Affine, Intrinsics};
use glam::DVec3;

/// Pose, shape and camera parameters of one frame.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FitState {
    pub affine: Affine,
    /// Joint shape weights (mm along unit modes).
    pub shape: Vec<f64>,
    /// Intrinsics of every camera (extrinsics stay as calibrated).
    pub intrinsics: Vec<Intrinsics>,
}

/// Which parameters a block moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Block {
    /// Rigid: rotation vector and translation (6), about the current pose.
    Rigid,
    /// The 12 affine parameters q1…q12 of eq. 2.
    Affine,
    /// The joint shape weights.
    Shape,
    /// fx, fy, cx, cy, k1 of each of the n cameras, five per camera in camera order. One
    /// block for all: the stereo term ties the cameras together (a focal change in one view
    /// alone moves every triangulated point), so they must move jointly.
    Cameras(usize),
}

impl Block {
    pub fn size(self, model: &Model) -> usize {
        match self {
            Block::Rigid => 6,
            Block::Affine => 12,
            Block::Shape => model.shape.mode_count(),
            Block::Cameras(n) => 5 * n,
        }
    }
}

/// Applies a block increment to a state. Rigid increments turn the posed model about the
/// posed `centre_pre` (the model centre in preoperative coordinates).
pub fn apply_increment(
    state: &FitState,
    block: Block,
    delta: &[f64],
    centre_pre: DVec3,
) -> FitState {
    let mut out = state.clone();
    match block {
        Block::Affine => {
            for (q, d) in out.affine.q.iter_mut().zip(delta) {
                *q += d;
            }
        }
        Block::Rigid => {
            let rot = crate::geometry::pose::rotation_from_vector(DVec3::new(
                delta[0], delta[1], delta[2],
            ));
            let centre = state.affine.apply(centre_pre);
            // New pose: rotate the posed model about its centre, then shift.
            let about = Affine::from_linear_translation(
                rot,
                centre - rot * centre + DVec3::new(delta[3], delta[4], delta[5]),
            );
            out.affine = about.compose(&state.affine);
        }
        Block::Shape => {
            for (w, d) in out.shape.iter_mut().zip(delta) {
                *w += d;
            }
        }
        Block::Cameras(_) => {
            for (intr, d) in out.intrinsics.iter_mut().zip(delta.chunks(5)) {
                let mut v = intr.corrected();
                for (x, dx) in v.iter_mut().zip(d) {
                    *x += dx;
                }
                *intr = intr.with_corrected(v);
            }
        }
    }
    out
}
