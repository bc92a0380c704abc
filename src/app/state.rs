//! The app's state in parts with one job each: [`Document`] (what the user opened and made:
//! the scene, the strokes, the forest, the placement and the fits), [`ViewState`] (what is
//! shown and how), [`Status`] (the worker's progress, the last error and notice) and [`Prefs`]
//! (kept between runs). Panels and views only read them; every change goes through a command
//! (`commands`), applied once per frame.

use super::view::ViewTransform;
use crate::appearance::{Appearance, ClassMap};
use crate::fit::config::Mode;
use crate::fit::{FitState, Model};
use crate::geometry::Affine;
use crate::scene::Scene;
use crate::session::{FitSettings, FrameResult, SESSION_FORMAT, Session};
use crate::strokes::SeedEditor;
use crate::worker::Task;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::sync::Arc;

/// Preferences kept between runs (eframe persistence); every field has a default, so an old
/// or damaged preferences file never stops the app.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
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
    /// Draw each hidden structure's 95 % region (where it could be) around its outline.
    pub show_hidden_region: bool,
    pub hidden_region_opacity: f32,
    /// The fit mode last chosen (R, L, LS, LSC), kept between runs.
    pub mode: String,
    /// Always pick files in the built-in browser, never the system's dialog.
    pub builtin_file_browser: bool,
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
            show_hidden_region: true,
            hidden_region_opacity: 0.3,
            mode: "LSC".into(),
            builtin_file_browser: false,
        }
    }
}

