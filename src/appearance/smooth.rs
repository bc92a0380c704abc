//! Spatial smoothing of class probabilities: a pixel's label is decided by the probabilities
//! around it, not by its own alone.
//!
//! The forest labels each pixel on its own; on real tissue its mistakes are speckle (a glint
//! on fat, a pale spot on the kidney) that a few pixels' neighbourhood outvotes. Three passes
//! of a running-sum box filter approximate a Gaussian (σ² = 3·(w² − 1)/12 for a box of width
//! w = 2r + 1) at O(1) per pixel whatever the radius; the borders clamp (a pixel outside the
//! frame repeats the edge). Sums stay normalised, so each pixel's probabilities still add to 1.

use super::ProbabilityMaps;
use rayon::prelude::*;

/// Box radius (px) of three passes whose Gaussian has standard deviation `sigma_px`.
pub fn box_radius_for_sigma(sigma_px: f32) -> usize {
    // σ² = (w² − 1)/4 for three passes of width w: w = sqrt(4σ² + 1).
    let w = (4.0 * sigma_px.max(0.0).powi(2) + 1.0).sqrt();
    ((w - 1.0) / 2.0).round().max(0.0) as usize
}

/// One pass of a running-sum box of radius `r` along a contiguous line (edges clamped), from
/// `src` into `dst` (same length).
fn box_line(src: &[f32], dst: &mut [f32], r: usize) {
    let n = src.len();
    let at = |i: isize| src[i.clamp(0, n as isize - 1) as usize];
    let norm = 1.0 / (2 * r + 1) as f32;
    let mut sum: f32 = (-(r as isize)..=r as isize).map(at).sum();
    for (i, d) in dst.iter_mut().enumerate() {
        *d = sum * norm;
        sum += at(i as isize + r as isize + 1) - at(i as isize - r as isize);
    }
}

/// One class plane smoothed by three box passes along rows and three along columns.
fn smooth_plane(plane: &mut [f32], width: usize, height: usize, r: usize) {
    let mut tmp = vec![0f32; plane.len()];
    for _ in 0..3 {
        plane
            .par_chunks(width)
            .zip(tmp.par_chunks_mut(width))
            .for_each(|(src, dst)| box_line(src, dst, r));
        plane.copy_from_slice(&tmp);
    }
    // Columns: transpose through a buffer so each column is contiguous (cache-friendly).
    let mut cols = vec![0f32; plane.len()];
    for (y, row) in plane.chunks(width).enumerate() {
        for (x, &v) in row.iter().enumerate() {
            cols[x * height + y] = v;
        }
    }
    let mut out = vec![0f32; plane.len()];
    for _ in 0..3 {
        cols.par_chunks(height)
            .zip(out.par_chunks_mut(height))
            .for_each(|(src, dst)| box_line(src, dst, r));
        cols.copy_from_slice(&out);
    }
    for (x, col) in cols.chunks(height).enumerate() {
        for (y, &v) in col.iter().enumerate() {
            plane[y * width + x] = v;
        }
    }
}

impl ProbabilityMaps {
    /// The maps smoothed by a Gaussian of `sigma_px` (three box passes); unchanged for a
    /// radius of 0 or an empty map.
    pub fn smoothed(&self, sigma_px: f32) -> ProbabilityMaps {
        let r = box_radius_for_sigma(sigma_px);
        if r == 0 || self.width == 0 || self.height == 0 || self.classes == 0 {
            return self.clone();
        }
        let mut out = self.clone();
        for k in 0..self.classes {
            let mut plane: Vec<f32> = self
                .data
                .iter()
                .skip(k)
                .step_by(self.classes)
                .copied()
                .collect();
            smooth_plane(&mut plane, self.width, self.height, r);
            for (i, v) in plane.into_iter().enumerate() {
                out.data[i * self.classes + k] = v;
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Brute force: three clamped box passes along rows, then three along columns.
    fn brute(plane: &[f32], w: usize, h: usize, r: usize) -> Vec<f32> {
        let r = r as isize;
        let mut p = plane.to_vec();
        for axis in 0..2 {
            for _ in 0..3 {
                let q = p.clone();
                for y in 0..h as isize {
                    for x in 0..w as isize {
                        let mut s = 0.0;
                        for d in -r..=r {
                            let (xx, yy) = if axis == 0 {
                                ((x + d).clamp(0, w as isize - 1), y)
                            } else {
                                (x, (y + d).clamp(0, h as isize - 1))
                            };
                            s += q[(yy as usize) * w + xx as usize];
                        }
                        p[(y as usize) * w + x as usize] = s / (2 * r + 1) as f32;
                    }
                }
            }
        }
        p
    }

    #[test]
    fn smoothing_matches_brute_force_three_box_passes_and_keeps_sums_at_one() {
        let (w, h, k) = (23, 11, 3);
        let mut rng = crate::rng::Rng::new(4);
        let mut data = Vec::new();
        for _ in 0..w * h {
            let raw: Vec<f32> = (0..k).map(|_| rng.uniform() as f32 + 0.01).collect();
            let s: f32 = raw.iter().sum();
            data.extend(raw.iter().map(|v| v / s));
        }
        let maps = ProbabilityMaps {
            width: w,
            height: h,
            classes: k,
            data,
        };
        let sigma = 2.0;
        let r = box_radius_for_sigma(sigma);
        assert_eq!(
            r, 2,
            "σ 2 px: boxes of width 5 (σ 2.45 px, the nearest odd width)"
        );
        let fast = maps.smoothed(sigma);
        for c in 0..k {
            let want = brute(&maps.class_plane(c).data, w, h, r);
            let got = fast.class_plane(c).data;
            for (a, b) in got.iter().zip(&want) {
                assert!((a - b).abs() < 1e-5, "{a} against brute force {b}");
            }
        }
        for p in fast.data.chunks_exact(k) {
            assert!((p.iter().sum::<f32>() - 1.0).abs() < 1e-4);
        }
        assert_eq!(
            maps.smoothed(0.3),
            maps,
            "a radius of 0 leaves the maps alone"
        );
    }
}
