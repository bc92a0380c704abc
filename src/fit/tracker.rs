//! Frame-to-frame tracking: warm start from the previous frame, per-frame confidence, and
//! tracking loss. When confidence collapses (organ covered or out of view) the last good pose
//! is held and the frame marked lost; shape and intrinsics learnt before are never updated from
//! a lost frame, and fitting resumes from the last good state when the organ returns. Inside a
//! zoom (marked in the scene, or detected by [`super::zoom`] in LSC) the intrinsics are
//! corrected while the pose is held where its motion before the zoom carries it
//! ([`super::motion`]).

use super::config::{FitConfig, FitParams, Mode, Phase, TrackingConfig, Zoom};
use super::context::FrameContext;
use super::hidden_region::{HiddenRegion, ZoomHistory, hidden_regions};
use super::model::Model;
use super::motion::MotionHistory;
use super::optimizer::{FrameFit, fit_frame};
use super::probability::ViewProbabilities;
use super::state::FitState;
use super::zoom::ZoomDetector;
use crate::appearance::{Appearance, ClassMap};
use crate::error::Error;
use crate::geometry::{Affine, Camera};
use crate::plane::{LabelImage, Mask};
use crate::render::raster::{
    RasterOptions, RenderObject, coverage, label_image, rasterize_objects,
};
use crate::scene::Scene;
use glam::DVec3;
use rayon::prelude::*;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

/// Too few lines or too little confidence: the organ is not where the fit put it.
fn is_lost(fit: &FrameFit, tracking: &TrackingConfig) -> bool {
    fit.confidence < tracking.lost_confidence || fit.lines < tracking.min_lines
}

/// What to track and how: the mode, the frames, the fit's configuration, and who may cancel.
#[derive(Debug, Clone)]
pub struct TrackOptions {
    pub mode: Mode,
    /// Inclusive frame range.
    pub frames: (usize, usize),
    /// Width of camera 0's frames (px): it sets the pyramid level tracking fits at.
    pub width: u32,
    pub config: FitConfig,
    /// Raised by whoever wants tracking to stop: checked between frames and between
    /// Gauss–Newton steps.
    pub cancel: Option<Arc<AtomicBool>>,
}

impl TrackOptions {
    /// Default settings for a video `width` pixels wide.
    pub fn new(mode: Mode, frames: (usize, usize), width: u32) -> Self {
        Self {
            mode,
            frames,
            width,
            config: FitConfig::default(),
            cancel: None,
        }
    }

    pub fn with_config(mut self, config: FitConfig) -> Self {
        self.config = config;
        self
    }

    /// Lets `cancel` stop the fit between steps as well as between frames.
    pub fn with_cancel(mut self, cancel: Option<Arc<AtomicBool>>) -> Self {
        self.cancel = cancel;
        self
    }

    /// The pyramid level frames are fitted at.
    pub fn fit_level(&self) -> usize {
        self.config.tracking.fit_level(self.width)
    }

    /// The settings of one fit in `phase` (see [`FitConfig::resolve`]).
    pub fn params(&self, phase: Phase, zoom: Zoom) -> FitParams {
        FitParams {
            cancel: self.cancel.clone(),
            information: true,
            ..self
                .config
                .resolve(self.mode, phase, zoom, self.fit_level())
        }
    }
}

/// One tracked frame with what the outputs need.
#[derive(Debug, Clone)]
pub struct TrackedFrame {
    pub frame: usize,
    pub state: FitState,
    pub energy: f64,
    pub iterations: u32,
    pub ms: f64,
    pub confidence: f64,
    pub lost: bool,
    /// The apparent size changed as in a zoom with the cameras fixed: depth explained it, so
    /// the hidden structures may be off (the confidence is lowered).
    pub depth_explains_zoom: bool,
    /// What else the tracker refused in this frame (`trajectory::CAMERA_CORRECTION_REFUSED`,
    /// `trajectory::PLACEMENT_REFUSED`), for trajectory.json's warnings.
    pub refused: Vec<&'static str>,
    /// Front-most visible structure per pixel, per camera.
    pub labels: Vec<LabelImage>,
    /// Each hidden structure's projection per camera (occlusion ignored).
    pub hidden: Vec<(String, Vec<Mask>)>,
    /// Vertex means of every structure's fitted mesh, camera-0 coordinates (mm).
    pub centroids: Vec<(String, DVec3)>,
    /// Where each hidden structure could be (its 95 % sphere), in `hidden`'s order.
    pub hidden_regions: Vec<HiddenRegion>,
    /// Each hidden structure's projections over its region, per camera.
    pub region_masks: Vec<(String, Vec<Mask>)>,
}

