//! One pixel's feature vector in AVX2 intrinsics, equal bit for bit to
//! [`FrameFeatures::at`](super::FrameFeatures::at): the channels of a summed-area table entry
//! sit side by side in memory, so one masked load reads a corner's five channel sums and one
//! vector operation works on all channels of a window at once, where the scalar code loops
//! over them. The fit asks for the features of every sample of its correspondence lines
//! (10,000–20,000 pixels a view at 960×540), and those queries were its largest single cost.
//! Same operations in the same order as the scalar code: integer sums wrap alike, means are the
//! same f32 products, deviations the same f64 spreads, no fused multiply–adds.

use super::features::{
    BANK_CHANNELS, CHANNELS, FEATURE_COUNT, FeatureVector, FrameFeatures, RECIPROCAL, SCALES,
    window,
};
use super::lab_avx2::quantise;
use std::arch::x86_64::*;

/// One corner of a window: the five channels' sums (lanes 0–4; lanes 5–7 zero).
#[target_feature(enable = "avx2")]
#[inline]
fn corner(table: &[[u32; CHANNELS]], k: usize) -> __m256i {
    let entry = &table[k];
    // SAFETY: the mask reads lanes 0–4 only: the 20 bytes of `entry`.
    unsafe {
        _mm256_maskload_epi32(
            entry.as_ptr().cast(),
            _mm256_setr_epi32(-1, -1, -1, -1, -1, 0, 0, 0),
        )
    }
}

/// One corner of the squares' table: the three bank channels (lanes 0–2; lane 3 zero).
#[target_feature(enable = "avx2")]
#[inline]
fn corner_squares(table: &[[u32; BANK_CHANNELS]], k: usize) -> __m128i {
    let entry = &table[k];
    // SAFETY: the mask reads lanes 0–2 only: the 12 bytes of `entry`.
    unsafe { _mm_maskload_epi32(entry.as_ptr().cast(), _mm_setr_epi32(-1, -1, -1, 0)) }
}

/// The corners' table indices (x1,y1), (x1,y0), (x0,y1), (x0,y0) of the window of radius `r`
/// around (x, y), clipped as `features::box_sums` clips it, and its pixel count.
#[inline]
fn corners(ff: &FrameFeatures, x: usize, y: usize, r: usize) -> ([usize; 4], u32) {
    let (x0, y0, x1, y1) = window(ff.width, ff.height, x, y, r);
    let s = ff.width + 1;
    (
        [y1 * s + x1, y0 * s + x1, y1 * s + x0, y0 * s + x0],
        ((x1 - x0) * (y1 - y0)) as u32,
    )
}

/// Every channel's sum over the window with these corners (a − b − c + d, wrapping).
#[target_feature(enable = "avx2")]
#[inline]
fn sums(ff: &FrameFeatures, [a, b, c, d]: [usize; 4]) -> __m256i {
    let t = &ff.integrals;
    _mm256_add_epi32(
        _mm256_sub_epi32(_mm256_sub_epi32(corner(t, a), corner(t, b)), corner(t, c)),
        corner(t, d),
    )
}

/// Every channel's window mean: the sum (below 2³¹, so the signed conversion reads it
/// right, and below 2²⁴, so f32 holds it exactly) times 1 / area.
#[target_feature(enable = "avx2")]
#[inline]
fn means(sums: __m256i, area: u32) -> __m256 {
    _mm256_mul_ps(
        _mm256_cvtepi32_ps(sums),
        _mm256_set1_ps(RECIPROCAL[area as usize]),
    )
}

/// The mean of each channel over the window of radius `r` around (x, y).
#[target_feature(enable = "avx2")]
#[inline]
fn means_at(ff: &FrameFeatures, x: usize, y: usize, r: usize) -> __m256 {
    let (corners, area) = corners(ff, x, y, r);
    means(sums(ff, corners), area)
}

/// What one scale gives: quantised means (5 channels), deviations and gradients (3 bank
/// channels), and the unquantised means for the differences between scales.
#[derive(Clone, Copy)]
struct Scale {
    means: __m256,
    mean_q: [i32; 8],
    deviation: [i32; 8],
    gradient: [i32; 8],
}

