//! The fit region's two summed-area tables (every channel, and the bank channels' squares) in
//! one pass over its pixels, in AVX2 intrinsics: a pixel's five channels are one vector, so a
//! table entry is one add to the row's running sum and one add of the entry above, where the
//! portable code ([`super::features`]' `summed_area`) loops over the channels of each table
//! in turn. The same wrapping u32 additions in the same order, so the tables are equal bit for
//! bit. The fit rebuilds these tables over most of each view's frame every frame (~110,000
//! pixels a view at 960×540), and they were the larger part of preparing its features.

use super::features::{BANK_CHANNELS, CHANNELS};
use std::arch::x86_64::*;

/// Fills the (w+1)×(h+1) tables `sums` (channels) and `squares` (the bank channels' squares)
/// of the w×h pixels `base`, row-major; their first row and column must already be zero and
/// stay so. Panics when a slice is shorter than those sizes (a caller's error).
#[target_feature(enable = "avx2")]
pub(super) fn fill(
    base: &[[u8; CHANNELS]],
    (w, h): (usize, usize),
    sums: &mut [[u32; CHANNELS]],
    squares: &mut [[u32; BANK_CHANNELS]],
) {
    let stride = w + 1;
    assert!(base.len() >= w * h);
    assert!(sums.len() >= stride * (h + 1) && squares.len() >= stride * (h + 1));
    if w == 0 {
        return;
    }
    let keep_sums = _mm256_setr_epi32(-1, -1, -1, -1, -1, 0, 0, 0);
    let keep_squares = _mm_setr_epi32(-1, -1, -1, 0);
    let sums_ptr = sums.as_mut_ptr();
    let squares_ptr = squares.as_mut_ptr();
    for (y, pixels) in base.chunks_exact(w).take(h).enumerate() {
        let (above, here) = (y * stride + 1, (y + 1) * stride + 1);
        let mut row = _mm256_setzero_si256();
        let mut row_squares = _mm_setzero_si128();
        for (x, p) in pixels.iter().enumerate() {
            // Lanes 0–4 the channels, 5–7 zero.
            let bytes =
                _mm_cvtsi64_si128(i64::from_le_bytes([p[0], p[1], p[2], p[3], p[4], 0, 0, 0]));
            row = _mm256_add_epi32(row, _mm256_cvtepu8_epi32(bytes));
            // 255² fits in 16 bits: squared as u16, widened. Lane 3 (not a bank channel) is
            // only ever written where the next entry will be, or masked off.
            let wide = _mm_cvtepu8_epi16(bytes);
            let square = _mm_cvtepu16_epi32(_mm_mullo_epi16(wide, wide));
            row_squares = _mm_add_epi32(row_squares, square);
            let (up, at) = (above + x, here + x);
            // SAFETY: `at` and `up` are entries 1..=w of rows y+1 and y, inside the tables
            // (asserted above). Before the row's last entry, the vectors reach 12 (sums) and 4
            // (squares) bytes into entry x+2 of the same rows, which exists; what is written
            // there is overwritten with that entry's own sums on the next pixel. The last entry
            // is read and written through masks, so the next row's zero column is left alone.
            unsafe {
                if x + 1 < w {
                    let a = _mm256_loadu_si256(sums_ptr.add(up).cast());
                    _mm256_storeu_si256(sums_ptr.add(at).cast(), _mm256_add_epi32(a, row));
                    let a = _mm_loadu_si128(squares_ptr.add(up).cast());
                    _mm_storeu_si128(squares_ptr.add(at).cast(), _mm_add_epi32(a, row_squares));
                } else {
                    let a = _mm256_maskload_epi32(sums_ptr.add(up).cast(), keep_sums);
                    let cell = _mm256_add_epi32(a, row);
                    _mm256_maskstore_epi32(sums_ptr.add(at).cast(), keep_sums, cell);
                    let a = _mm_maskload_epi32(squares_ptr.add(up).cast(), keep_squares);
                    let cell = _mm_add_epi32(a, row_squares);
                    _mm_maskstore_epi32(squares_ptr.add(at).cast(), keep_squares, cell);
                }
            }
        }
    }
}
