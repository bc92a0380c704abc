//! Building the correspondence lines of a frame at the current state: the rim of every
//! visible structure projected into every view, each rim point confirmed against a visibility
//! raster (the structure front-most just inside, something else just outside), one line per
//! 2×2 cell along the rim's image normal, and the forest's probabilities on its samples.

use super::{EnergyParams, Line, Sample};
use crate::appearance::Appearance;
use crate::fit::context::FrameContext;
use crate::fit::probability::ViewProbabilities;
use crate::fit::state::FitState;
use crate::render::raster::{RasterOptions, ViewRaster, rasterize};
use glam::DVec2;
use rayon::prelude::*;

impl FrameContext<'_> {
    /// Builds the lines of every view at the current state and fills their probabilities.
    pub fn build_lines(
        &self,
        state: &FitState,
        views: &mut [ViewProbabilities],
        appearance: Option<&Appearance>,
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
        appearance: Option<&Appearance>,
        params: &EnergyParams,
    ) -> (Vec<Line>, Vec<ViewRaster>) {
        crate::fit::profile::count(crate::fit::profile::Count::LineBuilds, 1);
        let deformed = self.model.deformed(&state.shape);
        let posed = self.model.posed(&state.affine, &deformed);
        let visible = self.imaged();
        // Views are independent: build their lines in parallel, then concatenate in view order.
        let per_view: Vec<(Vec<Line>, ViewRaster)> = views
            .par_iter()
            .zip(self.cameras.par_iter())
            .enumerate()
            .map(|(m, (view, cam))| {
                let size = view.size(params.level);
                let lcam = cam.at_level(&state.intrinsics[m], params.level, size);
                let objects = self.model.objects(&posed, &visible);
                // Visibility is judged one level coarser: a quarter of the pixels, and rim points
                // only need "this structure just inside, something else just outside".
                let vis_size = ((size.0 / 2).max(1), (size.1 / 2).max(1));
                let vis_cam = cam.at_level(&state.intrinsics[m], params.level + 1, vis_size);
                let raster = crate::fit::profile::time(crate::fit::profile::Phase::Raster, || {
                    rasterize(
                        &vis_cam,
                        &objects,
                        &RasterOptions {
                            cull_back_faces: true,
                            ..RasterOptions::default()
                        },
                    )
                });
                let (vw, vh) = (vis_size.0 as i64, vis_size.1 as i64);
                let centre = cam.extrinsics.center_mm();
                let (w, h) = (size.0 as i64, size.1 as i64);
                let mut taken = std::collections::HashSet::new();
                let mut view_lines = Vec::new();
                let rim_started = crate::fit::profile::enabled().then(std::time::Instant::now);
                for (oi, &si) in visible.iter().enumerate() {
                    let first_line = view_lines.len();
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
                        let (Some(inside), Some(outside)) = (
                            pick_vis(c - n * params.rim_check_px),
                            pick_vis(c + n * params.rim_check_px),
                        ) else {
                            continue;
                        };
                        if raster.object.data[inside] as usize != oi
                            || raster.object.data[outside] as usize == oi
                        {
                            continue;
                        }
                        let depth = lcam.to_camera(p).z;
                        if (raster.depth_mm.data[inside] as f64 - depth).abs()
                            > params.rim_depth_tolerance * depth
                        {
                            continue;
                        }
                        // One line per cell: neighbouring rim points add little but cost.
                        let cell = (
                            (c.x / params.line_cell_px) as i64,
                            (c.y / params.line_cell_px) as i64,
                            si,
                        );
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
                            weight: 1.0,
                        });
                    }
                    thin_evenly(&mut view_lines, first_line, params.max_lines_per_structure);
                }
                if let Some(t) = rim_started {
                    crate::fit::profile::add(crate::fit::profile::Phase::Rim, t.elapsed());
                }
                (view_lines, raster)
            })
            .collect();
        let (mut lines, rasters): (Vec<Vec<Line>>, Vec<ViewRaster>) = per_view.into_iter().unzip();
        // One view per thread, each view's own loops kept on its thread (`serially`): with
        // nested parallel loops a thread waiting on its view's work picked up the other view
        // whole, and the two ran one after the other in about a third of frames. The views'
        // feature tables are filled serially anyway, so one view per core is the split that
        // uses both (4703 at 960×540: 2.5–2.8 ms a view alone, 2.6–4.1 ms for both at once).
        crate::fit::profile::time(crate::fit::profile::Phase::Probabilities, || {
            views
                .par_iter_mut()
                .zip(lines.par_iter())
                .for_each(|(view, view_lines)| {
                    let pixels: Vec<u32> = view_lines
                        .iter()
                        .flat_map(|l| l.samples.iter().map(|s| s.pixel))
                        .collect();
                    crate::pool::serially(|| view.ensure(appearance, params.level, &pixels));
                });
        });
        lines
            .par_iter_mut()
            .zip(views.par_iter())
            .for_each(|(view_lines, view)| {
                for line in view_lines.iter_mut() {
                    let class = self.class_of[line.structure].unwrap_or(0);
                    for s in &mut line.samples {
                        // A highlight shows the light, not the tissue: undecided.
                        let p = if view.is_specular(params.level, s.pixel) {
                            0.5
                        } else {
                            view.get(params.level, s.pixel, class)
                        }
                        .clamp(params.probability_floor, 1.0 - params.probability_floor);
                        s.p_f = p;
                        s.g_f = -p.ln();
                        s.g_b = -(1.0 - p).ln();
                    }
                }
            });
        (lines.into_iter().flatten().collect(), rasters)
    }
}

