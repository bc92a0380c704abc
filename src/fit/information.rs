//! How sure the fit is of its own parameters: the Gauss–Newton information of the whole
//! frame (pose, shape weights and the rig's shared intrinsics together) at the fitted state.
//!
//! The optimiser moves one block at a time (§II-C), so its normal equations never hold the
//! cross terms between pose and shape, which are exactly what carries a hidden structure's
//! uncertainty: a shape mode that moves the tumour may also move the visible rim a little,
//! and the pose can partly take its place. Here every line's and every stereo match's row is
//! taken over all blocks at once, weighted as the fit weights it (a line by its target's
//! certainty, a match by its depth σ and Huber weight), and the fit's own priors on the
//! shape (Mahalanobis) and the affine's strain are added. Its inverse is the Laplace
//! approximation of the parameters' covariance, in the energy's units; `hidden_region`
//! scales it by a calibrated factor, since neighbouring lines see the same errors and are
//! not independent.

use super::context::FrameContext;
use super::lines::{EnergyParams, Line, target};
use super::optimizer::FitParams;
use super::state::{Block, FitState};
use super::stereo::{StereoSet, StereoTerm};
use nalgebra::DMatrix;
use rayon::prelude::*;

/// The rig's shared intrinsics among the columns: fx (fy following at the calibrated aspect),
/// cx, cy, as the camera block moves them.
pub const CAMERA_COLUMNS: usize = 3;

/// The joint information of one frame's fit. Columns: the pose block's increments, then the
/// shape weights (when the shape is fitted), then [`CAMERA_COLUMNS`].
#[derive(Debug, Clone, PartialEq)]
pub struct Information {
    /// The pose block the columns start with: rigid in mode R, affine otherwise.
    pub pose: Block,
    /// Shape weights among the columns (0 where the mode does not fit the shape).
    pub shape_modes: usize,
    /// Jᵀ W J of the image terms plus the fit's shape and strain priors.
    pub h: DMatrix<f64>,
    /// What the fit could not explain: the root mean square of the lines' target shifts at
    /// the fitted state (full-resolution px; lines whose edge lies past their end are left
    /// out). Near zero where the model's rim sits on the image's edges; a deformation the
    /// shape catalog does not span leaves it standing.
    pub rim_residual_px: f64,
}

impl Information {
    pub fn pose_columns(&self) -> usize {
        match self.pose {
            Block::Rigid => 6,
            _ => 12,
        }
    }

    /// The first camera column.
    pub fn camera_offset(&self) -> usize {
        self.pose_columns() + self.shape_modes
    }

    pub fn size(&self) -> usize {
        self.camera_offset() + CAMERA_COLUMNS
    }
}

/// A camera block row (five per camera) as the rig's shared fx, cx, cy move it: every camera
/// by the same increment, fy by the increment times the camera's calibrated aspect fy/fx and k1
/// by the scene's k1-vs-focal slope (as the optimizer's step moves them).
fn shared_camera_row(ctx: &FrameContext, row: &[f64], state: &FitState) -> [f64; CAMERA_COLUMNS] {
    let mut out = [0.0; CAMERA_COLUMNS];
    for (m, j) in row.chunks(5).enumerate() {
        let Some(intr) = state.intrinsics.get(m) else {
            break;
        };
        if j.len() < 5 {
            break;
        }
        out[0] += j[0] + ctx.calibrated_aspect(m) * j[1] + ctx.k1_slope(m, intr.fx) * j[4];
        out[1] += j[2];
        out[2] += j[3];
    }
    out
}

/// Adds w · rowᵀ row to `h`.
fn add_row(h: &mut DMatrix<f64>, row: &[f64], w: f64) {
    if !w.is_finite() || w <= 0.0 || row.iter().any(|v| !v.is_finite()) {
        return;
    }
    for r in 0..row.len() {
        if row[r] == 0.0 {
            continue;
        }
        for q in r..row.len() {
            h[(r, q)] += w * row[r] * row[q];
        }
    }
}

