//! The built-in file browser, for where the system's file dialog cannot open: a modal with the
//! folder's path (typed, or stepped up), its folders and the files the request can use, and a
//! name field. Opening needs an existing file; saving over an existing file asks first; a
//! folder request takes the folder shown, or the subfolder named in the field (made when it
//! does not exist yet). Errors (a folder that cannot be read or made) show inside the browser.
//! It knows nothing of what the path is for: [`crate::app::pickers`] finishes the request.

use crate::app::pickers::{FileRequest, Picker};
use egui::{Color32, RichText};
use std::path::{Path, PathBuf};

/// One listed entry.
#[derive(Debug, Clone, PartialEq)]
pub struct Entry {
    pub name: String,
    pub is_dir: bool,
}

/// The browser's state while it is open.
#[derive(Debug)]
pub struct Browser {
    pub request: FileRequest,
    picker: Picker,
    /// The folder shown.
    pub folder: PathBuf,
    path_text: String,
    /// The file name (open, save) or subfolder name (folder requests).
    pub name: String,
    entries: Result<Vec<Entry>, String>,
    show_hidden: bool,
    /// Saving over this existing file waits for the user's yes.
    replace_asked: Option<PathBuf>,
    error: Option<String>,
}

/// What the user did in the browser this frame.
pub enum Outcome {
    Open,
    Chosen(PathBuf),
    Cancelled,
}

impl Browser {
    /// A browser for `request`, showing `folder` (or the nearest existing folder above it).
    pub fn new(request: FileRequest, folder: &Path) -> Self {
        let picker = request.picker();
        let name = match &picker {
            Picker::SaveFile { file_name, .. } => file_name.clone(),
            _ => String::new(),
        };
        let mut b = Self {
            request,
            picker,
            folder: PathBuf::new(),
            path_text: String::new(),
            name,
            entries: Ok(Vec::new()),
            show_hidden: false,
            replace_asked: None,
            error: None,
        };
        let mut start = folder.to_path_buf();
        while !start.is_dir() && start.pop() {}
        b.enter(if start.as_os_str().is_empty() {
            PathBuf::from("/")
        } else {
            start
        });
        b
    }

    /// Shows `folder` and lists it.
    pub fn enter(&mut self, folder: PathBuf) {
        // A folder request's field names a subfolder of the folder shown: the one picked by a
        // click before a double-click entered it is not one of the new folder's (the export
        // went into seeds/seeds). A file name being saved stays.
        if matches!(self.picker, Picker::Folder { .. }) {
            self.name.clear();
        }
        self.entries = list(&folder, &self.picker, self.show_hidden);
        self.path_text = folder.display().to_string();
        self.folder = folder;
        self.replace_asked = None;
        self.error = None;
    }

    /// The entries listed (folders first, then the files the request can use).
    pub fn entries(&self) -> &[Entry] {
        self.entries.as_deref().unwrap_or_default()
    }

    /// What the confirm button does now: the path it would answer with, or why not.
    pub fn target(&self) -> Result<PathBuf, String> {
        let name = self.name.trim();
        match &self.picker {
            Picker::Folder { .. } if name.is_empty() => Ok(self.folder.clone()),
            _ if name.is_empty() => Err("type or pick a file name".into()),
            _ if name == "." || name == ".." => Err("a name, not . or ..".into()),
            // A name, or a path pasted whole (absolute, or under this folder).
            Picker::OpenFile { .. } => {
                let p = self.folder.join(name);
                if p.is_file() {
                    Ok(p)
                } else if name.contains('/') {
                    Err(format!("no file {}", p.display()))
                } else {
                    Err(format!("no file {name} in this folder"))
                }
            }
            Picker::SaveFile { .. } => {
                let p = self.folder.join(name);
                match p.parent() {
                    Some(parent) if !parent.is_dir() => {
                        Err(format!("no folder {} to save into", parent.display()))
                    }
                    _ => Ok(p),
                }
            }
            Picker::Folder { .. } => Ok(self.folder.join(name)),
        }
    }

