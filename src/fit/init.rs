//! Where a run starts. Automatic initialisation when a scene gives no `initial_pose`: the
//! forest's probability maps of the first frame locate the organ (centroid and area in every
//! view); orientation
//! hypotheses (60 view directions × 12 rolls) are placed on the centroid's ray at the depth their
//! silhouette area implies, moved so that their silhouette's centroid falls on the region's,
//! and scored by soft overlap with the forest's foreground in all views;
//! the best few are refined by a coarse rigid fit and the most confident, per structure, wins;
//! where a run starts, the winner is also turned ±20° about each camera axis and refined again
//! (the refinement can stop short of the truth as a kidney turns about its long axis).
//! The paper needed a rough manual placement; this needs none. A pose a scene gives is
//! polished the same way before its first frame is fitted ([`polished_pose`]): from 10° off,
//! the fit can settle in a basin of its own several degrees from the truth.

use super::config::{FitConfig, FitParams, Mode, Phase, Zoom};
use super::context::FrameContext;
use super::model::Model;
use super::optimizer::{FrameFit, fit_frame};
use super::probability::ViewProbabilities;
use crate::appearance::features::downsample;
use crate::appearance::{Appearance, ClassMap};
use crate::error::{Error, InputError, stop_if_cancelled};
use crate::geometry::pose::{rotation_apart_deg, rotation_from_vector};
use crate::geometry::{Affine, Camera};
use crate::plane::Plane;
use crate::render::raster::{RasterOptions, ViewRaster, rasterize};
use crate::scene::Scene;
use glam::{DMat3, DVec2, DVec3};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

/// A rough pose to start placing the model by hand: the preoperative orientation unchanged, the
/// organ's centre on camera 0's axis at the depth where it spans about 40 % of the image's
/// width. Not a fit: nothing in the images is looked at, so the app shows it as not fitted, and
/// no scene is written with it as its `initial_pose` (`new-scene` did: a run polished from it
/// fitted a turned kidney with nothing flagging it, Dice 0.31 where automatic placement gave
/// 0.97). `vertices` are the organ's, in the preoperative frame.
pub fn in_front_of_camera(camera: &Camera, vertices: &[DVec3]) -> Affine {
    let centre = crate::geometry::mesh::vertex_mean(vertices);
    let (lo, hi) = vertices.iter().fold(
        (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
        |(lo, hi), &v| (lo.min(v), hi.max(v)),
    );
    let extent = (hi - lo).max_element();
    let extent = if extent.is_finite() && extent > 0.0 {
        extent
    } else {
        100.0
    };
    let depth = camera.intrinsics.fx * extent / (0.4 * camera.width as f64);
    Affine::from_linear_translation(
        DMat3::IDENTITY,
        DVec3::new(-centre.x, -centre.y, depth - centre.z),
    )
}

/// Unit directions spread over the sphere (Fibonacci lattice).
fn directions(n: usize) -> Vec<DVec3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - y * y).sqrt();
            DVec3::new(
                r * (golden * i as f64).cos(),
                y,
                r * (golden * i as f64).sin(),
            )
        })
        .collect()
}

/// Rotation taking +z to `d`.
fn align_z(d: DVec3) -> DMat3 {
    let axis = DVec3::Z.cross(d);
    let s = axis.length();
    let c = DVec3::Z.dot(d);
    if s < 1e-9 {
        return if c > 0.0 {
            DMat3::IDENTITY
        } else {
            rotation_from_vector(DVec3::X * std::f64::consts::PI)
        };
    }
    rotation_from_vector(axis / s * s.atan2(c))
}

/// Per view: the probability of any structure (1 − P(background)), then of each class.
fn class_planes(appearance: &Appearance, frame: &image::RgbImage) -> (Plane<f32>, Vec<Plane<f32>>) {
    // Per pixel, as the placement was tuned (smoothed maps are for showing labels).
    let maps = appearance.classify_frame_per_pixel(frame);
    let planes: Vec<Plane<f32>> = (0..maps.classes).map(|k| maps.class_plane(k)).collect();
    (planes[0].map(|&p| 1.0 - p), planes)
}

