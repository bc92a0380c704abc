//! Scenes (CONTRACT §2): cameras, frames, structures with their meshes and joint shape model,
//! seeds, ground truth and zoom changes. [`Scene::open`] reads a scene folder or its scene.json
//! and validates everything it can without decoding every frame (frame headers, meshes,
//! catalogs, seeds, ground truth); [`Scene::decode_frames`] decodes every frame as well. Each
//! problem is one [`InputError`] naming the file and what is wrong. Parsing stops at the
//! files: the shape model is built from the structures by `fit::Model::build`, and the word
//! `demo` is resolved by `crate::open`.

pub mod format;
pub mod frames;
pub mod labels;
pub mod template;
pub mod trajectory;
mod validate;
pub mod write;

use crate::error::InputError;
use crate::geometry::mesh_io::load_mesh;
use crate::geometry::{Affine, Camera, Mesh};
use crate::plane::LabelImage;
use format::{FORMAT_V1, SceneFile};
use frames::{FrameCache, FrameSource};
use glam::DVec3;
use image::RgbImage;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use template::PathTemplate;
pub use trajectory::{Trajectory, TrajectoryError, TrajectoryFrame};
pub use validate::FramesSpec;
pub use validate::{AffineError, validate_affine};
use validate::{check_name, load_catalog, validate_camera};

/// Seed value meaning background or tools (CONTRACT §2); 0 means unpainted.
pub const SEED_BACKGROUND: u8 = 255;
pub const SEED_NONE: u8 = 0;

/// One preoperative structure.
#[derive(Debug, Clone)]
pub struct Structure {
    pub name: String,
    pub label: u8,
    /// False for hidden (e.g. endophytic) structures: no image term, drawn in the overlay.
    pub visible: bool,
    pub mesh: Mesh,
    /// Vertex arrays of the catalog given in the scene (same order as the mesh), if any.
    pub catalog: Option<Vec<Vec<DVec3>>>,
    /// Where the mesh came from (for messages).
    pub mesh_path: PathBuf,
}

/// Painted seeds: per camera, per frame, a label image (0 none, 255 background, else a label).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Seeds {
    pub by_camera: Vec<BTreeMap<usize, LabelImage>>,
}

impl Seeds {
    pub fn seeded_frames(&self) -> Vec<usize> {
        let mut f: Vec<usize> = self
            .by_camera
            .iter()
            .flat_map(|m| m.keys().copied())
            .collect();
        f.sort_unstable();
        f.dedup();
        f
    }

    /// Painted pixels per seed value, over all cameras and frames.
    pub fn pixel_counts(&self) -> BTreeMap<u8, usize> {
        let mut counts = BTreeMap::new();
        for img in self.by_camera.iter().flat_map(|m| m.values()) {
            for &v in &img.data {
                if v != SEED_NONE {
                    *counts.entry(v).or_insert(0) += 1;
                }
            }
        }
        counts
    }
}

/// Ground truth a scene may carry.
#[derive(Debug, Clone, Default)]
pub struct GroundTruth {
    /// Label images per camera and frame, read on demand.
    pub labels: Option<PathTemplate>,
    pub hidden: Option<PathTemplate>,
    pub trajectory: Option<Trajectory>,
    /// In-memory ground truth (the demo): `[camera][frame]`.
    pub memory_labels: Option<Arc<Vec<Vec<LabelImage>>>>,
}

/// A loaded, validated scene.
#[derive(Debug)]
pub struct Scene {
    /// Folder holding scene.json (None for in-memory scenes).
    pub root: Option<PathBuf>,
    /// How the user named it: the scene.json path, or "demo".
    pub origin: String,
    pub fps: f64,
    pub frame_count: usize,
    pub cameras: Vec<Camera>,
    pub frame_sources: Vec<FrameSource>,
    pub structures: Vec<Structure>,
    pub initial_pose: Option<Affine>,
    pub seeds: Seeds,
    pub seeds_template: Option<PathTemplate>,
    pub ground_truth: GroundTruth,
    /// Inclusive frame ranges where the zoom changes.
    pub zoom_changes: Vec<(usize, usize)>,
    /// k1 = c₀ + c₁/f + c₂/f², f = fx / width, where the scene gives the lens's relation.
    pub k1_vs_focal: Option<[f64; 3]>,
    /// Shared with copies made by [`Scene::with_seeds`].
    cache: Arc<FrameCache>,
}

