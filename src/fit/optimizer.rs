//! Minimises the objective frame by frame: block-coordinate T → W → π (paper §II-C), coarse to
//! fine, each block by damped Gauss–Newton steps in the style of the fast region-based trackers
//! (RBOT, SRT3D, ICG). The objective is a sum of image terms ([`LineTerm`], [`StereoTerm`]) and
//! the block's priors (`priors`); a step sums their normal equations, damps them, solves, and
//! is accepted on the objective.

pub use super::config::{FitParams, Mode};
use super::context::FrameContext;
use super::lines::target::{confidence, line_contrasts, structure_confidence};
use super::lines::{EnergyParams, Line, LineTerm};
use super::objective::{ImageTerm, NormalEquations, Prior};
use super::priors::{CameraDamping, PoseDamping, ShapePrior, StrainPrior};
use super::probability::ViewProbabilities;
use super::state::{Block, FitState, apply_increment};
use super::stereo::{StereoSet, StereoTerm};
use crate::appearance::Appearance;
use glam::DVec3;
use nalgebra::{DMatrix, DVector};
use std::sync::atomic::Ordering;

/// What fitting one frame produced.
#[derive(Debug, Clone)]
pub struct FrameFit {
    pub state: FitState,
    pub energy: f64,
    pub iterations: u32,
    /// Mean forest probability of a structure just inside its fitted contour minus just
    /// outside, over all lines of the finest level, in [0, 1].
    pub confidence: f64,
    /// The same per visible structure, then averaged over them ([`structure_confidence`]).
    pub structure_confidence: f64,
    pub lines: usize,
    /// The joint information of the fitted state (pose, shape, the rig's intrinsics), when
    /// `params.information` asks for it and the model has hidden structures.
    pub information: Option<super::information::Information>,
}

