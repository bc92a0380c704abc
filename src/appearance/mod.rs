//! Appearance: the forest that turns painted strokes into per-pixel class probabilities (paper
//! §III, eq. 9). Class 0 is background/tools (seed 255, ground truth 0); class k ≥ 1 is the k-th
//! visible structure. p_f^n is the forest's probability of structure n, p_b^n = 1 − p_f^n.

pub mod dense;
pub mod features;
pub mod forest;
pub mod hint;
#[cfg(target_arch = "x86_64")]
mod lab_avx2;
#[cfg(target_arch = "x86_64")]
mod pixel_avx2;
pub mod smooth;
#[cfg(target_arch = "x86_64")]
mod tables_avx2;
pub mod validate;

pub use features::{FEATURE_COUNT, FrameFeatures};
pub use forest::{Forest, ForestParams, Samples, TrainStats};

use crate::error::{Error, InputError};
use crate::plane::{LabelImage, Plane};
use crate::scene::{SEED_BACKGROUND, SEED_NONE, Scene};
use image::RgbImage;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};

/// Most training pixels kept per class (deterministic thinning beyond): painting a whole frame
/// should not make training slow.
pub const MAX_SAMPLES_PER_CLASS: usize = 60_000;

/// Which forest class stands for what.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ClassMap {
    /// Label of each class (0 for background).
    pub labels: Vec<u8>,
    /// Name of each class ("background", then structure names).
    pub names: Vec<String>,
}

impl ClassMap {
    pub fn from_scene(scene: &Scene) -> Self {
        let mut labels = vec![0u8];
        let mut names = vec!["background".to_string()];
        for (_, s) in scene.visible_structures() {
            labels.push(s.label);
            names.push(s.name.clone());
        }
        Self { labels, names }
    }

    pub fn len(&self) -> usize {
        self.labels.len()
    }

    pub fn is_empty(&self) -> bool {
        self.labels.is_empty()
    }

    /// Class of a seed value (None for unpainted or unknown values).
    pub fn class_of_seed(&self, v: u8) -> Option<usize> {
        match v {
            SEED_NONE => None,
            SEED_BACKGROUND => Some(0),
            l => self
                .labels
                .iter()
                .skip(1)
                .position(|&x| x == l)
                .map(|i| i + 1),
        }
    }

    /// Class of a ground-truth label (0 = background).
    pub fn class_of_label(&self, l: u8) -> Option<usize> {
        self.labels.iter().position(|&x| x == l)
    }
}

/// A trained appearance model: the forest and what its classes mean.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Appearance {
    pub classes: ClassMap,
    pub forest: Forest,
    pub stats: TrainStats,
    /// The features the forest was trained on ([`features::FEATURE_SET`]; empty in sessions
    /// saved before it was recorded). A forest of another set must not be walked: its splits
    /// would read other features.
    #[serde(default)]
    pub feature_set: String,
    /// How well forests trained without one seeded frame label that frame's strokes: what
    /// the out-of-bag error cannot say (None: fewer than two seeded frames or views).
    #[serde(default)]
    pub validation: Option<validate::Validation>,
}

/// Per-pixel class probabilities of one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct ProbabilityMaps {
    pub width: usize,
    pub height: usize,
    pub classes: usize,
    /// `classes` values per pixel, row-major.
    pub data: Vec<f32>,
}

impl ProbabilityMaps {
    pub fn class_plane(&self, k: usize) -> Plane<f32> {
        Plane {
            width: self.width,
            height: self.height,
            data: self
                .data
                .iter()
                .skip(k)
                .step_by(self.classes)
                .copied()
                .collect(),
        }
    }

    /// Most probable class's label per pixel.
    pub fn argmax_labels(&self, map: &ClassMap) -> LabelImage {
        Plane {
            width: self.width,
            height: self.height,
            data: self
                .data
                .chunks_exact(self.classes)
                .map(|p| map.labels[forest::argmax(p)])
                .collect(),
        }
    }

