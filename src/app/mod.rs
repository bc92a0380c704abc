//! The desktop app (eframe/egui, wgpu): paint seeds on the views, train the forest, place and
//! fit the model, track the video in the background, scrub, review and export. The app is a
//! thin face over the core: all heavy work runs on the [`Worker`] thread, and the UI only
//! sends typed commands and drains events each frame, so the window never blocks.
//!
//! Each frame: worker events are drained into the state ([`jobs`]); the panels and views draw
//! from the state, read-only ([`Shown`]), and send [`commands::AppCommand`]s for what the user
//! asks; the commands are applied after drawing. Files: `state` (document, view, status,
//! preferences), `actions` (every action's label and shortcut, once), `commands` (the queue and
//! what each command does), `jobs` (the worker), `files` (dialogs, sessions, autosave, seed
//! PNGs), `views` (the camera views, painting and placing), `overlay3d` (the wgpu overlay),
//! `panels`, `view` (zoom and pan), `frames` (frames decoded off the UI thread).

pub mod actions;
pub mod commands;
pub mod confirm;
pub mod files;
pub mod frames;
pub mod jobs;
pub mod overlay3d;
pub mod panels;
pub mod pickers;
pub mod state;
pub mod view;
pub mod views;

pub use pickers::{Dialogs, NoDialogs, Picked, Picker, RfdDialogs, UnavailableDialogs};
pub use state::{Busy, Document, Layer, Prefs, Status, StructureStyle, Tool, ViewState};

use crate::worker::Worker;
use actions::Action;
use commands::{AppCommand, CommandQueue};
use files::Files;
use jobs::Jobs;
use views::Screen;

/// The app: its state in parts, the worker, and the command queue.
pub struct EndofuseApp {
    pub worker: Worker,
    pub prefs: Prefs,
    pub doc: Document,
    pub view: ViewState,
    pub status: Status,
    pub files: Files,
    pub jobs: Jobs,
    pub screen: Screen,
    commands: CommandQueue,
    /// A question waiting for the user's answer (unsaved work, replacing an export).
    pub confirm: Option<confirm::Confirm>,
    /// The user answered the close question: the next close goes through.
    allow_close: bool,
}

/// What panels and views read while they draw one frame, and where they send commands.
pub struct Shown<'a> {
    pub doc: &'a Document,
    pub view: &'a ViewState,
    pub prefs: &'a Prefs,
    pub status: &'a Status,
    pub jobs: &'a Jobs,
    pub files: &'a Files,
    pub commands: &'a CommandQueue,
    /// The window's area below the menu bar: floating windows stay inside it, so none covers
    /// the menus.
    pub below_menu: egui::Rect,
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
            doc: Document::default(),
            view: ViewState::default(),
            status: Status::default(),
            files: Files::new(dialogs),
            jobs: Jobs::default(),
            screen: Screen::new(gpu_overlay),
            commands: CommandQueue::default(),
            confirm: None,
            allow_close: false,
        };
        if crate::fit::Mode::parse(&app.prefs.mode).is_some() {
            app.doc.settings.mode = app.prefs.mode.clone();
        }
        if !app.screen.loader.running() {
            app.status
                .fail("cannot start the thread that decodes frames: the views will stay empty");
        }
        app.open_scene(scene);
        app
    }

    /// Sends a command, applied after the current frame is drawn.
    pub fn send(&self, command: AppCommand) {
        self.commands.send(command);
    }

    /// Every action's shortcut, from the action table. A key that is also held for a drag
    /// (Space: pan) fires its action on release, unless the hold was used to drag.
    fn shortcuts(&mut self, ctx: &egui::Context) {
        // A text field or the close question has the keyboard.
        if ctx.egui_wants_keyboard_input()
            || self.confirm.is_some()
            || self.screen.browser.is_some()
        {
            return;
        }
        let held: Vec<egui::Key> = Action::ALL.iter().filter_map(|a| a.held_key()).collect();
        for a in Action::ALL {
            let Some(s) = a.shortcut() else { continue };
            // With nothing to cancel, Esc is left to egui: it closes menus and popups.
            if a == Action::Cancel && self.status.busy.is_none() && !self.view.playing {
                continue;
            }
            if s.modifiers == egui::Modifiers::NONE && held.contains(&s.logical_key) {
                let released = ctx.input(|i| {
                    i.events.iter().any(|e| {
                        matches!(e, egui::Event::Key { key, pressed: false, .. } if *key == s.logical_key)
                    })
                });
                // Swallow the press (egui would otherwise hand it to a focused widget).
                ctx.input_mut(|i| i.consume_shortcut(&s));
                if released {
                    if !self.screen.stroke.panned_with_key {
                        self.send(AppCommand::Action(a));
                    }
                    self.screen.stroke.panned_with_key = false;
                }
            } else {
                // Every press of the frame, not one: quick repeated steps are not dropped.
                while ctx.input_mut(|i| i.consume_shortcut(&s)) {
                    self.send(AppCommand::Action(a));
                }
            }
        }
    }

    /// A close with unsaved work is held back and asked about ([`confirm::Confirm::Close`]).
    fn close_guard(&mut self, ctx: &egui::Context) {
        if ctx.input(|i| i.viewport().close_requested()) && self.doc.unsaved() && !self.allow_close
        {
            ctx.send_viewport_cmd(egui::ViewportCommand::CancelClose);
            self.confirm = Some(confirm::Confirm::Close);
        }
    }
}

