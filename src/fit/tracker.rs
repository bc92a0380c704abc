//! Frame-to-frame tracking: warm start from the previous frame, per-frame confidence, and
//! tracking loss. When confidence collapses (organ covered or out of view) the last good pose
//! is held and the frame marked lost; shape and intrinsics learnt before are never updated from
//! a lost frame, and fitting resumes from the last good state when the organ returns. Inside a
//! zoom (marked in the scene, or detected by [`super::zoom`] in LSC) the intrinsics are
//! corrected while the pose is held where its motion before the zoom carries it
//! ([`super::motion`]).

use super::context::FrameContext;
use super::model::Model;
use super::motion::MotionHistory;
use super::optimizer::{FitParams, FrameFit, Mode, fit_frame};
use super::probability::ViewProbabilities;
use super::state::FitState;
use super::zoom::ZoomDetector;
use crate::appearance::{Appearance, ClassMap};
use crate::error::Error;
use crate::geometry::{Affine, Camera};
use crate::plane::{LabelImage, Mask};
use crate::render::raster::{RasterOptions, rasterize};
use crate::scene::Scene;
use glam::DVec3;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// Camera correction stays on this many frames after a marked zoom change ends: the
/// estimate lags the optics by a frame. Measured on three phantoms (seeds 1, 7, 11): one
/// frame gave hidden-tumour errors 1.62 / 2.98 / 2.39 mm, two frames 1.62 / 3.03 / 2.40 mm
/// (the focal length drifts along its ambiguity with depth once the optics stop).
pub const ZOOM_SETTLE_FRAMES: usize = 1;
/// Pose damping inside a marked zoom when the intrinsics are not corrected (R, L, LS), relative
/// to elsewhere: the affine then stands in for the zoom. Measured LS Dice on seeds 23 / 20 / 5:
/// 0.914 / 0.941 / 0.938 at 1, 0.933 / 0.969 / 0.946 at 0.3, 0.936 / 0.970 / 0.947 at 0.1, and
/// no better at 0.03.
pub const ZOOM_POSE_DAMPING_WITHOUT_CAMERAS: f64 = 0.1;
/// Tracked frames before a detected zoom that are not trusted for the pose's motion: a zoom
/// starts slowly, and its first frames stay under the detector's threshold.
const ZOOM_ONSET_FRAMES: usize = 2;
/// After this many lost frames in a row (and every as many after), try placing the model
/// afresh.
pub const REINIT_AFTER_LOST: usize = 3;
/// The pyramid level tracking fits at: the coarsest whose width stays at least 400 px.
pub fn fit_level(width: u32) -> usize {
    let mut level = 0;
    while level < 3 && (width >> (level + 1)) >= 400 {
        level += 1;
    }
    level
}

/// Too few lines or too little confidence: the organ is not where the fit put it.
fn is_lost(fit: &super::optimizer::FrameFit) -> bool {
    fit.confidence < LOST_CONFIDENCE || fit.lines < 12
}

/// Below this confidence a frame counts as lost.
pub const LOST_CONFIDENCE: f64 = 0.25;

#[derive(Debug, Clone)]
pub struct TrackOptions {
    pub mode: Mode,
    /// Inclusive frame range.
    pub frames: (usize, usize),
    /// Fit settings of the first frame (coarse to fine from the initial pose).
    pub first: FitParams,
    /// Fit settings of later frames (warm started).
    pub next: FitParams,
}

impl TrackOptions {
    /// Settings for a video `width` pixels wide: frames are fitted at the pyramid level
    /// whose width is nearest 400–800 px (measured: at 960×540, fitting at 480×270 gave the
    /// same Dice and hidden-tumour error as full resolution in a third of the time); the first
    /// frame comes down to it from two levels coarser.
    pub fn new(mode: Mode, frames: (usize, usize), width: u32) -> Self {
        let finest = fit_level(width);
        Self {
            mode,
            frames,
            // The initial pose is only a rough guess: hold it lightly.
            first: FitParams {
                mode,
                levels: vec![finest + 2, finest + 1, finest],
                rounds: 3,
                // Eight steps per block: with three, depth was still 3–4 mm off after the
                // first frame and took seven frames to settle (hidden-tumour error +0.1 mm).
                steps: 8,
                pose_damping: 0.1,
                // The initial pose may be centimetres off in depth: search disparities widely.
                stereo: super::stereo::StereoParams {
                    search_px: 12,
                    ..Default::default()
                },
                ..FitParams::default()
            },
            next: FitParams {
                mode,
                levels: vec![finest],
                rounds: 1,
                steps: 3,
                // One set of lines serves both blocks of a tracked frame: the warm start moves
                // the model by a pixel or two (measured: same Dice, LS 3.5 ms faster).
                rebuild_every: 6,
                // Frame after frame the shape held 4× firmer than on the first frame: with the
                // first frame's weak prior, a mode drifted towards its ±3σ limit over a dozen
                // frames and depth compensated (hidden tumour 3.16 mm on seed 7); with this one
                // 2.61 / 2.73 / 2.86 mm on seeds 1, 7, 11 (LSC) and LS Dice equal or higher.
                shape_prior: 8.0,
                ..FitParams::default()
            },
        }
    }

