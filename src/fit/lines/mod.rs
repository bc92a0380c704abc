//! The energy of eq. 4 on sparse correspondence lines, and its analytic gradient (eq. 13–17,
//! Tables II and III).
//!
//! For each view and visible structure, the rim of the posed mesh (edges between a face that
//! faces the camera and one that does not) is projected; rim points that the raster confirms as
//! the boundary of the structure's visible region (front-most inside, not the structure just
//! outside) each get a line along their image normal ([`build`]). Along a line, sample s at
//! position x_s has signed distance d_s = n·(c − x_s) to the projected rim point c (positive
//! inside), and contributes g_f H(d_s) + g_b (1 − H(d_s)) with g = −log p (eq. 9) and a logistic
//! Heaviside. The line set is fixed while it is evaluated, so E is smooth in T, W and π, and
//! ∂E/∂ξ = Σ (g_f − g_b) H'(d_s) n·∂c/∂ξ is checked against central differences in the tests.
//! The Gauss–Newton step meets each line's target shift ([`target`]) instead of following the
//! local slope: [`LineTerm`] is the term the optimiser sums.

pub mod build;
pub mod target;

use super::context::FrameContext;
use super::objective::{ImageTerm, NormalEquations};
use super::state::{Block, FitState};
use crate::geometry::camera::{level_scale, pixel_at_scale};
use glam::{DVec2, DVec3};
use rayon::prelude::*;

/// Energy settings at one pyramid level.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EnergyParams {
    /// The pyramid level the lines live at (set per fit, not configured).
    #[serde(skip)]
    pub level: usize,
    /// Samples on each side of the rim point (level pixels).
    pub half_length: usize,
    /// Logistic Heaviside width (level pixels).
    pub heaviside_px: f64,
    /// Probabilities are kept inside [floor, 1 − floor] before the logs.
    pub probability_floor: f32,
    /// Variance (level px²) of a line whose best shift lies at the end of its search range:
    /// as loose as a σ = 2 px edge, where a clean edge's parabola gives σ ≈ 0.15–0.5 px.
    pub saturated_line_variance_px2: f64,
    /// A softmin variance under this (level px²) is refined by a parabola through the best
    /// shift and its neighbours: near the optimum the softmin collapses onto one integer
    /// shift and loses the sub-pixel offset.
    pub parabola_below_variance_px2: f64,
    /// The parabola's variance (1 / curvature) is kept inside this range (level px²).
    pub parabola_variance_px2: [f64; 2],
    /// A softmin variance is at least this (level px²).
    pub min_softmin_variance_px2: f64,
    /// A rim point gets a line when the visibility raster (one level coarser) shows its
    /// structure this far inside and something else this far outside (level pixels).
    pub rim_check_px: f64,
    /// ... and the raster's depth just inside agrees with the rim point's within this share.
    pub rim_depth_tolerance: f64,
    /// At most one line per square cell of this side (level pixels).
    pub line_cell_px: f64,
    /// At most this many lines per structure and view (0: no limit). A rim with more is
    /// thinned evenly by angle around its centre, and each line kept weighs for the ones it
    /// stands for, so the silhouettes' total weight against the priors and the stereo term
    /// stays as tuned while the per-frame cost stops growing with the mesh's density (issue
    /// 14). Lines are one per rim edge, not one per cell: a phantom kidney gives 70–95 per
    /// view at 480×270, a KiTS kidney of ~5k vertices 190–210 (`line_cell_px` 2 → 4 took
    /// case_00003's 555 lines per frame only to 489). Neighbouring lines share pixels and the
    /// forest's errors are smooth, so most of them repeat each other: on 24 tuning scenes
    /// (3901–3912, 4101–4112, LSC) no limit / 64 / 48 / 32 / 24 / 16 gave Dice 0.9621 /
    /// 0.9620 / 0.9621 / 0.9620 / 0.9620 / 0.9618, hidden tumour 1.363 / 1.367 / 1.363 / 1.369
    /// / 1.371 / 1.382 mm (worst 4.44 / 4.43 / 4.37 / 4.32 / 4.33 / 4.63), fx error 0.921 /
    /// 0.926 / 0.935 / 0.931 / 0.936 / 0.971 %; on 24 others (3501–3512, 3701–3712) no limit
    /// / 32 gave Dice 0.9597 / 0.9593, hidden 1.562 / 1.571 mm (worst 3.95 / 4.00), fx 0.816 /
    /// 0.816 %. 32 is kept, twice the count where the figures began to move.
    pub max_lines_per_structure: usize,
    /// The confidence compares p_f on samples further than this inside and outside the
    /// fitted contour (level pixels).
    pub confidence_band_px: f64,
}

