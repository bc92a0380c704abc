//! Frame-to-frame tracking: warm start from the previous frame, per-frame confidence, and
//! tracking loss. When confidence collapses (organ covered or out of view) the last good pose
//! is held and the frame marked lost; shape and intrinsics learnt before are never updated from
//! a lost frame, and fitting resumes from the last good state when the organ returns.

use super::energy::{FitState, FrameContext};
use super::model::Model;
use super::optimizer::{FitParams, Mode, fit_frame};
use super::probability::ViewProbabilities;
use crate::appearance::{Appearance, ClassMap};
use crate::error::Error;
use crate::geometry::{Affine, Camera};
use crate::plane::{LabelImage, Mask};
use crate::render::raster::{RasterOptions, RenderObject, rasterize};
use crate::scene::Scene;
use glam::DVec3;
use std::sync::atomic::{AtomicBool, Ordering};

/// Below this confidence a frame counts as lost.
pub const LOST_CONFIDENCE: f64 = 0.25;
/// Pyramid levels built per frame.
const LEVELS: usize = 3;

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
    pub fn new(mode: Mode, frames: (usize, usize)) -> Self {
        Self {
            mode,
            frames,
            // The initial pose is only a rough guess: hold it lightly.
            first: FitParams {
                mode,
                levels: vec![2, 1, 0],
                rounds: 3,
                pose_damping: 0.1,
                ..FitParams::default()
            },
            next: FitParams {
                mode,
                levels: vec![1, 0],
                rounds: 1,
                steps: 3,
                ..FitParams::default()
            },
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
    /// Front-most visible structure per pixel, per camera.
    pub labels: Vec<LabelImage>,
    /// Each hidden structure's projection per camera (occlusion ignored).
    pub hidden: Vec<(String, Vec<Mask>)>,
    /// Vertex means of every structure's fitted mesh, camera-0 coordinates (mm).
    pub centroids: Vec<(String, DVec3)>,
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
    let visible: Vec<usize> = (0..model.structures.len())
        .filter(|&i| model.structures[i].visible)
        .collect();
    let labels_of: Vec<u8> = visible.iter().map(|&i| model.structures[i].label).collect();
    let objects: Vec<RenderObject> = visible
        .iter()
        .map(|&i| RenderObject {
            vertices: &posed[i],
            faces: &model.structures[i].faces,
        })
        .collect();
    let labels = cams
        .iter()
        .map(|c| rasterize(c, &objects, &RasterOptions::default()).label_image(&labels_of))
        .collect();
    let hidden = (0..model.structures.len())
        .filter(|&i| !model.structures[i].visible)
        .map(|i| {
            let obj = [RenderObject {
                vertices: &posed[i],
                faces: &model.structures[i].faces,
            }];
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

/// Tracks `options.frames` from `start`, handing each frame to `on_frame` as it finishes.
pub fn track(
    scene: &Scene,
    appearance: &Appearance,
    start: FitState,
    options: &TrackOptions,
    cancel: Option<&AtomicBool>,
    on_frame: &mut dyn FnMut(TrackedFrame) -> Result<(), Error>,
) -> Result<(), Error> {
    let model = Model::from_scene(scene);
    let classes = ClassMap::from_scene(scene);
    let class_of: Vec<Option<usize>> = scene
        .structures
        .iter()
        .map(|s| {
            if s.visible {
                classes.class_of_label(s.label)
            } else {
                None
            }
        })
        .collect();
    let mut good = start;
    let mut first = true;
    for t in options.frames.0..=options.frames.1 {
        if cancel.is_some_and(|c| c.load(Ordering::Relaxed)) {
            return Err(Error::Cancelled);
        }
        let frames: Vec<_> = (0..scene.cameras.len())
            .map(|c| scene.frame(c, t))
            .collect::<Result<_, _>>()?;
        let started = std::time::Instant::now();
        let mut views: Vec<ViewProbabilities> = frames
            .into_iter()
            .map(|f| ViewProbabilities::new(f, LEVELS, classes.len()))
            .collect();
        let ctx = FrameContext {
            model: &model,
            cameras: &scene.cameras,
            class_of: class_of.clone(),
        };
        let params = if first { &options.first } else { &options.next };
        let correct_cameras = options.mode == Mode::LSC && scene.in_zoom_change(t);
        let fit = fit_frame(
            &ctx,
            &good,
            &good,
            &mut views,
            appearance,
            params,
            correct_cameras,
        );
        let lost = fit.confidence < LOST_CONFIDENCE || fit.lines < 12;
        // A lost frame keeps the last good state: nothing learnt from it.
        let state = if lost {
            good.clone()
        } else {
            fit.state.clone()
        };
        if !lost {
            good = fit.state.clone();
            first = false;
        }
        let ms = started.elapsed().as_secs_f64() * 1e3;
        let Rendered {
            labels,
            hidden,
            centroids,
        } = render_state(scene, &model, &state);
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