/// One damped Gauss–Newton step on `block` over the lines and the stereo matches; returns the
/// new state and the line term's energy there. The image terms give the normal equations,
/// Levenberg–Marquardt damps them, the block's priors add theirs; the step is accepted when
/// the objective falls. `lines_energy`, when given, is the line term's energy at `state` on
/// these very lines (the previous step's answer): the term is a pure function of the lines and
/// the state, so it is not evaluated again.
#[allow(clippy::too_many_arguments)]
pub fn step(
    ctx: &FrameContext,
    lines: &[Line],
    stereo: &StereoSet,
    state: &FitState,
    prev: &FitState,
    block: Block,
    ep: &EnergyParams,
    params: &FitParams,
    lines_energy: Option<f64>,
) -> Option<(FitState, f64)> {
    let n = block.size(ctx.model);
    if n == 0 || lines.is_empty() {
        return None;
    }
    let deformed = ctx.model.deformed(&state.shape);
    let centre = ctx.model_centre(&deformed);
    let line_term = LineTerm {
        ctx,
        lines,
        params: *ep,
    };
    let stereo_term = StereoTerm::new(ctx, stereo, state, &deformed, params.stereo);
    let terms: [&dyn ImageTerm; 2] = [&line_term, &stereo_term];
    let mut eq = NormalEquations::zeros(n);
    super::profile::time(super::profile::Phase::NormalEquations, || {
        for term in terms {
            term.add_normal_equations(state, &deformed, block, &mut eq);
        }
    });
    eq.symmetrise();
    // A rig zooms as one: its cameras' intrinsics change by one shared increment, solved
    // for from the per-camera equations (Table III). Per camera, a relative shift of the
    // principal points fakes a change of disparity; the stereo term's curvature along it then
    // set the damping of every intrinsic, and the principal points stayed where calibration
    // left them while the pose slid sideways (10 px behind the zoom; now within 3).
    let rig = match block {
        Block::Cameras(m) => Some(shared_camera_increment(ctx, state, m)),
        _ => None,
    };
    if let Some(p) = &rig {
        eq = NormalEquations {
            h: p.transpose() * &eq.h * p,
            b: p.transpose() * &eq.b,
        };
    }
    // Of the shared intrinsics only fx is free. fy follows it at the calibrated aspect (a zoom
    // scales both alike; fitted apart, fy/fx wandered over 3 % on a 320×180 phantom). k1 is
    // barely seen by silhouettes, and left free it mimicked focal changes (k1 −1.3 against
    // +0.03 on a zoom in and out, issue 14): it follows fx by the scene's relation, or stays as
    // calibrated. The increment's fx column already carries both (`shared_camera_increment`);
    // the rows and columns of fy and k1 go, so fx and the principal point are solved for
    // without them.
    let holds_fy_k1 = matches!(block, Block::Cameras(_));
    if holds_fy_k1 {
        let size = eq.size();
        for k in [FY, K1] {
            for j in 0..size {
                eq.h[(k, j)] = 0.0;
                eq.h[(j, k)] = 0.0;
            }
            eq.h[(k, k)] = 1.0;
            eq.b[k] = 0.0;
        }
    }
    let b_data = eq.b.clone();
    let size = eq.size();
    let max_diag = (0..size)
        .map(|k| eq.h[(k, k)])
        .fold(0.0, f64::max)
        .max(1e-9);
    for k in 0..size {
        eq.h[(k, k)] += params.solver.lm * eq.h[(k, k)] + params.solver.lm_floor * max_diag;
    }
    let priors = add_priors(ctx, state, prev, block, centre, params, &mut eq);
    let cholesky = eq.h.clone().cholesky()?;
    // Accept only steps that lower the objective: the image terms on these lines and matches
    // plus the priors just added, the very energy the normal equations approximate. The stereo
    // term is linearised at `state` (its anchors' normals), so only the line term's energy
    // carries over from one step to the next.
    let energies_at = |st: &FitState, lines_energy: Option<f64>| {
        let moved;
        let d = if block == Block::Shape {
            moved = ctx.model.deformed(&st.shape);
            &moved
        } else {
            &deformed
        };
        let lines_energy = lines_energy.unwrap_or_else(|| line_term.energy(st, d));
        (
            lines_energy,
            lines_energy + stereo_term.energy(st, d) + priors.energy(st),
        )
    };
    let objective = |st: &FitState, lines_energy: Option<f64>| {
        super::profile::time(super::profile::Phase::Objective, || {
            energies_at(st, lines_energy)
        })
    };
    let (_, before) = objective(state, lines_energy);
    let try_step = |delta: &DVector<f64>, tries: usize| -> Option<(FitState, f64)> {
        if delta.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let mut delta = delta.clone();
        if holds_fy_k1 {
            delta[FY] = 0.0;
            delta[K1] = 0.0;
        }
        let full = match &rig {
            Some(p) => p * delta,
            None => delta,
        };
        let mut scale = 1.0;
        for _ in 0..tries {
            let scaled: Vec<f64> = full.iter().map(|d| d * scale).collect();
            let mut next = apply_increment(state, block, &scaled, centre);
            // Only the shape block moves the weights; the others' energies are evaluated
            // with the shape instance of `state` (and carried to the next step as such).
            if block == Block::Shape {
                ctx.model.shape.pca.clamp_weights(&mut next.shape);
            }
            if holds_fy_k1 {
                follow_fx(ctx, &mut next.intrinsics);
            }
            let (lines_energy, total) = objective(&next, None);
            if total < before {
                return Some((next, lines_energy));
            }
            scale *= 0.5;
        }
        None
    };
    // First the line targets (they see minima several pixels away, robustly) ...
    if let Some(next) = try_step(&cholesky.solve(&eq.b), params.solver.target_tries) {
        return Some(next);
    }
    // ... and near the optimum, where targets of ambiguous lines outvote the local slope, a
    // Newton step on the energy itself: H is positive definite, so −H⁻¹∇E descends. The
    // priors' share of b is minus their gradient.
    let gradient = terms
        .iter()
        .map(|t| DVector::from_vec(t.gradient(state, &deformed, block)))
        .reduce(|a, b| a + b)
        .unwrap_or_else(|| DVector::zeros(n));
    let gradient = match &rig {
        Some(p) => p.transpose() * gradient,
        None => gradient,
    };
    let prior = &eq.b - &b_data;
    try_step(
        &cholesky.solve(&(prior - gradient)),
        params.solver.newton_tries,
    )
}