impl Default for EnergyParams {
    fn default() -> Self {
        Self {
            level: 0,
            half_length: 10,
            heaviside_px: 1.2,
            probability_floor: 0.02,
            saturated_line_variance_px2: 4.0,
            parabola_below_variance_px2: 1.0,
            parabola_variance_px2: [0.02, 4.0],
            min_softmin_variance_px2: 0.25,
            rim_check_px: 3.0,
            rim_depth_tolerance: 0.08,
            line_cell_px: 2.0,
            max_lines_per_structure: 32,
            confidence_band_px: 1.5,
        }
    }
}

/// One sample of a line: a pixel along the normal and the forest's word on it (eq. 9).
#[derive(Debug, Clone)]
pub struct Sample {
    pub pos: DVec2,
    pub pixel: u32,
    pub g_f: f32,
    pub g_b: f32,
    pub p_f: f32,
}

/// One correspondence line.
#[derive(Debug, Clone)]
pub struct Line {
    pub view: usize,
    pub structure: usize,
    pub a: u32,
    pub b: u32,
    pub t: f64,
    /// Unit outward normal (level pixels).
    pub normal: DVec2,
    pub samples: Vec<Sample>,
    /// How many rim lines this one stands for (1, more where the rim was thinned): its
    /// energy, gradient, normal equations and joint information count this many times, and so
    /// does it in the confidence and the hidden regions' rim residual.
    pub weight: f64,
}

impl Line {
    /// A line of view 0 and structure 0 on the edge (0, 1), for unit tests.
    #[cfg(test)]
    pub(crate) fn for_tests(normal: DVec2, samples: Vec<Sample>) -> Self {
        Self {
            view: 0,
            structure: 0,
            a: 0,
            b: 1,
            t: 0.5,
            normal,
            samples,
            weight: 1.0,
        }
    }
}

/// The logistic Heaviside H(d) of width `width` and its derivative H'(d).
pub(crate) fn heaviside(d: f64, width: f64) -> (f64, f64) {
    let h = 1.0 / (1.0 + (-d / width).exp());
    (h, h * (1.0 - h) / width)
}

/// The logistic Heaviside of every sample of a line at once, with one `exp` per line instead
/// of one per sample: samples lie a whole pixel apart along the normal, so sample s sits at
/// d_s = t₀ + m_s for the first sample's t₀ and an integer m_s, and
/// H(d_s) = 1 / (1 + e^(−t₀/w) · e^(−m_s/w)) with e^(−m/w) from a table made once per sum.
/// The energy's `exp` per sample was most of a Gauss–Newton step's time (an energy is
/// evaluated up to nine times per step). A sample off the unit grid (none is, as built) takes
/// the direct formula.
pub(crate) struct HeavisideTable {
    width: f64,
    /// e^(−m/w) for m in −reach..=reach.
    shifts: Vec<f64>,
    reach: i64,
}

impl HeavisideTable {
    pub fn new(width: f64, half_length: usize) -> Self {
        let reach = 2 * half_length as i64 + 2;
        Self {
            width,
            shifts: (-reach..=reach)
                .map(|m| (-(m as f64) / width).exp())
                .collect(),
            reach,
        }
    }

