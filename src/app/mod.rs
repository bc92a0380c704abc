//! The desktop app (eframe/egui, wgpu): paint seeds on the views, train the forest, place and
//! fit the model, track the video in the background, scrub, review and export. The app is a
//! thin face over the core: all heavy work runs on the [`Worker`] thread, and the UI only
//! sends commands and drains events each frame, so the window never blocks.
//!
//! Files: `actions` (every action's label and shortcut, once), `seeds` (the paintable seed
//! layer with undo), `view` (zoom/pan), `views` (drawing and painting on the views),
//! `overlay3d` (the wgpu overlay), `panels` (side panel, timeline, status, review),
//! `session` (session file and autosave).

pub mod actions;
pub mod frames;
pub mod overlay3d;
pub mod panels;
pub mod view;
pub mod views;

use crate::appearance::{Appearance, ClassMap, ForestParams, ProbabilityMaps};
use crate::fit::FitState;
use crate::fit::Model;
use crate::fit::optimizer::Mode;
use crate::fit::tracker::TrackedFrame;
use crate::geometry::Affine;
use crate::scene::Scene;
use crate::scene::template::PathTemplate;
use crate::session::{self, FitSettings, FrameResult, SESSION_FORMAT, Session};
use crate::strokes::SeedEditor;
use crate::worker::{Command, Event, Task, Worker};
use actions::Action;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use view::ViewTransform;

/// Preferences kept between runs (eframe persistence); every field has a default, so an old
/// or damaged preferences file never stops the app.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default)]
pub struct Prefs {
    pub recent: Vec<String>,
    /// Brush and eraser radii in image pixels.
    pub brush_px: f32,
    pub eraser_px: f32,
    pub seed_opacity: f32,
    pub probability_opacity: f32,
    pub overlay_opacity: f32,
    pub show_seeds: bool,
    pub show_overlay: bool,
}

impl Default for Prefs {
    fn default() -> Self {
        Self {
            recent: Vec::new(),
            brush_px: 6.0,
            eraser_px: 10.0,
            seed_opacity: 0.85,
            probability_opacity: 0.6,
            overlay_opacity: 0.3,
            show_seeds: true,
            show_overlay: true,
        }
    }
}

/// What the left mouse button does on a view.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tool {
    Brush,
    Eraser,
    Place,
}

/// What is drawn under the seeds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layer {
    Image,
    /// Probability of one forest class.
    Probability(usize),
    Uncertainty,
}

/// Per-structure display settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StructureStyle {
    pub shown: bool,
    pub opacity: f32,
}

/// File dialogs behind a trait, so tests never open one (rfd runs on the UI thread).
pub trait Dialogs {
    fn pick_scene(&mut self) -> Option<PathBuf>;
    fn pick_session(&mut self) -> Option<PathBuf>;
    fn save_session(&mut self) -> Option<PathBuf>;
    fn pick_folder(&mut self, title: &str) -> Option<PathBuf>;
}

/// The native dialogs.
pub struct RfdDialogs;

impl Dialogs for RfdDialogs {
    fn pick_scene(&mut self) -> Option<PathBuf> {
        rfd::FileDialog::new()
            .set_title("Open a scene (scene.json)")
            .add_filter("scene", &["json"])
            .pick_file()
    }
    fn pick_session(&mut self) -> Option<PathBuf> {
        rfd::FileDialog::new()
            .set_title("Load a session")
            .add_filter("endofuse session", &["json"])
            .pick_file()
    }
    fn save_session(&mut self) -> Option<PathBuf> {
        rfd::FileDialog::new()
            .set_title("Save the session")
            .set_file_name("session.endofuse.json")
            .save_file()
    }
    fn pick_folder(&mut self, title: &str) -> Option<PathBuf> {
        rfd::FileDialog::new().set_title(title).pick_folder()
    }
}

/// No dialogs (tests): every request is cancelled.
pub struct NoDialogs;

impl Dialogs for NoDialogs {
    fn pick_scene(&mut self) -> Option<PathBuf> {
        None
    }
    fn pick_session(&mut self) -> Option<PathBuf> {
        None
    }
    fn save_session(&mut self) -> Option<PathBuf> {
        None
    }
    fn pick_folder(&mut self, _: &str) -> Option<PathBuf> {
        None
    }
}