/// Keeps at most `budget` of `lines[first..]` (one structure's lines in one view; 0: all),
/// spread evenly by their contour points' angle around the lines' mean, each kept line
/// weighing for the lines it stands for (`count / kept` in all). The rim's edges come in the
/// mesh's order, which says nothing of where they lie; sorted by angle, every `count / budget`-th
/// line is a stratified sample of the contour, concave dents included.
fn thin_evenly(lines: &mut Vec<super::Line>, first: usize, budget: usize) {
    let count = lines.len() - first;
    if budget == 0 || count <= budget {
        return;
    }
    let centre_of = |l: &super::Line| l.samples[l.samples.len() / 2].pos;
    let mean = lines[first..]
        .iter()
        .map(centre_of)
        .fold(DVec2::ZERO, |a, p| a + p)
        / count as f64;
    let mut order: Vec<(f64, usize)> = lines[first..]
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let d = centre_of(l) - mean;
            (d.y.atan2(d.x), i)
        })
        .collect();
    order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    // The k-th kept line is the middle one of the k-th of `budget` equal runs of the order.
    let mut keep: Vec<usize> = (0..budget)
        .map(|k| order[((2 * k + 1) * count) / (2 * budget)].1)
        .collect();
    keep.sort_unstable();
    let weight = count as f64 / budget as f64;
    let mut kept: Vec<super::Line> = Vec::with_capacity(budget);
    let mut tail = lines.split_off(first).into_iter().enumerate();
    for &k in &keep {
        for (i, mut line) in tail.by_ref() {
            if i == k {
                line.weight *= weight;
                kept.push(line);
                break;
            }
        }
    }
    lines.extend(kept);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::lines::{Line, Sample};

    /// A line whose middle sample lies at `at` (what the thinning sorts by).
    fn line_at(at: DVec2, structure: usize) -> Line {
        let mut line = Line::for_tests(
            DVec2::X,
            (-2..=2)
                .map(|k| Sample {
                    pos: at + DVec2::X * k as f64,
                    pixel: 0,
                    g_f: 0.0,
                    g_b: 0.0,
                    p_f: 0.0,
                })
                .collect(),
        );
        line.structure = structure;
        line
    }

    /// 200 lines round a circle, in a scrambled order (as a mesh's edges come), thinned to
    /// 50: the kept lines weigh 200 in all, and no two neighbours round the circle lie more
    /// than one kept line's share apart; the structure before them is left alone, and a budget
    /// of 0 or one the rim does not exceed keeps every line at weight 1.
    #[test]
    fn thinning_keeps_the_total_weight_and_spreads_the_lines_evenly() {
        let angle = |i: usize| (i * 37 % 200) as f64 * std::f64::consts::TAU / 200.0;
        let mut lines: Vec<Line> = (0..10)
            .map(|i| line_at(DVec2::splat(i as f64), 0))
            .collect();
        lines.extend((0..200).map(|i| {
            line_at(
                DVec2::new(300.0 + 80.0 * angle(i).cos(), 200.0 + 80.0 * angle(i).sin()),
                1,
            )
        }));
        let untouched = lines.clone();
        for budget in [0, 200, 500] {
            let mut same = untouched.clone();
            thin_evenly(&mut same, 10, budget);
            assert_eq!(same.len(), 210, "budget {budget}");
            assert!(same.iter().all(|l| l.weight == 1.0), "budget {budget}");
        }
        thin_evenly(&mut lines, 10, 50);
        assert_eq!(lines.len(), 60);
        assert!(
            lines[..10]
                .iter()
                .all(|l| l.structure == 0 && l.weight == 1.0)
        );
        let kept = &lines[10..];
        assert!(kept.iter().all(|l| l.structure == 1));
        let total: f64 = kept.iter().map(|l| l.weight).sum();
        assert!((total - 200.0).abs() < 1e-9, "total weight {total}");
        let mut angles: Vec<f64> = kept
            .iter()
            .map(|l| {
                let d = l.samples[2].pos - DVec2::new(300.0, 200.0);
                d.y.atan2(d.x)
            })
            .collect();
        angles.sort_by(f64::total_cmp);
        let share = std::f64::consts::TAU / 50.0;
        let mut gaps: Vec<f64> = angles.windows(2).map(|w| w[1] - w[0]).collect();
        gaps.push(angles[0] + std::f64::consts::TAU - angles[angles.len() - 1]);
        for g in gaps {
            assert!(
                (g - share).abs() < 1e-6,
                "gap {g} rad, against {share} for even spacing"
            );
        }
    }
}
