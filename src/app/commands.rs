//! The one way the UI changes the app (rerun's `CommandSender` idea): panels, views and the
//! key handler send [`AppCommand`]s into the [`CommandQueue`]; the app applies them once per
//! frame, after drawing, in the order they were sent. Every menu entry, button and shortcut is
//! an [`Action`] of the action table; the other commands carry a value a widget edited.

use super::EndofuseApp;
use super::actions::Action;
use super::pickers::FileRequest;
use super::state::{Layer, Prefs, StructureStyle, Tool, ViewPart};
use super::view::ViewTransform;
use crate::geometry::Affine;
use crate::session::FitSettings;
use crate::strokes::Dab;
use crossbeam_channel::{Receiver, Sender, unbounded};

/// What the user asked for.
#[derive(Debug, Clone, PartialEq)]
pub enum AppCommand {
    Action(Action),
    /// A scene folder, a scene.json, or "demo" (File → Open recent, a dropped folder).
    OpenScene(String),
    /// A session file (a dropped file, Restore of an autosave).
    LoadSession(std::path::PathBuf),
    /// Show frame `t` (the user scrubbed: stop following the tracker).
    SetFrame(usize),
    SetLayer(Layer),
    SetTrackRange(usize, usize),
    SetOverwrite(bool),
    SetPrefs(Prefs),
    SetSettings(FitSettings),
    SetStyle(usize, StructureStyle),
    SetReviewShown(bool),
    SetHelpShown(bool),
    SetTransform(ViewTransform),
    /// Hide (or show again) seeds or the overlay in one view only.
    ToggleInView {
        camera: usize,
        part: ViewPart,
    },
    /// Brush or eraser size times `factor`.
    ResizeBrush(f32),
    BeginStroke,
    /// Dabs along a segment of `camera`'s image at `frame` (pixel-centre coordinates).
    PaintLine {
        camera: usize,
        frame: usize,
        from: (f32, f32),
        to: (f32, f32),
        radius_px: f32,
        dab: Dab,
    },
    EndStroke,
    /// The model moved by hand to `affine` (this frame's fit is dropped: fit again from here);
    /// `new_step`: the move begins a gesture, which Undo takes back apart from the one before.
    Place {
        affine: Affine,
        new_step: bool,
    },
    DiscardAutosave,
    DismissError,
    /// Pick a file or folder for a field of the New scene form.
    BrowseNewScene(crate::app::panels::new_scene::Field),
    /// Build the scene the New scene form describes (then open it).
    CreateScene(Box<crate::newscene::NewSceneOptions>),
}

/// Commands sent during a frame, applied after it.
pub struct CommandQueue {
    tx: Sender<AppCommand>,
    rx: Receiver<AppCommand>,
}

impl Default for CommandQueue {
    fn default() -> Self {
        let (tx, rx) = unbounded();
        Self { tx, rx }
    }
}

impl CommandQueue {
    pub fn send(&self, command: AppCommand) {
        // The queue owns both ends: sending cannot fail while it lives.
        let _ = self.tx.send(command);
    }

    pub fn act(&self, action: Action) {
        self.send(AppCommand::Action(action));
    }

    /// Everything sent since the last call, oldest first.
    pub fn drain(&self) -> Vec<AppCommand> {
        self.rx.try_iter().collect()
    }
}

impl EndofuseApp {
    /// Applies every queued command.
    pub fn apply_commands(&mut self, ctx: &egui::Context) {
        for c in self.commands.drain() {
            self.apply(c, ctx);
        }
    }

