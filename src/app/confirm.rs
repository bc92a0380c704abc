//! Questions the app asks before it does something that cannot be undone: closing the window,
//! opening another scene or a session over unsaved strokes and results, replacing an earlier
//! export, and (once, when a scene opens) whether to restore the autosave found for it. Each is a modal with the safe
//! answer on Esc; nothing is lost without the user saying so.

use super::EndofuseApp;
use std::path::PathBuf;

/// What waits for the user's answer.
#[derive(Debug, Clone, PartialEq)]
pub enum Confirm {
    /// Close the window over unsaved work.
    Close,
    /// Open this scene ("demo", a folder or a scene.json) over unsaved work.
    Open(String),
    /// Load this session over unsaved work.
    LoadSession(PathBuf),
    /// Export into a folder that holds an earlier export.
    ReplaceExport(PathBuf),
}

impl EndofuseApp {
    /// Opens `spec` now, or asks first when the current scene has unsaved work.
    pub fn open_scene_asking(&mut self, spec: &str) {
        if self.doc.unsaved() {
            self.confirm = Some(Confirm::Open(spec.to_string()));
        } else {
            self.open_scene(spec);
        }
    }

    /// Loads the session at `path` now, or asks first when there is unsaved work.
    pub fn load_session_asking(&mut self, path: PathBuf) {
        if self.doc.unsaved() {
            self.confirm = Some(Confirm::LoadSession(path));
        } else {
            self.load_session_file(&path);
        }
    }

    /// Draws the pending question, if any, and acts on the answer.
    pub(super) fn confirm_modal(&mut self, ctx: &egui::Context) {
        if let Some(question) = self.confirm.clone() {
            if ctx.input_mut(|i| i.consume_key(egui::Modifiers::NONE, egui::Key::Escape)) {
                self.confirm = None;
                return;
            }
            self.ask(ctx, question);
        } else if let Some(path) = self.files.autosave_offer.clone() {
            self.autosave_modal(ctx, path);
        }
    }

    fn ask(&mut self, ctx: &egui::Context, question: Confirm) {
        let (title, detail, go) = match &question {
            Confirm::Close => (
                "Save changes before closing?".to_string(),
                "Your strokes or tracking results are not saved in a session file.".to_string(),
                "Close without saving",
            ),
            Confirm::Open(spec) => (
                "Save your work before opening another scene?".to_string(),
                format!(
                    "Your strokes or tracking results are not saved in a session file. Opening {} discards them.",
                    if spec == crate::open::DEMO {
                        "the demo"
                    } else {
                        spec.as_str()
                    }
                ),
                "Open without saving",
            ),
            Confirm::LoadSession(path) => (
                "Save your work before loading a session?".to_string(),
                format!(
                    "Your strokes or tracking results are not saved. Loading {} replaces them.",
                    path.display()
                ),
                "Load without saving",
            ),
            Confirm::ReplaceExport(dir) => (
                "Replace the earlier export?".to_string(),
                format!(
                    "{} holds an earlier endofuse export; its masks, overlays and JSON files will be overwritten.",
                    dir.display()
                ),
                "Replace",
            ),
        };
        let mut answer = None;
        egui::Modal::new(egui::Id::unique("confirm")).show(ctx, |ui| {
            ui.set_max_width(460.0);
            ui.heading(title);
            ui.label(detail);
            ui.add_space(6.0);
            ui.horizontal(|ui| {
                let unsaved = !matches!(question, Confirm::ReplaceExport(_));
                if unsaved && ui.button("Save session…").clicked() {
                    answer = Some(Answer::SaveFirst);
                }
                if ui.button(go).clicked() {
                    answer = Some(Answer::Go);
                }
                if ui.button("Cancel").clicked() {
                    answer = Some(Answer::Cancel);
                }
            });
        });
        let Some(answer) = answer else { return };
        self.confirm = None;
        if answer == Answer::Cancel {
            return;
        }
        if answer == Answer::SaveFirst {
            // Saved first, then on with the question (unless the save fails).
            let then = Some(question);
            self.request_path(super::pickers::FileRequest::SaveSession { then }, ctx);
            return;
        }
        self.proceed(question, ctx);
    }

    /// Does what the user agreed to (after saving, when they chose to save first).
    pub(super) fn proceed(&mut self, question: Confirm, ctx: &egui::Context) {
        if matches!(question, Confirm::Open(_) | Confirm::LoadSession(_)) {
            self.forget_current_autosave();
        }
        match question {
            Confirm::Close => {
                self.allow_close = true;
                ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            }
            Confirm::Open(spec) => self.open_scene(&spec),
            Confirm::LoadSession(path) => self.load_session_file(&path),
            Confirm::ReplaceExport(dir) => self.export_to(dir),
        }
    }

    fn autosave_modal(&mut self, ctx: &egui::Context, path: PathBuf) {
        let modified = std::fs::metadata(&path)
            .and_then(|m| m.modified())
            .ok()
            .and_then(|t| t.elapsed().ok())
            .map(|age| format!(" ({} min ago)", age.as_secs() / 60))
            .unwrap_or_default();
        let mut restore = None;
        egui::Modal::new(egui::Id::unique("autosave")).show(ctx, |ui| {
            ui.set_max_width(460.0);
            ui.heading("Restore autosaved work?");
            ui.label(format!(
                "An earlier run left strokes or results for this scene{modified} that were never saved."
            ));
            ui.horizontal(|ui| {
                if ui.button("Restore").clicked() {
                    restore = Some(true);
                }
                if ui.button("Discard").clicked() {
                    restore = Some(false);
                }
            });
        });
        match restore {
            Some(true) => self.load_session_file(&path),
            Some(false) => self.discard_autosave(),
            None => {}
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Answer {
    SaveFirst,
    Go,
    Cancel,
}
