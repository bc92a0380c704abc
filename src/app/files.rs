//! The app's files: the dialogs that pick them (behind a trait, so tests never open one),
//! sessions saved and loaded, the autosave written in the background and offered back when a
//! scene opens, the seeds saved as label PNGs, and files dropped on the window. Writing and
//! reading themselves are the core's (`session`, `export`); every failure is shown once.

use super::EndofuseApp;
use super::commands::AppCommand;
use super::jobs::{PendingSession, camera_sizes};
use super::pickers::{Dialogs, FileRequest};
use crate::error::Error;
use crate::session::{self, SESSION_FORMAT, Session};
use crate::strokes::SeedEditor;
use crossbeam_channel::{Receiver, Sender, unbounded};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Where the app's files go, and the autosave's bookkeeping.
pub struct Files {
    pub dialogs: Box<dyn Dialogs>,
    /// The folder of the last path chosen, where the built-in browser starts.
    pub last_folder: Option<PathBuf>,
    /// Folder of autosaves (None: the app's data folder).
    pub autosave_dir: Option<PathBuf>,
    /// An autosave found for the scene just opened, offered to the user.
    pub autosave_offer: Option<PathBuf>,
    last_autosave_s: f64,
    /// Autosaves report back from their thread: a failure is shown once, until one succeeds.
    autosaved_tx: Sender<Autosaved>,
    autosaved_rx: Receiver<Autosaved>,
    autosave_failing: bool,
    /// Counts saves under a name: an autosave begun before the last one is stale.
    generation: u64,
}

/// How one autosave went.
struct Autosaved {
    generation: u64,
    path: PathBuf,
    result: Result<(), Error>,
}

impl Files {
    pub fn new(dialogs: Box<dyn Dialogs>) -> Self {
        let (autosaved_tx, autosaved_rx) = unbounded();
        Self {
            dialogs,
            last_folder: None,
            autosave_dir: None,
            autosave_offer: None,
            last_autosave_s: 0.0,
            autosaved_tx,
            autosaved_rx,
            autosave_failing: false,
            generation: 0,
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

    /// The autosave file of the scene named `spec`.
    pub fn autosave_path(&self, spec: &str) -> PathBuf {
        session::autosave_path(&self.autosave_folder(), spec)
    }
}

/// True when `path` is a session file (its text names the session format).
pub(super) fn is_session_file(path: &Path) -> bool {
    crate::error::read_text(path).is_ok_and(|t| t.contains(SESSION_FORMAT))
}

/// Removes a file that may not exist; an error names it when it exists and cannot be removed.
fn remove_if_present(path: &Path) -> Result<(), Error> {
    match std::fs::remove_file(path) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(source) => Err(Error::Remove {
            path: path.to_path_buf(),
            source,
        }),
    }
}

impl EndofuseApp {
    /// After a scene opens: offer its autosave, if one was left.
    pub(super) fn offer_autosave(&mut self) {
        let autosave = self.files.autosave_path(&self.doc.spec);
        self.files.autosave_offer = autosave.exists().then_some(autosave);
    }

    /// The user chose to leave the current scene's unsaved work: its autosave goes too, so it
    /// is not offered back as if it had been kept.
    pub(super) fn forget_current_autosave(&mut self) {
        let path = self.files.autosave_path(&self.doc.spec);
        if let Err(e) = remove_if_present(&path) {
            self.status.fail(e);
        }
    }

    pub(super) fn discard_autosave(&mut self) {
        if let Some(path) = self.files.autosave_offer.take()
            && let Err(e) = remove_if_present(&path)
        {
            self.status.fail(e);
        }
    }

    /// Restores a session's seeds, settings, forest and results onto the loaded scene.
    pub(super) fn apply_session(&mut self, s: Session, path: &Path) {
        let Some(scene) = self.doc.scene.clone() else {
            return;
        };
        let sizes = camera_sizes(&scene);
        match session::decode_seeds(&s.seeds, &sizes, path) {
            Ok(seeds) => {
                self.doc.editor = SeedEditor::new(&seeds, sizes);
                self.seeds_loaded();
            }
            Err(e) => {
                self.status.fail(e);
                return;
            }
        }
        self.doc.settings = s.settings;
        self.doc.placement = s.placement.or(self.doc.placement);
        match s.forest {
            Some(f) if f.feature_set != crate::appearance::features::FEATURE_SET => {
                self.drop_forest();
                self.status.notify(
                    "The session's forest was trained on an earlier feature set: train again (T).",
                );
            }
            Some(f) if Some(&f.classes) == self.doc.classes.as_ref() => {
                self.use_forest(Arc::new(f))
            }
            Some(_) => {
                self.drop_forest();
                self.status
                    .notify("The session's forest is for other classes: train again.");
            }
            // Saved before training: the forest trained since is not the session's.
            None => self.drop_forest(),
        }
        self.doc.forget_placement_undo();
        self.doc.results = s
            .results
            .into_iter()
            .filter(|r| {
                r.frame < scene.frame_count && r.state.intrinsics.len() == scene.cameras.len()
            })
            .map(|r| (r.frame, r))
            .collect();
        // The session's fits came with the session's forest, just put in use.
        let fitted: Vec<usize> = self.doc.results.keys().copied().collect();
        self.jobs.fitted_with_current_forest(fitted.into_iter());
        self.screen.textures = Default::default();
        self.screen.stroke = Default::default();
        self.doc.touch();
        // A session file is saved work; an autosave restored is not, until it is saved.
        let autosave = self.files.autosave_path(&self.doc.spec);
        if path != autosave {
            self.doc.saved = self.doc.revision();
        }
        self.status
            .notify(format!("Session {} restored.", path.display()));
    }