/// What the worker is busy with, for the status bar.
#[derive(Debug, Clone, PartialEq)]
pub struct Busy {
    pub task: Task,
    pub what: String,
    pub done: usize,
    pub total: usize,
}

/// A session waiting for its scene to load.
struct PendingSession {
    session: Session,
    path: PathBuf,
}

pub struct EndofuseApp {
    pub worker: Worker,
    pub prefs: Prefs,
    dialogs: Box<dyn Dialogs>,
    /// True when the overlay's wgpu pipelines are registered.
    gpu_overlay: bool,

    pub scene: Option<Arc<Scene>>,
    pub scene_spec: String,
    /// The scene being loaded (it becomes `scene_spec` once it arrives).
    loading_spec: Option<String>,
    model: Option<Arc<Model>>,
    classes: Option<ClassMap>,
    pub editor: SeedEditor,
    /// Seeds revision the worker holds.
    seeds_sent: u64,
    /// Revision and results count at the last save (unsaved-changes check).
    saved: (u64, usize),
    autosaved: (u64, usize),
    last_autosave_s: f64,
    autosave_offer: Option<PathBuf>,
    pending_session: Option<PendingSession>,

    pub frame: usize,
    pub playing: bool,
    play_clock_s: f64,
    pub follow_tracking: bool,
    pub track_range: (usize, usize),

    pub tool: Tool,
    /// Forest class painted (0 = background/tools).
    pub class: usize,
    pub overwrite: bool,
    pub transform: Option<ViewTransform>,
    pub layer: Layer,
    pub styles: Vec<StructureStyle>,

    pub settings: FitSettings,
    pub appearance: Option<Arc<Appearance>>,
    probabilities: HashMap<usize, Arc<Vec<ProbabilityMaps>>>,
    probability_asked: Option<usize>,
    /// Strokes changed at this time (s) and a live retrain is due.
    retrain_due_s: Option<f64>,

    pub placement: Option<Affine>,
    pub results: BTreeMap<usize, FrameResult>,

    pub busy: Option<Busy>,
    pub error: Option<String>,
    pub notice: Option<String>,
    pub show_review: bool,
    confirm_close: bool,
    allow_close: bool,
    textures: views::Textures,
    stroke: views::StrokeState,
    /// Where the views and the timeline were drawn last frame (screen points), for tests.
    pub layout: Layout,
    /// Folder of autosaves (None: the app's data folder).
    pub autosave_dir: Option<PathBuf>,
    loader: frames::FrameLoader,
    /// Folder an export is being written to.
    exporting: Option<PathBuf>,
}

/// Screen rectangles of the last frame's views and timeline strip.
#[derive(Debug, Clone, Default)]
pub struct Layout {
    pub views: Vec<egui::Rect>,
    pub timeline: Option<egui::Rect>,
}

impl EndofuseApp {
    /// The app with its worker, loading `scene` ("demo", a folder or a scene.json).
    pub fn new(cc: &eframe::CreationContext<'_>, scene: &str, dialogs: Box<dyn Dialogs>) -> Self {
        let prefs: Prefs = cc
            .storage
            .and_then(|s| eframe::get_value(s, eframe::APP_KEY))
            .unwrap_or_default();
        let gpu_overlay = match cc.wgpu_render_state.as_ref() {
            Some(rs) => {
                overlay3d::register(rs);
                true
            }
            None => false,
        };
        let mut app = Self {
            worker: Worker::spawn(),
            prefs,
            dialogs,
            gpu_overlay,
            scene: None,
            scene_spec: String::new(),
            loading_spec: None,
            model: None,
            classes: None,
            editor: SeedEditor::default(),
            seeds_sent: 0,
            saved: (0, 0),
            autosaved: (0, 0),
            last_autosave_s: 0.0,
            autosave_offer: None,
            pending_session: None,
            frame: 0,
            playing: false,
            play_clock_s: 0.0,
            follow_tracking: true,
            track_range: (0, 0),
            tool: Tool::Brush,
            class: 1,
            overwrite: false,
            transform: None,
            layer: Layer::Image,
            styles: Vec::new(),
            settings: FitSettings::default(),
            appearance: None,
            probabilities: HashMap::new(),
            probability_asked: None,
            retrain_due_s: None,
            placement: None,
            results: BTreeMap::new(),
            busy: None,
            error: None,
            notice: None,
            show_review: false,
            confirm_close: false,
            allow_close: false,
            textures: views::Textures::default(),
            stroke: views::StrokeState::default(),
            layout: Layout::default(),
            autosave_dir: None,
            loader: frames::FrameLoader::spawn(),
            exporting: None,
        };
        app.open_scene(scene);
        app
    }

