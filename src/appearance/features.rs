//! Per-pixel appearance features (paper §III, widened by issue 13 to carry over to real
//! tissue): a multi-scale bank of box filters on CIELAB (L*, a*, b*) — value, local mean,
//! local standard deviation, gradient magnitude (Haar: the mean ahead minus the mean behind)
//! and difference of means between neighbouring scales — plus normalised red and green and
//! their local means. Chosen by held-out evaluation on real porcine nephrectomy frames, not on
//! the phantom (`cargo bench --bench appearance_heldout`): on the tuning frames this bank gave
//! kidney Dice 0.641 same-frame and 0.408 cross-frame where the earlier colour-histogram set gave
//! 0.605 and 0.374 (scikit-learn, same strokes); CIELAB beat YCbCr by 0.01–0.05.
//!
//! Scales are in pixels of the source frame (1, 2, 4, 8, 12 px), halved at each pyramid level
//! so every level sees the same physical window; they do not shrink with a small image's width.
//! Every windowed feature comes from integral images, so its cost does not grow with the window,
//! and one pixel's vector costs O(1) once a frame is prepared: the fit asks only for pixels near
//! contours. Features are quantised to u8 with fixed ranges, so a model trained on one frame
//! applies to any other.

use image::RgbImage;
use rayon::prelude::*;

/// Names this feature set in saved forests: a forest trained on another set is refused.
pub const FEATURE_SET: &str = "lab-box-72/1";

/// Window radii (px) at the source frame's resolution (pyramid level 0).
pub const RADII_PX: [usize; 5] = [1, 2, 4, 8, 12];
pub(super) const SCALES: usize = RADII_PX.len();
/// Channels with the whole bank (L*, a*, b*) and with value and means only (nr, ng).
pub(super) const BANK_CHANNELS: usize = 3;
const MEAN_CHANNELS: usize = 2;
pub(super) const CHANNELS: usize = BANK_CHANNELS + MEAN_CHANNELS;
/// Features of a bank channel: value; mean, deviation, gradient per scale; differences of
/// neighbouring scales' means.
const PER_BANK: usize = 1 + 3 * SCALES + (SCALES - 1);
const PER_MEAN: usize = 1 + SCALES;

/// Number of features per pixel.
pub const FEATURE_COUNT: usize = BANK_CHANNELS * PER_BANK + MEAN_CHANNELS * PER_MEAN;

const CHANNEL_NAMES: [&str; CHANNELS] = ["L*", "a*", "b*", "r/(r+g+b)", "g/(r+g+b)"];

/// What each feature is, for reports.
pub fn feature_names() -> Vec<String> {
    let mut names = Vec::with_capacity(FEATURE_COUNT);
    for (c, ch) in CHANNEL_NAMES.iter().enumerate() {
        names.push(ch.to_string());
        for r in RADII_PX {
            names.push(format!("mean {ch} r{r}"));
            if c < BANK_CHANNELS {
                names.push(format!("std {ch} r{r}"));
                names.push(format!("gradient {ch} r{r}"));
            }
        }
        if c < BANK_CHANNELS {
            for w in RADII_PX.windows(2) {
                names.push(format!("mean {ch} r{} - r{}", w[0], w[1]));
            }
        }
    }
    names
}

/// One pixel's features.
pub type FeatureVector = [u8; FEATURE_COUNT];

/// A frame prepared for feature queries: per-pixel channels and integral images.
pub struct FrameFeatures {
    pub(super) width: usize,
    pub(super) height: usize,
    /// Per pixel: L*, a*, b*, nr, ng (u8).
    pub(super) base: Vec<[u8; CHANNELS]>,
    /// Integral image ((w+1)×(h+1)) of every channel, interleaved: one window's corners give
    /// all channels' sums in four reads.
    pub(super) integrals: Vec<[u32; CHANNELS]>,
    /// Integral image of the bank channels' squares (interleaved), for the local deviation.
    pub(super) squares: Vec<[u32; BANK_CHANNELS]>,
    pub(super) radii: [usize; SCALES],
    /// Where this (possibly cropped) image sits in the full frame, and the full frame's size.
    offset: (usize, usize),
    full: (usize, usize),
}

/// Every pixel's channels (L*, a*, b*, nr, ng as u8), row-major.
pub(super) fn base_of(frame: &RgbImage) -> Vec<[u8; CHANNELS]> {
    let raw = frame.as_raw();
    let mut out = vec![[0u8; CHANNELS]; raw.len() / 3];
    out.par_chunks_mut(4096)
        .zip(raw.par_chunks(4096 * 3))
        .for_each(|(o, rgb)| base_channels_many(rgb, o));
    out
}

/// Below this many pixels [`FrameFeatures::pixels_auto`] always queries them one by one.
const DENSE_FROM_PIXELS: usize = 4096;

/// Pixels converted together by [`base_channels_many`]: the lanes of its vector arithmetic.
const LANES: usize = 8;

/// [`base_channels`] of every pixel of `rgb` (interleaved R, G, B) into `out`, equal bit for
/// bit: the same operations in the same order, on `LANES` pixels at once, in AVX2 intrinsics
/// where the CPU has them (`lab_avx2`, chosen at run time), else lane-wise Rust the compiler
/// vectorises as far as it can. The frame's CIELAB conversion was the fit's largest cost per
/// frame (~10 of its ~30 ms of CPU at 960×540).
fn base_channels_many(rgb: &[u8], out: &mut [[u8; CHANNELS]]) {
    #[cfg(target_arch = "x86_64")]
    if has_avx2() {
        // SAFETY: the CPU supports AVX2 (checked just above).
        unsafe { base_channels_many_avx2(rgb, out) };
        return;
    }
    base_channels_many_portable(rgb, out);
}

