//! What the app asks of the worker and what comes back: loading a scene, training, classifying
//! a frame for the probability view, placing, tracking and exporting are typed worker commands;
//! the worker's events are drained each frame and turned into state here. Nothing waits.

use super::EndofuseApp;
use super::state::{Layer, StructureStyle};
use crate::appearance::{ClassMap, ForestParams, ProbabilityMaps};
use crate::fit::Model;
use crate::scene::Scene;
use crate::session::{FrameResult, Session};
use crate::strokes::SeedEditor;
use crate::worker::{Command, Event, Task};
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;

/// A session waiting for its scene to load.
pub(super) struct PendingSession {
    pub session: Session,
    pub path: PathBuf,
}

/// The app's side of the conversation with the worker.
#[derive(Default)]
pub struct Jobs {
    /// Seeds revision the worker holds.
    seeds_sent: u64,
    /// The scene being loaded (it becomes the document's once it arrives).
    loading_spec: Option<String>,
    pub(super) pending_session: Option<PendingSession>,
    /// Folder an export is being written to.
    exporting: Option<PathBuf>,
    /// Probability maps of recent frames, one per camera.
    pub probabilities: HashMap<usize, Arc<Vec<ProbabilityMaps>>>,
    /// The frame and request number of the maps asked for: only that answer is taken (a
    /// request queued under an earlier forest must not pass for the current one's).
    probability_asked: Option<(usize, u64)>,
    probability_requests: u64,
    /// Frames whose maps are shown until better ones come: the quick coarse map, or the
    /// earlier forest's maps after a retrain (no blank flash on every live retrain).
    probability_refresh: std::collections::HashSet<usize>,
    /// Forests set (loaded, dropped, a scene opened) so far, and the count when the pending
    /// Train was sent: a Trained overtaken by a later forest is dropped, as the worker's was.
    forest_epoch: u64,
    train_epoch: u64,
    /// Counts every forest put in use (trained, loaded, dropped; a held-out figure arriving
    /// for the same forest does not count), and the count each frame's fit was made under:
    /// fits of an earlier forest are said to be so, not shown as current.
    forest_generation: u64,
    fit_generation: HashMap<usize, u64>,
    /// The strokes' revision the pending Train was sent with, and the one the forest in use
    /// learned (None where unknown: a forest loaded from a session).
    train_revision: u64,
    pub forest_revision: Option<u64>,
    /// The forest in use awaits its held-out figure (Command::Validate sent).
    pub validating: bool,
    /// Strokes changed at this time (s) and a live retrain is due.
    retrain_due_s: Option<f64>,
    /// The fit's configuration the worker tracks with (recorded in exports).
    pub config: crate::fit::FitConfig,
}

/// Probability maps kept for frames already shown (scrubbing back shows them at once), up
/// to this many bytes: at 1080p stereo with three classes one frame's maps take 50 MB, and a
/// count of frames alone let them grow with the resolution.
const PROBABILITY_CACHE_BYTES: usize = 256 << 20;

impl Jobs {
    /// How many of `fitted` frames were fitted with an earlier forest than the one in use.
    pub fn fits_of_earlier_forests(&self, fitted: impl Iterator<Item = usize>) -> usize {
        fitted
            .filter(|t| self.fit_generation.get(t) != Some(&self.forest_generation))
            .count()
    }

    /// Counts `frames`' fits as made with the forest in use (they arrived with it).
    pub(super) fn fitted_with_current_forest(&mut self, frames: impl Iterator<Item = usize>) {
        for t in frames {
            self.fit_generation.insert(t, self.forest_generation);
        }
    }

    /// Keeps `frame`'s maps; over [`PROBABILITY_CACHE_BYTES`] the frames farthest from it go
    /// first (it stays, however large).
    fn keep_maps(&mut self, frame: usize, maps: Arc<Vec<ProbabilityMaps>>) {
        let bytes = |m: &Arc<Vec<ProbabilityMaps>>| -> usize {
            m.iter()
                .map(|p| p.data.len() * std::mem::size_of::<f32>())
                .sum()
        };
        self.probabilities.insert(frame, maps);
        let mut total: usize = self.probabilities.values().map(bytes).sum();
        while total > PROBABILITY_CACHE_BYTES && self.probabilities.len() > 1 {
            let Some(&far) = self
                .probabilities
                .keys()
                .max_by_key(|&&t| t.abs_diff(frame))
            else {
                break;
            };
            if let Some(m) = self.probabilities.remove(&far) {
                total -= bytes(&m);
            }
            self.probability_refresh.remove(&far);
        }
    }