    /// Asks the worker to load a scene; the current one stays until the new one arrives.
    pub fn open_scene(&mut self, spec: &str) {
        self.loading_spec = Some(spec.to_string());
        self.busy = Some(Busy {
            task: Task::Load,
            what: format!("Loading {spec}…"),
            done: 0,
            total: 0,
        });
        self.worker.send(Command::LoadScene(spec.to_string()));
    }

    fn scene_loaded(&mut self, scene: Arc<Scene>, model: Arc<Model>) {
        if let Some(spec) = self.loading_spec.take() {
            self.scene_spec = spec;
        }
        self.editor = SeedEditor::new(&scene.seeds, camera_sizes(&scene));
        self.seeds_sent = self.editor.revision;
        self.saved = (self.editor.revision, 0);
        self.autosaved = self.saved;
        self.model = Some(model);
        let classes = ClassMap::from_scene(&scene);
        // Kidney (the first structure class) when there is one, else background.
        self.class = 1.min(classes.len() - 1);
        self.classes = Some(classes);
        self.styles = scene
            .structures
            .iter()
            .map(|_| StructureStyle {
                shown: true,
                opacity: self.prefs.overlay_opacity,
            })
            .collect();
        self.frame = 0;
        self.track_range = (0, scene.frame_count.saturating_sub(1));
        self.transform = None;
        self.layer = Layer::Image;
        self.appearance = None;
        self.probabilities.clear();
        self.probability_asked = None;
        self.placement = scene.initial_pose;
        self.results.clear();
        self.textures = views::Textures::default();
        let spec = self.scene_spec.clone();
        self.prefs.recent.retain(|r| r != &spec);
        if spec != "demo" {
            self.prefs.recent.insert(0, spec.clone());
            self.prefs.recent.truncate(8);
        }
        let autosave = session::autosave_path(&self.autosave_folder(), &spec);
        self.autosave_offer = autosave.exists().then_some(autosave);
        self.scene = Some(scene);
        if let Some(p) = self.pending_session.take() {
            self.apply_session(p.session, &p.path);
        }
    }

    /// The folder of autosaves: the one set (tests), else the app's data folder, else the
    /// temporary folder.
    fn autosave_folder(&self) -> PathBuf {
        self.autosave_dir
            .clone()
            .or_else(|| eframe::storage_dir("endofuse"))
            .unwrap_or_else(std::env::temp_dir)
    }

    /// True when every view shows the current frame (frames decode on a loader thread).
    pub fn frames_ready(&self) -> bool {
        views::frames_ready(self)
    }

    /// True when the probability maps of frame `t` have arrived.
    pub fn has_probabilities(&self, t: usize) -> bool {
        self.probabilities.contains_key(&t)
    }

    /// True when strokes or results changed since the last save.
    pub fn unsaved(&self) -> bool {
        self.scene.is_some() && (self.editor.revision, self.results.len()) != self.saved
    }

    pub fn session(&self) -> Session {
        Session {
            format: SESSION_FORMAT.into(),
            scene: self.scene_spec.clone(),
            seeds: session::encode_seeds(&self.editor.seeds()),
            settings: self.settings.clone(),
            placement: self.placement,
            forest: self.appearance.as_deref().cloned(),
            results: self.results.values().cloned().collect(),
        }
    }

    /// Restores a session's seeds, settings, forest and results onto the loaded scene.
    fn apply_session(&mut self, s: Session, path: &Path) {
        let Some(scene) = self.scene.clone() else {
            return;
        };
        let sizes = camera_sizes(&scene);
        match session::decode_seeds(&s.seeds, &sizes, path) {
            Ok(seeds) => {
                self.editor = SeedEditor::new(&seeds, sizes);
                // Loaded strokes count as a change until saved again under a session name.
                self.editor.revision = self.seeds_sent + 1;
            }
            Err(e) => {
                self.error = Some(e.to_string());
                return;
            }
        }
        self.settings = s.settings;
        self.placement = s.placement.or(self.placement);
        if let Some(f) = s.forest {
            if Some(&f.classes) == self.classes.as_ref() {
                let f = Arc::new(f);
                self.worker.send(Command::SetAppearance(f.clone()));
                self.appearance = Some(f);
            } else {
                self.notice =
                    Some("The session's forest is for other classes: train again.".into());
            }
        }
        self.results = s
            .results
            .into_iter()
            .filter(|r| {
                r.frame < scene.frame_count && r.state.intrinsics.len() == scene.cameras.len()
            })
            .map(|r| (r.frame, r))
            .collect();
        self.textures = views::Textures::default();
        self.notice = Some(format!("Session {} restored.", path.display()));
    }

