//! Every pixel's features at once, for whole probability maps (`classify`, the app's maps, the
//! first frame of `track`). The arithmetic is [`FrameFeatures::at`]'s, bit for bit: the same
//! integer window sums, the same f32 operations on them. Only the layout differs. The fit's
//! sparse queries want one interleaved summed-area table (a window's corners give every
//! channel in four reads); a whole frame wants one table per channel, so that a scale's windows
//! along a row are four contiguous slices the compiler vectorises, and a row's features are
//! written feature by feature into a row buffer, then transposed once. At 960×540 on one core
//! a whole frame's features took 329 ms before and take 147 ms (`cargo bench --bench
//! features_speed`; 1920×1080: 1,318 → 550 ms).
//!
//! [`FrameFeatures::at`]: super::FrameFeatures::at

use super::features::{
    BANK_CHANNELS, CHANNELS, FeatureVector, RECIPROCAL, SCALES, base_of, deviation, difference,
    gradient, mean, quantise, radii_at,
};
use crate::appearance::FEATURE_COUNT;
use image::RgbImage;
use rayon::prelude::*;

/// The features of every pixel of `frame`, pyramid level `level` of its source, row-major.
pub fn frame(frame: &RgbImage, level: usize) -> Vec<FeatureVector> {
    let (w, h) = (frame.width() as usize, frame.height() as usize);
    from_base(&base_of(frame), w, h, radii_at(level))
}

/// The features of every pixel from its channels (`base`, w × h, row-major).
pub(super) fn from_base(
    base: &[[u8; CHANNELS]],
    w: usize,
    h: usize,
    radii: [usize; SCALES],
) -> Vec<FeatureVector> {
    let mut out = vec![[0u8; FEATURE_COUNT]; w * h];
    if w == 0 || h == 0 {
        return out;
    }
    let sums: Vec<Vec<u32>> = (0..CHANNELS)
        .into_par_iter()
        .map(|c| table(base, w, h, |p| p[c] as u32))
        .collect();
    let squares: Vec<Vec<u32>> = (0..BANK_CHANNELS)
        .into_par_iter()
        .map(|c| table(base, w, h, |p| (p[c] as u32).pow(2)))
        .collect();
    let tables = Tables {
        w,
        h,
        radii,
        sums,
        squares,
    };
    out.par_chunks_mut(w).enumerate().for_each_init(
        || Scratch::new(w),
        |scratch, (y, row)| tables.row(base, y, row, scratch),
    );
    out
}

/// The ((w+1)×(h+1)) summed-area table of one value per pixel. Sums wrap: a window's sum is
/// below 2³² (625 · 255² at most), so the difference of four corners is exact.
fn table(
    base: &[[u8; CHANNELS]],
    w: usize,
    h: usize,
    value: impl Fn(&[u8; CHANNELS]) -> u32,
) -> Vec<u32> {
    let s = w + 1;
    let mut t = vec![0u32; s * (h + 1)];
    for (y, row) in t.chunks_exact_mut(s).skip(1).enumerate() {
        let mut acc = 0u32;
        for (cell, px) in row[1..].iter_mut().zip(&base[y * w..(y + 1) * w]) {
            acc = acc.wrapping_add(value(px));
            *cell = acc;
        }
    }
    // Down the columns, a whole row at a time (vectorised across it).
    for y in 2..=h {
        let (above, below) = t.split_at_mut(y * s);
        let prev = &above[(y - 1) * s..];
        for (cell, &p) in below[..s].iter_mut().zip(prev) {
            *cell = cell.wrapping_add(p);
        }
    }
    t
}

struct Tables {
    w: usize,
    h: usize,
    radii: [usize; SCALES],
    /// Per channel: its summed-area table.
    sums: Vec<Vec<u32>>,
    /// Per bank channel: the summed-area table of its squares.
    squares: Vec<Vec<u32>>,
}

