//! Per-pixel appearance features (paper §III): normalised RGB, YCbCr and local colour
//! histograms, plus box-smoothed colour at two scales, gradient magnitude and local contrast
//! (ilastik's usual extras, kept because they pay: see `benches/forest_vs_sklearn.md`).
//!
//! Every windowed feature comes from integral images, so its cost does not grow with the window,
//! and a single pixel's vector costs O(1) once a frame is prepared: the fit asks only for pixels
//! near contours. Window radii are given for a 960-px-wide image and scale with the width, so
//! pyramid levels see the same physical window. Features are quantised to u8 with fixed ranges,
//! so a model trained on one frame applies to any other.

use image::RgbImage;
use rayon::prelude::*;

/// Number of features per pixel.
pub const FEATURE_COUNT: usize = 29;
/// Bins per channel of the local histograms.
const HIST_BINS: usize = 4;

/// What each feature is, for reports and the app.
pub const FEATURE_NAMES: [&str; FEATURE_COUNT] = [
    "r/(r+g+b)",
    "g/(r+g+b)",
    "b/(r+g+b)",
    "Y",
    "Cb",
    "Cr",
    "hist Y 0",
    "hist Y 1",
    "hist Y 2",
    "hist Y 3",
    "hist Cb 0",
    "hist Cb 1",
    "hist Cb 2",
    "hist Cb 3",
    "hist Cr 0",
    "hist Cr 1",
    "hist Cr 2",
    "hist Cr 3",
    "mean Y small",
    "mean Cb small",
    "mean Cr small",
    "mean Y large",
    "mean Cb large",
    "mean Cr large",
    "gradient Y",
    "std Y",
    "mean Y context",
    "mean Cb context",
    "mean Cr context",
];

/// Window radii (px) at a 960-px-wide image.
const HIST_RADIUS_960: f64 = 5.0;
const SMALL_RADIUS_960: f64 = 3.0;
const LARGE_RADIUS_960: f64 = 10.0;
const CONTEXT_RADIUS_960: f64 = 16.0;

/// One pixel's features.
pub type FeatureVector = [u8; FEATURE_COUNT];

/// A frame prepared for feature queries: per-pixel channels and integral images.
pub struct FrameFeatures {
    width: usize,
    height: usize,
    /// Per pixel: nr, ng, nb, Y, Cb, Cr (u8).
    base: Vec<[u8; 6]>,
    /// Integral images ((w+1)×(h+1)) of: the 12 histogram indicators, Y, Cb, Cr.
    integrals: Vec<Vec<u32>>,
    /// Integral of Y², for the local standard deviation.
    integral_y2: Vec<u64>,
    radii: [usize; 4],
    /// Where this (possibly cropped) image sits in the full frame, and the full frame's size.
    offset: (usize, usize),
    full: (usize, usize),
}

/// How far (px) from a pixel the features of a `width`-wide frame look: the widest window
/// plus the gradient's two pixels.
pub fn reach_for_width(width: usize) -> usize {
    [
        HIST_RADIUS_960,
        SMALL_RADIUS_960,
        LARGE_RADIUS_960,
        CONTEXT_RADIUS_960,
    ]
    .iter()
    .map(|&r| radius_for(width, r))
    .max()
    .unwrap_or(1)
        + 2
}

fn radius_for(width: usize, r960: f64) -> usize {
    ((r960 * width as f64 / 960.0).round() as usize).max(1)
}

/// Recycled summed-area tables: the fit builds features over a fresh region of every frame.
/// Only a table's first row and column are cleared: [`FrameFeatures::build`] writes every other
/// entry before reading it.
static TABLES_U32: crate::pool::Pool<u32> = crate::pool::Pool::new();
static TABLES_U64: crate::pool::Pool<u64> = crate::pool::Pool::new();

/// A (`rows` × `stride`) summed-area table from `pool`, first row and column zero.
fn table<T: Copy + Default>(pool: &crate::pool::Pool<T>, stride: usize, rows: usize) -> Vec<T> {
    let mut buf = pool.take(stride * rows, T::default());
    let first = stride.min(buf.len());
    buf[..first].fill(T::default());
    for row in buf.chunks_exact_mut(stride.max(1)) {
        row[0] = T::default();
    }
    buf
}