/// Mean pixel position of a mask's set pixels; None where none is set.
fn centroid_px(mask: &Plane<bool>) -> Option<DVec2> {
    let (mut sum, mut n) = (DVec2::ZERO, 0usize);
    for (i, _) in mask.data.iter().enumerate().filter(|(_, m)| **m) {
        sum += DVec2::new((i % mask.width) as f64, (i / mask.width) as f64);
        n += 1;
    }
    (n > 0).then(|| sum / n as f64)
}

/// `affine` moved across camera 0's axis so that a silhouette seen `offset_px` from where it
/// should be, when the model stood at depth `seen_at_mm`, comes back there at any depth: the
/// offset is one of the model's own millimetres (offset × depth / f), which it keeps however
/// far it is placed.
fn shifted_across(
    affine: &Affine,
    offset_px: DVec2,
    seen_at_mm: f64,
    k: &crate::geometry::Intrinsics,
) -> Affine {
    let shift = DVec3::new(
        -offset_px.x * seen_at_mm / k.fx,
        -offset_px.y * seen_at_mm / k.fy,
        0.0,
    );
    Affine::from_linear_translation(affine.linear(), affine.translation_mm() + shift)
}

fn soft_iou(prob: &Plane<f32>, silhouette: &Plane<bool>) -> f64 {
    let (mut inter, mut sp, mut ss) = (0.0, 0.0, 0.0);
    for (&p, &s) in prob.data.iter().zip(&silhouette.data) {
        sp += p as f64;
        if s {
            ss += 1.0;
            inter += p as f64;
        }
    }
    inter / (sp + ss - inter).max(1e-9)
}

/// `affine` followed by the rotation `turn` (axis × angle, camera coordinates) about the
/// camera-space point `centre`.
pub fn turned_about(affine: &Affine, centre: DVec3, turn: DVec3) -> Affine {
    let r = rotation_from_vector(turn);
    Affine::from_linear_translation(
        r * affine.linear(),
        r * affine.translation_mm() + (centre - r * centre),
    )
}

/// What a placement is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Placing {
    /// The pose a run starts from: the winner is polished (`PlacementConfig::polish_deg`).
    Start,
    /// A fresh placement after lost frames, which the video waits for: no polishing.
    Recovery,
}

