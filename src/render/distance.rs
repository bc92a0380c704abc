//! Exact Euclidean distance transform (Felzenszwalb & Huttenlocher 2012: lower envelope of
//! parabolas, one pass over columns and one over rows, O(pixels)) and the signed distance map
//! φ of eq. 3/6, positive inside, with the contour half-way between inside and outside pixels.

use crate::plane::{DistanceMap, Mask, Plane};

/// Squared distance (px²) from every pixel to the nearest `true` pixel of `features`;
/// `f32::INFINITY` everywhere when there is none.
pub fn squared_edt(features: &Mask) -> DistanceMap {
    let (w, h) = (features.width, features.height);
    let mut grid: Vec<f64> = features
        .data
        .iter()
        .map(|&f| if f { 0.0 } else { f64::INFINITY })
        .collect();
    let n = w.max(h);
    let mut f = vec![0.0; n];
    let mut d = vec![0.0; n];
    let mut v = vec![0usize; n];
    let mut z = vec![0.0; n + 1];
    for x in 0..w {
        for y in 0..h {
            f[y] = grid[y * w + x];
        }
        edt_1d(&f[..h], &mut d[..h], &mut v, &mut z);
        for y in 0..h {
            grid[y * w + x] = d[y];
        }
    }
    for y in 0..h {
        let row = &mut grid[y * w..(y + 1) * w];
        f[..w].copy_from_slice(row);
        edt_1d(&f[..w], &mut d[..w], &mut v, &mut z);
        row.copy_from_slice(&d[..w]);
    }
    Plane {
        width: w,
        height: h,
        data: grid.into_iter().map(|x| x as f32).collect(),
    }
}

/// Inclusive bounds `[x0, y0, x1, y1]` of the `true` pixels of `mask`, widened by `margin`
/// px and clamped to the image; None when no pixel is `true`.
pub fn true_bounds(mask: &Mask, margin: usize) -> Option<[usize; 4]> {
    let (w, h) = (mask.width, mask.height);
    let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
    for (y, row) in mask.data.chunks_exact(w.max(1)).enumerate() {
        if let (Some(a), Some(b)) = (row.iter().position(|&v| v), row.iter().rposition(|&v| v)) {
            (x0, x1) = (x0.min(a), x1.max(b));
            (y0, y1) = (y0.min(y), y1.max(y));
        }
    }
    (x0 != usize::MAX).then(|| {
        [
            x0.saturating_sub(margin),
            y0.saturating_sub(margin),
            (x1 + margin).min(w - 1),
            (y1 + margin).min(h - 1),
        ]
    })
}

/// [`squared_edt`] over the box `[x0, y0, x1, y1]` of `features` only (pixels outside it get
/// `outside`): what a frame's masks need when everything of interest lies in a small part of
/// a 1080p frame (a transform of the whole frame is ~40 ms, single-threaded).
pub fn squared_edt_in(features: &Mask, bounds: [usize; 4], outside: f32) -> DistanceMap {
    let [x0, y0, x1, y1] = bounds;
    let (cw, ch) = (x1 + 1 - x0, y1 + 1 - y0);
    let crop = Plane {
        width: cw,
        height: ch,
        data: (y0..=y1)
            .flat_map(|y| {
                features.data[y * features.width + x0..=y * features.width + x1]
                    .iter()
                    .copied()
            })
            .collect(),
    };
    let d = squared_edt(&crop);
    let mut out = Plane::filled(features.width, features.height, outside);
    for (cy, row) in d.data.chunks_exact(cw).enumerate() {
        let start = (y0 + cy) * features.width + x0;
        out.data[start..start + cw].copy_from_slice(row);
    }
    out
}

/// Pixels within `radius_px` of a `true` pixel of `mask` (a disc dilation), exactly as a
/// threshold of [`squared_edt`] of the whole mask gives them: a pixel farther than the radius
/// from the mask's bounding box is farther from every mask pixel, so the transform runs on that
/// box widened by the radius only.
pub fn dilate(mask: &Mask, radius_px: f64) -> Mask {
    let r2 = radius_px * radius_px;
    let Some(bounds) = true_bounds(mask, radius_px.max(0.0).ceil() as usize + 1) else {
        return mask.clone();
    };
    squared_edt_in(mask, bounds, f32::INFINITY).map(|&d| (d as f64) <= r2)
}