/// Row buffers, one set per worker.
struct Scratch {
    /// The row's features, feature-major (feature k of pixel x at k·w + x): every loop writes
    /// a contiguous run, and one blocked transpose at the end writes the pixels' vectors.
    planes: Vec<u8>,
    means: Vec<Vec<f32>>,
    sums: Vec<u32>,
    squares: Vec<u32>,
    /// Sums of the windows above and below, before their means.
    other: Vec<u32>,
    up: Vec<f32>,
    down: Vec<f32>,
}

impl Scratch {
    fn new(w: usize) -> Self {
        Self {
            planes: vec![0; FEATURE_COUNT * w],
            means: vec![vec![0.0; w]; SCALES],
            sums: vec![0; w],
            squares: vec![0; w],
            other: vec![0; w],
            up: vec![0.0; w],
            down: vec![0.0; w],
        }
    }
}

/// The pixel count along x of the window of radius r around x, clipped to [0, w).
#[inline]
fn span(x: usize, r: usize, w: usize) -> usize {
    (x + r + 1).min(w) - x.saturating_sub(r)
}

/// The x range [lo, hi) whose windows of radius r lie wholly inside [0, w): there the loops
/// run without clamps (and vectorise); outside it they clamp as [`FrameFeatures::at`] does.
///
/// [`FrameFeatures::at`]: super::FrameFeatures::at
#[inline]
fn unclipped(r: usize, w: usize) -> (usize, usize) {
    let lo = r.min(w);
    (lo, w.saturating_sub(r).max(lo))
}

impl Tables {
    /// Sums of table `t` over the windows of radius `r` centred on row `yc`, for every x;
    /// returns the windows' row count.
    fn window_sums(&self, t: &[u32], yc: usize, r: usize, out: &mut [u32]) -> usize {
        let (w, h) = (self.w, self.h);
        let s = w + 1;
        let (y0, y1) = (yc.saturating_sub(r), (yc + r + 1).min(h));
        let (top, bottom) = (&t[y0 * s..(y0 + 1) * s], &t[y1 * s..(y1 + 1) * s]);
        let corners = |x0: usize, x1: usize| {
            bottom[x1]
                .wrapping_sub(top[x1])
                .wrapping_sub(bottom[x0])
                .wrapping_add(top[x0])
        };
        let (lo, hi) = unclipped(r, w);
        let n = hi - lo;
        if n > 0 {
            let (b1, t1) = (&bottom[lo + r + 1..][..n], &top[lo + r + 1..][..n]);
            let (b0, t0) = (&bottom[lo - r..][..n], &top[lo - r..][..n]);
            for ((((o, &a), &b), &c), &d) in out[lo..hi].iter_mut().zip(b1).zip(t1).zip(b0).zip(t0)
            {
                *o = a.wrapping_sub(b).wrapping_sub(c).wrapping_add(d);
            }
        }
        for x in (0..lo).chain(hi..w) {
            out[x] = corners(x.saturating_sub(r), (x + r + 1).min(w));
        }
        y1 - y0
    }

    /// Means from window sums (`rows`: the windows' row count).
    fn means(&self, sums: &[u32], r: usize, rows: usize, out: &mut [f32]) {
        let w = self.w;
        let (lo, hi) = unclipped(r, w);
        let inner = RECIPROCAL[(2 * r + 1) * rows];
        for (m, &s) in out[lo..hi].iter_mut().zip(&sums[lo..hi]) {
            *m = s as f32 * inner;
        }
        for x in (0..lo).chain(hi..w) {
            out[x] = mean(sums[x], (span(x, r, w) * rows) as u32);
        }
    }

