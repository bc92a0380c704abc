//! CPU compositing of labels over a frame: translucent fills with crisp contours for visible
//! structures, a dashed outline with a faint fill for hidden ones, a halo for where a hidden
//! one could be (its 95 % region), and seed strokes. Used for
//! the README's ground-truth picture and for exported overlay PNGs; the app draws its live
//! overlay on the GPU with the same colours.

use crate::fit::tracker::TrackedFrame;
use crate::plane::{LabelImage, Mask};
use crate::scene::Scene;
use crate::scene::{SEED_BACKGROUND, SEED_NONE};
use image::{Rgb, RgbImage};

/// Colour of structure number `index` (scene order), and of background seeds.
pub fn structure_colour(index: usize) -> [u8; 3] {
    const PALETTE: [[u8; 3]; 6] = [
        [60, 220, 90],
        [255, 210, 30],
        [235, 60, 235],
        [40, 200, 255],
        [255, 120, 40],
        [180, 140, 255],
    ];
    PALETTE[index % PALETTE.len()]
}

pub const BACKGROUND_SEED_COLOUR: [u8; 3] = [40, 110, 255];

fn blend(dst: &mut Rgb<u8>, c: [u8; 3], alpha: f32) {
    for (d, s) in dst.0.iter_mut().zip(c) {
        *d = (*d as f32 * (1.0 - alpha) + s as f32 * alpha).round() as u8;
    }
}

fn is_edge(w: usize, h: usize, x: usize, y: usize, inside: impl Fn(usize, usize) -> bool) -> bool {
    let me = inside(x, y);
    (x > 0 && inside(x - 1, y) != me)
        || (y > 0 && inside(x, y - 1) != me)
        || (x + 1 < w && inside(x + 1, y) != me)
        || (y + 1 < h && inside(x, y + 1) != me)
}

/// Fills and outlines each label of `labels` (`labels_to_index` maps a label to its colour
/// index) with opacity `alpha`.
pub fn draw_labels(
    img: &mut RgbImage,
    labels: &LabelImage,
    labels_to_index: &dyn Fn(u8) -> Option<usize>,
    alpha: f32,
) {
    let (w, h) = (labels.width, labels.height);
    for y in 0..h {
        for x in 0..w {
            let l = *labels.get(x, y);
            let Some(i) = (l != 0).then(|| labels_to_index(l)).flatten() else {
                continue;
            };
            let edge = is_edge(w, h, x, y, |a, b| *labels.get(a, b) == l);
            blend(
                img.get_pixel_mut(x as u32, y as u32),
                structure_colour(i),
                if edge { 1.0 } else { alpha },
            );
        }
    }
}

/// A hidden structure: dashed outline and a faint fill, drawn through whatever covers it.
pub fn draw_hidden(img: &mut RgbImage, mask: &Mask, colour_index: usize) {
    let (w, h) = (mask.width, mask.height);
    for y in 0..h {
        for x in 0..w {
            if !*mask.get(x, y) {
                continue;
            }
            let edge = is_edge(w, h, x, y, |a, b| *mask.get(a, b));
            let dash = ((x + y) / 5) % 2 == 0;
            let c = structure_colour(colour_index);
            blend(
                img.get_pixel_mut(x as u32, y as u32),
                c,
                if edge && dash {
                    1.0
                } else if edge {
                    0.3
                } else {
                    0.18
                },
            );
        }
    }
}

/// The opacity of each pixel of a hidden structure's 95 % region around its fitted
/// projection (`hidden`; `region` the union of its projections over the region, a superset):
/// a soft halo at `opacity` beside the fitted outline fading to a third of that at the
/// region's edge, and a dashed contour (opaque dashes) on that edge. 0 inside the fitted
/// projection (drawn by the structure itself) and outside the region.
pub fn region_alpha(hidden: &Mask, region: &Mask, opacity: f32) -> Vec<f32> {
    let (w, h) = (region.width, region.height);
    if hidden.width != w || hidden.height != h {
        return vec![0.0; region.data.len()];
    }
    let d2 = crate::render::squared_edt(hidden);
    let reach = region
        .data
        .iter()
        .zip(&d2.data)
        .filter(|(r, _)| **r)
        .map(|(_, &d)| d)
        .fold(0f32, f32::max)
        .sqrt()
        .max(1.0);
    let mut alpha = vec![0f32; region.data.len()];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if !region.data[i] || hidden.data[i] {
                continue;
            }
            let edge = is_edge(w, h, x, y, |a, b| *region.get(a, b));
            alpha[i] = if edge {
                if ((x + y) / 4) % 2 == 0 { 1.0 } else { 0.35 }
            } else {
                let d = d2.data[i].sqrt() / reach;
                opacity * (1.0 - 0.67 * d.clamp(0.0, 1.0))
            };
        }
    }
    alpha
}

