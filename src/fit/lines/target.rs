//! What one correspondence line says about where its contour should be: the softmin target
//! shift over its 1D energy profile and how certain that is (the Laplace approximation the
//! Gauss–Newton step weighs it by), in the style of SRT3D/ICG; and the fit's confidence, read
//! off the lines at the optimum.

use super::{EnergyParams, Line};
use crate::fit::context::FrameContext;
use crate::fit::state::FitState;
use glam::DVec2;

/// Longest line [`line_target`] works on the stack for: 2 × 64 + 1 samples (the longest
/// `energy.half_length` allows) and their shifts; a longer one takes the heap.
const STACK_SAMPLES: usize = 160;

/// A line's softmin target shift (level px) and its variance, from its 1D energy profile.
pub fn line_target(line: &Line, c: DVec2, ep: &EnergyParams) -> (f64, f64) {
    let r = (ep.half_length / 2) as i64;
    let n = line.samples.len();
    let shifts = (2 * r + 1) as usize;
    // The steps ask this of every line at every step: its buffers live on the stack (fresh
    // vectors per call were most of its cost).
    if n <= STACK_SAMPLES && n + shifts <= 2 * STACK_SAMPLES {
        let mut offsets = [0i64; STACK_SAMPLES];
        let mut heaviside = [0f64; 2 * STACK_SAMPLES];
        let mut profile = [0f64; STACK_SAMPLES];
        let mut weights = [0f64; STACK_SAMPLES];
        if shifts <= STACK_SAMPLES {
            return target_with(
                line,
                c,
                ep,
                &mut offsets[..n],
                &mut heaviside,
                &mut profile[..shifts],
                &mut weights[..shifts],
            );
        }
    }
    target_with(
        line,
        c,
        ep,
        &mut vec![0; n],
        &mut vec![0.0; n + shifts + 1],
        &mut vec![0.0; shifts],
        &mut vec![0.0; shifts],
    )
}

/// [`line_target`] in the given buffers: `offsets` one per sample, `heaviside` at least the
/// samples' span plus the shifts, `profile` and `weights` one per shift.
fn target_with(
    line: &Line,
    c: DVec2,
    ep: &EnergyParams,
    offsets: &mut [i64],
    heaviside: &mut [f64],
    profile: &mut [f64],
    weights: &mut [f64],
) -> (f64, f64) {
    let r = (ep.half_length / 2) as i64;
    // Samples lie one pixel apart along the normal, so every (sample, shift) pair sees the
    // Heaviside at t₀ + m for an integer m: evaluate those few once instead of per pair.
    let Some(first) = line.samples.first() else {
        return (0.0, f64::INFINITY);
    };
    let t0 = line.normal.dot(c - first.pos);
    for (o, s) in offsets.iter_mut().zip(&line.samples) {
        *o = (line.normal.dot(c - s.pos) - t0).round() as i64;
    }
    let lo = offsets.iter().copied().min().unwrap_or(0) - r;
    let hi = offsets.iter().copied().max().unwrap_or(0) + r;
    let span = (hi - lo + 1) as usize;
    if span > heaviside.len() {
        // Samples further apart than one pixel each (a caller's line, not the builder's).
        return target_with(line, c, ep, offsets, &mut vec![0.0; span], profile, weights);
    }
    // e^(−(t₀ + m)/w) = e^(−t₀/w) · e^(−1/w)^m: one `exp` and a running product per line.
    let first = (-(t0 + lo as f64) / ep.heaviside_px).exp();
    let ratio = (-1.0 / ep.heaviside_px).exp();
    let mut power = first;
    for h in heaviside[..span].iter_mut() {
        *h = 1.0 / (1.0 + power);
        power *= ratio;
    }
    // Each shift's energy summed over the samples in their order; the shifts side by side,
    // which read consecutive Heaviside values (the compiler vectorises this loop).
    profile.fill(0.0);
    let shifts = profile.len();
    for (s, &m) in line.samples.iter().zip(offsets.iter()) {
        let (g_f, g_b) = (s.g_f as f64, s.g_b as f64);
        let from = (m - r - lo) as usize;
        for (e, &h) in profile.iter_mut().zip(&heaviside[from..from + shifts]) {
            *e += g_f * h + g_b * (1.0 - h);
        }
    }
    let profile = &*profile;
    let min = profile.iter().cloned().fold(f64::INFINITY, f64::min);
    for (w, e) in weights.iter_mut().zip(profile) {
        *w = (-(e - min)).exp();
    }
    let weights = &*weights;
    let total: f64 = weights.iter().sum();
    let mean = weights
        .iter()
        .enumerate()
        .map(|(i, w)| w * (i as i64 - r) as f64)
        .sum::<f64>()
        / total;
    let var = weights
        .iter()
        .enumerate()
        .map(|(i, w)| w * ((i as i64 - r) as f64 - mean).powi(2))
        .sum::<f64>()
        / total;
    // Close to the optimum the softmin collapses onto one integer shift and loses the sub-pixel
    // offset the smooth energy still sees: refine with a parabola through the neighbours of
    // the best shift, weighted by its curvature (Laplace approximation).
    let k = profile
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))
        .map(|(i, _)| i)
        .unwrap_or(r as usize);
    // Best at the end of the range: the line only says "at least r further". That is what a
    // tool over the organ's rim looks like (background all along the line), and it must not
    // pull as firmly as a clean edge does (measured: seed 5's hidden-tumour error 4.72 →
    // 3.68 mm, seed 6's LS Dice 0.907 → 0.944).
    if k == 0 || k + 1 == profile.len() {
        return (k as f64 - r as f64, ep.saturated_line_variance_px2);
    }
    if var < ep.parabola_below_variance_px2 {
        let [lowest, highest] = ep.parabola_variance_px2;
        let (em, e0, ep) = (profile[k - 1], profile[k], profile[k + 1]);
        let curvature = em - 2.0 * e0 + ep;
        if curvature > 1e-9 {
            let offset = (0.5 * (em - ep) / curvature).clamp(-0.5, 0.5);
            return (
                k as f64 - r as f64 + offset,
                (1.0 / curvature).clamp(lowest, highest),
            );
        }
    }
    (mean, var.max(ep.min_softmin_variance_px2))
}

