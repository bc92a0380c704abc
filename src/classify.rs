//! `endofuse classify` (CONTRACT §1, §3): trains the forest on the scene's seeds and writes, per
//! frame and camera, 8-bit probability maps per class, the uncertainty map and argmax labels,
//! with metrics.json (forest size, training time, out-of-bag error, pixel Dice per class where
//! ground truth exists).

use crate::appearance::{Appearance, ForestParams};
use crate::error::Error;
use crate::plane::{Plane, dice};
use crate::scene::Scene;
use crate::scene::write::{write_json_atomic, write_labels};
use rayon::prelude::*;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

#[derive(Debug, Clone, Serialize)]
pub struct ForestMetrics {
    pub trees: usize,
    pub train_s: f64,
    pub oob_error: f64,
    pub oob_balanced_error: f64,
    pub samples: usize,
    /// Leave-one-seeded-frame-out agreement on the strokes (classes weighed equally): what
    /// the out-of-bag error cannot say about new frames. Absent with one seeded image.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub held_out: Option<crate::appearance::validate::Validation>,
}

/// What `classify` writes to metrics.json.
#[derive(Debug, Clone, Serialize)]
pub struct ClassifyMetrics {
    pub forest: ForestMetrics,
    /// Mean pixel Dice per class over frames and cameras with ground truth.
    pub pixel_dice: BTreeMap<String, f64>,
    /// The same over frames without seeds only (what the forest never saw).
    pub pixel_dice_unseeded: BTreeMap<String, f64>,
    pub frames: usize,
    /// Wall time of the frame loop divided by the views it classified (both cores busy):
    /// decoding, features, forest and writing the PNGs of one view.
    pub ms_per_view: f64,
}

/// Quantises a probability in [0, 1] to 8 bits (255 = 1.0).
pub fn to_u8(p: &Plane<f32>) -> Plane<u8> {
    p.map(|&v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
}

/// Runs the whole command; `progress(done, total)` as frames finish.
pub fn run(
    scene: &Scene,
    out: &Path,
    frames: (usize, usize),
    params: &ForestParams,
    cancel: Option<&AtomicBool>,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<ClassifyMetrics, Error> {
    // Ground truth checked whole before the run (it is read per frame as it is scored).
    scene.decode_ground_truth_of(frames.0..=frames.1, &|_, _| {})?;
    let model = Appearance::train(scene, params, cancel)?;
    let seeded = scene.seeds.seeded_frames();
    let names = &model.classes.names;
    let done = AtomicUsize::new(0);
    let total = frames.1 + 1 - frames.0;
    let jobs: Vec<(usize, usize)> = (frames.0..=frames.1)
        .flat_map(|t| (0..scene.cameras.len()).map(move |c| (t, c)))
        .collect();
    let loop_started = std::time::Instant::now();
    // Per job: Dice per class (None where the class is absent from both).
    let results: Vec<(usize, Vec<Option<f64>>)> = jobs
        .par_iter()
        .map(|&(t, c)| -> Result<_, Error> {
            crate::error::stop_if_cancelled(cancel)?;
            let frame = scene.frame(c, t)?;
            let maps = model.classify_frame(&frame);
            let cam = &scene.cameras[c].name;
            for (k, name) in names.iter().enumerate() {
                write_labels(
                    &out.join(format!("prob/{name}/{cam}/{t:06}.png")),
                    &to_u8(&maps.class_plane(k)),
                )?;
            }
            write_labels(
                &out.join(format!("uncertainty/{cam}/{t:06}.png")),
                &to_u8(&maps.uncertainty()),
            )?;
            let labels = maps.argmax_labels(&model.classes);
            write_labels(&out.join(format!("labels/{cam}/{t:06}.png")), &labels)?;
            let scores = match scene.ground_truth_labels(c, t) {
                Some(gt) => {
                    let gt = gt?;
                    model
                        .classes
                        .labels
                        .iter()
                        .map(|&l| dice(&labels.mask_of(l), &gt.mask_of(l)))
                        .collect()
                }
                None => Vec::new(),
            };
            if c + 1 == scene.cameras.len() {
                progress(done.fetch_add(1, Ordering::Relaxed) + 1, total);
            }
            Ok((t, scores))
        })
        .collect::<Result<_, _>>()?;
    let loop_s = loop_started.elapsed().as_secs_f64();
    let mean_dice = |keep: &dyn Fn(usize) -> bool| -> BTreeMap<String, f64> {
        names
            .iter()
            .enumerate()
            .filter_map(|(k, name)| {
                let v: Vec<f64> = results
                    .iter()
                    .filter(|(t, _)| keep(*t))
                    .filter_map(|(_, s)| s.get(k).copied().flatten())
                    .collect();
                (!v.is_empty()).then(|| (name.clone(), v.iter().sum::<f64>() / v.len() as f64))
            })
            .collect()
    };
    let metrics = ClassifyMetrics {
        forest: ForestMetrics {
            trees: model.forest.tree_count(),
            train_s: model.stats.train_s,
            oob_error: model.stats.oob_error,
            oob_balanced_error: model.stats.oob_balanced_error,
            samples: model.stats.samples,
            held_out: model.validation.clone(),
        },
        pixel_dice: mean_dice(&|_| true),
        pixel_dice_unseeded: mean_dice(&|t| !seeded.contains(&t)),
        frames: total,
        ms_per_view: loop_s * 1e3 / jobs.len().max(1) as f64,
    };
    write_json_atomic(&out.join("metrics.json"), &metrics)?;
    Ok(metrics)
}