/// Each hidden structure's projection widened by its region, per camera (`hidden` and
/// `regions` in the same order, by structure name).
pub fn region_masks(
    cams: &[Camera],
    hidden: &[(String, Vec<Mask>)],
    regions: &[HiddenRegion],
) -> Vec<(String, Vec<Mask>)> {
    hidden
        .iter()
        .filter_map(|(name, masks)| {
            let region = regions.iter().find(|r| &r.structure == name)?;
            Some((
                name.clone(),
                masks
                    .par_iter()
                    .zip(cams)
                    .map(|(m, c)| super::hidden_region::region_mask(m, c, region))
                    .collect(),
            ))
        })
        .collect()
}

/// Removes from the label image the pixels inside a fitted structure that the forest sees as
/// background or tools: an instrument crossing the kidney hides it there. The hidden
/// structures' masks are left whole (they ignore occlusion by definition).
fn mask_occluders(
    labels: &mut LabelImage,
    view: &mut ViewProbabilities,
    appearance: &Appearance,
    level: usize,
    tracking: &TrackingConfig,
) {
    if view.level_count() <= level {
        return;
    }
    // Label pixels this deep inside the labels are checked (a row-window test, equal to a
    // threshold of the depth transform).
    let checked =
        crate::render::distance::deep_inside(&labels.map(|&l| l != 0), tracking.occluder_margin_px);
    let (lw, lh) = view.size(level);
    let scale = 1usize << level;
    let coarse = |i: usize| -> usize {
        let (x, y) = ((i % labels.width) / scale, (i / labels.width) / scale);
        y.min(lh - 1) * lw + x.min(lw - 1)
    };
    let checked_pixels = || {
        checked
            .data
            .iter()
            .enumerate()
            .filter_map(|(i, &c)| c.then_some(i))
    };
    // The level's pixels under them, each once and in order (at level 1 a level pixel lies
    // under four label pixels): a mark per level pixel, not a sort of every label pixel's.
    let mut wanted = vec![false; lw * lh];
    for i in checked_pixels() {
        wanted[coarse(i)] = true;
    }
    let pixels: Vec<u32> = wanted
        .iter()
        .enumerate()
        .filter_map(|(i, &w)| w.then_some(i as u32))
        .collect();
    view.ensure(Some(appearance), level, &pixels);
    for i in checked_pixels() {
        if view.get(level, coarse(i) as u32, 0) > tracking.occluder_background {
            labels.data[i] = 0;
        }
    }
}

/// An experiment, not a mode: with `ENDOFUSE_TRUTH_PROBABILITIES=C` (0.5 < C ≤ 1) set, a scene
/// with ground-truth labels is tracked on probabilities made from them (C for the true class)
/// instead of the forest's, so that what the appearance costs the fit (a biased depth, a
/// misplaced hidden tumour) can be told apart from what the geometry does. Frames without
/// ground truth, and every run without the variable, use the forest.
fn truth_probabilities(
    scene: &Scene,
    camera: usize,
    frame: usize,
    class_labels: &[u8],
    levels: usize,
) -> Option<ViewProbabilities> {
    static CONFIDENCE: std::sync::OnceLock<Option<f32>> = std::sync::OnceLock::new();
    let confidence = (*CONFIDENCE.get_or_init(|| {
        std::env::var("ENDOFUSE_TRUTH_PROBABILITIES")
            .ok()
            .and_then(|v| v.parse::<f32>().ok())
            .filter(|c| *c > 0.5 && *c <= 1.0)
    }))?;
    let labels = scene.ground_truth_labels(camera, frame)?.ok()?;
    Some(ViewProbabilities::from_labels(
        &labels,
        class_labels,
        levels,
        confidence,
    ))
}

/// The cameras with the intrinsics of a state.
pub fn cameras_of(scene: &Scene, state: &FitState) -> Vec<Camera> {
    scene
        .cameras
        .iter()
        .zip(&state.intrinsics)
        .map(|(c, i)| Camera {
            intrinsics: *i,
            ..c.clone()
        })
        .collect()
}