/// Does this CPU have AVX2? (The standard library asks the CPU once and keeps the answer.)
#[cfg(target_arch = "x86_64")]
fn has_avx2() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn base_channels_many_avx2(rgb: &[u8], out: &mut [[u8; CHANNELS]]) {
    let (lut, recip) = (linear_lut(), reciprocals());
    // The closure inherits this function's AVX2, so it may call the AVX2 lanes.
    in_lanes(rgb, out, |p| {
        super::lab_avx2::base_channels_lanes(p, lut, recip)
    });
}

#[inline(always)]
fn base_channels_many_portable(rgb: &[u8], out: &mut [[u8; CHANNELS]]) {
    in_lanes(rgb, out, base_channels_lanes);
}

/// Converts `LANES` pixels at a time with `lanes` (given exactly `3 * LANES` bytes), the last
/// pixels one by one with [`base_channels`].
#[inline(always)]
fn in_lanes(
    rgb: &[u8],
    out: &mut [[u8; CHANNELS]],
    lanes: impl Fn(&[u8]) -> [[u8; CHANNELS]; LANES],
) {
    let n = out.len().min(rgb.len() / 3);
    let whole = n / LANES * LANES;
    for (o, p) in out[..whole]
        .chunks_exact_mut(LANES)
        .zip(rgb.chunks_exact(3 * LANES))
    {
        o.copy_from_slice(&lanes(p));
    }
    for i in whole..n {
        out[i] = base_channels(rgb[3 * i], rgb[3 * i + 1], rgb[3 * i + 2]);
    }
}

/// [`base_channels`] of `LANES` pixels, written lane-wise (every loop below is one vector
/// operation). `rgb` holds exactly `3 * LANES` bytes.
#[inline(always)]
fn base_channels_lanes(rgb: &[u8]) -> [[u8; CHANNELS]; LANES] {
    let lut = linear_lut();
    let mut cr = [0f32; LANES];
    let mut cg = [0f32; LANES];
    let mut cb = [0f32; LANES];
    let mut sum = [0usize; LANES];
    for k in 0..LANES {
        cr[k] = lut[rgb[3 * k] as usize];
        cg[k] = lut[rgb[3 * k + 1] as usize];
        cb[k] = lut[rgb[3 * k + 2] as usize];
        sum[k] = rgb[3 * k] as usize + rgb[3 * k + 1] as usize + rgb[3 * k + 2] as usize;
    }
    let mut t = [[0f32; LANES]; 3];
    for k in 0..LANES {
        let (r, g, b) = (cr[k], cg[k], cb[k]);
        t[0][k] = (0.412_456_4 * r + 0.357_576_1 * g + 0.180_437_5 * b) / 0.950_47;
        t[1][k] = 0.212_672_9 * r + 0.715_152_2 * g + 0.072_175 * b;
        t[2][k] = (0.019_333_9 * r + 0.119_192 * g + 0.950_304_1 * b) / 1.088_83;
    }
    let mut f = [[0f32; LANES]; 3];
    for (fc, tc) in f.iter_mut().zip(&t) {
        *fc = lab_f_lanes(tc);
    }
    let mut out = [[0u8; CHANNELS]; LANES];
    let recip = reciprocals();
    for k in 0..LANES {
        let (fx, fy, fz) = (f[0][k], f[1][k], f[2][k]);
        let (l, a, bb) = (116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz));
        let rc = recip[sum[k]] as u64;
        let n = |c: u8| (((c as u64 * rc) + 32768) >> 16).min(255) as u8;
        out[k] = [
            quantise(2.55 * l),
            quantise(128.0 + 1.5 * a),
            quantise(128.0 + 1.5 * bb),
            n(rgb[3 * k]),
            n(rgb[3 * k + 1]),
        ];
    }
    out
}

/// CIELAB's f(t) of `LANES` values: [`cube_root`] above the linear segment, as [`lab`] does.
#[inline(always)]
fn lab_f_lanes(t: &[f32; LANES]) -> [f32; LANES] {
    let mut y = [0f64; LANES];
    let mut t64 = [0f64; LANES];
    for k in 0..LANES {
        t64[k] = t[k] as f64;
        y[k] = f32::from_bits(t[k].to_bits() / 3 + 0x2a51_4067) as f64;
    }
    for _ in 0..2 {
        for k in 0..LANES {
            let y3 = y[k] * y[k] * y[k];
            y[k] *= (y3 + 2.0 * t64[k]) / (2.0 * y3 + t64[k]);
        }
    }
    let mut out = [0f32; LANES];
    for k in 0..LANES {
        out[k] = if t[k] > 0.008_856 {
            y[k] as f32
        } else {
            7.787 * t[k] + 16.0 / 116.0
        };
    }
    out
}

/// The radii at pyramid `level` (level 0: the source frame).
pub(super) fn radii_at(level: usize) -> [usize; SCALES] {
    RADII_PX.map(|r| ((r as f64 / (1u64 << level.min(16)) as f64).round() as usize).max(1))
}

/// How far (px) from a pixel the features at pyramid `level` look: a gradient's window sits a
/// radius away from the pixel, so twice the widest radius, plus one.
pub fn reach_for_level(level: usize) -> usize {
    2 * radii_at(level).into_iter().max().unwrap_or(1) + 1
}

/// Recycled summed-area tables: the fit builds features over a fresh region of every frame.
/// Only a table's first row and column are cleared: [`FrameFeatures::build`] writes every other
/// entry before reading it.
static TABLES_SUMS: crate::pool::Pool<[u32; CHANNELS]> = crate::pool::Pool::new();
static TABLES_SQUARES: crate::pool::Pool<[u32; BANK_CHANNELS]> = crate::pool::Pool::new();
/// Recycled per-pixel channels of a region (every entry is written before it is read).
static BASES: crate::pool::Pool<[u8; CHANNELS]> = crate::pool::Pool::new();