/// Squared distance (px²) from each `true` pixel of `region` to the nearest `false` pixel
/// (0 on `false` pixels; ∞ when every pixel is `true`), equal to [`squared_edt`] of the
/// complement: the region's bounding box widened by 1 px is ringed by `false` pixels (or the
/// image's edge, beyond which there are none), so no `false` pixel outside it is nearer.
pub fn squared_depth_inside(region: &Mask) -> DistanceMap {
    let Some(bounds) = true_bounds(region, 1) else {
        return Plane::filled(region.width, region.height, 0.0);
    };
    squared_edt_in(&region.map(|&v| !v), bounds, 0.0)
}

/// Margins up to this (px) take [`deep_inside`]'s row windows; wider ones the transform.
const ROW_WINDOW_MAX_MARGIN_PX: f32 = 16.0;

/// The `true` pixels of `region` whose squared distance to every `false` pixel is at least
/// `margin²`: exactly those where [`squared_depth_inside`] `>= margin * margin` (f32, as the
/// callers compare). Only the rows within the margin can hold a nearer `false` pixel, so each
/// pixel checks those few rows' horizontal distances to their nearest `false` pixel instead of
/// a transform of the whole frame (the tracker asks this of every output mask, ~500,000 pixels
/// a view at 960×540). Margins over 16 px take the transform.
pub fn deep_inside(region: &Mask, margin: f32) -> Mask {
    let (w, h) = (region.width, region.height);
    let m2 = margin * margin;
    // The depth is compared with margin², so a negative margin is its magnitude.
    if margin.is_nan() || margin.abs() > ROW_WINDOW_MAX_MARGIN_PX {
        // Wide, or NaN (nothing passes a comparison with NaN, as in the transform's case).
        let depth = squared_depth_inside(region);
        let data = region.data.iter().zip(&depth.data);
        return Plane {
            width: w,
            height: h,
            data: data.map(|(&r, &d)| r && d >= m2).collect(),
        };
    }
    let mut out = Plane::filled(w, h, false);
    let Some([_, y0, _, y1]) = true_bounds(region, 0) else {
        return out;
    };
    // Horizontal distances to the row's nearest `false` pixel, capped where they can no
    // longer matter (cap² > margin²): rows outside the bounds are all `false` (distance 0).
    let cap = margin.abs().ceil() as u32 + 1;
    let rows_below = (0..=cap as usize)
        .take_while(|&dy| ((dy * dy) as f32) < m2)
        .count();
    let (r0, r1) = (y0.saturating_sub(rows_below), (y1 + rows_below).min(h - 1));
    let mut horizontal = vec![0u32; (r1 + 1 - r0) * w];
    for (row, dist) in region.data[r0 * w..(r1 + 1) * w]
        .chunks_exact(w)
        .zip(horizontal.chunks_exact_mut(w))
    {
        let mut run = cap;
        for (d, &v) in dist.iter_mut().zip(row) {
            run = if v { (run + 1).min(cap) } else { 0 };
            *d = run;
        }
        run = cap;
        for (d, &v) in dist.iter_mut().zip(row).rev() {
            run = if v { (run + 1).min(cap) } else { 0 };
            *d = (*d).min(run);
        }
    }
    // Squared distances are small integers here (exact in f32): compared as integers against
    // the least one that is not nearer than the margin.
    let enough = (0..=cap * cap)
        .find(|&d2| (d2 as f32) >= m2)
        .unwrap_or(cap * cap);
    let mut nearest = vec![0u32; w];
    for y in y0..=y1 {
        nearest.fill(u32::MAX);
        for dy in 0..rows_below {
            for yy in [y.checked_sub(dy), Some(y + dy).filter(|&v| dy > 0 && v < h)]
                .into_iter()
                .flatten()
            {
                let dist = &horizontal[(yy - r0) * w..(yy + 1 - r0) * w];
                let dy2 = (dy * dy) as u32;
                for (n, &d) in nearest.iter_mut().zip(dist) {
                    *n = (*n).min(d * d + dy2);
                }
            }
        }
        let (row, deep) = (
            &region.data[y * w..(y + 1) * w],
            &mut out.data[y * w..(y + 1) * w],
        );
        for ((o, &r), &n) in deep.iter_mut().zip(row).zip(&nearest) {
            *o = r && n >= enough;
        }
    }
    out
}