/// Estimates the pose of frame `t` from the forest alone, with `config.placement`.
/// Err(Cancelled) once `cancel` is set (read between hypotheses and between refinements).
pub fn automatic_pose(
    scene: &Scene,
    model: &Model,
    appearance: &Appearance,
    config: &FitConfig,
    t: usize,
    placing: Placing,
    cancel: Option<&AtomicBool>,
) -> Result<Affine, Error> {
    let placement = &config.placement;
    let mut refiner = Refiner::new(scene, model, appearance, config, t, cancel)?;
    let small: Vec<image::RgbImage> = refiner
        .frames
        .iter()
        .map(|f| (0..placement.score_level).fold(f.as_ref().clone(), |img, _| downsample(&img)))
        .collect();
    let (probs, per_class): (Vec<Plane<f32>>, Vec<Vec<Plane<f32>>>) =
        small.iter().map(|f| class_planes(appearance, f)).unzip();
    let classes = ClassMap::from_scene(scene);
    let cams: Vec<Camera> = scene
        .cameras
        .iter()
        .zip(&small)
        .map(|(c, s)| {
            c.at_level(
                &c.intrinsics,
                placement.score_level,
                (s.width() as usize, s.height() as usize),
            )
        })
        .collect();
    let foreground = probs[0].map(|&p| p > 0.5);
    let area = foreground.count() as f64;
    let centre = match centroid_px(&foreground) {
        Some(c) if area >= placement.min_area_px => c,
        _ => return Err(InputError::new(&scene.origin, format!("cannot find the organ in frame {t} to place the model automatically: add seeds, or give an initial_pose")).into()),
    };
    let ray = cams[0].intrinsics.unproject(centre);
    let ray = DVec3::new(ray.x, ray.y, 1.0);
    let (mean, centre_pre) = (&refiner.mean, refiner.centre_pre);
    let visible = model.indices(true);
    let rasters = |affine: &Affine, cams: &[Camera]| -> Vec<ViewRaster> {
        let posed = model.posed(affine, mean);
        let objects = model.objects(&posed, &visible);
        cams.iter()
            .map(|c| rasterize(c, &objects, &RasterOptions::default()))
            .collect()
    };
    // Each visible structure's region against its own class: the exophytic tumour tells a
    // kidney from its mirror image, which the outline alone cannot.
    let score = |rs: &[ViewRaster]| -> f64 {
        let mut total = 0.0;
        let mut n = 0;
        for (m, r) in rs.iter().enumerate() {
            for (oi, &si) in visible.iter().enumerate() {
                let Some(k) = classes.class_of_label(model.structures[si].label) else {
                    continue;
                };
                total += soft_iou(&per_class[m][k], &r.visible_mask(oi as u8));
                n += 1;
            }
        }
        total / n.max(1) as f64
    };
    let place = |rot: DMat3, depth: f64| {
        Affine::from_linear_translation(rot, ray * depth - rot * centre_pre)
    };
    let mut scored: Vec<(f64, Affine)> = Vec::new();
    let centring = placement.silhouette_centring;
    let roll_angle = std::f64::consts::TAU / placement.rolls.max(1) as f64;
    for d in directions(placement.directions) {
        stop_if_cancelled(refiner.cancel)?;
        for roll in 0..placement.rolls {
            let rot = rotation_from_vector(d * (roll as f64 * roll_angle)) * align_z(d);
            // Depth from the area: projected area falls with the square of depth.
            let z_ref = placement.reference_depth_mm;
            let reference = rasters(&place(rot, z_ref), &cams[..1]);
            let covered = reference[0].coverage();
            let a_ref = covered.count() as f64;
            if a_ref < 1.0 {
                continue;
            }
            let depth = z_ref * (a_ref / area).sqrt();
            let mut affine = place(rot, depth);
            if centring > 0.0
                && let Some(c_ref) = centroid_px(&covered)
            {
                // The silhouette's centroid, not the model's centre, on the region's centroid:
                // a large exophytic tumour pulls the one away from the other.
                affine = shifted_across(
                    &affine,
                    (c_ref - centre) * centring,
                    z_ref,
                    &cams[0].intrinsics,
                );
            }
            scored.push((score(&rasters(&affine, &cams)), affine));
        }
    }
    scored.sort_by(|a, b| b.0.total_cmp(&a.0));
    // Refine the best few rigidly at coarse levels; keep the most confident.
    for (_, affine) in scored.into_iter().take(placement.refined) {
        refiner.refine(affine)?;
    }
    // The refinement can stop 15–30° from the truth (a kidney's outline changes little as it
    // turns about its long axis): the winner turned by ± `polish_deg` about each of camera
    // 0's axes, through the model's centre, is refined too.
    if placing == Placing::Start {
        refiner.polish(placement.polish_deg)?;
        refiner.settle_near_ties(NEAR_TIE_CONFIDENCE, NEAR_TIE_APART_DEG, NEAR_TIE_CONTENDERS)?;
    }
    refiner.best.map(|b| b.refined).ok_or_else(|| {
        InputError::new(
            &scene.origin,
            format!("no orientation of the model fits frame {t}: give an initial_pose"),
        )
        .into()
    })
}

/// The pose a run starting at frame `t` fits first: the scene's `initial_pose`, polished
/// ([`polished_pose`]), or without one the automatic placement ([`automatic_pose`]). What
/// `endofuse track` and the app both start from. Err(Cancelled) once `cancel` is set.
pub fn starting_pose(
    scene: &Scene,
    model: &Model,
    appearance: &Appearance,
    config: &FitConfig,
    t: usize,
    cancel: Option<&AtomicBool>,
) -> Result<Affine, Error> {
    match scene.initial_pose {
        Some(given) => polished_pose(scene, model, appearance, config, t, given, cancel),
        None => automatic_pose(scene, model, appearance, config, t, Placing::Start, cancel),
    }
}