impl Scene {
    /// Opens a scene folder or its scene.json: [`Scene::load`] of the folder's scene.json.
    pub fn open(path: &Path) -> Result<Scene, InputError> {
        let json = if path.is_dir() {
            path.join("scene.json")
        } else {
            path.to_path_buf()
        };
        Self::load(&json)
    }

    /// Loads and validates a scene.json and everything it refers to; every frame must exist
    /// and its header give the camera's size.
    pub fn load(json_path: &Path) -> Result<Scene, InputError> {
        let text = crate::error::read_text(json_path).map_err(|e| {
            let what = if json_path.exists() {
                format!("cannot read: {e}")
            } else {
                "no such scene (expected a scene folder, its scene.json, or 'demo')".into()
            };
            InputError::new(json_path, what)
        })?;
        let file: SceneFile = serde_json::from_str(&text).map_err(|e| {
            // serde's words for a document of the wrong shape name our struct ("expected
            // struct SceneFile with 10 elements" for an array): say what the file must be.
            let top = serde_json::from_str::<serde_json::Value>(&text).ok();
            let problem = match top {
                Some(v) if !v.is_object() => format!(
                    "malformed scene: the document is {}, not an object {{\"format\": …, \"cameras\": […], …}}",
                    json_kind(&v)
                ),
                _ => format!("malformed scene: {e}"),
            };
            InputError::new(json_path, problem)
        })?;
        let root = json_path
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_default();
        Self::from_file(file, &root, json_path)
    }

    fn from_file(file: SceneFile, root: &Path, json_path: &Path) -> Result<Scene, InputError> {
        let bad = |problem: String| InputError::new(json_path, problem);
        if file.format != FORMAT_V1 {
            return Err(bad(format!(
                "unsupported format '{}' (this program reads '{FORMAT_V1}')",
                file.format
            )));
        }
        if file.frame_count <= 0 {
            return Err(bad(format!(
                "frame_count must be positive, got {}",
                file.frame_count
            )));
        }
        if !(file.fps.is_finite() && file.fps > 0.0) {
            return Err(bad(format!("fps must be positive, got {}", file.fps)));
        }
        let frame_count = file.frame_count as usize;
        if file.cameras.is_empty() {
            return Err(bad("no cameras".into()));
        }
        let mut cameras = Vec::new();
        let mut frame_sources = Vec::new();
        let mut videos = frames::VideoReaders::default();
        for (i, c) in file.cameras.iter().enumerate() {
            let (camera, spec) = validate_camera(c, i).map_err(|e| bad(e.to_string()))?;
            // CONTRACT §2: rotation and translation map camera-0 coordinates into each camera,
            // so camera 0's are the identity. A tool that wrote a world frame instead gets its
            // rig used as written, and told.
            let e = &camera.extrinsics;
            if i == 0
                && ((e.rotation - glam::DMat3::IDENTITY)
                    .to_cols_array()
                    .iter()
                    .any(|v| v.abs() > 1e-6)
                    || e.translation_mm.length() > 1e-6)
            {
                log::warn!(
                    "{}: camera 0 ('{}') has a rotation or translation that is not the identity; \
                     the scene format makes camera 0 the reference (its coordinates are the \
                     model's), so poses are read in a frame that camera 0 does not see from",
                    json_path.display(),
                    camera.name
                );
            }
            if cameras.iter().any(|k: &Camera| k.name == camera.name) {
                return Err(bad(format!("two cameras are named '{}'", camera.name)));
            }
            frame_sources.push(match spec {
                FramesSpec::Sequence(template) => FrameSource::Files {
                    root: root.to_path_buf(),
                    template,
                    camera: camera.name.clone(),
                },
                FramesSpec::Video { path, crop } => {
                    videos.source(&root.join(path), crop, &camera, frame_count)?
                }
            });
            cameras.push(camera);
        }
        if file.structures.is_empty() {
            return Err(bad("no structures".into()));
        }
        let mut structures: Vec<Structure> = Vec::new();
        for (i, s) in file.structures.iter().enumerate() {
            let what = format!("structures[{i}] ('{}')", s.name);
            check_name(&s.name).map_err(|p| bad(format!("{what}: {p}")))?;
            if !(1..=254).contains(&s.label) {
                return Err(bad(format!(
                    "{what}: label {} is not allowed (1–254; 0 is background and 255 is reserved for background seeds)",
                    s.label
                )));
            }
            if let Some(other) = structures.iter().find(|o| o.label as i64 == s.label) {
                return Err(bad(format!(
                    "{what}: label {} is already used by '{}'",
                    s.label, other.name
                )));
            }
            if structures.iter().any(|o| o.name == s.name) {
                return Err(bad(format!(
                    "{what}: two structures are named '{}'",
                    s.name
                )));
            }
            let mesh_path = root.join(&s.mesh);
            let mesh = load_mesh(&mesh_path)?;
            let catalog = match &s.catalog {
                Some(dir) => Some(load_catalog(&root.join(dir), &mesh)?),
                None => None,
            };
            structures.push(Structure {
                name: s.name.clone(),
                label: s.label as u8,
                visible: s.visible,
                mesh,
                catalog,
                mesh_path,
            });
        }
        if !structures.iter().any(|s| s.visible) {
            return Err(bad(
                "no visible structure: at least one must give an image term".into(),
            ));
        }
        let initial_pose = match &file.initial_pose {
            Some(p) => {
                Some(validate_affine(&p.affine).map_err(|e| bad(format!("initial_pose: {e}")))?)
            }
            None => None,
        };
        let mut zoom_changes = Vec::new();
        for &[a, b] in &file.zoom_changes {
            if a < 0 || b < a || b as usize >= frame_count {
                return Err(bad(format!(
                    "zoom_changes: [{a}, {b}] is not an inclusive range inside 0..{}",
                    frame_count - 1
                )));
            }
            zoom_changes.push((a as usize, b as usize));
        }
        let k1_vs_focal = match &file.k1_vs_focal {
            None => None,
            Some(c) => match c.as_slice() {
                &[c0, c1, c2] if c.iter().all(|v| v.is_finite() && v.abs() <= 1e3) => {
                    Some([c0, c1, c2])
                }
                _ => {
                    return Err(bad(format!(
                        "k1_vs_focal: {c:?} must be three finite coefficients of at most 1000 (k1 = c0 + c1/f + c2/f², f = fx / width)"
                    )));
                }
            },
        };
        let mut scene = Scene {
            root: Some(root.to_path_buf()),
            origin: json_path.display().to_string(),
            fps: file.fps,
            frame_count,
            cameras,
            frame_sources,
            structures,
            initial_pose,
            seeds: Seeds::default(),
            seeds_template: None,
            ground_truth: GroundTruth::default(),
            zoom_changes,
            k1_vs_focal,
            cache: Arc::new(FrameCache::new(frames::DEFAULT_CACHE_FRAMES)),
        };
        scene.check_frame_headers()?;
        if let Some(t) = &file.seeds {
            let template = PathTemplate::parse(t).map_err(|e| bad(format!("seeds: {e}")))?;
            scene.seeds = scene.load_seeds(&template)?;
            scene.seeds_template = Some(template);
        }
        if let Some(gt) = &file.ground_truth {
            scene.ground_truth = scene.load_ground_truth(gt, json_path)?;
            scene.check_ground_truth_headers()?;
        }
        Ok(scene)
    }