    /// Deviations of the windows from their sums and sums of squares.
    fn deviations(&self, sums: &[u32], squares: &[u32], r: usize, rows: usize, out: &mut [u8]) {
        let w = self.w;
        let (lo, hi) = unclipped(r, w);
        let inner = ((2 * r + 1) * rows) as u32;
        for ((o, &s), &q) in out[lo..hi]
            .iter_mut()
            .zip(&sums[lo..hi])
            .zip(&squares[lo..hi])
        {
            *o = deviation(s, q, inner);
        }
        for x in (0..lo).chain(hi..w) {
            out[x] = deviation(sums[x], squares[x], (span(x, r, w) * rows) as u32);
        }
    }

    /// Gradients: the means a radius ahead minus those a radius behind, across (`means` of
    /// this row, clamped at the row's ends) and down (`down` − `up`).
    fn gradients(&self, means: &[f32], up: &[f32], down: &[f32], r: usize, out: &mut [u8]) {
        let w = self.w;
        let (lo, hi) = unclipped(r, w);
        let n = hi - lo;
        if n > 0 {
            let (ahead, behind) = (&means[lo + r..][..n], &means[lo - r..][..n]);
            for ((((o, &a), &b), &u), &d) in out[lo..hi]
                .iter_mut()
                .zip(ahead)
                .zip(behind)
                .zip(&up[lo..hi])
                .zip(&down[lo..hi])
            {
                *o = gradient(a - b, d - u);
            }
        }
        for x in (0..lo).chain(hi..w) {
            let gx = means[(x + r).min(w - 1)] - means[x.saturating_sub(r)];
            out[x] = gradient(gx, down[x] - up[x]);
        }
    }