    /// Answers with the target: a folder named but missing is made; saving over a file asks.
    pub fn confirm(&mut self) -> Option<PathBuf> {
        // A folder named where a file is wanted (typed or pasted whole): show it.
        let named = self.folder.join(self.name.trim());
        if matches!(self.picker, Picker::OpenFile { .. })
            && !self.name.trim().is_empty()
            && named.is_dir()
        {
            self.name.clear();
            self.enter(named);
            return None;
        }
        let target = match self.target() {
            Ok(t) => t,
            Err(e) => {
                self.error = Some(e);
                return None;
            }
        };
        match &self.picker {
            Picker::Folder { .. } if !target.is_dir() => {
                if let Err(e) = std::fs::create_dir_all(&target) {
                    self.error = Some(format!("cannot make {}: {e}", target.display()));
                    return None;
                }
                Some(target)
            }
            Picker::SaveFile { .. } if target.is_dir() => {
                self.enter(target);
                None
            }
            Picker::SaveFile { .. }
                if target.exists() && self.replace_asked.as_ref() != Some(&target) =>
            {
                self.replace_asked = Some(target);
                None
            }
            _ => Some(target),
        }
    }

    /// Makes the subfolder named in the field and shows it.
    pub fn make_folder(&mut self) {
        let name = self.name.trim().to_string();
        if name.is_empty() || name.contains('/') {
            self.error = Some("type the new folder's name in the field first".into());
            return;
        }
        let dir = self.folder.join(&name);
        match std::fs::create_dir(&dir) {
            Ok(()) => {
                self.name.clear();
                self.enter(dir);
            }
            Err(e) => self.error = Some(format!("cannot make {}: {e}", dir.display())),
        }
    }

    /// Draws the browser; says what the user did.
    pub fn show(&mut self, ctx: &egui::Context) -> Outcome {
        let mut outcome = Outcome::Open;
        let response =
            egui::Modal::new(egui::Id::unique("endofuse file browser")).show(ctx, |ui| {
                ui.set_width(600.0);
                ui.heading(self.picker.title());
                ui.label(RichText::new("built-in file browser").weak().small());
                self.path_row(ui);
                self.list(ui, &mut outcome);
                self.name_row(ui, &mut outcome);
                if let Some(e) = &self.error {
                    ui.colored_label(Color32::from_rgb(255, 110, 110), e);
                }
                self.buttons(ui, &mut outcome);
            });
        if response.should_close() && matches!(outcome, Outcome::Open) {
            outcome = Outcome::Cancelled;
        }
        outcome
    }