impl Drop for FrameFeatures {
    fn drop(&mut self) {
        TABLES_U32.give(std::mem::take(&mut self.integrals));
        TABLES_U64.give([std::mem::take(&mut self.integral_y2)]);
    }
}

impl FrameFeatures {
    pub fn new(frame: &RgbImage) -> Self {
        let full = (frame.width() as usize, frame.height() as usize);
        Self::build(frame, full, (0, 0))
    }

    /// Features of the pixels inside `(x0, y0, w, h)` of `frame` only: integral images cost
    /// the region, not the frame. Window radii still follow the full frame's width, and
    /// [`FrameFeatures::valid`] says where results equal whole-frame ones.
    pub fn region(frame: &RgbImage, x0: usize, y0: usize, w: usize, h: usize) -> Self {
        let full = (frame.width() as usize, frame.height() as usize);
        let (x0, y0) = (
            x0.min(full.0.saturating_sub(1)),
            y0.min(full.1.saturating_sub(1)),
        );
        let (w, h) = (w.clamp(1, full.0 - x0), h.clamp(1, full.1 - y0));
        let crop =
            image::imageops::crop_imm(frame, x0 as u32, y0 as u32, w as u32, h as u32).to_image();
        Self::build(&crop, full, (x0, y0))
    }

    /// Largest window radius (px) any feature reaches, plus the gradient's.
    pub fn reach(&self) -> usize {
        reach_for_width(self.full.0)
    }

    /// Does the full-frame pixel (x, y) get exactly its whole-frame features here? True when
    /// every window around it lies inside the region or is clipped by the frame itself.
    pub fn valid(&self, x: usize, y: usize) -> bool {
        let m = self.reach();
        let (ox, oy) = self.offset;
        let axis = |p: usize, o: usize, len: usize, full: usize| {
            (p >= o && p < o + len)
                && (p >= o + m || o == 0)
                && (p + m < o + len || o + len == full)
        };
        axis(x, ox, self.width, self.full.0) && axis(y, oy, self.height, self.full.1)
    }