    fn load_session_file(&mut self, path: &Path) {
        match Session::load(path) {
            Ok(s) => {
                if s.scene == self.scene_spec && self.scene.is_some() {
                    self.apply_session(s, path);
                } else {
                    let spec = s.scene.clone();
                    self.pending_session = Some(PendingSession {
                        session: s,
                        path: path.to_path_buf(),
                    });
                    self.open_scene(&spec);
                }
            }
            Err(e) => self.error = Some(e.to_string()),
        }
    }

    fn save_session_to(&mut self, path: &Path) {
        match self.session().save(path) {
            Ok(()) => {
                self.saved = (self.editor.revision, self.results.len());
                self.notice = Some(format!("Saved {}", path.display()));
                let _ = std::fs::remove_file(session::autosave_path(
                    &self.autosave_folder(),
                    &self.scene_spec,
                ));
            }
            Err(e) => self.error = Some(e.to_string()),
        }
    }

    /// Writes the autosave every few seconds when something changed, on a helper thread.
    fn autosave(&mut self, now_s: f64) {
        let state = (self.editor.revision, self.results.len());
        if self.scene.is_none()
            || self.editor.in_stroke()
            || state == self.autosaved
            || state == self.saved
            || now_s - self.last_autosave_s < 3.0
        {
            return;
        }
        self.last_autosave_s = now_s;
        self.autosaved = state;
        let session = self.session();
        let path = session::autosave_path(&self.autosave_folder(), &self.scene_spec);
        std::thread::spawn(move || {
            let _ = session.save(&path);
        });
    }

    /// Seeds for the worker, if they changed since it last had them.
    fn sync_seeds(&mut self) {
        if self.seeds_sent != self.editor.revision {
            self.worker.send(Command::SetSeeds(self.editor.seeds()));
            self.seeds_sent = self.editor.revision;
        }
    }

    fn forest_params(&self) -> ForestParams {
        ForestParams {
            trees: self.settings.trees.clamp(1, 200),
            ..ForestParams::default()
        }
    }

    pub fn train(&mut self) {
        if self.scene.is_none() {
            return;
        }
        let counts = self.editor.counts();
        if counts.is_empty() {
            self.error =
                Some("Paint some seeds first: background/tools and each structure.".into());
            return;
        }
        self.sync_seeds();
        self.retrain_due_s = None;
        self.busy = Some(Busy {
            task: Task::Train,
            what: "Training the forest…".into(),
            done: 0,
            total: 0,
        });
        self.worker.send(Command::Train(self.forest_params()));
    }

    fn ask_probabilities(&mut self) {
        if self.appearance.is_none()
            || self.layer == Layer::Image
            || self.probabilities.contains_key(&self.frame)
            || self.probability_asked.is_some()
        {
            return;
        }
        self.probability_asked = Some(self.frame);
        self.worker.send(Command::Classify { frame: self.frame });
    }

    pub fn mode(&self) -> Mode {
        match Mode::parse(&self.settings.mode).unwrap_or(Mode::LS) {
            Mode::LSC if !self.settings.camera_correction => Mode::LS,
            m => m,
        }
    }

    fn need_forest(&mut self) -> bool {
        if self.appearance.is_none() {
            self.error = Some("Train the forest first (T).".into());
            return false;
        }
        true
    }

