//! Synthetic stereo endoscopic phantoms with ground truth: `endofuse synth` writes one as a
//! scene folder (CONTRACT §2), and the built-in demo is the same generator run in memory.

pub mod anatomy;
pub mod look;
pub mod phantom;
pub mod seeds;
pub mod texture;

use crate::error::{Error, InputError};
use crate::geometry::mesh_io::write_obj;
use crate::geometry::{Camera, Mesh};
use crate::plane::LabelImage;
use crate::rng::Rng;
use crate::scene::format::{
    CameraEntry, FORMAT_V1, GroundTruthEntry, InitialPoseEntry, SceneFile, StructureEntry,
};
use crate::scene::write::{write_json_atomic, write_labels, write_mask, write_rgb};
use crate::scene::{GroundTruth, Scene, Seeds, Structure, Trajectory};
use phantom::{FrameTruth, Phantom};
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

/// How the phantom is made (the `synth` flags).
#[derive(Debug, Clone, PartialEq)]
pub struct SynthOptions {
    pub frames: usize,
    pub seed: u64,
    /// Standard deviation of additive Gaussian noise on intensities in [0, 1].
    pub noise: f64,
    pub width: u32,
    pub height: u32,
    pub views: usize,
    pub tools: bool,
    pub zoom: bool,
    pub smoke: bool,
    /// Frames that get seed strokes (the first three, as a user would).
    pub seeded_frames: usize,
    /// How far `initial_pose` is from the truth.
    pub initial_offset_mm: f64,
    pub initial_offset_deg: f64,
    /// Structures to render instead of the built-in anatomy (a patient's, from `import-ct`):
    /// name, label, visible, mesh. The kidney comes first; all are re-centred on its vertex mean.
    pub structures: Option<Vec<(String, u8, bool, Mesh)>>,
    /// The rig at rest instead of the built-in stereo pair (a real calibration): sizes,
    /// intrinsics with their distortion, extrinsics. The zoom then scales focal length and
    /// principal point and keeps the lens's distortion.
    pub cameras: Option<Vec<Camera>>,
    /// Draw the look (light colour and strength, glints, kidney tint, texture scale, blood-like
    /// patches, blur) from the seed instead of the default phantom's ([`look::Look`]).
    pub vary_look: bool,
    /// Draw the rig and the scene from the seed as real da Vinci data vary (issue 14): toe-in
    /// of 1–2° (±0.15° about the other axes), the right principal point up to 2 px off, k2 and
    /// p1/p2, a 20 % zoom over 10–15 frames (half the scenes zoom back out) with the principal
    /// point drifting ±4 px, depth 145–165 mm, a start 8 mm and 10° off ([`phantom::RigDraw`]).
    pub vary_rig: bool,
}

impl Default for SynthOptions {
    fn default() -> Self {
        Self {
            frames: 30,
            seed: 1,
            noise: 0.01,
            width: 960,
            height: 540,
            views: 2,
            tools: true,
            zoom: true,
            smoke: true,
            seeded_frames: 3,
            initial_offset_mm: 5.0,
            initial_offset_deg: 5.0,
            structures: None,
            cameras: None,
            vary_look: false,
            vary_rig: false,
        }
    }
}

/// Options that cannot make a scene. The messages name the `synth` flags, since that is where
/// the values come from.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SynthOptionsError {
    #[error("--frames must be between 1 and 100000, got {frames}")]
    Frames { frames: usize },
    #[error("--width/--height must be between 16 and 8192, got {width_px}×{height_px}")]
    Size { width_px: u32, height_px: u32 },
    #[error("--views must be between 1 and 16, got {views}")]
    Views { views: usize },
    #[error("--noise must be between 0 and 1 (intensities are in [0, 1]), got {noise}")]
    Noise { noise: f64 },
}