    fn build(frame: &RgbImage, full: (usize, usize), offset: (usize, usize)) -> Self {
        let (w, h) = (frame.width() as usize, frame.height() as usize);
        let base: Vec<[u8; 6]> = frame
            .as_raw()
            .par_chunks_exact(3)
            .with_min_len(4096)
            .map(|p| base_channels(p[0], p[1], p[2]))
            .collect();
        // 16 summed-area tables (12 histogram bins, 3 channel sums, Y²), filled in two fused
        // passes that run in parallel: one read of each pixel per pass instead of one per table.
        let stride = w + 1;
        // `add` adds a pixel's contribution to each table's running row sum.
        let fill = |tables: usize, squares: bool, add: &(dyn Fn(&[u8; 6], &mut [u32]) + Sync)| {
            let mut out: Vec<Vec<u32>> = (0..tables)
                .map(|_| table(&TABLES_U32, stride, h + 1))
                .collect();
            let mut y2 = if squares {
                table(&TABLES_U64, stride, h + 1)
            } else {
                Vec::new()
            };
            let mut row = vec![0u32; tables];
            for y in 0..h {
                row.fill(0);
                let mut row2 = 0u64;
                for x in 0..w {
                    let px = &base[y * w + x];
                    add(px, &mut row);
                    let (o, up) = ((y + 1) * stride + x + 1, y * stride + x + 1);
                    for (t, &r) in out.iter_mut().zip(&row) {
                        t[o] = t[up] + r;
                    }
                    if squares {
                        let v = px[3] as u64;
                        row2 += v * v;
                        y2[o] = y2[up] + row2;
                    }
                }
            }
            (out, y2)
        };
        let bin = |v: u8| v as usize * HIST_BINS / 256;
        let ((mut integrals, _), (rest, integral_y2)) = rayon::join(
            // Histograms of Y and Cb.
            || {
                fill(2 * HIST_BINS, false, &|px, row| {
                    row[bin(px[3])] += 1;
                    row[HIST_BINS + bin(px[4])] += 1;
                })
            },
            // Histogram of Cr, the Y, Cb, Cr sums and Y².
            || {
                fill(HIST_BINS + 3, true, &|px, row| {
                    row[bin(px[5])] += 1;
                    for c in 0..3 {
                        row[HIST_BINS + c] += px[3 + c] as u32;
                    }
                })
            },
        );
        integrals.extend(rest);
        let reference = full.0;
        let radii = [
            radius_for(reference, HIST_RADIUS_960),
            radius_for(reference, SMALL_RADIUS_960),
            radius_for(reference, LARGE_RADIUS_960),
            radius_for(reference, CONTEXT_RADIUS_960),
        ];
        Self {
            offset,
            full,
            width: w,
            height: h,
            base,
            integrals,
            integral_y2,
            radii,
        }
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn height(&self) -> usize {
        self.height
    }

    /// The feature vector of pixel (x, y).
    pub fn at(&self, x: usize, y: usize) -> FeatureVector {
        let (w, h) = (self.width, self.height);
        let mut f = [0u8; FEATURE_COUNT];
        let px = &self.base[y * w + x];
        f[..6].copy_from_slice(px);
        let q = |v: f64| (v.clamp(0.0, 255.0) + 0.5) as u8;
        let [rh, rs, rl, rc] = self.radii;
        for k in 0..3 * HIST_BINS {
            let (sum, area) = box_sum(&self.integrals[k], w, h, x, y, rh);
            f[6 + k] = q(255.0 * sum as f64 / area as f64);
        }
        for (j, r) in [rs, rl].into_iter().enumerate() {
            for c in 0..3 {
                let (sum, area) = box_sum(&self.integrals[3 * HIST_BINS + c], w, h, x, y, r);
                f[18 + 3 * j + c] = q(sum as f64 / area as f64);
            }
        }
        // Y smoothed over 3×3, at the four neighbours only (cheaper than a plane when only
        // pixels near contours are asked for).
        let iy = &self.integrals[3 * HIST_BINS];
        let s = |xx: usize, yy: usize| {
            let (sum, area) = box_sum(iy, w, h, xx.min(w - 1), yy.min(h - 1), 1);
            sum as f32 / area as f32
        };
        let (xl, xr, yu, yd) = (x.saturating_sub(1), x + 1, y.saturating_sub(1), y + 1);
        let gx = s(xr, y) - s(xl, y);
        let gy = s(x, yd) - s(x, yu);
        f[24] = q(2.0 * (gx * gx + gy * gy).sqrt() as f64);
        let (sum, area) = box_sum(&self.integrals[3 * HIST_BINS], w, h, x, y, rs);
        let (sum2, _) = box_sum64(&self.integral_y2, w, h, x, y, rs);
        let mean = sum as f64 / area as f64;
        let var = (sum2 as f64 / area as f64 - mean * mean).max(0.0);
        f[25] = q(4.0 * var.sqrt());
        for c in 0..3 {
            let (sum, area) = box_sum(&self.integrals[3 * HIST_BINS + c], w, h, x, y, rc);
            f[26 + c] = q(sum as f64 / area as f64);
        }
        f
    }

    /// Features of every pixel, row-major.
    pub fn all(&self) -> Vec<FeatureVector> {
        (0..self.width * self.height)
            .into_par_iter()
            .map(|i| self.at(i % self.width, i / self.width))
            .collect()
    }

    /// Features of the listed full-frame pixels (x, y); each must lie in the region.
    pub fn pixels(&self, list: &[(u32, u32)]) -> Vec<FeatureVector> {
        let (ox, oy) = self.offset;
        list.par_iter()
            .map(|&(x, y)| {
                self.at(
                    (x as usize).saturating_sub(ox).min(self.width - 1),
                    (y as usize).saturating_sub(oy).min(self.height - 1),
                )
            })
            .collect()
    }
}

/// 255·c / (r + g + b) in 16.16 fixed point, per channel sum 0…765 (0 for black).
fn reciprocals() -> &'static [u32; 766] {
    static TABLE: std::sync::OnceLock<[u32; 766]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        let mut t = [0u32; 766];
        for (s, v) in t.iter_mut().enumerate().skip(1) {
            *v = ((255u64 << 16) as f64 / s as f64).round() as u32;
        }
        t
    })
}