impl eframe::App for EndofuseApp {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        let ctx = ui.ctx().clone();
        self.tick(&ctx);
        self.shortcuts(&ctx);
        self.dropped_files(&ctx);
        {
            let mut shown = Shown {
                doc: &self.doc,
                view: &self.view,
                prefs: &self.prefs,
                status: &self.status,
                jobs: &self.jobs,
                files: &self.files,
                commands: &self.commands,
                below_menu: ctx.content_rect(),
            };
            panels::menu::menu_bar(&shown, ui);
            shown.below_menu = ui.available_rect_before_wrap();
            panels::menu::status_bar(&shown, ui);
            panels::timeline::timeline(&shown, &mut self.screen.layout, ui);
            panels::side::side_panel(&shown, ui);
            egui::CentralPanel::default().show(ui, |ui| views::views(&shown, &mut self.screen, ui));
            if shown.view.show_review {
                panels::review::review_window(&shown, &ctx);
            }
            panels::new_scene::window(&shown, &mut self.screen.new_scene, &ctx);
            if shown.view.show_help {
                panels::help::help_window(&shown, &ctx);
            }
        }
        self.browser_window(&ctx);
        self.apply_commands(&ctx);
        self.close_guard(&ctx);
        self.confirm_modal(&ctx);
    }

    fn save(&mut self, storage: &mut dyn eframe::Storage) {
        eframe::set_value(storage, eframe::APP_KEY, &self.prefs);
    }
}

/// Opens the desktop app on `scene` (blocks until the window closes).
pub fn run_native(scene: &str) -> anyhow::Result<()> {
    let options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_title("endofuse")
            .with_inner_size([1400.0, 820.0])
            // Below this the side panel and two views no longer fit: views shrank to
            // thumbnails and the track controls were cut off.
            .with_min_inner_size([900.0, 560.0])
            .with_drag_and_drop(true),
        ..Default::default()
    };
    let scene = scene.to_string();
    eframe::run_native(
        "endofuse",
        options,
        Box::new(move |cc| Ok(Box::new(EndofuseApp::new(cc, &scene, Box::new(RfdDialogs))))),
    )
    .map_err(|e| anyhow::anyhow!("cannot open the window: {}", window_error(&e.to_string())))
}

/// A window error in the user's terms: winit's says where in its own source it failed
/// ("os error at /root/.cargo/registry/…/linux/mod.rs:765: neither WAYLAND_DISPLAY nor …").
fn window_error(raw: &str) -> String {
    if raw.contains("WAYLAND_DISPLAY") && raw.contains("DISPLAY is set") {
        return "no display (neither DISPLAY nor WAYLAND_DISPLAY is set): run it in a desktop \
                session, or use the command-line commands (endofuse --help)"
            .into();
    }
    // Keep the message, drop the source location before it.
    match raw.find(".rs:") {
        Some(at) => {
            let after = &raw[at..];
            let tail = after.find(": ").map_or(after, |k| &after[k + 2..]);
            let head = raw[..at].rsplit_once(" at ").map_or("", |(h, _)| h);
            format!("{head}: {tail}")
        }
        None => raw.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::window_error;

    /// winit's errors lose the location in its own source; no display is said plainly.
    #[test]
    fn window_errors_are_said_without_winits_source_paths() {
        let raw = "winit EventLoopError: os error at /root/.cargo/registry/src/index.crates.io-1949cf8c6b5b557f/winit-0.30.13/src/platform_impl/linux/mod.rs:765: neither WAYLAND_DISPLAY nor WAYLAND_SOCKET nor DISPLAY is set.";
        let said = window_error(raw);
        assert!(
            said.starts_with("no display") && !said.contains(".cargo"),
            "{said}"
        );
        let other =
            window_error("winit EventLoopError: os error at /x/y/mod.rs:12: the X server refused");
        assert_eq!(
            other,
            "winit EventLoopError: os error: the X server refused"
        );
        assert_eq!(window_error("plain"), "plain");
    }
}