    /// An in-memory scene (the demo): frames and ground truth already made.
    #[allow(clippy::too_many_arguments)]
    pub fn in_memory(
        origin: &str,
        fps: f64,
        cameras: Vec<Camera>,
        frames: Vec<Vec<Arc<RgbImage>>>,
        structures: Vec<Structure>,
        initial_pose: Option<Affine>,
        seeds: Seeds,
        ground_truth: GroundTruth,
        zoom_changes: Vec<(usize, usize)>,
    ) -> Scene {
        let frame_count = frames.first().map(|f| f.len()).unwrap_or(0);
        Scene {
            root: None,
            origin: origin.to_string(),
            fps,
            frame_count,
            cameras,
            frame_sources: frames
                .into_iter()
                .map(|f| FrameSource::Memory(Arc::new(f)))
                .collect(),
            structures,
            initial_pose,
            seeds,
            seeds_template: None,
            ground_truth,
            zoom_changes,
            k1_vs_focal: None,
            cache: Arc::new(FrameCache::new(1)),
        }
    }

    /// The same scene with other seeds (the app's painted strokes); frames and their cache
    /// are shared, nothing is read again.
    pub fn with_seeds(&self, seeds: Seeds) -> Scene {
        Scene {
            root: self.root.clone(),
            origin: self.origin.clone(),
            fps: self.fps,
            frame_count: self.frame_count,
            cameras: self.cameras.clone(),
            frame_sources: self.frame_sources.clone(),
            structures: self.structures.clone(),
            initial_pose: self.initial_pose,
            seeds,
            seeds_template: self.seeds_template.clone(),
            ground_truth: self.ground_truth.clone(),
            zoom_changes: self.zoom_changes.clone(),
            k1_vs_focal: self.k1_vs_focal,
            cache: self.cache.clone(),
        }
    }