/// nr, ng, nb, Y, Cb, Cr of one pixel, in 16.16 fixed point (the per-pixel cost of every
/// feature query region; floating-point division and libm rounding cost three times as much).
#[inline]
fn base_channels(r: u8, g: u8, b: u8) -> [u8; 6] {
    let (r, g, b) = (r as i64, g as i64, b as i64);
    let recip = reciprocals()[(r + g + b) as usize] as i64;
    // 0.299, 0.587, 0.114 × 65536 (sum 65536).
    let y16 = 19595 * r + 38470 * g + 7471 * b;
    // Cb = 128 + 0.564 (B − Y), Cr = 128 + 0.713 (R − Y).
    let cb16 = (128 << 16) + ((36962 * ((b << 16) - y16)) >> 16);
    let cr16 = (128 << 16) + ((46727 * ((r << 16) - y16)) >> 16);
    let q = |v16: i64| ((v16 + 32768) >> 16).clamp(0, 255) as u8;
    [
        q(r * recip),
        q(g * recip),
        q(b * recip),
        q(y16),
        q(cb16),
        q(cr16),
    ]
}

/// Corners (x0, y0, x1, y1; end exclusive) of the window of radius r around (x, y), clipped
/// to a w × h image.
#[inline]
fn window(w: usize, h: usize, x: usize, y: usize, r: usize) -> (usize, usize, usize, usize) {
    (
        x.saturating_sub(r),
        y.saturating_sub(r),
        (x + r + 1).min(w),
        (y + r + 1).min(h),
    )
}

/// Sum and pixel count of the window of radius r around (x, y), clipped to the image.
#[inline]
fn box_sum(table: &[u32], w: usize, h: usize, x: usize, y: usize, r: usize) -> (u32, u32) {
    let (x0, y0, x1, y1) = window(w, h, x, y, r);
    let s = w + 1;
    let sum = table[y1 * s + x1]
        .wrapping_sub(table[y0 * s + x1])
        .wrapping_sub(table[y1 * s + x0])
        .wrapping_add(table[y0 * s + x0]);
    (sum, ((x1 - x0) * (y1 - y0)) as u32)
}

#[inline]
fn box_sum64(table: &[u64], w: usize, h: usize, x: usize, y: usize, r: usize) -> (u64, u64) {
    let (x0, y0, x1, y1) = window(w, h, x, y, r);
    let s = w + 1;
    let sum = table[y1 * s + x1] + table[y0 * s + x0] - table[y0 * s + x1] - table[y1 * s + x0];
    (sum, ((x1 - x0) * (y1 - y0)) as u64)
}