    pub fn track(&mut self, frames: (usize, usize)) {
        if !self.need_forest() {
            return;
        }
        let Some(scene) = &self.scene else {
            return;
        };
        let last = scene.frame_count.saturating_sub(1);
        let frames = (
            frames.0.min(last),
            frames.1.min(last).max(frames.0.min(last)),
        );
        // Start from what is known at the first frame: its fit, else the placement.
        let start = self
            .results
            .get(&frames.0)
            .filter(|r| !r.lost)
            .map(|r| r.state.affine)
            .or(self.placement);
        self.follow_tracking = true;
        self.busy = Some(Busy {
            task: Task::Track,
            what: format!(
                "Tracking frames {}–{} ({})…",
                frames.0,
                frames.1,
                self.mode().name()
            ),
            done: 0,
            total: frames.1 + 1 - frames.0,
        });
        self.worker.send(Command::Track {
            mode: self.mode(),
            frames,
            start,
        });
    }

    pub fn do_action(&mut self, a: Action, ctx: &egui::Context) {
        let frames = self.scene.as_ref().map(|s| s.frame_count).unwrap_or(1);
        match a {
            Action::OpenScene => {
                if let Some(p) = self.dialogs.pick_scene() {
                    self.open_scene(&p.display().to_string());
                }
            }
            Action::OpenDemo => self.open_scene("demo"),
            Action::SaveSession => {
                if let Some(p) = self.dialogs.save_session() {
                    self.save_session_to(&p);
                }
            }
            Action::LoadSession => {
                if let Some(p) = self.dialogs.pick_session() {
                    self.load_session_file(&p);
                }
            }
            Action::SaveSeeds => self.save_seed_pngs(),
            Action::Export => self.export(),
            Action::Brush => self.tool = Tool::Brush,
            Action::Eraser => self.tool = Tool::Eraser,
            Action::Place => self.tool = Tool::Place,
            Action::BrushSmaller | Action::BrushBigger => {
                let f = if a == Action::BrushBigger { 1.25 } else { 0.8 };
                self.resize_brush(f);
            }
            Action::Undo => {
                self.editor.undo();
            }
            Action::Redo => {
                self.editor.redo();
            }
            Action::Train => self.train(),
            Action::ShowImage => self.layer = Layer::Image,
            Action::ShowProbability => {
                let k = match self.layer {
                    Layer::Probability(k) => k,
                    _ => self.class,
                };
                self.layer = Layer::Probability(k);
            }
            Action::ShowUncertainty => self.layer = Layer::Uncertainty,
            Action::Initialise => {
                if self.need_forest() {
                    self.busy = Some(Busy {
                        task: Task::Initialise,
                        what: format!("Placing the model on frame {}…", self.frame),
                        done: 0,
                        total: 0,
                    });
                    self.worker.send(Command::Initialise { frame: self.frame });
                }
            }
            Action::FitFrame => self.track((self.frame, self.frame)),
            Action::Track => self.track(self.track_range),
            Action::Cancel => {
                if self.busy.is_some() {
                    self.worker.cancel();
                }
                self.playing = false;
            }
            Action::PlayPause => {
                self.playing = !self.playing;
                self.play_clock_s = ctx.input(|i| i.time);
            }
            Action::StepBack => self.set_frame(self.frame.saturating_sub(1)),
            Action::StepForward => self.set_frame((self.frame + 1).min(frames - 1)),
            Action::FirstFrame => self.set_frame(0),
            Action::LastFrame => self.set_frame(frames - 1),
            Action::ResetView => self.transform = None,
            Action::Review => self.show_review = !self.show_review,
        }
    }

    pub fn resize_brush(&mut self, factor: f32) {
        let r = match self.tool {
            Tool::Eraser => &mut self.prefs.eraser_px,
            _ => &mut self.prefs.brush_px,
        };
        *r = (*r * factor).clamp(1.0, 200.0);
    }

    /// Moves to frame `t` (the user scrubbed: stop following the tracker).
    pub fn set_frame(&mut self, t: usize) {
        if t != self.frame {
            self.follow_tracking = false;
        }
        self.frame = t;
    }

    /// Writes the painted seeds as the contract's label PNGs: into the scene's seeds folder
    /// (its `seeds` template, or `seeds/{camera}/{frame:06}.png` added to scene.json), or for
    /// the demo into a folder the user picks.
    fn save_seed_pngs(&mut self) {
        let Some(scene) = self.scene.clone() else {
            return;
        };
        let seeds = self.editor.seeds();
        let result = match &scene.root {
            Some(root) => write_seeds_into_scene(&scene, root, &seeds),
            None => match self.dialogs.pick_folder("Folder for the seed PNGs") {
                Some(dir) => {
                    let flat = PathTemplate::parse("{camera}/{frame:06}.png")
                        .expect("the folder template is valid");
                    write_seed_pngs(&scene, &dir, &flat, &seeds).map(|n| (n, dir))
                }
                None => return,
            },
        };
        match result {
            Ok((n, dir)) => {
                self.notice = Some(format!("Wrote {n} seed PNGs under {}", dir.display()))
            }
            Err(e) => self.error = Some(e.to_string()),
        }
    }

