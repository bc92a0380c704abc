//! The paper's synthetic set-up (§IV-A): one virtual kidney seen by M cameras spread around
//! it, each image its projection by eq. 10 (1 inside the silhouette, 0 outside) polluted with
//! additive white Gaussian noise of standard deviation σ, and the fit run on those images alone.
//!
//! The region terms of eq. 4 come from the image model itself: with intensities 0 and 1 and
//! Gaussian noise, the posterior of "kidney" at a pixel of intensity I is the logistic of
//! (I − ½)/σ̂², σ̂ estimated from the image (median absolute difference of neighbours), so the
//! fit knows no more about the noise than the image shows. Chan–Vese ([`super::chan_vese`])
//! gets the same images.

use crate::fit::config::{FitConfig, FitParams, Phase, Zoom};
use crate::fit::probability::ViewProbabilities;
use crate::fit::tracker::{TrackOptions, initial_state, render_state};
use crate::fit::{FitState, FrameContext, Mode, Model, fit_frame};
use crate::geometry::{Affine, Camera, Extrinsics, Intrinsics};
use crate::plane::{Mask, dice};
use crate::rng::Rng;
use crate::scene::{GroundTruth, Scene, Seeds, Structure};
use crate::shape::JointShapeModel;
use glam::{DMat3, DQuat, DVec3};
use std::path::PathBuf;
use std::sync::{Arc, OnceLock};

/// Image size of every virtual camera (px).
pub const WIDTH_PX: u32 = 640;
pub const HEIGHT_PX: u32 = 480;
/// Focal length (px): the 104 mm kidney spans about half the image at [`DISTANCE_MM`].
pub const FOCAL_PX: f64 = 840.0;
/// Distance from every camera to the kidney's centre (mm).
pub const DISTANCE_MM: f64 = 320.0;

/// The virtual kidney (the built-in anatomy's, alone: the paper's synthetic test has one
/// structure) and its joint shape model, built once (the generated catalog costs ~0.3 s).
fn kidney() -> &'static (Structure, JointShapeModel) {
    static KIDNEY: OnceLock<(Structure, JointShapeModel)> = OnceLock::new();
    KIDNEY.get_or_init(|| {
        let structure = Structure {
            name: "kidney".into(),
            label: 1,
            visible: true,
            mesh: crate::synth::anatomy::kidney(),
            catalog: None,
            mesh_path: PathBuf::from("experiments/kidney.obj"),
        };
        let shape = crate::shape::joint_model_of(std::slice::from_ref(&structure))
            .expect("a generated catalog of the built-in kidney always builds");
        (structure, shape)
    })
}

/// Unit vectors from the kidney to each of `views` cameras, spread evenly over the sphere
/// (Fibonacci points) and turned so that camera 0 looks along +z from the origin.
pub fn view_directions(views: usize) -> Vec<DVec3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let points: Vec<DVec3> = (0..views.max(1))
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / views.max(1) as f64;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = i as f64 * golden;
            DVec3::new(r * phi.cos(), r * phi.sin(), z)
        })
        .collect();
    let turn = DQuat::from_rotation_arc(points[0], DVec3::new(0.0, 0.0, -1.0));
    points.iter().map(|&p| (turn * p).normalize()).collect()
}

/// Camera looking at `target` from `target + distance·direction`: its extrinsics map camera-0
/// coordinates into it (eq. 11).
fn camera_towards(name: String, target: DVec3, direction: DVec3, intrinsics: Intrinsics) -> Camera {
    let position = target + DISTANCE_MM * direction;
    let z = -direction;
    let hint = if z.cross(DVec3::Y).length() > 0.1 {
        DVec3::Y
    } else {
        DVec3::X
    };
    let x = hint.cross(z).normalize();
    let y = z.cross(x);
    // Rows x, y, z: p_cam = R (p_ref − position).
    let rotation = DMat3::from_cols(x, y, z).transpose();
    Camera {
        name,
        width: WIDTH_PX,
        height: HEIGHT_PX,
        intrinsics,
        extrinsics: Extrinsics {
            rotation,
            translation_mm: -(rotation * position),
        },
    }
}

/// The fit's configuration in every experiment: the project's defaults, except that the first
/// frame's start is not held (its pose damping is 0). In tracking the start is a guess worth
/// staying near; here it is only the perturbation under test, and holding it biased every fit
/// towards it (4 views, 15° about z: 4.6° left; unheld: 0.3°).
pub fn experiment_config() -> FitConfig {
    let mut config = FitConfig::default();
    config.first_frame.pose_damping = 0.0;
    config
}

