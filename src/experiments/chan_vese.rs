//! The baseline of Fig. 4: Chan and Vese's active contour without edges (ACWOE, the paper's
//! [37]), which minimises the same region energy as eq. 4 over a level-set function φ of the
//! image instead of over the pose and shape of a model, with length (curvature) regularisation.
//!
//! The scheme is Getreuer's semi-implicit one, as scikit-image's `chan_vese` implements it
//! (its defaults: μ = 0.25, λ₁ = λ₂ = 1, Δt = 0.5, tolerance 10⁻³, 500 iterations, a
//! checkerboard start, intensities scaled to [0, 1]), so the two can be checked against each
//! other (`benches/chan_vese_vs_skimage.py`). Two departures, both measured on the experiments'
//! 640×480 images at σ = 0.25 (four views): every `reinit_every` iterations φ is reset to the
//! signed distance of its zero level (scikit-image leaves φ unreset), which keeps |∇φ| ≈ 1 so
//! the curvature term means the same everywhere; and up to 1,000 iterations. Unreset, the RMS
//! change of φ falls under the tolerance after ~50 iterations with the checkerboard still
//! half there (Dice 0.20–0.84); reset every 20 for 200 iterations 0.48–0.999; for 1,000,
//! 0.998–0.999.

use crate::plane::Mask;
use crate::render::squared_edt;

/// Settings of one segmentation (see the module docs for the defaults' origin).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChanVeseParams {
    /// Weight of the contour length.
    pub mu: f64,
    pub lambda_inside: f64,
    pub lambda_outside: f64,
    pub dt: f64,
    /// Stop when the RMS change of φ in one iteration falls below this.
    pub tolerance: f64,
    pub max_iterations: usize,
    /// Reset φ to a signed distance every this many iterations (None: never, as scikit-image).
    pub reinit_every: Option<usize>,
}

impl Default for ChanVeseParams {
    fn default() -> Self {
        Self {
            mu: 0.25,
            lambda_inside: 1.0,
            lambda_outside: 1.0,
            dt: 0.5,
            tolerance: 1e-3,
            max_iterations: 1000,
            reinit_every: Some(20),
        }
    }
}

/// What a segmentation produced.
#[derive(Debug, Clone)]
pub struct Segmentation {
    /// φ > 0.
    pub inside: Mask,
    /// Mean intensity inside and outside at the end (of the [0, 1]-scaled image).
    pub c_inside: f64,
    pub c_outside: f64,
    pub iterations: usize,
}

impl Segmentation {
    /// The brighter phase: the object of an image whose object is brighter than its
    /// background (which phase is "inside" depends only on the checkerboard's start).
    pub fn brighter(&self) -> Mask {
        if self.c_inside >= self.c_outside {
            self.inside.clone()
        } else {
            self.inside.map(|&v| !v)
        }
    }
}

/// Smoothed Dirac delta of the scheme (scikit-image's `_cv_delta`, h = 1).
fn delta(x: f64) -> f64 {
    1.0 / (1.0 + x * x)
}

/// Segments a `width`×`height` image (row-major intensities) into two phases.
pub fn segment(intensity: &[f32], width: usize, height: usize, p: &ChanVeseParams) -> Segmentation {
    let n = width * height;
    assert_eq!(intensity.len(), n, "image size");
    // Scaled to [0, 1] as scikit-image does.
    let (lo, hi) = intensity
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let span = if hi > lo { (hi - lo) as f64 } else { 1.0 };
    let img: Vec<f64> = intensity.iter().map(|&v| (v - lo) as f64 / span).collect();
    // Checkerboard start: sin(πx/5)·sin(πy/5).
    let mut phi: Vec<f64> = (0..n)
        .map(|i| {
            let (x, y) = ((i % width) as f64, (i / width) as f64);
            (std::f64::consts::PI / 5.0 * x).sin() * (std::f64::consts::PI / 5.0 * y).sin()
        })
        .collect();
    let mut next = vec![0.0; n];
    let mut last_mask: Vec<bool> = phi.iter().map(|&v| v > 0.0).collect();
    let mut still = 0;
    let mut iterations = 0;
    let (mut c1, mut c2) = averages(&img, &phi);
    while iterations < p.max_iterations {
        (c1, c2) = averages(&img, &phi);
        update_rows(&phi, &mut next, &img, width, height, (c1, c2), p);
        iterations += 1;
        let change = (next
            .iter()
            .zip(&phi)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            / n as f64)
            .sqrt();
        std::mem::swap(&mut phi, &mut next);
        if p.reinit_every
            .is_some_and(|k| k > 0 && iterations.is_multiple_of(k))
        {
            reinitialise(&mut phi, width, height);
            // Reset φ moves by more than the tolerance every time: converged instead when the
            // segmentation itself stands still (fewer than 1 pixel in 10⁴ changed since the
            // last reset, three resets running).
            let now: Vec<bool> = phi.iter().map(|&v| v > 0.0).collect();
            let changed = now.iter().zip(&last_mask).filter(|(a, b)| a != b).count();
            still = if changed * 10_000 < n { still + 1 } else { 0 };
            last_mask = now;
            if still >= 3 {
                break;
            }
        }
        if change < p.tolerance {
            break;
        }
    }
    let inside = Mask::from_vec(width, height, phi.iter().map(|&v| v > 0.0).collect())
        .expect("φ has the image's size");
    if iterations > 0 {
        (c1, c2) = averages(&img, &phi);
    }
    Segmentation {
        inside,
        c_inside: c1,
        c_outside: c2,
        iterations,
    }
}