/// The per-pixel channels of the `size` pixels at `offset` in `frame`, row-major, converted
/// straight from the frame's rows. The caller keeps the region inside the frame.
fn base_of_region(
    frame: &RgbImage,
    (x0, y0): (usize, usize),
    (w, h): (usize, usize),
) -> Vec<[u8; CHANNELS]> {
    let (raw, fw) = (frame.as_raw(), frame.width() as usize);
    let mut out = BASES.take(w * h, [0u8; CHANNELS]);
    out.par_chunks_mut(w.max(1))
        .enumerate()
        .with_min_len(crate::pool::min_split(h, 16))
        .for_each(|(y, row)| {
            let start = ((y0 + y) * fw + x0) * 3;
            base_channels_many(&raw[start..start + 3 * row.len()], row);
        });
    out
}

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

/// The ((w+1)×(h+1)) summed-area table of `value(pixel)` (N values per pixel, interleaved).
/// Sums wrap: a window's sum is below 2³² (625 · 255² at most), so the difference of four
/// corners is exact however large the frame.
fn summed_area<const N: usize>(
    pool: &crate::pool::Pool<[u32; N]>,
    base: &[[u8; CHANNELS]],
    w: usize,
    h: usize,
    value: impl Fn(&[u8; CHANNELS], usize) -> u32,
) -> Vec<[u32; N]>
where
    [u32; N]: Default,
{
    let stride = w + 1;
    let mut t = table(pool, stride, h + 1);
    for y in 0..h {
        let mut row = [0u32; N];
        for x in 0..w {
            let px = &base[y * w + x];
            let (o, up) = ((y + 1) * stride + x + 1, y * stride + x + 1);
            let above = t[up];
            let cell = &mut t[o];
            for c in 0..N {
                row[c] = row[c].wrapping_add(value(px, c));
                cell[c] = above[c].wrapping_add(row[c]);
            }
        }
    }
    t
}

/// The channels' summed-area table and their squares' table (bank channels) of the w×h
/// pixels `base`: in one AVX2 pass where the CPU has it ([`super::tables_avx2`], equal bit for
/// bit), else each table by [`summed_area`], the two in parallel.
fn summed_areas(
    base: &[[u8; CHANNELS]],
    w: usize,
    h: usize,
) -> (Vec<[u32; CHANNELS]>, Vec<[u32; BANK_CHANNELS]>) {
    #[cfg(target_arch = "x86_64")]
    if has_avx2() {
        let mut sums = table(&TABLES_SUMS, w + 1, h + 1);
        let mut squares = table(&TABLES_SQUARES, w + 1, h + 1);
        // SAFETY: the CPU supports AVX2 (checked just above).
        unsafe { super::tables_avx2::fill(base, (w, h), &mut sums, &mut squares) };
        return (sums, squares);
    }
    rayon::join(
        || summed_area(&TABLES_SUMS, base, w, h, |px, c| px[c] as u32),
        || summed_area(&TABLES_SQUARES, base, w, h, |px, c| (px[c] as u32).pow(2)),
    )
}

impl Drop for FrameFeatures {
    fn drop(&mut self) {
        TABLES_SUMS.give([std::mem::take(&mut self.integrals)]);
        TABLES_SQUARES.give([std::mem::take(&mut self.squares)]);
        BASES.give([std::mem::take(&mut self.base)]);
    }
}

impl FrameFeatures {
    /// Features of a source frame (pyramid level 0).
    pub fn new(frame: &RgbImage) -> Self {
        Self::at_level(frame, 0)
    }

    /// Features of `frame`, pyramid level `level` of its source (windows scaled to match).
    pub fn at_level(frame: &RgbImage, level: usize) -> Self {
        let full = (frame.width() as usize, frame.height() as usize);
        Self::build(frame, level, full, (0, 0), full)
    }

    /// Features of the pixels inside `(x0, y0, w, h)` of `frame` (pyramid level `level`)
    /// only: integral images cost the region, not the frame. [`FrameFeatures::valid`] says
    /// where results equal whole-frame ones.
    pub fn region(
        frame: &RgbImage,
        level: usize,
        x0: usize,
        y0: usize,
        w: usize,
        h: usize,
    ) -> Self {
        let full = (frame.width() as usize, frame.height() as usize);
        let (x0, y0) = (
            x0.min(full.0.saturating_sub(1)),
            y0.min(full.1.saturating_sub(1)),
        );
        let (w, h) = (w.clamp(1, full.0 - x0), h.clamp(1, full.1 - y0));
        Self::build(frame, level, full, (x0, y0), (w, h))
    }