/// The intrinsics every virtual camera is calibrated with.
pub fn calibrated_intrinsics() -> Intrinsics {
    Intrinsics::pinhole(
        FOCAL_PX,
        FOCAL_PX,
        WIDTH_PX as f64 / 2.0,
        HEIGHT_PX as f64 / 2.0,
    )
}

/// The kidney seen by `views` cameras, its true state, and what the fit needs.
pub struct Rig {
    pub scene: Scene,
    pub model: Model,
    /// The pose, shape and cameras the images are made with.
    pub truth: FitState,
    /// The kidney's true centre, camera-0 coordinates (mm): rotations are perturbed about it.
    pub centre_mm: DVec3,
}

impl Rig {
    /// `views` cameras around the kidney at its mean shape, all with `intrinsics` (one per
    /// camera, or the calibrated ones when empty).
    pub fn new(views: usize, intrinsics: &[Intrinsics]) -> Rig {
        let (structure, shape) = kidney();
        let centre_mm = DVec3::new(0.0, 0.0, DISTANCE_MM);
        let cameras: Vec<Camera> = view_directions(views)
            .into_iter()
            .enumerate()
            .map(|(m, d)| {
                let k = intrinsics
                    .get(m)
                    .copied()
                    .unwrap_or_else(calibrated_intrinsics);
                camera_towards(format!("view{m}"), centre_mm, d, k)
            })
            .collect();
        // One blank frame per camera: the fit reads probabilities, never the frames.
        let frames = cameras
            .iter()
            .map(|c| vec![Arc::new(image::RgbImage::new(c.width, c.height))])
            .collect();
        let scene = Scene::in_memory(
            "experiments",
            30.0,
            cameras,
            frames,
            vec![structure.clone()],
            None,
            Seeds {
                by_camera: vec![Default::default(); views.max(1)],
            },
            GroundTruth::default(),
            Vec::new(),
        );
        let model = Model::with_shape(&scene, shape.clone());
        let mesh_centre = crate::geometry::mesh::vertex_mean(&structure.mesh.vertices);
        let affine = Affine::from_linear_translation(DMat3::IDENTITY, centre_mm - mesh_centre);
        let truth = initial_state(&scene, &model, affine);
        Rig {
            scene,
            model,
            truth,
            centre_mm,
        }
    }

    /// The kidney's silhouette in every camera for `state` (noise-free truth when `state` is
    /// the truth).
    pub fn silhouettes(&self, state: &FitState) -> Vec<Mask> {
        render_state(&self.scene, &self.model, state)
            .labels
            .iter()
            .map(|l| l.mask_of(1))
            .collect()
    }

    /// The fit's settings for one frame of `mode` in `phase`, from the project's defaults (or
    /// `config`).
    pub fn params(&self, mode: Mode, phase: Phase, zoom: Zoom, config: &FitConfig) -> FitParams {
        TrackOptions::new(mode, (0, 0), WIDTH_PX)
            .with_config(config.clone())
            .params(phase, zoom)
    }

    /// Fits from `start` on `images` (one per camera).
    pub fn fit(&self, images: &[NoisyImage], start: &FitState, params: &FitParams) -> FitState {
        let ctx = FrameContext::new(&self.model, &self.scene);
        let levels = params.levels.iter().max().map_or(1, |&l| l + 1);
        let mut views: Vec<ViewProbabilities> =
            images.iter().map(|im| im.probabilities(levels)).collect();
        fit_frame(&ctx, start, start, &mut views, None, params).state
    }

    /// Mean Dice over the cameras of `state`'s silhouettes against `truth` (the true ones).
    pub fn dice_against(&self, state: &FitState, truth: &[Mask]) -> f64 {
        let fitted = self.silhouettes(state);
        let scores: Vec<f64> = fitted
            .iter()
            .zip(truth)
            .map(|(a, b)| dice(a, b).unwrap_or(1.0))
            .collect();
        scores.iter().sum::<f64>() / scores.len().max(1) as f64
    }

    /// The fitted kidney's posed vertices (camera-0 coordinates, mm).
    pub fn posed(&self, state: &FitState) -> Vec<DVec3> {
        let deformed = self.model.deformed(&state.shape);
        self.model.posed(&state.affine, &deformed).swap_remove(0)
    }

    /// Root-mean-square distance between the posed vertices of two states (mm).
    pub fn vertex_rmse_mm(&self, a: &FitState, b: &FitState) -> f64 {
        let (pa, pb) = (self.posed(a), self.posed(b));
        let sum: f64 = pa
            .iter()
            .zip(&pb)
            .map(|(x, y)| x.distance_squared(*y))
            .sum();
        (sum / pa.len().max(1) as f64).sqrt()
    }
}

