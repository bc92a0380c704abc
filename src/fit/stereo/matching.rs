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

/// An image's intensity as a weighted sum of its channels (see [`channel_weights`]).
struct Grey {
    width: i64,
    height: i64,
    data: Vec<f32>,
}

impl Grey {
    fn new(img: &RgbImage, weights: [f32; 3]) -> Self {
        Self {
            width: img.width() as i64,
            height: img.height() as i64,
            data: img
                .as_raw()
                .chunks_exact(3)
                .map(|p| {
                    weights[0] * p[0] as f32 + weights[1] * p[1] as f32 + weights[2] * p[2] as f32
                })
                .collect(),
        }
    }

    /// The plane smoothed by a binomial kernel of `radius` (1: [1 2 1] / 4, 2: [1 4 6 4 1] / 16,
    /// along each axis), edges clamped; itself at 0.
    fn smoothed(self, radius: usize) -> Self {
        if radius == 0 || self.width < 1 || self.height < 1 {
            return self;
        }
        let n = 2 * radius;
        let mut kernel = vec![1f32];
        for _ in 0..n {
            let mut next = vec![0f32; kernel.len() + 1];
            for (i, k) in kernel.iter().enumerate() {
                next[i] += 0.5 * k;
                next[i + 1] += 0.5 * k;
            }
            kernel = next;
        }
        let (w, h) = (self.width as usize, self.height as usize);
        // One multiply-add over a whole row per tap (the compiler vectorises these), edges
        // clamped by padding each row and clamping the rows' indices.
        let mut across = vec![0f32; w * h];
        let mut padded = vec![0f32; w + n];
        for (src, out) in self.data.chunks_exact(w).zip(across.chunks_exact_mut(w)) {
            padded[..radius].fill(src[0]);
            padded[radius..radius + w].copy_from_slice(src);
            padded[radius + w..].fill(src[w - 1]);
            for (j, &k) in kernel.iter().enumerate() {
                for (o, v) in out.iter_mut().zip(&padded[j..j + w]) {
                    *o += k * v;
                }
            }
        }
        let mut data = vec![0f32; w * h];
        for (y, out) in data.chunks_exact_mut(w).enumerate() {
            for (j, &k) in kernel.iter().enumerate() {
                let sy = (y + j).saturating_sub(radius).min(h - 1);
                for (o, v) in out.iter_mut().zip(&across[sy * w..(sy + 1) * w]) {
                    *o += k * v;
                }
            }
        }
        Self { data, ..self }
    }
}

/// Channel weights for matching: each channel's share of the tissue's squared mean colour,
/// scaled to sum to 3 (so a grey level means what it meant for R + G + B). Texture is albedo
/// times shading, so it is strongest in the tissue's dominant channel, while a specular
/// highlight adds the light's colour to every channel alike, and a glint's match lies behind a
/// convex surface: on red kidney, green and blue carry little but glints. At the true pose of
/// the phantom's frames (480×270 and 960×540, seeds 71–73; the patch following the model's
/// surface) the matches lay +0.035 px deep with R + G + B, +0.027 with the mean colour and
/// +0.023 with its square (red alone +0.022; the specular-free sum − 3·min +0.058, its
/// texture too faint).
fn channel_weights(img: &RgbImage, pixels: impl Iterator<Item = (u32, u32)>) -> [f32; 3] {
    let mut sum = [0f64; 3];
    for (x, y) in pixels {
        if let Some(p) = img.get_pixel_checked(x, y) {
            (0..3).for_each(|c| sum[c] += p[c] as f64);
        }
    }
    let squared = sum.map(|c| c * c);
    let total: f64 = squared.iter().sum();
    if total <= 0.0 {
        return [1.0; 3];
    }
    squared.map(|c| (3.0 * c / total) as f32)
}