    /// Exports masks, overlay PNGs, trajectory.json and metrics.json of the tracked frames
    /// through the same writer as `endofuse track` (on the worker).
    fn export(&mut self) {
        let (Some(scene), Some(model)) = (self.scene.clone(), self.model.clone()) else {
            return;
        };
        if self.results.is_empty() {
            self.error = Some("Nothing tracked yet to export.".into());
            return;
        }
        let Some(dir) = self.dialogs.pick_folder("Export tracking results to") else {
            return;
        };
        let results: Vec<FrameResult> = self.results.values().cloned().collect();
        let mode = self.mode();
        let train_s = self
            .appearance
            .as_ref()
            .map(|a| a.stats.train_s)
            .unwrap_or(f64::NAN);
        self.busy = Some(Busy {
            task: Task::Job,
            what: format!("Exporting to {}…", dir.display()),
            done: 0,
            total: 0,
        });
        self.exporting = Some(dir.clone());
        self.worker.send(Command::Run(Box::new(move || {
            export_results(&scene, &model, &results, mode, &dir, train_s).map(|_| ())
        })));
    }

    fn handle_event(&mut self, e: Event, ctx: &egui::Context) {
        match e {
            Event::SceneLoaded { scene, model } => {
                self.error = None;
                self.scene_loaded(scene, model);
            }
            Event::Trained(a) => {
                self.notice = Some(format!(
                    "Forest trained on {} pixels in {:.2} s, out-of-bag error {:.2} %",
                    a.stats.samples,
                    a.stats.train_s,
                    a.stats.oob_error * 100.0
                ));
                self.appearance = Some(a);
                self.probabilities.clear();
                self.probability_asked = None;
                self.textures.probability_key = None;
                if self.layer == Layer::Image {
                    self.layer = Layer::Probability(self.class);
                }
            }
            Event::Probabilities { frame, maps } => {
                self.probability_asked = None;
                if self.probabilities.len() > 8 {
                    self.probabilities.clear();
                }
                self.probabilities.insert(frame, maps);
            }
            Event::Initialised(a) => {
                self.placement = Some(a);
                self.notice =
                    Some("Model placed: check it, then Fit this frame (F) or Track.".into());
            }
            Event::Progress { task, done, total } => {
                if let Some(b) = &mut self.busy
                    && b.task == task
                {
                    b.done = done;
                    b.total = total;
                }
            }
            Event::Frame(f) => {
                let r = FrameResult {
                    frame: f.frame,
                    state: f.state.clone(),
                    energy: f.energy,
                    confidence: f.confidence,
                    lost: f.lost,
                    ms: f.ms,
                    dice: Vec::new(),
                };
                if self.follow_tracking {
                    self.frame = f.frame;
                }
                self.results.insert(f.frame, r);
            }
            Event::Dice { frame, dice } => {
                if let Some(r) = self.results.get_mut(&frame) {
                    r.dice = dice;
                }
            }
            Event::Finished(task) => self.task_ended(task, true),
            Event::Cancelled(task) => {
                self.task_ended(task, false);
                self.notice = Some("Cancelled.".into());
            }
            Event::Failed { task, message } => {
                self.task_ended(task, false);
                self.error = Some(message);
            }
        }
        ctx.request_repaint();
    }

    /// Bookkeeping when the worker ends `task`, however it ended (`finished`: it completed).
    fn task_ended(&mut self, task: Task, finished: bool) {
        if self.busy.as_ref().is_some_and(|b| b.task == task) {
            self.busy = None;
        }
        match task {
            Task::Classify => self.probability_asked = None,
            Task::Load if !finished => {
                self.pending_session = None;
                self.loading_spec = None;
            }
            Task::Job => {
                if let Some(dir) = self.exporting.take()
                    && finished
                {
                    self.notice = Some(format!("Exported the tracked frames to {}", dir.display()));
                }
            }
            _ => {}
        }
    }

