//! The help sheet (F1, Help menu): the first steps of the workflow, then every entry of the
//! action table with its shortcut — generated from the table, so it cannot drift from what the
//! keys do.

use crate::app::Shown;
use crate::app::actions::Action;
use crate::app::commands::AppCommand;
use egui::RichText;

/// The workflow a new user follows, in order.
pub const FIRST_STEPS: [&str; 6] = [
    "Open a scene (File > Open, or File > New scene from a CT, a calibration and videos); the demo opens by itself.",
    "Paint seeds on the first frames: 1 background and tools, 2, 3, … the structures; B brush, E eraser.",
    "Train the forest (T) and check the probability view (P).",
    "Place the model (M, or Place automatically) and Fit this frame (F).",
    "Track (Ctrl+T) in mode LSC; scrub by clicking or dragging the timeline (bars: each frame's confidence, red lost; blue ticks: seeded frames); frames not yet fitted say so in the views.",
    "Review the plots, then File > Export, and save the session (Ctrl+S).",
];

pub fn help_window(shown: &Shown, ctx: &egui::Context) {
    let mut open = shown.view.show_help;
    let class_names: &[String] = shown
        .doc
        .classes
        .as_ref()
        .map_or(&[], |c| c.names.as_slice());
    egui::Window::new("Help")
        .constrain_to(shown.below_menu)
        .open(&mut open)
        .default_size([520.0, 560.0])
        .show(ctx, |ui| {
            ui.heading("First steps");
            for (n, step) in FIRST_STEPS.iter().enumerate() {
                ui.label(format!("{}. {step}", n + 1));
            }
            ui.separator();
            ui.heading("Every action and its shortcut");
            egui::ScrollArea::vertical().show(ui, |ui| {
                egui::Grid::new("help-actions")
                    .num_columns(2)
                    .striped(true)
                    .show(ui, |ui| {
                        for a in Action::ALL {
                            let label = match a {
                                // The scene's own names, and only the classes it has.
                                Action::PickClass(k) if !class_names.is_empty() => {
                                    match class_names.get(k as usize) {
                                        Some(name) if k > 0 => format!("Paint {name}"),
                                        Some(_) => a.label().to_string(),
                                        None => continue,
                                    }
                                }
                                _ => a.label().to_string(),
                            };
                            ui.label(label);
                            let keys = match (a.shortcut(), a.held_key()) {
                                (Some(_), _) => a.shortcut_text(ctx),
                                (None, Some(k)) => format!("hold {}", k.name()),
                                (None, None) => String::new(),
                            };
                            ui.label(RichText::new(keys).monospace());
                            ui.end_row();
                        }
                    });
            });
        });
    if open != shown.view.show_help {
        shown.commands.send(AppCommand::SetHelpShown(open));
    }
}
