//! `endofuse track` (CONTRACT §1, §3): trains the forest on the seeds, starts from the scene's
//! initial pose (or estimates one), tracks every frame, and writes visible masks, hidden
//! structures' projections, trajectory.json and metrics.json (Dice, hidden-structure Dice and
//! centroid error, camera errors, timing) where ground truth exists.

use crate::appearance::{Appearance, ForestParams};
use crate::error::Error;
use crate::fit::Model;
use crate::fit::config::{FitConfig, Mode, ResolvedConfig};
use crate::fit::tracker::{TrackOptions, TrackedFrame, initial_state, track};
use crate::plane::dice;
use crate::scene::write::{write_json_atomic, write_labels, write_mask};
use crate::scene::{Scene, Trajectory, TrajectoryFrame};
use rayon::prelude::*;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::atomic::AtomicBool;

#[derive(Debug, Clone, Serialize)]
pub struct DiceSummary {
    pub mean: f64,
    pub by_structure: BTreeMap<String, f64>,
    pub per_frame: Vec<f64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct HiddenMetrics {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dice_mean: Option<f64>,
    pub centroid_error_mm_mean: f64,
    pub centroid_error_mm_max: f64,
    /// Frames the centroid error is over: those the ground-truth trajectory gives a centroid.
    pub centroid_frames: usize,
    /// Share of frames whose true centroid lies inside the 95 % region (`hidden_region`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub coverage95: Option<f64>,
    /// Median radius of the 95 % region over frames (mm).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub radius95_mm_median: Option<f64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct CameraMetrics {
    pub fx_rel_error_mean: f64,
    pub cx_error_px_mean: f64,
    pub fx_rel_error_max: f64,
    pub cy_error_px_mean: f64,
    pub k1_error_max: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct Percentiles {
    pub median: f64,
    pub p95: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct Timing {
    pub forest_train_s: f64,
    pub ms_per_frame: Percentiles,
}

#[derive(Debug, Clone, Serialize)]
pub struct TrackMetrics {
    pub mode: String,
    pub frames: usize,
    pub lost_frames: usize,
    /// Frames whose apparent size changed as in a zoom with the cameras fixed (trajectory.json
    /// warns "depth_explains_zoom" on each): the hidden structures may be off there.
    pub depth_explains_zoom_frames: usize,
    /// Frames per refusal ("camera_correction_refused", "placement_refused"; trajectory.json
    /// warns on each): what the tracker would have done looked implausible.
    #[serde(skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub refused_frames: std::collections::BTreeMap<String, usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dice: Option<DiceSummary>,
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub hidden: BTreeMap<String, HiddenMetrics>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub camera: Option<CameraMetrics>,
    pub timing: Timing,
    /// The fit's configuration and what it resolved to, so the run can be reproduced
    /// (`track --config metrics.json`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub config: Option<ResolvedConfig>,
    /// The forest's settings (trained on the scene's seeds).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub forest: Option<ForestParams>,
}

fn mean(v: &[f64]) -> f64 {
    if v.is_empty() {
        f64::NAN
    } else {
        v.iter().sum::<f64>() / v.len() as f64
    }
}

fn percentile(v: &[f64], q: f64) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    if s.is_empty() {
        return f64::NAN;
    }
    s[((s.len() - 1) as f64 * q).round() as usize]
}

/// Runs the whole command with the fit configured by `config`; `progress(done, total)` as
/// frames finish.
pub fn run(
    scene: &Scene,
    out: &Path,
    mode: Mode,
    frames: (usize, usize),
    config: &FitConfig,
    cancel: Option<&AtomicBool>,
    progress: &dyn Fn(usize, usize),
) -> Result<TrackMetrics, Error> {
    run_timed(
        scene,
        out,
        mode,
        frames,
        config,
        Timings::Recorded,
        cancel,
        progress,
    )
}

/// Whether trajectory.json records each frame's time (`ms`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Timings {
    Recorded,
    /// Left out (`track --no-timings`): the only part of the file that differs between two
    /// runs of the same input.
    LeftOut,
}

/// [`run`], with or without per-frame times in trajectory.json.
#[allow(clippy::too_many_arguments)]
pub fn run_timed(
    scene: &Scene,
    out: &Path,
    mode: Mode,
    frames: (usize, usize),
    config: &FitConfig,
    timings: Timings,
    cancel: Option<&AtomicBool>,
    progress: &dyn Fn(usize, usize),
) -> Result<TrackMetrics, Error> {
    // Ground truth is read frame by frame as the run scores it: a bad value met at frame N
    // would throw N tracked frames away. Every image is checked before anything is done.
    scene.decode_ground_truth_of(frames.0..=frames.1, &|_, _| {})?;
    let forest = ForestParams::default();
    let appearance = Appearance::train(scene, &forest, cancel)?;
    log::info!(
        "forest: {} trees on {} seeded pixels in {:.2} s, out-of-bag error {:.3}",
        forest.trees,
        appearance.stats.samples,
        appearance.stats.train_s,
        appearance.stats.oob_error
    );
    let model = Model::build(scene)?;
    let affine =
        crate::fit::init::starting_pose(scene, &model, &appearance, config, frames.0, cancel)?;
    let start = initial_state(scene, &model, affine);
    let options =
        TrackOptions::new(mode, frames, scene.cameras[0].width).with_config(config.clone());
    let total = frames.1 + 1 - frames.0;
    let mut recorder = Recorder::new(scene, out, mode);
    recorder.record_timings = timings == Timings::Recorded;
    let mut resolved = options.config.resolved(mode, options.fit_level());
    resolved.frames = Some([frames.0, frames.1]);
    recorder.config = Some(resolved);
    recorder.forest = Some(forest);
    log::info!(
        "tracking frames {}..{} in mode {} at pyramid level {}",
        frames.0,
        frames.1,
        mode.name(),
        options.fit_level()
    );
    track(
        scene,
        &model,
        &appearance,
        start,
        &options,
        cancel,
        &mut |f| {
            log::debug!(
                "frame {}: confidence {:.3}, {} steps, {:.1} ms{}",
                f.frame,
                f.confidence,
                f.iterations,
                f.ms,
                if f.lost { ", lost" } else { "" }
            );
            recorder.record(&f)?;
            progress(recorder.frames(), total);
            Ok(())
        },
    )?;
    recorder.finish(appearance.stats.train_s)
}

/// Dice of each visible structure in frame `f` against ground truth, per camera (structures
/// where truth and prediction are both empty are left out). Empty without ground truth.
pub fn frame_dice(scene: &Scene, f: &TrackedFrame) -> Result<Vec<(String, f64)>, Error> {
    let mut scores = Vec::new();
    for c in 0..scene.cameras.len() {
        if let Some(gt) = scene.ground_truth_labels(c, f.frame) {
            let gt = gt?;
            let Some(labels) = f.labels.get(c) else {
                continue;
            };
            for s in scene.structures.iter().filter(|s| s.visible) {
                if let Some(d) = dice(&labels.mask_of(s.label), &gt.mask_of(s.label)) {
                    scores.push((s.name.clone(), d));
                }
            }
        }
    }
    Ok(scores)
}

/// Writes what `track` writes, frame by frame, and gathers the metrics (CONTRACT §3). The
/// command and the app's export both go through it, so their files are the same.
pub struct Recorder<'a> {
    scene: &'a Scene,
    out: &'a Path,
    mode: Mode,
    anchor_name: String,
    trajectory: Trajectory,
    per_frame_dice: Vec<f64>,
    by_structure: BTreeMap<String, Vec<f64>>,
    all_dice: Vec<f64>,
    hidden_dice: BTreeMap<String, Vec<f64>>,
    centroid_err: BTreeMap<String, Vec<f64>>,
    /// Per hidden structure: each frame's region radius and whether it held the truth.
    region: BTreeMap<String, Vec<(f64, bool)>>,
    fx_err: Vec<f64>,
    cx_err: Vec<f64>,
    cy_err: Vec<f64>,
    k1_err: Vec<f64>,
    ms: Vec<f64>,
    lost_frames: usize,
    depth_zoom_frames: usize,
    refused_frames: std::collections::BTreeMap<String, usize>,
    /// Also write overlay PNGs (`overlay/{camera}/{frame}.png`), as the app's export does.
    pub overlays: bool,
    /// Write each frame's `ms` into trajectory.json (off: the file depends on the input
    /// alone, so two runs compare byte for byte).
    pub record_timings: bool,
    /// The configuration the frames were fitted with, for metrics.json.
    pub config: Option<ResolvedConfig>,
    /// The forest's settings, for metrics.json.
    pub forest: Option<ForestParams>,
}