    /// Largest distance (px) any feature reaches.
    pub fn reach(&self) -> usize {
        2 * self.radii.into_iter().max().unwrap_or(1) + 1
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

    /// The features of the `size` pixels at `offset` in `frame` (read in place: a region is
    /// not copied out first).
    fn build(
        frame: &RgbImage,
        level: usize,
        full: (usize, usize),
        offset: (usize, usize),
        size: (usize, usize),
    ) -> Self {
        let (w, h) = size;
        let base = base_of_region(frame, offset, size);
        let (sums, squares) = summed_areas(&base, w, h);
        Self {
            offset,
            full,
            width: w,
            height: h,
            base,
            integrals: sums,
            squares,
            radii: radii_at(level),
        }
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn height(&self) -> usize {
        self.height
    }

    /// The bank channels' means over the window of radius `r` around (x, y), clipped to the
    /// image (a gradient needs no other channel).
    #[inline]
    fn bank_means(&self, x: usize, y: usize, r: usize) -> [f32; BANK_CHANNELS] {
        let (sums, area) = box_sums(&self.integrals, self.width, self.height, x, y, r);
        std::array::from_fn(|c| mean(sums[c], area))
    }

    /// The feature vector of pixel (x, y).
    pub fn at(&self, x: usize, y: usize) -> FeatureVector {
        let (w, h) = (self.width, self.height);
        // Per scale, all channels at once: means, deviations and gradients.
        let mut means = [[0f32; CHANNELS]; SCALES];
        let mut std = [[0u8; BANK_CHANNELS]; SCALES];
        let mut grad = [[0u8; BANK_CHANNELS]; SCALES];
        for (i, &r) in self.radii.iter().enumerate() {
            // Coarse levels round neighbouring radii to the same one (level 1: 1, 1, 2, 4, 6):
            // the same windows give the same values, so they are copied, not summed again.
            if i > 0 && r == self.radii[i - 1] {
                (means[i], std[i], grad[i]) = (means[i - 1], std[i - 1], grad[i - 1]);
                continue;
            }
            let (sums, area) = box_sums(&self.integrals, w, h, x, y, r);
            means[i] = sums.map(|s| mean(s, area));
            let (sq, _) = box_sums(&self.squares, w, h, x, y, r);
            // Haar gradient at this scale: the window a radius ahead minus the one a radius
            // behind, across and down.
            let right = self.bank_means((x + r).min(w - 1), y, r);
            let left = self.bank_means(x.saturating_sub(r), y, r);
            let down = self.bank_means(x, (y + r).min(h - 1), r);
            let up = self.bank_means(x, y.saturating_sub(r), r);
            for c in 0..BANK_CHANNELS {
                std[i][c] = deviation(sums[c], sq[c], area);
                grad[i][c] = gradient(right[c] - left[c], down[c] - up[c]);
            }
        }
        let mut f = [0u8; FEATURE_COUNT];
        let px = &self.base[y * w + x];
        let mut o = 0;
        for (c, &value) in px.iter().enumerate() {
            f[o] = value;
            o += 1;
            for i in 0..SCALES {
                f[o] = quantise(means[i][c]);
                o += 1;
                if c < BANK_CHANNELS {
                    f[o] = std[i][c];
                    f[o + 1] = grad[i][c];
                    o += 2;
                }
            }
            if c < BANK_CHANNELS {
                for i in 0..SCALES - 1 {
                    f[o] = difference(means[i][c], means[i + 1][c]);
                    o += 1;
                }
            }
        }
        debug_assert_eq!(o, FEATURE_COUNT);
        f
    }

    /// Features of every pixel, row-major, equal to [`FrameFeatures::at`] bit for bit (the
    /// dense path of [`super::dense`]; it reads only the per-pixel channels).
    pub fn all(&self) -> Vec<FeatureVector> {
        super::dense::from_base(&self.base, self.width, self.height, self.radii)
    }

    /// [`FrameFeatures::pixels`], computed densely (~1.5× cheaper per pixel, equal bit for bit)
    /// over the listed pixels' box widened by the features' reach, when the list covers a third
    /// of that box or more: the tracker's occluder check asks for every pixel inside the fitted
    /// organs, ~57,000 a view at 960×540, and those per-pixel queries were the largest cost of
    /// `track`'s frame. Within the box a listed pixel's windows are clipped where the region's
    /// are: either they do not reach the box's edge, or that edge is the region's.
    pub fn pixels_auto(&self, list: &[(u32, u32)]) -> Vec<FeatureVector> {
        if list.len() < DENSE_FROM_PIXELS {
            return self.pixels(list);
        }
        let local: Vec<(usize, usize)> = list.iter().map(|&(x, y)| self.local(x, y)).collect();
        let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
        for &(x, y) in &local {
            (x0, x1) = (x0.min(x), x1.max(x));
            (y0, y1) = (y0.min(y), y1.max(y));
        }
        let m = self.reach();
        let (bx0, by0) = (x0.saturating_sub(m), y0.saturating_sub(m));
        let (bx1, by1) = ((x1 + m).min(self.width - 1), (y1 + m).min(self.height - 1));
        let (bw, bh) = (bx1 + 1 - bx0, by1 + 1 - by0);
        if list.len() * 3 < bw * bh {
            return self.pixels(list);
        }
        let all = if (bw, bh) == (self.width, self.height) {
            super::dense::from_base(&self.base, bw, bh, self.radii)
        } else {
            let rows = self.base[by0 * self.width..(by1 + 1) * self.width].chunks_exact(self.width);
            let boxed: Vec<[u8; CHANNELS]> =
                rows.flat_map(|row| &row[bx0..=bx1]).copied().collect();
            super::dense::from_base(&boxed, bw, bh, self.radii)
        };
        local
            .iter()
            .map(|&(x, y)| all[(y - by0) * bw + (x - bx0)])
            .collect()
    }

    /// The region's own coordinates of full-frame pixel (x, y), clamped into the region.
    fn local(&self, x: u32, y: u32) -> (usize, usize) {
        let (ox, oy) = self.offset;
        (
            (x as usize).saturating_sub(ox).min(self.width - 1),
            (y as usize).saturating_sub(oy).min(self.height - 1),
        )
    }

    /// Features of the listed full-frame pixels (x, y); each must lie in the region. Equal
    /// to [`FrameFeatures::at`] of each, bit for bit; in AVX2 intrinsics where the CPU has them
    /// (`pixel_avx2`: 5,000 pixels in row-major order 1.78 ms through `at`, 1.01 ms here, on
    /// one core, `cargo bench --bench features_speed`).
    pub fn pixels(&self, list: &[(u32, u32)]) -> Vec<FeatureVector> {
        #[cfg(target_arch = "x86_64")]
        if has_avx2() {
            // SAFETY: the CPU supports AVX2 (checked just above).
            return self.pixels_by(list, |ff, x, y| unsafe {
                super::pixel_avx2::feature_vector(ff, x, y)
            });
        }
        self.pixels_scalar(list)
    }

    /// [`FrameFeatures::pixels`] through [`FrameFeatures::at`] on any CPU.
    pub fn pixels_scalar(&self, list: &[(u32, u32)]) -> Vec<FeatureVector> {
        self.pixels_by(list, Self::at)
    }

    /// `vector` of each listed full-frame pixel, given in the region's own coordinates.
    fn pixels_by(
        &self,
        list: &[(u32, u32)],
        vector: impl Fn(&Self, usize, usize) -> FeatureVector + Sync,
    ) -> Vec<FeatureVector> {
        list.par_iter()
            .with_min_len(crate::pool::min_split(list.len(), 1))
            .map(|&(x, y)| {
                let (lx, ly) = self.local(x, y);
                vector(self, lx, ly)
            })
            .collect()
    }
}

/// A specular highlight: near-saturated and almost colourless. Its colour is the light's, not
/// the tissue's, so it neither trains the forest nor votes in the fit.
#[inline]
pub fn is_specular(rgb: [u8; 3]) -> bool {
    let [r, g, b] = rgb;
    let (hi, lo) = (r.max(g).max(b) as u32, r.min(g).min(b) as u32);
    // hi ≥ 230 and (hi − lo) / hi < 0.25, in integers.
    hi >= 230 && 4 * (hi - lo) < hi
}

/// sRGB (0–255) to linear light.
fn linear_lut() -> &'static [f32; 256] {
    static TABLE: std::sync::OnceLock<[f32; 256]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        let mut t = [0f32; 256];
        for (i, v) in t.iter_mut().enumerate() {
            let c = i as f64 / 255.0;
            *v = if c <= 0.04045 {
                (c / 12.92) as f32
            } else {
                ((c + 0.055) / 1.055).powf(2.4) as f32
            };
        }
        t
    })
}

