//! Where the next stroke helps most, as ilastik users expect of the uncertainty view: the
//! unpainted patch where the forest hesitates most between its two likeliest classes. Patches
//! are square cells of the image; a cell with any painted pixel is skipped (strokes there
//! already told the forest what it is), and a patch the forest is fairly sure of is no hint.

use crate::plane::{LabelImage, Plane};
use crate::scene::SEED_NONE;

/// A suggested place for the next stroke (image pixels).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StrokeHint {
    pub x: f32,
    pub y: f32,
    /// Half the cell's side.
    pub radius: f32,
    /// Mean uncertainty 1 − (p₁ − p₂) over the cell.
    pub uncertainty: f32,
}

/// Below this mean uncertainty no cell is worth a stroke.
pub const HINT_MIN_UNCERTAINTY: f32 = 0.35;

/// The side of a cell (px) of a `width`-wide image: a thirtieth of it, at least 16 px.
pub fn cell_px(width: usize) -> usize {
    (width / 30).max(16)
}

/// The unpainted cell ([`cell_px`]) of highest mean uncertainty, if it reaches
/// [`HINT_MIN_UNCERTAINTY`]. `seeds` (same size, when given) marks painted pixels.
pub fn next_stroke(uncertainty: &Plane<f32>, seeds: Option<&LabelImage>) -> Option<StrokeHint> {
    let (w, h) = (uncertainty.width, uncertainty.height);
    let cell = cell_px(w);
    let painted = |x: usize, y: usize| {
        seeds.is_some_and(|s| s.width == w && s.height == h && *s.get(x, y) != SEED_NONE)
    };
    let mut best: Option<StrokeHint> = None;
    for cy in (0..h).step_by(cell) {
        for cx in (0..w).step_by(cell) {
            let (x1, y1) = ((cx + cell).min(w), (cy + cell).min(h));
            // Partial cells at the border count only when at least half there.
            if (x1 - cx) * 2 < cell || (y1 - cy) * 2 < cell {
                continue;
            }
            let (mut sum, mut n, mut any_paint) = (0f32, 0usize, false);
            for y in cy..y1 {
                for x in cx..x1 {
                    any_paint |= painted(x, y);
                    let u = *uncertainty.get(x, y);
                    if u.is_finite() {
                        sum += u;
                        n += 1;
                    }
                }
            }
            if any_paint || n == 0 {
                continue;
            }
            let mean = sum / n as f32;
            if mean >= HINT_MIN_UNCERTAINTY && best.is_none_or(|b| mean > b.uncertainty) {
                best = Some(StrokeHint {
                    x: (cx + x1) as f32 / 2.0,
                    y: (cy + y1) as f32 / 2.0,
                    radius: cell as f32 / 2.0,
                    uncertainty: mean,
                });
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_hint_is_the_most_uncertain_unpainted_cell() {
        let mut u = Plane::filled(64, 48, 0.1f32);
        // Two uncertain patches; the stronger one is painted already.
        for y in 16..32 {
            for x in 0..16 {
                u.set(x, y, 0.6);
            }
            for x in 32..48 {
                u.set(x, y, 0.9);
            }
        }
        let mut seeds = Plane::filled(64, 48, SEED_NONE);
        seeds.set(40, 20, 2);
        let hint = next_stroke(&u, Some(&seeds)).expect("a hint");
        assert_eq!((hint.x, hint.y, hint.radius), (8.0, 24.0, 8.0));
        assert!((hint.uncertainty - 0.6).abs() < 1e-6);
        // Unpainted, the stronger patch wins; a sure forest gives no hint.
        assert_eq!(next_stroke(&u, None).unwrap().x, 40.0);
        assert!(next_stroke(&Plane::filled(64, 48, 0.2), None).is_none());
    }
}