/// What a state looks like at full resolution: label images per camera, each hidden
/// structure's masks per camera, and every structure's centroid.
pub struct Rendered {
    pub labels: Vec<LabelImage>,
    pub hidden: Vec<(String, Vec<Mask>)>,
    pub centroids: Vec<(String, DVec3)>,
}

/// Renders the labels, hidden masks and centroids of a state at full resolution.
pub fn render_state(scene: &Scene, model: &Model, state: &FitState) -> Rendered {
    let deformed = model.deformed(&state.shape);
    let posed = model.posed(&state.affine, &deformed);
    let cams = cameras_of(scene, state);
    let visible = model.indices(true);
    let labels_of: Vec<u8> = visible.iter().map(|&i| model.structures[i].label).collect();
    let objects = model.objects(&posed, &visible);
    // Every view's labels and every hidden structure's masks at once: full-resolution rasters
    // of object indices only (the fit's surface planes are not needed here).
    let raster = |c: &Camera, objects: &[RenderObject]| {
        rasterize_objects(c, objects, &RasterOptions::default())
    };
    let labels = cams
        .par_iter()
        .map(|c| label_image(&raster(c, &objects), &labels_of))
        .collect();
    let hidden = (0..model.structures.len())
        .filter(|&i| !model.structures[i].visible)
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|i| {
            let obj = model.objects(&posed, &[i]);
            (
                model.structures[i].name.clone(),
                cams.par_iter()
                    .map(|c| coverage(&raster(c, &obj)))
                    .collect(),
            )
        })
        .collect();
    let centroids = model
        .structures
        .iter()
        .zip(&posed)
        .map(|(s, p)| (s.name.clone(), crate::geometry::mesh::vertex_mean(p)))
        .collect();
    Rendered {
        labels,
        hidden,
        centroids,
    }
}

/// The state tracking starts from: the scene's initial pose (or the automatic estimate),
/// mean shape, calibrated cameras.
pub fn initial_state(scene: &Scene, model: &Model, affine: Affine) -> FitState {
    FitState {
        affine,
        shape: vec![0.0; model.shape.mode_count()],
        intrinsics: scene.cameras.iter().map(|c| c.intrinsics).collect(),
    }
}

/// What tracking carries from one frame to the next, and how it fits the next one.
struct FrameTracker<'a> {
    ctx: FrameContext<'a>,
    scene: &'a Scene,
    appearance: &'a Appearance,
    options: &'a TrackOptions,
    cancel: Option<&'a AtomicBool>,
    /// The last frame that was not lost, and its number.
    good: FitState,
    good_frame: usize,
    first: bool,
    /// The first frame that was not lost: zoom detection waits while the fit settles after it.
    first_good_frame: Option<usize>,
    lost_run: usize,
    /// Poses of frames fitted with fixed intrinsics: their motion carries the pose through a
    /// zoom.
    motion: MotionHistory,
    zoom: ZoomDetector,
    /// The same test, in modes without camera correction: a zoom there is explained by depth.
    depth_zoom: ZoomDetector,
    /// The hidden regions of the last good frame (a lost frame keeps its state, and them).
    regions: Vec<HiddenRegion>,
    /// What the cameras have done so far: a zoom's focal-length error outlasts it.
    zoom_history: ZoomHistory,
}

/// One frame's fit and what the tracker made of it.
struct Outcome {
    fit: FrameFit,
    /// The fit's state, or the last good one where the frame is lost.
    state: FitState,
    lost: bool,
    /// The apparent size changed as in a zoom and only the pose could follow it.
    depth_explains_zoom: bool,
    /// The cameras may have zoomed in this frame (corrected or not): the hidden regions take
    /// the depth as loosely known from here on.
    zoom_uncertain: bool,
    /// ... and the camera correction followed it.
    zoom_corrected: bool,
    refused: Vec<&'static str>,
}

impl<'a> FrameTracker<'a> {
    /// Err(Cancelled) once the user cancelled: a fit cut short is not a result.
    fn cancelled(&self) -> Result<(), Error> {
        crate::error::stop_if_cancelled(self.cancel)
    }

