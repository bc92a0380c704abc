//! The per-pixel channels (CIELAB and normalised red and green, quantised) of eight pixels at
//! once in AVX2 intrinsics: the same operations in the same order as
//! [`super::features::base_channels`], so the result is equal bit for bit (no fused
//! multiply–adds; f32 and f64 rounding as the scalar code rounds). The compiler's own
//! vectorisation of the lane-wise Rust left most of this scalar, and the conversion was the
//! largest part of preparing a region's features for the fit (1.4 of the 1.9 ms a 420×270
//! region took on one core).

use super::features::{BANK_CHANNELS, CHANNELS};
use std::arch::x86_64::*;

/// Pixels per call (`features::base_channels_many`'s lanes).
const LANES: usize = 8;

/// The channels of 8 pixels; `rgb` holds exactly 24 bytes (R, G, B interleaved), `lut` is
/// sRGB → linear light and `recip` 255·2¹⁶ / (r + g + b).
#[target_feature(enable = "avx2")]
pub(super) fn base_channels_lanes(
    rgb: &[u8],
    lut: &[f32; 256],
    recip: &[u32; 766],
) -> [[u8; CHANNELS]; LANES] {
    let mut cr = [0f32; LANES];
    let mut cg = [0f32; LANES];
    let mut cb = [0f32; LANES];
    for k in 0..LANES {
        cr[k] = lut[rgb[3 * k] as usize];
        cg[k] = lut[rgb[3 * k + 1] as usize];
        cb[k] = lut[rgb[3 * k + 2] as usize];
    }
    let (r, g, b) = (load(&cr), load(&cg), load(&cb));
    let c = _mm256_set1_ps;
    let mul = _mm256_mul_ps;
    let add = _mm256_add_ps;
    // As the scalar code: ((c₀·r + c₁·g) + c₂·b) / n, each step rounded.
    let x = _mm256_div_ps(
        add(
            add(mul(c(0.412_456_4), r), mul(c(0.357_576_1), g)),
            mul(c(0.180_437_5), b),
        ),
        c(0.950_47),
    );
    let y = add(
        add(mul(c(0.212_672_9), r), mul(c(0.715_152_2), g)),
        mul(c(0.072_175), b),
    );
    let z = _mm256_div_ps(
        add(
            add(mul(c(0.019_333_9), r), mul(c(0.119_192), g)),
            mul(c(0.950_304_1), b),
        ),
        c(1.088_83),
    );
    let (fx, fy, fz) = (lab_f(x), lab_f(y), lab_f(z));
    let sub = _mm256_sub_ps;
    let l = sub(mul(c(116.0), fy), c(16.0));
    let a = mul(c(500.0), sub(fx, fy));
    let bb = mul(c(200.0), sub(fy, fz));
    let bank: [[i32; LANES]; BANK_CHANNELS] = [
        quantise(mul(c(2.55), l)),
        quantise(add(c(128.0), mul(c(1.5), a))),
        quantise(add(c(128.0), mul(c(1.5), bb))),
    ];
    let mut out = [[0u8; CHANNELS]; LANES];
    for (k, o) in out.iter_mut().enumerate() {
        let (pr, pg, pb) = (rgb[3 * k], rgb[3 * k + 1], rgb[3 * k + 2]);
        let rc = recip[pr as usize + pg as usize + pb as usize] as u64;
        let n = |v: u8| (((v as u64 * rc) + 32768) >> 16).min(255) as u8;
        *o = [
            bank[0][k] as u8,
            bank[1][k] as u8,
            bank[2][k] as u8,
            n(pr),
            n(pg),
        ];
    }
    out
}

#[target_feature(enable = "avx2")]
fn load(v: &[f32; LANES]) -> __m256 {
    // SAFETY: `v` holds 8 f32 (32 bytes); the load is unaligned.
    unsafe { _mm256_loadu_ps(v.as_ptr()) }
}

/// (v.clamp(0, 255) + 0.5) truncated, as `features::quantise`, of 8 lanes (v is never NaN
/// here); also `pixel_avx2`'s.
#[target_feature(enable = "avx2")]
#[inline]
pub(super) fn quantise(v: __m256) -> [i32; LANES] {
    let clamped = _mm256_min_ps(_mm256_max_ps(v, _mm256_setzero_ps()), _mm256_set1_ps(255.0));
    let q = _mm256_cvttps_epi32(_mm256_add_ps(clamped, _mm256_set1_ps(0.5)));
    let mut out = [0i32; LANES];
    // SAFETY: `out` holds 8 i32 (32 bytes); the store is unaligned.
    unsafe { _mm256_storeu_si256(out.as_mut_ptr().cast(), q) };
    out
}

/// CIELAB's f(t): the cube root above the linear segment, as `features::lab_f_lanes` and
/// `features::cube_root` compute it (bit-level guess, two Halley steps in f64).
#[target_feature(enable = "avx2")]
fn lab_f(t: __m256) -> __m256 {
    let mut bits = [0u32; LANES];
    // SAFETY: `bits` holds 8 u32 (32 bytes); the store is unaligned.
    unsafe { _mm256_storeu_si256(bits.as_mut_ptr().cast(), _mm256_castps_si256(t)) };
    let guess = bits.map(|b| b / 3 + 0x2a51_4067);
    // SAFETY: as above, a load of 8 u32.
    let guess = _mm256_castsi256_ps(unsafe { _mm256_loadu_si256(guess.as_ptr().cast()) });
    let halves = [
        (_mm256_castps256_ps128(t), _mm256_castps256_ps128(guess)),
        (
            _mm256_extractf128_ps::<1>(t),
            _mm256_extractf128_ps::<1>(guess),
        ),
    ];
    let [lo, hi] = halves.map(|(t, guess)| {
        let t64 = _mm256_cvtps_pd(t);
        let mut y = _mm256_cvtps_pd(guess);
        let two = _mm256_set1_pd(2.0);
        for _ in 0..2 {
            let y3 = _mm256_mul_pd(_mm256_mul_pd(y, y), y);
            let num = _mm256_add_pd(y3, _mm256_mul_pd(two, t64));
            let den = _mm256_add_pd(_mm256_mul_pd(two, y3), t64);
            y = _mm256_mul_pd(y, _mm256_div_pd(num, den));
        }
        _mm256_cvtpd_ps(y)
    });
    let root = _mm256_set_m128(hi, lo);
    let linear = _mm256_add_ps(
        _mm256_mul_ps(_mm256_set1_ps(7.787), t),
        _mm256_set1_ps(16.0f32 / 116.0),
    );
    let above = _mm256_cmp_ps::<_CMP_GT_OQ>(t, _mm256_set1_ps(0.008_856));
    _mm256_blendv_ps(linear, root, above)
}