    /// Another forest or scene: no maps, request or held-out figure of the earlier one stays.
    fn forget_maps(&mut self) {
        self.probabilities.clear();
        self.probability_refresh.clear();
        self.probability_asked = None;
        self.validating = false;
    }
}

/// (width, height) of every camera of a scene.
pub(super) fn camera_sizes(scene: &Scene) -> Vec<(usize, usize)> {
    scene
        .cameras
        .iter()
        .map(|c| (c.width as usize, c.height as usize))
        .collect()
}

impl EndofuseApp {
    /// Queues a worker command; a worker that is gone is said once.
    fn send_job(&mut self, command: Command) {
        if !self.worker.send(command) {
            self.status.busy = None;
            self.status
                .fail("the background worker has stopped: save your session and restart the app");
        }
    }

    /// Asks the worker to build a new scene folder (File → New scene); it opens when built.
    pub fn create_scene(&mut self, options: crate::newscene::NewSceneOptions) {
        self.status
            .busy_with(Task::NewScene, "Creating the scene…".into(), 0);
        self.send_job(Command::NewScene(Box::new(options)));
    }

    /// Asks the worker to load a scene; the current one stays until the new one arrives.
    pub fn open_scene(&mut self, spec: &str) {
        self.jobs.loading_spec = Some(spec.to_string());
        self.status
            .busy_with(Task::Load, format!("Loading {spec}…"), 0);
        self.send_job(Command::LoadScene(spec.to_string()));
    }

    fn scene_loaded(&mut self, scene: Arc<Scene>, model: Arc<Model>) {
        if let Some(spec) = self.jobs.loading_spec.take() {
            self.doc.spec = spec;
        }
        let doc = &mut self.doc;
        doc.editor = SeedEditor::new(&scene.seeds, camera_sizes(&scene));
        self.jobs.seeds_sent = doc.editor.revision;
        doc.saved = doc.revision();
        doc.autosaved = doc.saved;
        doc.model = Some(model);
        let classes = ClassMap::from_scene(&scene);
        // Kidney (the first structure class) when there is one, else background.
        self.view.class = 1.min(classes.len() - 1);
        doc.classes = Some(classes);
        self.view.styles = scene
            .structures
            .iter()
            .map(|_| StructureStyle {
                shown: true,
                opacity: self.prefs.overlay_opacity,
            })
            .collect();
        self.view.frame = 0;
        self.view.track_range = (0, scene.frame_count.saturating_sub(1));
        self.view.transform = None;
        self.view.layer = Layer::Image;
        doc.appearance = None;
        self.jobs.forget_maps();
        self.jobs.forest_epoch += 1;
        doc.placement = scene.initial_pose;
        doc.results.clear();
        doc.forget_placement_undo();
        self.screen.textures = Default::default();
        self.screen.stroke = Default::default();
        let spec = doc.spec.clone();
        self.prefs.recent.retain(|r| r != &spec);
        if spec != crate::open::DEMO {
            self.prefs.recent.insert(0, spec.clone());
            self.prefs.recent.truncate(8);
        }
        doc.scene = Some(scene);
        self.offer_autosave();
        if let Some(p) = self.jobs.pending_session.take() {
            self.apply_session(p.session, &p.path);
        }
    }

    /// Marks seeds loaded from a session as changed: they reach the worker before the next
    /// training, and count as unsaved until saved again under a session name.
    pub(super) fn seeds_loaded(&mut self) {
        // Loaded strokes count as a change until saved again under a session name.
        self.doc.editor.revision = self.jobs.seeds_sent + 1;
    }

    /// Uses a forest the app holds (a loaded session): the worker gets it too.
    pub(super) fn use_forest(&mut self, forest: Arc<crate::appearance::Appearance>) {
        self.jobs.forest_epoch += 1;
        self.send_job(Command::SetAppearance(Some(forest.clone())));
        self.forest_changed(Some(forest));
    }

    /// No forest (a session restored from before training).
    pub(super) fn drop_forest(&mut self) {
        self.jobs.forest_epoch += 1;
        self.send_job(Command::SetAppearance(None));
        self.forest_changed(None);
        self.view.layer = Layer::Image;
    }