    /// The last good state with its pose carried on to frame `t` by the motion before it: where
    /// a zoom holds the pose (zooming in and coming closer look alike within a frame).
    fn carried(&self, t: usize) -> FitState {
        FitState {
            affine: self.motion.predict(
                &self.good.affine,
                t.saturating_sub(self.good_frame) as f64,
                t,
            ),
            ..self.good.clone()
        }
    }

    fn fit(
        &self,
        views: &mut [ViewProbabilities],
        anchor: &FitState,
        params: &FitParams,
    ) -> FrameFit {
        fit_frame(
            &self.ctx,
            anchor,
            anchor,
            views,
            Some(self.appearance),
            params,
        )
    }

    fn is_lost(&self, fit: &FrameFit) -> bool {
        is_lost(fit, &self.options.config.tracking)
    }

    /// Fits frame `t`: camera correction inside marked (or detected) zooms, a fresh placement
    /// after a lost stretch, and the bookkeeping of what the next frame starts from.
    fn frame(&mut self, t: usize, views: &mut [ViewProbabilities]) -> Result<Outcome, Error> {
        let options = self.options;
        let zoom_config = &options.config.zoom;
        let phase = if self.first {
            Phase::FirstFrame
        } else {
            Phase::Tracked
        };
        let in_zoom =
            (0..=zoom_config.settle_frames).any(|k| t >= k && self.scene.in_zoom_change(t - k));
        if in_zoom {
            self.zoom.reset();
        }
        let mut correct_cameras = options.mode == Mode::LSC && (in_zoom || self.zoom.active());
        // Without camera correction (R, L, LS) the pose is all that can follow a zoom: it
        // must move as fast as the image changes.
        let zoom = if correct_cameras {
            Zoom::Cameras
        } else if in_zoom {
            Zoom::PoseOnly
        } else {
            Zoom::Off
        };
        let anchor = if correct_cameras {
            self.carried(t)
        } else {
            self.good.clone()
        };
        let mut fit = self.fit(views, &anchor, &options.params(phase, zoom));
        self.cancelled()?;
        if options.mode == Mode::LSC && !correct_cameras && self.zoom_starts(t, &fit) {
            // The frames just before held the zoom's onset, taken for motion.
            self.motion.forget_latest(zoom_config.onset_frames);
            fit = self.fit(
                views,
                &self.carried(t),
                &options.params(phase, Zoom::Cameras),
            );
            correct_cameras = true;
            self.cancelled()?;
        } else if correct_cameras && !in_zoom && !self.is_lost(&fit) {
            self.zoom.corrected(&self.good, &fit.state);
        }
        let mut refused = Vec::new();
        let mut zoom_refused = false;
        if correct_cameras && !self.cameras_plausible(&fit.state) {
            // A runaway correction: the frame is fitted again with the cameras as they were.
            log::info!("frame {t}: camera correction refused (fx or fy/fx implausible)");
            refused.push(crate::scene::trajectory::CAMERA_CORRECTION_REFUSED);
            self.zoom.reset();
            fit = self.fit(
                views,
                &self.good.clone(),
                &options.params(phase, Zoom::PoseOnly),
            );
            correct_cameras = false;
            // The pose alone followed whatever zoom this was.
            zoom_refused = true;
            self.cancelled()?;
        }
        log::debug!(
            "frame {t}: cameras corrected {correct_cameras}, fx {:.1}, confidence {:.3}, {} lines",
            fit.state.intrinsics.first().map_or(f64::NAN, |k| k.fx),
            fit.confidence,
            fit.lines,
        );
        let (fit, lost) = self.placed_afresh_if_lost(t, views, fit, &mut refused);
        // A cancel inside the fresh placement reads there as "no placement": the frame must
        // not be reported lost (and a run's last frame finished) on that account.
        self.cancelled()?;
        let depth_explains_zoom = !correct_cameras
            && !lost
            && (in_zoom
                || zoom_refused
                || (options.mode != Mode::LSC && self.size_changes_like_a_zoom(t, &fit)));
        // A lost frame keeps the last good state: nothing learnt from it.
        let state = if lost {
            self.motion.clear();
            self.zoom.reset();
            self.good.clone()
        } else {
            self.good = fit.state.clone();
            self.good_frame = t;
            self.first = false;
            self.first_good_frame.get_or_insert(t);
            if !correct_cameras {
                self.motion.push(t, self.good.affine);
            }
            fit.state.clone()
        };
        Ok(Outcome {
            fit,
            state,
            lost,
            depth_explains_zoom,
            zoom_uncertain: in_zoom || correct_cameras || depth_explains_zoom || zoom_refused,
            zoom_corrected: correct_cameras,
            refused,
        })
    }

