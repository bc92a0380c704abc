//! Every user action of the app, defined once: its label (menus, buttons, tooltips) and its
//! keyboard shortcut. Menus, buttons and the key handler all read this table, so a shortcut
//! shown is always the shortcut that works: the number keys that pick the seed class and the
//! Space key held to pan are entries of it too.

use egui::{Key, KeyboardShortcut, Modifiers};

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Action {
    NewScene,
    OpenScene,
    OpenDemo,
    SaveSession,
    LoadSession,
    SaveSeeds,
    Export,
    Brush,
    Eraser,
    Place,
    BrushSmaller,
    BrushBigger,
    Undo,
    Redo,
    Train,
    ShowImage,
    ShowProbability,
    ShowUncertainty,
    Initialise,
    FitFrame,
    Track,
    Cancel,
    PlayPause,
    StepBack,
    StepForward,
    FirstFrame,
    LastFrame,
    ResetView,
    Review,
    /// Show or hide the hidden structures' 95 % regions.
    HiddenRegion,
    /// Paint forest class k (0 = background/tools) with the brush: number key k + 1.
    PickClass(u8),
    /// Pan the views: drag while holding Space (or with the middle button).
    Pan,
    /// The help sheet: every action and its shortcut, and the first steps.
    Help,
}

/// Classes the number keys can pick (1 = background/tools, 2… the visible structures).
pub const CLASS_KEY_COUNT: u8 = 9;

const CLASS_KEYS: [Key; CLASS_KEY_COUNT as usize] = [
    Key::Num1,
    Key::Num2,
    Key::Num3,
    Key::Num4,
    Key::Num5,
    Key::Num6,
    Key::Num7,
    Key::Num8,
    Key::Num9,
];

const CLASS_LABELS: [&str; CLASS_KEY_COUNT as usize] = [
    "Paint background / tools",
    "Paint class 2",
    "Paint class 3",
    "Paint class 4",
    "Paint class 5",
    "Paint class 6",
    "Paint class 7",
    "Paint class 8",
    "Paint class 9",
];

/// egui's text for a shortcut, with the keys it spells out by name ("OpenBracket") written
/// as the key's own symbol.
pub fn shortcut_text(ctx: &egui::Context, shortcut: &KeyboardShortcut) -> String {
    let text = ctx.format_shortcut(shortcut);
    match shortcut.logical_key {
        Key::OpenBracket => text.replace("OpenBracket", "["),
        Key::CloseBracket => text.replace("CloseBracket", "]"),
        _ => text,
    }
}

const fn key(k: Key) -> Option<KeyboardShortcut> {
    Some(KeyboardShortcut::new(Modifiers::NONE, k))
}

const fn cmd(k: Key) -> Option<KeyboardShortcut> {
    Some(KeyboardShortcut::new(Modifiers::COMMAND, k))
}

impl Action {
    /// In the order the key handler tries them (Redo before Undo: Ctrl+Shift+Z contains Ctrl+Z).
    pub const ALL: [Action; 41] = [
        Action::NewScene,
        Action::OpenScene,
        Action::OpenDemo,
        Action::SaveSession,
        Action::LoadSession,
        Action::SaveSeeds,
        Action::Export,
        Action::Brush,
        Action::Eraser,
        Action::Place,
        Action::BrushSmaller,
        Action::BrushBigger,
        Action::Redo,
        Action::Undo,
        Action::Train,
        Action::ShowImage,
        Action::ShowProbability,
        Action::ShowUncertainty,
        Action::Initialise,
        Action::FitFrame,
        Action::Track,
        Action::Cancel,
        Action::PlayPause,
        Action::StepBack,
        Action::StepForward,
        Action::FirstFrame,
        Action::LastFrame,
        Action::ResetView,
        Action::Review,
        Action::HiddenRegion,
        Action::PickClass(0),
        Action::PickClass(1),
        Action::PickClass(2),
        Action::PickClass(3),
        Action::PickClass(4),
        Action::PickClass(5),
        Action::PickClass(6),
        Action::PickClass(7),
        Action::PickClass(8),
        Action::Pan,
        Action::Help,
    ];