impl<'a> Recorder<'a> {
    pub fn new(scene: &'a Scene, out: &'a Path, mode: Mode) -> Self {
        let model_anchor = crate::fit::model::anchor_index(&scene.structures);
        Self {
            scene,
            out,
            mode,
            anchor_name: scene.structures[model_anchor].name.clone(),
            record_timings: true,
            trajectory: Trajectory::default(),
            per_frame_dice: Vec::new(),
            by_structure: BTreeMap::new(),
            all_dice: Vec::new(),
            hidden_dice: BTreeMap::new(),
            centroid_err: BTreeMap::new(),
            region: BTreeMap::new(),
            fx_err: Vec::new(),
            cx_err: Vec::new(),
            cy_err: Vec::new(),
            k1_err: Vec::new(),
            ms: Vec::new(),
            lost_frames: 0,
            depth_zoom_frames: 0,
            refused_frames: Default::default(),
            overlays: false,
            config: None,
            forest: None,
        }
    }

    /// Frames recorded so far.
    pub fn frames(&self) -> usize {
        self.trajectory.frames.len()
    }

    /// Writes one frame's masks (and overlays) and adds it to the metrics.
    pub fn record(&mut self, f: &TrackedFrame) -> Result<(), Error> {
        let scene = self.scene;
        let out = self.out;
        let t = f.frame;
        // Every view's files at once (PNG encoding is most of it); the first view's error is
        // the one reported, as when they were written in turn.
        let written: Vec<Result<(), Error>> = (0..scene.cameras.len())
            .into_par_iter()
            .map(|c| {
                let cam = &scene.cameras[c];
                write_labels(
                    &out.join(format!("masks/{}/{t:06}.png", cam.name)),
                    &f.labels[c],
                )?;
                for (name, masks) in &f.hidden {
                    write_mask(
                        &out.join(format!("hidden/{name}/{}/{t:06}.png", cam.name)),
                        &masks[c],
                    )?;
                }
                for (name, masks) in &f.region_masks {
                    write_mask(
                        &out.join(format!("hidden_region/{name}/{}/{t:06}.png", cam.name)),
                        &masks[c],
                    )?;
                }
                if self.overlays {
                    let mut img = (*scene.frame(c, t)?).clone();
                    crate::overlay::draw_tracked(&mut img, scene, f, c);
                    crate::scene::write::write_rgb(
                        &out.join(format!("overlay/{}/{t:06}.png", cam.name)),
                        &img,
                    )?;
                }
                Ok(())
            })
            .collect();
        written.into_iter().collect::<Result<(), Error>>()?;
        let frame_scores = frame_dice(scene, f)?;
        for (name, d) in &frame_scores {
            self.by_structure.entry(name.clone()).or_default().push(*d);
        }
        for (c, cam) in scene.cameras.iter().enumerate() {
            for (name, masks) in &f.hidden {
                let path = match (&scene.ground_truth.hidden, &scene.root) {
                    (Some(tpl), Some(root)) => root.join(tpl.expand(t, &cam.name, name)),
                    _ => continue,
                };
                if path.exists() {
                    let size = (masks[c].width as u32, masks[c].height as u32);
                    let gt = crate::scene::read_hidden_mask(&path, size)?;
                    if let Some(d) = dice(&masks[c], &gt.map(|&v| v >= 128)) {
                        self.hidden_dice.entry(name.clone()).or_default().push(d);
                    }
                }
            }
        }
        if !frame_scores.is_empty() {
            let values: Vec<f64> = frame_scores.iter().map(|(_, d)| *d).collect();
            self.per_frame_dice.push(mean(&values));
            self.all_dice.extend(values);
        }
        if let Some(truth) = scene
            .ground_truth
            .trajectory
            .as_ref()
            .and_then(|g| g.get(t))
        {
            for r in &f.hidden_regions {
                if let Some(tc) = truth.centroids.get(&r.structure) {
                    self.region
                        .entry(r.structure.clone())
                        .or_default()
                        .push((r.radius_mm, r.holds(glam::DVec3::from_array(*tc))));
                }
            }
            for (name, c) in &f.centroids {
                if let Some(tc) = truth.centroids.get(name) {
                    self.centroid_err
                        .entry(name.clone())
                        .or_default()
                        .push((*c - glam::DVec3::from_array(*tc)).length());
                }
            }
            for (est, tru) in f.state.intrinsics.iter().zip(&truth.cameras) {
                self.fx_err.push((est.fx - tru.fx).abs() / tru.fx);
                self.cx_err.push((est.cx - tru.cx).abs());
                self.cy_err.push((est.cy - tru.cy).abs());
                self.k1_err.push((est.k1 - tru.k1).abs());
            }
        }
        self.ms.push(f.ms);
        self.lost_frames += f.lost as usize;
        self.depth_zoom_frames += f.depth_explains_zoom as usize;
        for w in &f.refused {
            *self.refused_frames.entry(w.to_string()).or_default() += 1;
        }
        self.trajectory.frames.push(TrajectoryFrame {
            frame: t as u32,
            affine: f.state.affine.q.to_vec(),
            shape: BTreeMap::from([(self.anchor_name.clone(), f.state.shape.clone())]),
            cameras: f.state.intrinsics.clone(),
            centroids: f
                .centroids
                .iter()
                .map(|(n, c)| (n.clone(), c.to_array()))
                .collect(),
            energy: Some(f.energy),
            iterations: Some(f.iterations),
            ms: self.record_timings.then_some(f.ms),
            confidence: Some(f.confidence),
            lost: Some(f.lost),
            warnings: f
                .depth_explains_zoom
                .then_some(crate::scene::trajectory::DEPTH_EXPLAINS_ZOOM)
                .into_iter()
                .chain(f.refused.iter().copied())
                .map(String::from)
                .collect(),
            hidden_region: f
                .hidden_regions
                .iter()
                .map(|r| (r.structure.clone(), r.entry()))
                .collect(),
        });
        Ok(())
    }