    fn path_row(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            let up = self.folder.parent().map(Path::to_path_buf);
            if ui
                .add_enabled(up.is_some(), egui::Button::new("Up"))
                .on_hover_text("The folder above")
                .clicked()
                && let Some(up) = up
            {
                self.enter(up);
            }
            let edit = ui.add(
                egui::TextEdit::singleline(&mut self.path_text)
                    .desired_width(f32::INFINITY)
                    .hint_text("a folder; Enter to go there"),
            );
            if edit.lost_focus() && ui.input(|i| i.key_pressed(egui::Key::Enter)) {
                let typed = PathBuf::from(self.path_text.trim());
                if typed.is_dir() {
                    self.enter(typed);
                } else {
                    self.error = Some(format!(
                        "{} is not a folder (the list still shows {})",
                        typed.display(),
                        self.folder.display()
                    ));
                }
            }
        });
    }

    fn list(&mut self, ui: &mut egui::Ui, outcome: &mut Outcome) {
        let mut go: Option<PathBuf> = None;
        let mut pick: Option<(String, bool)> = None;
        egui::Frame::group(ui.style()).show(ui, |ui| {
            egui::ScrollArea::vertical()
                .max_height(260.0)
                .min_scrolled_height(260.0)
                .auto_shrink([false, false])
                .show(ui, |ui| match &self.entries {
                    Err(e) => {
                        ui.colored_label(Color32::from_rgb(255, 110, 110), e);
                    }
                    Ok(entries) if entries.is_empty() => {
                        ui.label(RichText::new("(nothing here the request can use)").weak());
                    }
                    Ok(entries) => {
                        for e in entries {
                            let text = if e.is_dir {
                                format!("{}/", e.name)
                            } else {
                                e.name.clone()
                            };
                            // A folder request picks folders with one click, as it picks
                            // files elsewhere: the picked one shows so (it fills the field).
                            let pickable =
                                !e.is_dir || matches!(self.picker, Picker::Folder { .. });
                            let selected = pickable && self.name == e.name;
                            let r = ui.selectable_label(selected, text);
                            let r = if e.is_dir && pickable {
                                r.on_hover_text("Click: use this folder · double-click: open it")
                            } else {
                                r
                            };
                            if r.double_clicked() {
                                if e.is_dir {
                                    go = Some(self.folder.join(&e.name));
                                } else {
                                    pick = Some((e.name.clone(), true));
                                }
                            } else if r.clicked() {
                                if e.is_dir && !matches!(self.picker, Picker::Folder { .. }) {
                                    go = Some(self.folder.join(&e.name));
                                } else {
                                    pick = Some((e.name.clone(), false));
                                }
                            }
                        }
                    }
                });
        });
        if let Some(dir) = go {
            self.enter(dir);
        }
        if let Some((name, and_confirm)) = pick {
            self.name = name;
            self.error = None;
            self.replace_asked = None;
            if and_confirm && let Some(p) = self.confirm() {
                *outcome = Outcome::Chosen(p);
            }
        }
    }

    fn name_row(&mut self, ui: &mut egui::Ui, outcome: &mut Outcome) {
        let label = match self.picker {
            Picker::OpenFile { .. } => "File:",
            Picker::SaveFile { .. } => "Save as:",
            Picker::Folder { .. } => "Subfolder:",
        };
        ui.horizontal(|ui| {
            ui.label(label);
            let hint = match self.picker {
                Picker::Folder { .. } => "empty: the folder shown; a name: that subfolder",
                _ => "a file name",
            };
            let edit = ui.add(
                egui::TextEdit::singleline(&mut self.name)
                    .desired_width(f32::INFINITY)
                    .hint_text(hint),
            );
            if edit.changed() {
                self.replace_asked = None;
                self.error = None;
            }
            if edit.lost_focus()
                && ui.input(|i| i.key_pressed(egui::Key::Enter))
                && let Some(p) = self.confirm()
            {
                *outcome = Outcome::Chosen(p);
            }
        });
    }

    fn buttons(&mut self, ui: &mut egui::Ui, outcome: &mut Outcome) {
        if let Some(p) = self.replace_asked.clone() {
            ui.colored_label(
                Color32::from_rgb(255, 190, 70),
                format!("{} exists: replace it?", p.display()),
            );
        }
        ui.horizontal(|ui| {
            if ui.checkbox(&mut self.show_hidden, "hidden files").changed() {
                let folder = self.folder.clone();
                self.enter(folder);
            }
            ui.with_layout(egui::Layout::right_to_left(egui::Align::Center), |ui| {
                if ui.button("Cancel").clicked() {
                    *outcome = Outcome::Cancelled;
                }
                let go = match (&self.picker, &self.replace_asked) {
                    (_, Some(_)) => "Replace".to_string(),
                    (Picker::OpenFile { .. }, _) => "Open".into(),
                    (Picker::SaveFile { .. }, _) => "Save".into(),
                    (Picker::Folder { .. }, _) if self.name.trim().is_empty() => {
                        "Use this folder".into()
                    }
                    (Picker::Folder { .. }, _) => format!("Use {}", self.name.trim()),
                };
                if ui
                    .add_enabled(self.target().is_ok(), egui::Button::new(go))
                    .clicked()
                    && let Some(p) = self.confirm()
                {
                    *outcome = Outcome::Chosen(p);
                }
                if matches!(self.picker, Picker::Folder { .. } | Picker::SaveFile { .. })
                    && ui
                        .button("New folder")
                        .on_hover_text("Makes the folder named in the field, and opens it")
                        .clicked()
                {
                    self.make_folder();
                }
            });
        });
    }
}