    pub fn label(self) -> &'static str {
        match self {
            Action::NewScene => "New scene from CT, calibration and videos…",
            Action::OpenScene => "Open scene…",
            Action::OpenDemo => "Open the demo",
            Action::SaveSession => "Save session…",
            Action::LoadSession => "Load session…",
            Action::SaveSeeds => "Save seeds as label PNGs…",
            Action::Export => "Export masks, overlays and trajectory…",
            Action::Brush => "Brush",
            Action::Eraser => "Eraser",
            Action::Place => "Place model",
            Action::BrushSmaller => "Smaller brush",
            Action::BrushBigger => "Bigger brush",
            Action::Undo => "Undo",
            Action::Redo => "Redo stroke",
            Action::Train => "Train forest",
            Action::ShowImage => "Image",
            Action::ShowProbability => "Probability",
            Action::ShowUncertainty => "Uncertainty",
            Action::Initialise => "Place automatically",
            Action::FitFrame => "Fit this frame",
            Action::Track => "Track",
            Action::Cancel => "Cancel",
            Action::PlayPause => "Play / pause",
            Action::StepBack => "Previous frame",
            Action::StepForward => "Next frame",
            Action::FirstFrame => "First frame",
            Action::LastFrame => "Last frame",
            Action::ResetView => "Fit views to window",
            Action::Review => "Review plots",
            Action::HiddenRegion => "Where hidden structures could be (95 % region)",
            Action::Help => "Help: shortcuts and first steps",
            Action::PickClass(k) => CLASS_LABELS.get(k as usize).copied().unwrap_or("Paint"),
            Action::Pan => "Pan views (hold and drag)",
        }
    }

    pub fn shortcut(self) -> Option<KeyboardShortcut> {
        match self {
            Action::NewScene => cmd(Key::N),
            Action::OpenScene => cmd(Key::O),
            Action::SaveSession => cmd(Key::S),
            Action::LoadSession => cmd(Key::L),
            Action::Export => cmd(Key::E),
            Action::Brush => key(Key::B),
            Action::Eraser => key(Key::E),
            Action::Place => key(Key::M),
            Action::BrushSmaller => key(Key::OpenBracket),
            Action::BrushBigger => key(Key::CloseBracket),
            Action::Undo => cmd(Key::Z),
            Action::Redo => Some(KeyboardShortcut::new(
                Modifiers::COMMAND.plus(Modifiers::SHIFT),
                Key::Z,
            )),
            Action::Train => key(Key::T),
            Action::ShowImage => key(Key::I),
            Action::ShowProbability => key(Key::P),
            Action::ShowUncertainty => key(Key::U),
            Action::FitFrame => key(Key::F),
            Action::Track => cmd(Key::T),
            Action::Cancel => key(Key::Escape),
            Action::PlayPause => key(Key::Space),
            Action::StepBack => key(Key::ArrowLeft),
            Action::StepForward => key(Key::ArrowRight),
            Action::FirstFrame => key(Key::Home),
            Action::LastFrame => key(Key::End),
            Action::ResetView => key(Key::R),
            Action::HiddenRegion => key(Key::H),
            Action::Help => key(Key::F1),
            Action::PickClass(k) => CLASS_KEYS.get(k as usize).copied().and_then(key),
            Action::OpenDemo
            | Action::SaveSeeds
            | Action::Initialise
            | Action::Review
            | Action::Pan => None,
        }
    }

    /// A key that the action needs held down while the mouse works (not a press). Where it is
    /// also another action's shortcut (Space: play / pause), that action fires when the key is
    /// released without having been held for a drag.
    pub fn held_key(self) -> Option<Key> {
        match self {
            Action::Pan => Some(Key::Space),
            _ => None,
        }
    }

    /// The shortcut as a user reads it ("Ctrl+T", "[", "Esc"); empty where there is none.
    pub fn shortcut_text(self, ctx: &egui::Context) -> String {
        self.shortcut()
            .map(|s| shortcut_text(ctx, &s))
            .unwrap_or_default()
    }

    /// "Label (shortcut)" for tooltips.
    pub fn hint(self, ctx: &egui::Context) -> String {
        match (self.shortcut(), self.held_key()) {
            (Some(s), _) => format!("{} ({})", self.label(), shortcut_text(ctx, &s)),
            (None, Some(k)) => format!("{} (hold {})", self.label(), k.name()),
            (None, None) => self.label().to_string(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_two_actions_share_a_shortcut() {
        let mut seen = Vec::new();
        for a in Action::ALL {
            if let Some(s) = a.shortcut() {
                assert!(!seen.contains(&s), "{a:?} repeats a shortcut");
                seen.push(s);
            }
        }
        // Every action is listed once.
        for (i, a) in Action::ALL.iter().enumerate() {
            assert!(!Action::ALL[i + 1..].contains(a), "{a:?} listed twice");
        }
    }
}