    /// 1 − (p_top1 − p_top2), as ilastik shows uncertainty.
    pub fn uncertainty(&self) -> Plane<f32> {
        let data = self
            .data
            .chunks_exact(self.classes)
            .map(|p| {
                let (mut a, mut b) = (0f32, 0f32);
                for &v in p {
                    if v > a {
                        b = a;
                        a = v;
                    } else if v > b {
                        b = v;
                    }
                }
                1.0 - (a - b)
            })
            .collect();
        Plane {
            width: self.width,
            height: self.height,
            data,
        }
    }
}

impl Appearance {
    /// A forest of `trees` trees (default settings otherwise) on the scene's seeds: what the
    /// fit's tests stand on.
    #[cfg(test)]
    pub(crate) fn for_tests(scene: &Scene, trees: usize) -> Appearance {
        Appearance::train(
            scene,
            &ForestParams {
                trees,
                ..ForestParams::default()
            },
            None,
        )
        .expect("the phantom's seeds train a forest")
    }

    /// Trains the forest on every seeded pixel of every seeded frame in every view, with its
    /// held-out figure.
    pub fn train(
        scene: &Scene,
        params: &ForestParams,
        cancel: Option<&AtomicBool>,
    ) -> Result<Appearance, Error> {
        let started = std::time::Instant::now();
        let set = TrainingSet::collect(scene, cancel, None)?;
        let mut appearance = Appearance::fit(&set, params)?;
        appearance.validation = set.validate(params);
        // Report what the user waits for: reading seeded frames, features, the forest and its
        // check.
        appearance.stats.train_s = started.elapsed().as_secs_f64();
        Ok(appearance)
    }

    /// The forest alone, without the held-out figure (the app's live loop shows the maps
    /// first and checks the forest after). `stats.train_s` counts reading the seeds too.
    pub fn fit(set: &TrainingSet, params: &ForestParams) -> Result<Appearance, Error> {
        let started = std::time::Instant::now();
        let (forest, mut stats) = Forest::train(&set.samples, set.classes.len(), params)
            .map_err(|e| InputError::new(&set.origin, e.to_string()))?;
        stats.train_s = set.collect_s + started.elapsed().as_secs_f64();
        Ok(Appearance {
            classes: set.classes.clone(),
            forest,
            stats,
            feature_set: features::FEATURE_SET.to_string(),
            validation: None,
        })
    }

    /// A forest whose trees drew fewer samples than there were: the app's live preview
    /// ([`LIVE_PREVIEW_SAMPLES_PER_TREE`]), retrained whole before it tracks or places.
    pub fn is_live_preview(&self) -> bool {
        let cap = self.forest.params.max_samples_per_tree;
        cap != 0 && self.stats.samples > cap
    }

    /// Every pixel's probabilities, smoothed over its neighbourhood
    /// ([`PROBABILITY_SMOOTHING_SIGMA_PX`]): what `classify` and the app's maps show.
    pub fn classify_frame(&self, frame: &RgbImage) -> ProbabilityMaps {
        self.classify_frame_per_pixel(frame)
            .smoothed(PROBABILITY_SMOOTHING_SIGMA_PX)
    }

    /// Every pixel's probabilities as the forest gives them, each pixel on its own.
    pub fn classify_frame_per_pixel(&self, frame: &RgbImage) -> ProbabilityMaps {
        ProbabilityMaps {
            width: frame.width() as usize,
            height: frame.height() as usize,
            classes: self.classes.len(),
            data: self.forest.predict_many(&dense::frame(frame, 0)),
        }
    }

