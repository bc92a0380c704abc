//! The energy of eq. 4 on sparse correspondence lines, and its analytic gradient (eq. 13–17,
//! Tables II and III).
//!
//! For each view and visible structure, the rim of the posed mesh (edges between a face that
//! faces the camera and one that does not) is projected; rim points that the raster confirms as
//! the boundary of the structure's visible region (front-most inside, not the structure just
//! outside) each get a line along their image normal. Along a line, sample s at position x_s
//! has signed distance d_s = n·(c − x_s) to the projected rim point c (positive inside), and
//! contributes g_f H(d_s) + g_b (1 − H(d_s)) with g = −log p (eq. 9) and a logistic
//! Heaviside. The line set is fixed while it is evaluated, so E is smooth in T, W and π, and
//! ∂E/∂ξ = Σ (g_f − g_b) H'(d_s) n·∂c/∂ξ is checked against central differences in the tests.

use super::model::Model;
use super::probability::ViewProbabilities;
use crate::appearance::Appearance;
use crate::geometry::{Affine, Camera, Intrinsics};
use crate::render::raster::{RasterOptions, ViewRaster, rasterize};
use glam::{DVec2, DVec3};
use rayon::prelude::*;

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

/// Energy settings at one pyramid level.
#[derive(Debug, Clone, Copy)]
pub struct EnergyParams {
    pub level: usize,
    /// Samples on each side of the rim point (level pixels).
    pub half_length: usize,
    /// Logistic Heaviside width (level pixels).
    pub heaviside_px: f64,
    /// Probabilities are kept inside [floor, 1 − floor] before the logs.
    pub probability_floor: f32,
}

impl Default for EnergyParams {
    fn default() -> Self {
        Self {
            level: 0,
            half_length: 10,
            heaviside_px: 1.2,
            probability_floor: 0.02,
        }
    }
}

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
}

/// Scale of a pyramid level relative to full resolution.
pub fn level_scale(level: usize) -> f64 {
    1.0 / (1u32 << level) as f64
}

/// Full-resolution pixel → level pixel.
pub fn to_level(p: DVec2, s: f64) -> DVec2 {
    (p + DVec2::splat(0.5)) * s - DVec2::splat(0.5)
}

/// A camera as seen at a pyramid level.
pub fn level_camera(
    camera: &Camera,
    intrinsics: &Intrinsics,
    level: usize,
    size: (usize, usize),
) -> Camera {
    let s = level_scale(level);
    let mut c = camera.clone();
    c.intrinsics = Intrinsics {
        fx: intrinsics.fx * s,
        fy: intrinsics.fy * s,
        cx: (intrinsics.cx + 0.5) * s - 0.5,
        cy: (intrinsics.cy + 0.5) * s - 0.5,
        ..*intrinsics
    };
    c.width = size.0 as u32;
    c.height = size.1 as u32;
    c
}

fn heaviside(d: f64, width: f64) -> (f64, f64) {
    let h = 1.0 / (1.0 + (-d / width).exp());
    (h, h * (1.0 - h) / width)
}

/// Lines per parallel work item in sums over lines (fixed, so sums are reproducible).
pub const LINE_CHUNK: usize = 64;

/// Everything the energy needs about one frame.
pub struct FrameContext<'a> {
    pub model: &'a Model,
    pub cameras: &'a [Camera],
    /// Forest class of each structure (None for hidden ones).
    pub class_of: Vec<Option<usize>>,
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
        }
    }
}