/// One scale's features at (x, y), as `FrameFeatures::at` computes them.
#[target_feature(enable = "avx2")]
#[inline]
fn scale(ff: &FrameFeatures, x: usize, y: usize, r: usize) -> Scale {
    let (w, h) = (ff.width, ff.height);
    let ([a, b, c, d], area) = corners(ff, x, y, r);
    let s = sums(ff, [a, b, c, d]);
    let m = means(s, area);
    // Deviation: 3·√(n·Σv² − (Σv)²) / n, the spread in f64 as `features::deviation` does.
    let q = &ff.squares;
    let sq = _mm_add_epi32(
        _mm_sub_epi32(
            _mm_sub_epi32(corner_squares(q, a), corner_squares(q, b)),
            corner_squares(q, c),
        ),
        corner_squares(q, d),
    );
    let sum = _mm256_cvtepi32_pd(_mm256_castsi256_si128(s));
    let sum_sq = _mm256_cvtepi32_pd(sq);
    let spread = _mm256_max_pd(
        _mm256_sub_pd(
            _mm256_mul_pd(_mm256_set1_pd(area as f64), sum_sq),
            _mm256_mul_pd(sum, sum),
        ),
        _mm256_setzero_pd(),
    );
    // Four lanes (three channels), quantised in the lower half of eight.
    let deviation = quantise(_mm256_zextps128_ps256(_mm_mul_ps(
        _mm_mul_ps(_mm_set1_ps(3.0), _mm_sqrt_ps(_mm256_cvtpd_ps(spread))),
        _mm_set1_ps(RECIPROCAL[area as usize]),
    )));
    // Haar gradient: the window a radius ahead minus the one a radius behind.
    let gx = _mm256_sub_ps(
        means_at(ff, (x + r).min(w - 1), y, r),
        means_at(ff, x.saturating_sub(r), y, r),
    );
    let gy = _mm256_sub_ps(
        means_at(ff, x, (y + r).min(h - 1), r),
        means_at(ff, x, y.saturating_sub(r), r),
    );
    let magnitude = _mm256_sqrt_ps(_mm256_add_ps(_mm256_mul_ps(gx, gx), _mm256_mul_ps(gy, gy)));
    Scale {
        means: m,
        mean_q: quantise(m),
        deviation,
        gradient: quantise(_mm256_mul_ps(_mm256_set1_ps(2.0), magnitude)),
    }
}

/// The feature vector of pixel (x, y) of the region (its own coordinates).
#[target_feature(enable = "avx2")]
pub(super) fn feature_vector(ff: &FrameFeatures, x: usize, y: usize) -> FeatureVector {
    let mut scales = [scale(ff, x, y, ff.radii[0]); SCALES];
    for i in 1..SCALES {
        // Repeated radii (coarse levels) repeat the same windows.
        if ff.radii[i] != ff.radii[i - 1] {
            scales[i] = scale(ff, x, y, ff.radii[i]);
        } else {
            scales[i] = scales[i - 1];
        }
    }
    // Differences of neighbouring scales' means: 128 + 2 (finer − coarser).
    let differences: [[i32; 8]; SCALES - 1] = std::array::from_fn(|i| {
        quantise(_mm256_add_ps(
            _mm256_set1_ps(128.0),
            _mm256_mul_ps(
                _mm256_set1_ps(2.0),
                _mm256_sub_ps(scales[i].means, scales[i + 1].means),
            ),
        ))
    });
    let mut f = [0u8; FEATURE_COUNT];
    let px = &ff.base[y * ff.width + x];
    let mut o = 0;
    for (c, &value) in px.iter().enumerate() {
        f[o] = value;
        o += 1;
        for s in &scales {
            f[o] = s.mean_q[c] as u8;
            o += 1;
            if c < BANK_CHANNELS {
                f[o] = s.deviation[c] as u8;
                f[o + 1] = s.gradient[c] as u8;
                o += 2;
            }
        }
        if c < BANK_CHANNELS {
            for d in &differences {
                f[o] = d[c] as u8;
                o += 1;
            }
        }
    }
    debug_assert_eq!(o, FEATURE_COUNT);
    f
}