    /// Lets `cancel` stop the fit between steps as well as between frames.
    pub fn with_cancel(mut self, cancel: Option<Arc<AtomicBool>>) -> Self {
        self.first.cancel = cancel.clone();
        self.next.cancel = cancel;
        self
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
    /// Front-most visible structure per pixel, per camera.
    pub labels: Vec<LabelImage>,
    /// Each hidden structure's projection per camera (occlusion ignored).
    pub hidden: Vec<(String, Vec<Mask>)>,
    /// Vertex means of every structure's fitted mesh, camera-0 coordinates (mm).
    pub centroids: Vec<(String, DVec3)>,
}

/// Pixels this far inside a silhouette (px) are checked: nearer the edge the forest's own
/// uncertainty would nibble at a correct contour.
const OCCLUDER_MARGIN_PX: f32 = 3.0;

/// Removes from the label image the pixels inside a fitted structure that the forest sees as
/// background or tools: an instrument crossing the kidney hides it there. The hidden
/// structures' masks are left whole (they ignore occlusion by definition).
fn mask_occluders(
    labels: &mut LabelImage,
    view: &mut ViewProbabilities,
    appearance: &Appearance,
    level: usize,
) {
    if view.level_count() <= level {
        return;
    }
    let inside = crate::render::squared_edt(&labels.map(|&l| l == 0));
    let (lw, lh) = view.size(level);
    let scale = 1usize << level;
    let coarse = |i: usize| -> u32 {
        let (x, y) = ((i % labels.width) / scale, (i / labels.width) / scale);
        (y.min(lh - 1) * lw + x.min(lw - 1)) as u32
    };
    let candidates: Vec<usize> = (0..labels.data.len())
        .filter(|&i| {
            labels.data[i] != 0 && inside.data[i] >= OCCLUDER_MARGIN_PX * OCCLUDER_MARGIN_PX
        })
        .collect();
    let pixels: Vec<u32> = candidates.iter().map(|&i| coarse(i)).collect();
    view.ensure(appearance, level, &pixels);
    for (&i, &c) in candidates.iter().zip(&pixels) {
        if view.get(level, c, 0) > 0.6 {
            labels.data[i] = 0;
        }
    }
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
    let labels = cams
        .iter()
        .map(|c| rasterize(c, &objects, &RasterOptions::default()).label_image(&labels_of))
        .collect();
    let hidden = (0..model.structures.len())
        .filter(|&i| !model.structures[i].visible)
        .map(|i| {
            let obj = model.objects(&posed, &[i]);
            (
                model.structures[i].name.clone(),
                cams.iter()
                    .map(|c| rasterize(c, &obj, &RasterOptions::default()).coverage())
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
    lost_run: usize,
    /// Poses of frames fitted with fixed intrinsics: their motion carries the pose through a
    /// zoom.
    motion: MotionHistory,
    zoom: ZoomDetector,
}

/// One frame's fit and what the tracker made of it.
struct Outcome {
    fit: FrameFit,
    /// The fit's state, or the last good one where the frame is lost.
    state: FitState,
    lost: bool,
}

impl<'a> FrameTracker<'a> {
    /// Err(Cancelled) once the user cancelled: a fit cut short is not a result.
    fn cancelled(&self) -> Result<(), Error> {
        if self.cancel.is_some_and(|c| c.load(Ordering::Relaxed)) {
            Err(Error::Cancelled)
        } else {
            Ok(())
        }
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
        correct_cameras: bool,
    ) -> FrameFit {
        fit_frame(
            &self.ctx,
            anchor,
            anchor,
            views,
            self.appearance,
            params,
            correct_cameras,
        )
    }

    /// Fits frame `t`: camera correction inside marked (or detected) zooms, a fresh placement
    /// after a lost stretch, and the bookkeeping of what the next frame starts from.
    fn frame(&mut self, t: usize, views: &mut [ViewProbabilities]) -> Result<Outcome, Error> {
        let options = self.options;
        let params = if self.first {
            &options.first
        } else {
            &options.next
        };
        let in_zoom = (0..=ZOOM_SETTLE_FRAMES).any(|k| t >= k && self.scene.in_zoom_change(t - k));
        if in_zoom {
            self.zoom.reset();
        }
        let mut correct_cameras = options.mode == Mode::LSC && (in_zoom || self.zoom.active());
        // Without camera correction (R, L, LS) the pose is all that can follow a zoom: it
        // must move as fast as the image changes.
        let zoom_params;
        let params = if in_zoom && !correct_cameras {
            zoom_params = FitParams {
                pose_damping: params.pose_damping * ZOOM_POSE_DAMPING_WITHOUT_CAMERAS,
                ..params.clone()
            };
            &zoom_params
        } else {
            params
        };
        let anchor = if correct_cameras {
            self.carried(t)
        } else {
            self.good.clone()
        };
        let mut fit = self.fit(views, &anchor, params, correct_cameras);
        self.cancelled()?;
        if options.mode == Mode::LSC && !correct_cameras && self.zoom_starts(t, &fit) {
            // The frames just before held the zoom's onset, taken for motion.
            self.motion.forget_latest(ZOOM_ONSET_FRAMES);
            fit = self.fit(views, &self.carried(t), params, true);
            correct_cameras = true;
            self.cancelled()?;
        } else if correct_cameras && !in_zoom && !is_lost(&fit) {
            self.zoom.corrected(&self.good, &fit.state);
        }
        let (fit, lost) = self.placed_afresh_if_lost(t, views, fit);
        // A lost frame keeps the last good state: nothing learnt from it.
        let state = if lost {
            self.motion.clear();
            self.zoom.reset();
            self.good.clone()
        } else {
            self.good = fit.state.clone();
            self.good_frame = t;
            self.first = false;
            if !correct_cameras {
                self.motion.push(t, self.good.affine);
            }
            fit.state.clone()
        };
        Ok(Outcome { fit, state, lost })
    }

    /// A zoom the scene does not mark (LSC): the frame's apparent size jumped with the
    /// intrinsics fixed. Only against the frame just before: after lost frames the organ may
    /// simply be elsewhere, and a lost stretch must not turn into a change of intrinsics.
    fn zoom_starts(&mut self, t: usize, fit: &FrameFit) -> bool {
        if self.first || self.good_frame + 1 != t || is_lost(fit) {
            return false;
        }
        let model = self.ctx.model;
        let centre = self.ctx.model_centre(&model.deformed(&self.good.shape));
        self.zoom.fires(&self.good, &fit.state, centre)
    }

    /// After [`REINIT_AFTER_LOST`] lost frames in a row the organ may be back somewhere else:
    /// it is placed afresh, keeping the shape and intrinsics learnt before the loss. Returns the
    /// frame's fit and whether it is lost.
    fn placed_afresh_if_lost(
        &mut self,
        t: usize,
        views: &mut [ViewProbabilities],
        fit: FrameFit,
    ) -> (FrameFit, bool) {
        if !is_lost(&fit) {
            self.lost_run = 0;
            return (fit, false);
        }
        self.lost_run += 1;
        if !self.lost_run.is_multiple_of(REINIT_AFTER_LOST) {
            return (fit, true);
        }
        let Ok(affine) =
            super::init::automatic_pose(self.scene, self.ctx.model, self.appearance, t)
        else {
            return (fit, true);
        };
        let restart = FitState {
            affine,
            ..self.good.clone()
        };
        let again = self.fit(views, &restart, &self.options.first, false);
        if is_lost(&again) {
            (fit, true)
        } else {
            self.lost_run = 0;
            (again, false)
        }
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
        lost_run: 0,
        motion: MotionHistory::default(),
        zoom: ZoomDetector::default(),
    };
    for t in options.frames.0..=options.frames.1 {
        tracker.cancelled()?;
        let frames: Vec<_> = (0..scene.cameras.len())
            .map(|c| scene.frame(c, t))
            .collect::<Result<_, _>>()?;
        let started = std::time::Instant::now();
        let levels = fit_level(scene.cameras[0].width) + 3;
        let mut views: Vec<ViewProbabilities> =
            super::profile::time(super::profile::Phase::Pyramid, || {
                frames
                    .into_iter()
                    .map(|f| ViewProbabilities::new(f, levels, classes.len()))
                    .collect()
            });
        let Outcome { fit, state, lost } = tracker.frame(t, &mut views)?;
        let ms = started.elapsed().as_secs_f64() * 1e3;
        let Rendered {
            mut labels,
            hidden,
            centroids,
        } = render_state(scene, model, &state);
        for (l, view) in labels.iter_mut().zip(views.iter_mut()) {
            mask_occluders(l, view, appearance, fit_level(scene.cameras[0].width));
        }
        on_frame(TrackedFrame {
            frame: t,
            state,
            energy: fit.energy,
            iterations: fit.iterations,
            ms,
            confidence: fit.confidence,
            lost,
            labels,
            hidden,
            centroids,
        })?;
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
            &appearance,
            &options.first,
            false,
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
