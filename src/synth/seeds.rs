//! Seed strokes as a user paints them: a few brush scribbles inside each class (background and
//! tools, then each visible structure), kept a brush radius plus a margin away from the class
//! boundary, as someone careful would on the first frames.

use crate::plane::{LabelImage, Mask, Plane};
use crate::render::squared_edt;
use crate::rng::Rng;
use crate::scene::{SEED_BACKGROUND, SEED_NONE};

/// Gap (px) a brush keeps from a class boundary in ordinary strokes.
pub const CLEARANCE_PX: f64 = 2.0;
/// Gap (px) in strokes that trace an edge: a careful user paints right up to it, which teaches
/// the forest what pixels next to an edge look like (without them it erodes every region).
pub const EDGE_CLEARANCE_PX: f64 = 0.5;

/// Paints `strokes` scribbles of a round brush of `radius` px inside `region` with `value`.
pub fn paint_strokes(
    seeds: &mut LabelImage,
    region: &Mask,
    value: u8,
    strokes: usize,
    radius: f64,
    clearance_px: f64,
    rng: &mut Rng,
) {
    let (w, h) = (region.width, region.height);
    // Distance from each pixel to the nearest pixel outside the region.
    let inside = squared_edt(&region.map(|&r| !r));
    let margin = radius + clearance_px;
    let ok = |x: f64, y: f64| {
        if x < 0.0 || y < 0.0 || x >= w as f64 || y >= h as f64 {
            return false;
        }
        (*inside.get(x as usize, y as usize) as f64).sqrt() >= margin
    };
    let candidates: Vec<usize> = (0..w * h)
        .filter(|&i| (inside.data[i] as f64).sqrt() >= margin + 1.0)
        .collect();
    if candidates.is_empty() {
        return;
    }
    let length = (w.max(h) as f64 / 6.0).max(8.0);
    for _ in 0..strokes {
        let start = candidates[rng.below(candidates.len())];
        let (mut x, mut y) = ((start % w) as f64, (start / w) as f64);
        let mut heading = rng.range(0.0, std::f64::consts::TAU);
        let mut travelled = 0.0;
        while travelled < length {
            stamp(seeds, Some(region), x, y, radius, value);
            heading += rng.range(-0.35, 0.35);
            let (nx, ny) = (x + 1.5 * heading.cos(), y + 1.5 * heading.sin());
            if !ok(nx, ny) {
                // Turn back inside rather than crossing the boundary.
                heading += std::f64::consts::PI * rng.range(0.6, 1.0);
                if !ok(x + 1.5 * heading.cos(), y + 1.5 * heading.sin()) {
                    break;
                }
                continue;
            }
            x = nx;
            y = ny;
            travelled += 1.5;
        }
    }
}

/// A filled disc of `value`, clipped to `region` when given: a stroke never labels the wrong
/// class, even where it passes within a pixel of an edge.
pub fn stamp(
    seeds: &mut LabelImage,
    region: Option<&Mask>,
    cx: f64,
    cy: f64,
    radius: f64,
    value: u8,
) {
    let r = radius.ceil() as i64;
    for dy in -r..=r {
        for dx in -r..=r {
            let (x, y) = (cx.round() as i64 + dx, cy.round() as i64 + dy);
            let inside =
                x >= 0 && y >= 0 && (x as usize) < seeds.width && (y as usize) < seeds.height;
            if inside
                && ((dx * dx + dy * dy) as f64) <= radius * radius
                && region.is_none_or(|m| *m.get(x as usize, y as usize))
            {
                seeds.set(x as usize, y as usize, value);
            }
        }
    }
}

/// The pixels of `region` within `distance_px` of any pixel of `other`.
fn near(region: &Mask, other: &Mask, distance_px: f64) -> Mask {
    let d2 = squared_edt(other);
    Plane {
        width: region.width,
        height: region.height,
        data: region
            .data
            .iter()
            .zip(&d2.data)
            .map(|(&r, &d)| r && (d as f64) <= distance_px * distance_px)
            .collect(),
    }
}

/// Seeds for one view of one frame, from its ground-truth labels and tool mask.
pub fn seeds_for_view(
    labels: &LabelImage,
    tools: &Mask,
    structure_labels: &[u8],
    rng: &mut Rng,
) -> LabelImage {
    let mut seeds = Plane::filled(labels.width, labels.height, SEED_NONE);
    let radius = (labels.width.max(labels.height) as f64 / 240.0).max(2.0);
    let background = labels.map(|&l| l == 0);
    let tissue_background = Plane {
        width: labels.width,
        height: labels.height,
        data: background
            .data
            .iter()
            .zip(&tools.data)
            .map(|(&b, &t)| b && !t)
            .collect(),
    };
    paint_strokes(
        &mut seeds,
        &tissue_background,
        SEED_BACKGROUND,
        4,
        radius,
        CLEARANCE_PX,
        rng,
    );
    // Users also paint right around the organ, where mistakes would cost most: background
    // strokes in a ring outside the anatomy.
    let ring_px = 45.0 * labels.width.max(labels.height) as f64 / 960.0;
    let ring = near(&tissue_background, &labels.map(|&l| l != 0), ring_px);
    paint_strokes(
        &mut seeds,
        &ring,
        SEED_BACKGROUND,
        3,
        radius,
        EDGE_CLEARANCE_PX,
        rng,
    );
    paint_strokes(
        &mut seeds,
        tools,
        SEED_BACKGROUND,
        1,
        radius,
        CLEARANCE_PX,
        rng,
    );
    for &l in structure_labels {
        let strokes = if l == structure_labels[0] { 3 } else { 2 };
        let region = labels.mask_of(l);
        paint_strokes(&mut seeds, &region, l, strokes, radius, CLEARANCE_PX, rng);
        // And one stroke along the inside of its edge, as a careful user traces it.
        let rim = near(&region, &region.map(|&r| !r), ring_px);
        paint_strokes(&mut seeds, &rim, l, 1, radius, EDGE_CLEARANCE_PX, rng);
    }
    seeds
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strokes_stay_inside_their_class() {
        let (w, h) = (120, 80);
        let labels = Plane::from_vec(
            w,
            h,
            (0..w * h)
                .map(|i| {
                    if ((i % w) as f64 - 60.0).hypot((i / w) as f64 - 40.0) < 25.0 {
                        1
                    } else {
                        0
                    }
                })
                .collect(),
        )
        .unwrap();
        let tools = Plane::filled(w, h, false);
        let mut rng = Rng::new(3);
        let seeds = seeds_for_view(&labels, &tools, &[1], &mut rng);
        let mut painted = [0usize; 256];
        for (s, l) in seeds.data.iter().zip(&labels.data) {
            painted[*s as usize] += 1;
            if *s == 1 {
                assert_eq!(*l, 1);
            }
            if *s == SEED_BACKGROUND {
                assert_eq!(*l, 0);
            }
        }
        assert!(painted[1] > 50, "kidney strokes {}", painted[1]);
        assert!(painted[255] > 50, "background strokes {}", painted[255]);
    }
}