    /// A quick first map of a frame, at full size: classified at pyramid level 1 (a quarter of
    /// the pixels, features of the same physical windows) and drawn 2×2 per pixel. The app
    /// shows it while the full map is made (960×540: ~35 ms against ~135 ms a view).
    pub fn classify_coarse(&self, frame: &RgbImage) -> ProbabilityMaps {
        let (w, h) = (frame.width() as usize, frame.height() as usize);
        let half = features::downsample(frame);
        let (hw, hh) = (half.width() as usize, half.height() as usize);
        let k = self.classes.len();
        // Smoothed at its own level: half the pixels across, half the σ.
        let coarse = ProbabilityMaps {
            width: hw,
            height: hh,
            classes: k,
            data: self.forest.predict_many(&dense::frame(&half, 1)),
        }
        .smoothed(PROBABILITY_SMOOTHING_SIGMA_PX / 2.0)
        .data;
        let mut data = vec![0f32; w * h * k];
        data.par_chunks_mut((w * k).max(1))
            .enumerate()
            .for_each(|(y, row)| {
                let sy = (y / 2).min(hh.saturating_sub(1));
                for (x, out) in row.chunks_exact_mut(k).enumerate() {
                    let i = sy * hw + (x / 2).min(hw.saturating_sub(1));
                    out.copy_from_slice(&coarse[i * k..(i + 1) * k]);
                }
            });
        ProbabilityMaps {
            width: w,
            height: h,
            classes: k,
            data,
        }
    }

    /// Probabilities of listed pixels of a prepared frame (`classes` values each).
    pub fn classify_pixels(&self, ff: &FrameFeatures, pixels: &[(u32, u32)]) -> Vec<f32> {
        let features =
            crate::fit::profile::time(crate::fit::profile::Phase::SparseFeatures, || {
                ff.pixels_auto(pixels)
            });
        self.forest.predict_many(&features)
    }
}

fn seeds_origin(scene: &Scene) -> String {
    match (&scene.root, &scene.seeds_template) {
        (Some(root), Some(t)) => root.join(t.source()).display().to_string(),
        _ => scene.origin.clone(),
    }
}

/// σ (px of the frame) of the Gaussian that smooths full maps before a label is read off
/// them: the forest's isolated mistakes (a glint on fat, a pale spot on the kidney) are
/// outvoted by their neighbourhood. Chosen on the tuning phantoms and real frames of
/// `benches/appearance_heldout.rs` (σ 0 / 1.5 / 2 / 3 / 4 / 6 px: tumour Dice 0.948 / 0.968 /
/// 0.973 / 0.974 / 0.972 / 0.964 on average, kidney level to 4 px, the smaller of the two
/// best kept); three 5-px boxes, σ 2.45 px in effect. The fit reads single pixels' own
/// probabilities ([`Appearance::classify_pixels`]), unsmoothed.
pub const PROBABILITY_SMOOTHING_SIGMA_PX: f32 = 2.5;

/// Cap on each tree's draws when the app retrains live after a stroke, as ilastik's live update
/// does: the maps must follow the strokes at once. At 960×540 with strokes on six images
/// (93,663 samples) the forest trains in 127 ms instead of 334 ms, and the coarse maps show
/// 271 ms after the stroke ends instead of 486 ms (`LIVE_FOREST_SAMPLES=25000 cargo bench
/// --bench live_update`). The appearance bench's tuning phantoms and real frames did not move
/// (kidney / tumour within ±0.005), but tracking the project's phantoms (synth 30–33, LSC, two
/// forest seeds) did, a little: Dice 0.9650 → 0.9634, hidden tumour 1.19 → 1.25 mm. So the
/// capped forest is a preview: `Train forest`, tracking and placing use the full one, which
/// the app trains first when it holds a preview ([`Appearance::is_live_preview`]).
pub const LIVE_PREVIEW_SAMPLES_PER_TREE: usize = 25_000;

/// Pyramid levels whose features train the forest: every level the fit may visit (down to
/// two below the tracking level of a 1920-wide video).
pub const TRAINING_LEVELS: usize = 5;

/// Halves a seed image: a pixel keeps a value only where its 2×2 children all have it.
fn downsample_seeds(seeds: &LabelImage) -> LabelImage {
    let (w, h) = ((seeds.width / 2).max(1), (seeds.height / 2).max(1));
    let mut out = Plane::filled(w, h, SEED_NONE);
    for y in 0..h {
        for x in 0..w {
            let v = *seeds.get((2 * x).min(seeds.width - 1), (2 * y).min(seeds.height - 1));
            let same = [(1, 0), (0, 1), (1, 1)].iter().all(|&(dx, dy)| {
                *seeds.get(
                    (2 * x + dx).min(seeds.width - 1),
                    (2 * y + dy).min(seeds.height - 1),
                ) == v
            });
            if same {
                out.set(x, y, v);
            }
        }
    }
    out
}