/// Squared distance (px²) to the nearest `true` pixel and that pixel's index (y·w + x), for
/// every pixel; index `u32::MAX` and distance ∞ when there is none. Same two passes as
/// [`squared_edt`], carrying the argmin: the fit uses it to find, for a band pixel, the contour
/// pixel (and so the surface point) that moves it.
pub fn nearest_feature(features: &Mask) -> (DistanceMap, Plane<u32>) {
    let (w, h) = (features.width, features.height);
    let mut grid: Vec<f64> = features
        .data
        .iter()
        .map(|&f| if f { 0.0 } else { f64::INFINITY })
        .collect();
    // After the column pass: the row of the nearest feature in this column.
    let mut row_of = vec![u32::MAX; w * h];
    let n = w.max(h);
    let (mut f, mut d, mut v, mut z, mut arg) = (
        vec![0.0; n],
        vec![0.0; n],
        vec![0usize; n],
        vec![0.0; n + 1],
        vec![0usize; n],
    );
    for x in 0..w {
        for y in 0..h {
            f[y] = grid[y * w + x];
        }
        edt_1d_arg(&f[..h], &mut d[..h], &mut v, &mut z, &mut arg[..h]);
        for y in 0..h {
            grid[y * w + x] = d[y];
            row_of[y * w + x] = if d[y].is_finite() {
                arg[y] as u32
            } else {
                u32::MAX
            };
        }
    }
    let mut index = vec![u32::MAX; w * h];
    for y in 0..h {
        f[..w].copy_from_slice(&grid[y * w..(y + 1) * w]);
        edt_1d_arg(&f[..w], &mut d[..w], &mut v, &mut z, &mut arg[..w]);
        for x in 0..w {
            grid[y * w + x] = d[x];
            if d[x].is_finite() {
                let col = arg[x];
                index[y * w + x] = row_of[y * w + col] * w as u32 + col as u32;
            }
        }
    }
    (
        Plane {
            width: w,
            height: h,
            data: grid.into_iter().map(|x| x as f32).collect(),
        },
        Plane {
            width: w,
            height: h,
            data: index,
        },
    )
}

fn edt_1d_arg(f: &[f64], d: &mut [f64], v: &mut [usize], z: &mut [f64], arg: &mut [usize]) {
    edt_1d(f, d, v, z);
    if d.first().is_none_or(|x| !x.is_finite()) {
        return;
    }
    // Recover the winning parabola per sample by the same envelope walk.
    let mut k = 0;
    for (q, a) in arg.iter_mut().enumerate() {
        while z[k + 1] < q as f64 {
            k += 1;
        }
        *a = v[k];
    }
}

/// 1D squared distance transform of the sampled function `f` (∞ = no feature).
fn edt_1d(f: &[f64], d: &mut [f64], v: &mut [usize], z: &mut [f64]) {
    let n = f.len();
    let Some(first) = f.iter().position(|x| x.is_finite()) else {
        d.fill(f64::INFINITY);
        return;
    };
    let mut k = 0;
    v[0] = first;
    z[0] = f64::NEG_INFINITY;
    z[1] = f64::INFINITY;
    for q in first + 1..n {
        if !f[q].is_finite() {
            continue;
        }
        let parabola_cut = |p: usize| {
            ((f[q] + (q * q) as f64) - (f[p] + (p * p) as f64)) / (2.0 * (q as f64 - p as f64))
        };
        let mut s = parabola_cut(v[k]);
        // z[0] is −∞, so this never pops the first parabola.
        while s <= z[k] {
            k -= 1;
            s = parabola_cut(v[k]);
        }
        k += 1;
        v[k] = q;
        z[k] = s;
        z[k + 1] = f64::INFINITY;
    }
    let mut k = 0;
    for (q, out) in d.iter_mut().enumerate() {
        while z[k + 1] < q as f64 {
            k += 1;
        }
        let p = v[k];
        let dq = q as f64 - p as f64;
        *out = dq * dq + f[p];
    }
}