    /// (H(d_s), H'(d_s)) of every sample of `line` with the contour point at `c`.
    #[inline]
    pub fn of_line<'a>(
        &'a self,
        line: &'a Line,
        c: DVec2,
    ) -> impl Iterator<Item = (f64, f64)> + 'a {
        let t0 = line
            .samples
            .first()
            .map_or(0.0, |s| line.normal.dot(c - s.pos));
        let first = (-t0 / self.width).exp();
        line.samples.iter().map(move |s| {
            let d = line.normal.dot(c - s.pos);
            let m = (d - t0).round();
            if (d - t0 - m).abs() > 1e-6 || m.abs() > self.reach as f64 {
                return heaviside(d, self.width);
            }
            let h = 1.0 / (1.0 + first * self.shifts[(m as i64 + self.reach) as usize]);
            (h, h * (1.0 - h) / self.width)
        })
    }
}

/// Lines per parallel work item in sums over lines (fixed, so sums are reproducible).
pub const LINE_CHUNK: usize = 64;

/// Buffers [`FrameContext::line_jacobian_into`] reuses from one line to the next.
#[derive(Debug, Default)]
pub struct JacobianScratch {
    /// n·∂c/∂ξ of the last line.
    pub jn: Vec<f64>,
    /// ∂P/∂ξ of its rim point.
    surface: Vec<DVec3>,
}