/// The scene's `initial_pose` refined as the placement refines its hypotheses, and that
/// refinement turned by ± `placement.initial_polish_deg` about each of camera 0's axes through
/// the model's centre and refined again; the most confident, per structure, wins (the given
/// pose itself, unrefined, where its own refinement does). Fitted as it is, a pose 10° off can
/// stop 9° off, in a basin of its own (a kidney's outline changes little as it turns about
/// some axes). Seven coarse fits, 0.5-0.6 s at 960×540; Err(Cancelled) between two of them
/// once `cancel` is set.
pub fn polished_pose(
    scene: &Scene,
    model: &Model,
    appearance: &Appearance,
    config: &FitConfig,
    t: usize,
    start: Affine,
    cancel: Option<&AtomicBool>,
) -> Result<Affine, Error> {
    let degrees = config.placement.initial_polish_deg;
    if degrees <= 0.0 {
        return Ok(start);
    }
    let mut refiner = Refiner::new(scene, model, appearance, config, t, cancel)?;
    refiner.refine(start)?;
    refiner.polish(degrees)?;
    // The given pose, where no turn of it was more confident: the full fit of the first frame
    // starts from it, as it would unpolished (the coarse rigid fit can move a good pose a few
    // degrees the wrong way).
    Ok(match refiner.best {
        Some(b) if b.start != start => b.refined,
        _ => start,
    })
}

/// Refined poses this close in confidence to the best are a near tie ([`Refiner::settle_near_ties`]).
const NEAR_TIE_CONFIDENCE: f64 = 0.03;
/// ... when at least this far apart in rotation (degrees): a different basin, not the same one.
const NEAR_TIE_APART_DEG: f64 = 30.0;
/// At most this many poses settle a tie (each a first-frame fit, ~0.1–0.3 s).
const NEAR_TIE_CONTENDERS: usize = 3;

/// Which of a [`Refiner`]'s settings a fit runs with.
#[derive(Debug, Clone, Copy)]
enum Settings {
    /// The placement's coarse rigid refinement.
    Placement,
    /// The first frame's own fit, rigid, coarse to fine: what settles a near tie.
    FirstFrame,
}

/// The most confident pose a [`Refiner`] has seen.
#[derive(Debug, Clone, Copy)]
struct Refined {
    /// Per structure (see [`super::optimizer::FrameFit::structure_confidence`]).
    confidence: f64,
    start: Affine,
    refined: Affine,
}

/// Refines poses by the placement's coarse rigid fit on one frame and keeps the most
/// confident, per structure. One set of views serves every pose: a pixel's probabilities
/// depend neither on the pose asking for them nor on the region its features were computed
/// over (`FrameFeatures::valid`), so each pose reuses what the others classified.
struct Refiner<'a> {
    ctx: FrameContext<'a>,
    scene: &'a Scene,
    appearance: &'a Appearance,
    params: FitParams,
    /// The first frame's own fit, rigid: what settles a near tie.
    first_frame: FitParams,
    /// The frame of every view, full resolution.
    frames: Vec<Arc<image::RgbImage>>,
    views: Vec<ViewProbabilities>,
    /// The mean shape (preoperative mm) and its anchor structure's centre, which turns keep.
    mean: Arc<Vec<Vec<DVec3>>>,
    centre_pre: DVec3,
    best: Option<Refined>,
    /// Every pose refined so far, in order.
    seen: Vec<Refined>,
    cancel: Option<&'a AtomicBool>,
}

impl<'a> Refiner<'a> {
    /// Reads frame `t` of every view (an unreadable frame is the caller's error).
    fn new(
        scene: &'a Scene,
        model: &'a Model,
        appearance: &'a Appearance,
        config: &FitConfig,
        t: usize,
        cancel: Option<&'a AtomicBool>,
    ) -> Result<Self, Error> {
        let frames: Vec<Arc<image::RgbImage>> = (0..scene.cameras.len())
            .map(|c| scene.frame(c, t))
            .collect::<Result<_, _>>()?;
        let params = config.resolve(Mode::R, Phase::Placement, Zoom::Off, 0);
        let width = frames.first().map_or(0, |f| f.width());
        let first_frame = config.resolve(
            Mode::R,
            Phase::FirstFrame,
            Zoom::Off,
            config.tracking.fit_level(width),
        );
        // Levels are made on first use: the first frame's, deeper at 960×540, cost nothing
        // until a near tie needs them, and then reuse what the placement classified.
        let pyramid = params
            .levels
            .iter()
            .chain(&first_frame.levels)
            .max()
            .map_or(1, |l| l + 1);
        let classes = ClassMap::from_scene(scene).len();
        let mean = model.deformed(&vec![0.0; model.shape.mode_count()]);
        let centre_pre = crate::geometry::mesh::vertex_mean(&mean[model.anchor]);
        Ok(Refiner {
            ctx: FrameContext::new(model, scene),
            scene,
            appearance,
            views: frames
                .iter()
                .map(|f| ViewProbabilities::new(f.clone(), pyramid, classes))
                .collect(),
            frames,
            params,
            first_frame,
            mean,
            centre_pre,
            best: None,
            seen: Vec::new(),
            cancel,
        })
    }