    /// Writes trajectory.json and metrics.json; `forest_train_s` is the forest's training time.
    pub fn finish(self, forest_train_s: f64) -> Result<TrackMetrics, Error> {
        let scene = self.scene;
        write_json_atomic(&self.out.join("trajectory.json"), &self.trajectory)?;
        let hidden: BTreeMap<String, HiddenMetrics> = self
            .centroid_err
            .iter()
            .filter(|(name, _)| {
                scene
                    .structures
                    .iter()
                    .any(|s| &s.name == *name && !s.visible)
            })
            .map(|(name, errs)| {
                (
                    name.clone(),
                    HiddenMetrics {
                        dice_mean: self.hidden_dice.get(name).map(|v| mean(v)),
                        centroid_error_mm_mean: mean(errs),
                        centroid_error_mm_max: errs.iter().cloned().fold(0.0, f64::max),
                        centroid_frames: errs.len(),
                        coverage95: self.region.get(name).filter(|r| !r.is_empty()).map(|r| {
                            r.iter().filter(|(_, inside)| *inside).count() as f64 / r.len() as f64
                        }),
                        radius95_mm_median: self.region.get(name).filter(|r| !r.is_empty()).map(
                            |r| {
                                percentile(
                                    &r.iter().map(|(radius, _)| *radius).collect::<Vec<_>>(),
                                    0.5,
                                )
                            },
                        ),
                    },
                )
            })
            .collect();
        let metrics = TrackMetrics {
            mode: self.mode.name().into(),
            frames: self.trajectory.frames.len(),
            lost_frames: self.lost_frames,
            depth_explains_zoom_frames: self.depth_zoom_frames,
            refused_frames: self.refused_frames,
            dice: (!self.all_dice.is_empty()).then(|| DiceSummary {
                mean: mean(&self.all_dice),
                by_structure: self
                    .by_structure
                    .iter()
                    .map(|(k, v)| (k.clone(), mean(v)))
                    .collect(),
                per_frame: self.per_frame_dice.clone(),
            }),
            hidden,
            camera: (!self.fx_err.is_empty()).then(|| CameraMetrics {
                fx_rel_error_mean: mean(&self.fx_err),
                cx_error_px_mean: mean(&self.cx_err),
                fx_rel_error_max: self.fx_err.iter().cloned().fold(0.0, f64::max),
                cy_error_px_mean: mean(&self.cy_err),
                k1_error_max: self.k1_err.iter().cloned().fold(0.0, f64::max),
            }),
            timing: Timing {
                forest_train_s,
                ms_per_frame: Percentiles {
                    median: percentile(&self.ms, 0.5),
                    p95: percentile(&self.ms, 0.95),
                },
            },
            config: self.config,
            forest: self.forest,
        };
        write_json_atomic(&self.out.join("metrics.json"), &metrics)?;
        Ok(metrics)
    }
}