impl FrameContext<'_> {
    /// The rim point of a line in camera-0 coordinates and its deformed preoperative position.
    fn rim_point(&self, line: &Line, state: &FitState, deformed: &[Vec<DVec3>]) -> (DVec3, DVec3) {
        let d = &deformed[line.structure];
        let pre = d[line.a as usize].lerp(d[line.b as usize], line.t);
        (state.affine.apply(pre), pre)
    }

    /// Where the line's contour point c is now: the deformed, posed rim point projected into
    /// the line's view at `level` (None behind the camera). `deformed` is the model's shape
    /// instance for `state`.
    pub fn contour_point(
        &self,
        line: &Line,
        state: &FitState,
        deformed: &[Vec<DVec3>],
        level: usize,
    ) -> Option<DVec2> {
        let (p, _) = self.rim_point(line, state, deformed);
        let c = state.intrinsics[line.view].project(self.cameras[line.view].to_camera(p))?;
        Some(pixel_at_scale(c, level_scale(level)))
    }

    /// E (eq. 4 on the lines) at `state`. Lines whose rim point leaves the view add nothing.
    pub fn energy(&self, lines: &[Line], state: &FitState, params: &EnergyParams) -> f64 {
        self.energy_with(lines, state, &self.model.deformed(&state.shape), params)
    }

    /// [`FrameContext::energy`] with the shape instance of `state` already at hand (blocks
    /// that do not move the shape evaluate many poses of one instance).
    pub fn energy_with(
        &self,
        lines: &[Line],
        state: &FitState,
        deformed: &[Vec<DVec3>],
        params: &EnergyParams,
    ) -> f64 {
        let table = HeavisideTable::new(params.heaviside_px, params.half_length);
        let line_energy = |line: &Line| {
            let Some(c) = self.contour_point(line, state, deformed, params.level) else {
                return 0.0;
            };
            line.samples
                .iter()
                .zip(table.of_line(line, c))
                .map(|(s, (h, _))| s.g_f as f64 * h + s.g_b as f64 * (1.0 - h))
                .sum::<f64>()
                * line.weight
        };
        // Fixed chunks summed in order: parallel, and the same sum on every run.
        lines
            .par_chunks(LINE_CHUNK)
            .with_min_len(crate::pool::min_split(lines.len().div_ceil(LINE_CHUNK), 1))
            .map(|chunk| chunk.iter().map(line_energy).sum::<f64>())
            .collect::<Vec<f64>>()
            .into_iter()
            .sum()
    }

    /// A line's contour point c now (as [`FrameContext::contour_point`]) and n·∂c/∂ξ: how the
    /// block's parameters move it along the line's normal. What both the Gauss–Newton step and
    /// the analytic gradient need of every line; None where c leaves the view.
    pub fn line_jacobian(
        &self,
        line: &Line,
        state: &FitState,
        deformed: &[Vec<DVec3>],
        block: Block,
        level: usize,
        rotation_centre: DVec3,
    ) -> Option<(DVec2, Vec<f64>)> {
        let mut scratch = JacobianScratch::default();
        let c = self.line_jacobian_into(
            line,
            state,
            deformed,
            block,
            level,
            rotation_centre,
            &mut scratch,
        )?;
        Some((c, scratch.jn))
    }

    /// [`FrameContext::line_jacobian`] with n·∂c/∂ξ left in `scratch.jn`: the steps take it
    /// for every line, reusing one scratch per chunk of lines (fresh vectors per line were a
    /// quarter of their time). None where c leaves the view (`scratch.jn` then undefined).
    #[allow(clippy::too_many_arguments)]
    pub fn line_jacobian_into(
        &self,
        line: &Line,
        state: &FitState,
        deformed: &[Vec<DVec3>],
        block: Block,
        level: usize,
        rotation_centre: DVec3,
        scratch: &mut JacobianScratch,
    ) -> Option<DVec2> {
        let c = self.contour_point(line, state, deformed, level)?;
        let cam = &self.cameras[line.view];
        let intr = &state.intrinsics[line.view];
        let (p, pre) = self.rim_point(line, state, deformed);
        let s = level_scale(level);
        let pc = cam.to_camera(p);
        // d pixel / d reference point = J_proj · R_m (eq. 10–11), at the line's level.
        let jr = cam.jacobian_ref_point_with(intr, p)?;
        let n = line.normal;
        let jn = &mut scratch.jn;
        jn.clear();
        match block {
            Block::Cameras(cameras) => {
                let ji = intr.jacobian_intrinsics(pc)?;
                jn.resize(5 * cameras, 0.0);
                for (k, o) in jn.iter_mut().skip(5 * line.view).take(5).enumerate() {
                    *o = n.x * (s * ji[0][k]) + n.y * (s * ji[1][k]);
                }
            }
            _ => {
                let weights = [(line.a, 1.0 - line.t), (line.b, line.t)];
                self.surface_jacobian_into(
                    line.structure,
                    &weights,
                    p,
                    pre,
                    state,
                    block,
                    rotation_centre,
                    &mut scratch.surface,
                );
                jn.extend(scratch.surface.iter().map(|v| {
                    let along_x = s * (jr[0][0] * v.x + jr[0][1] * v.y + jr[0][2] * v.z);
                    let along_y = s * (jr[1][0] * v.x + jr[1][1] * v.y + jr[1][2] * v.z);
                    n.x * along_x + n.y * along_y
                }));
            }
        }
        Some(c)
    }

    /// ∂E/∂ξ for a block, analytic.
    pub fn gradient(
        &self,
        lines: &[Line],
        state: &FitState,
        block: Block,
        params: &EnergyParams,
    ) -> Vec<f64> {
        self.gradient_with(
            lines,
            state,
            &self.model.deformed(&state.shape),
            block,
            params,
        )
    }

    /// [`FrameContext::gradient`] with the shape instance of `state` already at hand.
    pub fn gradient_with(
        &self,
        lines: &[Line],
        state: &FitState,
        deformed: &[Vec<DVec3>],
        block: Block,
        params: &EnergyParams,
    ) -> Vec<f64> {
        let rotation_centre = self.rotation_centre(state, deformed);
        let mut g = vec![0.0; block.size(self.model)];
        let table = HeavisideTable::new(params.heaviside_px, params.half_length);
        let mut scratch = JacobianScratch::default();
        for line in lines {
            let Some(c) = self.line_jacobian_into(
                line,
                state,
                deformed,
                block,
                params.level,
                rotation_centre,
                &mut scratch,
            ) else {
                continue;
            };
            let jn = &scratch.jn;
            // dE/d(normal displacement of c).
            let de: f64 = line
                .samples
                .iter()
                .zip(table.of_line(line, c))
                .map(|(s, (_, dh))| (s.g_f - s.g_b) as f64 * dh)
                .sum::<f64>()
                * line.weight;
            for (gk, jk) in g.iter_mut().zip(jn) {
                *gk += de * jk;
            }
        }
        g
    }
}