    /// The forest is another one (trained, loaded or dropped): the maps of the one before go.
    fn forest_changed(&mut self, forest: Option<Arc<crate::appearance::Appearance>>) {
        // Which strokes it learned is known only for a Trained forest (set after this).
        self.jobs.forest_revision = None;
        let frame = self.view.frame;
        let keep = forest
            .is_some()
            .then(|| self.jobs.probabilities.remove(&frame))
            .flatten();
        self.doc.appearance = forest;
        self.doc.touch();
        self.jobs.forest_generation += 1;
        self.jobs.forget_maps();
        if let Some(maps) = keep {
            self.jobs.probabilities.insert(frame, maps);
            self.jobs.probability_refresh.insert(frame);
        }
        self.screen.textures.probability_key = None;
    }

    /// Seeds for the worker, if they changed since it last had them.
    fn sync_seeds(&mut self) {
        if self.jobs.seeds_sent != self.doc.editor.revision {
            self.send_job(Command::SetSeeds(self.doc.editor.seeds()));
            self.jobs.seeds_sent = self.doc.editor.revision;
        }
    }

    /// The forest's settings; `live`: the preview retrained after a stroke.
    fn forest_params(&self, live: bool) -> ForestParams {
        ForestParams {
            trees: self.doc.settings.trees.clamp(1, 200),
            max_samples_per_tree: if live {
                self.doc.settings.live_preview_samples
            } else {
                0
            },
            ..ForestParams::default()
        }
    }

    /// Trains the full forest (`Train forest`, T).
    pub fn train(&mut self) {
        self.train_with(false);
    }

    /// Tracking and placing stand on the full forest: when the one in use is a live preview,
    /// the full one is trained first (the worker runs commands in order, so the job that
    /// follows uses it).
    fn full_forest_first(&mut self) {
        if self
            .doc
            .appearance
            .as_ref()
            .is_some_and(|a| a.is_live_preview())
        {
            self.send_train(false);
        }
    }

    /// Sends the worker the current seeds and a Train; a live retrain that was due is
    /// superseded.
    fn send_train(&mut self, live: bool) {
        self.sync_seeds();
        self.jobs.retrain_due_s = None;
        self.jobs.train_epoch = self.jobs.forest_epoch;
        self.jobs.train_revision = self.doc.editor.revision;
        self.send_job(Command::Train(self.forest_params(live)));
    }

    fn train_with(&mut self, live: bool) {
        if self.doc.scene.is_none() {
            return;
        }
        if self.doc.editor.counts().is_empty() {
            self.status
                .fail("Paint some seeds first: background/tools and each structure.");
            return;
        }
        self.status
            .busy_with(Task::Train, "Training the forest…".into(), 0);
        self.send_train(live);
    }

    fn ask_probabilities(&mut self) {
        let frame = self.view.frame;
        if self.doc.appearance.is_none()
            || self.view.layer == Layer::Image
            || (self.jobs.probabilities.contains_key(&frame)
                && !self.jobs.probability_refresh.contains(&frame))
            || self.jobs.probability_asked.is_some()
        {
            return;
        }
        self.jobs.probability_requests += 1;
        let request = self.jobs.probability_requests;
        self.jobs.probability_asked = Some((frame, request));
        self.send_job(Command::Classify { frame, request });
    }

    /// True when the full probability maps of frame `t` from the current forest have arrived.
    pub fn has_probabilities(&self, t: usize) -> bool {
        self.jobs.probabilities.contains_key(&t) && !self.jobs.probability_refresh.contains(&t)
    }

    fn need_forest(&mut self) -> bool {
        if self.doc.appearance.is_none() {
            self.status.fail("Train the forest first (T).");
            return false;
        }
        true
    }

    pub(super) fn initialise(&mut self) {
        if self.need_forest() {
            self.full_forest_first();
            let frame = self.view.frame;
            self.status.busy_with(
                Task::Initialise,
                format!("Placing the model on frame {frame}…"),
                0,
            );
            self.send_job(Command::Initialise { frame });
        }
    }