/// One camera's image by eq. 10 with noise: intensity 1 inside the silhouette, 0 outside,
/// plus N(0, σ²) per pixel (not clipped).
#[derive(Debug, Clone)]
pub struct NoisyImage {
    pub width: usize,
    pub height: usize,
    pub intensity: Vec<f32>,
}

impl NoisyImage {
    pub fn new(silhouette: &Mask, sigma: f64, rng: &mut Rng) -> NoisyImage {
        let intensity = silhouette
            .data
            .iter()
            .map(|&inside| (if inside { 1.0 } else { 0.0 } + sigma * rng.normal()) as f32)
            .collect();
        NoisyImage {
            width: silhouette.width,
            height: silhouette.height,
            intensity,
        }
    }

    /// The noise's standard deviation as the image shows it: 1.4826 × the median absolute
    /// difference of horizontal neighbours, over √2 (edges are too few to move a median).
    pub fn noise_sigma(&self) -> f64 {
        let mut d: Vec<f32> = self
            .intensity
            .chunks(self.width.max(1))
            .flat_map(|row| row.windows(2).map(|p| (p[1] - p[0]).abs()))
            .collect();
        if d.is_empty() {
            return 0.0;
        }
        let mid = d.len() / 2;
        let (_, median, _) = d.select_nth_unstable_by(mid, f32::total_cmp);
        1.4826 * *median as f64 / std::f64::consts::SQRT_2
    }

    /// Background and kidney probabilities per pixel from the image model (module docs).
    pub fn probabilities(&self, levels: usize) -> ViewProbabilities {
        // A noise-free image still needs finite log-odds.
        let s2 = self.noise_sigma().max(0.05).powi(2);
        let mut planes = Vec::with_capacity(self.intensity.len() * 2);
        for &i in &self.intensity {
            let odds = ((i as f64 - 0.5) / s2).clamp(-30.0, 30.0);
            let p = 1.0 / (1.0 + (-odds).exp());
            planes.push((1.0 - p) as f32);
            planes.push(p as f32);
        }
        ViewProbabilities::from_planes(planes, self.width, self.height, 2, levels)
    }
}

/// The noisy images of every camera for `truth` silhouettes, trial `trial` of `seed`.
pub fn noisy_images(silhouettes: &[Mask], sigma: f64, seed: u64, trial: u64) -> Vec<NoisyImage> {
    silhouettes
        .iter()
        .enumerate()
        .map(|(m, s)| {
            let mut rng = Rng::fork(seed, trial * 1_000 + m as u64);
            NoisyImage::new(s, sigma, &mut rng)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The cameras look at the kidney: its centre projects to each image's centre, and camera
    /// 0 is the reference (identity extrinsics).
    #[test]
    fn every_camera_looks_at_the_kidney() {
        let rig = Rig::new(7, &[]);
        for cam in &rig.scene.cameras {
            let p = cam.project(rig.centre_mm).expect("in front");
            assert!((p.x - WIDTH_PX as f64 / 2.0).abs() < 1e-6, "{p:?}");
            assert!((p.y - HEIGHT_PX as f64 / 2.0).abs() < 1e-6, "{p:?}");
        }
        let e = rig.scene.cameras[0].extrinsics;
        assert!(
            (e.rotation - DMat3::IDENTITY)
                .abs()
                .to_cols_array()
                .iter()
                .all(|v| *v < 1e-9)
        );
        assert!(e.translation_mm.length() < 1e-9);
        let masks = rig.silhouettes(&rig.truth);
        for m in &masks {
            let share = m.count() as f64 / m.data.len() as f64;
            assert!((0.02..0.6).contains(&share), "kidney covers {share}");
        }
    }

    /// The noise the image shows is the noise put in (within 5 %), and the probabilities side
    /// with the truth on most pixels at the paper's σ = 0.75.
    #[test]
    fn noise_estimate_and_probabilities_follow_the_image_model() {
        let rig = Rig::new(1, &[]);
        let masks = rig.silhouettes(&rig.truth);
        for sigma in [0.25, 0.75, 1.75] {
            let img = &noisy_images(&masks, sigma, 3, 0)[0];
            let est = img.noise_sigma();
            assert!(
                (est / sigma - 1.0).abs() < 0.05,
                "σ {sigma}: estimated {est}"
            );
        }
        let img = &noisy_images(&masks, 0.75, 3, 0)[0];
        let probs = img.probabilities(1);
        let right = masks[0]
            .data
            .iter()
            .enumerate()
            .filter(|&(i, &inside)| (probs.get(0, i as u32, 1) > 0.5) == inside)
            .count();
        let share = right as f64 / masks[0].data.len() as f64;
        assert!(share > 0.7 && share < 0.8, "share right {share}");
    }
}
