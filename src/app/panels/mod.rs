//! The panels around the views: the menu bar and status bar ([`menu`]), the timeline with
//! per-frame confidence ([`timeline`]), the side panel ([`side`]) and the review window with
//! plots over time ([`review`]). They read the app's state and send commands; none of them
//! changes a field.

pub mod browser;
pub mod help;
pub mod menu;
pub mod new_scene;
pub mod review;
pub mod side;
pub mod timeline;

use super::Shown;
use super::actions::Action;

/// A button for an action, with its shortcut in the tooltip.
pub(super) fn action_button(shown: &Shown, ui: &mut egui::Ui, a: Action, enabled: bool) {
    let hint = a.hint(ui.ctx());
    if ui
        .add_enabled(enabled, egui::Button::new(a.label()))
        .on_hover_text(hint)
        .clicked()
    {
        shown.commands.act(a);
    }
}

/// A menu entry for an action, with its shortcut beside it.
pub(super) fn menu_item(shown: &Shown, ui: &mut egui::Ui, a: Action) {
    menu_item_if(shown, ui, a, Ok(()));
}

/// A menu entry that is greyed out, saying why on hover, unless `ready` is Ok.
pub(super) fn menu_item_if(shown: &Shown, ui: &mut egui::Ui, a: Action, ready: Result<(), &str>) {
    let mut button = egui::Button::new(a.label());
    if let Some(s) = a.shortcut() {
        button = button.shortcut_text(crate::app::actions::shortcut_text(ui.ctx(), &s));
    }
    let r = ui.add_enabled(ready.is_ok(), button);
    let r = match ready {
        Err(why) => r.on_disabled_hover_text(why),
        Ok(()) => r,
    };
    if r.clicked() {
        shown.commands.act(a);
        ui.close();
    }
}