/// CIELAB (D65) of an sRGB pixel.
pub fn lab(r: u8, g: u8, b: u8) -> [f32; 3] {
    let lut = linear_lut();
    let (r, g, b) = (lut[r as usize], lut[g as usize], lut[b as usize]);
    let x = (0.412_456_4 * r + 0.357_576_1 * g + 0.180_437_5 * b) / 0.950_47;
    let y = 0.212_672_9 * r + 0.715_152_2 * g + 0.072_175 * b;
    let z = (0.019_333_9 * r + 0.119_192 * g + 0.950_304_1 * b) / 1.088_83;
    let f = |t: f32| {
        if t > 0.008_856 {
            cube_root(t)
        } else {
            7.787 * t + 16.0 / 116.0
        }
    };
    let (fx, fy, fz) = (f(x), f(y), f(z));
    [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
}

/// The cube root of t in CIELAB's range (0.008856 < t ≲ 1.1): a bit-level first guess (within
/// ~5 %) and two Halley steps in f64, which leave it correctly rounded to f32 but for a rare
/// last-bit tie. libm's `cbrtf` was the largest single cost of a frame's features.
#[inline]
fn cube_root(t: f32) -> f32 {
    let t64 = t as f64;
    let mut y = f32::from_bits(t.to_bits() / 3 + 0x2a51_4067) as f64;
    for _ in 0..2 {
        let y3 = y * y * y;
        y *= (y3 + 2.0 * t64) / (2.0 * y3 + t64);
    }
    y as f32
}

/// L*, a*, b*, nr, ng of one pixel, quantised: L* × 2.55, 128 + 1.5 a* (and b*), 255 c/(r+g+b).
#[inline]
fn base_channels(r: u8, g: u8, b: u8) -> [u8; CHANNELS] {
    let [l, a, bb] = lab(r, g, b);
    let recip = reciprocals()[r as usize + g as usize + b as usize] as u64;
    let q = quantise;
    let n = |c: u8| (((c as u64 * recip) + 32768) >> 16).min(255) as u8;
    [
        q(2.55 * l),
        q(128.0 + 1.5 * a),
        q(128.0 + 1.5 * bb),
        n(r),
        n(g),
    ]
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

/// The largest window a feature sums: radius 12 at the source frame.
const MAX_AREA: usize = {
    let mut r = 0;
    let mut i = 0;
    while i < SCALES {
        if RADII_PX[i] > r {
            r = RADII_PX[i];
        }
        i += 1;
    }
    (2 * r + 1) * (2 * r + 1)
};

/// 1/n for every window area n: a mean is a multiply, not a division (the features' hottest
/// arithmetic: 70 means per pixel).
pub(super) static RECIPROCAL: [f32; MAX_AREA + 1] = {
    let mut t = [0f32; MAX_AREA + 1];
    let mut n = 1;
    while n <= MAX_AREA {
        t[n] = 1.0 / n as f32;
        n += 1;
    }
    t
};

/// A window's mean from its sum and pixel count.
#[inline]
pub(super) fn mean(sum: u32, area: u32) -> f32 {
    sum as f32 * RECIPROCAL[area as usize]
}

/// A feature value (0–255 scale) rounded to u8, saturating.
#[inline]
pub(super) fn quantise(v: f32) -> u8 {
    // max/min (NaN → 0, as the saturating cast gives it) put v + 0.5 in [0.5, 255.5], so the
    // unchecked conversion is defined and equals `(v.clamp(0.0, 255.0) + 0.5) as u8`; unlike
    // that saturating cast it compiles to vector conversions in the dense path's row loops.
    #[allow(clippy::manual_clamp)] // clamp keeps NaN, which the conversion must not see
    let v = v.max(0.0).min(255.0) + 0.5;
    // SAFETY: v is finite and within i32's range (above).
    unsafe { v.to_int_unchecked::<i32>() as u8 }
}

/// Three standard deviations of a window from its sum, sum of squares and pixel count,
/// quantised. The variance's numerator n·Σv² − (Σv)² is exact in f64 (every term is below
/// 2⁵³), so a flat bright window gives 0, not a rounding residue.
#[inline]
pub(super) fn deviation(sum: u32, sum_sq: u32, area: u32) -> u8 {
    let (s, s2) = (sum as f64, sum_sq as f64);
    let spread = (area as f64 * s2 - s * s).max(0.0);
    quantise(3.0 * (spread as f32).sqrt() * RECIPROCAL[area as usize])
}

/// Gradient magnitude from the across and down differences of means, quantised.
#[inline]
pub(super) fn gradient(gx: f32, gy: f32) -> u8 {
    quantise(2.0 * (gx * gx + gy * gy).sqrt())
}

/// The difference of a scale's mean and the next scale's, around 128, quantised.
#[inline]
pub(super) fn difference(finer: f32, coarser: f32) -> u8 {
    quantise(128.0 + 2.0 * (finer - coarser))
}

/// Corners (x0, y0, x1, y1; end exclusive) of the window of radius r around (x, y), clipped
/// to a w × h image.
#[inline]
pub(super) fn window(
    w: usize,
    h: usize,
    x: usize,
    y: usize,
    r: usize,
) -> (usize, usize, usize, usize) {
    (
        x.saturating_sub(r),
        y.saturating_sub(r),
        (x + r + 1).min(w),
        (y + r + 1).min(h),
    )
}

/// Every channel's sum over the window of radius r around (x, y), clipped to the image, and
/// the window's pixel count. Sums wrap (see [`summed_area`]): the difference is exact.
#[inline]
fn box_sums<const N: usize>(
    table: &[[u32; N]],
    w: usize,
    h: usize,
    x: usize,
    y: usize,
    r: usize,
) -> ([u32; N], u32) {
    let (x0, y0, x1, y1) = window(w, h, x, y, r);
    let s = w + 1;
    let (a, b, c, d) = (
        &table[y1 * s + x1],
        &table[y0 * s + x1],
        &table[y1 * s + x0],
        &table[y0 * s + x0],
    );
    let sums = std::array::from_fn(|k| {
        a[k].wrapping_sub(b[k])
            .wrapping_sub(c[k])
            .wrapping_add(d[k])
    });
    (sums, ((x1 - x0) * (y1 - y0)) as u32)
}

/// Halves a frame by 2×2 averaging (one pyramid level).
pub fn downsample(frame: &RgbImage) -> RgbImage {
    let (sw, sh) = (frame.width() as usize, frame.height() as usize);
    let (w, h) = ((sw / 2).max(1), (sh / 2).max(1));
    let src = frame.as_raw();
    let mut out = vec![0u8; w * h * 3];
    out.par_chunks_mut(w * 3).enumerate().for_each(|(y, row)| {
        let (y0, y1) = ((2 * y).min(sh - 1), (2 * y + 1).min(sh - 1));
        if sw >= 2 {
            // No column is clamped (2x + 1 < sw for every x < sw / 2): whole 2×2 blocks of the
            // two source rows, a loop the compiler vectorises (the fit halves every frame).
            let (r0, r1) = (&src[y0 * sw * 3..], &src[y1 * sw * 3..]);
            for ((o, a), b) in row
                .chunks_exact_mut(3)
                .zip(r0.chunks_exact(6))
                .zip(r1.chunks_exact(6))
            {
                for c in 0..3 {
                    let v = a[c] as u32 + a[c + 3] as u32 + b[c] as u32 + b[c + 3] as u32;
                    o[c] = ((v + 2) / 4) as u8;
                }
            }
            return;
        }
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

    fn noise_frame(seed: u64, w: u32, h: u32) -> RgbImage {
        let mut rng = Rng::new(seed);
        RgbImage::from_fn(w, h, |_, _| {
            image::Rgb([
                rng.below(256) as u8,
                rng.below(256) as u8,
                rng.below(256) as u8,
            ])
        })
    }

    /// The lane-wise conversion (vector instructions) equals the per-pixel one bit for bit, on
    /// every value of each channel against a grid of the others, dark colours (the linear
    /// segment of f) and tails shorter than a lane group, by both the AVX2 and the portable path.
    #[test]
    fn lane_wise_base_channels_equal_per_pixel_ones() {
        let mut rgb = Vec::new();
        for a in 0..=255u8 {
            for b in (0..=255u8).step_by(5) {
                for c in (0..=255u8).step_by(17) {
                    rgb.extend_from_slice(&[a, b, c, b, c, a, c, a, b]);
                }
            }
        }
        for a in 0..12u8 {
            for b in 0..12u8 {
                for c in 0..12u8 {
                    rgb.extend_from_slice(&[a, b, c]);
                }
            }
        }
        // An odd count: the last pixels go through the per-pixel tail.
        rgb.extend_from_slice(&[200, 10, 90, 255, 255, 255, 0, 0, 0]);
        let n = rgb.len() / 3;
        let expected: Vec<[u8; CHANNELS]> = rgb
            .chunks_exact(3)
            .map(|p| base_channels(p[0], p[1], p[2]))
            .collect();
        let mut got = vec![[0u8; CHANNELS]; n];
        base_channels_many(&rgb, &mut got);
        assert!(got == expected, "dispatched lane-wise conversion differs");
        let mut portable = vec![[0u8; CHANNELS]; n];
        base_channels_many_portable(&rgb, &mut portable);
        assert!(
            portable == expected,
            "portable lane-wise conversion differs"
        );
        // And through base_of on a frame whose size is no multiple of a lane group.
        let frame = noise_frame(3, 37, 11);
        let whole = base_of(&frame);
        for (i, p) in frame.pixels().enumerate() {
            assert_eq!(whole[i], base_channels(p[0], p[1], p[2]), "pixel {i}");
        }
    }

    /// The one-pass AVX2 tables equal the portable ones bit for bit, on sizes from one pixel
    /// to rows longer than a vector, and leave recycled tables' other rows alone.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx2_summed_areas_equal_the_portable_ones() {
        if !has_avx2() {
            return;
        }
        for (seed, (w, h)) in [(1usize, 1usize), (2, 1), (1, 3), (2, 2), (9, 4), (37, 11)]
            .into_iter()
            .enumerate()
        {
            let base = base_of(&noise_frame(seed as u64, w as u32, h as u32));
            let (sums, squares) = (
                summed_area(&TABLES_SUMS, &base, w, h, |px, c| px[c] as u32),
                summed_area(&TABLES_SQUARES, &base, w, h, |px, c| (px[c] as u32).pow(2)),
            );
            // Tables full of garbage, first row and column cleared, as the pool gives them.
            let mut fast_sums = vec![[7u32; CHANNELS]; (w + 1) * (h + 1)];
            let mut fast_squares = vec![[9u32; BANK_CHANNELS]; (w + 1) * (h + 1)];
            for (t, row) in fast_sums.chunks_exact_mut(w + 1).enumerate() {
                row[0] = [0; CHANNELS];
                if t == 0 {
                    row.fill([0; CHANNELS]);
                }
            }
            for (t, row) in fast_squares.chunks_exact_mut(w + 1).enumerate() {
                row[0] = [0; BANK_CHANNELS];
                if t == 0 {
                    row.fill([0; BANK_CHANNELS]);
                }
            }
            // SAFETY: the CPU supports AVX2 (checked above).
            unsafe {
                super::super::tables_avx2::fill(&base, (w, h), &mut fast_sums, &mut fast_squares)
            };
            assert!(fast_sums == sums, "sums of {w}×{h}");
            assert!(fast_squares == squares, "squares of {w}×{h}");
        }
    }

    /// Every windowed feature equals a brute-force sum over its clipped window.
    #[test]
    fn integral_features_match_brute_force() {
        let (w, h) = (97usize, 53usize);
        let frame = noise_frame(71, w as u32, h as u32);
        // Leave dirty tables in the pool first: recycled tables must give the same sums as
        // fresh ones (only their first row and column are cleared).
        drop(FrameFeatures::new(&noise_frame(
            5,
            w as u32 + 13,
            h as u32 + 7,
        )));
        let ff = FrameFeatures::new(&frame);
        let all = ff.all();
        let mut rng = Rng::new(9);
        let window_mean = |c: usize, cx: usize, cy: usize, r: usize| -> (f64, f64) {
            let mut v = Vec::new();
            for yy in cy.saturating_sub(r)..(cy + r + 1).min(h) {
                for xx in cx.saturating_sub(r)..(cx + r + 1).min(w) {
                    v.push(ff.base[yy * w + xx][c] as f64);
                }
            }
            let mean = v.iter().sum::<f64>() / v.len() as f64;
            let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / v.len() as f64;
            (mean, var.sqrt())
        };
        let q = |v: f64| (v.clamp(0.0, 255.0) + 0.5) as u8;
        for _ in 0..200 {
            let (x, y) = (rng.below(w), rng.below(h));
            let f = all[y * w + x];
            assert_eq!(f, ff.at(x, y));
            let mut o = 0;
            for c in 0..CHANNELS {
                assert_eq!(f[o], ff.base[y * w + x][c]);
                o += 1;
                let mut means = Vec::new();
                for &r in &ff.radii {
                    let (mean, std) = window_mean(c, x, y, r);
                    means.push(mean);
                    assert!((f[o] as f64 - mean).abs() <= 0.51, "mean c{c} r{r}");
                    o += 1;
                    if c < BANK_CHANNELS {
                        assert!(
                            (f[o] as f64 - (3.0 * std).min(255.0)).abs() <= 1.0,
                            "std c{c} r{r}"
                        );
                        let gx = window_mean(c, (x + r).min(w - 1), y, r).0
                            - window_mean(c, x.saturating_sub(r), y, r).0;
                        let gy = window_mean(c, x, (y + r).min(h - 1), r).0
                            - window_mean(c, x, y.saturating_sub(r), r).0;
                        let g = q(2.0 * (gx * gx + gy * gy).sqrt());
                        assert!(
                            (f[o + 1] as i32 - g as i32).abs() <= 1,
                            "gradient c{c} r{r}"
                        );
                        o += 2;
                    }
                }
                if c < BANK_CHANNELS {
                    for i in 0..SCALES - 1 {
                        let d = q(128.0 + 2.0 * (means[i] - means[i + 1]));
                        assert!((f[o] as i32 - d as i32).abs() <= 1, "difference c{c} {i}");
                        o += 1;
                    }
                }
            }
            assert_eq!(o, FEATURE_COUNT);
        }
        assert_eq!(feature_names().len(), FEATURE_COUNT);
    }

    #[test]
    fn highlights_are_bright_and_colourless() {
        assert!(is_specular([255, 255, 255]));
        assert!(is_specular([240, 232, 220]));
        // Bright but coloured (reddish fat in the light), or colourless but grey: tissue.
        assert!(!is_specular([250, 150, 140]));
        assert!(!is_specular([200, 200, 200]));
    }

    /// Every one of the 16.7 million sRGB colours: the dispatched conversion (AVX2 intrinsics
    /// where the CPU has them) equals the per-pixel one (0.8 s in the test build).
    #[test]
    fn every_colour_converts_as_the_per_pixel_code_does() {
        let rgb: Vec<u8> = (0..1u32 << 24)
            .flat_map(|c| [(c >> 16) as u8, (c >> 8) as u8, c as u8])
            .collect();
        let mut got = vec![[0u8; CHANNELS]; rgb.len() / 3];
        base_channels_many(&rgb, &mut got);
        let differing = rgb
            .chunks_exact(3)
            .zip(&got)
            .filter(|(p, g)| base_channels(p[0], p[1], p[2]) != **g)
            .count();
        assert_eq!(differing, 0, "colours converted differently");
    }

    /// The vector path of [`FrameFeatures::pixels`] (AVX2 where the CPU has it) equals
    /// [`FrameFeatures::at`] on every pixel: frames narrower and shorter than the windows,
    /// every pyramid level's radii (levels 3 and 4 repeat radii most), flat patches (zero
    /// deviation), saturated ones, and a region cut out of a frame. On a CPU without AVX2
    /// both sides are the scalar path, and the test says so.
    #[test]
    fn pixel_features_equal_the_scalar_ones_everywhere() {
        #[cfg(target_arch = "x86_64")]
        if !has_avx2() {
            eprintln!("no AVX2 on this CPU: the vector path is not exercised");
        }
        for (w, h, level) in [
            (61, 37, 0),
            (61, 37, 1),
            (40, 23, 2),
            (13, 11, 3),
            (13, 11, 4),
            (9, 7, 0),
            (200, 5, 1),
        ] {
            let mut frame = noise_frame(w as u64 * 31 + level as u64, w, h);
            for (x, y, p) in frame.enumerate_pixels_mut() {
                if x < w / 3 {
                    *p = image::Rgb([120, 40, 30]);
                } else if y < h / 4 {
                    *p = image::Rgb([255, 255, 255]);
                }
            }
            let every: Vec<(u32, u32)> = (0..h).flat_map(|y| (0..w).map(move |x| (x, y))).collect();
            let ff = FrameFeatures::at_level(&frame, level);
            assert!(
                ff.pixels(&every) == ff.pixels_scalar(&every),
                "{w}×{h} level {level}"
            );
            let region = FrameFeatures::region(&frame, level, 3, 2, w as usize / 2, h as usize);
            let inside: Vec<(u32, u32)> = every
                .iter()
                .copied()
                .filter(|&(x, y)| (3..3 + w / 2).contains(&x) && y >= 2.min(h - 1))
                .collect();
            assert!(
                region.pixels(&inside) == region.pixels_scalar(&inside),
                "region of {w}×{h} level {level}"
            );
        }
    }

    /// The fast cube root equals f64's, rounded to f32, over CIELAB's whole range.
    #[test]
    fn cube_root_is_correctly_rounded_over_labs_range() {
        let (mut t, mut checked, mut off_by_one_ulp) = (0.008_857f32, 0, 0);
        while t < 1.2 {
            let want = (t as f64).cbrt() as f32;
            let got = cube_root(t);
            let ulps = (got.to_bits() as i64 - want.to_bits() as i64).abs();
            assert!(ulps <= 1, "cbrt({t}) = {got}, want {want}");
            off_by_one_ulp += ulps as usize;
            checked += 1;
            t = f32::from_bits(t.to_bits() + 97);
        }
        assert!(checked > 100_000);
        assert!(
            off_by_one_ulp * 1000 < checked,
            "{off_by_one_ulp} of {checked} a ulp off"
        );
    }

    #[test]
    fn lab_matches_reference_values() {
        // sRGB white, black, pure red (CIE reference values).
        let close = |a: [f32; 3], b: [f32; 3]| a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 0.3);
        assert!(
            close(lab(255, 255, 255), [100.0, 0.0, 0.0]),
            "{:?}",
            lab(255, 255, 255)
        );
        assert!(close(lab(0, 0, 0), [0.0, 0.0, 0.0]));
        assert!(
            close(lab(255, 0, 0), [53.24, 80.09, 67.20]),
            "{:?}",
            lab(255, 0, 0)
        );
    }

    #[test]
    fn region_features_equal_whole_frame_features_where_valid() {
        let frame = noise_frame(72, 200, 120);
        for level in [0, 1] {
            let whole = FrameFeatures::at_level(&frame, level);
            for (x0, y0, w, h) in [(30, 20, 100, 70), (0, 0, 90, 50), (120, 60, 80, 60)] {
                let region = FrameFeatures::region(&frame, level, x0, y0, w, h);
                let mut checked = 0;
                for y in 0..120 {
                    for x in 0..200 {
                        if region.valid(x, y) {
                            assert_eq!(
                                region.pixels(&[(x as u32, y as u32)])[0],
                                whole.at(x, y),
                                "pixel ({x},{y}) of region ({x0},{y0},{w},{h}), level {level}"
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
        // A region's per-pixel channels are read from the frame in place: they equal the whole
        // frame's there, for regions one pixel wide or high and at the frame's last column.
        let whole = FrameFeatures::new(&frame);
        for (x0, y0, w, h) in [
            (199, 0, 1, 120),
            (0, 119, 200, 1),
            (57, 33, 1, 1),
            (3, 5, 61, 7),
        ] {
            let region = FrameFeatures::region(&frame, 0, x0, y0, w, h);
            assert_eq!((region.width, region.height), (w, h));
            for y in 0..h {
                for x in 0..w {
                    assert_eq!(
                        region.base[y * w + x],
                        whole.base[(y0 + y) * 200 + x0 + x],
                        "pixel ({x},{y}) of region ({x0},{y0},{w},{h})"
                    );
                }
            }
        }
    }

    #[test]
    fn scales_are_source_pixels_halved_per_level_and_downsample_halves() {
        assert_eq!(radii_at(0), [1, 2, 4, 8, 12]);
        assert_eq!(radii_at(1), [1, 1, 2, 4, 6]);
        assert_eq!(radii_at(2), [1, 1, 1, 2, 3]);
        assert_eq!(reach_for_level(0), 25);
        let img = RgbImage::from_fn(5, 4, |x, _| image::Rgb([x as u8 * 10, 0, 0]));
        let d = downsample(&img);
        assert_eq!((d.width(), d.height()), (2, 2));
        assert_eq!(d.get_pixel(0, 0).0[0], 5);
    }

    /// Every downsampled pixel is the rounded mean of its 2×2 source block (the last row or
    /// column repeated where the source is odd or one pixel wide), on odd, even and 1-px sizes.
    #[test]
    fn downsample_is_the_rounded_mean_of_each_block() {
        for (w, h) in [(9u32, 7u32), (10, 6), (1, 5), (6, 1), (1, 1), (2, 3)] {
            let img = noise_frame(u64::from(w * 31 + h), w, h);
            let d = downsample(&img);
            let (dw, dh) = ((w / 2).max(1), (h / 2).max(1));
            assert_eq!((d.width(), d.height()), (dw, dh));
            for y in 0..dh {
                for x in 0..dw {
                    let (x0, x1) = ((2 * x).min(w - 1), (2 * x + 1).min(w - 1));
                    let (y0, y1) = ((2 * y).min(h - 1), (2 * y + 1).min(h - 1));
                    for c in 0..3 {
                        let v: u32 = [(x0, y0), (x1, y0), (x0, y1), (x1, y1)]
                            .iter()
                            .map(|&(a, b)| img.get_pixel(a, b).0[c] as u32)
                            .sum();
                        assert_eq!(
                            d.get_pixel(x, y).0[c] as u32,
                            (v + 2) / 4,
                            "{w}×{h} ({x},{y})"
                        );
                    }
                }
            }
        }
    }
}