impl Prefs {
    /// The radius (image px) the left button paints or erases with.
    pub fn radius_px(&self, tool: Tool) -> f32 {
        match tool {
            Tool::Eraser => self.eraser_px,
            _ => self.brush_px,
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

/// What the worker is busy with, for the status bar.
#[derive(Debug, Clone, PartialEq)]
pub struct Busy {
    pub task: Task,
    pub what: String,
    pub done: usize,
    pub total: usize,
}

/// What the user opened and made.
#[derive(Default)]
pub struct Document {
    pub scene: Option<Arc<Scene>>,
    /// The model of the scene's structures (its joint shape model built once, by the worker).
    pub model: Option<Arc<Model>>,
    pub classes: Option<ClassMap>,
    /// The scene as the user named it: a folder, a scene.json, or "demo".
    pub spec: String,
    pub editor: SeedEditor,
    pub settings: FitSettings,
    pub appearance: Option<Arc<Appearance>>,
    /// The pose the model was placed at (the scene's, automatic, or by hand).
    pub placement: Option<Affine>,
    pub results: BTreeMap<usize, FrameResult>,
    /// What moving the model by hand replaced, newest last (Undo restores it).
    pub placement_undo: Vec<PlacementUndo>,
    /// Counts changes to what a session keeps besides the strokes: fits, the placement, the
    /// settings, the forest.
    pub edits: u64,
    /// [`Document::revision`] at the last save, and at the last autosave.
    pub saved: (u64, u64),
    pub autosaved: (u64, u64),
}

/// The model moved by hand on `frame`: the placement before, and the frame's fit the move
/// set aside. Moves one after another, with nothing else between them, are one entry.
#[derive(Clone)]
pub struct PlacementUndo {
    /// The id of its mark in the stroke editor's history (one history for both).
    pub id: u64,
    pub frame: usize,
    pub placement: Option<Affine>,
    pub result: Option<FrameResult>,
    /// [`Document::edits`] after the latest move of this entry.
    pub edits_after: u64,
}

/// What [`Document::undo`] took back.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Undid {
    Nothing,
    Stroke,
    /// A hand move of the model; `restored`: the frame whose fit came back with it.
    Move {
        restored: Option<usize>,
    },
}

impl Document {
    /// Moves the model by hand to `affine` on `frame`, setting that frame's fit aside; both
    /// come back with [`Document::undo`]. `new_step`: this move begins a gesture (a drag, a
    /// run of wheel turns), so Undo takes it back apart from the gesture before; the moves of
    /// one gesture undo as one.
    pub fn place(&mut self, frame: usize, affine: Affine, new_step: bool) {
        let continuing = !new_step
            && self.placement_undo.last().is_some_and(|u| {
                u.frame == frame && u.edits_after == self.edits && self.editor.newest_is_mark(u.id)
            });
        if !continuing {
            let id = self.placement_undo.last().map_or(0, |u| u.id + 1);
            self.placement_undo.push(PlacementUndo {
                id,
                frame,
                placement: self.placement,
                result: self.results.get(&frame).cloned(),
                edits_after: 0,
            });
            self.editor.mark(id);
            // The editor's history holds at most as many steps as this list keeps.
            let oldest = self
                .placement_undo
                .len()
                .saturating_sub(crate::strokes::UNDO_STEPS);
            self.placement_undo.drain(..oldest);
        }
        self.placement = Some(affine);
        self.results.remove(&frame);
        self.touch();
        if let Some(u) = self.placement_undo.last_mut() {
            u.edits_after = self.edits;
        }
    }

    /// A fit arrived or the model was placed otherwise: what hand moves set aside can no
    /// longer be put back over it (it would replace the newer fit).
    pub fn forget_placement_undo(&mut self) {
        self.placement_undo.clear();
        self.editor.forget_marks(|_| false);
    }

    /// Is there a stroke or a hand move of the model to take back?
    pub fn can_undo(&self) -> bool {
        self.editor.can_undo()
    }

    /// Takes back the newest stroke or hand move of the model, saying which it was.
    pub fn undo(&mut self) -> Undid {
        let id = match self.editor.undo_step() {
            crate::strokes::Undone::Nothing => return Undid::Nothing,
            crate::strokes::Undone::Stroke => return Undid::Stroke,
            crate::strokes::Undone::Mark(id) => id,
        };
        let Some(at) = self.placement_undo.iter().position(|u| u.id == id) else {
            return Undid::Nothing;
        };
        let u = self.placement_undo.remove(at);
        self.placement_undo.truncate(at);
        self.placement = u.placement;
        let restored = u.result.map(|r| {
            self.results.insert(u.frame, r);
            u.frame
        });
        self.touch();
        Undid::Move { restored }
    }

    /// True when anything a session keeps changed since the last save.
    pub fn unsaved(&self) -> bool {
        self.scene.is_some() && self.revision() != self.saved
    }

    /// What the save markers compare: the strokes' revision and the count of other edits.
    pub fn revision(&self) -> (u64, u64) {
        (self.editor.revision, self.edits)
    }

    /// Something a session keeps, other than the strokes, changed.
    pub fn touch(&mut self) {
        self.edits += 1;
    }

    pub fn session(&self) -> Session {
        Session {
            format: SESSION_FORMAT.into(),
            scene: self.spec.clone(),
            seeds: crate::session::encode_seeds(&self.editor.seeds()),
            settings: self.settings.clone(),
            placement: self.placement,
            forest: self.appearance.as_deref().cloned(),
            results: self.results.values().cloned().collect(),
        }
    }

    /// The mode tracking runs in (LSC when the settings name none it knows).
    pub fn mode(&self) -> Mode {
        Mode::parse(&self.settings.mode).unwrap_or(Mode::LSC)
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

    /// Seed value painted for forest class `k`.
    pub fn seed_value(&self, k: usize) -> u8 {
        if k == 0 {
            return crate::scene::SEED_BACKGROUND;
        }
        self.classes
            .as_ref()
            .and_then(|c| c.labels.get(k).copied())
            .unwrap_or(crate::scene::SEED_BACKGROUND)
    }

    /// Colour of forest class `k` (0 = background/tools) for seeds and probability maps.
    pub fn class_colour(&self, k: usize) -> [u8; 3] {
        if k == 0 {
            return crate::overlay::BACKGROUND_SEED_COLOUR;
        }
        let (Some(classes), Some(scene)) = (&self.classes, &self.scene) else {
            return [255, 255, 255];
        };
        let label = classes.labels.get(k).copied().unwrap_or(0);
        let i = scene
            .structures
            .iter()
            .position(|s| s.label == label)
            .unwrap_or(k);
        crate::overlay::structure_colour(i)
    }

    /// Frames in the scene (1 without one).
    pub fn frame_count(&self) -> usize {
        self.scene.as_ref().map_or(1, |s| s.frame_count.max(1))
    }
}

/// What is shown and how.
pub struct ViewState {
    pub frame: usize,
    pub playing: bool,
    pub play_clock_s: f64,
    /// The view follows frames as the tracker delivers them (until the user scrubs).
    pub follow_tracking: bool,
    pub track_range: (usize, usize),
    pub tool: Tool,
    /// Forest class painted (0 = background/tools).
    pub class: usize,
    /// Strokes paint over other classes.
    pub overwrite: bool,
    pub transform: Option<ViewTransform>,
    pub layer: Layer,
    pub styles: Vec<StructureStyle>,
    pub show_review: bool,
    /// The help sheet is open.
    pub show_help: bool,
    /// Per camera: seeds and overlay hidden in that view only (to see the probability under
    /// them). Missing entries are shown.
    pub hidden: Vec<ViewHidden>,
}

/// What one view hides of what the side panel shows.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ViewHidden {
    pub seeds: bool,
    pub overlay: bool,
}

/// A part of a view that can be hidden in it alone.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ViewPart {
    Seeds,
    Overlay,
}

impl ViewState {
    /// What view `camera` hides.
    pub fn hidden_in(&self, camera: usize) -> ViewHidden {
        self.hidden.get(camera).copied().unwrap_or_default()
    }
}

impl Default for ViewState {
    fn default() -> Self {
        Self {
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
            show_review: false,
            show_help: false,
            hidden: Vec::new(),
        }
    }
}

/// The status line: the worker's job, the last error (shown until dismissed) and notice.
#[derive(Debug, Clone, Default)]
pub struct Status {
    pub busy: Option<Busy>,
    pub error: Option<String>,
    pub notice: Option<String>,
}

impl Status {
    /// Shows `error` to the user (and logs it): the one place an error reaches the window.
    pub fn fail(&mut self, error: impl std::fmt::Display) {
        let message = error.to_string();
        log::warn!("{message}");
        self.error = Some(message);
    }