    /// Drains worker events; plays; schedules live retraining; autosaves.
    fn tick(&mut self, ctx: &egui::Context) {
        for e in self.worker.drain() {
            self.handle_event(e, ctx);
        }
        views::receive_frames(self, ctx);
        let now = ctx.input(|i| i.time);
        if self.playing
            && let Some(scene) = &self.scene
        {
            let dt = 1.0 / scene.fps.clamp(1.0, 120.0);
            if now - self.play_clock_s >= dt {
                self.play_clock_s = now;
                self.frame = (self.frame + 1) % scene.frame_count.max(1);
            }
            ctx.request_repaint();
        }
        if self.settings.live_update
            && self.seeds_sent != self.editor.revision
            && !self.editor.in_stroke()
        {
            let due = *self.retrain_due_s.get_or_insert(now + 0.6);
            if now >= due && self.busy.is_none() {
                self.train();
            }
            ctx.request_repaint_after(std::time::Duration::from_millis(200));
        }
        self.ask_probabilities();
        self.autosave(now);
        if self.busy.is_some() {
            ctx.request_repaint_after(std::time::Duration::from_millis(50));
        }
    }

    fn shortcuts(&mut self, ctx: &egui::Context) {
        if ctx.egui_wants_keyboard_input() {
            return;
        }
        for a in Action::ALL {
            if let Some(s) = a.shortcut()
                && ctx.input_mut(|i| i.consume_shortcut(&s))
            {
                self.do_action(a, ctx);
            }
        }
        let classes = self.classes.as_ref().map(|c| c.len()).unwrap_or(0);
        for (k, key) in actions::CLASS_KEYS.iter().enumerate().take(classes) {
            if ctx.input_mut(|i| i.consume_key(egui::Modifiers::NONE, *key)) {
                self.class = k;
                if self.tool == Tool::Eraser || self.tool == Tool::Place {
                    self.tool = Tool::Brush;
                }
                if let Layer::Probability(_) = self.layer {
                    self.layer = Layer::Probability(k);
                }
            }
        }
    }

    fn dropped_files(&mut self, ctx: &egui::Context) {
        let dropped: Vec<PathBuf> = ctx.input(|i| {
            i.raw
                .dropped_files
                .iter()
                .map(|f| f.path().to_path_buf())
                .filter(|p| !p.as_os_str().is_empty())
                .collect()
        });
        if let Some(p) = dropped.first() {
            let is_session = p.is_file()
                && std::fs::read_to_string(p)
                    .ok()
                    .is_some_and(|t| t.contains(SESSION_FORMAT));
            if is_session {
                self.load_session_file(p);
            } else {
                self.open_scene(&p.display().to_string());
            }
        }
    }

    /// The state drawn at frame `t`: its fit, else the placement (mean shape, calibration).
    pub fn state_at(&self, t: usize) -> Option<FitState> {
        if let Some(r) = self.results.get(&t) {
            return Some(r.state.clone());
        }
        let (scene, model) = (self.scene.as_ref()?, self.model.as_ref()?);
        let affine = self.placement?;
        Some(crate::fit::tracker::initial_state(scene, model, affine))
    }

    fn close_guard(&mut self, ctx: &egui::Context) {
        if ctx.input(|i| i.viewport().close_requested()) && self.unsaved() && !self.allow_close {
            ctx.send_viewport_cmd(egui::ViewportCommand::CancelClose);
            self.confirm_close = true;
        }
        if !self.confirm_close {
            return;
        }
        egui::Modal::new(egui::Id::unique("confirm-close")).show(ctx, |ui| {
            ui.heading("Save changes before closing?");
            ui.label("Your strokes or tracking results are not saved in a session file.");
            ui.horizontal(|ui| {
                if ui.button("Save…").clicked() {
                    if let Some(p) = self.dialogs.save_session() {
                        self.save_session_to(&p);
                        self.allow_close = true;
                        ctx.send_viewport_cmd(egui::ViewportCommand::Close);
                    }
                    self.confirm_close = false;
                }
                if ui.button("Close without saving").clicked() {
                    self.allow_close = true;
                    self.confirm_close = false;
                    ctx.send_viewport_cmd(egui::ViewportCommand::Close);
                }
                if ui.button("Cancel").clicked() {
                    self.confirm_close = false;
                }
            });
        });
    }
}