/// The correspondence lines of one step as a term of the objective: their energy (eq. 4 on the
/// lines), its analytic gradient, and Gauss–Newton normal equations that meet each line's
/// target shift with the certainty its 1D energy profile gives ([`target::line_target`]).
pub struct LineTerm<'a> {
    pub ctx: &'a FrameContext<'a>,
    pub lines: &'a [Line],
    pub params: EnergyParams,
}

impl ImageTerm for LineTerm<'_> {
    fn energy(&self, state: &FitState, deformed: &[Vec<DVec3>]) -> f64 {
        self.ctx
            .energy_with(self.lines, state, deformed, &self.params)
    }

    fn gradient(&self, state: &FitState, deformed: &[Vec<DVec3>], block: Block) -> Vec<f64> {
        self.ctx
            .gradient_with(self.lines, state, deformed, block, &self.params)
    }

    fn add_normal_equations(
        &self,
        state: &FitState,
        deformed: &[Vec<DVec3>],
        block: Block,
        eq: &mut NormalEquations,
    ) {
        let (ctx, ep) = (self.ctx, &self.params);
        let n = eq.size();
        let rotation_centre = ctx.rotation_centre(state, deformed);
        // Normal equations over lines, in fixed chunks in parallel, added up in order.
        let partial = |chunk: &[Line]| {
            let mut part = NormalEquations::zeros(n);
            let mut scratch = JacobianScratch::default();
            for line in chunk {
                let Some(c) = ctx.line_jacobian_into(
                    line,
                    state,
                    deformed,
                    block,
                    ep.level,
                    rotation_centre,
                    &mut scratch,
                ) else {
                    continue;
                };
                let jn = &scratch.jn;
                let (target, var) = target::line_target(line, c, ep);
                let w = line.weight / var;
                for r in 0..n {
                    part.b[r] += w * jn[r] * target;
                    for q in r..n {
                        part.h[(r, q)] += w * jn[r] * jn[q];
                    }
                }
            }
            part
        };
        let parts: Vec<NormalEquations> = self
            .lines
            .par_chunks(LINE_CHUNK)
            .with_min_len(crate::pool::min_split(
                self.lines.len().div_ceil(LINE_CHUNK),
                1,
            ))
            .map(partial)
            .collect();
        for part in parts {
            eq.h += part.h;
            eq.b += part.b;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::appearance::Appearance;
    use crate::fit::Model;
    use crate::fit::probability::ViewProbabilities;
    use crate::fit::state::apply_increment;
    use crate::geometry::Affine;

    /// The one-`exp`-per-line Heaviside equals the direct one on every sample, for contour
    /// points near the line and far off it (where e^(±t/w) overflows), on a slanted normal.
    #[test]
    fn heaviside_table_equals_the_direct_heaviside() {
        let normal = DVec2::new(0.6, -0.8);
        let centre = DVec2::new(101.3, 57.9);
        let samples = (-10..=10)
            .map(|k| Sample {
                pos: centre + normal * k as f64,
                pixel: 0,
                g_f: 0.0,
                g_b: 0.0,
                p_f: 0.0,
            })
            .collect();
        let line = Line::for_tests(normal, samples);
        for width in [0.5, 1.2, 3.0] {
            let table = HeavisideTable::new(width, 10);
            for shift in [-900.0, -30.0, -10.5, -2.25, 0.0, 0.3, 7.75, 12.0, 900.0] {
                let c = centre + normal * shift + normal.perp() * 0.4;
                for (s, (h, dh)) in line.samples.iter().zip(table.of_line(&line, c)) {
                    let (h0, dh0) = heaviside(normal.dot(c - s.pos), width);
                    assert!(
                        (h - h0).abs() <= 1e-12 && (dh - dh0).abs() <= 1e-12 / width,
                        "width {width}, shift {shift}: H {h} against {h0}, H' {dh} against {dh0}"
                    );
                }
            }
        }
    }

    /// Central differences of E (lines fixed) against the analytic gradient, for every block,
    /// at two pyramid levels, away from the truth so that the gradient is not small.
    #[test]
    fn gradients_match_central_differences() {
        let scene = crate::synth::one_small_frame();
        let appearance = Appearance::for_tests(&scene, 5);
        let model = Model::build(&scene).unwrap();
        let classes = crate::appearance::ClassMap::from_scene(&scene);
        let ctx = FrameContext::new(&model, &scene);
        let truth = scene.ground_truth.trajectory.as_ref().unwrap().frames[0].clone();
        let mut q = [0.0; 12];
        q.copy_from_slice(&truth.affine);
        let mut state = FitState {
            affine: Affine { q },
            shape: vec![0.0; model.shape.mode_count()],
            intrinsics: scene.cameras.iter().map(|c| c.intrinsics).collect(),
        };
        // Off the truth: shifted, a little shape, a little zoom.
        state.affine.q[9] += 2.0;
        state.affine.q[10] -= 1.5;
        for (k, w) in state.shape.iter_mut().enumerate().take(3) {
            *w = (k as f64 - 1.0) * 0.5 * model.shape.pca.sigma_mm[k];
        }
        state.intrinsics[1].fx *= 1.02;
        let mut checked = 0;
        for level in [0usize, 1] {
            let mut views: Vec<ViewProbabilities> = (0..scene.cameras.len())
                .map(|c| ViewProbabilities::new(scene.frame(c, 0).unwrap(), 2, classes.len()))
                .collect();
            // At level 0 the rims are thinned: kept lines weigh for the ones left out.
            let ep = EnergyParams {
                level,
                max_lines_per_structure: if level == 0 { 16 } else { 0 },
                ..EnergyParams::default()
            };
            let lines = ctx.build_lines(&state, &mut views, Some(&appearance), &ep);
            assert!(lines.len() > 40, "level {level}: {} lines", lines.len());
            assert_eq!(
                lines.iter().any(|l| l.weight > 1.0),
                level == 0,
                "level {level}: thinned lines weigh more than 1"
            );
            assert!(
                lines.iter().any(|l| l.view == 1) && lines.iter().any(|l| l.structure == 1),
                "lines in both views and on the tumour"
            );
            for block in [Block::Rigid, Block::Affine, Block::Shape, Block::Cameras(2)] {
                let g = ctx.gradient(&lines, &state, block, &ep);
                let centre = ctx.model_centre(&model.deformed(&state.shape));
                let n = block.size(&model);
                let steps: Vec<f64> = (0..n)
                    .map(|k| match block {
                        Block::Rigid => {
                            if k < 3 {
                                1e-5
                            } else {
                                1e-3
                            }
                        }
                        Block::Affine => {
                            if k < 9 {
                                1e-5
                            } else {
                                1e-3
                            }
                        }
                        Block::Shape => 1e-3,
                        Block::Cameras(_) => [1e-2, 1e-2, 1e-2, 1e-2, 1e-5][k % 5],
                    })
                    .collect();
                let fd: Vec<f64> = (0..n)
                    .map(|k| {
                        let mut d = vec![0.0; n];
                        d[k] = steps[k];
                        let plus =
                            ctx.energy(&lines, &apply_increment(&state, block, &d, centre), &ep);
                        d[k] = -steps[k];
                        let minus =
                            ctx.energy(&lines, &apply_increment(&state, block, &d, centre), &ep);
                        (plus - minus) / (2.0 * steps[k])
                    })
                    .collect();
                let scale = fd.iter().map(|v| v.abs()).fold(0.0, f64::max);
                assert!(scale > 1e-6, "{block:?}: gradient vanishes");
                for k in 0..n {
                    let err = (g[k] - fd[k]).abs();
                    assert!(
                        err <= 2e-3 * (fd[k].abs() + 0.01 * scale),
                        "level {level} {block:?} param {k}: analytic {} vs differences {}",
                        g[k],
                        fd[k]
                    );
                    checked += 1;
                }
            }
        }
        assert!(checked > 50);
    }
}