    /// One row of features.
    fn row(&self, base: &[[u8; CHANNELS]], y: usize, out: &mut [FeatureVector], sc: &mut Scratch) {
        let (w, h) = (self.w, self.h);
        let mut planes = std::mem::take(&mut sc.planes);
        let mut plane = planes.chunks_exact_mut(w);
        let mut next = || plane.next().expect("one plane per feature");
        for c in 0..CHANNELS {
            for (v, px) in next().iter_mut().zip(&base[y * w..(y + 1) * w]) {
                *v = px[c];
            }
            for (i, &r) in self.radii.iter().enumerate() {
                let rows = self.window_sums(&self.sums[c], y, r, &mut sc.sums);
                self.means(&sc.sums, r, rows, &mut sc.means[i]);
                for (v, &m) in next().iter_mut().zip(&sc.means[i]) {
                    *v = quantise(m);
                }
                if c < BANK_CHANNELS {
                    self.window_sums(&self.squares[c], y, r, &mut sc.squares);
                    self.deviations(&sc.sums, &sc.squares, r, rows, next());
                    let (yu, yd) = (y.saturating_sub(r), (y + r).min(h - 1));
                    let rows_up = self.window_sums(&self.sums[c], yu, r, &mut sc.other);
                    self.means(&sc.other, r, rows_up, &mut sc.up);
                    let rows_down = self.window_sums(&self.sums[c], yd, r, &mut sc.other);
                    self.means(&sc.other, r, rows_down, &mut sc.down);
                    self.gradients(&sc.means[i], &sc.up, &sc.down, r, next());
                }
            }
            if c < BANK_CHANNELS {
                for i in 0..SCALES - 1 {
                    let (a, b) = (&sc.means[i], &sc.means[i + 1]);
                    for ((v, &a), &b) in next().iter_mut().zip(a).zip(b) {
                        *v = difference(a, b);
                    }
                }
            }
        }
        debug_assert!(plane.next().is_none(), "every feature written");
        // Feature-major to pixel-major, 64 pixels at a time (their vectors stay in cache).
        for (block, pixels) in out.chunks_mut(64).enumerate() {
            let x0 = block * 64;
            for (k, values) in planes.chunks_exact(w).enumerate() {
                for (f, &v) in pixels.iter_mut().zip(&values[x0..]) {
                    f[k] = v;
                }
            }
        }
        sc.planes = planes;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::appearance::FrameFeatures;
    use crate::rng::Rng;

    /// Every pixel of the dense path equals the per-pixel path, on frames wider and narrower
    /// than the windows (the clipped borders are where the two differ in code).
    #[test]
    fn dense_features_equal_per_pixel_features_everywhere() {
        let mut rng = Rng::new(13);
        for (w, h) in [(61u32, 37u32), (30, 70), (5, 3), (1, 1), (26, 25), (24, 2)] {
            let img = RgbImage::from_fn(w, h, |_, _| {
                image::Rgb([
                    rng.below(256) as u8,
                    rng.below(256) as u8,
                    rng.below(256) as u8,
                ])
            });
            for level in [0, 1, 2] {
                let ff = FrameFeatures::at_level(&img, level);
                let dense = frame(&img, level);
                assert_eq!(dense.len(), (w * h) as usize);
                for y in 0..h as usize {
                    for x in 0..w as usize {
                        assert_eq!(
                            dense[y * w as usize + x],
                            ff.at(x, y),
                            "pixel ({x},{y}) of {w}×{h}, level {level}"
                        );
                    }
                }
            }
        }
    }

    /// A query of part of a region (computed densely over its box widened by the features'
    /// reach) equals the per-pixel query: discs in the middle, against a region's edge inside
    /// the frame, and at the frame's corner.
    #[test]
    fn a_query_of_part_of_a_region_computed_densely_equals_its_per_pixel_query() {
        let mut rng = Rng::new(19);
        let img = RgbImage::from_fn(220, 160, |_, _| {
            image::Rgb([
                rng.below(256) as u8,
                rng.below(256) as u8,
                rng.below(256) as u8,
            ])
        });
        let (x0, y0, w, h) = (12usize, 8usize, 190usize, 140usize);
        let ff = FrameFeatures::region(&img, 1, x0, y0, w, h);
        for (cx, cy) in [(110.0, 80.0), (20.0, 60.0), (60.0, 12.0)] {
            let list: Vec<(u32, u32)> = (y0..y0 + h)
                .flat_map(|y| (x0..x0 + w).map(move |x| (x, y)))
                .filter(|&(x, y)| (x as f64 - cx).hypot(y as f64 - cy) < 52.0)
                .map(|(x, y)| (x as u32, y as u32))
                .collect();
            // Enough pixels, and a third of their widened box, for the dense path.
            assert!(list.len() >= 4096, "{} pixels", list.len());
            assert!(
                ff.pixels_auto(&list) == ff.pixels(&list),
                "disc at ({cx},{cy})"
            );
        }
        let ff = FrameFeatures::region(&img, 1, 0, 0, 150, 120);
        let corner: Vec<(u32, u32)> = (0..70u32)
            .flat_map(|y| (0..70u32).map(move |x| (x, y)))
            .collect();
        assert!(
            ff.pixels_auto(&corner) == ff.pixels(&corner),
            "corner square"
        );
    }

    /// A region's many-pixel query (computed densely) equals its per-pixel query, on a region
    /// cut from the middle of a frame and one touching its corner, at two levels.
    #[test]
    fn a_regions_dense_query_equals_its_per_pixel_query() {
        let mut rng = Rng::new(17);
        let img = RgbImage::from_fn(150, 90, |_, _| {
            image::Rgb([
                rng.below(256) as u8,
                rng.below(256) as u8,
                rng.below(256) as u8,
            ])
        });
        for (x0, y0, w, h) in [(20usize, 10usize, 101usize, 67usize), (0, 0, 90, 60)] {
            for level in [0, 1] {
                let ff = FrameFeatures::region(&img, level, x0, y0, w, h);
                // Every pixel of the region: well over the dense path's threshold.
                let list: Vec<(u32, u32)> = (y0..y0 + h)
                    .flat_map(|y| (x0..x0 + w).map(move |x| (x as u32, y as u32)))
                    .collect();
                assert!(
                    ff.pixels_auto(&list) == ff.pixels(&list),
                    "region at ({x0},{y0})"
                );
            }
        }
    }
}