    pub fn track(&mut self, frames: (usize, usize)) {
        if !self.need_forest() {
            return;
        }
        let Some(scene) = &self.doc.scene else {
            return;
        };
        let last = scene.frame_count.saturating_sub(1);
        let frames = (
            frames.0.min(last),
            frames.1.min(last).max(frames.0.min(last)),
        );
        // Start from what is known at the first frame: its fit, else the placement.
        let start = self
            .doc
            .results
            .get(&frames.0)
            .filter(|r| !r.lost)
            .map(|r| r.state.affine)
            .or(self.doc.placement);
        self.view.follow_tracking = true;
        self.full_forest_first();
        let mode = self.doc.mode();
        self.status.busy_with(
            Task::Track,
            format!(
                "Tracking frames {}–{} ({})…",
                frames.0,
                frames.1,
                mode.name()
            ),
            frames.1 + 1 - frames.0,
        );
        self.send_job(Command::Track {
            mode,
            frames,
            start,
        });
    }

    /// Exports masks, overlay PNGs, trajectory.json and metrics.json of the tracked frames
    /// through the same writer as `endofuse track` (on the worker).
    pub(super) fn export(&mut self, ctx: &egui::Context) {
        if self.doc.scene.is_none() || self.doc.model.is_none() {
            return;
        }
        if self.doc.results.is_empty() {
            self.status.fail("Nothing tracked yet to export.");
            return;
        }
        self.request_path(super::pickers::FileRequest::Export, ctx);
    }

    /// Exports into `dir` when it is empty or new; asks first when it holds an earlier export;
    /// refuses any other folder.
    pub(super) fn export_into(&mut self, dir: std::path::PathBuf) {
        match crate::export::check_export_folder(&dir) {
            Ok(crate::export::ExportFolder::Fresh) => self.export_to(dir),
            Ok(crate::export::ExportFolder::EarlierExport) => {
                self.confirm = Some(super::confirm::Confirm::ReplaceExport(dir));
            }
            Err(e) => self.status.fail(e.to_string()),
        }
    }

    /// Exports into `dir`, checked (or confirmed) already.
    pub(super) fn export_to(&mut self, dir: std::path::PathBuf) {
        let (Some(scene), Some(model)) = (self.doc.scene.clone(), self.doc.model.clone()) else {
            return;
        };
        let forest_train_s = self
            .doc
            .appearance
            .as_ref()
            .map_or(f64::NAN, |a| a.stats.train_s);
        self.status
            .busy_with(Task::Export, format!("Exporting to {}…", dir.display()), 0);
        self.jobs.exporting = Some(dir.clone());
        self.send_job(Command::Export(Box::new(crate::export::ExportJob {
            scene,
            model,
            results: self.doc.results.values().cloned().collect(),
            mode: self.doc.mode(),
            dir,
            forest_train_s,
            config: self.jobs.config.clone(),
        })));
    }