/// The priors of one step on one block, added to the normal equations in a fixed order (each
/// scaled to the curvature accumulated before it).
enum BlockPriors<'a> {
    None,
    Rigid(PoseDamping),
    Affine(PoseDamping, StrainPrior),
    Shape(ShapePrior<'a>),
    Cameras(CameraDamping),
}

impl BlockPriors<'_> {
    /// The priors' total energy at `state`: the part of the objective whose curvature they
    /// added to the normal equations. (Until this was the whole sum, steps were accepted on the
    /// shape prior alone: a step could raise the pose, strain or camera priors' energy, and so
    /// the objective being minimised, and still be taken.)
    fn energy(&self, state: &FitState) -> f64 {
        match self {
            BlockPriors::None => 0.0,
            BlockPriors::Rigid(pose) => pose.energy(state),
            BlockPriors::Affine(pose, strain) => pose.energy(state) + strain.energy(state),
            BlockPriors::Shape(shape) => shape.energy(state),
            BlockPriors::Cameras(cameras) => cameras.energy(state),
        }
    }
}

/// Makes the priors of `block` and adds their normal equations to `eq`.
fn add_priors<'a>(
    ctx: &FrameContext<'a>,
    state: &FitState,
    prev: &FitState,
    block: Block,
    centre: DVec3,
    params: &FitParams,
    eq: &mut NormalEquations,
) -> BlockPriors<'a> {
    let pose = |eq: &mut NormalEquations| {
        let priors = &params.priors;
        let damping = PoseDamping::new(
            block,
            prev,
            centre,
            priors.pose_damping,
            priors.pose_damping_depth,
            &eq.h,
        )?;
        damping.add_normal_equations(state, eq);
        Some(damping)
    };
    match block {
        Block::Rigid => pose(eq).map_or(BlockPriors::None, BlockPriors::Rigid),
        Block::Affine => {
            let Some(damping) = pose(eq) else {
                return BlockPriors::None;
            };
            let strain = StrainPrior::new(params.priors.strain, params.priors.strain_scale, &eq.h);
            strain.add_normal_equations(state, eq);
            BlockPriors::Affine(damping, strain)
        }
        Block::Shape => {
            let shape = ShapePrior::new(
                params.priors.shape,
                &ctx.model.shape.pca.sigma_mm,
                prev,
                params.priors.shape_damping,
                &eq.h,
            );
            shape.add_normal_equations(state, eq);
            BlockPriors::Shape(shape)
        }
        Block::Cameras(_) => {
            let priors = &params.priors;
            let damping =
                CameraDamping::new(prev, priors.camera_damping, priors.camera_relative, &eq.h);
            damping.add_normal_equations(state, eq);
            BlockPriors::Cameras(damping)
        }
    }
}

/// Indices of fy and k1 among a camera block's shared parameters (fx, fy, cx, cy, k1).
const FY: usize = 1;
const K1: usize = 4;

/// fy and k1 of every camera set from its fx: the calibrated aspect, the scene's k1-vs-focal
/// relation (k1 held where the scene gives none).
fn follow_fx(ctx: &FrameContext, intrinsics: &mut [crate::geometry::Intrinsics]) {
    for (m, intr) in intrinsics.iter_mut().enumerate() {
        intr.fy = intr.fx * ctx.calibrated_aspect(m);
        if let Some(k1) = ctx.k1_at(m, intr.fx) {
            intr.k1 = k1;
        }
    }
}

/// ∂(all cameras' intrinsics)/∂(shared increment): 5·cameras × 5, each camera's five
/// parameters moving by the rig's one increment, where fy and k1 follow fx: fx's column moves
/// each camera's fy by its calibrated aspect and its k1 by the scene's k1-vs-focal slope, and
/// the columns of fy and k1 are zero. (Until 2026-12-06 fx's column moved fx alone, so a step
/// and its equilibrium saw only the horizontal stretch of a zoom, while the step taken moved fy
/// and k1 with it.)
fn shared_camera_increment(ctx: &FrameContext, state: &FitState, cameras: usize) -> DMatrix<f64> {
    DMatrix::from_fn(5 * cameras, 5, |r, c| {
        let m = r / 5;
        match (r % 5, c) {
            (FY, 0) => ctx.calibrated_aspect(m),
            (K1, 0) => state
                .intrinsics
                .get(m)
                .map_or(0.0, |intr| ctx.k1_slope(m, intr.fx)),
            (FY, _) | (K1, _) => 0.0,
            (k, c) if k == c => 1.0,
            _ => 0.0,
        }
    })
}