impl SynthOptions {
    /// Refuses options that cannot make a scene.
    pub fn validate(&self) -> Result<(), SynthOptionsError> {
        if self.frames == 0 || self.frames > 100_000 {
            return Err(SynthOptionsError::Frames {
                frames: self.frames,
            });
        }
        if !(16..=8192).contains(&self.width) || !(16..=8192).contains(&self.height) {
            return Err(SynthOptionsError::Size {
                width_px: self.width,
                height_px: self.height,
            });
        }
        if self.views == 0 || self.views > 16 {
            return Err(SynthOptionsError::Views { views: self.views });
        }
        if !(self.noise.is_finite() && (0.0..=1.0).contains(&self.noise)) {
            return Err(SynthOptionsError::Noise { noise: self.noise });
        }
        Ok(())
    }
}

/// The seed strokes of frame `t` (empty when `t` is not a seeded frame).
fn frame_seeds(phantom: &Phantom, truth: &FrameTruth, t: usize) -> Option<Vec<LabelImage>> {
    if t >= phantom.options.seeded_frames {
        return None;
    }
    let visible: Vec<u8> = phantom
        .structures
        .iter()
        .filter(|s| s.2)
        .map(|s| s.1)
        .collect();
    Some(
        truth
            .labels
            .iter()
            .zip(&truth.tools)
            .enumerate()
            .map(|(m, (labels, tools))| {
                let mut rng = Rng::fork(phantom.options.seed ^ 0x0005_EED5, (t * 64 + m) as u64);
                seeds::seeds_for_view(labels, tools, &visible, &mut rng)
            })
            .collect(),
    )
}

