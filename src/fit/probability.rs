//! Forest probabilities of one frame of one view, per pyramid level, computed lazily: only the
//! pixels the correspondence lines touch are ever classified, which is what makes per-frame
//! fitting affordable (a whole 960×540 view costs ~100 ms; the lines need a few thousand pixels).

use crate::appearance::features::downsample;
use crate::appearance::{Appearance, FrameFeatures};
use image::RgbImage;
use std::sync::Arc;

struct Level {
    /// Made on first use: tracked frames never need the coarse levels.
    image: Option<Arc<RgbImage>>,
    features: Option<FrameFeatures>,
    /// (x, y, w, h) the features cover.
    region: Option<(usize, usize, usize, usize)>,
    /// `classes` probabilities per pixel; NaN where not yet computed (empty until first use).
    probs: Vec<f32>,
}

/// Lazily classified pyramid of one view's frame.
pub struct ViewProbabilities {
    levels: Vec<Level>,
    sizes: Vec<(usize, usize)>,
    classes: usize,
}

/// Recycled probability planes: one per fitted level, view and frame.
static PROBABILITIES: crate::pool::Pool<f32> = crate::pool::Pool::new();

impl Drop for ViewProbabilities {
    fn drop(&mut self) {
        PROBABILITIES.give(self.levels.iter_mut().map(|l| std::mem::take(&mut l.probs)));
    }
}

impl ViewProbabilities {
    pub fn new(frame: Arc<RgbImage>, levels: usize, classes: usize) -> Self {
        let (w, h) = (frame.width() as usize, frame.height() as usize);
        let sizes: Vec<(usize, usize)> = (0..levels.max(1))
            .map(|l| ((w >> l).max(1), (h >> l).max(1)))
            .collect();
        let mut out: Vec<Level> = (0..sizes.len())
            .map(|_| Level {
                image: None,
                features: None,
                region: None,
                probs: Vec::new(),
            })
            .collect();
        out[0].image = Some(frame);
        Self {
            levels: out,
            sizes,
            classes,
        }
    }

    /// The image of a level, downsampling from the finer one on first use.
    fn image(&mut self, level: usize) -> Arc<RgbImage> {
        if let Some(img) = &self.levels[level].image {
            return img.clone();
        }
        let finer = self.image(level - 1);
        let img = Arc::new(downsample(&finer));
        self.levels[level].image = Some(img.clone());
        img
    }

    /// Probabilities made from a label image instead of the forest: `confidence` for the
    /// pixel's class, the rest shared by the others; coarser levels average 2×2 blocks. This is
    /// how the fit is tested apart from the appearance model.
    pub fn from_labels(
        labels: &crate::plane::LabelImage,
        class_labels: &[u8],
        levels: usize,
        confidence: f32,
    ) -> Self {
        let k = class_labels.len();
        let other = (1.0 - confidence) / (k.max(2) - 1) as f32;
        let probs: Vec<f32> = labels
            .data
            .iter()
            .flat_map(|&l| {
                let c = class_labels.iter().position(|&x| x == l).unwrap_or(0);
                (0..k).map(move |j| if j == c { confidence } else { other })
            })
            .collect();
        Self::from_planes(probs, labels.width, labels.height, k, levels)
    }