/// Bilinear interpolation of a row-major `width` × `height` grid (pixel centres at integer
/// coordinates) at `p` from its values `at(index)`; None outside the grid's interior or where
/// one of the four is None.
#[inline]
fn bilinear(
    width: usize,
    height: usize,
    p: DVec2,
    at: impl Fn(usize) -> Option<f64>,
) -> Option<f64> {
    // Negative and NaN coordinates first (NaN was sampled at 0 before): for the rest
    // truncation is the floor, and the matcher's ~130,000 samples a frame do not call libm's
    // `floor` in a baseline x86-64 build (no SSE4.1 rounding instruction; the default build
    // targets the building CPU, .cargo/config.toml). Huge ones saturate, so the
    // bound is checked without adding to them.
    if !(p.x >= 0.0 && p.y >= 0.0) {
        return None;
    }
    let (x0, y0) = (p.x as usize, p.y as usize);
    if x0 >= width.saturating_sub(1) || y0 >= height.saturating_sub(1) {
        return None;
    }
    let (fx, fy) = (p.x - x0 as f64, p.y - y0 as f64);
    let i = y0 * width + x0;
    let top = at(i)? * (1.0 - fx) + at(i + 1)? * fx;
    let bottom = at(i + width)? * (1.0 - fx) + at(i + width + 1)? * fx;
    Some(top * (1.0 - fy) + bottom * fy)
}