/// φ of eq. 3/6 for a silhouette: inside, the distance to the nearest outside pixel minus ½;
/// outside, minus (the distance to the nearest inside pixel minus ½). So the zero level lies
/// half-way between neighbouring inside and outside pixels. An empty mask gives −(w+h)
/// everywhere, a full one +(w+h).
pub fn signed_distance(mask: &Mask) -> DistanceMap {
    let far = (mask.width + mask.height) as f32;
    let to_inside = squared_edt(mask);
    let to_outside = squared_edt(&mask.map(|&m| !m));
    let data = mask
        .data
        .iter()
        .zip(to_inside.data.iter().zip(&to_outside.data))
        .map(|(&inside, (&di, &doo))| {
            if inside {
                if doo.is_finite() {
                    doo.sqrt() - 0.5
                } else {
                    far
                }
            } else if di.is_finite() {
                -(di.sqrt() - 0.5)
            } else {
                -far
            }
        })
        .collect();
    Plane {
        width: mask.width,
        height: mask.height,
        data,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn brute_squared(features: &Mask) -> Vec<f32> {
        let pts: Vec<(i64, i64)> = (0..features.height)
            .flat_map(|y| (0..features.width).map(move |x| (x, y)))
            .filter(|&(x, y)| *features.get(x, y))
            .map(|(x, y)| (x as i64, y as i64))
            .collect();
        (0..features.height)
            .flat_map(|y| (0..features.width).map(move |x| (x as i64, y as i64)))
            .map(|(x, y)| {
                pts.iter()
                    .map(|&(a, b)| ((a - x).pow(2) + (b - y).pow(2)) as f32)
                    .fold(f32::INFINITY, f32::min)
            })
            .collect()
    }

    #[test]
    fn cropped_transforms_equal_the_whole_frame_ones() {
        let mut rng = Rng::new(52);
        for trial in 0..80 {
            let (w, h) = (1 + rng.below(50), 1 + rng.below(40));
            // A blob somewhere (touching the edges sometimes) plus specks.
            let (cx, cy, r) = (
                rng.range(-5.0, w as f64 + 5.0),
                rng.range(-5.0, h as f64 + 5.0),
                rng.range(0.0, 12.0),
            );
            let density = [0.0, 0.0, 0.002, 0.02][trial % 4];
            let mask = Plane::from_vec(
                w,
                h,
                (0..w * h)
                    .map(|i| {
                        let (x, y) = ((i % w) as f64, (i / w) as f64);
                        (x - cx).hypot(y - cy) < r || rng.uniform() < density
                    })
                    .collect(),
            )
            .unwrap();
            let radius = rng.range(0.0, 9.0);
            let whole = squared_edt(&mask).map(|&d| (d as f64) <= radius * radius);
            assert_eq!(dilate(&mask, radius), whole, "dilate {w}x{h} r {radius}");
            let inside_whole = squared_edt(&mask.map(|&v| !v));
            let inside = squared_depth_inside(&mask);
            for (i, &m) in mask.data.iter().enumerate() {
                let want = if m { inside_whole.data[i] } else { 0.0 };
                assert_eq!(inside.data[i], want, "depth {w}x{h} pixel {i}");
            }
        }
    }

    /// The row-window test equals a threshold of the transform, margins inside and beyond its
    /// row windows (the transform's path), negative and infinite ones included, on blobs
    /// touching the image's edges.
    #[test]
    fn deep_inside_equals_the_thresholded_depth() {
        let mut rng = Rng::new(53);
        for trial in 0..120 {
            let (w, h) = (1 + rng.below(60), 1 + rng.below(45));
            let (cx, cy, r) = (
                rng.range(-5.0, w as f64 + 5.0),
                rng.range(-5.0, h as f64 + 5.0),
                rng.range(0.0, 25.0),
            );
            let holes = [0.0, 0.002, 0.02, 0.2][trial % 4];
            let mask = Plane::from_vec(
                w,
                h,
                (0..w * h)
                    .map(|i| {
                        let (x, y) = ((i % w) as f64, (i / w) as f64);
                        (x - cx).hypot(y - cy) < r && rng.uniform() >= holes
                    })
                    .collect(),
            )
            .unwrap();
            let depth = squared_depth_inside(&mask);
            for margin in [
                0.0f32,
                0.5,
                1.0,
                1.5,
                2.0,
                2.9,
                3.0,
                3.2,
                7.0,
                16.0,
                17.5,
                f32::NAN,
                -2.0,
                -0.5,
                f32::INFINITY,
                f32::NEG_INFINITY,
            ] {
                let want: Vec<bool> = (0..w * h)
                    .map(|i| mask.data[i] && depth.data[i] >= margin * margin)
                    .collect();
                assert_eq!(
                    deep_inside(&mask, margin).data,
                    want,
                    "{w}x{h}, margin {margin}, trial {trial}"
                );
            }
        }
        // Every pixel true: no `false` pixel anywhere, every pixel deep.
        let full = Plane::filled(7, 5, true);
        assert!(deep_inside(&full, 3.0).data.iter().all(|&d| d));
    }

    #[test]
    fn edt_equals_brute_force_on_random_masks() {
        let mut rng = Rng::new(51);
        for trial in 0..60 {
            let (w, h) = (1 + rng.below(40), 1 + rng.below(30));
            let density = [0.0, 0.002, 0.02, 0.2, 0.7][trial % 5];
            let mask = Plane::from_vec(w, h, (0..w * h).map(|_| rng.uniform() < density).collect())
                .unwrap();
            let fast = squared_edt(&mask);
            assert_eq!(fast.data, brute_squared(&mask), "{w}x{h} density {density}");
        }
    }

    #[test]
    fn nearest_feature_points_at_a_nearest_pixel() {
        let mut rng = Rng::new(53);
        for _ in 0..40 {
            let (w, h) = (1 + rng.below(40), 1 + rng.below(30));
            let mask =
                Plane::from_vec(w, h, (0..w * h).map(|_| rng.uniform() < 0.05).collect()).unwrap();
            let (dist, index) = nearest_feature(&mask);
            assert_eq!(dist.data, brute_squared(&mask));
            for i in 0..w * h {
                let j = index.data[i];
                if dist.data[i].is_finite() {
                    let j = j as usize;
                    assert!(mask.data[j], "index points at a feature");
                    let d2 = ((j % w) as f32 - (i % w) as f32).powi(2)
                        + ((j / w) as f32 - (i / w) as f32).powi(2);
                    assert_eq!(d2, dist.data[i]);
                } else {
                    assert_eq!(j, u32::MAX);
                }
            }
        }
    }

    #[test]
    fn signed_distance_equals_brute_force_and_approximates_a_disc() {
        let mut rng = Rng::new(52);
        for _ in 0..20 {
            let (w, h) = (10 + rng.below(40), 10 + rng.below(40));
            let mask =
                Plane::from_vec(w, h, (0..w * h).map(|_| rng.uniform() < 0.4).collect()).unwrap();
            let phi = signed_distance(&mask);
            let din = brute_squared(&mask);
            let dout = brute_squared(&mask.map(|&m| !m));
            for i in 0..w * h {
                let expect = if mask.data[i] {
                    dout[i].sqrt() - 0.5
                } else {
                    -(din[i].sqrt() - 0.5)
                };
                assert!((phi.data[i] - expect).abs() < 1e-5);
                assert_eq!(phi.data[i] > 0.0, mask.data[i], "sign says inside");
            }
        }
        // A disc: φ is the signed distance to the circle within a pixel.
        let (w, h, r) = (64, 64, 20.0f64);
        let mask = Plane::from_vec(
            w,
            h,
            (0..w * h)
                .map(|i| ((i % w) as f64 - 31.5).hypot((i / w) as f64 - 31.5) < r)
                .collect(),
        )
        .unwrap();
        let phi = signed_distance(&mask);
        for i in 0..w * h {
            let truth = r - ((i % w) as f64 - 31.5).hypot((i / w) as f64 - 31.5);
            assert!(
                (phi.data[i] as f64 - truth).abs() < 1.0,
                "pixel {i}: {} vs {truth}",
                phi.data[i]
            );
        }
        let empty = signed_distance(&Plane::filled(5, 4, false));
        assert!(empty.data.iter().all(|&v| v == -9.0));
    }
}