    pub(super) fn load_session_file(&mut self, path: &Path) {
        if self.files.autosave_offer.as_deref() == Some(path) {
            self.files.autosave_offer = None;
        }
        match Session::load(path) {
            Ok(s) => {
                if s.scene == self.doc.spec && self.doc.scene.is_some() {
                    self.apply_session(s, path);
                } else {
                    let spec = s.scene.clone();
                    self.jobs.pending_session = Some(PendingSession {
                        session: s,
                        path: path.to_path_buf(),
                    });
                    self.open_scene(&spec);
                }
            }
            Err(e) => self.status.fail(e),
        }
    }

    pub(super) fn save_session_to(&mut self, path: &Path) {
        // A session replaces an earlier session, never another file picked by mistake (a
        // scene.json, a mesh).
        if path.is_file() && !is_session_file(path) {
            self.status.fail(format!(
                "{} is not an endofuse session: not replaced; choose another name",
                path.display()
            ));
            return;
        }
        match self.doc.session().save(path) {
            Ok(()) => {
                self.doc.saved = self.doc.revision();
                self.status.notify(format!("Saved {}", path.display()));
                // Saved under a name: the autosave is no longer needed, nor any still being
                // written (it would offer to restore what was just saved).
                self.files.generation += 1;
                if let Err(e) = remove_if_present(&self.files.autosave_path(&self.doc.spec)) {
                    self.status.fail(e);
                }
            }
            Err(e) => self.status.fail(e),
        }
    }

    /// Writes the autosave every few seconds when something changed, on a helper thread; a
    /// failed autosave is shown once (until one succeeds again).
    pub(super) fn autosave(&mut self, now_s: f64) {
        for done in self.files.autosaved_rx.try_iter().collect::<Vec<_>>() {
            match done.result {
                // Written after the session was saved under a name: not wanted.
                Ok(()) if done.generation != self.files.generation => {
                    if let Err(e) = remove_if_present(&done.path) {
                        self.status.fail(e);
                    }
                }
                Ok(()) => self.files.autosave_failing = false,
                Err(e) => {
                    if !self.files.autosave_failing {
                        self.status.fail(format!("autosave failed: {e}"));
                    }
                    self.files.autosave_failing = true;
                }
            }
        }
        let state = self.doc.revision();
        if self.doc.scene.is_none()
            || self.doc.editor.in_stroke()
            || state == self.doc.autosaved
            || state == self.doc.saved
            || now_s - self.files.last_autosave_s < 3.0
        {
            return;
        }
        self.files.last_autosave_s = now_s;
        self.doc.autosaved = state;
        let session = self.doc.session();
        let path = self.files.autosave_path(&self.doc.spec);
        let (done, generation) = (self.files.autosaved_tx.clone(), self.files.generation);
        std::thread::spawn(move || {
            let result = session.save(&path);
            // The app may be closing: then nobody needs to hear how it went.
            let _ = done.send(Autosaved {
                generation,
                path,
                result,
            });
        });
    }

    /// Writes the painted seeds as the contract's label PNGs: into the scene's seeds folder
    /// (its `seeds` template, or `seeds/{camera}/{frame:06}.png` added to scene.json), or for
    /// the demo into a folder the user picks.
    pub(super) fn save_seed_pngs(&mut self, ctx: &egui::Context) {
        let Some(scene) = self.doc.scene.clone() else {
            return;
        };
        match &scene.root {
            Some(root) => {
                let result =
                    crate::export::write_seeds_into_scene(&scene, root, &self.doc.editor.seeds());
                self.seeds_written(result);
            }
            None => self.request_path(FileRequest::SeedFolder, ctx),
        }
    }

    /// Writes the painted seeds as label PNGs under `dir` (the demo's, picked by the user).
    pub(super) fn save_seed_pngs_into(&mut self, dir: &Path) {
        let Some(scene) = self.doc.scene.clone() else {
            return;
        };
        let result = crate::export::write_seeds_into_folder(&scene, dir, &self.doc.editor.seeds())
            .map(|n| (n, dir.to_path_buf()));
        self.seeds_written(result);
    }

    fn seeds_written(&mut self, result: Result<(usize, PathBuf), Error>) {
        match result {
            Ok((n, dir)) => self
                .status
                .notify(format!("Wrote {n} seed PNGs under {}", dir.display())),
            Err(e) => self.status.fail(e),
        }
    }

    /// A scene folder, a scene.json or a session file dropped on the window.
    pub(super) fn dropped_files(&mut self, ctx: &egui::Context) {
        let dropped: Vec<PathBuf> = ctx.input(|i| {
            i.raw
                .dropped_files
                .iter()
                .map(|f| f.path().to_path_buf())
                .filter(|p| !p.as_os_str().is_empty())
                .collect()
        });
        // A CT, a calibration or videos fill the New scene form.
        if !dropped.is_empty() {
            let was_open = self.screen.new_scene.is_some();
            let mut form = self.screen.new_scene.take().unwrap_or_default();
            let used = form.fill_from_dropped(&dropped);
            if used || was_open {
                self.screen.new_scene = Some(form);
            }
            if used {
                return;
            }
        }
        if let Some(p) = dropped.first() {
            let is_session = p.is_file() && is_session_file(p);
            self.send(if is_session {
                AppCommand::LoadSession(p.clone())
            } else {
                AppCommand::OpenScene(p.display().to_string())
            });
        }
    }
}