/// A hidden structure's 95 % region ([`region_alpha`]) over `img` in colour `colour_index`.
pub fn draw_region(
    img: &mut RgbImage,
    hidden: &Mask,
    region: &Mask,
    colour_index: usize,
    opacity: f32,
) {
    let c = structure_colour(colour_index);
    for (i, a) in region_alpha(hidden, region, opacity)
        .into_iter()
        .enumerate()
    {
        let (x, y) = ((i % region.width) as u32, (i / region.width) as u32);
        if a > 0.0 && x < img.width() && y < img.height() {
            blend(img.get_pixel_mut(x, y), c, a);
        }
    }
}

/// Seed strokes, opaque.
pub fn draw_seeds(
    img: &mut RgbImage,
    seeds: &LabelImage,
    labels_to_index: &dyn Fn(u8) -> Option<usize>,
) {
    for (i, &v) in seeds.data.iter().enumerate() {
        let c = match v {
            SEED_NONE => continue,
            SEED_BACKGROUND => BACKGROUND_SEED_COLOUR,
            l => match labels_to_index(l) {
                Some(k) => structure_colour(k),
                None => continue,
            },
        };
        let (x, y) = ((i % seeds.width) as u32, (i / seeds.width) as u32);
        if x < img.width() && y < img.height() {
            blend(img.get_pixel_mut(x, y), c, 0.9);
        }
    }
}

/// Tiles same-sized images into a grid of `columns`.
pub fn tile(images: &[RgbImage], columns: usize) -> RgbImage {
    let Some(first) = images.first() else {
        return RgbImage::new(1, 1);
    };
    let (w, h) = (first.width(), first.height());
    let rows = images.len().div_ceil(columns.max(1)) as u32;
    let mut out = RgbImage::new(w * columns as u32, h * rows);
    for (i, img) in images.iter().enumerate() {
        let (cx, cy) = ((i % columns) as u32 * w, (i / columns) as u32 * h);
        image::imageops::overlay(&mut out, img, cx as i64, cy as i64);
    }
    out
}

/// A tracked frame over camera `c`'s image: visible structures filled and outlined, hidden
/// ones dashed, each in its scene colour (what the app's export writes).
/// Each hidden structure's 95 % region is drawn around its outline.
pub fn draw_tracked(img: &mut RgbImage, scene: &Scene, f: &TrackedFrame, c: usize) {
    draw_fit(img, scene, &f.labels, &f.hidden, c, 0.3);
    for (name, regions) in &f.region_masks {
        let i = scene.structures.iter().position(|s| &s.name == name);
        let hidden = f.hidden.iter().find(|(n, _)| n == name).map(|(_, m)| m);
        if let (Some(i), Some(region), Some(hidden)) =
            (i, regions.get(c), hidden.and_then(|m| m.get(c)))
        {
            draw_region(img, hidden, region, i, 0.25);
        }
    }
}

/// Fitted labels (fill opacity `alpha`) and hidden structures' masks of camera `c` over
/// `img`, in the scene's colours.
pub fn draw_fit(
    img: &mut RgbImage,
    scene: &Scene,
    labels: &[LabelImage],
    hidden: &[(String, Vec<Mask>)],
    c: usize,
    alpha: f32,
) {
    let index = |l: u8| scene.structures.iter().position(|s| s.label == l);
    if let Some(labels) = labels.get(c) {
        draw_labels(img, labels, &index, alpha);
    }
    for (name, masks) in hidden {
        let i = scene.structures.iter().position(|s| &s.name == name);
        if let (Some(i), Some(mask)) = (i, masks.get(c)) {
            draw_hidden(img, mask, i);
        }
    }
}