    /// Applies one command now.
    pub fn apply(&mut self, command: AppCommand, ctx: &egui::Context) {
        match command {
            AppCommand::Action(a) => self.do_action(a, ctx),
            AppCommand::OpenScene(spec) => self.open_scene_asking(&spec),
            AppCommand::LoadSession(path) => self.load_session_asking(path),
            AppCommand::SetFrame(t) => {
                self.set_frame(t);
                self.view.playing = false;
            }
            AppCommand::SetLayer(l) => self.view.layer = l,
            AppCommand::SetTrackRange(a, b) => self.view.track_range = (a.min(b), a.max(b)),
            AppCommand::SetOverwrite(o) => self.view.overwrite = o,
            AppCommand::SetPrefs(p) => self.prefs = p,
            AppCommand::SetSettings(s) => {
                if s != self.doc.settings {
                    self.prefs.mode = s.mode.clone();
                    self.doc.settings = s;
                    self.doc.touch();
                }
            }
            AppCommand::SetStyle(i, s) => {
                if let Some(style) = self.view.styles.get_mut(i) {
                    *style = s;
                }
            }
            AppCommand::SetHelpShown(shown) => self.view.show_help = shown,
            AppCommand::SetReviewShown(shown) => self.view.show_review = shown,
            AppCommand::SetTransform(t) => self.view.transform = Some(t),
            AppCommand::ToggleInView { camera, part } => {
                if self.view.hidden.len() <= camera {
                    self.view.hidden.resize(camera + 1, Default::default());
                }
                let hidden = &mut self.view.hidden[camera];
                match part {
                    ViewPart::Seeds => hidden.seeds = !hidden.seeds,
                    ViewPart::Overlay => hidden.overlay = !hidden.overlay,
                }
            }
            AppCommand::ResizeBrush(factor) => self.resize_brush(factor),
            AppCommand::BeginStroke => self.doc.editor.begin_stroke(),
            AppCommand::PaintLine {
                camera,
                frame,
                from,
                to,
                radius_px,
                dab,
            } => {
                // The editor's stroke may have ended under the drag (an undo, a scene or a
                // session arriving): the rest of the drag is one stroke again, not a step per
                // dab.
                if !self.doc.editor.in_stroke() {
                    self.doc.editor.begin_stroke();
                }
                self.doc
                    .editor
                    .line(camera, frame, from, to, radius_px, dab);
            }
            AppCommand::EndStroke => {
                if self.doc.editor.in_stroke() {
                    self.doc.editor.end_stroke();
                }
            }
            AppCommand::Place { affine, new_step } => {
                self.doc.place(self.view.frame, affine, new_step);
                self.screen.textures.forget_overlays();
            }
            AppCommand::DiscardAutosave => self.discard_autosave(),
            AppCommand::DismissError => self.status.error = None,
            AppCommand::BrowseNewScene(field) => {
                self.request_path(FileRequest::NewSceneField(field), ctx)
            }
            AppCommand::CreateScene(options) => self.create_scene(*options),
        }
    }