impl eframe::App for EndofuseApp {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        let ctx = ui.ctx().clone();
        self.tick(&ctx);
        self.shortcuts(&ctx);
        self.dropped_files(&ctx);
        panels::menu_bar(self, ui);
        panels::status_bar(self, ui);
        panels::timeline(self, ui);
        panels::side_panel(self, ui);
        egui::CentralPanel::default().show(ui, |ui| views::views(self, ui));
        if self.show_review {
            panels::review_window(self, &ctx);
        }
        self.close_guard(&ctx);
    }

    fn save(&mut self, storage: &mut dyn eframe::Storage) {
        eframe::set_value(storage, eframe::APP_KEY, &self.prefs);
    }
}

/// (width, height) of every camera of a scene.
fn camera_sizes(scene: &Scene) -> Vec<(usize, usize)> {
    scene
        .cameras
        .iter()
        .map(|c| (c.width as usize, c.height as usize))
        .collect()
}

/// Opens the desktop app on `scene` (blocks until the window closes).
pub fn run_native(scene: &str) -> anyhow::Result<()> {
    let options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_title("endofuse")
            .with_inner_size([1400.0, 820.0])
            .with_drag_and_drop(true),
        ..Default::default()
    };
    let scene = scene.to_string();
    eframe::run_native(
        "endofuse",
        options,
        Box::new(move |cc| Ok(Box::new(EndofuseApp::new(cc, &scene, Box::new(RfdDialogs))))),
    )
    .map_err(|e| anyhow::anyhow!("cannot open the window: {e}"))
}

/// Where seed PNGs go in a scene folder whose scene.json names none.
const DEFAULT_SEEDS_TEMPLATE: &str = "seeds/{camera}/{frame:06}.png";

/// Writes every painted view and frame as a label PNG at `dir`/`template`; returns how many.
fn write_seed_pngs(
    scene: &Scene,
    dir: &Path,
    template: &PathTemplate,
    seeds: &crate::scene::Seeds,
) -> Result<usize, crate::Error> {
    let mut n = 0;
    for (c, frames) in seeds.by_camera.iter().enumerate() {
        for (&t, img) in frames {
            let path = dir.join(template.expand(t, &scene.cameras[c].name, ""));
            crate::scene::write::write_labels(&path, img)?;
            n += 1;
        }
    }
    Ok(n)
}

/// Writes seed PNGs into a scene folder; adds a `seeds` entry to its scene.json when it has
/// none. Returns how many files were written and where.
fn write_seeds_into_scene(
    scene: &Scene,
    root: &Path,
    seeds: &crate::scene::Seeds,
) -> Result<(usize, PathBuf), crate::Error> {
    let template = scene.seeds_template.clone().unwrap_or_else(|| {
        PathTemplate::parse(DEFAULT_SEEDS_TEMPLATE).expect("the default template is valid")
    });
    let n = write_seed_pngs(scene, root, &template, seeds)?;
    if scene.seeds_template.is_none() {
        let json = root.join("scene.json");
        let text = std::fs::read_to_string(&json).map_err(|source| crate::Error::Write {
            path: json.clone(),
            source,
        })?;
        let mut v: serde_json::Value = serde_json::from_str(&text)
            .map_err(|e| crate::error::input_err(json.display().to_string(), e.to_string()))?;
        if let Some(o) = v.as_object_mut() {
            o.insert("seeds".into(), template.source().into());
        }
        crate::scene::write::write_json_atomic(&json, &v)?;
    }
    Ok((n, root.to_path_buf()))
}

/// Re-renders tracked states and writes them as `endofuse track` does, plus overlay PNGs.
pub fn export_results(
    scene: &Scene,
    model: &Model,
    results: &[FrameResult],
    mode: Mode,
    dir: &Path,
    forest_train_s: f64,
) -> Result<crate::track::TrackMetrics, crate::Error> {
    let mut recorder = crate::track::Recorder::new(scene, dir, mode);
    recorder.overlays = true;
    for r in results {
        let rendered = crate::fit::tracker::render_state(scene, model, &r.state);
        recorder.record(&TrackedFrame {
            frame: r.frame,
            state: r.state.clone(),
            energy: r.energy,
            iterations: 0,
            ms: r.ms,
            confidence: r.confidence,
            lost: r.lost,
            labels: rendered.labels,
            hidden: rendered.hidden,
            centroids: rendered.centroids,
        })?;
    }
    recorder.finish(forest_train_s)
}