    /// Frame `t` of camera `c`, decoded (cached).
    pub fn frame(&self, c: usize, t: usize) -> Result<Arc<RgbImage>, InputError> {
        let cam = self
            .cameras
            .get(c)
            .ok_or_else(|| InputError::new(&self.origin, format!("no camera {c}")))?;
        let source = &self.frame_sources[c];
        self.cache.get(c, t, source, (cam.width, cam.height))
    }

    /// Ground-truth labels of frame `t` in camera `c`, if the scene has them.
    pub fn ground_truth_labels(
        &self,
        c: usize,
        t: usize,
    ) -> Option<Result<LabelImage, InputError>> {
        if let Some(mem) = &self.ground_truth.memory_labels {
            return mem.get(c).and_then(|f| f.get(t)).cloned().map(Ok);
        }
        let template = self.ground_truth.labels.as_ref()?;
        let path = self
            .root
            .as_ref()?
            .join(template.expand(t, &self.cameras[c].name, ""));
        if !path.exists() {
            return None;
        }
        Some(self.read_ground_truth_labels(&path, c))
    }

    /// A ground-truth label image of camera `c`, its size and values checked.
    fn read_ground_truth_labels(&self, path: &Path, c: usize) -> Result<LabelImage, InputError> {
        let img = labels::read_label_png_sized(path, |w, h| self.check_label_size(path, w, h, c))?;
        self.check_ground_truth_values(path, &img)?;
        Ok(img)
    }

    /// Every value of a ground-truth label image is 0 or a structure's label: another value
    /// (a seed image's 255, a tool's own class numbers) would be scored as a structure missed
    /// and lower the Dice with nothing saying why.
    pub fn check_ground_truth_values(
        &self,
        path: &Path,
        img: &LabelImage,
    ) -> Result<(), InputError> {
        let seen = values_present(img);
        let unknown = (1..=255u8)
            .find(|&v| seen[v as usize] && !self.structures.iter().any(|s| s.label == v));
        let Some(v) = unknown else {
            return Ok(());
        };
        let labels: Vec<String> = self
            .structures
            .iter()
            .map(|s| format!("{} {}", s.label, s.name))
            .collect();
        Err(InputError::new(
            path,
            format!(
                "ground-truth value {v} is no structure's label (0 is background; the scene's labels: {})",
                labels.join(", ")
            ),
        ))
    }

    /// Which frames have ground-truth labels for every camera.
    pub fn ground_truth_frames(&self) -> Vec<usize> {
        if let Some(mem) = &self.ground_truth.memory_labels {
            return (0..mem.first().map(|v| v.len()).unwrap_or(0)).collect();
        }
        let (Some(template), Some(root)) = (&self.ground_truth.labels, &self.root) else {
            return Vec::new();
        };
        (0..self.frame_count)
            .filter(|&t| {
                self.cameras
                    .iter()
                    .all(|c| root.join(template.expand(t, &c.name, "")).exists())
            })
            .collect()
    }

    /// A label image of `width`×`height` fits camera `c`.
    fn check_label_size(
        &self,
        path: &Path,
        width: usize,
        height: usize,
        c: usize,
    ) -> Result<(), InputError> {
        let cam = &self.cameras[c];
        if width != cam.width as usize || height != cam.height as usize {
            return Err(InputError::new(
                path,
                format!(
                    "label image is {width}×{height} but camera '{}' is {}×{}",
                    cam.name, cam.width, cam.height
                ),
            ));
        }
        Ok(())
    }

    /// Every ground-truth label image that exists (visible and hidden structures) has its
    /// camera's size, so that `info` refuses what `classify` and `track` would (headers only).
    fn check_ground_truth_headers(&self) -> Result<(), InputError> {
        for (c, cam) in self.cameras.iter().enumerate() {
            for t in 0..self.frame_count {
                for path in self.ground_truth_files(t, c) {
                    frames::check_image_header(
                        &path,
                        (cam.width, cam.height),
                        "ground-truth label image",
                    )?;
                }
            }
        }
        Ok(())
    }

    /// The ground-truth images of frame `t` in camera `c` that exist as files: the label image
    /// and each hidden structure's mask (none for a scene without a folder).
    fn ground_truth_files(&self, t: usize, c: usize) -> Vec<PathBuf> {
        let (labels, hidden) = self.ground_truth_paths(t, c);
        labels.into_iter().chain(hidden).collect()
    }