    /// Does what an entry of the action table does.
    pub fn do_action(&mut self, a: Action, ctx: &egui::Context) {
        let frames = self.doc.frame_count();
        match a {
            Action::OpenScene => self.request_path(FileRequest::OpenScene, ctx),
            Action::NewScene => {
                self.screen.new_scene.get_or_insert_with(Default::default);
            }
            Action::OpenDemo => self.open_scene_asking(crate::open::DEMO),
            Action::SaveSession => self.request_path(FileRequest::SaveSession { then: None }, ctx),
            Action::LoadSession => self.request_path(FileRequest::LoadSession, ctx),
            Action::SaveSeeds => self.save_seed_pngs(ctx),
            Action::Export => self.export(ctx),
            Action::Brush => self.view.tool = Tool::Brush,
            Action::Eraser => self.view.tool = Tool::Eraser,
            Action::Place => {
                self.view.tool = Tool::Place;
                self.place_in_front_if_nothing_drawn();
            }
            Action::BrushSmaller => self.resize_brush(0.8),
            Action::BrushBigger => self.resize_brush(1.25),
            Action::Undo => {
                if let crate::app::state::Undid::Move { restored } = self.doc.undo() {
                    self.screen.textures.forget_overlays();
                    self.status.notify(match restored {
                        Some(t) => format!("Model move undone: frame {t}'s fit is back."),
                        // The start M put in front of the camera is a step too: said so, as
                        // the model vanishing looked like an undo gone too far.
                        None if self.doc.placement.is_none() => {
                            "Model placement undone: nothing placed (M puts it back in front of \
                             the camera)."
                                .to_string()
                        }
                        None => "Model move undone.".to_string(),
                    });
                }
            }
            Action::Redo => {
                self.doc.editor.redo();
            }
            Action::Train => self.train(),
            Action::ShowImage => self.view.layer = Layer::Image,
            Action::ShowProbability => {
                let k = match self.view.layer {
                    Layer::Probability(k) => k,
                    _ => self.view.class,
                };
                self.view.layer = Layer::Probability(k);
            }
            Action::ShowUncertainty => self.view.layer = Layer::Uncertainty,
            Action::Initialise => self.initialise(),
            Action::FitFrame => self.track((self.view.frame, self.view.frame)),
            Action::Track => self.track(self.view.track_range),
            Action::Cancel => {
                if self.status.busy.is_some() {
                    self.worker.cancel();
                }
                self.view.playing = false;
            }
            Action::PlayPause => {
                self.view.playing = !self.view.playing;
                self.view.play_clock_s = ctx.input(|i| i.time);
            }
            Action::StepBack => self.set_frame(self.view.frame.saturating_sub(1)),
            Action::StepForward => self.set_frame((self.view.frame + 1).min(frames - 1)),
            Action::FirstFrame => self.set_frame(0),
            Action::LastFrame => self.set_frame(frames - 1),
            Action::ResetView => self.view.transform = None,
            Action::Review => self.view.show_review = !self.view.show_review,
            Action::HiddenRegion => self.prefs.show_hidden_region = !self.prefs.show_hidden_region,
            Action::Help => self.view.show_help = !self.view.show_help,
            Action::PickClass(k) => {
                let classes = self.doc.classes.as_ref().map_or(0, |c| c.len());
                if (k as usize) < classes {
                    self.view.class = k as usize;
                    if matches!(self.view.tool, Tool::Eraser | Tool::Place) {
                        self.view.tool = Tool::Brush;
                    }
                    if let Layer::Probability(_) = self.view.layer {
                        self.view.layer = Layer::Probability(k as usize);
                    }
                }
            }
            // Panning is a drag with the key held: the views do it.
            Action::Pan => {}
        }
    }

    /// The Place tool chosen with nothing drawn at this frame (no fit, no placement: a scene
    /// without `initial_pose`): the model appears in front of the first camera, as an undo step
    /// of its own, to be dragged onto the organ; the drags had nothing to move before.
    fn place_in_front_if_nothing_drawn(&mut self) {
        let frame = self.view.frame;
        if self.doc.state_at(frame).is_some() {
            return;
        }
        let (Some(scene), Some(model)) = (&self.doc.scene, &self.doc.model) else {
            return;
        };
        let Some(camera) = scene.cameras.first() else {
            return;
        };
        let mean = model.deformed(&vec![0.0; model.shape.mode_count()]);
        let Some(organ) = mean.get(model.anchor) else {
            return;
        };
        let guess = crate::fit::init::in_front_of_camera(camera, organ);
        self.doc.place(frame, guess, true);
        self.screen.textures.forget_overlays();
        self.status.notify(
            "Model in front of the camera: drag it onto the organ (right-drag turns, \
             Shift+right-drag rolls, wheel: depth).",
        );
    }

    pub fn resize_brush(&mut self, factor: f32) {
        let r = match self.view.tool {
            Tool::Eraser => &mut self.prefs.eraser_px,
            _ => &mut self.prefs.brush_px,
        };
        // Whole pixels above 10, tenths below: sizes a user reads and sets again.
        let v = (*r * factor).clamp(1.0, 200.0);
        *r = if v >= 10.0 {
            v.round()
        } else {
            (v * 10.0).round() / 10.0
        };
    }

    /// Moves to frame `t` (the user scrubbed: stop following the tracker).
    pub fn set_frame(&mut self, t: usize) {
        if t != self.view.frame {
            self.view.follow_tracking = false;
        }
        self.view.frame = t;
    }
}