/// Feature vectors and classes of all seeded pixels. Errors name the seeds and the class.
pub fn collect_samples(
    scene: &Scene,
    classes: &ClassMap,
    cancel: Option<&AtomicBool>,
) -> Result<Samples, Error> {
    collect_grouped(scene, classes, cancel, None).map(|(s, _)| s)
}

/// The seeded pixels, ready to learn: what the forest trains on, and what the held-out figure
/// leaves out group by group. The app's worker keeps it so the figure can follow the forest.
pub struct TrainingSet {
    pub classes: ClassMap,
    pub samples: Samples,
    groups: Groups,
    /// Where the seeds came from, for errors.
    origin: String,
    /// Seconds spent reading the seeded frames and their features.
    pub collect_s: f64,
}

impl TrainingSet {
    /// Every seeded pixel of the scene; images whose strokes are unchanged since `cache` last
    /// saw them are not read again.
    pub fn collect(
        scene: &Scene,
        cancel: Option<&AtomicBool>,
        cache: Option<&SampleCache>,
    ) -> Result<TrainingSet, Error> {
        let started = std::time::Instant::now();
        let classes = ClassMap::from_scene(scene);
        let (samples, groups) = collect_grouped(scene, &classes, cancel, cache)?;
        Ok(TrainingSet {
            classes,
            samples,
            groups,
            origin: seeds_origin(scene),
            collect_s: started.elapsed().as_secs_f64(),
        })
    }

    /// The held-out figure of a forest trained with `params` on this set.
    pub fn validate(&self, params: &ForestParams) -> Option<validate::Validation> {
        validate::held_out(
            &self.samples,
            &self.groups.ids,
            self.groups.by,
            self.classes.len(),
            params,
        )
    }
}

/// Per seeded pixel: features, class, and whether it is a specular highlight.
type Sample = (features::FeatureVector, u8, bool);

/// Each seeded image's samples, by camera and frame, with a hash of its strokes: a retrain after
/// a stroke reads again only the image the stroke changed (3 seeded frames of 2 views at
/// 960×540: 105 ms → ~20 ms). One cache serves one scene's frames and structures.
#[derive(Default)]
pub struct SampleCache(Mutex<HashMap<ImageKey, CachedSamples>>);

/// A seeded image: camera and frame.
type ImageKey = (usize, usize);
/// The hash of an image's strokes, and its samples.
type CachedSamples = (u64, Arc<Vec<Sample>>);

impl SampleCache {
    fn get(&self, key: (usize, usize), hash: u64) -> Option<Arc<Vec<Sample>>> {
        let map = self.0.lock().unwrap_or_else(|p| p.into_inner());
        map.get(&key)
            .filter(|(h, _)| *h == hash)
            .map(|(_, s)| s.clone())
    }

    fn put(&self, key: (usize, usize), hash: u64, samples: Arc<Vec<Sample>>) {
        let mut map = self.0.lock().unwrap_or_else(|p| p.into_inner());
        map.insert(key, (hash, samples));
    }
}

fn strokes_hash(seeds: &LabelImage) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    (seeds.width, seeds.height).hash(&mut h);
    seeds.data.hash(&mut h);
    h.finish()
}

/// Each training sample's group, and what a group is ("frame" or "view").
struct Groups {
    ids: Vec<u32>,
    by: &'static str,
}

