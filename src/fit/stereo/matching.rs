//! Stereo matches: points on a grid inside camera 0's fitted silhouette, matched along their
//! epipolar lines in every partner view by normalised cross-correlation (see the module above),
//! and triangulated with the cameras' current intrinsics.

use super::StereoParams;
use crate::appearance::Appearance;
use crate::fit::context::FrameContext;
use crate::fit::probability::ViewProbabilities;
use crate::fit::state::FitState;
use crate::geometry::camera::{level_scale, pixel_at_scale, pixel_from_scale};
use crate::geometry::{Camera, Intrinsics};
use crate::render::raster::{NO_OBJECT, NO_TRIANGLE, RasterOptions, ViewRaster, rasterize};
use glam::{DVec2, DVec3};
use image::RgbImage;
use rayon::prelude::*;

/// One point of camera 0 matched in another view, and the model surface it was seen on.
#[derive(Debug, Clone, PartialEq)]
pub struct StereoMatch {
    pub structure: usize,
    /// Vertices of the face hit and their barycentric weights.
    pub vertices: [(u32, f64); 3],
    /// The partner view.
    pub view: usize,
    /// Full-resolution pixel in camera 0 and its match in `view`.
    pub pixel_ref: DVec2,
    pub pixel_other: DVec2,
    /// Standard deviation of the triangulated point along camera 0's ray, mm.
    pub sigma_mm: f64,
}

/// The matches of one measurement and their points triangulated with the intrinsics they were
/// measured at (kept: in most steps the intrinsics do not move).
#[derive(Debug, Clone, Default)]
pub struct StereoSet {
    pub matches: Vec<StereoMatch>,
    pub intrinsics: Vec<Intrinsics>,
    pub(super) points: Vec<Option<StereoPoint>>,
}

impl StereoSet {
    pub fn new(cameras: &[Camera], intrinsics: &[Intrinsics], matches: Vec<StereoMatch>) -> Self {
        let points = matches
            .iter()
            .map(|m| triangulate(cameras, intrinsics, m))
            .collect();
        Self {
            matches,
            intrinsics: intrinsics.to_vec(),
            points,
        }
    }
}

/// A match triangulated at the current intrinsics.
#[derive(Debug, Clone, Copy)]
pub struct StereoPoint {
    /// The triangulated point, camera-0 coordinates (mm).
    pub target_mm: DVec3,
    /// Camera 0's unit ray through the point.
    pub ray: DVec3,
}

/// The closest point on camera 0's ray through `pixel_ref` to the partner's ray through
/// `pixel_other` (None for parallel rays or a point behind camera 0).
pub fn triangulate(
    cameras: &[Camera],
    intrinsics: &[Intrinsics],
    m: &StereoMatch,
) -> Option<StereoPoint> {
    let (o0, d0) = cameras
        .first()?
        .pixel_ray_with(intrinsics.first()?, m.pixel_ref);
    let (om, dm) = cameras
        .get(m.view)?
        .pixel_ray_with(intrinsics.get(m.view)?, m.pixel_other);
    // Minimise |o0 + s d0 − (om + u dm)|² over s and u.
    let w = o0 - om;
    let (a, b, c) = (d0.dot(d0), d0.dot(dm), dm.dot(dm));
    let (d, e) = (d0.dot(w), dm.dot(w));
    let den = a * c - b * b;
    if den.abs() < 1e-12 {
        return None;
    }
    let s = (b * e - c * d) / den;
    (s > 0.0).then(|| StereoPoint {
        target_mm: o0 + d0 * s,
        ray: d0,
    })
}

/// An image's intensity, R + G + B: three channels' texture at a third of one channel's
/// relative noise.
struct Grey {
    width: i64,
    height: i64,
    data: Vec<f32>,
}

impl Grey {
    fn new(img: &RgbImage) -> Self {
        Self {
            width: img.width() as i64,
            height: img.height() as i64,
            data: img
                .as_raw()
                .chunks_exact(3)
                .map(|p| p[0] as f32 + p[1] as f32 + p[2] as f32)
                .collect(),
        }
    }
}