/// One semi-implicit step of every pixel (rows in parallel), edge-padded like scikit-image.
fn update_rows(
    phi: &[f64],
    next: &mut [f64],
    img: &[f64],
    width: usize,
    height: usize,
    (c1, c2): (f64, f64),
    p: &ChanVeseParams,
) {
    use rayon::prelude::*;
    const ETA: f64 = 1e-16;
    next.par_chunks_mut(width).enumerate().for_each(|(y, row)| {
        let up = y.saturating_sub(1) * width;
        let down = (y + 1).min(height - 1) * width;
        let here = y * width;
        for (x, out) in row.iter_mut().enumerate() {
            let (xl, xr) = (x.saturating_sub(1), (x + 1).min(width - 1));
            let c = phi[here + x];
            let (xp, xn) = (phi[here + xr], phi[here + xl]);
            let (yp, yn) = (phi[down + x], phi[up + x]);
            let (phix0, phiy0) = ((xp - xn) / 2.0, (yp - yn) / 2.0);
            let cc1 = 1.0 / (ETA + (xp - c).powi(2) + phiy0 * phiy0).sqrt();
            let cc2 = 1.0 / (ETA + (c - xn).powi(2) + phiy0 * phiy0).sqrt();
            let cc3 = 1.0 / (ETA + phix0 * phix0 + (yp - c).powi(2)).sqrt();
            let cc4 = 1.0 / (ETA + phix0 * phix0 + (c - yn).powi(2)).sqrt();
            let k = xp * cc1 + xn * cc2 + yp * cc3 + yn * cc4;
            let v = img[here + x];
            let data = -p.lambda_inside * (v - c1).powi(2) + p.lambda_outside * (v - c2).powi(2);
            let d = p.dt * delta(c);
            *out = (c + d * (p.mu * k + data)) / (1.0 + p.mu * d * (cc1 + cc2 + cc3 + cc4));
        }
    });
}

/// Mean intensity where φ > 0 and where not (0 for an empty phase).
fn averages(img: &[f64], phi: &[f64]) -> (f64, f64) {
    let (mut s1, mut n1, mut s2, mut n2) = (0.0, 0usize, 0.0, 0usize);
    for (&v, &f) in img.iter().zip(phi) {
        if f > 0.0 {
            s1 += v;
            n1 += 1;
        } else {
            s2 += v;
            n2 += 1;
        }
    }
    (s1 / n1.max(1) as f64, s2 / n2.max(1) as f64)
}

/// φ ← the signed distance (px) of its zero level: + inside, − outside, half a pixel from the
/// boundary on either side.
fn reinitialise(phi: &mut [f64], width: usize, height: usize) {
    let inside = Mask::from_vec(width, height, phi.iter().map(|&v| v > 0.0).collect())
        .expect("φ has the image's size");
    if inside.count() == 0 || inside.count() == inside.data.len() {
        return;
    }
    let to_inside = squared_edt(&inside);
    let to_outside = squared_edt(&inside.map(|&v| !v));
    for (i, f) in phi.iter_mut().enumerate() {
        *f = if inside.data[i] {
            (to_outside.data[i] as f64).sqrt() - 0.5
        } else {
            -((to_inside.data[i] as f64).sqrt() - 0.5)
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plane::dice;
    use crate::rng::Rng;

    fn disc(width: usize, height: usize) -> Mask {
        let (cx, cy, r) = (width as f64 / 2.0, height as f64 / 2.0, height as f64 / 3.0);
        Mask::from_vec(
            width,
            height,
            (0..width * height)
                .map(|i| {
                    let (x, y) = ((i % width) as f64, (i / width) as f64);
                    (x - cx).hypot(y - cy) < r
                })
                .collect(),
        )
        .unwrap()
    }

    /// A bright disc in light noise is found (Dice > 0.97), with and without reinitialisation,
    /// and the phase means come out near the true intensities.
    #[test]
    fn finds_a_disc_in_light_noise() {
        let truth = disc(64, 48);
        let mut rng = Rng::new(5);
        let img: Vec<f32> = truth
            .data
            .iter()
            .map(|&v| (if v { 1.0 } else { 0.0 } + 0.2 * rng.normal()) as f32)
            .collect();
        for reinit in [None, Some(20)] {
            let seg = segment(
                &img,
                64,
                48,
                &ChanVeseParams {
                    reinit_every: reinit,
                    ..Default::default()
                },
            );
            let d = dice(&seg.brighter(), &truth).unwrap();
            assert!(d > 0.97, "reinit {reinit:?}: Dice {d}");
            let (bright, dark) = (
                seg.c_inside.max(seg.c_outside),
                seg.c_inside.min(seg.c_outside),
            );
            assert!(bright - dark > 0.3, "means {bright} {dark}");
        }
    }

    /// Reinitialisation keeps the zero level (the segmentation) and makes |∇φ| ≈ 1.
    #[test]
    fn reinitialisation_keeps_the_contour() {
        let truth = disc(40, 30);
        let mut phi: Vec<f64> = truth
            .data
            .iter()
            .map(|&v| if v { 3.0 } else { -0.2 })
            .collect();
        reinitialise(&mut phi, 40, 30);
        let kept = truth.data.iter().zip(&phi).all(|(&v, &f)| v == (f > 0.0));
        assert!(kept);
        // Along the middle row, neighbours inside the disc differ by one pixel's distance.
        let row = 15 * 40;
        assert!(((phi[row + 20] - phi[row + 19]).abs() - 1.0).abs() < 0.2 || phi[row + 20] > 8.0);
        assert!((phi[row + 2] - phi[row + 3]).abs() > 0.8);
    }
}