    /// Whether corrected intrinsics are ones a zoom can give: fx within `max_zoom_factor` of
    /// calibration either way, and fy/fx within `max_aspect_change` of the calibrated ratio.
    fn cameras_plausible(&self, state: &FitState) -> bool {
        let k = &self.options.config.tracking;
        state
            .intrinsics
            .iter()
            .zip(self.scene.cameras.iter())
            .all(|(now, cam)| {
                let cal = &cam.intrinsics;
                let zoom = now.fx / cal.fx;
                let aspect = (now.fy / now.fx) / (cal.fy / cal.fx);
                zoom.is_finite()
                    && (1.0 / k.max_zoom_factor..=k.max_zoom_factor).contains(&zoom)
                    && (aspect - 1.0).abs() <= k.max_aspect_change
            })
    }

    /// Without camera correction: did this frame's apparent size change as in a zoom (the
    /// depth then took the zoom's place)? Against the frame just before only, as in LSC.
    fn size_changes_like_a_zoom(&mut self, t: usize, fit: &FrameFit) -> bool {
        self.centre_after_good_frame(t).is_some_and(|centre| {
            self.depth_zoom
                .changes_like_a_zoom(&self.good, &fit.state, centre)
        })
    }

    /// The model's centre at the last good shape, when frame `t` follows that good frame
    /// directly and the fit has settled: a change of apparent size means something only
    /// against the frame just before (after lost frames the organ may simply be elsewhere).
    fn centre_after_good_frame(&self, t: usize) -> Option<glam::DVec3> {
        if self.first || self.good_frame + 1 != t || self.settling(t) {
            return None;
        }
        let model = self.ctx.model;
        Some(self.ctx.model_centre(&model.deformed(&self.good.shape)))
    }

    /// Whether frame `t` is among the first after the first fitted frame: the fit is still
    /// converging there (its depth moves millimetres a frame), which the zoom test would take
    /// for a zoom.
    fn settling(&self, t: usize) -> bool {
        let warmup = self.options.config.zoom.detector.warmup_frames;
        self.first_good_frame.is_none_or(|f| t < f + warmup)
    }

    /// A zoom the scene does not mark (LSC): the frame's apparent size jumped with the
    /// intrinsics fixed. Only against the frame just before: after lost frames the organ may
    /// simply be elsewhere, and a lost stretch must not turn into a change of intrinsics.
    fn zoom_starts(&mut self, t: usize, fit: &FrameFit) -> bool {
        if self.is_lost(fit) {
            return false;
        }
        self.centre_after_good_frame(t)
            .is_some_and(|centre| self.zoom.fires(&self.good, &fit.state, centre))
    }

    /// After `reinit_after_lost` lost frames in a row the organ may be back somewhere else:
    /// it is placed afresh, keeping the shape and intrinsics learnt before the loss. Returns the
    /// frame's fit and whether it is lost.
    fn placed_afresh_if_lost(
        &mut self,
        t: usize,
        views: &mut [ViewProbabilities],
        fit: FrameFit,
        refused: &mut Vec<&'static str>,
    ) -> (FrameFit, bool) {
        if !self.is_lost(&fit) {
            self.lost_run = 0;
            return (fit, false);
        }
        self.lost_run += 1;
        let config = &self.options.config;
        if !self
            .lost_run
            .is_multiple_of(config.tracking.reinit_after_lost.max(1))
        {
            return (fit, true);
        }
        let affine = match super::init::automatic_pose(
            self.scene,
            self.ctx.model,
            self.appearance,
            config,
            t,
            super::init::Placing::Recovery,
            self.cancel,
        ) {
            Ok(affine) => affine,
            Err(e) => {
                // Expected while the organ is out of view; the frame stays lost.
                log::debug!("frame {t}: no fresh placement: {e}");
                return (fit, true);
            }
        };
        let restart = FitState {
            affine,
            ..self.good.clone()
        };
        let again = self.fit(
            views,
            &restart,
            &self.options.params(Phase::FirstFrame, Zoom::Off),
        );
        if self.is_lost(&again) {
            return (fit, true);
        }
        // A placement is a guess from one frame; one that puts the organ centimetres from
        // where it was a few frames ago found something else.
        let centre = |s: &FitState| {
            self.ctx
                .rotation_centre(s, &self.ctx.model.deformed(&s.shape))
        };
        // Only against a pose that was tracked (not the start, which may itself be the wrong
        // guess), and more leeway the longer the organ was out of sight (per second lost).
        let jump = (centre(&again.state) - centre(&self.good)).length();
        let lost_s = (t.saturating_sub(self.good_frame)) as f64 / self.scene.fps.max(1.0);
        let limit = config.tracking.reinit_max_jump_mm * (1.0 + lost_s);
        if !self.first && jump > limit {
            log::info!("frame {t}: fresh placement {jump:.0} mm from the last good pose refused");
            refused.push(crate::scene::trajectory::PLACEMENT_REFUSED);
            return (fit, true);
        }
        self.lost_run = 0;
        (again, false)
    }
}