    /// [`Scene::ground_truth_files`] apart: the label image, and the hidden structures' masks.
    fn ground_truth_paths(&self, t: usize, c: usize) -> (Option<PathBuf>, Vec<PathBuf>) {
        let (Some(root), Some(cam)) = (&self.root, self.cameras.get(c)) else {
            return (None, Vec::new());
        };
        let gt = &self.ground_truth;
        let labels = gt
            .labels
            .as_ref()
            .map(|l| root.join(l.expand(t, &cam.name, "")))
            .filter(|p| p.exists());
        let mut hidden = Vec::new();
        if let Some(h) = &gt.hidden {
            hidden.extend(
                self.structures
                    .iter()
                    .filter(|s| !s.visible)
                    .map(|s| root.join(h.expand(t, &cam.name, &s.name))),
            );
        }
        hidden.retain(|p| p.exists());
        (labels, hidden)
    }

    /// Every frame file exists and its header gives its camera's size (cheap).
    fn check_frame_headers(&self) -> Result<(), InputError> {
        for (c, cam) in self.cameras.iter().enumerate() {
            for t in 0..self.frame_count {
                if let Some(path) = self.frame_sources[c].path(t) {
                    frames::check_frame_header(&path, (cam.width, cam.height))?;
                }
            }
        }
        Ok(())
    }

    /// Decodes every frame file of every camera completely (what `info` does), reporting
    /// `progress(done, total)` over all cameras' frames.
    pub fn decode_frames(&self, progress: &dyn Fn(usize, usize)) -> Result<(), InputError> {
        let total = self.cameras.len() * self.frame_count;
        for (c, cam) in self.cameras.iter().enumerate() {
            for t in 0..self.frame_count {
                match &self.frame_sources[c] {
                    FrameSource::Files { .. } => {
                        if let Some(path) = self.frame_sources[c].path(t) {
                            frames::decode_frame(&path, (cam.width, cam.height))?;
                        }
                    }
                    FrameSource::Video { .. } => {
                        self.frame(c, t)?;
                    }
                    FrameSource::Memory(_) => {}
                }
                progress(c * self.frame_count + t + 1, total);
            }
        }
        Ok(())
    }

    /// Decodes every ground-truth image (label images and hidden structures' masks) as `track`
    /// will read them: `info` then refuses what `track` would, not after a run. Without files
    /// (ground truth in memory, or none), nothing is read and no progress reported.
    pub fn decode_ground_truth(&self, progress: &dyn Fn(usize, usize)) -> Result<(), InputError> {
        self.decode_ground_truth_of(0..=self.frame_count.saturating_sub(1), progress)
    }

    /// [`Scene::decode_ground_truth`] of the frames in `frames` (a run's range: what it will
    /// score), `progress` counted over the scene's frames.
    pub fn decode_ground_truth_of(
        &self,
        frames: std::ops::RangeInclusive<usize>,
        progress: &dyn Fn(usize, usize),
    ) -> Result<(), InputError> {
        for t in frames.filter(|&t| t < self.frame_count) {
            let mut any = false;
            for c in 0..self.cameras.len() {
                let (label_path, hidden_paths) = self.ground_truth_paths(t, c);
                if let Some(path) = label_path {
                    self.read_ground_truth_labels(&path, c)?;
                    any = true;
                }
                for path in hidden_paths {
                    read_hidden_mask(&path, (self.cameras[c].width, self.cameras[c].height))?;
                    any = true;
                }
            }
            if any {
                progress(t + 1, self.frame_count);
            }
        }
        Ok(())
    }

    fn load_seeds(&self, template: &PathTemplate) -> Result<Seeds, InputError> {
        let root = self.root.clone().unwrap_or_default();
        let mut seeds = Seeds {
            by_camera: vec![BTreeMap::new(); self.cameras.len()],
        };
        for (c, cam) in self.cameras.iter().enumerate() {
            for t in 0..self.frame_count {
                let path = root.join(template.expand(t, &cam.name, ""));
                if !path.exists() {
                    continue;
                }
                let img = labels::read_label_png_sized(&path, |w, h| {
                    self.check_label_size(&path, w, h, c)
                })?;
                self.check_seed_values(&path, &img)?;
                seeds.by_camera[c].insert(t, img);
            }
        }
        Ok(seeds)
    }