    /// Probabilities given whole for every pixel of level 0 (`classes` values per pixel,
    /// row-major), e.g. from an image model instead of the forest; coarser levels average
    /// 2×2 blocks. Nothing is ever classified: [`ViewProbabilities::ensure`] finds every pixel
    /// known.
    pub fn from_planes(
        mut probs: Vec<f32>,
        width: usize,
        height: usize,
        classes: usize,
        levels: usize,
    ) -> Self {
        let k = classes;
        let (mut w, mut h) = (width, height);
        let mut out = Vec::new();
        let mut sizes = Vec::new();
        for l in 0..levels.max(1) {
            if l > 0 {
                let (nw, nh) = ((w / 2).max(1), (h / 2).max(1));
                let mut next = vec![0f32; nw * nh * k];
                for y in 0..nh {
                    for x in 0..nw {
                        for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                            let (sx, sy) = ((2 * x + dx).min(w - 1), (2 * y + dy).min(h - 1));
                            for j in 0..k {
                                next[(y * nw + x) * k + j] += 0.25 * probs[(sy * w + sx) * k + j];
                            }
                        }
                    }
                }
                probs = next;
                w = nw;
                h = nh;
            }
            sizes.push((w, h));
            out.push(Level {
                image: None,
                features: None,
                region: None,
                probs: probs.clone(),
            });
        }
        Self {
            levels: out,
            sizes,
            classes: k,
        }
    }

    /// The same probabilities with the frame they belong to, so that what reads the image
    /// (the stereo term, highlight checks) still can: the experiments that give the fit true
    /// probabilities keep the rest of the frame's evidence.
    pub fn with_frame(mut self, frame: Arc<RgbImage>) -> Self {
        if let Some(first) = self.levels.first_mut() {
            first.image = Some(frame);
        }
        self
    }

    /// The frame at a pyramid level, when the probabilities come from one (not from labels).
    pub fn level_image(&mut self, level: usize) -> Option<Arc<RgbImage>> {
        self.levels.first()?.image.as_ref()?;
        (level < self.levels.len()).then(|| self.image(level))
    }

    pub fn level_count(&self) -> usize {
        self.levels.len()
    }

    pub fn size(&self, level: usize) -> (usize, usize) {
        self.sizes[level]
    }

    /// Classifies the listed pixel indices of `level` that are not known yet.
    /// Without a forest (`None`: the probabilities were given whole) a pixel left unknown is
    /// a caller's error: it counts as undecided (equal probabilities), and debug builds stop.
    pub fn ensure(&mut self, appearance: Option<&Appearance>, level: usize, pixels: &[u32]) {
        let k = self.classes;
        let (w, h) = self.sizes[level];
        if self.levels[level].probs.is_empty() {
            let mut probs = PROBABILITIES.take(w * h * k, f32::NAN);
            probs.fill(f32::NAN);
            self.levels[level].probs = probs;
        }
        let lv = &self.levels[level];
        let w = w as u32;
        let mut missing: Vec<u32> = pixels
            .iter()
            .copied()
            .filter(|&i| lv.probs[i as usize * k].is_nan())
            .collect();
        if missing.is_empty() {
            return;
        }
        missing.sort_unstable();
        missing.dedup();
        let Some(appearance) = appearance else {
            debug_assert!(
                false,
                "probabilities given whole, yet {} pixels unknown",
                missing.len()
            );
            let lv = &mut self.levels[level];
            for &i in &missing {
                lv.probs[i as usize * k..(i as usize + 1) * k].fill(1.0 / k as f32);
            }
            return;
        };
        let image = self.image(level);
        let lv = &mut self.levels[level];
        // Features over a region around the requested pixels only; grown (rarely: the model
        // moves little within a frame) when a request falls outside it.
        let covered = lv.features.as_ref().is_some_and(|f| {
            missing
                .iter()
                .all(|&i| f.valid((i % w) as usize, (i / w) as usize))
        });
        if !covered {
            let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
            for &i in &missing {
                let (x, y) = ((i % w) as usize, (i / w) as usize);
                x0 = x0.min(x);
                y0 = y0.min(y);
                x1 = x1.max(x);
                y1 = y1.max(y);
            }
            if let Some((ox, oy, ow, oh)) = lv.region {
                x0 = x0.min(ox);
                y0 = y0.min(oy);
                x1 = x1.max(ox + ow - 1);
                y1 = y1.max(oy + oh - 1);
            }
            // Margin: the widest window, plus slack so small motions need no rebuild.
            let margin = crate::appearance::features::reach_for_level(level) + 16;
            let (iw, ih) = (image.width() as usize, image.height() as usize);
            let (rx0, ry0) = (x0.saturating_sub(margin), y0.saturating_sub(margin));
            let (rx1, ry1) = ((x1 + margin).min(iw - 1), (y1 + margin).min(ih - 1));
            lv.region = Some((rx0, ry0, rx1 + 1 - rx0, ry1 + 1 - ry0));
            super::profile::count(
                super::profile::Count::FeaturePixels,
                (rx1 + 1 - rx0) * (ry1 + 1 - ry0),
            );
            lv.features = Some(super::profile::time(
                super::profile::Phase::Features,
                || FrameFeatures::region(&image, level, rx0, ry0, rx1 + 1 - rx0, ry1 + 1 - ry0),
            ));
        }
        let Some(features) = lv.features.as_ref() else {
            return;
        };
        let coords: Vec<(u32, u32)> = missing.iter().map(|&i| (i % w, i / w)).collect();
        super::profile::count(super::profile::Count::ClassifiedPixels, coords.len());
        let p = super::profile::time(super::profile::Phase::Forest, || {
            appearance.classify_pixels(features, &coords)
        });
        for (j, &i) in missing.iter().enumerate() {
            lv.probs[i as usize * k..(i as usize + 1) * k].copy_from_slice(&p[j * k..(j + 1) * k]);
        }
    }

    /// Is the pixel (an index of `level`) a specular highlight? Its probabilities then do not
    /// vote (the lines count it as undecided). False where the probabilities came from labels.
    #[inline]
    pub fn is_specular(&self, level: usize, pixel: u32) -> bool {
        self.levels[level].image.as_ref().is_some_and(|img| {
            let w = img.width();
            let (x, y) = (pixel % w, pixel / w);
            y < img.height() && crate::appearance::features::is_specular(img.get_pixel(x, y).0)
        })
    }

    /// Probability of `class` at a pixel index of `level` (must have been ensured).
    #[inline]
    pub fn get(&self, level: usize, pixel: u32, class: usize) -> f32 {
        self.levels[level].probs[pixel as usize * self.classes + class]
    }
}