/// The joint information at `state` from the final level's `lines` (energy settings `ep`) and
/// stereo matches, with the priors of `params` (its shape prior and strain prior).
pub fn joint_information(
    ctx: &FrameContext,
    lines: &[Line],
    stereo: &StereoSet,
    state: &FitState,
    ep: &EnergyParams,
    params: &FitParams,
) -> Information {
    let pose = if params.mode == super::Mode::R {
        Block::Rigid
    } else {
        Block::Affine
    };
    let model = ctx.model;
    let shape_modes = if matches!(params.mode, super::Mode::LS | super::Mode::LSC) {
        model.shape.mode_count()
    } else {
        0
    };
    let mut info = Information {
        pose,
        shape_modes,
        h: DMatrix::zeros(0, 0),
        rim_residual_px: 0.0,
    };
    let n = info.size();
    let cameras = Block::Cameras(ctx.cameras.len());
    let mut blocks = vec![pose];
    if shape_modes > 0 {
        blocks.push(Block::Shape);
    }
    let mut h = DMatrix::zeros(n, n);
    let deformed = model.deformed(&state.shape);
    let rotation_centre = ctx.rotation_centre(state, &deformed);
    // Each line's row in parallel (its Jacobians are the cost), added up in the lines' order:
    // the same matrix as a serial loop, bit for bit, however many threads.
    let line_rows: Vec<Option<(Vec<f64>, f64, f64)>> = lines
        .par_iter()
        .map(|line| {
            let mut row = Vec::with_capacity(n);
            let mut c = None;
            for &block in &blocks {
                let (at, j) =
                    ctx.line_jacobian(line, state, &deformed, block, ep.level, rotation_centre)?;
                c = Some(at);
                row.extend(j);
            }
            let (at, j) =
                ctx.line_jacobian(line, state, &deformed, cameras, ep.level, rotation_centre)?;
            row.extend(shared_camera_row(ctx, &j, state));
            let (shift, variance) = target::line_target(line, c.unwrap_or(at), ep);
            Some((row, shift, variance))
        })
        .collect();
    // The rim residual's mean square counts each line as the rim lines it stands for.
    let (mut shift2, mut shifts) = (0.0, 0.0);
    for (line, row) in lines.iter().zip(line_rows) {
        let Some((row, shift, variance)) = row else {
            continue;
        };
        add_row(&mut h, &row, line.weight / variance);
        if variance != ep.saturated_line_variance_px2 && shift.is_finite() {
            shift2 += line.weight * shift * shift;
            shifts += line.weight;
        }
    }
    if shifts > 0.0 {
        let level_px = 1.0 / crate::geometry::camera::level_scale(ep.level);
        info.rim_residual_px = level_px * (shift2 / shifts).sqrt();
    }
    if !stereo.matches.is_empty() {
        let term = StereoTerm::new(ctx, stereo, state, &deformed, params.stereo);
        let mut joint_blocks = blocks.clone();
        joint_blocks.push(cameras);
        let geometric = info.camera_offset();
        term.for_each_joint_row(state, &deformed, &joint_blocks, |r, _, w| {
            if r.len() < geometric {
                return;
            }
            let mut full = r[..geometric].to_vec();
            full.extend(shared_camera_row(ctx, &r[geometric..], state));
            add_row(&mut h, &full, w);
        });
    }
    for r in 0..n {
        for q in 0..r {
            h[(r, q)] = h[(q, r)];
        }
    }
    // The fit's priors, as its steps add them: the strain prior relative to the affine's own
    // curvature, the shape's Mahalanobis prior absolute.
    if pose == Block::Affine {
        super::priors::StrainPrior::new(params.priors.strain, params.priors.strain_scale, &h)
            .add_curvature(state, &mut h);
    }
    let offset = info.pose_columns();
    for (k, sigma) in model
        .shape
        .pca
        .sigma_mm
        .iter()
        .take(shape_modes)
        .enumerate()
    {
        h[(offset + k, offset + k)] += params.priors.shape / (sigma * sigma).max(1e-12);
    }
    info.h = h;
    info
}