/// Intensity sampled bilinearly; None outside the image.
#[inline]
fn sample(img: &Grey, p: DVec2) -> Option<f64> {
    // Negative and NaN coordinates first (NaN was sampled at 0 before): for the rest
    // truncation is the floor, and the matcher's ~130,000 samples a frame no longer call
    // libm's `floor` (the build targets x86-64 without SSE4.1's rounding instruction). Huge
    // ones saturate at i64::MAX, so the bound is checked without adding to them.
    if !(p.x >= 0.0 && p.y >= 0.0) {
        return None;
    }
    let (x0, y0) = (p.x as i64, p.y as i64);
    if x0 >= img.width - 1 || y0 >= img.height - 1 {
        return None;
    }
    let (fx, fy) = (p.x - x0 as f64, p.y - y0 as f64);
    let i = (y0 * img.width + x0) as usize;
    let w = img.width as usize;
    let g = |k: usize| img.data[k] as f64;
    let top = g(i) * (1.0 - fx) + g(i + 1) * fx;
    let bottom = g(i + w) * (1.0 - fx) + g(i + w + 1) * fx;
    Some(top * (1.0 - fy) + bottom * fy)
}

/// Zero mean and unit norm in place; false when the values hold no texture.
fn normalise(v: &mut [f64]) -> bool {
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    v.iter_mut().for_each(|x| *x -= mean);
    let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
    // Under one grey level of contrast per pixel the correlation is noise.
    if norm < (v.len() as f64).sqrt() {
        return false;
    }
    v.iter_mut().for_each(|x| *x /= norm);
    true
}

/// Images and cameras of one stereo pair at the matching level.
struct Pair<'a> {
    images: (&'a Grey, &'a Grey),
    cameras: (&'a Camera, &'a Camera),
    intrinsics: (&'a Intrinsics, &'a Intrinsics),
    /// Full-resolution → matching-level pixel scale.
    scale: f64,
}

/// Matches a camera-0 pixel (full resolution) along its epipolar line in the partner,
/// around where the model's `depth_mm` (camera-0 z) puts it. Patches and the search are at the
/// matching level, aligned with the epipolar direction: one strip of the partner image serves
/// every candidate shift. Returns the partner pixel (full resolution) and the σ of the point
/// along camera 0's ray (mm).
fn match_point(
    pair: &Pair,
    pixel: DVec2,
    depth_mm: f64,
    params: &StereoParams,
) -> Option<(DVec2, f64)> {
    let (origin, dir) = pair.cameras.0.pixel_ray_with(pair.intrinsics.0, pixel);
    // `depth_mm` is along camera 0's own axis.
    let t0 = depth_mm / (pair.cameras.0.extrinsics.rotation * dir).z;
    let project = |t: f64| {
        pair.intrinsics
            .1
            .project(pair.cameras.1.to_camera(origin + dir * t))
    };
    let (q0, q1) = (project(t0)?, project(t0 * 1.001)?);
    // Partner pixels per mm along the ray, and the epipolar direction.
    let px_per_mm = (q1 - q0).length() / (t0 * 0.001);
    let e = (q1 - q0).try_normalize()?;
    let e_perp = e.perp();
    let s = pair.scale;
    let (u0, c0) = (pixel_at_scale(pixel, s), pixel_at_scale(q0, s));
    let (hw, k) = (params.half_window, params.search_px);
    let side = (2 * hw + 1) as usize;
    let mut left = Vec::with_capacity(side * side);
    for dy in -hw..=hw {
        for dx in -hw..=hw {
            left.push(sample(
                pair.images.0,
                u0 + e * dx as f64 + e_perp * dy as f64,
            )?);
        }
    }
    if !normalise(&mut left) {
        return None;
    }
    let len = (2 * k + 2 * hw + 1) as usize;
    let mut strip = vec![0.0; side * len];
    for (row, dy) in (-hw..=hw).enumerate() {
        for j in 0..len {
            let along = j as f64 - (k + hw) as f64;
            strip[row * len + j] = sample(pair.images.1, c0 + e * along + e_perp * dy as f64)?;
        }
    }
    // Column sums of the strip: each candidate window's sum and sum of squares from `side`
    // columns instead of side² samples. The left patch has zero mean and unit norm, so
    // NCC = Σ l·r / √(Σ r² − (Σ r)² / n).
    let (mut col, mut col2) = (vec![0.0; len], vec![0.0; len]);
    for row in strip.chunks_exact(len) {
        for (j, v) in row.iter().enumerate() {
            col[j] += v;
            col2[j] += v * v;
        }
    }
    let n = (side * side) as f64;
    let scores: Vec<Option<f64>> = (0..=(2 * k) as usize)
        .map(|shift| {
            let sum: f64 = col[shift..shift + side].iter().sum();
            let sum2: f64 = col2[shift..shift + side].iter().sum();
            let var = sum2 - sum * sum / n;
            // Under one grey level of contrast per pixel the correlation is noise.
            if var < n {
                return None;
            }
            let dot: f64 = left
                .chunks_exact(side)
                .zip(strip.chunks_exact(len))
                .map(|(l, r)| {
                    l.iter()
                        .zip(&r[shift..shift + side])
                        .map(|(a, b)| a * b)
                        .sum::<f64>()
                })
                .sum();
            Some(dot / var.sqrt())
        })
        .collect();
    let (best, score) = scores
        .iter()
        .enumerate()
        .filter_map(|(i, s)| s.map(|s| (i, s)))
        .max_by(|a, b| a.1.total_cmp(&b.1))?;
    // A peak on the search boundary may lie outside it; a weak one is not a match.
    if best == 0 || best + 1 == scores.len() || score < params.min_ncc {
        return None;
    }
    let (sm, sp) = (scores[best - 1]?, scores[best + 1]?);
    let curvature = sm - 2.0 * score + sp;
    if curvature >= -1e-9 {
        return None;
    }
    let offset = (0.5 * (sm - sp) / curvature).clamp(-0.5, 0.5);
    let along = best as f64 - k as f64 + offset;
    let other = pixel_from_scale(c0 + e * along, s);
    Some((other, params.sigma_px / s / px_per_mm))
}