/// [`collect_samples`], with each sample's group: its seeded frame (all views of a frame are one
/// group: the other view of the same moment is no test), or its view when only one frame is
/// seeded.
fn collect_grouped(
    scene: &Scene,
    classes: &ClassMap,
    cancel: Option<&AtomicBool>,
    cache: Option<&SampleCache>,
) -> Result<(Samples, Groups), Error> {
    let origin = seeds_origin(scene);
    let jobs: Vec<(usize, usize)> = scene
        .seeds
        .by_camera
        .iter()
        .enumerate()
        .flat_map(|(c, m)| m.keys().map(move |&t| (c, t)))
        .collect();
    if jobs.is_empty() || scene.seeds.pixel_counts().is_empty() {
        return Err(InputError::new(
            &origin,
            "no seeds: paint background/tools and every visible structure on at least one frame",
        )
        .into());
    }
    let frames: std::collections::BTreeSet<usize> = jobs.iter().map(|&(_, t)| t).collect();
    let group_of =
        |c: usize, t: usize| -> u32 { if frames.len() > 1 { t as u32 } else { c as u32 } };
    let per_job: Vec<Result<Arc<Vec<Sample>>, Error>> = jobs
        .par_iter()
        .map(|&(c, t)| {
            crate::error::stop_if_cancelled(cancel)?;
            let seeds = &scene.seeds.by_camera[c][&t];
            let hash = strokes_hash(seeds);
            if let Some(hit) = cache.and_then(|k| k.get((c, t), hash)) {
                return Ok(hit);
            }
            let frame = scene.frame(c, t)?;
            if seeds.width != frame.width() as usize || seeds.height != frame.height() as usize {
                return Err(InputError::new(
                    &origin,
                    format!(
                        "seeds of frame {t} in camera '{}' are {}×{} but the frame is {}×{}",
                        scene.cameras[c].name,
                        seeds.width,
                        seeds.height,
                        frame.width(),
                        frame.height()
                    ),
                )
                .into());
            }
            // Every pyramid level the fit visits: coarse levels see smoother images, so the
            // forest must learn them too (a coarse pixel is seeded where its 4 children agree).
            let mut out = Vec::new();
            let mut img = (*frame).clone();
            let mut lab = seeds.clone();
            for level in 0..TRAINING_LEVELS {
                if level > 0 {
                    img = features::downsample(&img);
                    lab = downsample_seeds(&lab);
                }
                let ff = FrameFeatures::at_level(&img, level);
                let rgb = img.as_raw();
                out.extend(lab.data.iter().enumerate().filter_map(|(i, &v)| {
                    classes.class_of_seed(v).map(|k| {
                        let p = [rgb[3 * i], rgb[3 * i + 1], rgb[3 * i + 2]];
                        (
                            ff.at(i % lab.width, i / lab.width),
                            k as u8,
                            features::is_specular(p),
                        )
                    })
                }));
            }
            let out = Arc::new(out);
            if let Some(k) = cache {
                k.put((c, t), hash, out.clone());
            }
            Ok(out)
        })
        .collect();
    let mut by_class: Vec<Vec<(features::FeatureVector, u32)>> = vec![Vec::new(); classes.len()];
    let mut highlights: Vec<Vec<(features::FeatureVector, u32)>> = vec![Vec::new(); classes.len()];
    for (job, &(c, t)) in per_job.into_iter().zip(&jobs) {
        let g = group_of(c, t);
        for &(f, k, specular) in job?.iter() {
            let to = if specular {
                &mut highlights
            } else {
                &mut by_class
            };
            to[k as usize].push((f, g));
        }
    }
    // Highlights show the light, not the tissue: they train nothing, unless a class was
    // painted on highlights alone (then they are all it has).
    for (v, h) in by_class.iter_mut().zip(highlights) {
        if v.is_empty() {
            *v = h;
        }
    }
    for (k, v) in by_class.iter().enumerate() {
        if v.is_empty() {
            let what = if k == 0 {
                "background/tools (seed value 255)".to_string()
            } else {
                format!("'{}' (label {})", classes.names[k], classes.labels[k])
            };
            return Err(InputError::new(
                &origin,
                format!("no seeded pixel for {what}: paint at least one stroke of every class"),
            )
            .into());
        }
    }
    let mut samples = Samples::default();
    let mut groups = Vec::new();
    for (k, v) in by_class.into_iter().enumerate() {
        let step = v.len().div_ceil(MAX_SAMPLES_PER_CLASS).max(1);
        for (f, g) in v.into_iter().step_by(step) {
            samples.push(f, k as u8);
            groups.push(g);
        }
    }
    let by = if frames.len() > 1 { "frame" } else { "view" };
    Ok((samples, Groups { ids: groups, by }))
}