/// The folders of `folder` and the files `picker` can use, names sorted without case.
fn list(folder: &Path, picker: &Picker, show_hidden: bool) -> Result<Vec<Entry>, String> {
    let read =
        std::fs::read_dir(folder).map_err(|e| format!("cannot read {}: {e}", folder.display()))?;
    let mut entries: Vec<Entry> = read
        .flatten()
        .filter_map(|d| {
            let name = d.file_name().to_string_lossy().into_owned();
            if !show_hidden && name.starts_with('.') {
                return None;
            }
            // Follows links: a linked folder lists as a folder.
            let is_dir = d.path().is_dir();
            let wanted = is_dir
                || match picker {
                    Picker::OpenFile { extensions, .. } => {
                        extensions.is_empty()
                            || Path::new(&name)
                                .extension()
                                .and_then(|e| e.to_str())
                                .is_some_and(|e| {
                                    extensions.iter().any(|x| x.eq_ignore_ascii_case(e))
                                })
                    }
                    Picker::SaveFile { .. } => true,
                    Picker::Folder { .. } => false,
                };
            wanted.then_some(Entry { name, is_dir })
        })
        .collect();
    entries.sort_by(|a, b| {
        b.is_dir
            .cmp(&a.is_dir)
            .then_with(|| a.name.to_lowercase().cmp(&b.name.to_lowercase()))
    });
    Ok(entries)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("endofuse-browser-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(d.join("sub")).unwrap();
        std::fs::write(d.join("scene.json"), "{}").unwrap();
        std::fs::write(d.join("notes.txt"), "").unwrap();
        std::fs::write(d.join(".hidden.json"), "").unwrap();
        d
    }

    #[test]
    fn open_lists_folders_and_matching_files_and_needs_an_existing_file() {
        let d = scratch("open");
        let mut b = Browser::new(FileRequest::OpenScene, &d);
        let names: Vec<&str> = b.entries().iter().map(|e| e.name.as_str()).collect();
        assert_eq!(names, ["sub", "scene.json"]);
        assert!(b.confirm().is_none(), "no name: nothing chosen");
        b.name = "missing.json".into();
        assert!(b.confirm().is_none());
        b.name = "scene.json".into();
        assert_eq!(b.confirm(), Some(d.join("scene.json")));
        // A path pasted whole opens the file it names, wherever the list is.
        let mut b = Browser::new(FileRequest::OpenScene, &d.join("sub"));
        b.name = d.join("scene.json").display().to_string();
        assert_eq!(b.confirm(), Some(d.join("scene.json")));
        // A folder pasted there opens it.
        b.name = d.join("sub").display().to_string();
        assert!(b.confirm().is_none());
        assert_eq!(b.folder, d.join("sub"));
        b.name = d.join("nowhere/scene.json").display().to_string();
        assert!(b.confirm().is_none());
        assert!(b.error.as_deref().is_some_and(|e| e.contains("nowhere")));
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn saving_over_a_file_asks_first_and_a_folder_request_makes_the_named_folder() {
        let d = scratch("save");
        let mut b = Browser::new(FileRequest::SaveSession { then: None }, &d);
        assert_eq!(b.name, "session.endofuse.json");
        b.name = "notes.txt".into();
        assert!(b.confirm().is_none(), "asked first");
        assert_eq!(b.confirm(), Some(d.join("notes.txt")), "then replaced");
        let mut f = Browser::new(FileRequest::Export, &d);
        assert!(f.entries().iter().all(|e| e.is_dir), "folders only");
        assert_eq!(f.confirm(), Some(d.clone()), "empty name: the folder shown");
        f.name = "export1".into();
        assert_eq!(f.confirm(), Some(d.join("export1")));
        assert!(d.join("export1").is_dir());
        // A subfolder picked by a click, then entered by a double-click: the field no longer
        // names it (the export went into sub/sub); a file name being saved stays.
        let mut f = Browser::new(FileRequest::Export, &d);
        f.name = "sub".into();
        f.enter(d.join("sub"));
        assert_eq!(f.name, "");
        assert_eq!(f.confirm(), Some(d.join("sub")));
        let mut b = Browser::new(FileRequest::SaveSession { then: None }, &d);
        b.enter(d.join("sub"));
        assert_eq!(b.name, "session.endofuse.json");
        // A start folder that no longer exists: the nearest one above.
        let b = Browser::new(FileRequest::LoadSession, &d.join("gone/deeper"));
        assert_eq!(b.folder, d);
        let _ = std::fs::remove_dir_all(&d);
    }
}
