//! Choosing a file or a folder: the system's dialog where it works, the built-in browser
//! where it does not. Where no xdg-desktop-portal file chooser runs (minimal
//! desktops, i3, many lab machines) the system dialog closes at once with nothing chosen, exactly
//! like a cancel; a dialog that answers "nothing" faster than a person can cancel is taken as
//! unavailable, said in the status bar, and the request goes to the built-in browser
//! ([`super::panels::browser`]), as every later one does: the preference "Use the built-in file
//! browser" is ticked for the user, who can untick it to try the system dialog again. Every file action of the
//! app asks through [`EndofuseApp::request_path`] and is finished by [`EndofuseApp::path_chosen`],
//! whichever picker answered.

use super::EndofuseApp;
use super::confirm::Confirm;
use super::panels::browser::{Browser, Outcome};
use super::panels::new_scene::Field;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// What a picker is asked for.
#[derive(Debug, Clone, PartialEq)]
pub enum Picker {
    /// An existing file, titled, offering files that end in one of `extensions` (empty: any).
    OpenFile {
        title: String,
        extensions: Vec<String>,
    },
    /// A file to write, proposing `file_name`.
    SaveFile { title: String, file_name: String },
    /// A folder (existing, or made in the picker).
    Folder { title: String },
}

impl Picker {
    pub fn title(&self) -> &str {
        match self {
            Picker::OpenFile { title, .. }
            | Picker::SaveFile { title, .. }
            | Picker::Folder { title } => title,
        }
    }
}

/// How a picker answered.
#[derive(Debug, Clone, PartialEq)]
pub enum Picked {
    Chosen(PathBuf),
    Cancelled,
    /// The picker cannot be shown here (why, in words).
    Unavailable(String),
}

/// The system's file dialogs behind a trait, so tests never open one (they run on the UI
/// thread).
pub trait Dialogs {
    fn pick(&mut self, picker: &Picker) -> Picked;
}

/// The system's dialogs (rfd: the xdg-desktop-portal, else zenity, on Linux).
pub struct RfdDialogs;

/// A dialog that returns nothing sooner than this was never shown.
const FASTEST_HUMAN_CANCEL: Duration = Duration::from_millis(300);

impl Dialogs for RfdDialogs {
    fn pick(&mut self, picker: &Picker) -> Picked {
        let started = Instant::now();
        let dialog = rfd::FileDialog::new().set_title(picker.title());
        let chosen = match picker {
            Picker::OpenFile { extensions, .. } => {
                let dialog = if extensions.is_empty() {
                    dialog
                } else {
                    dialog.add_filter("expected files", extensions)
                };
                dialog.add_filter("any file", &["*"]).pick_file()
            }
            Picker::SaveFile { file_name, .. } => dialog.set_file_name(file_name).save_file(),
            Picker::Folder { .. } => dialog.pick_folder(),
        };
        match chosen {
            Some(p) => Picked::Chosen(p),
            None if started.elapsed() < FASTEST_HUMAN_CANCEL => {
                Picked::Unavailable("it needs an xdg-desktop-portal file chooser or zenity".into())
            }
            None => Picked::Cancelled,
        }
    }
}

/// No system dialogs (tests, and the preference "always use the built-in browser").
pub struct NoDialogs;

impl Dialogs for NoDialogs {
    fn pick(&mut self, _: &Picker) -> Picked {
        Picked::Cancelled
    }
}

/// A system dialog that is never available: every request goes to the built-in browser.
pub struct UnavailableDialogs;

impl Dialogs for UnavailableDialogs {
    fn pick(&mut self, _: &Picker) -> Picked {
        Picked::Unavailable("no system file dialog in this test".into())
    }
}

/// What a chosen path is for.
#[derive(Debug, Clone, PartialEq)]
pub enum FileRequest {
    OpenScene,
    LoadSession,
    /// Save the session; then go on with the question that asked to save first.
    SaveSession {
        then: Option<Confirm>,
    },
    Export,
    /// The demo's seeds, written as label PNGs into a folder.
    SeedFolder,
    /// A path for a field of the New scene form.
    NewSceneField(Field),
}