/// Mean p_f just inside minus just outside the fitted contours, over lines (each counting as
/// the rim lines it stands for), clamped to [0, 1] (`contrasts` from [`line_contrasts`]).
pub fn confidence(contrasts: &[(usize, f64, f64)]) -> f64 {
    mean_clamped(contrasts.iter().map(|&(_, c, w)| (c, w)))
}

/// [`confidence`] per structure, then averaged over `structures` (those the forest knows): a
/// small exophytic tumour counts as much as the kidney, whose outline alone cannot tell the
/// organ from its mirror image, and a structure without a line (turned out of sight) counts 0.
pub fn structure_confidence(contrasts: &[(usize, f64, f64)], structures: &[usize]) -> f64 {
    mean_clamped(structures.iter().map(|&s| {
        let of_s = contrasts.iter().filter(|&&(t, _, _)| t == s);
        (mean_clamped(of_s.map(|&(_, c, w)| (c, w))), 1.0)
    }))
}

/// The weighted mean of (value, weight) pairs, clamped to [0, 1]; 0 without weight.
fn mean_clamped(values: impl Iterator<Item = (f64, f64)>) -> f64 {
    let (sum, total) = values.fold((0.0, 0.0), |(s, t), (v, w)| (s + v * w, t + w));
    if total <= 0.0 {
        0.0
    } else {
        (sum / total).clamp(0.0, 1.0)
    }
}