    fn handle_event(&mut self, e: Event, ctx: &egui::Context) {
        match e {
            Event::SceneLoaded { scene, model } => {
                self.status.error = None;
                self.scene_loaded(scene, model);
            }
            // A forest loaded or dropped after this Train was sent replaced it in the worker
            // too: it is not the one in use.
            Event::Trained(_) if self.jobs.train_epoch != self.jobs.forest_epoch => {}
            Event::Trained(a) => {
                let preview = if a.is_live_preview() {
                    " (a live preview: each tree drew a sample of them; Track and Place retrain on all)"
                } else {
                    ""
                };
                self.status.notify(format!(
                    "Forest trained on {} samples (the painted pixels and their coarser pyramid levels) in {:.2} s{preview}; checking it on strokes it did not learn…",
                    a.stats.samples, a.stats.train_s
                ));
                self.forest_changed(Some(a));
                self.jobs.forest_revision = Some(self.jobs.train_revision);
                if self.view.layer == Layer::Image {
                    self.view.layer = Layer::Probability(self.view.class);
                }
                // The visible frame's maps first, the held-out figure after.
                self.ask_probabilities();
                self.send_job(Command::Validate);
                self.jobs.validating = true;
            }
            Event::Validated { of, validated } => {
                let current = self
                    .doc
                    .appearance
                    .as_ref()
                    .is_some_and(|a| Arc::ptr_eq(a, &of));
                if current {
                    let check = match &validated.validation {
                        Some(v) => format!(
                            "; with each seeded {} left out in turn, {:.0} % of its strokes are labelled right",
                            v.left_out,
                            100.0 * v.balanced_accuracy
                        ),
                        None => {
                            "; seed a second frame to check it on strokes it did not learn".into()
                        }
                    };
                    let preview = if validated.is_live_preview() {
                        " (a live preview; Track and Place retrain on all)"
                    } else {
                        ""
                    };
                    self.status.notify(format!(
                        "Forest trained on {} samples in {:.2} s{preview}{check}.",
                        validated.stats.samples, validated.stats.train_s
                    ));
                    // The same forest: its maps stay.
                    self.doc.appearance = Some(validated);
                    self.doc.touch();
                    self.jobs.validating = false;
                }
            }
            Event::Probabilities {
                frame,
                maps,
                coarse,
                request,
            } => {
                // Only the answer to the latest request: one queued under an earlier forest
                // or for a frame left since is dropped.
                if self.jobs.probability_asked != Some((frame, request)) {
                    return;
                }
                if !coarse {
                    self.jobs.probability_asked = None;
                }
                self.jobs.keep_maps(frame, maps);
                if coarse {
                    self.jobs.probability_refresh.insert(frame);
                } else {
                    self.jobs.probability_refresh.remove(&frame);
                }
                if frame == self.view.frame {
                    self.screen.textures.probability_key = None;
                }
            }
            Event::Initialised(a) => {
                self.doc.forget_placement_undo();
                self.doc.placement = Some(a);
                self.doc.touch();
                self.status
                    .notify("Model placed: check it, then Fit this frame (F) or Track.");
            }
            Event::Progress { task, done, total } => {
                if let Some(b) = &mut self.status.busy
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
                    hidden_error_mm: self.hidden_errors(&f),
                    depth_explains_zoom: f.depth_explains_zoom,
                    refused: f.refused.iter().map(|w| w.to_string()).collect(),
                    hidden_region: f
                        .hidden_regions
                        .iter()
                        .map(|r| (r.structure.clone(), r.entry()))
                        .collect(),
                };
                if self.view.follow_tracking {
                    self.view.frame = f.frame;
                }
                self.doc.forget_placement_undo();
                self.doc.results.insert(f.frame, r);
                self.jobs
                    .fitted_with_current_forest(std::iter::once(f.frame));
                self.doc.touch();
            }
            Event::Dice { frame, dice } => {
                if let Some(r) = self.doc.results.get_mut(&frame) {
                    r.dice = dice;
                    self.doc.touch();
                }
            }
            Event::Stage { task, what } => {
                if let Some(b) = &mut self.status.busy
                    && b.task == task
                {
                    b.what = what;
                }
            }
            Event::SceneCreated { scene_json, notes } => {
                self.screen.new_scene = None;
                let notes: String = notes.iter().map(|n| format!(" Note: {n}.")).collect();
                self.status.notify(format!(
                    "Created {}: paint seeds on the first frames, train (T), place the model \
                     (Place automatically, or M), then track (Ctrl+T).{notes}",
                    scene_json.display()
                ));
                self.open_scene_asking(&scene_json.display().to_string());
            }
            Event::Finished(task) => self.task_ended(task, true),
            Event::Cancelled(task) => {
                // A cancelled track leaves a mix: the frames it reached are new, the others
                // keep whatever fit they had. Say so rather than let the timeline look whole.
                let reached = self
                    .status
                    .busy
                    .as_ref()
                    .filter(|b| b.task == task && task == Task::Track)
                    .map(|b| (b.done, b.total));
                self.task_ended(task, false);
                self.status.notify(match reached {
                    Some((done, total)) if done < total => format!(
                        "Cancelled after {done} of {total} frames: the frames it did not reach \
                         keep the fits they had before (from an earlier run, or none)."
                    ),
                    _ => "Cancelled.".to_string(),
                });
            }
            Event::Failed { task, message } => {
                self.task_ended(task, false);
                if task == Task::NewScene
                    && let Some(form) = self.screen.new_scene.as_mut()
                {
                    form.error = Some(message.clone());
                    form.creating = false;
                }
                self.status.fail(message);
            }
        }
        ctx.request_repaint();
    }

    /// Each hidden structure's centroid error at a tracked frame, against the scene's
    /// ground-truth trajectory (none without one).
    fn hidden_errors(&self, f: &crate::fit::tracker::TrackedFrame) -> Vec<(String, f64)> {
        let Some(scene) = self.doc.scene.as_ref() else {
            return Vec::new();
        };
        let Some(truth) = scene
            .ground_truth
            .trajectory
            .as_ref()
            .and_then(|t| t.get(f.frame))
        else {
            return Vec::new();
        };
        scene
            .structures
            .iter()
            .filter(|s| !s.visible)
            .filter_map(|s| {
                let fitted = f.centroids.iter().find(|(n, _)| *n == s.name)?.1;
                let true_c = glam::DVec3::from_array(*truth.centroids.get(&s.name)?);
                Some((s.name.clone(), (fitted - true_c).length()))
            })
            .collect()
    }

    /// Bookkeeping when the worker ends `task`, however it ended (`finished`: it completed).
    fn task_ended(&mut self, task: Task, finished: bool) {
        if let Some(busy) = self.status.busy.take_if(|b| b.task == task)
            && finished
            && task == Task::Track
        {
            let lost = self.doc.results.values().filter(|r| r.lost).count();
            // Where ground truth exists, the hidden structures' error goes in the summary:
            // a good Dice says nothing about them.
            let mut hidden: std::collections::BTreeMap<&str, (f64, f64, usize)> =
                Default::default();
            for r in self.doc.results.values() {
                for (name, e) in &r.hidden_error_mm {
                    let h = hidden.entry(name).or_insert((0.0, 0.0, 0));
                    h.0 += e;
                    h.1 = h.1.max(*e);
                    h.2 += 1;
                }
            }
            let hidden: Vec<String> = hidden
                .iter()
                .map(|(n, (sum, max, k))| {
                    format!(
                        "; {n} {:.1} mm off on average (max {max:.1})",
                        sum / *k as f64
                    )
                })
                .collect();
            let by_depth = self
                .doc
                .results
                .values()
                .filter(|r| r.depth_explains_zoom)
                .count();
            let warning = if by_depth > 0 {
                format!(
                    " Warning: in {by_depth} frames the image zoomed and only depth could follow \
                     (cameras fixed): hidden structures may be off there; LSC corrects the cameras."
                )
            } else {
                String::new()
            };
            // The figures after the count cover every fitted frame, not only this job's.
            let fitted = self.doc.results.len();
            let lost = match lost {
                0 => "none lost".to_string(),
                n => format!("{n} lost"),
            };
            self.status.notify(format!(
                "Fitted {} frame{} in mode {}. Over all {fitted} fitted frame{}: {lost}{}.{warning}",
                busy.total,
                if busy.total == 1 { "" } else { "s" },
                self.doc.mode().name(),
                if fitted == 1 { "" } else { "s" },
                hidden.concat()
            ));
        }
        match task {
            // A classification that ended without its full maps (cancelled, failed) is asked
            // again when the view needs it; a finished one cleared the request with its maps.
            Task::Classify if !finished => self.jobs.probability_asked = None,
            // Whatever became of it, no figure is coming.
            Task::Validate => self.jobs.validating = false,
            Task::Load if !finished => {
                self.jobs.pending_session = None;
                self.jobs.loading_spec = None;
            }
            Task::Export => {
                if let Some(dir) = self.jobs.exporting.take()
                    && finished
                {
                    self.status
                        .notify(format!("Exported the tracked frames to {}", dir.display()));
                }
            }
            _ => {}
        }
    }

    /// Drains worker events; plays; schedules live retraining; autosaves.
    pub(super) fn tick(&mut self, ctx: &egui::Context) {
        for e in self.worker.drain() {
            self.handle_event(e, ctx);
        }
        self.receive_frames(ctx);
        let now = ctx.input(|i| i.time);
        if self.view.playing
            && let Some(scene) = &self.doc.scene
        {
            let dt = 1.0 / scene.fps.clamp(1.0, 120.0);
            if now - self.view.play_clock_s >= dt {
                self.view.play_clock_s = now;
                self.view.frame = (self.view.frame + 1) % scene.frame_count.max(1);
            }
            ctx.request_repaint();
        }
        if self.doc.settings.live_update
            && self.jobs.seeds_sent != self.doc.editor.revision
            && !self.doc.editor.in_stroke()
        {
            // Retrain as soon as a stroke ends, as ilastik's live update does (the painting
            // itself never waits: a stroke in progress holds the retrain).
            let due = *self.jobs.retrain_due_s.get_or_insert(now + 0.05);
            if now >= due && self.status.busy.is_none() {
                self.train_with(true);
            }
            // Wake when it is due, not on the next input.
            ctx.request_repaint_after(std::time::Duration::from_secs_f64((due - now).max(0.01)));
        }
        self.ask_probabilities();
        self.autosave(now);
        if self.status.busy.is_some() {
            ctx.request_repaint_after(std::time::Duration::from_millis(50));
        }
    }
}