    /// This frame fitted from `affine` (the mean shape) with the placement's coarse settings
    /// or the first frame's own.
    fn fit_from(&mut self, affine: Affine, settings: Settings) -> Result<FrameFit, Error> {
        stop_if_cancelled(self.cancel)?;
        let start = super::tracker::initial_state(self.scene, self.ctx.model, affine);
        let params = match settings {
            Settings::Placement => &self.params,
            Settings::FirstFrame => &self.first_frame,
        };
        Ok(fit_frame(
            &self.ctx,
            &start,
            &start,
            &mut self.views,
            Some(self.appearance),
            params,
        ))
    }

    fn refine(&mut self, affine: Affine) -> Result<(), Error> {
        let fit = self.fit_from(affine, Settings::Placement)?;
        log::debug!(
            "placement candidate: confidence {:.3} (per structure {:.3}), energy {:.1}, affine \
             {:?}",
            fit.confidence,
            fit.structure_confidence,
            fit.energy,
            fit.state.affine
        );
        // Per structure: over all lines the kidney's outline outvotes the small tumour, and a
        // mirror image whose outline fits a little better won (a 320×180 phantom: confidence
        // 0.734 against 0.709, tumour Dice 0).
        let refined = Refined {
            confidence: fit.structure_confidence,
            start: affine,
            refined: fit.state.affine,
        };
        self.seen.push(refined);
        if self
            .best
            .is_none_or(|b| fit.structure_confidence > b.confidence)
        {
            self.best = Some(refined);
        }
        Ok(())
    }

    /// A near tie settled by the first frame's own fit. The coarse rigid refinement can leave
    /// two orientations far apart within a few hundredths of confidence: on tuning scene 1710
    /// (KiTS case_00204, 480×270, noise 0.10) the right one scored 0.454 and one 141° off
    /// 0.458, and the wrong one won and was tracked at 0.25–0.36 for 30 frames. Fitted
    /// coarse to fine as the first frame is (rigid), they score 0.563 and 0.415. So every
    /// refined pose within `margin` of the best and at least `apart_deg` from each one kept
    /// (at most `most` in all) is fitted so, and the most confident wins.
    fn settle_near_ties(&mut self, margin: f64, apart_deg: f64, most: usize) -> Result<(), Error> {
        let Some(best) = self.best else {
            return Ok(());
        };
        let mut ranked = self.seen.clone();
        ranked.sort_by(|a, b| b.confidence.total_cmp(&a.confidence));
        let mut contenders: Vec<Refined> = vec![best];
        for r in ranked {
            if contenders.len() >= most || r.confidence < best.confidence - margin {
                break;
            }
            if contenders
                .iter()
                .all(|c| rotation_apart_deg(&c.refined, &r.refined) >= apart_deg)
            {
                contenders.push(r);
            }
        }
        if contenders.len() < 2 {
            return Ok(());
        }
        let mut winner: Option<(f64, Refined)> = None;
        for c in contenders {
            let fit = self.fit_from(c.refined, Settings::FirstFrame)?;
            log::debug!(
                "placement near tie: coarse confidence {:.3}, first-frame fit {:.3}",
                c.confidence,
                fit.structure_confidence
            );
            if winner.is_none_or(|(w, _)| fit.structure_confidence > w) {
                winner = Some((fit.structure_confidence, c));
            }
        }
        self.best = winner.map(|(_, c)| c);
        Ok(())
    }