    /// Every seed value is 0, 255 or a visible structure's label.
    pub fn check_seed_values(&self, path: &Path, img: &LabelImage) -> Result<(), InputError> {
        let seen = values_present(img);
        for v in 1..255u8 {
            if !seen[v as usize] {
                continue;
            }
            match self.structures.iter().find(|s| s.label == v) {
                None => {
                    return Err(InputError::new(
                        path,
                        format!(
                            "seed value {v} is no structure's label (use 255 for background, 0 for unpainted)"
                        ),
                    ));
                }
                Some(s) if !s.visible => {
                    return Err(InputError::new(
                        path,
                        format!(
                            "seeds paint the hidden structure '{}' (label {v}), which cannot be seen in the images",
                            s.name
                        ),
                    ));
                }
                _ => {}
            }
        }
        Ok(())
    }

    fn load_ground_truth(
        &self,
        gt: &format::GroundTruthEntry,
        json_path: &Path,
    ) -> Result<GroundTruth, InputError> {
        let bad = |p: String| InputError::new(json_path, p);
        let root = self.root.clone().unwrap_or_default();
        let labels = gt
            .labels
            .as_deref()
            .map(PathTemplate::parse)
            .transpose()
            .map_err(|e| bad(format!("ground_truth.labels: {e}")))?;
        let hidden = PathTemplate::parse(
            gt.hidden
                .as_deref()
                .unwrap_or(format::DEFAULT_HIDDEN_TEMPLATE),
        )
        .map_err(|e| bad(format!("ground_truth.hidden: {e}")))?;
        let trajectory = match &gt.trajectory {
            Some(rel) => {
                let path = root.join(rel);
                let text = crate::error::read_text(&path).map_err(|e| {
                    InputError::new(&path, format!("cannot read ground-truth trajectory: {e}"))
                })?;
                let (traj, ignored) = Trajectory::from_json(&text)
                    .map_err(|e| InputError::new(&path, format!("malformed trajectory: {e}")))?;
                if let Some(note) = ignored {
                    log::warn!("{}: {note}", path.display());
                }
                traj.validate(self.frame_count, self.cameras.len())
                    .map_err(|e| InputError::new(&path, e.to_string()))?;
                Some(traj)
            }
            None => None,
        };
        Ok(GroundTruth {
            labels,
            hidden: Some(hidden),
            trajectory,
            memory_labels: None,
        })
    }

    pub fn visible_structures(&self) -> impl Iterator<Item = (usize, &Structure)> {
        self.structures
            .iter()
            .enumerate()
            .filter(|(_, s)| s.visible)
    }

    pub fn structure_by_label(&self, label: u8) -> Option<&Structure> {
        self.structures.iter().find(|s| s.label == label)
    }

    /// Is frame `t` inside a marked zoom change?
    pub fn in_zoom_change(&self, t: usize) -> bool {
        self.zoom_changes.iter().any(|&(a, b)| (a..=b).contains(&t))
    }
}

/// Which of the 256 values occur in `img`.
fn values_present(img: &LabelImage) -> [bool; 256] {
    let mut seen = [false; 256];
    for &v in &img.data {
        seen[v as usize] = true;
    }
    seen
}

/// A hidden structure's ground-truth mask (CONTRACT: 0 outside, 255 inside), `size` checked.
/// Any other value is refused: a mask written 0/1 would otherwise read as empty.
pub fn read_hidden_mask(path: &Path, size: (u32, u32)) -> Result<LabelImage, InputError> {
    let (cw, ch) = (size.0 as usize, size.1 as usize);
    let img = labels::read_label_png_sized(path, |w, h| {
        if (w, h) == (cw, ch) {
            return Ok(());
        }
        Err(InputError::new(
            path,
            format!("hidden-structure mask is {w}×{h} but the camera is {cw}×{ch}"),
        ))
    })?;
    let seen = values_present(&img);
    if let Some(v) = (1..255u8).find(|&v| seen[v as usize]) {
        return Err(InputError::new(
            path,
            format!("hidden-structure mask holds value {v}; a mask is 0 (outside) or 255 (inside)"),
        ));
    }
    Ok(img)
}

/// "an array", "a number", … for a JSON value, in messages.
fn json_kind(v: &serde_json::Value) -> &'static str {
    match v {
        serde_json::Value::Null => "null",
        serde_json::Value::Bool(_) => "a boolean",
        serde_json::Value::Number(_) => "a number",
        serde_json::Value::String(_) => "a string",
        serde_json::Value::Array(_) => "an array",
        serde_json::Value::Object(_) => "an object",
    }
}
