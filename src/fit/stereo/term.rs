//! The stereo depth term: each triangulated match pulls the model surface it was seen on
//! along that surface's normal (point-to-plane, Huber-robust), weighted by its own depth
//! uncertainty; the camera block sees the re-triangulation's derivative.

use super::StereoParams;
use super::matching::{StereoMatch, StereoSet, triangulate};
use crate::fit::context::FrameContext;
use crate::fit::objective::{ImageTerm, NormalEquations};
use crate::fit::state::{Block, FitState};
use crate::geometry::{Camera, Intrinsics};
use glam::DVec3;
use rayon::prelude::*;

/// A triangulated match with the plane it pulls: the unit normal of its model face, held
/// fixed while one step is taken (point-to-plane), and the residual's σ along it (mm).
#[derive(Debug, Clone, Copy)]
struct Anchor {
    target_mm: DVec3,
    normal: DVec3,
    sigma_mm: f64,
}

/// The stereo term of one set of matches at one state: triangulations, residuals, energy and
/// normal equations.
pub struct StereoTerm<'a> {
    ctx: &'a FrameContext<'a>,
    cameras: &'a [Camera],
    matches: &'a [StereoMatch],
    anchors: Vec<Option<Anchor>>,
    /// The intrinsics the anchors' targets were triangulated with.
    intrinsics: Vec<Intrinsics>,
    params: StereoParams,
}

impl<'a> StereoTerm<'a> {
    /// Triangulates every match with the intrinsics of `state` (reusing the set's points when
    /// they are the ones measured with) and takes its face's normal there; `deformed` is the
    /// shape instance of `state`.
    pub fn new(
        ctx: &'a FrameContext<'a>,
        set: &'a StereoSet,
        state: &FitState,
        deformed: &[Vec<DVec3>],
        params: StereoParams,
    ) -> Self {
        let same = state.intrinsics == set.intrinsics;
        let matches = set.matches.as_slice();
        let anchors = matches
            .iter()
            .zip(&set.points)
            .map(|(m, p)| {
                let p = if same {
                    (*p)?
                } else {
                    triangulate(ctx.cameras, &state.intrinsics, m)?
                };
                let posed = Self::face(m, deformed)?.map(|v| state.affine.apply(v));
                let normal = (posed[1] - posed[0])
                    .cross(posed[2] - posed[0])
                    .try_normalize()?;
                // The match is uncertain along the ray: its share along the normal, kept from
                // vanishing at grazing angles where the model itself is least sure.
                Some(Anchor {
                    target_mm: p.target_mm,
                    normal,
                    sigma_mm: m.sigma_mm * normal.dot(p.ray).abs().max(0.5),
                })
            })
            .collect();
        Self {
            ctx,
            cameras: ctx.cameras,
            matches,
            anchors,
            intrinsics: state.intrinsics.clone(),
            params,
        }
    }

    /// The deformed preoperative vertices of a match's face.
    fn face(m: &StereoMatch, deformed: &[Vec<DVec3>]) -> Option<[DVec3; 3]> {
        let d = deformed.get(m.structure)?;
        let [Some(a), Some(b), Some(c)] = m.vertices.map(|(k, _)| d.get(k as usize).copied())
        else {
            return None;
        };
        Some([a, b, c])
    }

    /// Match i's triangulated point at `intrinsics` (the anchor's when they are the same).
    fn target(&self, i: usize, intrinsics: &[Intrinsics]) -> Option<DVec3> {
        let anchor = self.anchors[i]?;
        if intrinsics == self.intrinsics.as_slice() {
            Some(anchor.target_mm)
        } else {
            triangulate(self.cameras, intrinsics, &self.matches[i]).map(|p| p.target_mm)
        }
    }

    /// Residual along the normal (mm), its σ (mm), the posed model point, its deformed
    /// preoperative position and the normal.
    fn residual(
        &self,
        i: usize,
        state: &FitState,
        deformed: &[Vec<DVec3>],
    ) -> Option<(f64, f64, DVec3, DVec3, DVec3)> {
        let m = &self.matches[i];
        let anchor = self.anchors[i]?;
        let target = self.target(i, &state.intrinsics)?;
        let [a, b, c] = Self::face(m, deformed)?;
        let pre = a * m.vertices[0].1 + b * m.vertices[1].1 + c * m.vertices[2].1;
        let posed = state.affine.apply(pre);
        Some((
            anchor.normal.dot(posed - target),
            anchor.sigma_mm,
            posed,
            pre,
            anchor.normal,
        ))
    }