impl FrameContext<'_> {
    /// The structures with an image term (a forest class), in the order their render objects
    /// take in the visibility rasters: a raster's object id `o` is structure `imaged()[o]`.
    pub fn imaged(&self) -> Vec<usize> {
        (0..self.model.structures.len())
            .filter(|&i| self.class_of[i].is_some())
            .collect()
    }

    /// Builds the lines of every view at the current state and fills their probabilities.
    pub fn build_lines(
        &self,
        state: &FitState,
        views: &mut [ViewProbabilities],
        appearance: &Appearance,
        params: &EnergyParams,
    ) -> Vec<Line> {
        self.build_lines_and_rasters(state, views, appearance, params)
            .0
    }

    /// [`FrameContext::build_lines`], also returning each view's visibility raster of the
    /// visible structures, one level coarser than `params.level` (the stereo term looks its
    /// surface points up there instead of rendering again).
    pub fn build_lines_and_rasters(
        &self,
        state: &FitState,
        views: &mut [ViewProbabilities],
        appearance: &Appearance,
        params: &EnergyParams,
    ) -> (Vec<Line>, Vec<ViewRaster>) {
        let deformed = self.model.deformed(&state.shape);
        let posed = self.model.posed(&state.affine, &deformed);
        let visible = self.imaged();
        // Views are independent: build their lines in parallel, then concatenate in view order.
        let per_view: Vec<(Vec<Line>, ViewRaster)> = views
            .par_iter_mut()
            .zip(self.cameras.par_iter())
            .enumerate()
            .map(|(m, (view, cam))| {
                let size = view.size(params.level);
                let lcam = level_camera(cam, &state.intrinsics[m], params.level, size);
                let objects = self.model.objects(&posed, &visible);
                // Visibility is judged one level coarser: a quarter of the pixels, and rim points
                // only need "this structure just inside, something else just outside".
                let vis_size = ((size.0 / 2).max(1), (size.1 / 2).max(1));
                let vis_cam = level_camera(cam, &state.intrinsics[m], params.level + 1, vis_size);
                let raster = super::profile::time(super::profile::Phase::Raster, || {
                    rasterize(&vis_cam, &objects, &RasterOptions::default())
                });
                let (vw, vh) = (vis_size.0 as i64, vis_size.1 as i64);
                let centre = cam.extrinsics.center_mm();
                let (w, h) = (size.0 as i64, size.1 as i64);
                let mut taken = std::collections::HashSet::new();
                let mut view_lines = Vec::new();
                for (oi, &si) in visible.iter().enumerate() {
                    let st = &self.model.structures[si];
                    let verts = &posed[si];
                    // Which faces look at the camera: once per face, not once per edge side.
                    let facing: Vec<bool> = st
                        .faces
                        .iter()
                        .map(|f| {
                            let [a, b, c] = f.map(|k| verts[k as usize]);
                            (b - a).cross(c - a).dot(a - centre) < 0.0
                        })
                        .collect();
                    for e in st.edges.iter().filter(|e| !e.boundary) {
                        let (f0, f1) = (facing[e.faces[0] as usize], facing[e.faces[1] as usize]);
                        if f0 == f1 {
                            continue;
                        }
                        let front = if f0 { e.faces[0] } else { e.faces[1] };
                        let third = st.faces[front as usize]
                            .iter()
                            .copied()
                            .find(|&k| k != e.a && k != e.b)
                            .unwrap_or(e.a);
                        let (Some(pa), Some(pb), Some(px)) = (
                            lcam.project(verts[e.a as usize]),
                            lcam.project(verts[e.b as usize]),
                            lcam.project(verts[third as usize]),
                        ) else {
                            continue;
                        };
                        let t = 0.5;
                        let p = verts[e.a as usize].lerp(verts[e.b as usize], t);
                        let Some(c) = lcam.project(p) else { continue };
                        let dir = pb - pa;
                        if dir.length() < 1e-6 {
                            continue;
                        }
                        let mut n = dir.perp().normalize();
                        if n.dot(px - c) > 0.0 {
                            n = -n;
                        }
                        // Confirm the rim point bounds the structure's visible region here.
                        let pick = |q: DVec2| -> Option<usize> {
                            let (x, y) = (q.x.round() as i64, q.y.round() as i64);
                            (x >= 0 && y >= 0 && x < w && y < h).then(|| (y * w + x) as usize)
                        };
                        let pick_vis = |q: DVec2| -> Option<usize> {
                            let q = (q + DVec2::splat(0.5)) * 0.5 - DVec2::splat(0.5);
                            let (x, y) = (q.x.round() as i64, q.y.round() as i64);
                            (x >= 0 && y >= 0 && x < vw && y < vh).then(|| (y * vw + x) as usize)
                        };
                        let (Some(inside), Some(outside)) =
                            (pick_vis(c - n * 3.0), pick_vis(c + n * 3.0))
                        else {
                            continue;
                        };
                        if raster.object.data[inside] as usize != oi
                            || raster.object.data[outside] as usize == oi
                        {
                            continue;
                        }
                        let depth = lcam.to_camera(p).z;
                        if (raster.depth_mm.data[inside] as f64 - depth).abs() > 0.08 * depth {
                            continue;
                        }
                        // One line per 2×2 cell: neighbouring rim points add little but cost.
                        let cell = ((c.x / 2.0) as i64, (c.y / 2.0) as i64, si);
                        if !taken.insert(cell) {
                            continue;
                        }
                        let l = params.half_length as i64;
                        let samples: Vec<Sample> = (-l..=l)
                            .filter_map(|k| {
                                let pos = c + n * k as f64;
                                pick(pos).map(|i| Sample {
                                    pos,
                                    pixel: i as u32,
                                    g_f: 0.0,
                                    g_b: 0.0,
                                    p_f: 0.0,
                                })
                            })
                            .collect();
                        if samples.len() < params.half_length {
                            continue;
                        }
                        view_lines.push(Line {
                            view: m,
                            structure: si,
                            a: e.a,
                            b: e.b,
                            t,
                            normal: n,
                            samples,
                        });
                    }
                }
                let pixels: Vec<u32> = view_lines
                    .iter()
                    .flat_map(|l| l.samples.iter().map(|s| s.pixel))
                    .collect();
                super::profile::time(super::profile::Phase::Probabilities, || {
                    view.ensure(appearance, params.level, &pixels)
                });
                for line in &mut view_lines {
                    let class = self.class_of[line.structure].unwrap_or(0);
                    for s in &mut line.samples {
                        let p = view
                            .get(params.level, s.pixel, class)
                            .clamp(params.probability_floor, 1.0 - params.probability_floor);
                        s.p_f = p;
                        s.g_f = -p.ln();
                        s.g_b = -(1.0 - p).ln();
                    }
                }
                (view_lines, raster)
            })
            .collect();
        let (lines, rasters): (Vec<Vec<Line>>, Vec<ViewRaster>) = per_view.into_iter().unzip();
        (lines.into_iter().flatten().collect(), rasters)
    }

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
        Some(to_level(c, level_scale(level)))
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
        let line_energy = |line: &Line| {
            let Some(c) = self.contour_point(line, state, deformed, params.level) else {
                return 0.0;
            };
            line.samples
                .iter()
                .map(|s| {
                    let (h, _) = heaviside(line.normal.dot(c - s.pos), params.heaviside_px);
                    s.g_f as f64 * h + s.g_b as f64 * (1.0 - h)
                })
                .sum::<f64>()
        };
        // Fixed chunks summed in order: parallel, and the same sum on every run.
        lines
            .par_chunks(LINE_CHUNK)
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
        let c = self.contour_point(line, state, deformed, level)?;
        let j = self.point_jacobian(line, state, deformed, block, level, rotation_centre)?;
        let jn = j
            .iter()
            .map(|jk| line.normal.x * jk[0] + line.normal.y * jk[1])
            .collect();
        Some((c, jn))
    }

    /// ∂c/∂ξ (2 × block size) of a line's rim point, at the line's level. `rotation_centre`
    /// is [`FrameContext::rotation_centre`] of `state` (rigid blocks turn about it).
    fn point_jacobian(
        &self,
        line: &Line,
        state: &FitState,
        deformed: &[Vec<DVec3>],
        block: Block,
        level: usize,
        rotation_centre: DVec3,
    ) -> Option<Vec<[f64; 2]>> {
        let cam = &self.cameras[line.view];
        let intr = &state.intrinsics[line.view];
        let (p, pre) = self.rim_point(line, state, deformed);
        let s = level_scale(level);
        let pc = cam.to_camera(p);
        let jp = intr.jacobian_point(pc)?;
        // d pixel / d reference point = J_proj · R_m.
        let r = cam.extrinsics.rotation;
        let jref = |v: DVec3| -> [f64; 2] {
            let w = r * v;
            [
                s * (jp[0][0] * w.x + jp[0][1] * w.y + jp[0][2] * w.z),
                s * (jp[1][0] * w.x + jp[1][1] * w.y + jp[1][2] * w.z),
            ]
        };
        Some(match block {
            Block::Cameras(n) => {
                let mut out = vec![[0.0; 2]; 5 * n];
                let ji = intr.jacobian_intrinsics(pc)?;
                for (k, o) in out.iter_mut().skip(5 * line.view).take(5).enumerate() {
                    *o = [s * ji[0][k], s * ji[1][k]];
                }
                out
            }
            _ => {
                let weights = [(line.a, 1.0 - line.t), (line.b, line.t)];
                self.surface_jacobian(
                    line.structure,
                    &weights,
                    p,
                    pre,
                    state,
                    block,
                    rotation_centre,
                )
                .into_iter()
                .map(jref)
                .collect()
            }
        })
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
        match block {
            Block::Affine => {
                let j = Affine::jacobian(pre);
                (0..12)
                    .map(|k| DVec3::new(j[0][k], j[1][k], j[2][k]))
                    .collect()
            }
            Block::Rigid => {
                // Increments about the current pose: P = R(δω)(P₀ − c₀) + c₀ + δt, where P₀ is
                // the posed point; so ∂P/∂δω = −[P₀ − c₀]×, ∂P/∂δt = I (c₀: the model centre).
                let q = posed - rotation_centre;
                let mut out = Vec::with_capacity(6);
                for k in 0..3 {
                    let mut e = DVec3::ZERO;
                    e[k] = 1.0;
                    out.push(e.cross(q));
                }
                for k in 0..3 {
                    let mut e = DVec3::ZERO;
                    e[k] = 1.0;
                    out.push(e);
                }
                out
            }
            Block::Shape => {
                let lin = state.affine.linear();
                let part = self.model.structures[structure].part;
                (0..self.model.shape.mode_count())
                    .map(|k| {
                        let u = self.model.shape.mode_part(k, part);
                        lin * weights
                            .iter()
                            .map(|&(v, w)| u[v as usize] * w)
                            .sum::<DVec3>()
                    })
                    .collect()
            }
            Block::Cameras(_) => Vec::new(),
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

    /// ∂E/∂ξ for a block, analytic.
    pub fn gradient(
        &self,
        lines: &[Line],
        state: &FitState,
        block: Block,
        params: &EnergyParams,
    ) -> Vec<f64> {
        let deformed = self.model.deformed(&state.shape);
        let rotation_centre = self.rotation_centre(state, &deformed);
        let mut g = vec![0.0; block.size(self.model)];
        for line in lines {
            let Some((c, jn)) =
                self.line_jacobian(line, state, &deformed, block, params.level, rotation_centre)
            else {
                continue;
            };
            // dE/d(normal displacement of c).
            let de: f64 = line
                .samples
                .iter()
                .map(|s| {
                    let (_, dh) = heaviside(line.normal.dot(c - s.pos), params.heaviside_px);
                    (s.g_f - s.g_b) as f64 * dh
                })
                .sum();
            for (gk, jk) in g.iter_mut().zip(&jn) {
                *gk += de * jk;
            }
        }
        g
    }
}

/// Applies a block increment to a state.
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::appearance::Appearance;
    use crate::synth::{SynthOptions, memory_scene};

    /// Central differences of E (lines fixed) against the analytic gradient, for every block,
    /// at two pyramid levels, away from the truth so that the gradient is not small.
    #[test]
    fn gradients_match_central_differences() {
        let scene = memory_scene(&SynthOptions {
            frames: 1,
            width: 240,
            height: 136,
            noise: 0.02,
            ..SynthOptions::default()
        })
        .unwrap();
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
            let ep = EnergyParams {
                level,
                ..EnergyParams::default()
            };
            let lines = ctx.build_lines(&state, &mut views, &appearance, &ep);
            assert!(lines.len() > 40, "level {level}: {} lines", lines.len());
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