    /// Tells the user what just happened. An earlier error no longer describes the present
    /// (it would hide this: "Saved …" under an old "Nothing tracked yet"), so it goes.
    pub fn notify(&mut self, notice: impl Into<String>) {
        self.error = None;
        self.notice = Some(notice.into());
    }

    /// A job starts: the previous job's notice ("Model placed…", "Exported to …") no longer
    /// describes what is on screen.
    pub fn busy_with(&mut self, task: Task, what: String, total: usize) {
        self.notice = None;
        self.busy = Some(Busy {
            task,
            what,
            done: 0,
            total,
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Seeds;
    use crate::strokes::Dab;

    fn result(frame: usize, energy: f64) -> FrameResult {
        FrameResult {
            frame,
            state: FitState {
                affine: Affine::IDENTITY,
                shape: vec![],
                intrinsics: vec![],
            },
            energy,
            confidence: 0.9,
            lost: false,
            ms: 1.0,
            dice: vec![],
            hidden_error_mm: vec![],
            depth_explains_zoom: false,
            refused: vec![],
            hidden_region: Default::default(),
        }
    }

    fn moved(x_mm: f64) -> Affine {
        let mut a = Affine::IDENTITY;
        a.q[9] = x_mm;
        a
    }

    /// A stroke of `value` (each call a different one, so that every stroke changes pixels).
    fn stroke(doc: &mut Document, value: u8) {
        doc.editor.begin_stroke();
        let paint = Dab::Paint {
            value,
            overwrite: true,
        };
        doc.editor.line(0, 0, (2.0, 2.0), (8.0, 8.0), 2.0, paint);
        doc.editor.end_stroke();
    }

    /// A hand move of the model discards the frame's fit; Undo brings the fit and the
    /// placement before back, and takes strokes and moves back newest first.
    #[test]
    fn undo_takes_back_a_model_move_and_restores_the_fit() {
        let mut doc = Document {
            editor: SeedEditor::new(&Seeds::default(), vec![(16, 16)]),
            placement: Some(moved(0.0)),
            ..Document::default()
        };
        doc.results.insert(3, result(3, 7.0));
        stroke(&mut doc, 1);
        // One drag is many moves: they undo as one.
        for x in 1..=5 {
            doc.place(3, moved(x as f64), x == 1);
        }
        assert!(!doc.results.contains_key(&3));
        assert_eq!(doc.placement, Some(moved(5.0)));
        stroke(&mut doc, 2);
        // One history: stroke, the five moves as one step, stroke.
        assert_eq!(doc.editor.undo_steps(), 3);

        // The stroke after the move goes first ...
        assert_eq!(doc.undo(), Undid::Stroke);
        assert_eq!(doc.editor.undo_steps(), 2);
        assert_eq!(doc.placement, Some(moved(5.0)));
        // ... then the move, with the fit it discarded ...
        assert_eq!(doc.undo(), Undid::Move { restored: Some(3) });
        assert_eq!(doc.placement, Some(moved(0.0)));
        assert_eq!(doc.results.get(&3), Some(&result(3, 7.0)));
        assert!(doc.placement_undo.is_empty());
        // ... then the stroke before it.
        assert!(doc.can_undo());
        assert_eq!(doc.undo(), Undid::Stroke);
        assert_eq!(doc.editor.undo_steps(), 0);
        assert!(!doc.can_undo());
    }

    /// Two drags in a row, nothing between them, are two steps: Undo takes back the second
    /// and leaves the first.
    #[test]
    fn consecutive_gestures_undo_one_at_a_time() {
        let mut doc = Document {
            editor: SeedEditor::new(&Seeds::default(), vec![(16, 16)]),
            placement: Some(moved(0.0)),
            ..Document::default()
        };
        for (x, first) in [(1.0, true), (2.0, false), (3.0, true), (4.0, false)] {
            doc.place(2, moved(x), first);
        }
        assert_eq!(doc.editor.undo_steps(), 2);
        assert_eq!(doc.undo(), Undid::Move { restored: None });
        assert_eq!(doc.placement, Some(moved(2.0)), "the first drag stays");
        assert_eq!(doc.undo(), Undid::Move { restored: None });
        assert_eq!(doc.placement, Some(moved(0.0)));
        assert!(!doc.can_undo());
    }

    /// A stroke between two moves keeps them apart, and Undo takes back the second move,
    /// the stroke and the first move in that order; a fit that arrives after a move is not
    /// replaced by the fit the move set aside.
    #[test]
    fn strokes_and_moves_undo_newest_first_and_a_newer_fit_is_kept() {
        let mut doc = Document {
            editor: SeedEditor::new(&Seeds::default(), vec![(16, 16)]),
            placement: Some(moved(0.0)),
            ..Document::default()
        };
        doc.results.insert(1, result(1, 5.0));
        doc.place(1, moved(1.0), true);
        stroke(&mut doc, 1);
        doc.place(1, moved(2.0), true);
        assert_eq!(doc.placement_undo.len(), 2);
        assert_eq!(
            doc.undo(),
            Undid::Move { restored: None },
            "the second move: no fit to restore"
        );
        assert_eq!(doc.placement, Some(moved(1.0)));
        assert_eq!(doc.editor.undo_steps(), 2, "the stroke is still there");
        assert_eq!(doc.undo(), Undid::Stroke);
        assert_eq!(doc.editor.undo_steps(), 1, "then the stroke");
        assert_eq!(
            doc.undo(),
            Undid::Move { restored: Some(1) },
            "then the first move, with its fit"
        );
        assert_eq!(doc.placement, Some(moved(0.0)));

        // A move, then a fit of that frame arrives: Undo leaves the new fit alone.
        doc.place(1, moved(3.0), true);
        doc.forget_placement_undo();
        doc.results.insert(1, result(1, 9.0));
        assert_eq!(doc.undo(), Undid::Nothing);
        assert_eq!(doc.results.get(&1).map(|r| r.energy), Some(9.0));
        assert_eq!(doc.placement, Some(moved(3.0)));
    }

    /// Moves separated by something else (here a fit arriving) are separate undo steps.
    #[test]
    fn moves_with_an_edit_between_are_separate_undo_steps() {
        let mut doc = Document {
            editor: SeedEditor::new(&Seeds::default(), vec![(16, 16)]),
            ..Document::default()
        };
        doc.place(0, moved(1.0), true);
        doc.results.insert(0, result(0, 2.0));
        doc.touch();
        doc.place(0, moved(2.0), true);
        assert_eq!(doc.placement_undo.len(), 2);
        assert_eq!(doc.undo(), Undid::Move { restored: Some(0) });
        assert_eq!(doc.placement, Some(moved(1.0)));
        assert_eq!(doc.undo(), Undid::Move { restored: None });
        assert_eq!(doc.placement, None);
        assert!(doc.results.get(&0).is_some_and(|r| r.energy == 2.0));
    }
}