/// Tracks `options.frames` from `start`, handing each frame to `on_frame` as it finishes.
pub fn track(
    scene: &Scene,
    model: &Model,
    appearance: &Appearance,
    start: FitState,
    options: &TrackOptions,
    cancel: Option<&AtomicBool>,
    on_frame: &mut dyn FnMut(TrackedFrame) -> Result<(), Error>,
) -> Result<(), Error> {
    let classes = ClassMap::from_scene(scene);
    let mut tracker = FrameTracker {
        ctx: FrameContext::new(model, scene),
        scene,
        appearance,
        options,
        cancel,
        good: start,
        good_frame: options.frames.0,
        first: true,
        first_good_frame: None,
        lost_run: 0,
        motion: MotionHistory::new(options.config.zoom.motion),
        zoom: ZoomDetector::new(options.config.zoom.detector),
        depth_zoom: ZoomDetector::new(options.config.zoom.detector),
        regions: Vec::new(),
        zoom_history: ZoomHistory::None,
    };
    for t in options.frames.0..=options.frames.1 {
        tracker.cancelled()?;
        let frames: Vec<_> = (0..scene.cameras.len())
            .map(|c| scene.frame(c, t))
            .collect::<Result<_, _>>()?;
        let started = std::time::Instant::now();
        super::profile::frame_started();
        // Levels 0 to the coarsest the first frame starts at.
        let levels = options.fit_level() + options.config.first_frame.coarser_levels + 1;
        let mut views: Vec<ViewProbabilities> =
            super::profile::time(super::profile::Phase::Pyramid, || {
                frames
                    .into_iter()
                    .enumerate()
                    .map(
                        |(c, f)| match truth_probabilities(scene, c, t, &classes.labels, levels) {
                            Some(view) => view.with_frame(f),
                            None => ViewProbabilities::new(f, levels, classes.len()),
                        },
                    )
                    .collect()
            });
        let Outcome {
            fit,
            state,
            lost,
            depth_explains_zoom,
            zoom_uncertain,
            zoom_corrected,
            refused,
        } = crate::pool::on_workers(|| tracker.frame(t, &mut views))?;
        if zoom_uncertain {
            tracker.zoom_history = tracker
                .zoom_history
                .after_zoom_frame(zoom_corrected, &tracker.regions);
        }
        if let (false, Some(info)) = (lost, &fit.information) {
            tracker.regions = hidden_regions(
                &tracker.ctx,
                &state,
                info,
                fit.confidence,
                tracker.zoom_history,
                &options.config.hidden_region,
            );
            tracker.zoom_history = tracker.zoom_history.with_reference(&tracker.regions);
        }
        let elapsed = started.elapsed();
        super::profile::frame_done(t == options.frames.0, elapsed, fit.lines);
        let ms = elapsed.as_secs_f64() * 1e3;
        // The outputs and what the caller does with them, timed apart from the fit.
        let counted = t != options.frames.0;
        let outputs_started = std::time::Instant::now();
        let Rendered {
            mut labels,
            hidden,
            centroids,
        } = super::profile::outside(super::profile::Phase::OutputRasters, counted, || {
            render_state(scene, model, &state)
        });
        let hidden_regions = if lost {
            super::hidden_region::widened_when_lost(
                &tracker.regions,
                t.saturating_sub(tracker.good_frame),
                &options.config.hidden_region,
            )
        } else {
            tracker.regions.clone()
        };
        let hidden_regions = super::hidden_region::with_margins(model, &state, hidden_regions);
        let region_masks =
            super::profile::outside(super::profile::Phase::RegionMasks, counted, || {
                region_masks(&cameras_of(scene, &state), &hidden, &hidden_regions)
            });
        super::profile::outside(super::profile::Phase::Occluders, counted, || {
            labels
                .par_iter_mut()
                .zip(views.par_iter_mut())
                .for_each(|(l, view)| {
                    mask_occluders(
                        l,
                        view,
                        appearance,
                        options.fit_level(),
                        &options.config.tracking,
                    )
                })
        });
        if counted {
            super::profile::add(super::profile::Phase::Outputs, outputs_started.elapsed());
        }
        let frame = TrackedFrame {
            frame: t,
            state,
            energy: fit.energy,
            iterations: fit.iterations,
            ms,
            // Reported lower where depth stood in for a zoom (losing the frame is decided on
            // the fit's own confidence).
            confidence: if depth_explains_zoom {
                fit.confidence * options.config.tracking.depth_zoom_confidence
            } else {
                fit.confidence
            },
            lost,
            depth_explains_zoom,
            refused,
            labels,
            hidden,
            centroids,
            hidden_regions,
            region_masks,
        };
        super::profile::outside(super::profile::Phase::Record, counted, || on_frame(frame))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::probability::ViewProbabilities;
    use crate::synth::{SynthOptions, memory_scene};

    /// The fit alone, against ground truth: probabilities made from the true labels, a start
    /// 5 mm and 5° off; every visible structure must be found and the hidden tumour placed.
    #[test]
    fn fit_recovers_the_phantom_from_true_probabilities() {
        let scene = memory_scene(&SynthOptions {
            frames: 1,
            width: 320,
            height: 180,
            noise: 0.0,
            tools: false,
            zoom: false,
            ..SynthOptions::default()
        })
        .unwrap();
        let appearance = Appearance::for_tests(&scene, 2);
        let model = Model::build(&scene).unwrap();
        let classes = ClassMap::from_scene(&scene);
        let ctx = FrameContext::new(&model, &scene);
        let truth = &scene.ground_truth.trajectory.as_ref().unwrap().frames[0];
        let start = initial_state(&scene, &model, scene.initial_pose.unwrap());
        let mut views: Vec<ViewProbabilities> = (0..2)
            .map(|c| {
                ViewProbabilities::from_labels(
                    &scene.ground_truth_labels(c, 0).unwrap().unwrap(),
                    &classes.labels,
                    3,
                    0.9,
                )
            })
            .collect();
        let options = TrackOptions::new(Mode::LS, (0, 0), scene.cameras[0].width);
        let before = render_state(&scene, &model, &start);
        let fit = fit_frame(
            &ctx,
            &start,
            &start,
            &mut views,
            Some(&appearance),
            &options.params(Phase::FirstFrame, Zoom::Off),
        );
        let after = render_state(&scene, &model, &fit.state);
        let error = |r: &Rendered, name: &str| {
            r.centroids
                .iter()
                .find(|(n, _)| n == name)
                .map(|(_, c)| (*c - DVec3::from_array(truth.centroids[name])).length())
                .unwrap()
        };
        for c in 0..2 {
            let gt = scene.ground_truth_labels(c, 0).unwrap().unwrap();
            for label in [1u8, 2] {
                let d = crate::plane::dice(&after.labels[c].mask_of(label), &gt.mask_of(label))
                    .unwrap();
                assert!(d > 0.93, "camera {c} label {label}: Dice {d}");
            }
        }
        let (e0, e1) = (error(&before, "tumour_endo"), error(&after, "tumour_endo"));
        assert!(
            e1 < e0 && e1 < 6.0,
            "hidden tumour centroid error {e0:.2} mm → {e1:.2} mm"
        );
        assert!(fit.confidence > 0.7, "confidence {}", fit.confidence);
    }
}