impl FileRequest {
    pub fn picker(&self) -> Picker {
        let open = |title: &str, extensions: &[&str]| Picker::OpenFile {
            title: title.into(),
            extensions: extensions.iter().map(|e| e.to_string()).collect(),
        };
        let folder = |title: &str| Picker::Folder {
            title: title.into(),
        };
        match self {
            FileRequest::OpenScene => open("Open a scene (scene.json)", &["json"]),
            FileRequest::LoadSession => open("Load a session", &["json"]),
            FileRequest::SaveSession { .. } => Picker::SaveFile {
                title: "Save the session".into(),
                file_name: "session.endofuse.json".into(),
            },
            FileRequest::Export => folder("Export tracking results to"),
            FileRequest::SeedFolder => folder("Folder for the seed PNGs"),
            FileRequest::NewSceneField(field) if field.is_folder() => folder(field.label()),
            FileRequest::NewSceneField(field) => open(field.label(), field.extensions()),
        }
    }
}

impl EndofuseApp {
    /// Asks for the path `request` needs: the system dialog (unless it failed before or the
    /// preference says otherwise), else the built-in browser. Finished by [`Self::path_chosen`],
    /// now or when the browser answers.
    pub fn request_path(&mut self, request: FileRequest, ctx: &egui::Context) {
        if !self.prefs.builtin_file_browser {
            match self.files.dialogs.pick(&request.picker()) {
                Picked::Chosen(path) => return self.path_chosen(request, path, ctx),
                Picked::Cancelled => return,
                Picked::Unavailable(why) => {
                    // Remembered (File → "Use the built-in file browser" shows it, and
                    // unticking it tries the system dialog again).
                    self.prefs.builtin_file_browser = true;
                    self.status.notify(format!(
                        "No system file dialog could open ({why}): using the built-in file \
                         browser from now on (File menu to change)."
                    ));
                }
            }
        }
        let folder = self.browse_from();
        self.screen.browser = Some(Browser::new(request, &folder));
    }

    /// Where the built-in browser starts: the last folder a path was chosen in, else the
    /// scene's folder, else the working folder.
    fn browse_from(&self) -> PathBuf {
        self.files
            .last_folder
            .clone()
            .or_else(|| self.doc.scene.as_ref().and_then(|s| s.root.clone()))
            .or_else(|| std::env::current_dir().ok())
            .unwrap_or_else(|| PathBuf::from("/"))
    }

    /// Draws the built-in browser, if open, and finishes its request when a path is chosen.
    pub(super) fn browser_window(&mut self, ctx: &egui::Context) {
        let Some(browser) = self.screen.browser.as_mut() else {
            return;
        };
        match browser.show(ctx) {
            Outcome::Open => {}
            Outcome::Cancelled => self.screen.browser = None,
            Outcome::Chosen(path) => {
                if let Some(browser) = self.screen.browser.take() {
                    self.path_chosen(browser.request, path, ctx);
                }
            }
        }
    }

    /// Does what `request` asked a path for.
    pub fn path_chosen(&mut self, request: FileRequest, path: PathBuf, ctx: &egui::Context) {
        // The next browser starts beside what was chosen (a chosen folder's parent: reopening
        // inside an export invites nesting another in it).
        let folder = path.parent().map(Path::to_path_buf);
        self.files.last_folder = folder.filter(|f| !f.as_os_str().is_empty());
        match request {
            // A session picked where a scene was asked for: what the user meant is clear.
            FileRequest::OpenScene if super::files::is_session_file(&path) => {
                self.load_session_asking(path)
            }
            FileRequest::OpenScene => self.open_scene_asking(&path.display().to_string()),
            FileRequest::LoadSession => self.load_session_asking(path),
            FileRequest::SaveSession { then } => {
                self.save_session_to(&path);
                // A failed save keeps the work (the status bar says why).
                if let Some(question) = then
                    && !self.doc.unsaved()
                {
                    self.proceed(question, ctx);
                }
            }
            FileRequest::Export => self.export_into(path),
            FileRequest::SeedFolder => self.save_seed_pngs_into(&path),
            FileRequest::NewSceneField(field) => {
                if let Some(form) = self.screen.new_scene.as_mut() {
                    form.set(field, &path);
                }
            }
        }
    }
}