/// Whether `other` and `reference` form a stereo pair the term can match across: a baseline,
/// and viewing directions at most `max_angle_deg` apart.
pub fn is_stereo_partner(reference: &Camera, other: &Camera, max_angle_deg: f64) -> bool {
    let axis = |c: &Camera| c.extrinsics.rotation.transpose() * DVec3::Z;
    let cos = axis(reference).dot(axis(other));
    (other.extrinsics.center_mm() - reference.extrinsics.center_mm()).length() > 0.1
        && cos >= max_angle_deg.to_radians().cos()
}

/// Finds stereo matches on the model's visible surface in camera 0 at `state`. Points lie on
/// a grid over the visible structures' region, kept away from its edges, where the forest
/// agrees with the structure (its probabilities at `level`): tools and smoke in front of the
/// organ give no points. Patches are matched at `level`. The surface is looked up one level
/// coarser (a quarter of the pixels; grid points lie several pixels apart anyway): in
/// `raster` when the caller has it for `state` (camera 0's visibility raster of the visible
/// structures), else rendered here.
pub fn measure(
    ctx: &FrameContext,
    state: &FitState,
    views: &mut [ViewProbabilities],
    appearance: Option<&Appearance>,
    level: usize,
    raster: Option<&ViewRaster>,
    params: &StereoParams,
) -> StereoSet {
    if views.len() < 2 || params.weight <= 0.0 || level >= views[0].level_count() {
        return StereoSet::default();
    }
    let Some(images) = views
        .iter_mut()
        .map(|v| v.level_image(level))
        .collect::<Option<Vec<_>>>()
    else {
        return StereoSet::default();
    };
    let images: Vec<Grey> = images.par_iter().map(|i| Grey::new(i)).collect();
    let model = ctx.model;
    let visible = ctx.imaged();
    let (w, h) = views[0].size(level);
    let rendered;
    let raster = match raster {
        Some(r) => r,
        None => {
            let posed = model.posed(&state.affine, &model.deformed(&state.shape));
            let objects = model.objects(&posed, &visible);
            let size = ((w / 2).max(1), (h / 2).max(1));
            let cam0 = ctx.cameras[0].at_level(&state.intrinsics[0], level + 1, size);
            rendered = rasterize(&cam0, &objects, &RasterOptions::default());
            &rendered
        }
    };
    let (rw, rh) = (raster.object.width, raster.object.height);
    let ratio = 2usize;
    let covered = raster
        .object
        .data
        .iter()
        .filter(|&&o| o != NO_OBJECT)
        .count();
    if covered == 0 {
        return StereoSet::default();
    }
    let stride = ((covered as f64 / params.max_points as f64).sqrt().ceil() as usize).max(1);
    // Raster pixels of a neighbour checked either way: the patch lies inside the region.
    let erode = (params.half_window.max(2) as usize).div_ceil(ratio);
    let scale = level_scale(level);
    // (raster x, raster y, level x, level y, structure)
    let mut candidates = Vec::new();
    for ry in (erode..rh.saturating_sub(erode)).step_by(stride) {
        for rx in (erode..rw.saturating_sub(erode)).step_by(stride) {
            let o = *raster.object.get(rx, ry);
            if o == NO_OBJECT
                || *raster.triangle.get(rx, ry) == NO_TRIANGLE
                || [
                    (rx - erode, ry),
                    (rx + erode, ry),
                    (rx, ry - erode),
                    (rx, ry + erode),
                ]
                .iter()
                .any(|&(a, b)| *raster.object.get(a, b) != o)
            {
                continue;
            }
            let (x, y) = ((rx * ratio).min(w - 1), (ry * ratio).min(h - 1));
            candidates.push((rx, ry, x, y, visible[o as usize]));
        }
    }
    // The forest's word over each patch (its centre and corners): one edge of a tool inside a
    // patch outweighs the tissue's faint texture, and the match follows the tool.
    let hw = params.half_window as usize;
    let patch_pixels = |x: usize, y: usize| {
        let (w, h) = (w, h);
        [(hw, hw), (0, 0), (2 * hw, 0), (0, 2 * hw), (2 * hw, 2 * hw)]
            .into_iter()
            .map(move |(dx, dy)| {
                let (px, py) = ((x + dx).saturating_sub(hw), (y + dy).saturating_sub(hw));
                (py.min(h - 1) * w + px.min(w - 1)) as u32
            })
    };
    let pixels: Vec<u32> = candidates
        .iter()
        .flat_map(|c| patch_pixels(c.2, c.3))
        .collect();
    views[0].ensure(appearance, level, &pixels);
    let candidates: Vec<_> = candidates
        .into_iter()
        .filter(|&(_, _, x, y, si)| {
            ctx.class_of[si].is_some_and(|k| views[0].get(level, (y * w + x) as u32, k) >= 0.5)
                && patch_pixels(x, y).all(|i| views[0].get(level, i, 0) < 0.5)
        })
        .collect();
    let work: Vec<_> = (1..views.len())
        .filter(|&m| {
            is_stereo_partner(
                &ctx.cameras[0],
                &ctx.cameras[m],
                params.max_partner_angle_deg,
            )
        })
        .flat_map(|m| candidates.iter().map(move |c| (m, c)))
        .collect();
    let matches = work
        .par_iter()
        .filter_map(|&(m, &(rx, ry, x, y, si))| {
            let pair = Pair {
                images: (&images[0], &images[m]),
                cameras: (&ctx.cameras[0], &ctx.cameras[m]),
                intrinsics: (&state.intrinsics[0], &state.intrinsics[m]),
                scale,
            };
            // The level pixel's centre at full resolution.
            let full = pixel_from_scale(DVec2::new(x as f64, y as f64), scale);
            let depth = *raster.depth_mm.get(rx, ry) as f64;
            let (other, sigma_mm) = match_point(&pair, full, depth, params)?;
            let face = model.structures[si].faces[*raster.triangle.get(rx, ry) as usize];
            let [b1, b2] = raster.barycentric.get(rx, ry).map(|b| b as f64);
            Some(StereoMatch {
                structure: si,
                vertices: [(face[0], 1.0 - b1 - b2), (face[1], b1), (face[2], b2)],
                view: m,
                pixel_ref: full,
                pixel_other: other,
                sigma_mm,
            })
        })
        .collect();
    StereoSet::new(ctx.cameras, &state.intrinsics, matches)
}