/// Halves a frame by 2×2 averaging (one pyramid level).
pub fn downsample(frame: &RgbImage) -> RgbImage {
    let (sw, sh) = (frame.width() as usize, frame.height() as usize);
    let (w, h) = ((sw / 2).max(1), (sh / 2).max(1));
    let src = frame.as_raw();
    let mut out = vec![0u8; w * h * 3];
    out.par_chunks_mut(w * 3).enumerate().for_each(|(y, row)| {
        let (y0, y1) = ((2 * y).min(sh - 1), (2 * y + 1).min(sh - 1));
        for x in 0..w {
            let (x0, x1) = ((2 * x).min(sw - 1), (2 * x + 1).min(sw - 1));
            for c in 0..3 {
                let v = src[(y0 * sw + x0) * 3 + c] as u32
                    + src[(y0 * sw + x1) * 3 + c] as u32
                    + src[(y1 * sw + x0) * 3 + c] as u32
                    + src[(y1 * sw + x1) * 3 + c] as u32;
                row[x * 3 + c] = ((v + 2) / 4) as u8;
            }
        }
    });
    RgbImage::from_raw(w as u32, h as u32, out).unwrap_or_else(|| RgbImage::new(w as u32, h as u32))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// Windowed features equal brute-force sums over the clipped window.
    #[test]
    fn integral_features_match_brute_force() {
        let mut rng = Rng::new(71);
        let (w, h) = (97usize, 53usize);
        let frame = RgbImage::from_fn(w as u32, h as u32, |_, _| {
            image::Rgb([
                rng.below(256) as u8,
                rng.below(256) as u8,
                rng.below(256) as u8,
            ])
        });
        // Leave dirty tables in the pool first: recycled tables must give the same sums as
        // fresh ones (only their first row and column are cleared).
        let other = RgbImage::from_fn(w as u32 + 13, h as u32 + 7, |x, y| {
            image::Rgb([(x * 7 + y) as u8, (y * 5) as u8, 255])
        });
        drop(FrameFeatures::new(&other));
        drop(FrameFeatures::new(&other));
        let ff = FrameFeatures::new(&frame);
        let all = ff.all();
        let [rh, rs, rl, _] = ff.radii;
        for _ in 0..300 {
            let (x, y) = (rng.below(w), rng.below(h));
            let f = all[y * w + x];
            assert_eq!(f, ff.at(x, y));
            let window = |r: usize| -> Vec<[u8; 6]> {
                let mut v = Vec::new();
                for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                    for xx in x.saturating_sub(r)..(x + r + 1).min(w) {
                        v.push(ff.base[yy * w + xx]);
                    }
                }
                v
            };
            let win = window(rh);
            for ch in 0..3 {
                for bin in 0..HIST_BINS {
                    let n = win
                        .iter()
                        .filter(|p| p[3 + ch] as usize * HIST_BINS / 256 == bin)
                        .count();
                    let expect = (255.0 * n as f64 / win.len() as f64).round() as u8;
                    assert_eq!(
                        f[6 + ch * HIST_BINS + bin],
                        expect,
                        "hist ch {ch} bin {bin}"
                    );
                }
            }
            for (j, r) in [rs, rl].into_iter().enumerate() {
                let win = window(r);
                for c in 0..3 {
                    let mean = win.iter().map(|p| p[3 + c] as f64).sum::<f64>() / win.len() as f64;
                    assert_eq!(f[18 + 3 * j + c], mean.round() as u8);
                }
            }
            let win = window(rs);
            let mean = win.iter().map(|p| p[3] as f64).sum::<f64>() / win.len() as f64;
            let var = win
                .iter()
                .map(|p| (p[3] as f64 - mean).powi(2))
                .sum::<f64>()
                / win.len() as f64;
            assert!((f[25] as f64 - (4.0 * var.sqrt()).min(255.0)).abs() <= 1.0);
        }
        // Histogram fractions of one channel sum to one window.
        let f = ff.at(40, 20);
        let total: u32 = f[6..10].iter().map(|&v| v as u32).sum();
        assert!((253..=257).contains(&total), "{total}");
    }

    #[test]
    fn region_features_equal_whole_frame_features_where_valid() {
        let mut rng = Rng::new(72);
        let frame = RgbImage::from_fn(200, 120, |_, _| {
            image::Rgb([
                rng.below(256) as u8,
                rng.below(256) as u8,
                rng.below(256) as u8,
            ])
        });
        let whole = FrameFeatures::new(&frame);
        for (x0, y0, w, h) in [(30, 20, 100, 70), (0, 0, 90, 50), (120, 60, 80, 60)] {
            let region = FrameFeatures::region(&frame, x0, y0, w, h);
            let mut checked = 0;
            for y in 0..120 {
                for x in 0..200 {
                    if region.valid(x, y) {
                        assert_eq!(
                            region.pixels(&[(x as u32, y as u32)])[0],
                            whole.at(x, y),
                            "pixel ({x},{y}) of region ({x0},{y0},{w},{h})"
                        );
                        checked += 1;
                    }
                }
            }
            assert!(
                checked > 100,
                "region ({x0},{y0},{w},{h}): {checked} valid pixels"
            );
        }
    }

    #[test]
    fn radii_scale_with_width_and_downsample_halves() {
        assert_eq!(radius_for(960, LARGE_RADIUS_960), 10);
        assert_eq!(radius_for(480, LARGE_RADIUS_960), 5);
        assert_eq!(radius_for(1920, LARGE_RADIUS_960), 20);
        let img = RgbImage::from_fn(5, 4, |x, _| image::Rgb([x as u8 * 10, 0, 0]));
        let d = downsample(&img);
        assert_eq!((d.width(), d.height()), (2, 2));
        assert_eq!(d.get_pixel(0, 0).0[0], 5);
    }
}