/// Fits one frame from `start`; `prev` anchors the damping. `params.correct_cameras` enables the π
/// block (LSC inside a zoom change).
pub fn fit_frame(
    ctx: &FrameContext,
    start: &FitState,
    prev: &FitState,
    views: &mut [ViewProbabilities],
    appearance: Option<&Appearance>,
    params: &FitParams,
) -> FrameFit {
    let mut state = start.clone();
    let mut iterations = 0u32;
    let mut blocks = vec![if params.mode == Mode::R {
        Block::Rigid
    } else {
        Block::Affine
    }];
    if matches!(params.mode, Mode::LS | Mode::LSC) && ctx.model.shape.mode_count() > 0 {
        blocks.push(Block::Shape);
    }
    if params.hold_pose {
        blocks.retain(|&b| b == Block::Shape);
    }
    if params.correct_cameras {
        // Zooming in and moving closer look alike in one frame: during a zoom the cameras go
        // first (and `FitConfig::resolve` holds the pose harder), so the change is explained
        // by the intrinsics.
        blocks.insert(0, Block::Cameras(ctx.cameras.len()));
    }
    let levels: Vec<usize> = params
        .levels
        .iter()
        .copied()
        .filter(|&l| l < views.first().map(|v| v.level_count()).unwrap_or(1))
        .collect();
    let mut last_lines: Vec<Line> = Vec::new();
    let mut last_level = None;
    // The line term's energy at `state` on `lines`, while both are unchanged.
    let mut lines_energy: Option<f64> = None;
    let finest = levels.last().copied().unwrap_or(0);
    let mut matches = StereoSet::default();
    for &level in &levels {
        let ep = params.energy_at(level);
        // Lines live across blocks and rounds: rebuilt every `rebuild_every` steps and when the
        // level changes (rim points re-project with the state at every evaluation, and
        // ±10 px of samples outlast a few steps of motion).
        let mut lines: Vec<Line> = Vec::new();
        let mut since_build = usize::MAX;
        let mut matched = false;
        for _ in 0..params.rounds {
            for &block in &blocks {
                // The affine only moves rigidly at coarse levels: a 12-dof fit to a blurred
                // silhouette drifts into shears.
                let block = if block == Block::Affine && level >= params.solver.rigid_from_level {
                    Block::Rigid
                } else {
                    block
                };
                for _ in 0..params.steps {
                    if params
                        .cancel
                        .as_ref()
                        .is_some_and(|c| c.load(Ordering::Relaxed))
                    {
                        break;
                    }
                    if since_build >= params.rebuild_every.max(1) {
                        let rasters;
                        (lines, rasters) =
                            super::profile::time(super::profile::Phase::Lines, || {
                                ctx.build_lines_and_rasters(&state, views, appearance, &ep)
                            });
                        since_build = 0;
                        lines_energy = None;
                        if !matched {
                            // Once per level, from the state the level starts at: the model moves
                            // little within a level, and point-to-plane lets it slide.
                            matches = super::profile::time(super::profile::Phase::Stereo, || {
                                super::stereo::measure(
                                    ctx,
                                    &state,
                                    views,
                                    appearance,
                                    finest,
                                    // The lines' rasters lie one level below `level`; the
                                    // matcher wants them one below `finest`.
                                    rasters.first().filter(|_| level == finest),
                                    &params.stereo,
                                )
                            });
                            matched = true;
                        }
                    }
                    since_build += 1;
                    last_level = Some(level);
                    iterations += 1;
                    // One thread: a step's loops over 128 lines take 50–150 µs, about what
                    // waking the pool's other thread costs (4703, LS: steps 2.0 ms a frame on
                    // one thread, 2.4 on two).
                    let next = super::profile::time(super::profile::Phase::Steps, || {
                        crate::pool::serially(|| {
                            step(
                                ctx,
                                &lines,
                                &matches,
                                &state,
                                prev,
                                block,
                                &ep,
                                params,
                                lines_energy,
                            )
                        })
                    });
                    match next {
                        Some((next, energy)) => (state, lines_energy) = (next, Some(energy)),
                        None => break,
                    }
                }
            }
        }
        last_lines = lines;
    }
    let final_level = levels.last().copied().unwrap_or(0);
    let ep = params.energy_at(final_level);
    // The last block's lines serve for the energy and confidence when they are at this level.
    let (lines, energy) = if last_level == Some(final_level) && !last_lines.is_empty() {
        let energy = lines_energy.unwrap_or_else(|| ctx.energy(&last_lines, &state, &ep));
        (last_lines, energy)
    } else {
        let lines = ctx.build_lines(&state, views, appearance, &ep);
        let energy = ctx.energy(&lines, &state, &ep);
        (lines, energy)
    };
    let information =
        (params.information && ctx.model.structures.iter().any(|s| !s.visible)).then(|| {
            super::profile::time(super::profile::Phase::Information, || {
                super::information::joint_information(ctx, &lines, &matches, &state, &ep, params)
            })
        });
    let contrasts = line_contrasts(&lines, &state, ctx, &ep);
    FrameFit {
        information,
        confidence: confidence(&contrasts),
        structure_confidence: structure_confidence(&contrasts, &ctx.imaged()),
        energy,
        iterations,
        lines: lines.len(),
        state,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::Model;
    use crate::synth::{SynthOptions, memory_scene};

    /// The shared increment's columns against central differences of every camera's five
    /// corrected intrinsics as a step sets them (fy and k1 following fx): fx's column carries
    /// fy's aspect and k1's slope, the principal point moves alone, fy's and k1's columns are
    /// empty.
    #[test]
    fn shared_camera_increment_matches_central_differences_of_the_followed_intrinsics() {
        let mut scene = memory_scene(&SynthOptions {
            frames: 1,
            width: 240,
            height: 136,
            ..SynthOptions::default()
        })
        .unwrap();
        scene.k1_vs_focal = Some([0.02, -0.05, 0.03]);
        scene.cameras[1].intrinsics.fy = scene.cameras[1].intrinsics.fx * 1.01;
        let model = Model::build(&scene).unwrap();
        let ctx = FrameContext::new(&model, &scene);
        let mut start: Vec<_> = scene.cameras.iter().map(|c| c.intrinsics).collect();
        for intr in &mut start {
            intr.fx *= 1.07;
        }
        follow_fx(&ctx, &mut start);
        let state = FitState {
            affine: crate::geometry::Affine::IDENTITY,
            shape: vec![0.0; model.shape.mode_count()],
            intrinsics: start.clone(),
        };
        let m = scene.cameras.len();
        let p = shared_camera_increment(&ctx, &state, m);
        assert_eq!(p.shape(), (5 * m, 5));
        for k in 0..5 {
            let h = 1e-3;
            let moved = |d: f64| {
                let mut intr = start.clone();
                for i in &mut intr {
                    let mut v = i.corrected();
                    v[k] += d;
                    *i = i.with_corrected(v);
                }
                if k == 0 {
                    follow_fx(&ctx, &mut intr);
                }
                intr
            };
            let (plus, minus) = (moved(h), moved(-h));
            for c in 0..m {
                for r in 0..5 {
                    let fd = if k == FY || k == K1 {
                        0.0
                    } else {
                        (plus[c].corrected()[r] - minus[c].corrected()[r]) / (2.0 * h)
                    };
                    let an = p[(5 * c + r, k)];
                    assert!(
                        (fd - an).abs() <= 1e-6 * (1.0 + fd.abs()),
                        "camera {c}, parameter {r}, column {k}: central differences {fd}, increment {an}"
                    );
                }
            }
        }
        // The scene's relation moves k1 with fx here: the column is not trivially zero.
        assert!(p[(K1, 0)].abs() > 1e-7, "k1 slope {}", p[(K1, 0)]);
        assert!((p[(5 + FY, 0)] - 1.01).abs() < 1e-9);
    }
}