    /// The most confident pose so far turned by ±`degrees` about each of camera 0's axes,
    /// through the model's centre, each refined in turn.
    fn polish(&mut self, degrees: f64) -> Result<(), Error> {
        let Some(winner) = self.best.filter(|_| degrees > 0.0).map(|b| b.refined) else {
            return Ok(());
        };
        let centre = winner.apply(self.centre_pre);
        for axis in [DVec3::X, DVec3::Y, DVec3::Z] {
            for sign in [-1.0, 1.0] {
                let turn = axis * (sign * degrees.to_radians());
                self.refine(turned_about(&winner, centre, turn))?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {

    /// The hand placement's start: the organ's centre on camera 0's axis, its projection about
    /// 40 % of the image wide, the orientation untouched; a degenerate mesh still gives a
    /// finite pose.
    #[test]
    fn in_front_of_camera_centres_the_organ_at_a_fraction_of_the_width() {
        let scene = crate::synth::memory_scene(&crate::synth::SynthOptions {
            frames: 1,
            width: 320,
            height: 180,
            ..crate::synth::SynthOptions::default()
        })
        .unwrap();
        let cam = &scene.cameras[0];
        let mesh = &scene.structures[0].mesh;
        let a = in_front_of_camera(cam, &mesh.vertices);
        assert_eq!(a.linear(), DMat3::IDENTITY);
        let posed: Vec<DVec3> = mesh.vertices.iter().map(|&v| a.apply(v)).collect();
        let centre = crate::geometry::mesh::vertex_mean(&posed);
        assert!(centre.x.abs() < 1e-9 && centre.y.abs() < 1e-9 && centre.z > 0.0);
        let xs: Vec<f64> = posed
            .iter()
            .filter_map(|&p| cam.project(p).map(|q| q.x))
            .collect();
        let span = xs.iter().cloned().fold(f64::MIN, f64::max)
            - xs.iter().cloned().fold(f64::MAX, f64::min);
        let fraction = span / cam.width as f64;
        assert!(
            (0.2..=0.45).contains(&fraction),
            "spans {fraction} of the width"
        );
        let flat = in_front_of_camera(cam, &[DVec3::ONE; 3]);
        assert!(flat.is_finite());
        assert!(in_front_of_camera(cam, &[]).is_finite());
    }
    use super::*;
    use crate::geometry::pose::rotation_to_vector;

    /// A cancel stops the automatic placement and the polish of a given pose (the app's
    /// Initialise and Track wait on them for a second or more): Err(Cancelled), not a pose;
    /// with the flag clear the same calls place the model.
    #[test]
    fn a_cancelled_placement_or_polish_places_nothing() {
        let scene = crate::synth::one_small_frame();
        let model = Model::build(&scene).unwrap();
        let appearance = Appearance::for_tests(&scene, 4);
        let config = FitConfig::default();
        let given = scene
            .initial_pose
            .expect("the phantom gives an initial pose");
        let cancelled = AtomicBool::new(true);
        let place = |cancel| {
            automatic_pose(
                &scene,
                &model,
                &appearance,
                &config,
                0,
                Placing::Start,
                cancel,
            )
        };
        let polish = |cancel| polished_pose(&scene, &model, &appearance, &config, 0, given, cancel);
        assert!(matches!(place(Some(&cancelled)), Err(Error::Cancelled)));
        assert!(matches!(polish(Some(&cancelled)), Err(Error::Cancelled)));
        let clear = AtomicBool::new(false);
        assert!(place(Some(&clear)).is_ok());
        assert!(polish(Some(&clear)).is_ok());
    }

    /// A polishing turn keeps the model's centre where it was, turns the pose by exactly the
    /// angle asked about the axis asked, and leaves its scale and shear alone.
    #[test]
    fn a_polishing_turn_rotates_about_the_centre_by_the_angle_asked() {
        let linear = rotation_from_vector(DVec3::new(0.3, -0.5, 0.2))
            * DMat3::from_diagonal(DVec3::new(1.05, 0.97, 1.01));
        let affine = Affine::from_linear_translation(linear, DVec3::new(4.0, -3.0, 150.0));
        let centre_pre = DVec3::new(2.0, 1.0, -5.0);
        let centre = affine.apply(centre_pre);
        for turn in [
            DVec3::X * 20f64.to_radians(),
            DVec3::Y * -20f64.to_radians(),
            DVec3::Z * 35f64.to_radians(),
        ] {
            let turned = turned_about(&affine, centre, turn);
            assert!((turned.apply(centre_pre) - centre).length() < 1e-9);
            // The turn between the two poses, read back from any point pair.
            let relative = turned.linear() * affine.linear().inverse();
            assert!(
                (rotation_to_vector(relative) - turn).length() < 1e-9,
                "{turn}"
            );
            let p = DVec3::new(-7.0, 9.0, 3.0);
            let (a, b) = (affine.apply(p), turned.apply(p));
            assert!(((b - centre).length() - (a - centre).length()).abs() < 1e-9);
        }
    }

    /// The centring a hypothesis gets, against brute force: a kidney-like sphere beside a
    /// large one (an exophytic tumour) is placed with the model's centre on a pixel's ray,
    /// rastered at the reference depth, moved by [`shifted_across`] and rastered again at the
    /// depth it is placed at: its silhouette's centroid then lies on that pixel (within the
    /// perspective the shift leaves out), where unmoved it was pixels away.
    #[test]
    fn a_centred_hypothesis_puts_its_silhouette_on_the_regions_centroid() {
        use crate::geometry::mesh::{Mesh, icosphere};
        use crate::geometry::{Extrinsics, Intrinsics};
        use crate::render::raster::RenderObject;
        let cam = Camera {
            name: "t".into(),
            width: 120,
            height: 68,
            intrinsics: Intrinsics::pinhole(126.0, 126.0, 59.5, 33.5),
            extrinsics: Extrinsics::default(),
        };
        let sphere = |c: DVec3, r: f64| {
            let s = icosphere(3);
            Mesh::new(s.vertices.iter().map(|&v| c + v * r).collect(), s.faces)
        };
        // The model's centre (the kidney's) at the origin, the tumour beside and before it.
        // Its parallax is what the shift leaves out (the nearer tumour moves more than the
        // kidney): the centred silhouette lands 0.7 px from the pixel at 150 mm (23 px
        // unmoved) and 1.8 px at 200 mm (15 px); the refinement takes the rest. A shift
        // without the reference depth's scaling lands 5.1 px off at 150 mm, one the wrong
        // way round 33 px (both tried).
        let meshes = [
            sphere(DVec3::ZERO, 30.0),
            sphere(DVec3::new(38.0, -14.0, -25.0), 28.0),
        ];
        let raster = |a: &Affine| {
            let posed: Vec<Vec<DVec3>> = meshes
                .iter()
                .map(|m| m.vertices.iter().map(|&v| a.apply(v)).collect())
                .collect();
            let objects: Vec<RenderObject> = posed
                .iter()
                .zip(&meshes)
                .map(|(v, m)| RenderObject {
                    vertices: v,
                    faces: &m.faces,
                    closed: true,
                })
                .collect();
            rasterize(&cam, &objects, &RasterOptions::default()).coverage()
        };
        let target = DVec2::new(52.0, 37.0);
        let ray = cam.intrinsics.unproject(target);
        let ray = DVec3::new(ray.x, ray.y, 1.0);
        let z_ref = 200.0;
        let at = |z: f64| Affine::from_linear_translation(DMat3::IDENTITY, ray * z);
        let seen = centroid_px(&raster(&at(z_ref))).expect("in view");
        assert!((seen - target).length() > 4.0, "the tumour pulls it {seen}");
        for z in [150.0, 200.0] {
            let unmoved = centroid_px(&raster(&at(z))).unwrap();
            let moved = shifted_across(&at(z), seen - target, z_ref, &cam.intrinsics);
            let centred = centroid_px(&raster(&moved)).unwrap();
            assert!(
                (centred - target).length() < 0.15 * (unmoved - target).length()
                    && (centred - target).length() < 3.0,
                "at {z} mm: {centred} against {target} (unmoved {unmoved})"
            );
        }
        assert!(centroid_px(&Plane::filled(4, 3, false)).is_none());
    }
}