/// Each line's structure, its mean p_f just inside minus just outside the fitted contour, and
/// its weight (the rim lines it stands for).
pub fn line_contrasts(
    lines: &[Line],
    state: &FitState,
    ctx: &FrameContext,
    ep: &EnergyParams,
) -> Vec<(usize, f64, f64)> {
    let deformed = ctx.model.deformed(&state.shape);
    let mut out = Vec::with_capacity(lines.len());
    for line in lines {
        let Some(c) = ctx.contour_point(line, state, &deformed, ep.level) else {
            continue;
        };
        let (mut pin, mut nin, mut pout, mut nout) = (0.0, 0, 0.0, 0);
        for s in &line.samples {
            let dist = line.normal.dot(c - s.pos);
            if dist > ep.confidence_band_px {
                pin += s.p_f as f64;
                nin += 1;
            } else if dist < -ep.confidence_band_px {
                pout += s.p_f as f64;
                nout += 1;
            }
        }
        if nin > 0 && nout > 0 {
            out.push((
                line.structure,
                pin / nin as f64 - pout / nout as f64,
                line.weight,
            ));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::super::Sample;
    use super::*;

    /// The target as it was computed before its buffers moved to the stack: vectors, and each
    /// shift's energy summed over the samples in one pass.
    fn target_with_vectors(line: &Line, c: DVec2, ep: &EnergyParams) -> (f64, f64) {
        let r = (ep.half_length / 2) as i64;
        let first = &line.samples[0];
        let t0 = line.normal.dot(c - first.pos);
        let offsets: Vec<i64> = line
            .samples
            .iter()
            .map(|s| (line.normal.dot(c - s.pos) - t0).round() as i64)
            .collect();
        let lo = offsets.iter().copied().min().unwrap() - r;
        let hi = offsets.iter().copied().max().unwrap() + r;
        let first = (-(t0 + lo as f64) / ep.heaviside_px).exp();
        let ratio = (-1.0 / ep.heaviside_px).exp();
        let mut power = first;
        let heaviside: Vec<f64> = (lo..=hi)
            .map(|_| {
                let h = 1.0 / (1.0 + power);
                power *= ratio;
                h
            })
            .collect();
        let profile: Vec<f64> = (-r..=r)
            .map(|delta| {
                line.samples
                    .iter()
                    .zip(&offsets)
                    .map(|(s, &m)| {
                        let h = heaviside[(m + delta - lo) as usize];
                        s.g_f as f64 * h + s.g_b as f64 * (1.0 - h)
                    })
                    .sum()
            })
            .collect();
        let min = profile.iter().cloned().fold(f64::INFINITY, f64::min);
        let weights: Vec<f64> = profile.iter().map(|e| (-(e - min)).exp()).collect();
        let total: f64 = weights.iter().sum();
        let mean = weights
            .iter()
            .enumerate()
            .map(|(i, w)| w * (i as i64 - r) as f64)
            .sum::<f64>()
            / total;
        let var = weights
            .iter()
            .enumerate()
            .map(|(i, w)| w * ((i as i64 - r) as f64 - mean).powi(2))
            .sum::<f64>()
            / total;
        let k = profile
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(b.1))
            .map(|(i, _)| i)
            .unwrap();
        if k == 0 || k + 1 == profile.len() {
            return (k as f64 - r as f64, ep.saturated_line_variance_px2);
        }
        if var < ep.parabola_below_variance_px2 {
            let [lowest, highest] = ep.parabola_variance_px2;
            let (em, e0, ep) = (profile[k - 1], profile[k], profile[k + 1]);
            let curvature = em - 2.0 * e0 + ep;
            if curvature > 1e-9 {
                let offset = (0.5 * (em - ep) / curvature).clamp(-0.5, 0.5);
                return (
                    k as f64 - r as f64 + offset,
                    (1.0 / curvature).clamp(lowest, highest),
                );
            }
        }
        (mean, var.max(ep.min_softmin_variance_px2))
    }

    /// The stack buffers give the very bits the vectors gave: random lines of every allowed
    /// half-length, samples a pixel apart (as built), gaps of 2–3 px (a caller's line: the span
    /// outgrows the stack's Heaviside buffer) and 200-sample lines (the heap path).
    #[test]
    fn stack_buffers_give_the_bits_the_vectors_gave() {
        let mut rng = crate::rng::Rng::new(17);
        let mut checked = 0;
        for case in 0..600 {
            let half_length = [2, 5, 10, 33, 64][case % 5];
            let ep = EnergyParams {
                half_length,
                ..EnergyParams::default()
            };
            let (count, step) = match case % 3 {
                0 => (2 * half_length + 1, 1.0),
                1 => (2 * half_length + 1, 2.0 + (case % 2) as f64),
                _ => (200, 1.0),
            };
            let angle = rng.uniform() * std::f64::consts::TAU;
            let normal = DVec2::new(angle.cos(), angle.sin());
            let centre = DVec2::new(100.0, 80.0);
            let samples: Vec<Sample> = (0..count)
                .map(|i| {
                    let p_f = (rng.uniform() as f32).clamp(1e-3, 1.0 - 1e-3);
                    Sample {
                        pos: centre + normal * ((i as f64 - (count / 2) as f64) * step),
                        pixel: 0,
                        g_f: -p_f.ln(),
                        g_b: -(1.0 - p_f).ln(),
                        p_f,
                    }
                })
                .collect();
            let line = Line::for_tests(normal, samples);
            let c = centre + normal * (rng.uniform() * 6.0 - 3.0);
            let (a, b) = (
                line_target(&line, c, &ep),
                target_with_vectors(&line, c, &ep),
            );
            assert_eq!(
                (a.0.to_bits(), a.1.to_bits()),
                (b.0.to_bits(), b.1.to_bits()),
                "case {case}: {a:?} against {b:?}"
            );
            checked += 1;
        }
        assert_eq!(checked, 600);
    }

    /// A horizontal line through c = (20, 5) with outward normal +x, one sample per pixel from
    /// −10 to +10 px, and the forest's p_f at offset k given by `p`.
    fn line(p: impl Fn(i64) -> f32) -> (Line, DVec2) {
        let c = DVec2::new(20.0, 5.0);
        let samples = (-10..=10)
            .map(|k| {
                let p_f = p(k);
                Sample {
                    pos: c + DVec2::X * k as f64,
                    pixel: 0,
                    g_f: -p_f.ln(),
                    g_b: -(1.0 - p_f).ln(),
                    p_f,
                }
            })
            .collect();
        (Line::for_tests(DVec2::X, samples), c)
    }

    #[test]
    fn a_clean_edge_gives_its_shift_with_a_tight_variance() {
        // The organ reaches two pixels beyond the contour.
        let (l, c) = line(|k| if k <= 2 { 0.98 } else { 0.02 });
        let (target, var) = line_target(&l, c, &EnergyParams::default());
        assert!((target - 2.5).abs() < 0.6, "target {target}");
        assert!(
            var < EnergyParams::default().saturated_line_variance_px2 / 4.0,
            "variance {var}"
        );
    }

    #[test]
    fn a_line_all_background_pulls_only_loosely() {
        // A tool lying over the rim: nothing of the organ anywhere on the line. The best shift
        // is the end of the range, and it says only "at least that far".
        let (l, c) = line(|_| 0.02);
        let (target, var) = line_target(&l, c, &EnergyParams::default());
        assert_eq!(target, -5.0);
        assert_eq!(var, EnergyParams::default().saturated_line_variance_px2);
        // All organ: the other end, just as loose.
        let (l, c) = line(|_| 0.98);
        let (target, var) = line_target(&l, c, &EnergyParams::default());
        assert_eq!(target, 5.0);
        assert_eq!(var, EnergyParams::default().saturated_line_variance_px2);
    }

    /// The placement's choice between a mirror image whose kidney outline fits a little better
    /// and the right pose, whose small tumour fits too: over all lines the mirror wins, per
    /// structure the right pose does; a structure turned out of sight counts 0.
    #[test]
    fn per_structure_confidence_lets_the_small_tumour_tell_the_mirror_image() {
        let lines = |kidney: f64, tumour: Option<f64>| -> Vec<(usize, f64, f64)> {
            let mut v = vec![(0, kidney, 1.0); 60];
            if let Some(t) = tumour {
                v.extend(std::iter::repeat_n((1, t, 1.0), 6));
            }
            v
        };
        let mirror = lines(0.9, Some(-0.1));
        let right = lines(0.8, Some(0.7));
        assert!(confidence(&mirror) > confidence(&right));
        let structures = [0, 1];
        assert!(
            structure_confidence(&right, &structures) > structure_confidence(&mirror, &structures)
        );
        let hidden = lines(0.9, None);
        assert!((structure_confidence(&hidden, &structures) - 0.45).abs() < 1e-12);
        assert!(
            structure_confidence(&right, &structures) > structure_confidence(&hidden, &structures)
        );
        assert_eq!(structure_confidence(&[], &structures), 0.0);
        // A thinned rim: 12 kidney lines weighing 5 each count as the 60 they stand for.
        let thinned = |kidney: f64, tumour: f64| -> Vec<(usize, f64, f64)> {
            let mut v = vec![(0, kidney, 5.0); 12];
            v.extend(std::iter::repeat_n((1, tumour, 1.0), 6));
            v
        };
        for (k, t) in [(0.9, -0.1), (0.8, 0.7)] {
            let (whole, thin) = (lines(k, Some(t)), thinned(k, t));
            assert!((confidence(&whole) - confidence(&thin)).abs() < 1e-12);
            assert!(
                (structure_confidence(&whole, &structures)
                    - structure_confidence(&thin, &structures))
                .abs()
                    < 1e-12
            );
        }
    }
}