/// Intensity sampled bilinearly; None outside the image.
#[inline]
fn sample(img: &Grey, p: DVec2) -> Option<f64> {
    bilinear(img.width as usize, img.height as usize, p, |k| {
        Some(img.data[k] as f64)
    })
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
/// every candidate shift. The integer peak found, the sub-pixel peak is sought with the
/// partner patch following the model's surface (`model_depth`: camera-0 z at a full-resolution
/// pixel; see [`warped_window`]) when `params.warp` is set: it may climb up to two pixels from
/// the strip's peak, within the search range. Where the model does not cover the patch's
/// lattice (near the region's edge) the square window's parabola stands, with its lean.
/// Returns the partner pixel (full resolution) and the σ of the point along camera 0's ray
/// (mm).
fn match_point(
    pair: &Pair,
    pixel: DVec2,
    depth_mm: f64,
    model_depth: &dyn Fn(DVec2) -> Option<f64>,
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
            let var = textured_variance(sum, sum2, n)?;
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
    if params.warp
        && let Some(warp) = warped_window(pair, u0, e, hw, model_depth)
    {
        let centre = warp[warp.len() / 2];
        let start = (c0 + e * (best as f64 - k as f64) - centre).dot(e).round() as i64;
        let (other, _) = refine_warped(pair.images.1, &left, &warp, e, start, params)?;
        let found = centre + e * other;
        // Within the strip's own range: a peak the climb carried past it is not the search's.
        if (found - c0).dot(e).abs() > k as f64 - 0.5 {
            return None;
        }
        return Some((pixel_from_scale(found, s), params.sigma_px / s / px_per_mm));
    }
    let offset = parabola_peak(scores[best - 1]?, score, scores[best + 1]?)?;
    let along = best as f64 - k as f64 + offset;
    let other = pixel_from_scale(c0 + e * along, s);
    Some((other, params.sigma_px / s / px_per_mm))
}

/// Where each pixel of the reference patch (centred on `u0`, axes `e` and its perpendicular,
/// matching-level pixels) lands in the partner if it lies on the model's surface. A square
/// window assumes a surface facing the camera; on a convex one the disparity falls off
/// towards the window's edges and the plain match lies deep (a ray-cast sphere of 25 mm:
/// +0.038 px, against +0.017 px warped; see the tests). The partner positions come from the
/// model's depth at a 3 × 3 lattice of the patch (its corners, edge midpoints and centre),
/// carried across by the cameras and interpolated biquadratically between. Row-major like
/// the patch. None where the model does not cover the lattice.
fn warped_window(
    pair: &Pair,
    u0: DVec2,
    e: DVec2,
    hw: i64,
    model_depth: &dyn Fn(DVec2) -> Option<f64>,
) -> Option<Vec<DVec2>> {
    let s = pair.scale;
    let e_perp = e.perp();
    let h = hw as f64;
    let mut nodes = [[DVec2::ZERO; 3]; 3];
    for (b, row) in nodes.iter_mut().enumerate() {
        for (a, node) in row.iter_mut().enumerate() {
            let at = u0 + e * ((a as f64 - 1.0) * h) + e_perp * ((b as f64 - 1.0) * h);
            let full = pixel_from_scale(at, s);
            let z = model_depth(full)?;
            let (origin, dir) = pair.cameras.0.pixel_ray_with(pair.intrinsics.0, full);
            let t = z / (pair.cameras.0.extrinsics.rotation * dir).z;
            let q = pair
                .intrinsics
                .1
                .project(pair.cameras.1.to_camera(origin + dir * t))?;
            *node = pixel_at_scale(q, s);
        }
    }
    // Quadratic Lagrange weights of the nodes at −h, 0, h.
    let weights = |x: f64| {
        [
            x * (x - h) / (2.0 * h * h),
            (h * h - x * x) / (h * h),
            x * (x + h) / (2.0 * h * h),
        ]
    };
    let wx: Vec<[f64; 3]> = (-hw..=hw).map(|d| weights(d as f64)).collect();
    let mut out = Vec::with_capacity(wx.len() * wx.len());
    for wy in &wx {
        // The row's three nodes interpolated first: separable.
        let row: [DVec2; 3] = std::array::from_fn(|a| {
            nodes[0][a] * wy[0] + nodes[1][a] * wy[1] + nodes[2][a] * wy[2]
        });
        out.extend(
            wx.iter()
                .map(|w| row[0] * w[0] + row[1] * w[1] + row[2] * w[2]),
        );
    }
    Some(out)
}

/// Normalised cross-correlation of the reference patch with the partner sampled at `warp`
/// moved `shift` pixels along `e`.
fn warped_score(img: &Grey, left: &[f64], warp: &[DVec2], e: DVec2, shift: f64) -> Option<f64> {
    let (mut sum, mut sum2, mut dot) = (0.0, 0.0, 0.0);
    for (l, &p) in left.iter().zip(warp) {
        let v = sample(img, p + e * shift)?;
        sum += v;
        sum2 += v * v;
        dot += l * v;
    }
    textured_variance(sum, sum2, left.len() as f64).map(|var| dot / var.sqrt())
}

/// A window's variance times its size n, from its sum and sum of squares; None under one
/// grey level of contrast per pixel, where the correlation is noise.
fn textured_variance(sum: f64, sum2: f64, n: f64) -> Option<f64> {
    let var = sum2 - sum * sum / n;
    (var >= n).then_some(var)
}

/// The sub-pixel offset (within ±½) of the peak of the parabola through three scores a pixel
/// apart, the middle one the highest; None where they do not bend down.
fn parabola_peak(minus: f64, here: f64, plus: f64) -> Option<f64> {
    let curvature = minus - 2.0 * here + plus;
    if curvature >= -1e-9 {
        return None;
    }
    Some((0.5 * (minus - plus) / curvature).clamp(-0.5, 0.5))
}

/// The correlation peak of the warped patch along `e`, climbing at most two pixels from the
/// integer `start` (pixels from the warp's centre) and refined by a parabola. Returns the
/// shift and score; None where the climb ends before a peak or the peak is weaker than
/// `min_ncc` (the caller checks the search range).
fn refine_warped(
    img: &Grey,
    left: &[f64],
    warp: &[DVec2],
    e: DVec2,
    start: i64,
    params: &StereoParams,
) -> Option<(f64, f64)> {
    let score = |j: i64| warped_score(img, left, warp, e, j as f64);
    let (mut j, mut here) = (start, score(start)?);
    let (mut minus, mut plus) = (score(j - 1)?, score(j + 1)?);
    // A step or two at most: the unwarped peak lies within a pixel or so of the warped one.
    for _ in 0..2 {
        if minus > here && minus >= plus {
            (plus, here, j) = (here, minus, j - 1);
            minus = score(j - 1)?;
        } else if plus > here {
            (minus, here, j) = (here, plus, j + 1);
            plus = score(j + 1)?;
        } else {
            break;
        }
    }
    if minus > here || plus > here || here < params.min_ncc {
        return None;
    }
    Some((j as f64 + parabola_peak(minus, here, plus)?, here))
}

/// The raster's depth (mm) at a point of it, bilinear between its pixel centres; None where
/// one of the four is not covered.
fn raster_depth(raster: &ViewRaster, p: DVec2) -> Option<f64> {
    let depth = &raster.depth_mm;
    bilinear(depth.width, depth.height, p, |k| {
        let z = depth.data[k] as f64;
        z.is_finite().then_some(z)
    })
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
    let weights = channel_weights(
        &images[0],
        candidates.iter().map(|c| (c.2 as u32, c.3 as u32)),
    );
    let images: Vec<Grey> =
        crate::fit::profile::time(crate::fit::profile::Phase::StereoImages, || {
            images
                .par_iter()
                .map(|i| Grey::new(i, weights).smoothed(params.smooth_radius >> level))
                .collect()
        });
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
    let searched = crate::fit::profile::enabled().then(std::time::Instant::now);
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
            let model_depth = |p: DVec2| raster_depth(raster, pixel_at_scale(p, scale * 0.5));
            let (other, sigma_mm) = match_point(&pair, full, depth, &model_depth, params)?;
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
    if let Some(t) = searched {
        crate::fit::profile::add(crate::fit::profile::Phase::StereoSearch, t.elapsed());
    }
    StereoSet::new(ctx.cameras, &state.intrinsics, matches)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::SynthOptions;
    use crate::synth::phantom::Phantom;
    use crate::synth::texture::{Material, albedo};

    const CENTRE_MM: DVec3 = DVec3::new(3.0, -2.0, 150.0);
    const RADIUS_MM: f64 = 25.0;

    /// Where a ray first meets the sphere.
    fn hit(origin: DVec3, dir: DVec3, radius_mm: f64) -> Option<DVec3> {
        let oc = origin - CENTRE_MM;
        let b = oc.dot(dir);
        let disc = b * b - (oc.length_squared() - radius_mm * radius_mm);
        let t = -b - disc.max(0.0).sqrt();
        (disc >= 0.0 && t > 0.0).then(|| origin + dir * t)
    }

    /// The sphere with the phantom kidney's albedo, lit from between the cameras (no
    /// highlights), ray-cast exactly at every pixel centre: the brute-force truth.
    fn render(cam: &Camera) -> Grey {
        let light = DVec3::new(2.25, 0.0, 0.0);
        let mut img = RgbImage::new(cam.width, cam.height);
        for (x, y, px) in img.enumerate_pixels_mut() {
            let (o, d) = cam.pixel_ray(DVec2::new(x as f64, y as f64));
            let v = hit(o, d, RADIUS_MM).map_or(0.02, |p| {
                let n = (p - CENTRE_MM).normalize();
                let a = albedo(Material::Kidney, p).0.x as f64;
                a * (0.1 + 0.9 * n.dot((light - p).normalize()).max(0.0))
            });
            let v = (v * 255.0).round().clamp(0.0, 255.0) as u8;
            *px = image::Rgb([v, v, v]);
        }
        Grey::new(&img, [1.0; 3])
    }

    /// Mean error of the matches along the epipolar line (full-resolution px, + deeper)
    /// over a grid on the sphere, matched with and without following the model's surface;
    /// the model is the sphere `model_dr_mm` larger.
    fn sphere_bias(model_dr_mm: f64) -> (f64, f64, usize) {
        let ph = Phantom::new(SynthOptions {
            frames: 1,
            width: 480,
            height: 270,
            ..SynthOptions::default()
        });
        let cams = ph.cameras(0);
        let images = (render(&cams[0]), render(&cams[1]));
        let pair = Pair {
            images: (&images.0, &images.1),
            cameras: (&cams[0], &cams[1]),
            intrinsics: (&cams[0].intrinsics, &cams[1].intrinsics),
            scale: 1.0,
        };
        let model_depth = |q: DVec2| {
            let (o, d) = cams[0].pixel_ray(q);
            hit(o, d, RADIUS_MM + model_dr_mm).map(|p| p.z)
        };
        let mut errors = [Vec::new(), Vec::new()];
        for y in (0..270).step_by(12) {
            for x in (0..480).step_by(12) {
                let pixel = DVec2::new(x as f64, y as f64);
                let (o, d) = cams[0].pixel_ray(pixel);
                let Some(p) = hit(o, d, RADIUS_MM) else {
                    continue;
                };
                // Away from the limb, where the window would straddle the background.
                if (p - CENTRE_MM).normalize().dot(-d) < 0.4 {
                    continue;
                }
                let truth = cams[1].project(p).unwrap();
                let deeper = cams[1].project(o + d * (p - o).length() * 1.001).unwrap();
                let e = (deeper - truth).normalize();
                let found: Vec<Option<f64>> = [false, true]
                    .iter()
                    .map(|&warp| {
                        let params = StereoParams {
                            warp,
                            ..StereoParams::default()
                        };
                        let model_z = model_depth(pixel)?;
                        let (other, _) = match_point(&pair, pixel, model_z, &model_depth, &params)?;
                        Some((other - truth).dot(e))
                    })
                    .collect();
                if let [Some(plain), Some(warped)] = found[..] {
                    errors[0].push(plain);
                    errors[1].push(warped);
                }
            }
        }
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
        (mean(&errors[0]), mean(&errors[1]), errors[0].len())
    }

    /// A square window assumes the surface faces the camera; on a curved one its disparity
    /// falls off towards the window's edges and the plain match lies deep. Following the
    /// model's surface more than halves that, and an imperfect model (2 mm too large) still
    /// helps. (`matches_recover_the_true_depth` in the module above runs the same path through
    /// `measure`, the model's depth read from a raster one level coarser.)
    #[test]
    fn following_the_model_surface_reduces_the_window_bias() {
        let (plain, warped, n) = sphere_bias(0.0);
        assert!(n >= 80, "{n} matches");
        // Measured: plain +0.038 px, warped +0.017 px (0.3 and 0.13 mm); warped on the 2 mm
        // larger model −0.002 px.
        assert!(plain > 0.025, "plain window bias {plain} px");
        assert!(warped.abs() < 0.025, "warped bias {warped} px");
        assert!(
            plain - warped > 0.01,
            "plain {plain} px, warped {warped} px"
        );
        let (_, off_model, _) = sphere_bias(2.0);
        assert!(
            off_model.abs() < 0.025,
            "warped on a 2 mm larger model: {off_model} px"
        );
    }

    /// The row-wise smoothing against the kernel applied pixel by pixel (binomial weights
    /// C(2r, j) / 4^r, edges clamped), on a plane narrower and shorter than the kernel too.
    #[test]
    fn smoothing_matches_the_kernel_applied_pixel_by_pixel() {
        let binomial = |n: usize, j: usize| -> f64 {
            (0..j).fold(1.0, |c, i| c * (n - i) as f64 / (i + 1) as f64) / 2f64.powi(n as i32)
        };
        for (w, h) in [(23usize, 17usize), (3, 2), (1, 5)] {
            let data: Vec<f32> = (0..w * h)
                .map(|i| ((i * 7919) % 251) as f32 * 0.7 + (i % 3) as f32)
                .collect();
            for radius in [0usize, 1, 2, 3] {
                let grey = Grey {
                    width: w as i64,
                    height: h as i64,
                    data: data.clone(),
                };
                let out = grey.smoothed(radius);
                let r = radius as i64;
                for y in 0..h as i64 {
                    for x in 0..w as i64 {
                        let mut want = 0.0;
                        for dy in -r..=r {
                            for dx in -r..=r {
                                let sx = (x + dx).clamp(0, w as i64 - 1) as usize;
                                let sy = (y + dy).clamp(0, h as i64 - 1) as usize;
                                want += binomial(2 * radius, (dx + r) as usize)
                                    * binomial(2 * radius, (dy + r) as usize)
                                    * data[sy * w + sx] as f64;
                            }
                        }
                        let got = out.data[y as usize * w + x as usize] as f64;
                        assert!(
                            (got - want).abs() < 1e-3,
                            "{w}x{h}, radius {radius}, ({x}, {y}): {got} against {want}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn channel_weights_follow_the_tissue_colour() {
        let mut img = RgbImage::new(4, 4);
        img.pixels_mut()
            .for_each(|p| *p = image::Rgb([200, 60, 40]));
        let w = channel_weights(&img, (0..4).map(|i| (i, i)));
        assert!((w.iter().sum::<f32>() - 3.0).abs() < 1e-5);
        assert!(w[0] > 2.5 && w[2] < w[1], "{w:?}");
        // Nothing to weigh by: plain R + G + B.
        assert_eq!(channel_weights(&img, std::iter::empty()), [1.0; 3]);
    }
}