    /// ∂r/∂π of match i for the corrected intrinsics of `cameras` cameras, five per camera:
    /// r = n·(P − X(π)), and X's derivative is taken by central differences of the
    /// triangulation, which has no convenient closed form under distortion. Only camera 0 and
    /// the match's partner move X.
    fn camera_row(
        &self,
        i: usize,
        cameras: usize,
        state: &FitState,
        normal: DVec3,
    ) -> Option<Vec<f64>> {
        let m = &self.matches[i];
        let mut row = vec![0.0; 5 * cameras];
        for c in [0, m.view] {
            let base = state.intrinsics.get(c)?.corrected();
            for k in 0..5 {
                // Steps: 1e-4 of the focal length for fx, fy, cx, cy (px); 1e-5 for k1.
                let h = if k == 4 { 1e-5 } else { 1e-4 * base[0] };
                let at = |d: f64| {
                    let mut v = base;
                    v[k] += d;
                    let mut intr = state.intrinsics.clone();
                    intr[c] = intr[c].with_corrected(v);
                    triangulate(self.cameras, &intr, m).map(|p| p.target_mm)
                };
                let (plus, minus) = (at(h)?, at(-h)?);
                if let Some(r) = row.get_mut(5 * c + k) {
                    *r = -normal.dot(plus - minus) / (2.0 * h);
                }
            }
        }
        Some(row)
    }

    /// Huber weight of a normalised residual.
    fn robust(&self, z: f64) -> f64 {
        if z.abs() <= self.params.huber {
            1.0
        } else {
            self.params.huber / z.abs()
        }
    }

    /// Calls `f(∂r/∂ξ, r, weight)` for every usable match, where weight is the IRLS weight
    /// of the Huber energy (its gradient is weight · r · ∂r/∂ξ).
    fn for_each_row(
        &self,
        state: &FitState,
        deformed: &[Vec<DVec3>],
        block: Block,
        mut f: impl FnMut(&[f64], f64, f64),
    ) {
        self.for_each_joint_row(state, deformed, &[block], |row, r, w| f(row, r, w));
    }

    /// [`StereoTerm::for_each_row`] over several blocks at once: each match's row is its
    /// rows for `blocks` in turn, side by side (a match without a row in one block is left
    /// out). What the joint information of the fit (`fit::information`) needs.
    pub fn for_each_joint_row(
        &self,
        state: &FitState,
        deformed: &[Vec<DVec3>],
        blocks: &[Block],
        mut f: impl FnMut(&[f64], f64, f64),
    ) {
        let ctx = self.ctx;
        let rotation_centre = ctx.rotation_centre(state, deformed);
        // Each match's row in parallel (a camera block's row is 20 triangulations), handed to
        // `f` in the matches' order: sums over them equal a serial loop's, bit for bit.
        let rows: Vec<Option<(Vec<f64>, f64, f64)>> = (0..self.matches.len())
            .into_par_iter()
            .map(|i| {
                let (r, sigma, posed, pre, normal) = self.residual(i, state, deformed)?;
                let m = &self.matches[i];
                let mut row = Vec::new();
                for &block in blocks {
                    if let Block::Cameras(n) = block {
                        row.extend(self.camera_row(i, n, state, normal)?);
                    } else {
                        row.extend(
                            ctx.surface_jacobian(
                                m.structure,
                                &m.vertices,
                                posed,
                                pre,
                                state,
                                block,
                                rotation_centre,
                            )
                            .iter()
                            .map(|c| normal.dot(*c)),
                        );
                    }
                }
                let w = self.params.weight * self.robust(r / sigma) / (sigma * sigma);
                Some((row, r, w))
            })
            .collect();
        for (row, r, w) in rows.into_iter().flatten() {
            f(&row, r, w);
        }
    }
}

impl ImageTerm for StereoTerm<'_> {
    /// The term's energy: weight × Σ Huber(r/σ).
    fn energy(&self, state: &FitState, deformed: &[Vec<DVec3>]) -> f64 {
        let c = self.params.huber;
        (0..self.matches.len())
            .filter_map(|i| self.residual(i, state, deformed))
            .map(|(r, sigma, ..)| {
                let z = (r / sigma).abs();
                if z <= c {
                    0.5 * z * z
                } else {
                    c * z - 0.5 * c * c
                }
            })
            .sum::<f64>()
            * self.params.weight
    }

    fn gradient(&self, state: &FitState, deformed: &[Vec<DVec3>], block: Block) -> Vec<f64> {
        let mut g = vec![0.0; block.size(self.ctx.model)];
        self.for_each_row(state, deformed, block, |row, r, w| {
            for (gk, jk) in g.iter_mut().zip(row) {
                *gk += w * r * jk;
            }
        });
        g
    }

    /// The IRLS normal equations of the Huber energy.
    fn add_normal_equations(
        &self,
        state: &FitState,
        deformed: &[Vec<DVec3>],
        block: Block,
        eq: &mut NormalEquations,
    ) {
        let n = eq.size();
        let (h, b) = (&mut eq.h, &mut eq.b);
        self.for_each_row(state, deformed, block, |row, r, w| {
            for i in 0..n {
                b[i] -= w * row[i] * r;
                for j in i..n {
                    h[(i, j)] += w * row[i] * row[j];
                }
            }
        });
    }
}