/// Writes a phantom scene into `dir`; `progress(done, total)` is called as frames finish.
pub fn write_scene(
    dir: &Path,
    options: &SynthOptions,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<(), Error> {
    options
        .validate()
        .map_err(|e| InputError::new(dir, e.to_string()))?;
    let phantom = Phantom::new(options.clone());
    let cams0 = phantom.initial_cameras();
    let wrap = |path: PathBuf| {
        move |source| Error::Write {
            path: path.clone(),
            source,
        }
    };
    std::fs::create_dir_all(dir.join("meshes")).map_err(wrap(dir.to_path_buf()))?;
    for (name, _, _, mesh) in &phantom.structures {
        let p = dir.join(format!("meshes/{name}.obj"));
        write_obj(&p, mesh).map_err(wrap(p.clone()))?;
    }
    let done = AtomicUsize::new(0);
    let frames: Vec<_> = (0..options.frames)
        .into_par_iter()
        .map(|t| -> Result<_, Error> {
            let truth = phantom.render(t);
            for (m, cam) in cams0.iter().enumerate() {
                write_rgb(
                    &dir.join(format!("{}/{t:06}.png", cam.name)),
                    &truth.images[m],
                )?;
                write_labels(
                    &dir.join(format!("gt/{}/{t:06}.png", cam.name)),
                    &truth.labels[m],
                )?;
                for (name, masks) in &truth.hidden {
                    write_mask(
                        &dir.join(format!("gt/hidden/{name}/{}/{t:06}.png", cam.name)),
                        &masks[m],
                    )?;
                }
            }
            if let Some(seeds) = frame_seeds(&phantom, &truth, t) {
                for (m, cam) in cams0.iter().enumerate() {
                    write_labels(
                        &dir.join(format!("seeds/{}/{t:06}.png", cam.name)),
                        &seeds[m],
                    )?;
                }
            }
            progress(done.fetch_add(1, Ordering::Relaxed) + 1, options.frames);
            Ok(truth.trajectory)
        })
        .collect::<Result<_, _>>()?;
    write_json_atomic(&dir.join("gt/trajectory.json"), &Trajectory { frames })?;
    let file = SceneFile {
        format: FORMAT_V1.into(),
        fps: 30.0,
        frame_count: options.frames as i64,
        cameras: cams0
            .iter()
            .map(|c| CameraEntry::from_camera(c, format!("{}/{{frame:06}}.png", c.name).into()))
            .collect(),
        structures: phantom
            .structures
            .iter()
            .map(|(name, label, visible, _)| StructureEntry {
                name: name.to_string(),
                label: *label as i64,
                visible: *visible,
                mesh: format!("meshes/{name}.obj"),
                catalog: None,
            })
            .collect(),
        initial_pose: Some(InitialPoseEntry {
            affine: phantom.initial_pose().q.to_vec(),
        }),
        seeds: Some("seeds/{camera}/{frame:06}.png".into()),
        ground_truth: Some(GroundTruthEntry {
            labels: Some("gt/{camera}/{frame:06}.png".into()),
            trajectory: Some("gt/trajectory.json".into()),
            hidden: None,
        }),
        zoom_changes: phantom
            .zoom_ranges
            .iter()
            .map(|&(a, b)| [a as i64, b as i64])
            .collect(),
        k1_vs_focal: phantom.k1_vs_focal().map(|c| c.to_vec()),
    };
    write_json_atomic(&dir.join("scene.json"), &file)
}

/// The demo's options: small enough to make in a couple of seconds when the app opens.
pub fn demo_options() -> SynthOptions {
    SynthOptions {
        frames: 40,
        seed: 7,
        width: 480,
        height: 270,
        ..SynthOptions::default()
    }
}

/// One 240×136 frame of the phantom with noise 0.02: what the fit's unit tests stand on.
#[cfg(test)]
pub(crate) fn one_small_frame() -> Scene {
    memory_scene(&SynthOptions {
        frames: 1,
        width: 240,
        height: 136,
        noise: 0.02,
        ..SynthOptions::default()
    })
    .expect("the small phantom builds")
}

/// Builds a phantom scene in memory (the built-in demo, and tests).
pub fn memory_scene(options: &SynthOptions) -> Result<Scene, InputError> {
    options
        .validate()
        .map_err(|e| InputError::new("demo", e.to_string()))?;
    let phantom = Phantom::new(options.clone());
    let truths: Vec<FrameTruth> = (0..options.frames)
        .into_par_iter()
        .map(|t| phantom.render(t))
        .collect();
    let cams0 = phantom.initial_cameras();
    let views = cams0.len();
    let mut seeds = Seeds {
        by_camera: vec![BTreeMap::new(); views],
    };
    for (t, truth) in truths.iter().enumerate() {
        if let Some(s) = frame_seeds(&phantom, truth, t) {
            for (m, img) in s.into_iter().enumerate() {
                seeds.by_camera[m].insert(t, img);
            }
        }
    }
    let frames: Vec<Vec<Arc<image::RgbImage>>> = (0..views)
        .map(|m| {
            truths
                .iter()
                .map(|tr| Arc::new(tr.images[m].clone()))
                .collect()
        })
        .collect();
    let labels: Vec<Vec<LabelImage>> = (0..views)
        .map(|m| truths.iter().map(|tr| tr.labels[m].clone()).collect())
        .collect();
    let structures = phantom
        .structures
        .iter()
        .map(|(name, label, visible, mesh)| Structure {
            name: name.to_string(),
            label: *label,
            visible: *visible,
            mesh: mesh.clone(),
            catalog: None,
            mesh_path: PathBuf::from(format!("demo/meshes/{name}.obj")),
        })
        .collect();
    let ground_truth = GroundTruth {
        labels: None,
        hidden: None,
        trajectory: Some(Trajectory {
            frames: truths.iter().map(|t| t.trajectory.clone()).collect(),
        }),
        memory_labels: Some(Arc::new(labels)),
    };
    let mut scene = Scene::in_memory(
        "demo",
        30.0,
        cams0,
        frames,
        structures,
        Some(phantom.initial_pose()),
        seeds,
        ground_truth,
        phantom.zoom_ranges.clone(),
    );
    scene.k1_vs_focal = phantom.k1_vs_focal();
    Ok(scene)
}

/// The built-in demo scene.
pub fn demo_scene() -> Result<Scene, InputError> {
    memory_scene(&demo_options())
}
